//! Config limits shared by every family: the caps on every size a `.duo`
//! header may carry, the names of config fields, [`ConfigError`], and the
//! checks of a VQ-VAE config. Each family validates its config with these
//! (Duolando: `duolando::validate`) once, before any weight is bound or
//! any arena is planned, so that every
//! later product of dimensions fits comfortably in `usize` (even on 32-bit
//! targets) and the engine's assumptions (head split, stream count, the
//! vocabulary quirk of the original heads) hold.
//!
//! The caps are generous for the published model (n_embd 768, width 512,
//! depth 3, 12 layers) and for the sibling models of DESIGN.md §7.

use crate::duolando::config::Part;
use crate::nn::vq_config::VqConfig;

/// Largest transformer width (`n_embd`).
pub const MAX_EMBD: u32 = 4096;
/// Most attention heads.
pub const MAX_HEADS: u32 = 64;
/// Most blocks in the GPT base or head stack.
pub const MAX_GPT_LAYERS: u32 = 24;
/// Most blocks in one LAT.
pub const MAX_LAT_LAYERS: u32 = 8;
/// Largest `block_size` (tokens per stream in the window).
pub const MAX_BLOCK_SIZE: u32 = 256;
/// Largest look-ahead in tokens.
pub const MAX_LOOK_FORWARD: u32 = 256;
/// Largest music feature width (`n_music`).
pub const MAX_MUSIC_DIM: u32 = 4096;
/// Largest LAT downsample rate (input rows per output token).
pub const MAX_DOWNSAMPLE: u32 = 16;
/// Largest vocabulary / codebook.
pub const MAX_VOCAB: u32 = 65536;
/// Largest VQ-VAE conv width, inner residual width and codebook row width.
pub const MAX_WIDTH: u32 = 4096;
/// Most residual blocks per Resnet1D.
pub const MAX_DEPTH: u32 = 8;
/// Most strided stages per VQ-VAE.
pub const MAX_DOWN_T: u32 = 4;
/// Largest stride of a strided stage.
pub const MAX_STRIDE: u32 = 8;
/// Largest dilation of any residual conv (`growth^(depth-1)`).
pub const MAX_DILATION: u32 = 4096;
/// Largest `music_motion_rate`.
pub const MAX_MUSIC_MOTION_RATE: u32 = 64;
/// Streams of the coordinated attention the engine implements (Duolando).
pub const DUOLANDO_STREAMS: u32 = 10;

/// Which VQ-VAE a config field belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VqWhich {
    Part(Part),
    Transl,
}

/// A field of [`VqConfig`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VqField {
    InChannels,
    RotChannels,
    Width,
    Depth,
    DilationGrowthRate,
    DownT,
    StrideT,
    EmbWidth,
    LBins,
    MConv,
    /// `stride_t ^ down_t` (frames per token).
    Hop,
    /// `growth ^ (depth - 1)`.
    MaxDilation,
}

/// Which LAT a config field belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LatWhich {
    Music,
    Leader,
}

/// A field of [`crate::duolando::config::LatConfig`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LatField {
    NIn,
    NLayer,
    NHead,
    DownsampleRate,
}

/// The config field a [`ConfigError`] is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConfigField {
    NEmbd,
    NHead,
    NLayerBase,
    NLayerHead,
    BlockSize,
    LookForward,
    /// `vocab[i]`, i in stream order up, down, lhand, rhand, transl.
    Vocab(u8),
    NStreams,
    FinalLn,
    MusicMotionRate,
    /// Music feature width (Bailando `n_music`).
    NMusic,
    Lat(LatWhich, LatField),
    Vq(VqWhich, VqField),
}

