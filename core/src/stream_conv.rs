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
use crate::config::{ModelConfig, VqConfig};
use crate::error::{Buffer, Error};
use crate::kernels::{conv1d, conv1d_col_len, conv_transpose1d, convt_z_len, relu_inplace, ConvGeom, Matrix};
use crate::limits::{MAX_DEPTH, MAX_DILATION, MAX_DOWNSAMPLE, MAX_DOWN_T, MAX_STRIDE, MAX_WIDTH};
use crate::model::{ConvTW, ConvW, DecoderW, EncoderW, ResBlockW};
use crate::schema::dilation;

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

const EMPTY_UNIT: Unit = Unit { kind: UnitKind::Conv, kernel: 1, stride: 1, pad: 0, dilation: 1, c_in: 0, c_out: 0 };

/// `floor(a / b)` for `b > 0`.
fn div_floor(a: isize, b: isize) -> isize {
    a.div_euclid(b)
}

/// `ceil(a / b)` for `b > 0`.
fn div_ceil(a: isize, b: isize) -> isize {
    -(-a).div_euclid(b)
}

impl Unit {
    fn conv(kernel: usize, stride: usize, pad: usize, dilation: usize, c_in: usize, c_out: usize) -> Unit {
        Unit { kind: UnitKind::Conv, kernel, stride, pad, dilation, c_in, c_out }
    }
    fn res(dil: usize, width: usize) -> Unit {
        Unit { kind: UnitKind::Res, kernel: 3, stride: 1, pad: dil, dilation: dil, c_in: width, c_out: width }
    }
    fn convt(stride: usize, c_in: usize, c_out: usize) -> Unit {
        Unit { kind: UnitKind::ConvT, kernel: 2 * stride, stride, pad: stride / 2, dilation: 1, c_in, c_out }
    }

    /// Output columns of the unit over `n_in` input columns (PyTorch's formulas).
    pub fn out_len(&self, n_in: usize) -> usize {
        let (n, k, s, p, d) = (n_in as isize, self.kernel as isize, self.stride as isize, self.pad as isize, self.dilation as isize);
        let len = match self.kind {
            UnitKind::ConvT if n == 0 => 0,
            UnitKind::ConvT => (n - 1) * s - 2 * p + k,
            _ => div_floor(n + 2 * p - d * (k - 1) - 1, s) + 1,
        };
        len.max(0) as usize
    }

    /// Smallest input index output `t` reads (may be negative: zero padding).
    pub fn first_in(&self, t: usize) -> isize {
        let (t, k, s, p) = (t as isize, self.kernel as isize, self.stride as isize, self.pad as isize);
        match self.kind {
            UnitKind::ConvT => div_ceil(t + p - (k - 1), s),
            _ => t * s - p,
        }
    }

