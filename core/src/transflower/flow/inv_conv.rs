//! The invertible 1x1 convolution in LU form, reversed
//! (models/flowplusplus/inv_conv.py `InvertibleConv1x1`, LU_decomposed):
//!
//! ```text
//! L = l * strict_lower + I        U = u * strict_upper + diag(sign_s * exp(log_s))
//! reverse weight W = f32(inv64(U)) @ (f32(inv64(L)) @ inv(p))     (C, C)
//! y[o, h] = sum_i W[o, i] x[i, h]
//! ```
//!
//! The authors compute W on the first reverse call and keep it for the
//! module's lifetime: [`inverse_weight`] computes it once per generation
//! ([`crate::transflower::exact`]). The triangular inverses run in f64 by
//! substitution and are rounded to f32 as the authors round torch's f64
//! `inverse`; the product is accumulated in f64 and rounded (the authors'
//! is an f32 matmul: a difference of ~1 ulp per entry).

use crate::transflower::model::InvConvW;

/// Working memory of [`inverse_weight`] for C channels.
pub struct InverseScratch<'s> {
    /// (C, C): f32(inv64(L)), then (L^-1 p^-1).
    pub li: &'s mut [f32],
    /// (C, C): f32(inv64(U)).
    pub ui: &'s mut [f32],
    /// (C): one column in f64.
    pub col: &'s mut [f64],
}

/// `w` (C, C) = the reverse weight of `conv` (C channels; `p` checked to
/// be a permutation and `sign_s` +-1 at bind).
pub fn inverse_weight(conv: &InvConvW<'_>, c: usize, s: &mut InverseScratch<'_>, w: &mut [f32]) {
    let (li, ui, col) = (&mut s.li[..c * c], &mut s.ui[..c * c], &mut s.col[..c]);
    // L^-1 by forward substitution, column by column (unit diagonal).
    for j in 0..c {
        for i in 0..c {
            col[i] = if i < j {
                0.0
            } else if i == j {
                1.0
            } else {
                let row = &conv.l[i * c + j..i * c + i];
                -row.iter()
                    .zip(&col[j..i])
                    .fold(0.0f64, |acc, (&l, &x)| acc + l as f64 * x)
            };
        }
        for i in 0..c {
            li[i * c + j] = col[i] as f32;
        }
    }
    // U^-1 by back substitution; the diagonal as the authors form it (f32).
    let diag = |i: usize| (conv.sign_s[i] * libm::expf(conv.log_s[i])) as f64;
    for j in 0..c {
        for i in (0..c).rev() {
            col[i] = if i > j {
                0.0
            } else if i == j {
                1.0 / diag(j)
            } else {
                let row = &conv.u[i * c + i + 1..=i * c + j];
                -row.iter()
                    .zip(&col[i + 1..=j])
                    .fold(0.0f64, |acc, (&u, &x)| acc + u as f64 * x)
                    / diag(i)
            };
        }
        for i in 0..c {
            ui[i * c + j] = col[i] as f32;
        }
    }
    // L^-1 p^-1 = L^-1 p^T: column j is L^-1's column pi(j), where p[j, pi(j)] = 1.
    for j in 0..c {
        let pj = conv.p[j * c..(j + 1) * c]
            .iter()
            .position(|&v| v == 1.0)
            .unwrap_or(j);
        for i in 0..c {
            col[i] = li[i * c + pj] as f64;
        }
        for i in 0..c {
            // Column j of the product is written into `w` (li is read whole first).
            let mut acc = 0.0f64;
            for k in 0..c {
                acc += ui[i * c + k] as f64 * col[k];
            }
            w[i * c + j] = acc as f32;
        }
    }
}

/// `x` (C, H) = W x in place; `tmp`: (C, H).
pub fn apply(w: &[f32], x: &mut [f32], h: usize, tmp: &mut [f32]) {
    let c = x.len() / h.max(1);
    let tmp = &mut tmp[..c * h];
    for o in 0..c {
        for t in 0..h {
            let mut acc = 0.0f32;
            for i in 0..c {
                acc += w[o * c + i] * x[i * h + t];
            }
            tmp[o * h + t] = acc;
        }
    }
    x.copy_from_slice(tmp);
}