/// Why a model config (Duolando: [`crate::duolando::config::ModelConfig`]) was rejected. Values are the offending numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConfigError {
    /// A size that must be positive is 0.
    Zero { field: ConfigField },
    /// A size above its cap.
    TooLarge {
        field: ConfigField,
        value: u32,
        max: u32,
    },
    /// A size below its minimum.
    TooSmall {
        field: ConfigField,
        value: u32,
        min: u32,
    },
    /// `value` must be a multiple of `divisor` (e.g. n_embd of n_head).
    NotDivisible {
        field: ConfigField,
        value: u32,
        divisor: u32,
    },
    /// `value` must equal `expected` (e.g. vocab == l_bins of its VQ-VAE,
    /// in_channels == 3 x part joints).
    Mismatch {
        field: ConfigField,
        value: u32,
        expected: u32,
    },
    /// A value the engine does not implement (e.g. a final LayerNorm, an
    /// odd stride, a stream count other than 10).
    Unsupported { field: ConfigField, value: u32 },
}

pub(crate) fn range(field: ConfigField, value: u32, min: u32, max: u32) -> Result<(), ConfigError> {
    if value == 0 && min > 0 {
        return Err(ConfigError::Zero { field });
    }
    if value < min {
        return Err(ConfigError::TooSmall { field, value, min });
    }
    if value > max {
        return Err(ConfigError::TooLarge { field, value, max });
    }
    Ok(())
}

pub(crate) fn equal(field: ConfigField, value: u32, expected: u32) -> Result<(), ConfigError> {
    if value != expected {
        return Err(ConfigError::Mismatch {
            field,
            value,
            expected,
        });
    }
    Ok(())
}

pub(crate) fn divisible(field: ConfigField, value: u32, divisor: u32) -> Result<(), ConfigError> {
    if divisor == 0 || value % divisor != 0 {
        return Err(ConfigError::NotDivisible {
            field,
            value,
            divisor,
        });
    }
    Ok(())
}

impl VqConfig {
    /// Checks one VQ-VAE config; `in_channels`/`rot_channels` are compared
    /// with the caller's expectation (3 x joints / 9 x joints of the part).
    pub(crate) fn validate(
        &self,
        which: VqWhich,
        in_ch: u32,
        rot_ch: u32,
    ) -> Result<(), ConfigError> {
        let f = |v| ConfigField::Vq(which, v);
        equal(f(VqField::InChannels), self.in_channels, in_ch)?;
        equal(f(VqField::RotChannels), self.rot_channels, rot_ch)?;
        range(f(VqField::Width), self.width, 1, MAX_WIDTH)?;
        range(f(VqField::Depth), self.depth, 1, MAX_DEPTH)?;
        range(
            f(VqField::DilationGrowthRate),
            self.dilation_growth_rate,
            1,
            MAX_DILATION,
        )?;
        range(f(VqField::DownT), self.down_t, 1, MAX_DOWN_T)?;
        range(f(VqField::StrideT), self.stride_t, 2, MAX_STRIDE)?;
        // Conv(k=2s, s, p=s/2) maps L frames to exactly L/s only for even s.
        if self.stride_t % 2 != 0 {
            return Err(ConfigError::Unsupported {
                field: f(VqField::StrideT),
                value: self.stride_t,
            });
        }
        range(f(VqField::EmbWidth), self.emb_width, 1, MAX_WIDTH)?;
        range(f(VqField::LBins), self.l_bins, 1, MAX_VOCAB)?;
        range(f(VqField::MConv), self.m_conv_den, 1, MAX_WIDTH)?;
        let inner = self.res_inner().unwrap_or(u32::MAX);
        range(f(VqField::MConv), inner, 1, MAX_WIDTH)?;
        let dil = self
            .dilation_growth_rate
            .checked_pow(self.depth - 1)
            .unwrap_or(u32::MAX);
        range(f(VqField::MaxDilation), dil, 1, MAX_DILATION)?;
        let hop = self.hop().unwrap_or(u32::MAX);
        range(f(VqField::Hop), hop, 2, MAX_DOWNSAMPLE * MAX_DOWNSAMPLE)?;
        Ok(())
    }
}
