//! Pointwise activations.

/// Exact GELU (`nn.GELU()` default): `0.5 x (1 + erf(x / sqrt 2))`
/// ([`crate::kernels::simd::gelu_inplace`]: erf to 1.5e-7).
pub fn gelu_inplace(x: &mut [f32]) {
    super::simd::gelu_inplace(x)
}

pub fn relu_inplace(x: &mut [f32]) {
    for v in x {
        *v = v.max(0.0);
    }
}

/// `out = max(x, 0)`.
pub fn relu_into(x: &[f32], out: &mut [f32]) {
    for (o, v) in out.iter_mut().zip(x) {
        *o = v.max(0.0);
    }
}
