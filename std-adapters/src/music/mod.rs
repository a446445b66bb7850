//! Duolando music features from audio: the 54-d per-frame vector the
//! original models were trained on (librosa 0.8.1, `extractor.py` and
//! `_prepare_music_data.py`), computed natively.
//!
//! Audio mono at 15360 Hz, hop 512 (30 frames/s), n_fft 2048, centred
//! frames. Per frame, in order: MFCC 20 of `power_to_db(mel, ref=max)`,
//! their delta (width 3), chroma_cqt 12 of the HPSS harmonic part (7
//! octaves), onset strength 1 (median over mel bands) of the percussive
//! part, beat one-hot 1 from `beat_track` on that envelope.
//!
//! The same building blocks make Bailando's 438-d features at 3840 Hz
//! (7.5 frames/s): see [`bailando`] and [`FeatureSet`]; Transflower's 85-d
//! audio input at 96 kHz (20 frames/s) is [`transflower`].
//! See docs/MUSIC.md for the facts, the measured deviations and the speed.

pub mod bailando;
pub mod beat;
pub mod cqt;
mod error;
pub mod extractor;
pub mod hpss;
pub mod madmom;
pub mod median;
pub mod mel;
pub mod mfcc;
pub mod octave;
pub mod onset;
pub mod pad;
pub mod stft;
pub mod streaming;
pub mod tempo;
pub mod transflower;
pub mod tuning;

pub use error::MusicError;
pub use extractor::{Extractor, FeatureSet};
pub use streaming::{Streaming, StreamingConfig};

/// Sample rate the Duolando features are defined at.
pub const SAMPLE_RATE: u32 = 15360;
/// Hop in samples (30 frames/s).
pub const HOP: usize = 512;
/// FFT size of the spectrogram, HPSS and onset STFTs.
pub const N_FFT: usize = 2048;
/// Mel bands of the MFCC spectrogram.
pub const N_MELS: usize = 128;
/// Width of one Duolando feature row.
pub const FEATURE_DIM: usize = 54;
/// Shortest accepted input: 3 frames (librosa's delta needs width 3 <= T).
pub const MIN_SAMPLES: usize = 2 * HOP;
/// Column ranges of the groups in a row.
pub const MFCC_COLS: std::ops::Range<usize> = 0..20;
pub const DELTA_COLS: std::ops::Range<usize> = 20..40;
pub const CHROMA_COLS: std::ops::Range<usize> = 40..52;
pub const ONSET_COL: usize = 52;
pub const BEAT_COL: usize = 53;

/// Features of one song: `frames` rows of `dim` values ([`FEATURE_DIM`] = 54
/// for Duolando, [`bailando::FEATURE_DIM`] = 438 for Bailando).
#[derive(Debug, Clone, PartialEq)]
pub struct Features {
    pub frames: usize,
    /// Width of a row.
    pub dim: usize,
    /// (frames, dim) row-major.
    pub data: Vec<f32>,
    /// The global tempo `beat_track` used (0 when the onset envelope is all zero).
    pub tempo_bpm: f64,
}

impl Features {
    /// Row `t` (`dim` values).
    pub fn row(&self, t: usize) -> &[f32] {
        &self.data[t * self.dim..(t + 1) * self.dim]
    }
}

/// The 54-d features of mono samples at 15360 Hz (see [`Extractor`] to reuse plans).
pub fn features(samples_15360hz: &[f32]) -> Result<Features, MusicError> {
    Extractor::new().features(samples_15360hz)
}
