//! Transflower's 85-d audio features at 20 frames/s, as the authors'
//! `feature_extraction/audio_feature_extraction.sh` builds them
//! (guillefix/transflower-lightning; facts in docs/TRANSFLOWER.md
//! "Audio features").
//!
//! The authors' `process_audio.py` loads the audio at its default
//! `--sampling_rate 96000` (the script never overrides it) and uses
//! hop `round(96000 / 20) = 4800`. Per frame, in column order:
//!
//! - 0..80 `mel`: `power_to_db(melspectrogram(y, sr=96000, n_mels=80,
//!   hop_length=4800), ref=np.max)` (n_fft 2048, centred, Slaney bank up
//!   to 48 kHz, 80 dB floor), first frame dropped (`[1:]`). Reproduced.
//! - 80 `envelope`: `extract_features_envelope(y, sr, hop)` =
//!   `onset_strength(y=y, hop_length=4800, n_mels=100)` (the helper's
//!   default `mel_dim=100`: process_audio.py passes no size), and `sr` is
//!   NOT passed on, so the mel bank is librosa's default sr = 22050
//!   (fmax 11025) laid over the 96 kHz spectrum's bins; dB with
//!   ref 1, positive first difference, MEAN over the bands, one zero in
//!   front (lag 1, `n_fft // (2 hop) = 0`), first frame dropped. Reproduced.
//! - 81, 82 `madmombeats`: madmom's `RNNDownBeatProcessor` (an ensemble of
//!   8 BLSTMs, called with `fps=20` so its 100-fps-trained networks see
//!   20-fps spectral features; its rows are NOT shifted by `[1:]`, so
//!   madmom row k is at k/20 s while the mel/envelope row k is at
//!   (k+1)/20 s). Reproduced by `music::madmom` where the user gives
//!   madmom's networks ([`Beats::Madmom`]: they are CC BY-NC-SA, the engine
//!   ships none); without them [`beat_substitute`] puts the engine's own
//!   beat tracker there instead, at madmom's rough 20-fps levels and with
//!   madmom's one-row offset.
//! - 83, 84 `ddcpca`: 2 PCA components of a Beat Saber step-placement
//!   network's hidden states (the checkpoint and the fitted PCA are not
//!   available). NOT reproduced: 0, the PCA components' mean by
//!   construction; [`TfAudio::features_scaled`] writes them as exactly 0
//!   after scaling (they stand for the scaler's mean).
//!
//! Rows: `floor(len / 4800)` (the centred STFT's `1 + len / hop` frames
//! less the dropped first one; the authors then truncate every part to the
//! shortest, which these two already are).

use std::ops::Range;

use super::beat::beat_track;
use super::mel::MelBank;
use super::mfcc::power_to_db_in_place;
use super::stft::{Stft, C32};
use super::tempo::tempo;
use super::{Features, MusicError};

/// Sample rate the features are defined at (process_audio.py's default).
pub const SAMPLE_RATE: u32 = 96_000;
/// Frames per second.
pub const FPS: f64 = 20.0;
/// Hop in samples: `round(96000 / 20)`.
pub const HOP: usize = 4800;
/// librosa's default FFT size (both the mel and the envelope spectrograms).
pub const N_FFT: usize = 2048;
/// Mel bands of the mel columns (`--mel_feature_size 80`).
pub const N_MELS: usize = 80;
/// Mel bands of the envelope's spectrogram (the helper's default `mel_dim`).
pub const ENVELOPE_MELS: usize = 100;
/// The rate the envelope's mel bank is built for (onset_strength's default sr).
pub const ENVELOPE_SR: f64 = 22_050.0;
/// Width of one row.
pub const FEATURE_DIM: usize = 85;
/// Column groups.
pub const MEL_COLS: Range<usize> = 0..80;
pub const ENVELOPE_COL: usize = 80;
pub const BEAT_COL: usize = 81;
pub const DOWNBEAT_COL: usize = 82;
pub const PCA_COLS: Range<usize> = 83..85;
/// Shortest accepted input: one output row (two STFT frames).
pub const MIN_SAMPLES: usize = HOP;
/// Beats per bar of the downbeat substitute.
pub const BEATS_PER_BAR: usize = 4;

/// The reproduced part of one song: `frames` rows of mel (80) and envelope.
#[derive(Debug, Clone, PartialEq)]
pub struct MelEnvelope {
    pub frames: usize,
    /// (frames, 80) row-major, dB.
    pub mel: Vec<f32>,
    /// (frames,)
    pub envelope: Vec<f32>,
}

/// Plans for the Transflower audio features (immutable, reusable).
pub struct TfAudio {
    stft: Stft,
    mel: MelBank,
    envelope_mel: MelBank,
}

