//! Global tempo (librosa 0.8.1 `beat.tempo` with its defaults): the
//! autocorrelation tempogram of the onset envelope (8 s Hann windows,
//! centred with a linear ramp to zero, each frame's autocorrelation divided
//! by its maximum), averaged over time, weighted by a log-normal prior
//! around 120 BPM (one octave deviation), lags faster than 320 BPM excluded;
//! and the per-frame tempogram itself (Bailando's 384 channels).

use std::sync::Arc;

use realfft::num_complex::Complex;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};

use super::stft::periodic_hann;

/// Autocorrelation window in frames at 30 frames/s (`time_to_frames(8.0)`).
pub fn ac_window(frame_rate: f64) -> usize {
    (8.0 * frame_rate).floor() as usize
}

/// The onset envelope padded by `half` frames each side with numpy's
/// `linear_ramp` to zero (f32 like numpy on a float32 envelope): (n + 2 half,).
pub fn ramp_padded(onset: &[f32], half: usize) -> Vec<f32> {
    let n = onset.len();
    let mut padded = vec![0.0f32; n + 2 * half];
    let (first, last) = (onset[0], onset[n - 1]);
    for j in 0..half {
        padded[j] = first * (j as f32 / half as f32);
        padded[n + half + j] = last * ((half - 1 - j) as f32 / half as f32);
    }
    padded[half..half + n].copy_from_slice(onset);
    padded
}

/// One column of librosa's autocorrelation tempogram: a `win`-frame segment
/// of the envelope times a periodic Hann window, autocorrelated (lags
/// 0..win, zero-padded FFT), divided by its largest magnitude
/// (`normalize(norm=inf)`: an all-zero column stays zero).
pub struct LocalAutocorr {
    win: usize,
    window: Vec<f64>,
    fwd: Arc<dyn RealToComplex<f64>>,
    inv: Arc<dyn ComplexToReal<f64>>,
    /// (nfft,) time-domain scratch
    buf: Vec<f64>,
    /// (nfft/2+1,) spectrum scratch
    spec: Vec<Complex<f64>>,
}

impl LocalAutocorr {
    pub fn new(win: usize) -> Self {
        let nfft = (2 * win).next_power_of_two();
        let mut planner = RealFftPlanner::<f64>::new();
        let fwd = planner.plan_fft_forward(nfft);
        let inv = planner.plan_fft_inverse(nfft);
        let (buf, spec) = (fwd.make_input_vec(), fwd.make_output_vec());
        Self {
            win,
            window: periodic_hann(win),
            fwd,
            inv,
            buf,
            spec,
        }
    }

    /// Window length in frames.
    pub fn win(&self) -> usize {
        self.win
    }

    /// `seg` is (win,) envelope frames; `out` (win,) receives the normalised autocorrelation.
    pub fn column(&mut self, seg: &[f32], out: &mut [f64]) {
        let win = self.win;
        self.buf.iter_mut().for_each(|v| *v = 0.0);
        for ((b, &x), &w) in self.buf.iter_mut().zip(&seg[..win]).zip(&self.window) {
            *b = x as f64 * w;
        }
        self.fwd
            .process(&mut self.buf, &mut self.spec)
            .expect("fixed fft size");
        for c in self.spec.iter_mut() {
            *c = Complex::new(c.norm_sqr(), 0.0);
        }
        self.inv
            .process(&mut self.spec, &mut self.buf)
            .expect("fixed fft size");
        let ac = &self.buf[..win];
        let m = ac.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        // the inverse FFT is unnormalised; normalising by the max removes that scale too
        let scale = if m < f64::MIN_POSITIVE { 1.0 } else { 1.0 / m };
        for (o, &a) in out.iter_mut().zip(ac) {
            *o = a * scale;
        }
    }
}

/// librosa `feature.tempogram(onset_envelope, win_length=win)` (centred,
/// Hann, `norm=inf`): `out` becomes (T, win) row-major, one row per onset
/// frame, lag 0 first.
pub fn tempogram(onset: &[f32], win: usize, out: &mut Vec<f32>) {
    let n = onset.len();
    let padded = ramp_padded(onset, win / 2);
    let mut ac = LocalAutocorr::new(win);
    let mut col = vec![0.0f64; win]; // (win,)
    out.clear();
    out.reserve(n * win);
    for t in 0..n {
        ac.column(&padded[t..t + win], &mut col);
        out.extend(col.iter().map(|&v| v as f32));
    }
}

/// The tempogram averaged over time, (win,): `tg[lag]`.
pub fn mean_tempogram(onset: &[f32], win: usize) -> Vec<f64> {
    let n = onset.len();
    let padded = ramp_padded(onset, win / 2);
    let mut ac = LocalAutocorr::new(win);
    let mut col = vec![0.0f64; win]; // (win,)
    let mut sum = vec![0.0f64; win]; // (win,)
    for t in 0..n {
        ac.column(&padded[t..t + win], &mut col);
        for (s, &a) in sum.iter_mut().zip(&col) {
            *s += a;
        }
    }
    sum.iter().map(|s| s / n as f64).collect()
}

/// Best tempo from a mean tempogram: BPM of lag `k` is `60 frame_rate / k`.
pub fn tempo_from_tempogram(tg: &[f64], frame_rate: f64) -> f64 {
    let bpm = |k: usize| 60.0 * frame_rate / k as f64;
    let start = (1..tg.len()).find(|&k| bpm(k) < 320.0).unwrap_or(tg.len());
    let mut best = start;
    let mut best_score = f64::NEG_INFINITY;
    for (k, &v) in tg.iter().enumerate().skip(start) {
        let prior = -0.5 * (bpm(k).log2() - 120f64.log2()).powi(2);
        let score = (1e6 * v).ln_1p() + prior;
        if score > best_score {
            best_score = score;
            best = k;
        }
    }
    bpm(best)
}

/// librosa `beat.tempo(onset_envelope, sr, hop)` for `frame_rate = sr / hop`.
pub fn tempo(onset: &[f32], frame_rate: f64) -> f64 {
    let win = ac_window(frame_rate);
    tempo_from_tempogram(&mean_tempogram(onset, win), frame_rate)
}
