//! 1-D convolutions over time-major activations `(T, C)`, as GEMMs.
//!
//! `conv1d` gathers a tile of output rows into an im2col buffer and runs
//! [`linear`]; `conv_transpose1d` computes `z` (every input row's
//! contribution to `k` output rows) for a tile of input rows, as `x W` over
//! PyTorch-order weights or as [`linear`] over GEMM-order ones
//! ([`ConvTWeight`]), and scatter-adds `z` into the output. Input positions outside `[0, T_in)`
//! read as zero, so a caller can run a layer over a window with explicit
//! left context by choosing `pad` (streaming, DESIGN.md §3 S).

use super::linear::{linear, linear_xw};
use super::weights::Matrix;

/// A `ConvTranspose1d` weight as stored (docs/FORMAT.md §6). Either way
/// `z = x . W` has one row of `c_out * k` values per input row, value
/// `o * k + j` going to output channel `o` of the `j`-th output row the
/// input row reaches.
#[derive(Clone, Copy, Debug)]
pub enum ConvTWeight<'a> {
    /// PyTorch order, (c_in, c_out * k): `z = x W`, weight rows scaled and
    /// added ([`linear_xw`]; f32 and f16 files).
    Rows(Matrix<'a>),
    /// GEMM order, (c_out * k, c_in): row `o * k + j` holds `W[:, o, j]`,
    /// `z = x W^T` ([`linear`]: the int8 / 4-bit GEMMs, blocks along `c_in`).
    Gemm(Matrix<'a>),
}

impl ConvTWeight<'_> {
    /// Input channels.
    pub fn c_in(&self) -> usize {
        match self {
            ConvTWeight::Rows(m) => m.rows(),
            ConvTWeight::Gemm(m) => m.cols(),
        }
    }
    /// Values of `z` per input row (`c_out * k`).
    pub fn z_cols(&self) -> usize {
        match self {
            ConvTWeight::Rows(m) => m.cols(),
            ConvTWeight::Gemm(m) => m.rows(),
        }
    }
    /// The stored matrix.
    pub fn matrix(&self) -> &Matrix<'_> {
        match self {
            ConvTWeight::Rows(m) | ConvTWeight::Gemm(m) => m,
        }
    }
    /// `z = x . W` for `x.len() / c_in` input rows.
    fn z(&self, x: &[f32], z: &mut [f32]) {
        match self {
            ConvTWeight::Rows(m) => linear_xw(x, m, z),
            ConvTWeight::Gemm(m) => linear(x, m, None, z),
        }
    }
}

/// Output rows gathered per im2col tile (and input rows per transposed tile).
pub const CONV_TILE: usize = 32;

/// Geometry of a `Conv1d` (or the forward view of a `ConvTranspose1d`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvGeom {
    pub kernel: usize,
    pub stride: usize,
    /// Left offset: output row `t` reads input rows `t*stride - pad + j*dilation`.
    pub pad: usize,
    pub dilation: usize,
}

impl ConvGeom {
    /// Output length of a `Conv1d` with symmetric padding `pad` over `t_in`
    /// rows (PyTorch's formula); None if negative or on overflow.
    pub fn out_len(&self, t_in: usize) -> Option<usize> {
        let span = self
            .dilation
            .checked_mul(self.kernel.checked_sub(1)?)?
            .checked_add(1)?;
        let padded = t_in.checked_add(2 * self.pad)?;
        if padded < span || self.stride == 0 {
            return None;
        }
        Some((padded - span) / self.stride + 1)
    }
}

/// im2col scratch floats `conv1d` needs for `c_in` channels.
pub fn conv1d_col_len(c_in: usize, kernel: usize) -> usize {
    CONV_TILE * c_in * kernel
}

/// One independent sequence of a batched convolution: `t_in` input rows
/// (the segments' inputs lie one after another in the shared input), `t_out`
/// output rows (likewise in the shared output) and its own left offset
/// `pad`. Several streams' new columns run as one GEMM per tile, so the
/// weights are read once for all of them; each output row is computed
/// exactly as in a call over its segment alone (row-independent kernels).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvSeg {
    pub t_in: usize,
    pub t_out: usize,
    pub pad: usize,
}

/// `Conv1d`: `x` (t_in, c_in), `w` (c_out, c_in*k) viewing PyTorch's
/// (c_out, c_in, k), `b` (c_out), `y` (t_out, c_out) with `t_out =
/// y.len() / c_out`. `col`: >= [`conv1d_col_len`] floats (unused when the
/// conv is pointwise). Callers check lengths.
pub fn conv1d(
    x: &[f32],
    c_in: usize,
    w: &Matrix<'_>,
    b: &[f32],
    g: ConvGeom,
    y: &mut [f32],
    col: &mut [f32],
) {
    let rows = |len: usize, c: usize| len.checked_div(c).unwrap_or(0);
    let seg = ConvSeg {
        t_in: rows(x.len(), c_in),
        t_out: rows(y.len(), w.rows()),
        pad: g.pad,
    };
    conv1d_segs(x, c_in, w, b, g, &[seg], y, col);
}

