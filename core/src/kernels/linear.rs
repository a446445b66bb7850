//! Dense layers: `y = x W^T + b` (nn.Linear, conv as GEMM) and `z = x W`
//! (the transposed-convolution GEMM).

use super::weights::{Matrix, RowMatrix};

/// Weight rows kept hot per pass over the activations (~L2-sized blocks
/// at width 768).
const OUT_BLOCK: usize = 64;

/// `y = x W^T + b`. `x`: (n, in), `w`: (out, in), `b`: (out) or None,
/// `y`: (n, out); `n = x.len() / in`. Callers check the lengths.
pub fn linear(x: &[f32], w: &Matrix<'_>, b: Option<&[f32]>, y: &mut [f32]) {
    match w {
        Matrix::F32(m) => linear_impl(x, m, b, y),
    }
}

fn linear_impl<W: RowMatrix>(x: &[f32], w: &W, b: Option<&[f32]>, y: &mut [f32]) {
    let (n_in, n_out) = (w.cols(), w.rows());
    if n_in == 0 || n_out == 0 {
        return;
    }
    let n = (x.len() / n_in).min(y.len() / n_out);
    let mut o0 = 0;
    while o0 < n_out {
        let o1 = (o0 + OUT_BLOCK).min(n_out);
        for i in 0..n {
            let xi = &x[i * n_in..(i + 1) * n_in];
            let yi = &mut y[i * n_out..(i + 1) * n_out];
            for o in o0..o1 {
                let bias = b.map_or(0.0, |b| b[o]);
                yi[o] = w.dot(o, xi) + bias;
            }
        }
        o0 = o1;
    }
}

/// `z = x W` (no transpose). `x`: (n, rows), `w`: (rows, cols), `z`: (n, cols).
pub fn linear_xw(x: &[f32], w: &Matrix<'_>, z: &mut [f32]) {
    match w {
        Matrix::F32(m) => linear_xw_impl(x, m, z),
    }
}

fn linear_xw_impl<W: RowMatrix>(x: &[f32], w: &W, z: &mut [f32]) {
    let (rows, cols) = (w.rows(), w.cols());
    if rows == 0 || cols == 0 {
        return;
    }
    let n = (x.len() / rows).min(z.len() / cols);
    z[..n * cols].fill(0.0);
    for r in 0..rows {
        for i in 0..n {
            w.axpy(r, x[i * rows + r], &mut z[i * cols..(i + 1) * cols]);
        }
    }
}
