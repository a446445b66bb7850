//! The VQ bottleneck (`BottleneckBlock.quantise` / `dequantise`): nearest
//! codebook row by `|x|^2 - 2 x.k + |k|^2` (the original's formula and
//! evaluation order), ties to the lowest index; dequantise = row lookup.

use crate::error::{check_len, Buffer, Error};
use crate::kernels::Matrix;

/// `kk[j] = |k_j|^2` for every codebook row; `row`: (emb) scratch.
pub fn codebook_norms(codebook: &Matrix<'_>, row: &mut [f32], kk: &mut [f32]) {
    for (j, v) in kk.iter_mut().enumerate().take(codebook.rows()) {
        codebook.row_into(j, row);
        *v = row.iter().map(|x| x * x).sum();
    }
}

/// Index of the nearest codebook row to `x` (emb); `kk` from [`codebook_norms`].
pub fn nearest(codebook: &Matrix<'_>, kk: &[f32], x: &[f32]) -> u32 {
    let xx: f32 = x.iter().map(|v| v * v).sum();
    let dist = |j: usize| (xx - 2.0 * codebook.dot(j, x)) + kk[j];
    let mut best = 0usize;
    let mut best_d = dist(0);
    for j in 1..codebook.rows() {
        let d = dist(j);
        // Strict `<`: ties keep the lowest index.
        if d < best_d {
            best_d = d;
            best = j;
        }
    }
    best as u32
}

/// Codes of `feat` (n, emb): `codes` (n). `row`: (emb) scratch; `kk`: (l_bins).
pub fn quantise(
    codebook: &Matrix<'_>,
    feat: &[f32],
    codes: &mut [u32],
    row: &mut [f32],
    kk: &mut [f32],
) -> Result<(), Error> {
    let emb = codebook.cols();
    check_len(Buffer::Features, feat.len(), codes.len() * emb)?;
    let kk = &mut kk[..codebook.rows()];
    codebook_norms(codebook, &mut row[..emb], kk);
    for (code, x) in codes.iter_mut().zip(feat.chunks_exact(emb)) {
        *code = nearest(codebook, kk, x);
    }
    Ok(())
}

/// Codebook rows of `codes` into `out` (n, emb).
pub fn dequantise(
    codebook: &Matrix<'_>,
    codes: &[u32],
    stream: u8,
    out: &mut [f32],
) -> Result<(), Error> {
    let emb = codebook.cols();
    check_len(Buffer::Features, out.len(), codes.len() * emb)?;
    for (&c, o) in codes.iter().zip(out.chunks_exact_mut(emb)) {
        if c as usize >= codebook.rows() {
            return Err(Error::Token {
                stream,
                token: c,
                vocab: codebook.rows() as u32,
            });
        }
        codebook.row_into(c as usize, o);
    }
    Ok(())
}
