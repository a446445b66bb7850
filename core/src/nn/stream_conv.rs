//! Streaming ("truncated-prefix") form of one VQ-VAE conv stack
//! (docs/STREAMING.md §3.2 encoder, §3.7 decoders; `StreamConv` in
//! tools/reference/streaming.py is the executable spec).
//!
//! A stack is a chain of *units*: every `Conv1d`, every whole residual
//! block `x + conv1x1(relu(conv_dil(relu(x))))` and every
//! `ConvTranspose1d`. Input columns arrive a few at a time (encoder: `hop`
//! frames per push; decoder: one dequantised code per push). After any
//! push, output column `t` of the stack equals column `t` of the original
//! stack run on everything pushed so far, with its own zero padding at the
//! end of that prefix (what `vq_encoder::encode_features` /
//! `vq_decoder::decode` compute on the prefix).
//!
//! A column is *settled* once no longer prefix can change it (it reads no
//! end padding). Each unit keeps a ring of its settled input columns; a
//! push computes the newly settled outputs of every unit (one batched conv
//! per unit) and appends them to the next unit's ring (the last unit's to
//! the output ring). Unsettled columns (the *tail*) are computed only when
//! [`StreamStack::output`] asks for one: the cone of the requested columns,
//! unit by unit, from ring + tail of the unit below, zeros past the end.
//! At a lag of [`future_max`] or more no tail is ever computed.
//!
//! Several stacks of one geometry (the same stack of several sessions) can
//! be pushed and read together ([`StreamStack::push_many`],
//! [`StreamStack::output_many`]): unit after unit, every stack's new
//! columns (or tail cone) are gathered one after another and computed as
//! one segmented conv (`conv1d_segs`, `conv_transpose1d_segs`), so the
//! unit's weights are read once per kernel tile for all of them. Each
//! stack's columns are bit for bit those of its own push (row-independent
//! kernels); the single-stack calls are the same code on one stack.
//!
//! Every capacity (rings, output ring, scratch) comes from an integer
//! simulation of the settled counts ([`StackPlan`]), the same code path the
//! stack runs, so an [`Arena`](crate::arena::Arena) and a
//! [`Planner`](crate::arena::Planner) get the same sizes and no read can
//! leave a ring (a read outside one is an `Err`, never a panic).
//!
//! Buffers are time-major: a column block of `n` columns of `c` channels is
//! `(n, c)`, as everywhere in the engine.

use heapless::Vec;

use crate::arena::{ArenaError, Carve};
use crate::duolando::config::ModelConfig;
use crate::error::{Buffer, Error};
use crate::kernels::{
    conv1d, conv1d_col_len, conv1d_segs, conv_transpose1d_segs, convt_z_len, relu_inplace,
    ConvGeom, ConvSeg, Matrix,
};
use crate::limits::{MAX_DEPTH, MAX_DILATION, MAX_DOWNSAMPLE, MAX_DOWN_T, MAX_STRIDE, MAX_WIDTH};
use crate::nn::names::dilation;
use crate::nn::vq_config::VqConfig;
use crate::nn::weights::{ConvTW, ConvW, DecoderW, EncoderW, ResBlockW};

/// Most stacks one [`StreamStack::push_many`] / [`StreamStack::output_many`]
/// computes together (the sessions of a batch).
pub const MAX_STACKS: usize = 64;

/// Most units of one stack: decoder `1 + down_t * (depth + 1) + 1`.
pub const MAX_UNITS: usize = (MAX_DOWN_T * (MAX_DEPTH + 1)) as usize + 2;

/// Which conv stack of a VQ-VAE.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StackKind {
    /// `[Conv1d(k=2s, s, p=s/2) -> Resnet1D] x down_t -> Conv1d(k3, p1)`;
    /// `hop` frames (in_channels) in per push, one feature (emb_width) out.
    Encoder,
    /// `Conv1d(k3) -> [Resnet1D(reversed) -> ConvT(k=2s, s, p=s/2)] x down_t
    /// -> Conv1d(k3)`; one code (emb_width) in per push, `hop` frames out.
    Decoder,
}

/// The weights of one stack (the kind must match the stack's).
#[derive(Clone, Copy, Debug)]
pub enum StackW<'r, 'a> {
    Encoder(&'r EncoderW<'a>),
    Decoder(&'r DecoderW<'a>),
}

// ---------------------------------------------------------------------------
// Geometry: units and their index arithmetic
// ---------------------------------------------------------------------------

/// What a unit computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UnitKind {
    /// `Conv1d`: output `t` reads inputs `t*s - p + j*d`, `j < k`.
    Conv,
    /// Residual block (k3, stride 1, pad = dilation): output `t` reads
    /// inputs `t - d ..= t + d`.
    Res,
    /// `ConvTranspose1d`: input `i` writes outputs `i*s - p ..= i*s - p + k - 1`.
    ConvT,
}

/// One unit: kind, geometry and channels (from the [`VqConfig`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Unit {
    pub kind: UnitKind,
    pub kernel: usize,
    pub stride: usize,
    pub pad: usize,
    pub dilation: usize,
    pub c_in: usize,
    /// Output channels; for the last decoder unit the larger of the position
    /// and rotation outputs (the weights given may have fewer).
    pub c_out: usize,
}

const EMPTY_UNIT: Unit = Unit {
    kind: UnitKind::Conv,
    kernel: 1,
    stride: 1,
    pad: 0,
    dilation: 1,
    c_in: 0,
    c_out: 0,
};

/// `floor(a / b)` for `b > 0`.
fn div_floor(a: isize, b: isize) -> isize {
    a.div_euclid(b)
}

/// `ceil(a / b)` for `b > 0`.
fn div_ceil(a: isize, b: isize) -> isize {
    -(-a).div_euclid(b)
}

impl Unit {
    fn conv(
        kernel: usize,
        stride: usize,
        pad: usize,
        dilation: usize,
        c_in: usize,
        c_out: usize,
    ) -> Unit {
        Unit {
            kind: UnitKind::Conv,
            kernel,
            stride,
            pad,
            dilation,
            c_in,
            c_out,
        }
    }
    fn res(dil: usize, width: usize) -> Unit {
        Unit {
            kind: UnitKind::Res,
            kernel: 3,
            stride: 1,
            pad: dil,
            dilation: dil,
            c_in: width,
            c_out: width,
        }
    }
    fn convt(stride: usize, c_in: usize, c_out: usize) -> Unit {
        Unit {
            kind: UnitKind::ConvT,
            kernel: 2 * stride,
            stride,
            pad: stride / 2,
            dilation: 1,
            c_in,
            c_out,
        }
    }

    /// Output columns of the unit over `n_in` input columns (PyTorch's formulas).
    pub fn out_len(&self, n_in: usize) -> usize {
        let (n, k, s, p, d) = (
            n_in as isize,
            self.kernel as isize,
            self.stride as isize,
            self.pad as isize,
            self.dilation as isize,
        );
        let len = match self.kind {
            UnitKind::ConvT if n == 0 => 0,
            UnitKind::ConvT => (n - 1) * s - 2 * p + k,
            _ => div_floor(n + 2 * p - d * (k - 1) - 1, s) + 1,
        };
        len.max(0) as usize
    }

    /// Smallest input index output `t` reads (may be negative: zero padding).
    pub fn first_in(&self, t: usize) -> isize {
        let (t, k, s, p) = (
            t as isize,
            self.kernel as isize,
            self.stride as isize,
            self.pad as isize,
        );
        match self.kind {
            UnitKind::ConvT => div_ceil(t + p - (k - 1), s),
            _ => t * s - p,
        }
    }

