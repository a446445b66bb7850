//! Units of a stack and their index arithmetic (which input columns an
//! output column reads), and a stack's geometry.

use super::*;

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
pub(super) fn div_floor(a: isize, b: isize) -> isize {
    a.div_euclid(b)
}

/// `ceil(a / b)` for `b > 0`.
pub(super) fn div_ceil(a: isize, b: isize) -> isize {
    -(-a).div_euclid(b)
}

impl Unit {
    pub(super) fn conv(
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
    pub(super) fn res(dil: usize, width: usize) -> Unit {
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
    pub(super) fn convt(stride: usize, c_in: usize, c_out: usize) -> Unit {
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
    pub(super) fn gather_span(&self, a: usize, b: usize, n_in: usize) -> (usize, usize) {
        let lo = self.first_in(a).max(0) as usize;
        let hi = (self.last_in(b - 1) + 1).clamp(0, n_in as isize) as usize;
        (lo, hi.max(lo))
    }

    /// Left offset of the kernel when outputs `[a, ..)` are computed from
    /// input columns gathered from `g0` (`ConvGeom::pad` / the transposed
    /// conv's `pad`); never negative for the stacks' geometries.
    pub(super) fn local_pad(&self, a: usize, g0: usize) -> Option<usize> {
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
    pub(super) fn sim_pushes(&self, lag: usize) -> usize {
        3 * self.field_pushes() + lag + 4 * self.in_per_push.max(self.out_per_push) + 8
    }
}
