//! Dense layers: `y = x W^T + b` (nn.Linear, conv as GEMM) and `z = x W`
//! (the transposed-convolution GEMM). Written once against [`RowMatrix`].

use super::weights::{Matrix, PreparedAct, RowMatrix};

/// Weight bytes kept hot per pass over the activations (~L2-sized blocks:
/// 64 f32 rows at width 768, more rows for narrower weight types).
const BLOCK_BYTES: usize = 192 * 1024;

/// `y = x W^T + b`. `x`: (n, in), `w`: (out, in), `b`: (out) or None,
/// `y`: (n, out); `n = x.len() / in`. Callers check the lengths.
pub fn linear(x: &[f32], w: &Matrix<'_>, b: Option<&[f32]>, y: &mut [f32]) {
    let block = (BLOCK_BYTES / (w.weight_bytes() / w.rows().max(1)).max(1)).clamp(16, 1024);
    crate::with_rows!(w, m => linear_impl(x, m, b, y, block))
}

fn linear_impl<W: RowMatrix>(x: &[f32], w: &W, b: Option<&[f32]>, y: &mut [f32], block: usize) {
    let (n_in, n_out) = (w.cols(), w.rows());
    if n_in == 0 || n_out == 0 {
        return;
    }
    let n = (x.len() / n_in).min(y.len() / n_out);
    let chunk = W::CHUNK.min(n_in);
    let mut act = W::Act::new();
    let mut o0 = 0;
    while o0 < n_out {
        let o1 = (o0 + block).min(n_out);
        for i in 0..n {
            let xi = &x[i * n_in..(i + 1) * n_in];
            let yi = &mut y[i * n_out..(i + 1) * n_out];
            for o in o0..o1 {
                yi[o] = b.map_or(0.0, |b| b[o]);
            }
            let mut c0 = 0;
            while c0 < n_in {
                let xc = &xi[c0..(c0 + chunk).min(n_in)];
                W::prepare(xc, &mut act);
                for o in o0..o1 {
                    yi[o] += w.dot_chunk(o, c0, xc, &act);
                }
                c0 += chunk;
            }
        }
        o0 = o1;
    }
}

/// `z = x W` (no transpose). `x`: (n, rows), `w`: (rows, cols), `z`: (n, cols).
pub fn linear_xw(x: &[f32], w: &Matrix<'_>, z: &mut [f32]) {
    crate::with_rows!(w, m => linear_xw_impl(x, m, z))
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