    /// Largest input index output `t` reads (may be past the end: zero padding).
    pub fn last_in(&self, t: usize) -> isize {
        let (t, k, s, p, d) = (
            t as isize,
            self.kernel as isize,
            self.stride as isize,
            self.pad as isize,
            self.dilation as isize,
        );
        match self.kind {
            UnitKind::ConvT => div_floor(t + p, s),
            _ => t * s - p + d * (k - 1),
        }
    }

    /// Input columns `[lo, hi)` that outputs `[a, b)` read inside `[0, n_in)`
    /// (the rest is zero padding), `a < b`.
    fn gather_span(&self, a: usize, b: usize, n_in: usize) -> (usize, usize) {
        let lo = self.first_in(a).max(0) as usize;
        let hi = (self.last_in(b - 1) + 1).clamp(0, n_in as isize) as usize;
        (lo, hi.max(lo))
    }

    /// Left offset of the kernel when outputs `[a, ..)` are computed from
    /// input columns gathered from `g0` (`ConvGeom::pad` / the transposed
    /// conv's `pad`); never negative for the stacks' geometries.
    fn local_pad(&self, a: usize, g0: usize) -> Option<usize> {
        let (a, g0, s, p) = (
            a as isize,
            g0 as isize,
            self.stride as isize,
            self.pad as isize,
        );
        let pad = match self.kind {
            UnitKind::ConvT => a + p - g0 * s,
            _ => g0 - (a * s - p),
        };
        usize::try_from(pad).ok()
    }
}

/// The units of one stack, derived from its [`VqConfig`] only.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Geometry {
    pub kind: StackKind,
    pub units: [Unit; MAX_UNITS],
    pub n_units: usize,
    /// Input columns per push (encoder: hop; decoder: 1).
    pub in_per_push: usize,
    /// Output columns per pushed token (encoder: 1; decoder: hop).
    pub out_per_push: usize,
    /// Inner width of the residual blocks.
    pub inner: usize,
}

impl Geometry {
    /// None for a config outside the engine's limits (unvalidated).
    pub fn new(cfg: &VqConfig, kind: StackKind) -> Option<Geometry> {
        let hop = cfg.hop()? as usize;
        let (s, w, emb) = (
            cfg.stride_t as usize,
            cfg.width as usize,
            cfg.emb_width as usize,
        );
        // The engine's limits (crate::limits), so no index arithmetic can overflow.
        let chans = [
            cfg.width,
            cfg.emb_width,
            cfg.in_channels,
            cfg.rot_channels,
            cfg.res_inner()?,
        ];
        let max_dil = cfg
            .dilation_growth_rate
            .checked_pow(cfg.depth.saturating_sub(1))?;
        if !(1..=MAX_DEPTH).contains(&cfg.depth)
            || !(1..=MAX_DOWN_T).contains(&cfg.down_t)
            || !(2..=MAX_STRIDE).contains(&cfg.stride_t)
            || s % 2 != 0
            || !(1..=MAX_DILATION).contains(&max_dil)
            || chans.iter().any(|&c| c > MAX_WIDTH)
            || hop > (MAX_DOWNSAMPLE * MAX_DOWNSAMPLE) as usize
        {
            return None;
        }
        let mut units: Vec<Unit, MAX_UNITS> = Vec::new();
        let mut add = |u: Unit| units.push(u).ok();
        let dil = |d: u32, rev: bool| dilation(cfg, d, rev) as usize;
        match kind {
            StackKind::Encoder => {
                for i in 0..cfg.down_t {
                    let c_in = if i == 0 { cfg.in_channels as usize } else { w };
                    add(Unit::conv(2 * s, s, s / 2, 1, c_in, w))?;
                    for d in 0..cfg.depth {
                        add(Unit::res(dil(d, false), w))?;
                    }
                }
                add(Unit::conv(3, 1, 1, 1, w, emb))?;
            }
            StackKind::Decoder => {
                add(Unit::conv(3, 1, 1, 1, emb, w))?;
                for i in 0..cfg.down_t {
                    for d in 0..cfg.depth {
                        add(Unit::res(dil(d, true), w))?;
                    }
                    add(Unit::convt(s, w, if i + 1 == cfg.down_t { emb } else { w }))?;
                }
                let c_out = cfg.in_channels.max(cfg.rot_channels) as usize;
                add(Unit::conv(3, 1, 1, 1, emb, c_out))?;
            }
        }
        let mut arr = [EMPTY_UNIT; MAX_UNITS];
        arr[..units.len()].copy_from_slice(&units);
        let (in_per_push, out_per_push) = match kind {
            StackKind::Encoder => (hop, 1),
            StackKind::Decoder => (1, hop),
        };
        Some(Geometry {
            kind,
            units: arr,
            n_units: units.len(),
            in_per_push,
            out_per_push,
            inner: cfg.res_inner()? as usize,
        })
    }

    pub fn units(&self) -> &[Unit] {
        &self.units[..self.n_units]
    }

    /// Input columns one output column depends on, in pushes (rounded up), + 1.
    fn field_pushes(&self) -> usize {
        let mut span = 1usize;
        for u in self.units().iter().rev() {
            span = match u.kind {
                UnitKind::ConvT => (span + u.kernel) / u.stride + 2,
                _ => (span - 1) * u.stride + u.dilation * (u.kernel - 1) + 1,
            };
        }
        span / self.in_per_push + 2
    }

    /// Pushes the size simulation runs: well past the start-up transient
    /// (the schedule is periodic once the receptive field is inside the
    /// prefix) plus the lag. A test checks that doubling it changes nothing.
    fn sim_pushes(&self, lag: usize) -> usize {
        3 * self.field_pushes() + lag + 4 * self.in_per_push.max(self.out_per_push) + 8
    }
}

// ---------------------------------------------------------------------------
// Counts: settled / total columns per unit (shared by the stack and the plan)
// ---------------------------------------------------------------------------

/// Outputs `[lo, hi)` of one unit (empty when `lo >= hi`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Span {
    lo: usize,
    hi: usize,
}

impl Span {
    fn is_empty(&self) -> bool {
        self.lo >= self.hi
    }
    fn len(&self) -> usize {
        self.hi.saturating_sub(self.lo)
    }
}

/// Column counts of a stack after some pushes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Counts {
    /// Input columns of unit 0 (all settled).
    n_in0: usize,
    /// (n_units) output columns of each unit on the current prefix.
    n_out: [usize; MAX_UNITS],
    /// (n_units) settled output columns of each unit.
    set: [usize; MAX_UNITS],
}

impl Counts {
    const ZERO: Counts = Counts {
        n_in0: 0,
        n_out: [0; MAX_UNITS],
        set: [0; MAX_UNITS],
    };

    /// Input columns of unit `u`.
    fn n_in(&self, u: usize) -> usize {
        if u == 0 {
            self.n_in0
        } else {
            self.n_out[u - 1]
        }
    }

    /// Settled input columns of unit `u` (= columns its ring has received).
    fn set_in(&self, u: usize) -> usize {
        if u == 0 {
            self.n_in0
        } else {
            self.set[u - 1]
        }
    }

