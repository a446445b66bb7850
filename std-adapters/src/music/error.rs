//! Errors of the music feature extractor.

use thiserror::Error;

/// Why a signal could not be turned into Duolando music features.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MusicError {
    /// Fewer samples than the feature needs: three frames (the MFCC delta
    /// window) means at least `needed` samples at 15360 Hz.
    #[error("audio too short: {got} samples at 15360 Hz, need at least {needed} (3 frames of hop 512; librosa's delta needs width 3)")]
    TooShort { got: usize, needed: usize },
    /// Fewer samples than a feature set at another rate needs (Transflower: 96 kHz).
    #[error("audio too short: {got} samples at {rate} Hz, need at least {needed} ({what})")]
    TooShortAt {
        got: usize,
        needed: usize,
        rate: u32,
        what: &'static str,
    },
    /// A NaN or infinite sample (the decoders never produce one; a caller's buffer may).
    #[error("non-finite audio sample {value} at index {index}")]
    NonFinite { index: usize, value: f32 },
    /// The CQT needs an early downsampling step that this port does not implement
    /// (cannot happen at 15360 Hz; kept so that a change of rate fails loudly).
    #[error("unsupported CQT configuration: {0}")]
    Unsupported(&'static str),
}
