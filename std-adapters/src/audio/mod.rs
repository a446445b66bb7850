//! Audio files to mono samples at a target rate: WAV through hound,
//! MP3/OGG Vorbis/FLAC through symphonia (MP3 encoder delay and padding
//! trimmed from the LAME/Xing header), channels averaged (essentia's
//! MonoLoader mix), resampled with a Kaiser-windowed sinc (see
//! [`resample`] and docs/MUSIC.md for its deviation from libsamplerate).

mod decode;
mod error;
pub mod resample;

pub use decode::{decode, Decoded};
pub use error::AudioError;

use std::path::Path;

/// Decodes `path`, mixes it to mono and resamples it to `target_sr` Hz.
pub fn load_mono(path: impl AsRef<Path>, target_sr: u32) -> Result<Vec<f32>, AudioError> {
    let path = path.as_ref();
    mono_at(&decode(path)?, path, target_sr)
}

/// [`load_mono`] of an already decoded file (`path` names it in errors).
pub fn mono_at(d: &Decoded, path: &Path, target_sr: u32) -> Result<Vec<f32>, AudioError> {
    let mono = d.mono();
    if mono.is_empty() {
        return Err(AudioError::Empty {
            path: path.to_path_buf(),
        });
    }
    if target_sr == 0 {
        return Err(AudioError::BadRate {
            path: path.to_path_buf(),
            rate: 0,
        });
    }
    Ok(resample::resample(&mono, d.sample_rate, target_sr))
}