impl Default for TfAudio {
    fn default() -> Self {
        Self::new()
    }
}

impl TfAudio {
    pub fn new() -> Self {
        let sr = SAMPLE_RATE as f64;
        Self {
            stft: Stft::hann(N_FFT, HOP),
            mel: MelBank::new(sr, N_FFT, N_MELS, 0.0, sr / 2.0),
            envelope_mel: MelBank::new(ENVELOPE_SR, N_FFT, ENVELOPE_MELS, 0.0, ENVELOPE_SR / 2.0),
        }
    }

    /// Checks length and finiteness of mono samples at 96 kHz.
    pub fn validate(y: &[f32]) -> Result<(), MusicError> {
        if y.len() < MIN_SAMPLES {
            return Err(MusicError::TooShortAt {
                got: y.len(),
                needed: MIN_SAMPLES,
                rate: SAMPLE_RATE,
                what: "one Transflower frame (hop 4800 at 96 kHz)",
            });
        }
        if let Some((index, &value)) = y.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(MusicError::NonFinite { index, value });
        }
        Ok(())
    }

    /// Mel (80, dB re the song's max) and onset envelope of `y` (mono, 96 kHz).
    pub fn mel_envelope(&self, y: &[f32]) -> Result<MelEnvelope, MusicError> {
        Self::validate(y)?;
        let nb = self.stft.n_bins();
        let mut d: Vec<C32> = Vec::new(); // (T, 1025)
        self.stft.forward(y, &mut d);
        let t = d.len() / nb;
        let power: Vec<f32> = d.iter().map(|c| c.norm() * c.norm()).collect(); // (T, 1025)
        drop(d);

        // mel: power_to_db(melspectrogram, ref=np.max), then [1:]
        let mut mel = vec![0.0f32; t * N_MELS]; // (T, 80)
        for (p, m) in power.chunks_exact(nb).zip(mel.chunks_exact_mut(N_MELS)) {
            self.mel.apply(p, m);
        }
        let max = mel.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        power_to_db_in_place(&mut mel, max);
        mel.drain(..N_MELS);

        // envelope: onset_strength (sr 22050 bank, ref 1, mean), then [1:]
        let nm = ENVELOPE_MELS;
        let mut em = vec![0.0f32; t * nm]; // (T, 100)
        for (p, m) in power.chunks_exact(nb).zip(em.chunks_exact_mut(nm)) {
            self.envelope_mel.apply(p, m);
        }
        power_to_db_in_place(&mut em, 1.0);
        let mut envelope = Vec::with_capacity(t - 1); // frames 1..T
        for i in 1..t {
            let (prev, cur) = (&em[(i - 1) * nm..i * nm], &em[i * nm..(i + 1) * nm]);
            envelope.push(mean_positive_diff(cur, prev));
        }
        Ok(MelEnvelope {
            frames: t - 1,
            mel,
            envelope,
        })
    }

    /// The (T, 85) unscaled features of `y` (mono, 96 kHz), substitutes in
    /// columns 81..85 (see the module docs). `tempo_bpm` is the substitute
    /// beat tracker's tempo.
    pub fn features(&self, y: &[f32]) -> Result<Features, MusicError> {
        self.features_with(y, Beats::Substitute)
    }

    /// The (T, 85) unscaled features of `y` (mono, 96 kHz), columns 81, 82
    /// from `beats`, the PCA columns 0. With madmom's rows, T is the
    /// shorter of the two parts (the authors truncate every part to the
    /// shortest); `tempo_bpm` is 0 (no tempo is estimated).
    pub fn features_with(&self, y: &[f32], beats: Beats<'_>) -> Result<Features, MusicError> {
        let mut me = self.mel_envelope(y)?;
        let (beat, downbeat, tempo_bpm) = match beats {
            Beats::Substitute => beat_substitute(&me.envelope),
            Beats::Madmom(rows) => {
                me.truncate(rows.len());
                let (b, d) = rows[..me.frames].iter().map(|r| (r[0], r[1])).unzip();
                (b, d, 0.0)
            }
        };
        Ok(assemble(&me, &beat, &downbeat, [0.0, 0.0], tempo_bpm))
    }

    /// As [`TfAudio::features`], then standardised by `mean`/`scale` (the
    /// authors' StandardScaler: `(x - mean) / scale`, in f64); the PCA
    /// columns stand for the scaler's mean, so they are exactly 0.
    ///
    /// Panics unless `mean` and `scale` have [`FEATURE_DIM`] values.
    pub fn features_scaled(
        &self,
        y: &[f32],
        mean: &[f64],
        scale: &[f64],
    ) -> Result<Features, MusicError> {
        self.features_scaled_with(y, Beats::Substitute, mean, scale)
    }

    /// [`TfAudio::features_with`], then standardised as [`TfAudio::features_scaled`].
    pub fn features_scaled_with(
        &self,
        y: &[f32],
        beats: Beats<'_>,
        mean: &[f64],
        scale: &[f64],
    ) -> Result<Features, MusicError> {
        assert_eq!(mean.len(), FEATURE_DIM, "scaler width");
        assert_eq!(scale.len(), FEATURE_DIM, "scaler width");
        let mut f = self.features_with(y, beats)?;
        for row in f.data.chunks_exact_mut(FEATURE_DIM) {
            for ((v, &m), &s) in row.iter_mut().zip(mean).zip(scale) {
                *v = ((*v as f64 - m) / s) as f32;
            }
            row[PCA_COLS].fill(0.0);
        }
        Ok(f)
    }
}