    /// One push: returns the newly settled outputs of every unit.
    fn advance(&mut self, g: &Geometry) -> [Span; MAX_UNITS] {
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
    fn cone(&self, g: &Geometry, a: usize, b: usize) -> [Span; MAX_UNITS] {
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
    g: usize,
    h: usize,
    r: usize,
    t: usize,
    col: usize,
    z: usize,
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
    fn plus(self, o: ScratchNeed) -> ScratchNeed {
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
    fn fits(&self, s: &StreamScratch<'_>) -> bool {
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

fn future_max_of(g: &Geometry) -> usize {
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
    fn simulate(g: Geometry, lag_lo: usize, lag_hi: usize) -> StackPlan {
        let pushes = g.sim_pushes(lag_hi);
        StackPlan::simulate_for(g, lag_lo, lag_hi, pushes)
    }

    fn simulate_for(g: Geometry, lag_lo: usize, lag_hi: usize, pushes: usize) -> StackPlan {
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
    fn scratch_need(&self) -> ScratchNeed {
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

// ---------------------------------------------------------------------------
// Scratch shared by every stack of a model
// ---------------------------------------------------------------------------

/// Working memory of every stack of a model (sized for the widest stack
/// and every lag `0..=future_max`), for up to `n` stacks computed together
/// ([`StreamStack::push_many`]); carve once per session (`n = 1`) or per
/// batch of sessions.
pub struct StreamScratch<'s> {
    /// (cols, c_in) input columns of one unit, gathered contiguous.
    g: &'s mut [f32],
    /// (cols, inner) residual block inner activations.
    h: &'s mut [f32],
    /// (cols, width) residual block 1x1 output.
    r: &'s mut [f32],
    /// (cols, c_out) outputs of one unit: the settled batch of a push, or
    /// (ping-pong with `tb`) the tails of `output`.
    ta: &'s mut [f32],
    /// (cols, c_out) the other tail buffer.
    tb: &'s mut [f32],
    /// The kernel tile of one unit: `conv1d`'s im2col tile or
    /// `conv_transpose1d`'s (a unit is one or the other, so one region
    /// of the larger size serves both).
    tile: &'s mut [f32],
}

impl<'s> StreamScratch<'s> {
    /// Scratch for `n` stacks of needs at most `need` ([`ScratchNeed::for_model`]).
    pub fn carve<A: Carve<'s>>(a: &mut A, need: ScratchNeed, n: usize) -> Result<Self, ArenaError> {
        let per = |f: usize| f.checked_mul(n).ok_or(ArenaError::Overflow);
        Ok(StreamScratch {
            g: a.f32(per(need.g)?)?,
            h: a.f32(per(need.h)?)?,
            r: a.f32(per(need.r)?)?,
            ta: a.f32(per(need.t)?)?,
            tb: a.f32(per(need.t)?)?,
            tile: a.f32(need.col.max(need.z))?,
        })
    }
}

impl<'s> StreamScratch<'s> {
    /// Scratch for one stack of any VQ-VAE of `cfg` at a time.
    pub fn for_model<A: Carve<'s>>(a: &mut A, cfg: &ModelConfig) -> Result<Self, ArenaError> {
        StreamScratch::carve(
            a,
            ScratchNeed::for_model(cfg).ok_or(ArenaError::Overflow)?,
            1,
        )
    }
}

impl Default for StreamScratch<'_> {
    fn default() -> Self {
        StreamScratch {
            g: &mut [],
            h: &mut [],
            r: &mut [],
            ta: &mut [],
            tb: &mut [],
            tile: &mut [],
        }
    }
}

// ---------------------------------------------------------------------------
// Column ring
// ---------------------------------------------------------------------------

/// The last `cap` columns (`ch` floats each) of an append-only sequence.
struct ColRing<'s> {
    /// (cap, ch): column `i` at slot `i % cap`.
    data: &'s mut [f32],
    cap: usize,
    ch: usize,
    /// Columns appended so far.
    n: usize,
}

/// A ring read outside the columns it holds (the plan makes this
/// impossible; reported as an error, never a panic).
fn evicted(index: usize, oldest: usize, len: usize) -> Error {
    Error::Evicted { index, oldest, len }
}

impl<'s> ColRing<'s> {
    fn carve<A: Carve<'s>>(a: &mut A, cap: usize, ch: usize) -> Result<Self, ArenaError> {
        Ok(ColRing {
            data: a.f32(cap.checked_mul(ch).ok_or(ArenaError::Overflow)?)?,
            cap,
            ch,
            n: 0,
        })
    }

    /// Appends one column of at most `ch` floats (the oldest falls out).
    fn push(&mut self, col: &[f32]) -> Result<(), Error> {
        if col.len() > self.ch {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: col.len(),
                expected: self.ch,
            });
        }
        if self.cap > 0 {
            let s = (self.n % self.cap) * self.ch;
            let len = self.data.len();
            let slot = self.data.get_mut(s..s + col.len()).ok_or(Error::Length {
                buffer: Buffer::Features,
                len,
                expected: s + col.len(),
            })?;
            slot.copy_from_slice(col);
        }
        self.n += 1;
        Ok(())
    }

    /// Column `i` (ch floats).
    fn col(&self, i: usize) -> Result<&[f32], Error> {
        let oldest = self.n.saturating_sub(self.cap);
        if i < oldest || i >= self.n {
            return Err(evicted(i, oldest, self.n));
        }
        let s = (i % self.cap) * self.ch;
        self.data
            .get(s..s + self.ch)
            .ok_or(evicted(i, oldest, self.n))
    }
}

// ---------------------------------------------------------------------------
// Weights of a unit
// ---------------------------------------------------------------------------

/// The weights of one unit.
#[derive(Clone, Copy)]
enum UnitW<'r, 'a> {
    Conv(&'r ConvW<'a>),
    Res(&'r ResBlockW<'a>),
    ConvT(&'r ConvTW<'a>),
}

impl UnitW<'_, '_> {
    fn c_out(&self) -> usize {
        match self {
            UnitW::Conv(c) => c.c_out,
            UnitW::Res(r) => r.conv_1x1.c_out,
            UnitW::ConvT(t) => t.c_out,
        }
    }
}

/// A conv's shapes match its geometry and channels.
fn conv_fits(c: &ConvW<'_>, g: ConvGeom, c_in: usize, c_out: usize) -> bool {
    c.geom == g
        && c.c_in == c_in
        && c.c_out == c_out
        && mat_fits(&c.w, c_out, c_in * g.kernel)
        && c.b.len() == c_out
}

fn mat_fits(m: &Matrix<'_>, rows: usize, cols: usize) -> bool {
    m.rows() == rows && m.cols() == cols
}

impl<'r, 'a> UnitW<'r, 'a> {
    /// True if these weights implement `u` (channels of the last decoder
    /// unit: at most `u.c_out`).
    fn fits(&self, u: &Unit, inner: usize, last: bool) -> bool {
        let c_out_ok = |c: usize| {
            if last {
                c <= u.c_out && c > 0
            } else {
                c == u.c_out
            }
        };
        let geom = ConvGeom {
            kernel: u.kernel,
            stride: u.stride,
            pad: u.pad,
            dilation: u.dilation,
        };
        match (self, u.kind) {
            (UnitW::Conv(c), UnitKind::Conv) => {
                c_out_ok(c.c_out) && conv_fits(c, geom, u.c_in, c.c_out)
            }
            (UnitW::Res(r), UnitKind::Res) => {
                let g1 = ConvGeom {
                    kernel: 1,
                    stride: 1,
                    pad: 0,
                    dilation: 1,
                };
                conv_fits(&r.conv_dil, geom, u.c_in, inner)
                    && conv_fits(&r.conv_1x1, g1, inner, u.c_out)
            }
            (UnitW::ConvT(t), UnitKind::ConvT) => {
                c_out_ok(t.c_out)
                    && t.c_in == u.c_in
                    && (t.kernel, t.stride, t.pad) == (u.kernel, u.stride, u.pad)
                    && t.w.c_in() == u.c_in
                    && t.w.z_cols() == t.c_out * t.kernel
                    && t.b.len() == t.c_out
            }
            _ => false,
        }
    }

