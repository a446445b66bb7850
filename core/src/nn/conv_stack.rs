//! Working memory and the residual stack shared by the VQ-VAE encoder and
//! decoders (`Resnet1D` of `ResConv1DBlock`s).

use crate::arena::{ArenaError, Carve};
use crate::kernels::{conv1d, conv1d_col_len, convt_z_len, relu_inplace, relu_into};
use crate::nn::vq_config::VqConfig;
use crate::nn::weights::{ConvW, ResnetW};

/// Buffers for any of a model's VQ-VAEs over at most `rows` time steps.
pub struct ConvScratch<'s> {
    /// (rows, ch) ping-pong activations.
    pub a: &'s mut [f32],
    pub b: &'s mut [f32],
    /// (rows, ch) ReLU input / 1x1 output of a residual block.
    pub r: &'s mut [f32],
    /// (rows, ch) residual inner activations; codebook rows on decode.
    pub h: &'s mut [f32],
    /// im2col tile.
    pub col: &'s mut [f32],
    /// Transposed-conv tile.
    pub z: &'s mut [f32],
    /// (l_bins) squared codebook row norms.
    pub kk: &'s mut [f32],
    pub rows: usize,
    pub ch: usize,
}

/// Widest channel count and largest kernel/stride over `vqs`.
fn dims(vqs: &[VqConfig]) -> (usize, usize, usize, usize) {
    let mut ch = 0u32;
    let mut k = 3u32;
    let mut s = 1u32;
    let mut bins = 0u32;
    for vq in vqs {
        let inner = vq.res_inner().unwrap_or(0);
        ch = ch
            .max(vq.width)
            .max(inner)
            .max(vq.emb_width)
            .max(vq.in_channels)
            .max(vq.rot_channels);
        k = k.max(2 * vq.stride_t);
        s = s.max(vq.stride_t);
        bins = bins.max(vq.l_bins);
    }
    (ch as usize, k as usize, s as usize, bins as usize)
}

impl<'s> ConvScratch<'s> {
    /// Scratch for every VQ-VAE in `vqs` (a model's whole set).
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        vqs: &[VqConfig],
        rows: usize,
    ) -> Result<Self, ArenaError> {
        let (ch, k, s, bins) = dims(vqs);
        let n = rows.checked_mul(ch).ok_or(ArenaError::Overflow)?;
        Ok(ConvScratch {
            a: a.f32(n)?,
            b: a.f32(n)?,
            r: a.f32(n)?,
            h: a.f32(n)?,
            col: a.f32(conv1d_col_len(ch, k))?,
            z: a.f32(convt_z_len(ch, 2 * s))?,
            kk: a.f32(bins)?,
            rows,
            ch,
        })
    }
}

/// `y (len, c_out) = conv(x (len_in, c_in))`.
pub fn conv(w: &ConvW<'_>, x: &[f32], y: &mut [f32], col: &mut [f32]) {
    conv1d(x, w.c_in, &w.w, w.b, w.geom, y, col);
}

/// `Resnet1D` in place over `x` (len, width): per block
/// `x += conv_1x1(relu(conv_dil(relu(x))))`. `r`, `h`: >= len * width / inner.
pub fn resnet(
    blocks: &ResnetW<'_>,
    x: &mut [f32],
    len: usize,
    r: &mut [f32],
    h: &mut [f32],
    col: &mut [f32],
) {
    for blk in blocks {
        let (w, inner) = (blk.conv_dil.c_in, blk.conv_dil.c_out);
        let (x, r, h) = (&mut x[..len * w], &mut r[..len * w], &mut h[..len * inner]);
        relu_into(x, r);
        conv(&blk.conv_dil, r, h, col);
        relu_inplace(h);
        conv(&blk.conv_1x1, h, r, col);
        for (a, b) in x.iter_mut().zip(r.iter()) {
            *a += b;
        }
    }
}
