//! Bailando's music features (Li et al., CVPR 2022): the 438-d rows the
//! released GPT reads, at 7.5 frames/s.
//!
//! The authors' preprocessing loads audio at 3840 Hz (15360 * 2 / 8) and
//! makes the same librosa 0.8.1 calls as Duolando's 54-d features (n_fft
//! 2048, hop 512, centred frames), so every group comes from the same
//! building blocks ([`Extractor::bailando`]): per frame, in order,
//! - MFCC 20 of `power_to_db(mel 128 up to 1920 Hz, ref=max)` (0..20),
//! - their delta, width 3 (20..40),
//! - chroma_cqt 12 of the HPSS harmonic part over 5 octaves from C1 (40..52),
//! - onset strength of the percussive part, median over 128 mel bands of
//!   which only the lower 64 lie below 1920 Hz (52),
//! - beat one-hot from `beat_track` on that envelope (53),
//! - the autocorrelation tempogram of the envelope, 384 lags (54..438):
//!   51.2 s centred windows, so each row sees +-25.6 s of the song.
//!
//! See docs/MUSIC.md (Bailando) for the facts and the measured deviations.

use super::extractor::{Extractor, Parts};
use super::{Features, MusicError};

/// Sample rate the features are defined at (`15360 * 2 / 8`).
pub const SAMPLE_RATE: u32 = 3840;
/// Frames per second (3840 / 512).
pub const FRAME_RATE: f64 = 7.5;
/// Width of one row.
pub const FEATURE_DIM: usize = 438;
/// Octaves of the chroma CQT (the original uses 7 only at 30720 Hz).
pub const CHROMA_OCTAVES: usize = 5;
/// Tempogram window in frames (librosa's default `win_length`), = its channel count.
pub const TEMPOGRAM_WIN: usize = 384;
/// Column ranges of the groups in a row.
pub const MFCC_COLS: std::ops::Range<usize> = 0..20;
pub const DELTA_COLS: std::ops::Range<usize> = 20..40;
pub const CHROMA_COLS: std::ops::Range<usize> = 40..52;
pub const ONSET_COL: usize = 52;
pub const BEAT_COL: usize = 53;
pub const TEMPOGRAM_COLS: std::ops::Range<usize> = 54..438;

/// The 438-d features of mono samples at 3840 Hz (see [`Extractor::bailando`] to reuse plans).
pub fn features(samples_3840hz: &[f32]) -> Result<Features, MusicError> {
    Extractor::bailando().features(samples_3840hz)
}

/// Concatenates the groups and a (T, 384) tempogram into (T, 438) rows.
pub fn assemble(p: &Parts, tempogram: &[f32]) -> Features {
    let t = p.onset.len();
    debug_assert_eq!(tempogram.len(), t * TEMPOGRAM_WIN);
    let mut data = vec![0.0f32; t * FEATURE_DIM];
    for (i, row) in data.chunks_exact_mut(FEATURE_DIM).enumerate() {
        row[MFCC_COLS].copy_from_slice(&p.mfcc[i * 20..(i + 1) * 20]);
        row[DELTA_COLS].copy_from_slice(&p.delta[i * 20..(i + 1) * 20]);
        if (i + 1) * 12 <= p.chroma.len() {
            row[CHROMA_COLS].copy_from_slice(&p.chroma[i * 12..(i + 1) * 12]);
        }
        row[ONSET_COL] = p.onset[i];
        row[TEMPOGRAM_COLS].copy_from_slice(&tempogram[i * TEMPOGRAM_WIN..(i + 1) * TEMPOGRAM_WIN]);
    }
    for &b in &p.beats {
        if b < t {
            data[b * FEATURE_DIM + BEAT_COL] = 1.0;
        }
    }
    Features {
        frames: t,
        dim: FEATURE_DIM,
        data,
        tempo_bpm: p.tempo_bpm,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_adds_up() {
        assert_eq!(TEMPOGRAM_COLS.end, FEATURE_DIM);
        assert_eq!(TEMPOGRAM_COLS.len(), TEMPOGRAM_WIN);
        assert_eq!(SAMPLE_RATE as f64 / super::super::HOP as f64, FRAME_RATE);
        assert_eq!(SAMPLE_RATE, 15360 * 2 / 8);
    }

    #[test]
    fn shape_and_tempogram_lag0() {
        // 4 s of clicks at 3840 Hz: 31 frames, lag 0 of every non-zero tempogram row is 1.
        let sr = SAMPLE_RATE as usize;
        let mut y = vec![0.0f32; 4 * sr];
        for k in 0..8 {
            let i = sr / 4 + k * sr / 2;
            for j in 0..60 {
                y[i + j] = 0.8 * (-(j as f32) / 10.0).exp() * (j as f32 * 2.4).sin();
            }
        }
        let f = features(&y).unwrap();
        assert_eq!((f.frames, f.dim, f.data.len()), (31, 438, 31 * 438));
        assert!(f.data.iter().all(|v| v.is_finite()));
        let nonzero_rows = (0..f.frames)
            .filter(|&t| f.row(t)[TEMPOGRAM_COLS].iter().any(|&v| v != 0.0))
            .count();
        assert!(nonzero_rows > 0);
        for t in 0..f.frames {
            let r = &f.row(t)[TEMPOGRAM_COLS];
            if r.iter().any(|&v| v != 0.0) {
                assert!((r[0] - 1.0).abs() < 1e-6, "row {t} lag 0 = {}", r[0]);
                assert!(r.iter().all(|v| v.abs() <= 1.0 + 1e-6));
            }
        }
    }
}
