//! The offline pipeline: samples at 15360 Hz -> (T, 54) features, the
//! original `signal_to_feature` step by step; the same steps at 3840 Hz with
//! 5 chroma octaves and a tempogram make Bailando's (T, 438).

use super::beat::beat_track;
use super::cqt::{chroma_from_cqt, CqtBank, BINS_PER_OCTAVE};
use super::hpss::hpss;
use super::mel::MelBank;
use super::mfcc::{delta3, power_to_db_in_place, Dct, N_MFCC};
use super::onset::{onset_strength_with_top, ONSET_FMAX, ONSET_MELS};
use super::stft::{Stft, C32};
use super::tempo::tempo;
use super::tuning::estimate_tuning;
use super::{Features, MusicError, FEATURE_DIM, HOP, MIN_SAMPLES, N_FFT, N_MELS, SAMPLE_RATE};

/// Which model's music features: the same librosa 0.8.1 calls at another
/// sample rate, plus a tempogram for Bailando.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FeatureSet {
    /// Duolando: (T, 54) at 15360 Hz, 30 frames/s, chroma over 7 octaves.
    #[default]
    Duolando,
    /// Bailando (CVPR 2022): (T, 438) at 3840 Hz, 7.5 frames/s, chroma over
    /// 5 octaves, then a 384-lag tempogram.
    Bailando,
}

impl FeatureSet {
    /// Sample rate the features are defined at.
    pub fn sample_rate(self) -> u32 {
        match self {
            Self::Duolando => SAMPLE_RATE,
            Self::Bailando => super::bailando::SAMPLE_RATE,
        }
    }

    /// Width of a row.
    pub fn dim(self) -> usize {
        match self {
            Self::Duolando => FEATURE_DIM,
            Self::Bailando => super::bailando::FEATURE_DIM,
        }
    }

    /// Octaves of the chroma CQT.
    pub fn chroma_octaves(self) -> usize {
        match self {
            Self::Duolando => super::cqt::N_OCTAVES,
            Self::Bailando => super::bailando::CHROMA_OCTAVES,
        }
    }

    /// Frames per second (`sample_rate / 512`).
    pub fn frame_rate(self) -> f64 {
        self.sample_rate() as f64 / HOP as f64
    }

    /// Lower-case name (`duolando`, `bailando`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Duolando => "duolando",
            Self::Bailando => "bailando",
        }
    }
}

/// Precomputed plans and banks, reusable across songs (immutable, `Sync`).
pub struct Extractor {
    pub(crate) set: FeatureSet,
    pub(crate) stft: Stft,
    /// 128 mels up to the Nyquist frequency (the MFCC spectrogram).
    pub(crate) mel: MelBank,
    /// 128 mels up to 11025 Hz (the onset spectrogram, librosa 0.8.1; at
    /// 3840 Hz only the lower 64 bands reach below the Nyquist frequency).
    pub(crate) onset_mel: MelBank,
    /// 20 x 128 orthonormal DCT-II.
    pub(crate) dct: Dct,
}

impl Default for Extractor {
    fn default() -> Self {
        Self::new()
    }
}

/// Intermediate results of one run, for tests and diagnostics.
pub struct Parts {
    /// (T, 20)
    pub mfcc: Vec<f32>,
    /// (T, 20)
    pub delta: Vec<f32>,
    /// (T, 12)
    pub chroma: Vec<f32>,
    /// (T,)
    pub onset: Vec<f32>,
    /// beat frames
    pub beats: Vec<usize>,
    pub tempo_bpm: f64,
    /// estimated tuning in fractions of a 1/36-octave bin
    pub tuning: f64,
    /// harmonic and percussive signals (len,)
    pub harmonic: Vec<f32>,
    pub percussive: Vec<f32>,
}

impl Extractor {
    /// The Duolando extractor.
    pub fn new() -> Self {
        Self::for_set(FeatureSet::Duolando)
    }

    /// The Bailando extractor (3840 Hz in, (T, 438) out).
    pub fn bailando() -> Self {
        Self::for_set(FeatureSet::Bailando)
    }

    pub fn for_set(set: FeatureSet) -> Self {
        let sr = set.sample_rate() as f64;
        Self {
            set,
            stft: Stft::hann(N_FFT, HOP),
            mel: MelBank::new(sr, N_FFT, N_MELS, 0.0, sr / 2.0),
            onset_mel: MelBank::new(sr, N_FFT, ONSET_MELS, 0.0, ONSET_FMAX),
            dct: Dct::new(N_MELS, N_MFCC),
        }
    }