/// [`conv1d`] over several segments at once (`g.pad` unused: each segment
/// has its own): `x` holds the segments' input rows one after another,
/// `y` their output rows. im2col tiles of [`CONV_TILE`] rows run across
/// segment ends, so a tile reads the weights once for every segment in it.
#[allow(clippy::too_many_arguments)]
pub fn conv1d_segs(
    x: &[f32],
    c_in: usize,
    w: &Matrix<'_>,
    b: &[f32],
    g: ConvGeom,
    segs: &[ConvSeg],
    y: &mut [f32],
    col: &mut [f32],
) {
    let c_out = w.rows();
    if c_out == 0 || c_in == 0 {
        return;
    }
    // Pointwise, and the output rows are the input rows (a lone segment
    // may have spare input rows at its end): one GEMM, no im2col.
    let pointwise = g.kernel == 1 && g.stride == 1 && segs.iter().all(|s| s.pad == 0);
    let in_place =
        segs.iter().all(|s| s.t_in == s.t_out) || matches!(segs, [s] if s.t_in >= s.t_out);
    if pointwise && in_place {
        let n: usize = segs.iter().map(|s| s.t_out).sum();
        linear(&x[..n * c_in], w, Some(b), &mut y[..n * c_out]);
        return;
    }
    let ck = c_in * g.kernel;
    // Tile fill: (segment, its input row offset, first output row of the segment still to do).
    let (mut si, mut x0, mut t) = (0usize, 0usize, 0usize);
    let mut y0 = 0;
    while si < segs.len() {
        let mut rows = 0;
        while rows < CONV_TILE && si < segs.len() {
            let s = segs[si];
            if t >= s.t_out {
                x0 += s.t_in;
                si += 1;
                t = 0;
                continue;
            }
            let xs = &x[x0 * c_in..(x0 + s.t_in) * c_in];
            let row = &mut col[rows * ck..(rows + 1) * ck];
            for j in 0..g.kernel {
                // Input index t*s - pad + j*d, zero outside [0, t_in).
                let pos = (t * g.stride + j * g.dilation).checked_sub(s.pad);
                match pos {
                    Some(p) if p < s.t_in => {
                        let xr = &xs[p * c_in..(p + 1) * c_in];
                        for c in 0..c_in {
                            row[c * g.kernel + j] = xr[c];
                        }
                    }
                    _ => {
                        for c in 0..c_in {
                            row[c * g.kernel + j] = 0.0;
                        }
                    }
                }
            }
            rows += 1;
            t += 1;
        }
        if rows > 0 {
            linear(
                &col[..rows * ck],
                w,
                Some(b),
                &mut y[y0 * c_out..(y0 + rows) * c_out],
            );
            y0 += rows;
        }
    }
}

/// Scratch floats `conv_transpose1d` needs.
pub fn convt_z_len(c_out: usize, kernel: usize) -> usize {
    CONV_TILE * c_out * kernel
}

/// `ConvTranspose1d`: `x` (t_in, c_in), `w` PyTorch's (c_in, c_out, k) in
/// either stored order, `b` (c_out), `y` (t_out, c_out): output row
/// `t = i*stride - pad + j` receives `x[i] . W[:, o, j]`; rows outside
/// `[0, t_out)` are dropped. `z`: >= [`convt_z_len`] floats.
#[allow(clippy::too_many_arguments)]
pub fn conv_transpose1d(
    x: &[f32],
    w: &ConvTWeight<'_>,
    b: &[f32],
    kernel: usize,
    stride: usize,
    pad: usize,
    y: &mut [f32],
    z: &mut [f32],
) {
    let rows = |len: usize, c: usize| len.checked_div(c).unwrap_or(0);
    let seg = ConvSeg {
        t_in: rows(x.len(), w.c_in()),
        t_out: rows(y.len(), b.len()),
        pad,
    };
    conv_transpose1d_segs(x, w, b, kernel, stride, &[seg], y, z);
}

/// [`conv_transpose1d`] over several segments at once (inputs one after
/// another in `x`, outputs in `y`, each with its own `pad`): `z = x . W`
/// tiles of [`CONV_TILE`] input rows run across segment ends.
#[allow(clippy::too_many_arguments)]
pub fn conv_transpose1d_segs(
    x: &[f32],
    w: &ConvTWeight<'_>,
    b: &[f32],
    kernel: usize,
    stride: usize,
    segs: &[ConvSeg],
    y: &mut [f32],
    z: &mut [f32],
) {
    let c_in = w.c_in();
    let c_out = b.len();
    if c_in == 0 || c_out == 0 || kernel == 0 || w.z_cols() != c_out * kernel {
        return;
    }
    let t_in: usize = segs.iter().map(|s| s.t_in).sum();
    let t_out: usize = segs.iter().map(|s| s.t_out).sum();
    for yr in y[..t_out * c_out].chunks_exact_mut(c_out) {
        yr.copy_from_slice(b);
    }
    let zk = c_out * kernel;
    // Input row i0 of the whole input lies in segment `si`, which starts at input row `xs`, output row `ys`.
    let (mut si, mut xs, mut ys) = (0usize, 0usize, 0usize);
    let mut i0 = 0;
    while i0 < t_in {
        let rows = CONV_TILE.min(t_in - i0);
        w.z(&x[i0 * c_in..(i0 + rows) * c_in], &mut z[..rows * zk]);
        for r in 0..rows {
            let ig = i0 + r;
            while ig >= xs + segs[si].t_in {
                xs += segs[si].t_in;
                ys += segs[si].t_out;
                si += 1;
            }
            let s = segs[si];
            let i = ig - xs;
            let zr = &z[r * zk..(r + 1) * zk];
            for j in 0..kernel {
                let t = match (i * stride + j).checked_sub(s.pad) {
                    Some(t) if t < s.t_out => ys + t,
                    _ => continue,
                };
                let yr = &mut y[t * c_out..(t + 1) * c_out];
                for (o, yo) in yr.iter_mut().enumerate() {
                    *yo += zr[o * kernel + j];
                }
            }
        }
        i0 += rows;
    }
}
