//! Errors of audio loading: each names the file and what was expected.

use std::path::PathBuf;

use thiserror::Error;

/// Why an audio file could not be loaded.
#[derive(Debug, Error)]
pub enum AudioError {
    #[error("{path}: cannot read file: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: not a readable WAV file (expected RIFF/WAVE PCM or float): {reason}")]
    Wav { path: PathBuf, reason: String },
    #[error(
        "{path}: not a decodable audio file (expected WAV, MP3, OGG Vorbis or FLAC): {reason}"
    )]
    Format { path: PathBuf, reason: String },
    #[error("{path}: no audio track (expected one decodable audio stream)")]
    NoTrack { path: PathBuf },
    #[error("{path}: invalid sample rate {rate} Hz (expected > 0)")]
    BadRate { path: PathBuf, rate: u32 },
    #[error("{path}: invalid channel count {channels} (expected 1..=32)")]
    BadChannels { path: PathBuf, channels: usize },
    #[error("{path}: decoded to zero samples (expected audio)")]
    Empty { path: PathBuf },
}