    /// Checks length and finiteness.
    pub fn validate(y: &[f32]) -> Result<(), MusicError> {
        if y.len() < MIN_SAMPLES {
            return Err(MusicError::TooShort {
                got: y.len(),
                needed: MIN_SAMPLES,
            });
        }
        if let Some((index, &value)) = y.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(MusicError::NonFinite { index, value });
        }
        Ok(())
    }

    /// Which features this extractor makes.
    pub fn set(&self) -> FeatureSet {
        self.set
    }

    /// The features of `y` (mono at [`FeatureSet::sample_rate`]): (T, 54) for
    /// Duolando, (T, 438) for Bailando.
    pub fn features(&self, y: &[f32]) -> Result<Features, MusicError> {
        let p = self.parts(y)?;
        Ok(match self.set {
            FeatureSet::Duolando => assemble(&p),
            FeatureSet::Bailando => {
                let mut tg = Vec::new(); // (T, 384)
                super::tempo::tempogram(&p.onset, super::bailando::TEMPOGRAM_WIN, &mut tg);
                super::bailando::assemble(&p, &tg)
            }
        })
    }

    /// Every group separately.
    pub fn parts(&self, y: &[f32]) -> Result<Parts, MusicError> {
        self.parts_with_reference(y, |window_max| window_max)
    }

    /// As [`Extractor::parts`], with the dB reference of the MFCC spectrogram
    /// chosen by `reference(max mel power of y)` (offline: that max itself;
    /// streaming: a running max).
    pub fn parts_with_reference(
        &self,
        y: &[f32],
        reference: impl FnMut(f32) -> f32,
    ) -> Result<Parts, MusicError> {
        self.parts_with_levels(y, reference, |max_db| max_db)
    }

    /// As [`Extractor::parts_with_reference`], with the level the onset
    /// spectrogram's 80 dB floor hangs from chosen by `onset_top(max dB of
    /// y's onset mel spectrogram)` (offline: that max; streaming: a running max).
    pub fn parts_with_levels(
        &self,
        y: &[f32],
        mut reference: impl FnMut(f32) -> f32,
        onset_top: impl FnOnce(f32) -> f32,
    ) -> Result<Parts, MusicError> {
        Self::validate(y)?;
        let nb = self.stft.n_bins();
        let mut d: Vec<C32> = Vec::new(); // (T, 1025)
        self.stft.forward(y, &mut d);
        let t = d.len() / nb;

        // MFCC of power_to_db(mel, ref=max)
        let power: Vec<f32> = d.iter().map(|c| c.norm() * c.norm()).collect(); // (T, 1025)
        let mut mel = vec![0.0f32; t * N_MELS]; // (T, 128)
        for (p, m) in power.chunks_exact(nb).zip(mel.chunks_exact_mut(N_MELS)) {
            self.mel.apply(p, m);
        }
        let reference = reference(mel.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)));
        power_to_db_in_place(&mut mel, reference);
        let mut mfcc = vec![0.0f32; t * N_MFCC]; // (T, 20)
        for (m, o) in mel.chunks_exact(N_MELS).zip(mfcc.chunks_exact_mut(N_MFCC)) {
            self.dct.apply(m, o);
        }
        let mut delta = vec![0.0f32; t * N_MFCC]; // (T, 20)
        delta3(&mfcc, N_MFCC, &mut delta);
        drop(power);

        // HPSS
        let (mut harmonic, mut percussive) = (Vec::new(), Vec::new());
        hpss(&self.stft, &d, y.len(), &mut harmonic, &mut percussive);

        // chroma_cqt of the harmonic part (tuning estimated on it)
        self.stft.forward(&harmonic, &mut d);
        let mag: Vec<f32> = d.iter().map(|c| c.norm()).collect(); // (T, 1025)
        let sr = self.set.sample_rate() as f64;
        let tuning = estimate_tuning(&mag, N_FFT, sr, BINS_PER_OCTAVE);
        drop(mag);
        let n_octaves = self.set.chroma_octaves();
        let bank = CqtBank::new(sr, tuning, n_octaves)?;
        let mut cqt = Vec::new(); // (T, 252)
        bank.magnitude(&harmonic, HOP, &mut cqt);
        let mut chroma = Vec::new(); // (T, 12)
        chroma_from_cqt(&cqt, n_octaves, &mut chroma);

        // onset strength and beats of the percussive part
        self.stft.forward(&percussive, &mut d);
        let power: Vec<f32> = d.iter().map(|c| c.norm() * c.norm()).collect();
        let mut onset = Vec::new(); // (T,)
        onset_strength_with_top(&power, nb, &self.onset_mel, onset_top, &mut onset);
        let frame_rate = self.set.frame_rate();
        let tempo_bpm = if onset.iter().any(|&v| v != 0.0) {
            tempo(&onset, frame_rate)
        } else {
            0.0
        };
        let beats = beat_track(&onset, frame_rate, tempo_bpm);
        Ok(Parts {
            mfcc,
            delta,
            chroma,
            onset,
            beats,
            tempo_bpm,
            tuning,
            harmonic,
            percussive,
        })
    }
}

/// Concatenates the groups into (T, 54) rows: mfcc 20, delta 20, chroma 12, onset 1, beat 1.
pub fn assemble(p: &Parts) -> Features {
    let t = p.onset.len();
    let mut data = vec![0.0f32; t * FEATURE_DIM];
    for (i, row) in data.chunks_exact_mut(FEATURE_DIM).enumerate() {
        row[..20].copy_from_slice(&p.mfcc[i * 20..(i + 1) * 20]);
        row[20..40].copy_from_slice(&p.delta[i * 20..(i + 1) * 20]);
        if (i + 1) * 12 <= p.chroma.len() {
            row[40..52].copy_from_slice(&p.chroma[i * 12..(i + 1) * 12]);
        }
        row[52] = p.onset[i];
    }
    for &b in &p.beats {
        if b < t {
            data[b * FEATURE_DIM + 53] = 1.0;
        }
    }
    Features {
        frames: t,
        dim: FEATURE_DIM,
        data,
        tempo_bpm: p.tempo_bpm,
    }
}
