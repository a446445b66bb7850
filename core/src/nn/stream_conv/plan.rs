//! Settled and total columns per unit (the counts a stack and its plan
//! share), and the plan: every capacity from an integer simulation of the
//! counts.

use super::*;

/// Outputs `[lo, hi)` of one unit (empty when `lo >= hi`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Span {
    pub(super) lo: usize,
    pub(super) hi: usize,
}

impl Span {
    pub(super) fn is_empty(&self) -> bool {
        self.lo >= self.hi
    }
    fn len(&self) -> usize {
        self.hi.saturating_sub(self.lo)
    }
}

/// Column counts of a stack after some pushes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Counts {
    /// Input columns of unit 0 (all settled).
    n_in0: usize,
    /// (n_units) output columns of each unit on the current prefix.
    pub(super) n_out: [usize; MAX_UNITS],
    /// (n_units) settled output columns of each unit.
    pub(super) set: [usize; MAX_UNITS],
}

impl Counts {
    pub(super) const ZERO: Counts = Counts {
        n_in0: 0,
        n_out: [0; MAX_UNITS],
        set: [0; MAX_UNITS],
    };

    /// Input columns of unit `u`.
    pub(super) fn n_in(&self, u: usize) -> usize {
        if u == 0 {
            self.n_in0
        } else {
            self.n_out[u - 1]
        }
    }

    /// Settled input columns of unit `u` (= columns its ring has received).
    pub(super) fn set_in(&self, u: usize) -> usize {
        if u == 0 {
            self.n_in0
        } else {
            self.set[u - 1]
        }
    }

    /// One push: returns the newly settled outputs of every unit.
    pub(super) fn advance(&mut self, g: &Geometry) -> [Span; MAX_UNITS] {
        let mut new = [Span::default(); MAX_UNITS];
        self.n_in0 += g.in_per_push;
        for (u, unit) in g.units().iter().enumerate() {
            let (n_in, set_in) = (self.n_in(u), self.set_in(u));
            let n_out = unit.out_len(n_in);
            let lo = self.set[u];
            let mut hi = lo;
            while hi < n_out && unit.last_in(hi) < set_in as isize {
                hi += 1;
            }
            self.n_out[u] = n_out;
            self.set[u] = hi;
            new[u] = Span { lo, hi };
        }
        new
    }

    /// Unsettled outputs of every unit needed for the unsettled outputs
    /// `[a, b)` of the last unit (`a >= settled`, `b <= n_out`): the tail
    /// cone. Empty below the first unit whose needed inputs are all settled.
    pub(super) fn cone(&self, g: &Geometry, a: usize, b: usize) -> [Span; MAX_UNITS] {
        let mut need = [Span::default(); MAX_UNITS];
        let last = g.n_units - 1;
        need[last] = Span { lo: a, hi: b };
        for u in (1..=last).rev() {
            let Span { lo, hi } = need[u];
            if lo >= hi {
                break;
            }
            let unit = &g.units[u];
            let below_lo = unit.first_in(lo).max(self.set[u - 1] as isize);
            let below_hi = (unit.last_in(hi - 1) + 1).min(self.n_out[u - 1] as isize);
            if below_lo < below_hi {
                need[u - 1] = Span {
                    lo: below_lo as usize,
                    hi: below_hi as usize,
                };
            }
        }
        need
    }
}

// ---------------------------------------------------------------------------
// Plan: capacities from a simulation of the counts
// ---------------------------------------------------------------------------

/// Every size a stack needs, from its geometry and lag (no weights).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StackPlan {
    pub geometry: Geometry,
    pub lag: usize,
    /// (n_units) ring capacity of each unit: its settled input columns
    /// ever read (oldest age read).
    pub ring: [usize; MAX_UNITS],
    /// (n_units) most unsettled outputs of each unit computed by one
    /// `output` call at this lag (0 at lag >= future_max).
    pub tail: [usize; MAX_UNITS],
    /// Settled outputs of the last unit kept for `output`.
    pub out_ring: usize,
    /// (n_units) most outputs of each unit computed by one push (settled batch).
    pub batch: [usize; MAX_UNITS],
    /// (n_units) most input columns gathered for one computation.
    pub gather: [usize; MAX_UNITS],
}