/// Where the beat and downbeat columns (81, 82) come from.
#[derive(Clone, Copy, Debug)]
pub enum Beats<'a> {
    /// The engine's beat tracker at madmom's levels ([`beat_substitute`]).
    Substitute,
    /// madmom's `RNNDownBeatProcessor` rows at 20 fps (beat, downbeat), as
    /// `music::madmom::DownbeatRnn::activations` gives them: row k is at
    /// k/20 s, not shifted like the mel rows (the authors' alignment).
    Madmom(&'a [[f32; 2]]),
}

impl MelEnvelope {
    /// Keeps the first `frames` rows (no-op if there are fewer).
    pub fn truncate(&mut self, frames: usize) {
        if frames < self.frames {
            self.frames = frames;
            self.mel.truncate(frames * N_MELS);
            self.envelope.truncate(frames);
        }
    }
}

/// `mean(max(0, cur - prev))` over the bands, accumulated in f64.
fn mean_positive_diff(cur: &[f32], prev: &[f32]) -> f32 {
    let s: f64 = cur
        .iter()
        .zip(prev)
        .map(|(&a, &b)| (a - b).max(0.0) as f64)
        .sum();
    (s / cur.len() as f64) as f32
}

/// Substitute beat activation on a tracked beat and elsewhere: madmom's
/// 20-fps levels read off the goldens (tests/fixtures/transflower_audio:
/// on clicks madmom gives 0.07..0.26 over two rows, its median is 0.008 to
/// 0.019), so that after the authors' scaler the substitute sits in
/// madmom's range instead of tens of standard deviations out.
pub const BEAT_ON: f32 = 0.1;
pub const BEAT_OFF: f32 = 0.01;
/// The same for the downbeat column (madmom: max 0.04..0.07, median 0.002..0.008).
pub const DOWNBEAT_ON: f32 = 0.05;
pub const DOWNBEAT_OFF: f32 = 0.005;

/// The stand-in for madmom's beat and downbeat activations: librosa-style
/// tempo and beat tracking (`beat.rs`, `tempo.rs`) on the 20-fps envelope;
/// a beat tracked at envelope row r (time (r+1)/20 s) marks row r + 1
/// (madmom's time base, see the module docs) with [`BEAT_ON`], every 4th
/// beat (the phase whose beats carry the most envelope) also the downbeat
/// column with [`DOWNBEAT_ON`]; the other rows hold [`BEAT_OFF`] and
/// [`DOWNBEAT_OFF`]. Returns (beat, downbeat, tempo in BPM, 0 for a silent
/// envelope).
pub fn beat_substitute(envelope: &[f32]) -> (Vec<f32>, Vec<f32>, f64) {
    let n = envelope.len();
    let mut beat = vec![BEAT_OFF; n];
    let mut downbeat = vec![DOWNBEAT_OFF; n];
    if n < 2 || !envelope.iter().any(|&v| v != 0.0) {
        return (beat, downbeat, 0.0);
    }
    let bpm = tempo(envelope, FPS);
    let beats = beat_track(envelope, FPS, bpm);
    let phase = (0..BEATS_PER_BAR.min(beats.len()))
        .max_by(|&a, &b| {
            let s = |p: usize| -> f64 {
                beats[p..]
                    .iter()
                    .step_by(BEATS_PER_BAR)
                    .map(|&i| envelope[i] as f64)
                    .sum()
            };
            s(a).total_cmp(&s(b)).then(b.cmp(&a)) // ties: the earliest phase
        })
        .unwrap_or(0);
    for (k, &b) in beats.iter().enumerate() {
        let Some(row) = beat.get_mut(b + 1) else {
            continue;
        };
        *row = BEAT_ON;
        if k >= phase && (k - phase) % BEATS_PER_BAR == 0 {
            downbeat[b + 1] = DOWNBEAT_ON;
        }
    }
    (beat, downbeat, bpm)
}

