//! Constant-Q transform and chroma as librosa 0.8.1 `chroma_cqt` computes
//! them for Duolando (7 octaves at 15360 Hz) and Bailando (5 octaves at
//! 3840 Hz): octaves x 36 bins from C1 (shifted by the estimated tuning), multirate: the top octave's 36 filters are applied to the
//! signal, which is halved (kaiser_fast) before each lower octave, with the
//! hop halved too. Filters are Hann-windowed complex exponentials, L1
//! normalised, FFT'd to 512 bins and sparsified (1% of each row's mass).
//! Chroma sums three CQT bins per pitch class over the octaves and divides
//! each frame by its maximum.

use realfft::num_complex::Complex;
use rustfft::FftPlanner;

use super::octave::Halver;
use super::stft::{periodic_hann, Stft, C32};

/// CQT bins per octave in `chroma_cqt`.
pub const BINS_PER_OCTAVE: usize = 36;
/// Octaves of Duolando's chroma (`n_octaves=7` at 15360 Hz in the original extractor).
pub const N_OCTAVES: usize = 7;
/// Pitch classes.
pub const N_CHROMA: usize = 12;
/// `note_to_hz('C1')`.
pub const C1_HZ: f64 = 32.703_195_662_574_83;
/// librosa's tabulated Hann window bandwidth.
const HANN_BANDWIDTH: f64 = 1.500_183_105_468_75;
/// librosa `BW_FASTEST` (kaiser_fast roll-off).
const BW_FASTEST: f64 = 0.868_212_038_837_778_4;

/// One sparse row of the FFT-domain filter bank.
struct SparseRow {
    /// non-zero bins
    idx: Vec<u32>,
    /// their complex weights (complex64)
    w: Vec<C32>,
}

/// The filter bank of one octave (reused for every octave: all are the same
/// up to the per-octave gain) plus the final length normalisation.
pub struct CqtBank {
    /// 512 at 15360 Hz (and at 3840 Hz: the top octave's filters have the same length in samples).
    n_fft: usize,
    /// Octaves (7 for Duolando, 5 for Bailando).
    n_octaves: usize,
    /// (36,) sparse filters, lowest first.
    rows: Vec<SparseRow>,
    /// (36 n_octaves,) 1/sqrt(filter length) at the input rate.
    inv_sqrt_len: Vec<f32>,
}

fn q_factor() -> f64 {
    1.0 / (2f64.powf(1.0 / BINS_PER_OCTAVE as f64) - 1.0)
}

impl CqtBank {
    /// Builds the bank of `n_octaves` octaves from C1 for `sr` and `tuning`
    /// (fraction of a 1/36-octave bin), for hop 512.
    pub fn new(sr: f64, tuning: f64, n_octaves: usize) -> Result<Self, super::MusicError> {
        if n_octaves == 0 || n_octaves > 10 {
            return Err(super::MusicError::Unsupported(
                "CQT octave count must be 1..=10 (hop 512 halves per octave)",
            ));
        }
        let bpo = BINS_PER_OCTAVE as f64;
        let n_bins = BINS_PER_OCTAVE * n_octaves;
        let fmin = C1_HZ * 2f64.powf(tuning / bpo);
        let q = q_factor();
        let freq = |k: usize| fmin * 2f64.powf(k as f64 / bpo);
        let fmin_t = freq(n_bins - BINS_PER_OCTAVE);
        let fmax_t = freq(n_bins - 1);
        let cutoff = fmax_t * (1.0 + 0.5 * HANN_BANDWIDTH / q);
        let nyquist = sr / 2.0;
        if cutoff >= BW_FASTEST * nyquist {
            return Err(super::MusicError::Unsupported(
                "top CQT octave needs kaiser_best resampling (sample rate too low)",
            ));
        }
        let early = (((BW_FASTEST * nyquist / cutoff).log2().ceil() as i64) - 2).max(0);
        let twos = 9i64; // hop 512 = 2^9
        if early.min((twos - n_octaves as i64 + 1).max(0)) > 0 {
            return Err(super::MusicError::Unsupported(
                "CQT early downsampling (sample rate too high for this port)",
            ));
        }
        // filters of the top octave, at the input rate
        let lengths: Vec<f64> = (0..BINS_PER_OCTAVE)
            .map(|k| q * sr / (fmin_t * 2f64.powf(k as f64 / bpo)))
            .collect();
        let max_len = lengths.iter().copied().fold(0.0, f64::max);
        let n_fft = 2f64.powf(max_len.log2().ceil()) as usize;
        let mut fft = FftPlanner::<f64>::new().plan_fft_forward(n_fft);
        let mut rows = Vec::with_capacity(BINS_PER_OCTAVE);
        for (k, &l) in lengths.iter().enumerate() {
            let f = fmin_t * 2f64.powf(k as f64 / bpo);
            rows.push(Self::filter_row(l, f, sr, n_fft, &mut fft));
        }
        let inv_sqrt_len = (0..n_bins)
            .map(|k| (1.0 / (q * sr / freq(k)).sqrt()) as f32)
            .collect();
        Ok(Self {
            n_fft,
            n_octaves,
            rows,
            inv_sqrt_len,
        })
    }