/// Floats of each [`StreamScratch`] buffer one stack needs (a scratch for
/// `n` stacks at once holds `n` times the per-column buffers).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ScratchNeed {
    pub(super) g: usize,
    pub(super) h: usize,
    pub(super) r: usize,
    pub(super) t: usize,
    pub(super) col: usize,
    pub(super) z: usize,
}

impl ScratchNeed {
    fn max(self, o: ScratchNeed) -> ScratchNeed {
        ScratchNeed {
            g: self.g.max(o.g),
            h: self.h.max(o.h),
            r: self.r.max(o.r),
            t: self.t.max(o.t),
            col: self.col.max(o.col),
            z: self.z.max(o.z),
        }
    }
    /// The needs of two stacks computed together: per-column buffers add
    /// up, the kernel tiles are shared.
    pub(super) fn plus(self, o: ScratchNeed) -> ScratchNeed {
        ScratchNeed {
            g: self.g + o.g,
            h: self.h + o.h,
            r: self.r + o.r,
            t: self.t + o.t,
            col: self.col.max(o.col),
            z: self.z.max(o.z),
        }
    }

    /// The largest need of any stack of `cfg` (every VQ-VAE, both kinds,
    /// every lag `0..=future_max`); None for a config outside the limits.
    pub fn for_model(cfg: &ModelConfig) -> Option<ScratchNeed> {
        Self::for_vqs(&cfg.vqs())
    }

    /// The largest need of any stack of these VQ-VAEs (both kinds, every
    /// lag `0..=future_max`).
    pub fn for_vqs(vqs: &[VqConfig]) -> Option<ScratchNeed> {
        let mut need = ScratchNeed::default();
        for vq in vqs {
            for kind in [StackKind::Encoder, StackKind::Decoder] {
                let g = Geometry::new(vq, kind)?;
                let fmax = future_max_of(&g);
                need = need.max(StackPlan::simulate(g, 0, fmax).scratch_need());
            }
        }
        Some(need)
    }

    /// Every buffer of `self` at least that of `o`.
    pub fn holds(&self, o: &ScratchNeed) -> bool {
        self.g >= o.g
            && self.h >= o.h
            && self.r >= o.r
            && self.t >= o.t
            && self.col >= o.col
            && self.z >= o.z
    }

    /// True if `s` holds at least these floats in every buffer.
    pub(super) fn fits(&self, s: &StreamScratch<'_>) -> bool {
        s.g.len() >= self.g
            && s.h.len() >= self.h
            && s.r.len() >= self.r
            && s.ta.len() >= self.t
            && s.tb.len() >= self.t
            && s.tile.len() >= self.col.max(self.z)
    }
}

/// Smallest lag (tokens) at which every requested output is settled
/// (`e_max` / `d_max` of docs/STREAMING.md §1): the tiny fixture and the
/// published model 22 for both stacks, `tiny2` 8. 0 for an invalid config.
pub fn future_max(cfg: &VqConfig, kind: StackKind) -> usize {
    Geometry::new(cfg, kind)
        .map(|g| future_max_of(&g))
        .unwrap_or(0)
}

pub(super) fn future_max_of(g: &Geometry) -> usize {
    // Lag l works at push P iff the request [m(P-1-l), m(P-l)) is settled,
    // i.e. l >= P - floor(settled / m); the maximum over P is the answer.
    let (mut c, m, last) = (Counts::ZERO, g.out_per_push, g.n_units - 1);
    let mut need = 0;
    for p in 1..=g.sim_pushes(0) {
        c.advance(g);
        need = need.max(p.saturating_sub(c.set[last] / m));
    }
    need
}

impl StackPlan {
    /// The plan of a stack serving requests at `lag` (any lag; above
    /// [`future_max`] only the output ring grows). None for an invalid config.
    pub fn new(cfg: &VqConfig, kind: StackKind, lag: usize) -> Option<StackPlan> {
        let g = Geometry::new(cfg, kind)?;
        let fmax = future_max_of(&g);
        let sim_lag = lag.min(fmax);
        let mut plan = StackPlan::simulate(g, sim_lag, sim_lag);
        // Above future_max every request is settled and one token older
        // per extra lag: the output ring grows by out_per_push per token.
        let extra = (lag - sim_lag).checked_mul(plan.geometry.out_per_push)?;
        plan.out_ring = plan.out_ring.checked_add(extra)?;
        plan.lag = lag;
        Some(plan)
    }

