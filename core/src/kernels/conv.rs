//! 1-D convolutions over time-major activations `(T, C)`, as GEMMs.
//!
//! `conv1d` gathers a tile of output rows into an im2col buffer and runs
//! [`linear`]; `conv_transpose1d` runs `z = x W` for a tile of input rows
//! and scatter-adds `z` into the output. Input positions outside `[0, T_in)`
//! read as zero, so a caller can run a layer over a window with explicit
//! left context by choosing `pad` (streaming, DESIGN.md §3 S).

use super::linear::{linear, linear_xw};
use super::weights::Matrix;

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
        let span = self.dilation.checked_mul(self.kernel.checked_sub(1)?)?.checked_add(1)?;
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

/// `Conv1d`: `x` (t_in, c_in), `w` (c_out, c_in*k) viewing PyTorch's
/// (c_out, c_in, k), `b` (c_out), `y` (t_out, c_out) with `t_out =
/// y.len() / c_out`. `col`: >= [`conv1d_col_len`] floats (unused when the
/// conv is pointwise). Callers check lengths.
pub fn conv1d(x: &[f32], c_in: usize, w: &Matrix<'_>, b: &[f32], g: ConvGeom, y: &mut [f32], col: &mut [f32]) {
    let c_out = w.rows();
    if c_out == 0 || c_in == 0 {
        return;
    }
    let t_in = x.len() / c_in;
    let t_out = y.len() / c_out;
    if g.kernel == 1 && g.stride == 1 && g.pad == 0 {
        let n = t_in.min(t_out);
        linear(&x[..n * c_in], w, Some(b), &mut y[..n * c_out]);
        return;
    }
    let ck = c_in * g.kernel;
    let mut t0 = 0;
    while t0 < t_out {
        let rows = CONV_TILE.min(t_out - t0);
        for r in 0..rows {
            let t = t0 + r;
            let row = &mut col[r * ck..(r + 1) * ck];
            for j in 0..g.kernel {
                // Input index t*s - pad + j*d, zero outside [0, t_in).
                let pos = (t * g.stride + j * g.dilation).checked_sub(g.pad);
                match pos {
                    Some(p) if p < t_in => {
                        let xr = &x[p * c_in..(p + 1) * c_in];
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
        }
        linear(&col[..rows * ck], w, Some(b), &mut y[t0 * c_out..(t0 + rows) * c_out]);
        t0 += rows;
    }
}

/// Scratch floats `conv_transpose1d` needs.
pub fn convt_z_len(c_out: usize, kernel: usize) -> usize {
    CONV_TILE * c_out * kernel
}

/// `ConvTranspose1d`: `x` (t_in, c_in), `w` (c_in, c_out*k) viewing
/// PyTorch's (c_in, c_out, k), `b` (c_out), `y` (t_out, c_out): output row
/// `t = i*stride - pad + j` receives `x[i] . W[:, o, j]`; rows outside
/// `[0, t_out)` are dropped. `z`: >= [`convt_z_len`] floats.
pub fn conv_transpose1d(
    x: &[f32],
    w: &Matrix<'_>,
    b: &[f32],
    kernel: usize,
    stride: usize,
    pad: usize,
    y: &mut [f32],
    z: &mut [f32],
) {
    let c_in = w.rows();
    let c_out = b.len();
    if c_in == 0 || c_out == 0 || kernel == 0 {
        return;
    }
    let t_in = x.len() / c_in;
    let t_out = y.len() / c_out;
    for yr in y.chunks_exact_mut(c_out) {
        yr.copy_from_slice(b);
    }
    let zk = c_out * kernel;
    let mut i0 = 0;
    while i0 < t_in {
        let rows = CONV_TILE.min(t_in - i0);
        linear_xw(&x[i0 * c_in..(i0 + rows) * c_in], w, &mut z[..rows * zk]);
        for r in 0..rows {
            let i = i0 + r;
            let zr = &z[r * zk..(r + 1) * zk];
            for j in 0..kernel {
                let t = match (i * stride + j).checked_sub(pad) {
                    Some(t) if t < t_out => t,
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
