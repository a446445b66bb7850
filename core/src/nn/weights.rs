//! Borrowed weight views of the shared building blocks (Linear,
//! LayerNorm, transformer block, Conv1d, ConvTranspose1d, Resnet1D, VQ-VAE
//! encoder/decoder/codebook), bound by [`crate::nn::bind::Binder`].

use heapless::Vec;

use crate::kernels::{ConvGeom, ConvTWeight, Matrix};
use crate::limits::{MAX_DEPTH, MAX_DOWN_T};
use crate::nn::vq_config::VqConfig;

/// `nn.Linear`: `w` (out, in), optional bias (out).
#[derive(Clone, Copy, Debug)]
pub struct Linear<'a> {
    pub w: Matrix<'a>,
    pub b: Option<&'a [f32]>,
}

/// `nn.LayerNorm` affine parameters (C).
#[derive(Clone, Copy, Debug)]
pub struct LayerNormW<'a> {
    pub w: &'a [f32],
    pub b: &'a [f32],
}

/// A pre-LN transformer block: `x += proj(attn(ln1 x)); x += mlp.2(gelu(mlp.0(ln2 x)))`.
#[derive(Clone, Copy, Debug)]
pub struct BlockW<'a> {
    pub ln1: LayerNormW<'a>,
    pub ln2: LayerNormW<'a>,
    pub query: Linear<'a>,
    pub key: Linear<'a>,
    pub value: Linear<'a>,
    pub proj: Linear<'a>,
    pub fc: Linear<'a>,
    pub fc_out: Linear<'a>,
}

/// A `Conv1d` with its geometry.
#[derive(Clone, Copy, Debug)]
pub struct ConvW<'a> {
    /// (c_out, c_in * k).
    pub w: Matrix<'a>,
    pub b: &'a [f32],
    pub c_in: usize,
    pub c_out: usize,
    pub geom: ConvGeom,
}

/// A `ConvTranspose1d(k = 2s, stride s, pad s/2)`.
#[derive(Clone, Copy, Debug)]
pub struct ConvTW<'a> {
    /// PyTorch's (c_in, c_out, k) as stored: (c_in, c_out * k), or in GEMM
    /// order (c_out * k, c_in).
    pub w: ConvTWeight<'a>,
    pub b: &'a [f32],
    pub c_in: usize,
    pub c_out: usize,
    pub kernel: usize,
    pub stride: usize,
    pub pad: usize,
}

/// One `ResConv1DBlock`: `x + conv1x1(relu(conv_k3_dil(relu(x))))`.
#[derive(Clone, Copy, Debug)]
pub struct ResBlockW<'a> {
    pub conv_dil: ConvW<'a>,
    pub conv_1x1: ConvW<'a>,
}

/// `Resnet1D`: residual blocks in execution order.
pub type ResnetW<'a> = Vec<ResBlockW<'a>, { MAX_DEPTH as usize }>;

/// VQ-VAE encoder: `[conv(k2s, s) -> Resnet1D] x down_t -> conv(k3)`.
#[derive(Clone, Debug)]
pub struct EncoderW<'a> {
    pub stages: Vec<(ConvW<'a>, ResnetW<'a>), { MAX_DOWN_T as usize }>,
    pub out: ConvW<'a>,
}

/// VQ-VAE decoder: `conv(k3) -> [Resnet1D(reversed) -> convT] x down_t -> conv(k3)`.
#[derive(Clone, Debug)]
pub struct DecoderW<'a> {
    pub input: ConvW<'a>,
    pub stages: Vec<(ResnetW<'a>, ConvTW<'a>), { MAX_DOWN_T as usize }>,
    pub out: ConvW<'a>,
}

/// One VQ-VAE (a body part or the relative translation).
#[derive(Clone, Debug)]
pub struct VqW<'a> {
    pub cfg: VqConfig,
    pub encoder: EncoderW<'a>,
    /// `bottleneck.level_blocks.0.k` (l_bins, emb_width).
    pub codebook: Matrix<'a>,
    pub pos: DecoderW<'a>,
    /// Rotation decoder (None for the translation VQ-VAE).
    pub rot: Option<DecoderW<'a>>,
}