    /// Runs the counts over enough pushes and records, for requests at
    /// every lag in `lag_lo..=lag_hi` (`output(m(P-1-lag), m)` after push
    /// `P`), the largest read of every kind.
    pub(super) fn simulate(g: Geometry, lag_lo: usize, lag_hi: usize) -> StackPlan {
        let pushes = g.sim_pushes(lag_hi);
        StackPlan::simulate_for(g, lag_lo, lag_hi, pushes)
    }

    pub(super) fn simulate_for(
        g: Geometry,
        lag_lo: usize,
        lag_hi: usize,
        pushes: usize,
    ) -> StackPlan {
        let z = [0; MAX_UNITS];
        let mut p = StackPlan {
            geometry: g,
            lag: lag_hi,
            ring: z,
            tail: z,
            out_ring: 0,
            batch: z,
            gather: z,
        };
        let g = &p.geometry.clone();
        let m = g.out_per_push;
        let mut c = Counts::ZERO;
        for push in 1..=pushes {
            let new = c.advance(g);
            for (u, unit) in g.units().iter().enumerate() {
                if !new[u].is_empty() {
                    let (lo, hi) = unit.gather_span(new[u].lo, new[u].hi, c.n_in(u));
                    p.record_read(u, lo, hi, c.set_in(u));
                    p.batch[u] = p.batch[u].max(new[u].len());
                }
            }
            for lag in lag_lo..=lag_hi.min(push - 1) {
                let t = m * (push - 1 - lag);
                p.record_request(g, &c, t, m);
            }
        }
        p
    }

    /// A read of input columns `[lo, hi)` of unit `u` whose ring holds
    /// `set_in` columns (those `>= set_in` come from the tail below).
    fn record_read(&mut self, u: usize, lo: usize, hi: usize, set_in: usize) {
        if lo < set_in.min(hi) {
            self.ring[u] = self.ring[u].max(set_in - lo);
        }
        self.gather[u] = self.gather[u].max(hi - lo);
    }

    /// The reads of `output(t, n)` on counts `c`.
    fn record_request(&mut self, g: &Geometry, c: &Counts, t: usize, n: usize) {
        let last = g.n_units - 1;
        let set = c.set[last];
        if t < set {
            self.out_ring = self.out_ring.max(set - t);
        }
        if t + n <= set {
            return;
        }
        let need = c.cone(g, t.max(set), t + n);
        for (u, unit) in g.units().iter().enumerate() {
            if !need[u].is_empty() {
                let (lo, hi) = unit.gather_span(need[u].lo, need[u].hi, c.n_in(u));
                self.record_read(u, lo, hi, c.set_in(u));
                self.tail[u] = self.tail[u].max(need[u].len());
            }
        }
    }

    /// Floats of every scratch buffer this plan's computations need.
    pub(super) fn scratch_need(&self) -> ScratchNeed {
        let g = &self.geometry;
        let mut n = ScratchNeed::default();
        for (u, unit) in g.units().iter().enumerate() {
            let outs = self.batch[u].max(self.tail[u]);
            n.g = n.g.max(self.gather[u] * unit.c_in);
            n.t = n.t.max(outs * unit.c_out);
            match unit.kind {
                UnitKind::Conv => n.col = n.col.max(conv1d_col_len(unit.c_in, unit.kernel)),
                UnitKind::Res => {
                    n.h = n.h.max(outs * g.inner);
                    n.r = n.r.max(outs * unit.c_out);
                    n.col = n.col.max(conv1d_col_len(unit.c_in, unit.kernel));
                }
                UnitKind::ConvT => n.z = n.z.max(convt_z_len(unit.c_out, unit.kernel)),
            }
        }
        n
    }

    /// Ring capacities of the units (n_units).
    pub fn rings(&self) -> &[usize] {
        &self.ring[..self.geometry.n_units]
    }

    /// Tail sizes of the units (n_units).
    pub fn tails(&self) -> &[usize] {
        &self.tail[..self.geometry.n_units]
    }
}