    /// One filter: windowed exponential, L1-normalised, centred in `n_fft`,
    /// scaled by `length / n_fft`, FFT'd, kept to `n_fft/2+1` bins and sparsified.
    fn filter_row(
        l: f64,
        f: f64,
        sr: f64,
        n_fft: usize,
        fft: &mut std::sync::Arc<dyn rustfft::Fft<f64>>,
    ) -> SparseRow {
        let a = (-l / 2.0).floor() as i64;
        let b = (l / 2.0).floor() as i64;
        let count = (b - a) as usize;
        let win = periodic_hann(count);
        let mut sig: Vec<Complex<f64>> = (0..count)
            .map(|m| {
                let ph = (a + m as i64) as f64 * 2.0 * std::f64::consts::PI * f / sr;
                Complex::new(ph.cos(), ph.sin()) * win[m]
            })
            .collect();
        let l1: f64 = sig.iter().map(|c| c.norm()).sum();
        let lpad = (n_fft - count) / 2;
        let mut buf = vec![Complex::new(0.0, 0.0); n_fft]; // (n_fft,)
        for (m, c) in sig.drain(..).enumerate() {
            // complex64 after normalisation, then scaled by l/n_fft (complex64 again)
            let c = c / l1;
            let c = Complex::new(c.re as f32 as f64, c.im as f32 as f64) * (l / n_fft as f64);
            buf[lpad + m] = Complex::new(c.re as f32 as f64, c.im as f32 as f64);
        }
        fft.process(&mut buf);
        let half = &buf[..n_fft / 2 + 1];
        let mags: Vec<f64> = half.iter().map(|c| c.norm()).collect();
        let norm: f64 = mags.iter().sum();
        let mut sorted = mags.clone();
        sorted.sort_by(f64::total_cmp);
        let mut cum = 0.0;
        let mut thr = sorted[0];
        for &m in &sorted {
            cum += m / norm;
            thr = m;
            if cum >= 0.01 {
                break;
            }
        }
        let mut idx = Vec::new();
        let mut w = Vec::new();
        for (j, (c, &m)) in half.iter().zip(&mags).enumerate() {
            if m >= thr {
                idx.push(j as u32);
                w.push(C32::new(c.re as f32, c.im as f32));
            }
        }
        SparseRow { idx, w }
    }

    /// Octaves of the bank.
    pub fn n_octaves(&self) -> usize {
        self.n_octaves
    }

    /// |CQT| of `y` at hop 512: out becomes (T, 36 n_octaves) row-major, lowest bin first.
    pub fn magnitude(&self, y: &[f32], hop: usize, out: &mut Vec<f32>) {
        let n_octaves = self.n_octaves;
        let n_bins = BINS_PER_OCTAVE * n_octaves;
        let halver = Halver::new();
        let mut cur: Vec<f32> = y.to_vec();
        let mut next = Vec::new();
        let mut spec = Vec::new();
        // per octave responses, (T_i, 36) each, top octave first
        let mut resp: Vec<(usize, Vec<C32>)> = Vec::with_capacity(n_octaves);
        for i in 0..n_octaves {
            if i > 0 {
                halver.halve(&cur, &mut next);
                std::mem::swap(&mut cur, &mut next);
            }
            let h = hop >> i;
            let stft = Stft::ones(self.n_fft, h);
            stft.forward(&cur, &mut spec);
            let nb = stft.n_bins();
            let t = spec.len() / nb;
            let gain = (2f64.powi(i as i32)).sqrt();
            let mut r = vec![C32::new(0.0, 0.0); t * BINS_PER_OCTAVE];
            for (frame, o) in spec
                .chunks_exact(nb)
                .zip(r.chunks_exact_mut(BINS_PER_OCTAVE))
            {
                for (row, o) in self.rows.iter().zip(o.iter_mut()) {
                    let mut acc = Complex::new(0.0f64, 0.0f64);
                    for (&j, w) in row.idx.iter().zip(&row.w) {
                        let w = C32::new((w.re as f64 * gain) as f32, (w.im as f64 * gain) as f32);
                        let p = w * frame[j as usize];
                        acc += Complex::new(p.re as f64, p.im as f64);
                    }
                    *o = C32::new(acc.re as f32, acc.im as f32);
                }
            }
            resp.push((t, r));
        }
        let t = resp.iter().map(|(t, _)| *t).min().unwrap_or(0);
        out.clear();
        out.resize(t * n_bins, 0.0);
        for (i, (_, r)) in resp.iter().enumerate() {
            let base = n_bins - (i + 1) * BINS_PER_OCTAVE;
            for f in 0..t {
                for b in 0..BINS_PER_OCTAVE {
                    let k = base + b;
                    let v = r[f * BINS_PER_OCTAVE + b] * self.inv_sqrt_len[k];
                    out[f * n_bins + k] = v.norm();
                }
            }
        }
    }
}

/// librosa `cq_to_chroma` + `normalize(norm=inf)`: `cqt` is (T, 36 n_octaves), `out` (T, 12).
pub fn chroma_from_cqt(cqt: &[f32], n_octaves: usize, out: &mut Vec<f32>) {
    let n_bins = BINS_PER_OCTAVE * n_octaves;
    let t = cqt.len() / n_bins;
    out.clear();
    out.resize(t * N_CHROMA, 0.0);
    for (c, o) in cqt.chunks_exact(n_bins).zip(out.chunks_exact_mut(N_CHROMA)) {
        for oct in 0..n_octaves {
            let base = oct * BINS_PER_OCTAVE;
            for (p, v) in o.iter_mut().enumerate() {
                // pitch class p gathers bins 3p-1, 3p, 3p+1 of each octave (wrapping in the octave)
                for d in [BINS_PER_OCTAVE - 1, 0, 1] {
                    *v += c[base + (3 * p + d) % BINS_PER_OCTAVE];
                }
            }
        }
        let m = o.iter().fold(0.0f32, |a, &b| a.max(b.abs()));
        if m >= f32::MIN_POSITIVE {
            for v in o.iter_mut() {
                *v /= m;
            }
        }
    }
}