    /// Runs the unit for every job at once (one GEMM per kernel tile for
    /// all of them): job `j`'s outputs `[a, a + n_out)` from its `n_in`
    /// input columns gathered from `g0`, the jobs' inputs one after another
    /// in `x` (modified: ReLU in place for a residual block), their outputs
    /// likewise in `y`. `h`, `r`: residual scratch; `tile`: the kernel tile
    /// (im2col for a conv, the transposed conv's otherwise).
    #[allow(clippy::too_many_arguments)]
    fn run(
        &self,
        u: &Unit,
        jobs: &[Job],
        x: &mut [f32],
        y: &mut [f32],
        h: &mut [f32],
        r: &mut [f32],
        tile: &mut [f32],
    ) -> Result<(), Error> {
        let mut segs: Vec<ConvSeg, MAX_STACKS> = Vec::new();
        for j in jobs {
            let pad = u.local_pad(j.a, j.g0).ok_or(Error::Length {
                buffer: Buffer::Features,
                len: j.g0,
                expected: j.a,
            })?;
            segs.push(ConvSeg {
                t_in: j.n_in,
                t_out: j.n_out,
                pad,
            })
            .map_err(|_| Error::State)?;
        }
        let (n_in, n_out) = (
            jobs.iter().map(|j| j.n_in).sum::<usize>(),
            jobs.iter().map(|j| j.n_out).sum::<usize>(),
        );
        let oc = self.c_out();
        if x.len() != n_in * u.c_in || y.len() != n_out * oc {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: y.len(),
                expected: n_out * oc,
            });
        }
        let geom = ConvGeom {
            kernel: u.kernel,
            stride: u.stride,
            pad: 0,
            dilation: u.dilation,
        };
        let need = match self {
            UnitW::ConvT(t) => convt_z_len(t.c_out, t.kernel),
            _ => conv1d_col_len(u.c_in, u.kernel),
        };
        if need > tile.len() {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: tile.len(),
                expected: need,
            });
        }
        match self {
            UnitW::Conv(c) => conv1d_segs(x, c.c_in, &c.w, c.b, geom, &segs, y, tile),
            UnitW::ConvT(t) => {
                conv_transpose1d_segs(x, &t.w, t.b, t.kernel, t.stride, &segs, y, tile)
            }
            UnitW::Res(b) => {
                let (w, inner) = (b.conv_dil.c_in, b.conv_dil.c_out);
                // Identity: output a + t of a job is its gathered row a + t - g0.
                let (mut xo, mut yo) = (0, 0);
                for j in jobs {
                    let id = (xo + j.a.saturating_sub(j.g0)) * w;
                    let src = x.get(id..id + j.n_out * w).ok_or(Error::Length {
                        buffer: Buffer::Features,
                        len: x.len(),
                        expected: id + j.n_out * w,
                    })?;
                    y[yo * w..(yo + j.n_out) * w].copy_from_slice(src);
                    xo += j.n_in;
                    yo += j.n_out;
                }
                relu_inplace(x);
                let h = first(h, n_out * inner)?;
                conv1d_segs(x, w, &b.conv_dil.w, b.conv_dil.b, geom, &segs, h, tile);
                relu_inplace(h);
                let r = first(r, n_out * w)?;
                let g1 = ConvGeom {
                    kernel: 1,
                    stride: 1,
                    pad: 0,
                    dilation: 1,
                };
                conv1d(h, inner, &b.conv_1x1.w, b.conv_1x1.b, g1, r, tile);
                for (o, v) in y.iter_mut().zip(r.iter()) {
                    *o += v;
                }
            }
        }
        Ok(())
    }
}

/// One stack's share of a unit computed for several stacks at once.
#[derive(Clone, Copy, Debug)]
struct Job {
    /// First output column.
    a: usize,
    /// First gathered input column.
    g0: usize,
    n_in: usize,
    n_out: usize,
}

/// The first `n` floats of `b`, or a length error.
fn first(b: &mut [f32], n: usize) -> Result<&mut [f32], Error> {
    let len = b.len();
    b.get_mut(..n).ok_or(Error::Length {
        buffer: Buffer::Features,
        len,
        expected: n,
    })
}

// ---------------------------------------------------------------------------
// The streaming stack
// ---------------------------------------------------------------------------

/// State of one streaming stack: a ring of settled input columns per unit
/// and a ring of settled outputs, carved from an arena.
pub struct StreamStack<'s> {
    plan: StackPlan,
    /// Ring `u`: (plan.ring[u], c_in of unit u) settled inputs of unit `u`.
    rings: Vec<ColRing<'s>, MAX_UNITS>,
    /// (plan.out_ring, c_out of the last unit) settled outputs.
    out: ColRing<'s>,
    counts: Counts,
    pushed: usize,
    /// Output channels of the weights pushed with (0 before the first push).
    out_ch: usize,
    /// Scratch this stack's pushes need (checked before a push mutates).
    need: ScratchNeed,
    /// A push failed half-way: every call errors until `reset`.
    broken: bool,
}

