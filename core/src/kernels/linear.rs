//! Dense layers: `y = x W^T + b` (nn.Linear, conv as GEMM) and `z = x W`
//! (the transposed-convolution GEMM). Written once against [`RowMatrix`].

use super::simd::{TM, TN};
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
    if n == 0 {
        return;
    }
    let chunk = W::CHUNK.min(n_in);
    let mut act = W::Act::new();
    // Output blocks (weights kept hot in L2) x activation tiles of TM rows
    // (prepared once per block and chunk) x weight tiles of TN rows. Tails
    // repeat the last real row / output and drop the extra results.
    let mut o0 = 0;
    while o0 < n_out {
        let o1 = (o0 + block).min(n_out);
        let mut i0 = 0;
        while i0 < n {
            let mt = TM.min(n - i0);
            for i in i0..i0 + mt {
                let yi = &mut y[i * n_out + o0..i * n_out + o1];
                match b {
                    Some(b) => yi.copy_from_slice(&b[o0..o1]),
                    None => yi.fill(0.0),
                }
            }
            let mut c0 = 0;
            while c0 < n_in {
                let c1 = (c0 + chunk).min(n_in);
                let mut m = 0;
                let xt: [&[f32]; TM] = [(); TM].map(|_| {
                    let i = i0 + m.min(mt - 1);
                    m += 1;
                    &x[i * n_in + c0..i * n_in + c1]
                });
                W::prepare(&xt[..mt], &mut act);
                let mut t0 = o0;
                while t0 < o1 {
                    let nt = TN.min(o1 - t0);
                    let mut j = 0;
                    let ot: [usize; TN] = [(); TN].map(|_| {
                        j += 1;
                        t0 + (j - 1).min(nt - 1)
                    });
                    let tile = w.dot_tile(ot, c0, xt, &act);
                    for (r, tr) in tile.iter().enumerate().take(mt) {
                        let yr = &mut y[(i0 + r) * n_out + t0..(i0 + r) * n_out + t0 + nt];
                        for (yo, t) in yr.iter_mut().zip(tr) {
                            *yo += t;
                        }
                    }
                    t0 += nt;
                }
                c0 = c1;
            }
            i0 += mt;
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
