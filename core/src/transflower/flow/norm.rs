//! The norm module of a flow step, reversed (models/flowplusplus/act_norm.py):
//!
//! - `BatchNorm` (eval: running statistics; eps on the STD, beta
//!   SUBTRACTED in the forward pass): `inv_std = 1 / (sqrt(running_var) +
//!   1e-5)`; reverse `x = ((x + beta) / gamma) / inv_std + running_mean`.
//! - `ActNorm`: reverse `x = x / inv_std + mean`.
//!
//! Each op in the authors' order, in float32. `x`: (C, H) channel-major.

use crate::transflower::model::NormW;

/// The authors' `BatchNorm.eps` (added to the std, not the variance).
pub const BATCHNORM_EPS: f32 = 1e-5;

/// Reverses the norm on `x` (C, H) in place.
pub fn reverse(w: &NormW<'_>, x: &mut [f32], h: usize) {
    if h == 0 {
        return;
    }
    match *w {
        NormW::None => {}
        NormW::BatchNorm {
            gamma,
            beta,
            mean,
            var,
        } => {
            for (c, row) in x.chunks_exact_mut(h).enumerate() {
                let inv_std = 1.0 / (libm::sqrtf(var[c]) + BATCHNORM_EPS);
                for v in row {
                    *v = ((*v + beta[c]) / gamma[c]) / inv_std + mean[c];
                }
            }
        }
        NormW::ActNorm { mean, inv_std } => {
            for (c, row) in x.chunks_exact_mut(h).enumerate() {
                for v in row {
                    *v = *v / inv_std[c] + mean[c];
                }
            }
        }
    }
}