/// Rows of [mel 80, envelope, beat, downbeat, pca 2].
fn assemble(
    me: &MelEnvelope,
    beat: &[f32],
    downbeat: &[f32],
    pca: [f32; 2],
    tempo_bpm: f64,
) -> Features {
    let mut data = Vec::with_capacity(me.frames * FEATURE_DIM);
    for t in 0..me.frames {
        data.extend_from_slice(&me.mel[t * N_MELS..(t + 1) * N_MELS]);
        data.push(me.envelope[t]);
        data.push(beat[t]);
        data.push(downbeat[t]);
        data.extend_from_slice(&pca);
    }
    Features {
        frames: me.frames,
        dim: FEATURE_DIM,
        data,
        tempo_bpm,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clicks(seconds: f64, bpm: f64) -> Vec<f32> {
        let n = (seconds * SAMPLE_RATE as f64) as usize;
        let mut y = vec![0.0f32; n];
        let period = (60.0 / bpm * SAMPLE_RATE as f64) as usize;
        let mut i = SAMPLE_RATE as usize / 4;
        while i < n {
            for k in 0..(n - i).min(1920) {
                let t = k as f64 / SAMPLE_RATE as f64;
                y[i + k] += (0.8
                    * (2.0 * std::f64::consts::PI * 1500.0 * t).sin()
                    * (-t * 200.0).exp()) as f32;
            }
            i += period;
        }
        y
    }

    #[test]
    fn shape_columns_and_substitutes() {
        let y = clicks(10.0, 120.0);
        let f = TfAudio::new().features(&y).unwrap();
        assert_eq!((f.frames, f.dim), (y.len() / HOP, FEATURE_DIM));
        let col = |c: usize| -> Vec<f32> { (0..f.frames).map(|t| f.row(t)[c]).collect() };
        // mel in dB re the max: max 0, floor -80
        let mel_max = (0..f.frames)
            .flat_map(|t| f.row(t)[MEL_COLS].to_vec())
            .fold(f32::MIN, f32::max);
        assert_eq!(mel_max, 0.0);
        assert!(f.data.iter().all(|v| v.is_finite()));
        // beats at 120 BPM = every 10 frames; downbeats every 40
        let beats: Vec<usize> = (0..f.frames)
            .filter(|&t| f.row(t)[BEAT_COL] == BEAT_ON)
            .collect();
        assert!(beats.len() >= 10, "{beats:?}");
        assert!(beats.windows(2).all(|w| w[1] - w[0] == 10), "{beats:?}");
        assert!((f.tempo_bpm - 120.0).abs() < 5.0, "{}", f.tempo_bpm);
        let downs: Vec<usize> = (0..f.frames)
            .filter(|&t| f.row(t)[DOWNBEAT_COL] == DOWNBEAT_ON)
            .collect();
        assert!(downs.windows(2).all(|w| w[1] - w[0] == 40), "{downs:?}");
        assert!(downs.iter().all(|d| beats.contains(d)));
        assert!(col(PCA_COLS.start)
            .iter()
            .chain(&col(PCA_COLS.start + 1))
            .all(|&v| v == 0.0));
        // the envelope peaks on the clicks
        let env = col(ENVELOPE_COL);
        assert!(env.iter().all(|&v| v >= 0.0));
    }

    #[test]
    fn scaled_standardises_and_centres_pca() {
        let y = clicks(3.0, 100.0);
        let a = TfAudio::new();
        let raw = a.features(&y).unwrap();
        // means not representable in f32: the PCA columns must still be 0
        let mean: Vec<f64> = (0..FEATURE_DIM).map(|c| c as f64 * 0.5 - 3.1).collect();
        let scale: Vec<f64> = (0..FEATURE_DIM).map(|c| 1.0 + c as f64 * 0.1).collect();
        let s = a.features_scaled(&y, &mean, &scale).unwrap();
        for t in 0..raw.frames {
            for c in 0..FEATURE_DIM {
                let want = if PCA_COLS.contains(&c) {
                    0.0
                } else {
                    ((raw.row(t)[c] as f64 - mean[c]) / scale[c]) as f32
                };
                assert_eq!(s.row(t)[c], want, "t {t} c {c}");
            }
        }
    }

    #[test]
    fn refuses_short_and_non_finite() {
        let a = TfAudio::new();
        assert!(matches!(
            a.features(&vec![0.1; HOP - 1]),
            Err(MusicError::TooShortAt { .. })
        ));
        let f = a.features(&vec![0.0; HOP]).unwrap();
        assert_eq!(f.frames, 1);
        let mut y = vec![0.0; 2 * HOP];
        y[7] = f32::NAN;
        assert!(matches!(
            a.features(&y),
            Err(MusicError::NonFinite { index: 7, .. })
        ));
    }
}