    /// Largest input index output `t` reads (may be past the end: zero padding).
    pub fn last_in(&self, t: usize) -> isize {
        let (t, k, s, p, d) = (t as isize, self.kernel as isize, self.stride as isize, self.pad as isize, self.dilation as isize);
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
        let (a, g0, s, p) = (a as isize, g0 as isize, self.stride as isize, self.pad as isize);
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
        let (s, w, emb) = (cfg.stride_t as usize, cfg.width as usize, cfg.emb_width as usize);
        // The engine's limits (crate::limits), so no index arithmetic can overflow.
        let chans = [cfg.width, cfg.emb_width, cfg.in_channels, cfg.rot_channels, cfg.res_inner()?];
        let max_dil = cfg.dilation_growth_rate.checked_pow(cfg.depth.saturating_sub(1))?;
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
        Some(Geometry { kind, units: arr, n_units: units.len(), in_per_push, out_per_push, inner: cfg.res_inner()? as usize })
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
    const ZERO: Counts = Counts { n_in0: 0, n_out: [0; MAX_UNITS], set: [0; MAX_UNITS] };

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
                need[u - 1] = Span { lo: below_lo as usize, hi: below_hi as usize };
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

/// Floats of each [`StreamScratch`] buffer a plan needs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct ScratchNeed {
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
    /// True if `s` holds at least these floats in every buffer.
    fn fits(&self, s: &StreamScratch<'_>) -> bool {
        s.g.len() >= self.g
            && s.h.len() >= self.h
            && s.r.len() >= self.r
            && s.ta.len() >= self.t
            && s.tb.len() >= self.t
            && s.col.len() >= self.col
            && s.z.len() >= self.z
    }
}

/// Smallest lag (tokens) at which every requested output is settled
/// (`e_max` / `d_max` of docs/STREAMING.md §1): the tiny fixture and the
/// published model 22 for both stacks, `tiny2` 8. 0 for an invalid config.
pub fn future_max(cfg: &VqConfig, kind: StackKind) -> usize {
    Geometry::new(cfg, kind).map(|g| future_max_of(&g)).unwrap_or(0)
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
        let mut p = StackPlan { geometry: g, lag: lag_hi, ring: z, tail: z, out_ring: 0, batch: z, gather: z };
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
/// and every lag `0..=future_max`); carve once per session.
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
    /// im2col tile of `conv1d`.
    col: &'s mut [f32],
    /// Tile of `conv_transpose1d`.
    z: &'s mut [f32],
}

impl<'s> StreamScratch<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, cfg: &ModelConfig) -> Result<Self, ArenaError> {
        let mut need = ScratchNeed::default();
        for vq in cfg.parts.iter().chain(core::iter::once(&cfg.transl)) {
            for kind in [StackKind::Encoder, StackKind::Decoder] {
                let g = Geometry::new(vq, kind).ok_or(ArenaError::Overflow)?;
                let fmax = future_max_of(&g);
                need = need.max(StackPlan::simulate(g, 0, fmax).scratch_need());
            }
        }
        Ok(StreamScratch {
            g: a.f32(need.g)?,
            h: a.f32(need.h)?,
            r: a.f32(need.r)?,
            ta: a.f32(need.t)?,
            tb: a.f32(need.t)?,
            col: a.f32(need.col)?,
            z: a.f32(need.z)?,
        })
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
        Ok(ColRing { data: a.f32(cap.checked_mul(ch).ok_or(ArenaError::Overflow)?)?, cap, ch, n: 0 })
    }

    /// Appends one column of at most `ch` floats (the oldest falls out).
    fn push(&mut self, col: &[f32]) -> Result<(), Error> {
        if col.len() > self.ch {
            return Err(Error::Length { buffer: Buffer::Features, len: col.len(), expected: self.ch });
        }
        if self.cap > 0 {
            let s = (self.n % self.cap) * self.ch;
            let len = self.data.len();
            let slot = self.data.get_mut(s..s + col.len()).ok_or(Error::Length { buffer: Buffer::Features, len, expected: s + col.len() })?;
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
        self.data.get(s..s + self.ch).ok_or(evicted(i, oldest, self.n))
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
    c.geom == g && c.c_in == c_in && c.c_out == c_out && mat_fits(&c.w, c_out, c_in * g.kernel) && c.b.len() == c_out
}

fn mat_fits(m: &Matrix<'_>, rows: usize, cols: usize) -> bool {
    m.rows() == rows && m.cols() == cols
}

impl<'r, 'a> UnitW<'r, 'a> {
    /// True if these weights implement `u` (channels of the last decoder
    /// unit: at most `u.c_out`).
    fn fits(&self, u: &Unit, inner: usize, last: bool) -> bool {
        let c_out_ok = |c: usize| if last { c <= u.c_out && c > 0 } else { c == u.c_out };
        let geom = ConvGeom { kernel: u.kernel, stride: u.stride, pad: u.pad, dilation: u.dilation };
        match (self, u.kind) {
            (UnitW::Conv(c), UnitKind::Conv) => c_out_ok(c.c_out) && conv_fits(c, geom, u.c_in, c.c_out),
            (UnitW::Res(r), UnitKind::Res) => {
                let g1 = ConvGeom { kernel: 1, stride: 1, pad: 0, dilation: 1 };
                conv_fits(&r.conv_dil, geom, u.c_in, inner) && conv_fits(&r.conv_1x1, g1, inner, u.c_out)
            }
            (UnitW::ConvT(t), UnitKind::ConvT) => {
                c_out_ok(t.c_out)
                    && t.c_in == u.c_in
                    && (t.kernel, t.stride, t.pad) == (u.kernel, u.stride, u.pad)
                    && mat_fits(&t.w, u.c_in, t.c_out * t.kernel)
                    && t.b.len() == t.c_out
            }
            _ => false,
        }
    }

    /// Outputs `[a, a + y.len() / c_out)` from input columns gathered from
    /// `g0` into `x` ((x.len() / c_in) columns, modified: ReLU in place for a
    /// residual block). `h`, `r`: residual scratch; `col`, `z`: kernel tiles.
    #[allow(clippy::too_many_arguments)]
    fn run(&self, u: &Unit, a: usize, g0: usize, x: &mut [f32], y: &mut [f32], h: &mut [f32], r: &mut [f32], col: &mut [f32], z: &mut [f32]) -> Result<(), Error> {
        let pad = u.local_pad(a, g0).ok_or(Error::Length { buffer: Buffer::Features, len: g0, expected: a })?;
        let geom = ConvGeom { kernel: u.kernel, stride: u.stride, pad, dilation: u.dilation };
        let tile = match self {
            UnitW::ConvT(t) => convt_z_len(t.c_out, t.kernel).saturating_sub(z.len()),
            _ => conv1d_col_len(u.c_in, u.kernel).saturating_sub(col.len()),
        };
        if tile > 0 {
            return Err(Error::Length { buffer: Buffer::Features, len: col.len().min(z.len()), expected: tile });
        }
        match self {
            UnitW::Conv(c) => conv1d(x, c.c_in, &c.w, c.b, geom, y, col),
            UnitW::ConvT(t) => conv_transpose1d(x, &t.w, t.b, t.kernel, t.stride, pad, y, z),
            UnitW::Res(b) => {
                let (w, inner) = (b.conv_dil.c_in, b.conv_dil.c_out);
                let n = y.len() / w;
                // Identity: output a + j is input a + j = gathered row a + j - g0.
                let id = a.saturating_sub(g0) * w;
                let src = x.get(id..id + n * w).ok_or(Error::Length { buffer: Buffer::Features, len: x.len(), expected: id + n * w })?;
                y.copy_from_slice(src);
                relu_inplace(x);
                let h = first(h, n * inner)?;
                conv1d(x, w, &b.conv_dil.w, b.conv_dil.b, geom, h, col);
                relu_inplace(h);
                let r = first(r, n * w)?;
                let g1 = ConvGeom { kernel: 1, stride: 1, pad: 0, dilation: 1 };
                conv1d(h, inner, &b.conv_1x1.w, b.conv_1x1.b, g1, r, col);
                for (o, v) in y.iter_mut().zip(r.iter()) {
                    *o += v;
                }
            }
        }
        Ok(())
    }
}

/// The first `n` floats of `b`, or a length error.
fn first(b: &mut [f32], n: usize) -> Result<&mut [f32], Error> {
    let len = b.len();
    b.get_mut(..n).ok_or(Error::Length { buffer: Buffer::Features, len, expected: n })
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
    pub fn carve<A: Carve<'s>>(a: &mut A, cfg: &VqConfig, kind: StackKind, lag: usize) -> Result<Self, ArenaError> {
        let plan = StackPlan::new(cfg, kind, lag).ok_or(ArenaError::Overflow)?;
        let mut rings = Vec::new();
        for (u, unit) in plan.geometry.units().iter().enumerate() {
            let ring = ColRing::carve(a, plan.ring[u], unit.c_in)?;
            rings.push(ring).map_err(|_| ArenaError::Overflow)?;
        }
        let last = plan.geometry.units()[plan.geometry.n_units - 1];
        let out = ColRing::carve(a, plan.out_ring, last.c_out)?;
        let need = plan.scratch_need();
        Ok(StreamStack { plan, rings, out, counts: Counts::ZERO, pushed: 0, out_ch: 0, need, broken: false })
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
        let bad = Error::Length { buffer: self.out_buffer(), len: 0, expected: 0 };
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
            return Err(Error::Length { buffer: self.out_buffer(), len: v.len(), expected: g.n_units });
        }
        for (u, (uw, unit)) in v.iter().zip(g.units()).enumerate() {
            if !uw.fits(unit, g.inner, u + 1 == g.n_units) {
                return Err(Error::Length { buffer: self.out_buffer(), len: uw.c_out(), expected: unit.c_out });
            }
        }
        Ok(v)
    }

    /// Appends one push of input columns: encoder `cols` = (hop,
    /// in_channels) frames; decoder (1, emb_width) one dequantised code.
    /// On an error before any state changed the stack is unchanged; an
    /// error half-way (impossible with the planned sizes) leaves it broken
    /// until [`StreamStack::reset`].
    pub fn push(&mut self, w: StackW<'_, '_>, cols: &[f32], s: &mut StreamScratch<'_>) -> Result<(), Error> {
        if self.broken {
            return Err(Error::State);
        }
        let units = self.bind(w)?;
        let g = &self.plan.geometry;
        let c_in = g.units[0].c_in;
        let expected = g.in_per_push * c_in;
        if cols.len() != expected {
            return Err(Error::Length { buffer: self.in_buffer(), len: cols.len(), expected });
        }
        let oc = units[g.n_units - 1].c_out();
        if self.out_ch != 0 && oc != self.out_ch {
            return Err(Error::Length { buffer: self.out_buffer(), len: oc, expected: self.out_ch });
        }
        if !self.need.fits(s) {
            return Err(Error::Length { buffer: Buffer::Features, len: s.g.len(), expected: self.need.g });
        }
        self.broken = true;
        self.settle(&units, cols, s)?;
        self.out_ch = oc;
        self.pushed += 1;
        self.broken = false;
        Ok(())
    }

    /// The push proper: new input columns into ring 0, then every unit's
    /// newly settled outputs into the next ring.
    fn settle(&mut self, units: &[UnitW<'_, '_>], cols: &[f32], s: &mut StreamScratch<'_>) -> Result<(), Error> {
        let mut counts = self.counts;
        let new = counts.advance(&self.plan.geometry);
        for c in cols.chunks_exact(self.rings[0].ch) {
            self.rings[0].push(c)?;
        }
        let last = units.len() - 1;
        for (u, uw) in units.iter().enumerate() {
            let Span { lo, hi } = new[u];
            if lo >= hi {
                continue;
            }
            let unit = self.plan.geometry.units[u];
            let (g0, g1) = unit.gather_span(lo, hi, counts.n_in(u));
            let ring = &self.rings[u];
            if ring.n != counts.set_in(u) {
                return Err(evicted(g1, g0, ring.n));
            }
            let x = first(s.g, (g1 - g0) * unit.c_in)?;
            for (i, xc) in (g0..g1).zip(x.chunks_exact_mut(unit.c_in)) {
                xc.copy_from_slice(ring.col(i)?);
            }
            let oc = uw.c_out();
            let y = first(s.ta, (hi - lo) * oc)?;
            uw.run(&unit, lo, g0, x, y, s.h, s.r, s.col, s.z)?;
            let next = if u == last { &mut self.out } else { &mut self.rings[u + 1] };
            for c in y.chunks_exact(oc) {
                next.push(c)?;
            }
        }
        self.counts = counts;
        Ok(())
    }

    /// Output columns `[t, t + n)` of the stack on the prefix pushed so far
    /// into `out` (n, C): encoder features (C = emb_width), decoder frames
    /// (C = the decoder's output channels). Settled columns come from the
    /// output ring (bit-identical to the full conv); unsettled ones are
    /// computed now from the tail cone. Errors if `t + n` exceeds the
    /// prefix's output, or a column is older than the output ring holds.
    pub fn output(&self, w: StackW<'_, '_>, t: usize, n: usize, s: &mut StreamScratch<'_>, out: &mut [f32]) -> Result<(), Error> {
        if self.broken {
            return Err(Error::State);
        }
        let units = self.bind(w)?;
        let g = &self.plan.geometry;
        let last = g.n_units - 1;
        let oc = units[last].c_out();
        if self.out_ch != 0 && oc != self.out_ch {
            return Err(Error::Length { buffer: self.out_buffer(), len: oc, expected: self.out_ch });
        }
        let expected = n.checked_mul(oc).ok_or(Error::Length { buffer: self.out_buffer(), len: out.len(), expected: usize::MAX })?;
        if out.len() != expected {
            return Err(Error::Length { buffer: self.out_buffer(), len: out.len(), expected });
        }
        let end = t.saturating_add(n);
        if end > self.len() {
            return Err(Error::Length { buffer: self.out_buffer(), len: end, expected: self.len() });
        }
        let set = self.settled();
        for (j, o) in (t..end.min(set)).zip(out.chunks_exact_mut(oc)) {
            o.copy_from_slice(&self.out.col(j)?[..oc]);
        }
        if end > set {
            let a = t.max(set);
            let tail = self.tails(&units, a, end, s)?;
            out[(a - t) * oc..].copy_from_slice(&tail[..(end - a) * oc]);
        }
        Ok(())
    }

    /// Computes the unsettled outputs `[a, b)` of the last unit through the
    /// tail cone; returns them ((b - a), c_out) in a scratch buffer.
    fn tails<'x>(&self, units: &[UnitW<'_, '_>], a: usize, b: usize, s: &'x mut StreamScratch<'_>) -> Result<&'x [f32], Error> {
        let g = &self.plan.geometry;
        let c = &self.counts;
        let need = c.cone(g, a, b);
        let u0 = (0..g.n_units).find(|&u| !need[u].is_empty()).unwrap_or(g.n_units - 1);
        // prev: tail of the unit below ((need[u-1].len(), c_out of u-1)); cur: this unit's.
        let (mut prev, mut cur): (&mut [f32], &mut [f32]) = (&mut s.ta[..], &mut s.tb[..]);
        for u in u0..g.n_units {
            let unit = g.units[u];
            let Span { lo, hi } = need[u];
            let (g0, g1) = unit.gather_span(lo, hi, c.n_in(u));
            let (set_in, ring) = (c.set_in(u), &self.rings[u]);
            let x = first(s.g, (g1 - g0) * unit.c_in)?;
            for (i, xc) in (g0..g1).zip(x.chunks_exact_mut(unit.c_in)) {
                if i < set_in {
                    xc.copy_from_slice(ring.col(i)?);
                } else {
                    // Unsettled input: tail of unit u-1, which covers [set_in, g1).
                    let below = if u > 0 { need[u - 1] } else { Span::default() };
                    let k = i.checked_sub(below.lo).filter(|_| i < below.hi);
                    let src = k.and_then(|k| prev.get(k * unit.c_in..(k + 1) * unit.c_in));
                    xc.copy_from_slice(src.ok_or(evicted(i, set_in, c.n_in(u)))?);
                }
            }
            let oc = units[u].c_out();
            let y = first(cur, (hi - lo) * oc)?;
            units[u].run(&unit, lo, g0, x, y, s.h, s.r, s.col, s.z)?;
            core::mem::swap(&mut prev, &mut cur);
        }
        Ok(prev)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::presets::duolando_published;

    /// Geometries beyond the fixtures': stride 4, three stages, deep resnets.
    fn configs() -> [VqConfig; 4] {
        let p = duolando_published().parts[0];
        [
            p,
            VqConfig { depth: 2, ..p },
            VqConfig { stride_t: 4, down_t: 1, ..p },
            VqConfig { down_t: 3, depth: 4, dilation_growth_rate: 2, ..p },
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
            VqConfig { width: u32::MAX, ..p },
            VqConfig { dilation_growth_rate: u32::MAX, ..p },
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
        let units = [Unit::conv(4, 2, 1, 1, 1, 1), Unit::conv(8, 4, 2, 1, 1, 1), Unit::res(9, 1), Unit::convt(2, 1, 1), Unit::convt(4, 1, 1)];
        for u in units {
            for t in 0..40usize {
                let reads: std::vec::Vec<isize> = match u.kind {
                    UnitKind::ConvT => (-10..60).filter(|&i| (0..u.kernel as isize).any(|j| i * u.stride as isize - u.pad as isize + j == t as isize)).collect(),
                    _ => (0..u.kernel).map(|j| (t * u.stride + j * u.dilation) as isize - u.pad as isize).collect(),
                };
                assert_eq!(u.first_in(t), *reads.iter().min().unwrap(), "{u:?} t {t}");
                assert_eq!(u.last_in(t), *reads.iter().max().unwrap(), "{u:?} t {t}");
            }
        }
    }
}
