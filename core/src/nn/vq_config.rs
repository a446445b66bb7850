//! The config of one VQ-VAE, shared by every family (Duolando's body
//! parts and relative translation, Bailando's up and down halves). Field
//! names follow the original YAML keys.

use serde::{Deserialize, Serialize};

/// One VQ-VAE (a body part, or the relative translation).
///
/// Encoder: `[Conv1d(k=2*stride, s=stride, p=stride/2) -> Resnet1D(depth)] x down_t
/// -> Conv1d(k3,p1)`; quantizer: nearest of `l_bins` codebook rows
/// (`emb_width` wide); decoders: `Conv1d(k3) -> [Resnet1D(depth, reversed
/// dilations) -> ConvTranspose1d(k=2*stride, s=stride, p=stride/2)] x down_t
/// -> Conv1d(k3)`, one decoder per output head.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct VqConfig {
    /// Input channels of the encoder = output channels of the position
    /// decoder (`pos_channel` in YAML; `input_dim` for the translation VQ-VAE).
    pub in_channels: u32,
    /// Output channels of the rotation decoder (`rot_channel`; 0 = no
    /// rotation decoder, as in the translation VQ-VAE).
    pub rot_channels: u32,
    /// Hidden width of every conv (`width`).
    pub width: u32,
    /// Residual blocks per Resnet1D (`depth`).
    pub depth: u32,
    /// Dilation of residual block d is `dilation_growth_rate^d` (`dilation_growth_rate`).
    pub dilation_growth_rate: u32,
    /// Number of strided stages (`downs_t[0]`; the original has 1 level only).
    pub down_t: u32,
    /// Stride of each stage (`strides_t[0]`). Frames per token = stride^down_t.
    pub stride_t: u32,
    /// Codebook row width = encoder output channels (`emb_width`).
    pub emb_width: u32,
    /// Codebook rows (`l_bins`).
    pub l_bins: u32,
    /// `m_conv` as a ratio num/den (1.0 in every published config): the
    /// inner width of a residual block is `width * m_conv`.
    pub m_conv_num: u32,
    pub m_conv_den: u32,
}

impl VqConfig {
    /// Frames per token (`stride_t ^ down_t`), None on overflow.
    pub fn hop(&self) -> Option<u32> {
        self.stride_t.checked_pow(self.down_t)
    }
    /// Inner width of a residual block (`int(m_conv * width)`), None on overflow.
    pub fn res_inner(&self) -> Option<u32> {
        if self.m_conv_den == 0 {
            return None;
        }
        self.width
            .checked_mul(self.m_conv_num)
            .map(|v| v / self.m_conv_den)
    }
}