impl<'s> StreamStack<'s> {
    /// A stack of `kind` for `cfg`, serving requests `lag` pushes behind the
    /// newest (encoder: feature `q` after push `q + lag + 1`; decoder:
    /// frames `[hop q, hop q + hop)` after push `q + lag + 1`). Any lag
    /// works; requests with a smaller lag also work (the shared scratch
    /// covers `0..=future_max`), older ones than `lag` may error.
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &VqConfig,
        kind: StackKind,
        lag: usize,
    ) -> Result<Self, ArenaError> {
        let plan = StackPlan::new(cfg, kind, lag).ok_or(ArenaError::Overflow)?;
        let mut rings = Vec::new();
        for (u, unit) in plan.geometry.units().iter().enumerate() {
            let ring = ColRing::carve(a, plan.ring[u], unit.c_in)?;
            rings.push(ring).map_err(|_| ArenaError::Overflow)?;
        }
        let last = plan.geometry.units()[plan.geometry.n_units - 1];
        let out = ColRing::carve(a, plan.out_ring, last.c_out)?;
        let need = plan.scratch_need();
        Ok(StreamStack {
            plan,
            rings,
            out,
            counts: Counts::ZERO,
            pushed: 0,
            out_ch: 0,
            need,
            broken: false,
        })
    }

    /// Back to zero columns pushed (no allocation).
    pub fn reset(&mut self) {
        for r in self.rings.iter_mut() {
            r.n = 0;
        }
        self.out.n = 0;
        self.counts = Counts::ZERO;
        self.pushed = 0;
        self.out_ch = 0;
        self.broken = false;
    }

    /// Pushes so far.
    pub fn pushed(&self) -> usize {
        self.pushed
    }

    /// Output columns of the stack on the prefix pushed so far.
    pub fn len(&self) -> usize {
        self.counts.n_out[self.plan.geometry.n_units - 1]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Output columns that no further push can change.
    pub fn settled(&self) -> usize {
        self.counts.set[self.plan.geometry.n_units - 1]
    }

    /// The sizes this stack was carved with.
    pub fn plan(&self) -> &StackPlan {
        &self.plan
    }

    fn in_buffer(&self) -> Buffer {
        match self.plan.geometry.kind {
            StackKind::Encoder => Buffer::Pose,
            StackKind::Decoder => Buffer::Features,
        }
    }

    fn out_buffer(&self) -> Buffer {
        match self.plan.geometry.kind {
            StackKind::Encoder => Buffer::Features,
            StackKind::Decoder => Buffer::Output,
        }
    }

    /// The weights of every unit, checked against the geometry.
    fn bind<'r, 'a>(&self, w: StackW<'r, 'a>) -> Result<Vec<UnitW<'r, 'a>, MAX_UNITS>, Error> {
        let mut v: Vec<UnitW<'r, 'a>, MAX_UNITS> = Vec::new();
        let bad = Error::Length {
            buffer: self.out_buffer(),
            len: 0,
            expected: 0,
        };
        match (w, self.plan.geometry.kind) {
            (StackW::Encoder(e), StackKind::Encoder) => {
                for (conv, res) in e.stages.iter() {
                    v.push(UnitW::Conv(conv)).map_err(|_| bad.clone())?;
                    for b in res.iter() {
                        v.push(UnitW::Res(b)).map_err(|_| bad.clone())?;
                    }
                }
                v.push(UnitW::Conv(&e.out)).map_err(|_| bad.clone())?;
            }
            (StackW::Decoder(d), StackKind::Decoder) => {
                v.push(UnitW::Conv(&d.input)).map_err(|_| bad.clone())?;
                for (res, up) in d.stages.iter() {
                    for b in res.iter() {
                        v.push(UnitW::Res(b)).map_err(|_| bad.clone())?;
                    }
                    v.push(UnitW::ConvT(up)).map_err(|_| bad.clone())?;
                }
                v.push(UnitW::Conv(&d.out)).map_err(|_| bad.clone())?;
            }
            _ => return Err(bad),
        }
        let g = &self.plan.geometry;
        if v.len() != g.n_units {
            return Err(Error::Length {
                buffer: self.out_buffer(),
                len: v.len(),
                expected: g.n_units,
            });
        }
        for (u, (uw, unit)) in v.iter().zip(g.units()).enumerate() {
            if !uw.fits(unit, g.inner, u + 1 == g.n_units) {
                return Err(Error::Length {
                    buffer: self.out_buffer(),
                    len: uw.c_out(),
                    expected: unit.c_out,
                });
            }
        }
        Ok(v)
    }

    /// Appends one push of input columns: encoder `cols` = (hop,
    /// in_channels) frames; decoder (1, emb_width) one dequantised code.
    /// On an error before any state changed the stack is unchanged; an
    /// error half-way (impossible with the planned sizes) leaves it broken
    /// until [`StreamStack::reset`].
    pub fn push(
        &mut self,
        w: StackW<'_, '_>,
        cols: &[f32],
        s: &mut StreamScratch<'_>,
    ) -> Result<(), Error> {
        Self::push_many(&mut [self], w, &[cols], s)
    }

    /// [`StreamStack::push`] of `cols[i]` into `stacks[i]` for several
    /// stacks of one geometry (the same stack of several sessions), every
    /// unit computed for all of them at once: one read of its weights per
    /// kernel tile instead of one per stack. Each stack ends bit for bit as
    /// after its own push (row-independent kernels). `s` must hold the
    /// stacks' needs together ([`StreamScratch::carve`] for `n` stacks).
    pub fn push_many(
        stacks: &mut [&mut StreamStack<'s>],
        w: StackW<'_, '_>,
        cols: &[&[f32]],
        s: &mut StreamScratch<'_>,
    ) -> Result<(), Error> {
        let Some((units, oc)) = Self::check_push(stacks, w, cols, s)? else {
            return Ok(());
        };
        for st in stacks.iter_mut() {
            st.broken = true;
        }
        Self::settle(stacks, &units, cols, None, s)?;
        Self::pushed_one(stacks, oc);
        Ok(())
    }

    /// [`StreamStack::push`] then [`StreamStack::output`] of `[t, t + n)`,
    /// each unit's weights read once ([`StreamStack::push_output_many`]).
    pub fn push_output(
        &mut self,
        w: StackW<'_, '_>,
        cols: &[f32],
        t: usize,
        n: usize,
        s: &mut StreamScratch<'_>,
        out: &mut [f32],
    ) -> Result<(), Error> {
        Self::push_output_many(&mut [self], w, &[cols], &[t], n, s, &mut [out])
    }

    /// [`StreamStack::push_many`], then [`StreamStack::output_many`] of
    /// columns `[ts[i], ts[i] + n)` of `stacks[i]` on the prefix after the
    /// push into `outs[i]`, with each unit's tail computed right before
    /// its newly settled columns, while the unit's weights are in cache
    /// (the two calls read every unit's weights twice). Bit for bit the two
    /// calls; everything both check is checked before anything changes.
    pub fn push_output_many(
        stacks: &mut [&mut StreamStack<'s>],
        w: StackW<'_, '_>,
        cols: &[&[f32]],
        ts: &[usize],
        n: usize,
        s: &mut StreamScratch<'_>,
        outs: &mut [&mut [f32]],
    ) -> Result<(), Error> {
        let Some((units, oc)) = Self::check_push(stacks, w, cols, s)? else {
            return Ok(());
        };
        if ts.len() != stacks.len() || outs.len() != stacks.len() {
            return Err(Error::Length {
                buffer: stacks[0].out_buffer(),
                len: ts.len().min(outs.len()),
                expected: stacks.len(),
            });
        }
        let g = &stacks[0].plan.geometry;
        let last = g.n_units - 1;
        let expected = n.checked_mul(oc).ok_or(Error::Length {
            buffer: stacks[0].out_buffer(),
            len: n,
            expected: usize::MAX,
        })?;
        // Per stack: the unsettled columns [a, end) to compute after the push.
        let mut want: Vec<Option<(usize, usize)>, MAX_STACKS> = Vec::new();
        for ((st, &t), out) in stacks.iter().zip(ts).zip(outs.iter()) {
            let mut after = st.counts;
            after.advance(g);
            let (len, set) = (after.n_out[last], after.set[last]);
            let end = t.saturating_add(n);
            if out.len() != expected {
                return Err(Error::Length {
                    buffer: st.out_buffer(),
                    len: out.len(),
                    expected,
                });
            }
            if end > len {
                return Err(Error::Length {
                    buffer: st.out_buffer(),
                    len: end,
                    expected: len,
                });
            }
            // Settled columns come from the output ring after the push.
            let oldest = set.saturating_sub(st.out.cap);
            if t < set && t < oldest {
                return Err(evicted(t, oldest, set));
            }
            want.push((end > set).then(|| (t.max(set), end)))
                .map_err(|_| Error::State)?;
        }
        for st in stacks.iter_mut() {
            st.broken = true;
        }
        let (tail, at) = Self::settle(stacks, &units, cols, Some(&want), s)?;
        for (i, (st, out)) in stacks.iter().zip(outs.iter_mut()).enumerate() {
            let (t, set) = (ts[i], st.settled());
            for (j, o) in (t..(t + n).min(set)).zip(out.chunks_exact_mut(oc)) {
                o.copy_from_slice(&st.out.col(j)?[..oc]);
            }
            if let Some((a, end)) = want[i] {
                let src = tail
                    .get(at[i] * oc..(at[i] + end - a) * oc)
                    .ok_or(Error::State)?;
                out[(a - t) * oc..].copy_from_slice(src);
            }
        }
        Self::pushed_one(stacks, oc);
        Ok(())
    }

    /// What a push checks before it changes anything; the bound weights
    /// and the last unit's output channels (`None`: no stacks).
    #[allow(clippy::type_complexity)]
    fn check_push<'r, 'a>(
        stacks: &[&mut StreamStack<'s>],
        w: StackW<'r, 'a>,
        cols: &[&[f32]],
        s: &StreamScratch<'_>,
    ) -> Result<Option<(Vec<UnitW<'r, 'a>, MAX_UNITS>, usize)>, Error> {
        let units = Self::check_many(stacks.iter().map(|st| &**st), w, s)?;
        let Some(first) = stacks.first() else {
            return Ok(None);
        };
        if cols.len() != stacks.len() {
            return Err(Error::Length {
                buffer: first.in_buffer(),
                len: cols.len(),
                expected: stacks.len(),
            });
        }
        let g = &first.plan.geometry;
        let expected = g.in_per_push * g.units[0].c_in;
        if let Some(c) = cols.iter().find(|c| c.len() != expected) {
            return Err(Error::Length {
                buffer: first.in_buffer(),
                len: c.len(),
                expected,
            });
        }
        let oc = units[g.n_units - 1].c_out();
        Ok(Some((units, oc)))
    }

    /// Every stack has taken one more push (no longer broken).
    fn pushed_one(stacks: &mut [&mut StreamStack<'s>], oc: usize) {
        for st in stacks.iter_mut() {
            st.out_ch = oc;
            st.pushed += 1;
            st.broken = false;
        }
    }

    /// The checks every `*_many` call makes before it changes anything:
    /// at most [`MAX_STACKS`] stacks, none broken, one geometry, weights
    /// that fit it (and the output channels of earlier pushes), scratch for
    /// all of them together. Returns the bound weights.
    fn check_many<'r, 'a, 'x>(
        stacks: impl Iterator<Item = &'x StreamStack<'s>> + Clone,
        w: StackW<'r, 'a>,
        s: &StreamScratch<'_>,
    ) -> Result<Vec<UnitW<'r, 'a>, MAX_UNITS>, Error>
    where
        's: 'x,
    {
        let Some(first) = stacks.clone().next() else {
            return Ok(Vec::new());
        };
        let units = first.bind(w)?;
        let oc = units[first.plan.geometry.n_units - 1].c_out();
        let mut need = ScratchNeed::default();
        for (i, st) in stacks.enumerate() {
            if st.broken || i >= MAX_STACKS || st.plan.geometry != first.plan.geometry {
                return Err(Error::State);
            }
            if st.out_ch != 0 && oc != st.out_ch {
                return Err(Error::Length {
                    buffer: st.out_buffer(),
                    len: oc,
                    expected: st.out_ch,
                });
            }
            need = need.plus(st.need);
        }
        if !need.fits(s) {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: s.g.len(),
                expected: need.g,
            });
        }
        Ok(units)
    }

    /// The push proper: new input columns into ring 0 of every stack, then
    /// unit after unit every stack's newly settled outputs (one computation
    /// for all stacks) into the next ring. With `want` (per stack, the
    /// unsettled output columns `[a, b)` of the last unit wanted after the
    /// push, as [`StreamStack::output_many`] computes them), each unit's
    /// tail is computed right before its settled outputs, while its weights
    /// are in cache; the tails are returned as by [`StreamStack::tails`].
    #[allow(clippy::type_complexity)]
    fn settle<'x>(
        stacks: &mut [&mut StreamStack<'s>],
        units: &[UnitW<'_, '_>],
        cols: &[&[f32]],
        want: Option<&[Option<(usize, usize)>]>,
        s: &'x mut StreamScratch<'_>,
    ) -> Result<(&'x [f32], [usize; MAX_STACKS]), Error> {
        let g = stacks[0].plan.geometry.clone();
        let mut counts: Vec<Counts, MAX_STACKS> = Vec::new();
        let mut new: Vec<[Span; MAX_UNITS], MAX_STACKS> = Vec::new();
        for (st, c) in stacks.iter_mut().zip(cols) {
            let mut k = st.counts;
            new.push(k.advance(&g)).map_err(|_| Error::State)?;
            counts.push(k).map_err(|_| Error::State)?;
            for col in c.chunks_exact(st.rings[0].ch) {
                st.rings[0].push(col)?;
            }
        }
        let need = match want {
            Some(w) => Self::cones(&g, &counts, w)?,
            None => Vec::new(),
        };
        let u0 = Self::first_tail_unit(&g, &need);
        let StreamScratch {
            g: gs,
            h,
            r,
            ta,
            tb,
            tile,
        } = s;
        // prev: tails of the unit below (stack i's from row prev_at[i]);
        // cur: this unit's; settled outputs go through `prev` once it is dead.
        let (mut prev, mut cur): (&'x mut [f32], &'x mut [f32]) = (&mut ta[..], &mut tb[..]);
        let (mut prev_at, mut cur_at) = ([0usize; MAX_STACKS], [0usize; MAX_STACKS]);
        for (u, uw) in units.iter().enumerate() {
            let tail = u0.is_some_and(|u0| u >= u0);
            if tail {
                let w = Work { g: gs, h, r, tile };
                Self::tail_unit(
                    stacks,
                    &counts,
                    &need,
                    u,
                    uw,
                    prev,
                    &prev_at,
                    cur,
                    &mut cur_at,
                    w,
                )?;
            }
            let w = Work { g: gs, h, r, tile };
            Self::settle_unit(stacks, &counts, &new, u, uw, prev, w)?;
            if tail {
                core::mem::swap(&mut prev, &mut cur);
                core::mem::swap(&mut prev_at, &mut cur_at);
            }
        }
        for (st, c) in stacks.iter_mut().zip(counts) {
            st.counts = c;
        }
        Ok((prev, prev_at))
    }

    /// Unit `u`'s newly settled outputs `new[i][u]` of every stack, computed
    /// together into `y` (scratch) and pushed into the next ring (the
    /// output ring for the last unit).
    #[allow(clippy::too_many_arguments)]
    fn settle_unit(
        stacks: &mut [&mut StreamStack<'s>],
        counts: &[Counts],
        new: &[[Span; MAX_UNITS]],
        u: usize,
        uw: &UnitW<'_, '_>,
        y: &mut [f32],
        w: Work<'_>,
    ) -> Result<(), Error> {
        let g = &stacks[0].plan.geometry;
        let unit = g.units[u];
        let last = g.n_units - 1;
        // (stack, its job); the jobs' inputs gathered one after another into w.g.
        let mut jobs: Vec<(usize, Job), MAX_STACKS> = Vec::new();
        let (mut xo, mut yo) = (0, 0);
        for (i, st) in stacks.iter().enumerate() {
            let Span { lo, hi } = new[i][u];
            if lo >= hi {
                continue;
            }
            let (g0, g1) = unit.gather_span(lo, hi, counts[i].n_in(u));
            let ring = &st.rings[u];
            if ring.n != counts[i].set_in(u) {
                return Err(evicted(g1, g0, ring.n));
            }
            let x = cols_at(w.g, xo, g1 - g0, unit.c_in)?;
            for (c, xc) in (g0..g1).zip(x.chunks_exact_mut(unit.c_in)) {
                xc.copy_from_slice(ring.col(c)?);
            }
            jobs.push((
                i,
                Job {
                    a: lo,
                    g0,
                    n_in: g1 - g0,
                    n_out: hi - lo,
                },
            ))
            .map_err(|_| Error::State)?;
            xo += g1 - g0;
            yo += hi - lo;
        }
        if jobs.is_empty() {
            return Ok(());
        }
        let oc = uw.c_out();
        let js: Vec<Job, MAX_STACKS> = jobs.iter().map(|&(_, j)| j).collect();
        let y = first(y, yo * oc)?;
        uw.run(&unit, &js, first(w.g, xo * unit.c_in)?, y, w.h, w.r, w.tile)?;
        let mut rows = y.chunks_exact(oc);
        for &(i, j) in jobs.iter() {
            let st = &mut *stacks[i];
            let next = if u == last {
                &mut st.out
            } else {
                &mut st.rings[u + 1]
            };
            for c in rows.by_ref().take(j.n_out) {
                next.push(c)?;
            }
        }
        Ok(())
    }

    /// Output columns `[t, t + n)` of the stack on the prefix pushed so far
    /// into `out` (n, C): encoder features (C = emb_width), decoder frames
    /// (C = the decoder's output channels). Settled columns come from the
    /// output ring (bit-identical to the full conv); unsettled ones are
    /// computed now from the tail cone. Errors if `t + n` exceeds the
    /// prefix's output, or a column is older than the output ring holds.
    pub fn output(
        &self,
        w: StackW<'_, '_>,
        t: usize,
        n: usize,
        s: &mut StreamScratch<'_>,
        out: &mut [f32],
    ) -> Result<(), Error> {
        Self::output_many(&[self], w, &[t], n, s, &mut [out])
    }

    /// [`StreamStack::output`] of columns `[ts[i], ts[i] + n)` of
    /// `stacks[i]` into `outs[i]` for several stacks of one geometry, the
    /// tails of all of them computed together (one read of each unit's
    /// weights); bit for bit what each stack's own call gives.
    pub fn output_many(
        stacks: &[&StreamStack<'s>],
        w: StackW<'_, '_>,
        ts: &[usize],
        n: usize,
        s: &mut StreamScratch<'_>,
        outs: &mut [&mut [f32]],
    ) -> Result<(), Error> {
        let units = Self::check_many(stacks.iter().copied(), w, s)?;
        let Some(first) = stacks.first() else {
            return Ok(());
        };
        if ts.len() != stacks.len() || outs.len() != stacks.len() {
            return Err(Error::Length {
                buffer: first.out_buffer(),
                len: ts.len().min(outs.len()),
                expected: stacks.len(),
            });
        }
        let oc = units[first.plan.geometry.n_units - 1].c_out();
        let expected = n.checked_mul(oc).ok_or(Error::Length {
            buffer: first.out_buffer(),
            len: n,
            expected: usize::MAX,
        })?;
        // Per stack: the unsettled columns [a, end) still to compute, if any.
        let mut want: Vec<Option<(usize, usize)>, MAX_STACKS> = Vec::new();
        for ((st, &t), out) in stacks.iter().zip(ts).zip(outs.iter()) {
            if out.len() != expected {
                return Err(Error::Length {
                    buffer: st.out_buffer(),
                    len: out.len(),
                    expected,
                });
            }
            let end = t.saturating_add(n);
            if end > st.len() {
                return Err(Error::Length {
                    buffer: st.out_buffer(),
                    len: end,
                    expected: st.len(),
                });
            }
            let set = st.settled();
            want.push((end > set).then(|| (t.max(set), end)))
                .map_err(|_| Error::State)?;
        }
        for ((st, &t), out) in stacks.iter().zip(ts).zip(outs.iter_mut()) {
            let set = st.settled();
            for (j, o) in (t..(t + n).min(set)).zip(out.chunks_exact_mut(oc)) {
                o.copy_from_slice(&st.out.col(j)?[..oc]);
            }
        }
        if want.iter().any(Option::is_some) {
            let (tail, at) = Self::tails(stacks, &units, &want, s)?;
            for (i, out) in outs.iter_mut().enumerate() {
                if let Some((a, end)) = want[i] {
                    let src = tail
                        .get(at[i] * oc..(at[i] + end - a) * oc)
                        .ok_or(Error::State)?;
                    out[(a - ts[i]) * oc..].copy_from_slice(src);
                }
            }
        }
        Ok(())
    }

    /// Computes the unsettled outputs `want[i] = [a, b)` of the last unit
    /// of each stack through its tail cone, all stacks unit by unit
    /// together; returns them in a scratch buffer: stack `i`'s `(b - a,
    /// c_out)` rows from row `at[i]`.
    #[allow(clippy::type_complexity)]
    fn tails<'x>(
        stacks: &[&StreamStack<'s>],
        units: &[UnitW<'_, '_>],
        want: &[Option<(usize, usize)>],
        s: &'x mut StreamScratch<'_>,
    ) -> Result<(&'x [f32], [usize; MAX_STACKS]), Error> {
        let g = &stacks[0].plan.geometry;
        let mut counts: Vec<Counts, MAX_STACKS> = Vec::new();
        for st in stacks.iter() {
            counts.push(st.counts).map_err(|_| Error::State)?;
        }
        let need = Self::cones(g, &counts, want)?;
        let u0 = Self::first_tail_unit(g, &need).unwrap_or(g.n_units - 1);
        let StreamScratch {
            g: gs,
            h,
            r,
            ta,
            tb,
            tile,
        } = s;
        let (mut prev, mut cur): (&'x mut [f32], &'x mut [f32]) = (&mut ta[..], &mut tb[..]);
        let (mut prev_at, mut cur_at) = ([0usize; MAX_STACKS], [0usize; MAX_STACKS]);
        for (u, uw) in units.iter().enumerate().skip(u0) {
            let w = Work { g: gs, h, r, tile };
            Self::tail_unit(
                stacks,
                &counts,
                &need,
                u,
                uw,
                prev,
                &prev_at,
                cur,
                &mut cur_at,
                w,
            )?;
            core::mem::swap(&mut prev, &mut cur);
            core::mem::swap(&mut prev_at, &mut cur_at);
        }
        Ok((prev, prev_at))
    }

    /// The tail cone of every stack: per stack and unit, the unsettled
    /// outputs needed for `want[i]` (empty spans for `None`).
    fn cones(
        g: &Geometry,
        counts: &[Counts],
        want: &[Option<(usize, usize)>],
    ) -> Result<Vec<[Span; MAX_UNITS], MAX_STACKS>, Error> {
        let mut need: Vec<[Span; MAX_UNITS], MAX_STACKS> = Vec::new();
        for (c, w) in counts.iter().zip(want) {
            let cone = match *w {
                Some((a, b)) => c.cone(g, a, b),
                None => [Span::default(); MAX_UNITS],
            };
            need.push(cone).map_err(|_| Error::State)?;
        }
        Ok(need)
    }

    /// The first unit with a tail to compute in any stack's cone.
    fn first_tail_unit(g: &Geometry, need: &[[Span; MAX_UNITS]]) -> Option<usize> {
        (0..g.n_units).find(|&u| need.iter().any(|nd| !nd[u].is_empty()))
    }

    /// Unit `u`'s unsettled outputs `need[i][u]` of every stack into `cur`
    /// (stack i's rows from `cur_at[i]`): settled inputs from the unit's
    /// ring, unsettled ones from `prev`, the tails of unit `u - 1` (stack
    /// i's from row `prev_at[i]`).
    #[allow(clippy::too_many_arguments)]
    fn tail_unit<S: core::ops::Deref<Target = StreamStack<'s>>>(
        stacks: &[S],
        counts: &[Counts],
        need: &[[Span; MAX_UNITS]],
        u: usize,
        uw: &UnitW<'_, '_>,
        prev: &[f32],
        prev_at: &[usize; MAX_STACKS],
        cur: &mut [f32],
        cur_at: &mut [usize; MAX_STACKS],
        w: Work<'_>,
    ) -> Result<(), Error> {
        let unit = stacks[0].plan.geometry.units[u];
        let mut jobs: Vec<Job, MAX_STACKS> = Vec::new();
        let (mut xo, mut yo) = (0, 0);
        for (i, st) in stacks.iter().enumerate() {
            let Span { lo, hi } = need[i][u];
            if lo >= hi {
                continue;
            }
            let c = &counts[i];
            let (g0, g1) = unit.gather_span(lo, hi, c.n_in(u));
            let (set_in, ring) = (c.set_in(u), &st.rings[u]);
            let x = cols_at(w.g, xo, g1 - g0, unit.c_in)?;
            for (col, xc) in (g0..g1).zip(x.chunks_exact_mut(unit.c_in)) {
                if col < set_in {
                    xc.copy_from_slice(ring.col(col)?);
                } else {
                    // Unsettled input: tail of unit u-1, which covers [set_in, g1).
                    let below = if u > 0 {
                        need[i][u - 1]
                    } else {
                        Span::default()
                    };
                    let k = col.checked_sub(below.lo).filter(|_| col < below.hi);
                    let src = k.and_then(|k| {
                        prev.get((prev_at[i] + k) * unit.c_in..(prev_at[i] + k + 1) * unit.c_in)
                    });
                    xc.copy_from_slice(src.ok_or(evicted(col, set_in, c.n_in(u)))?);
                }
            }
            jobs.push(Job {
                a: lo,
                g0,
                n_in: g1 - g0,
                n_out: hi - lo,
            })
            .map_err(|_| Error::State)?;
            cur_at[i] = yo;
            xo += g1 - g0;
            yo += hi - lo;
        }
        let oc = uw.c_out();
        let y = first(cur, yo * oc)?;
        uw.run(
            &unit,
            &jobs,
            first(w.g, xo * unit.c_in)?,
            y,
            w.h,
            w.r,
            w.tile,
        )
    }
}

/// The scratch a unit's computation works in (gathered inputs, residual
/// inner and 1x1 rows, the kernel tile), borrowed from a [`StreamScratch`].
struct Work<'a> {
    g: &'a mut [f32],
    h: &'a mut [f32],
    r: &'a mut [f32],
    tile: &'a mut [f32],
}

/// Columns `[at, at + n)` of `c` floats each of `b`, or a length error.
fn cols_at(b: &mut [f32], at: usize, n: usize, c: usize) -> Result<&mut [f32], Error> {
    let len = b.len();
    b.get_mut(at * c..(at + n) * c).ok_or(Error::Length {
        buffer: Buffer::Features,
        len,
        expected: (at + n) * c,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::duolando::presets::duolando_published;

    /// Geometries beyond the fixtures': stride 4, three stages, deep resnets.
    fn configs() -> [VqConfig; 4] {
        let p = duolando_published().parts[0];
        [
            p,
            VqConfig { depth: 2, ..p },
            VqConfig {
                stride_t: 4,
                down_t: 1,
                ..p
            },
            VqConfig {
                down_t: 3,
                depth: 4,
                dilation_growth_rate: 2,
                ..p
            },
        ]
    }

    /// The simulation is long enough: twice as many pushes change no size
    /// and no future_max.
    #[test]
    fn simulation_reaches_the_steady_state() {
        for cfg in configs() {
            for kind in [StackKind::Encoder, StackKind::Decoder] {
                let g = Geometry::new(&cfg, kind).unwrap();
                let f = future_max_of(&g);
                let (mut c, m, last) = (Counts::ZERO, g.out_per_push, g.n_units - 1);
                let mut f2 = 0;
                for p in 1..=4 * g.sim_pushes(0) {
                    c.advance(&g);
                    f2 = f2.max(p.saturating_sub(c.set[last] / m));
                }
                assert_eq!(f, f2, "{kind:?} {cfg:?}");
                for lag in 0..=f + 1 {
                    let n = g.sim_pushes(lag);
                    let a = StackPlan::simulate_for(g.clone(), lag, lag, n);
                    let b = StackPlan::simulate_for(g.clone(), lag, lag, 3 * n);
                    assert_eq!(a, b, "{kind:?} lag {lag} {cfg:?}");
                }
                let a = StackPlan::simulate_for(g.clone(), 0, f, g.sim_pushes(f));
                let b = StackPlan::simulate_for(g.clone(), 0, f, 3 * g.sim_pushes(f));
                assert_eq!(a.scratch_need(), b.scratch_need());
            }
        }
    }

    /// Above future_max the output ring grows by one token per extra lag,
    /// exactly what a simulation at that lag measures.
    #[test]
    fn out_ring_above_future_max() {
        for cfg in configs() {
            for kind in [StackKind::Encoder, StackKind::Decoder] {
                let g = Geometry::new(&cfg, kind).unwrap();
                let f = future_max_of(&g);
                for lag in [f, f + 1, f + 5] {
                    let sim = StackPlan::simulate(g.clone(), lag, lag);
                    let plan = StackPlan::new(&cfg, kind, lag).unwrap();
                    assert_eq!(sim.out_ring, plan.out_ring, "{kind:?} lag {lag}");
                    assert_eq!(sim.ring, plan.ring);
                }
            }
        }
    }

    /// Configs outside the engine's limits: no plan, an arena error, no panic.
    #[test]
    fn invalid_configs_are_refused() {
        let p = duolando_published().parts[0];
        let bad = [
            VqConfig { depth: 0, ..p },
            VqConfig { stride_t: 3, ..p },
            VqConfig {
                width: u32::MAX,
                ..p
            },
            VqConfig {
                dilation_growth_rate: u32::MAX,
                ..p
            },
            VqConfig { down_t: 40, ..p },
            VqConfig { m_conv_den: 0, ..p },
        ];
        for cfg in bad {
            for kind in [StackKind::Encoder, StackKind::Decoder] {
                assert_eq!(future_max(&cfg, kind), 0);
                assert!(StackPlan::new(&cfg, kind, 3).is_none());
                let mut pl = crate::arena::Planner::new();
                assert!(StreamStack::carve(&mut pl, &cfg, kind, 3).is_err());
            }
        }
        let mut pl = crate::arena::Planner::new();
        assert!(StreamStack::carve(&mut pl, &p, StackKind::Decoder, usize::MAX).is_err());
    }

    /// Index arithmetic of the units against brute force over the kernel taps.
    #[test]
    fn unit_reads_match_brute_force() {
        let units = [
            Unit::conv(4, 2, 1, 1, 1, 1),
            Unit::conv(8, 4, 2, 1, 1, 1),
            Unit::res(9, 1),
            Unit::convt(2, 1, 1),
            Unit::convt(4, 1, 1),
        ];
        for u in units {
            for t in 0..40usize {
                let reads: std::vec::Vec<isize> = match u.kind {
                    UnitKind::ConvT => (-10..60)
                        .filter(|&i| {
                            (0..u.kernel as isize)
                                .any(|j| i * u.stride as isize - u.pad as isize + j == t as isize)
                        })
                        .collect(),
                    _ => (0..u.kernel)
                        .map(|j| (t * u.stride + j * u.dilation) as isize - u.pad as isize)
                        .collect(),
                };
                assert_eq!(u.first_in(t), *reads.iter().min().unwrap(), "{u:?} t {t}");
                assert_eq!(u.last_in(t), *reads.iter().max().unwrap(), "{u:?} t {t}");
            }
        }
    }
}
