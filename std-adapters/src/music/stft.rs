//! Centred short-time Fourier transform and its overlap-add inverse, as
//! librosa 0.8.1 `stft`/`istft` compute them (numpy-reflect padding of
//! `n_fft/2`, periodic window, `1 + len/hop` frames, window-sum-square
//! normalisation on the way back). FFTs run in f64 (numpy does), results
//! are stored as complex f32 (librosa's complex64).

use std::sync::Arc;

use realfft::num_complex::Complex;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};

use super::pad::reflect_pad_into;

/// Complex f32, librosa's `complex64`.
pub type C32 = Complex<f32>;

/// An STFT plan: window and FFTs for one `(n_fft, hop)`. Immutable, `Sync`.
pub struct Stft {
    pub n_fft: usize,
    pub hop: usize,
    /// (n_fft,) analysis/synthesis window.
    window: Vec<f64>,
    fwd: Arc<dyn RealToComplex<f64>>,
    inv: Arc<dyn ComplexToReal<f64>>,
}

impl Stft {
    /// Periodic Hann window (scipy `get_window('hann', n, fftbins=True)`).
    pub fn hann(n_fft: usize, hop: usize) -> Self {
        let w = periodic_hann(n_fft);
        Self::with_window(w, hop)
    }

    /// Rectangular window (`window='ones'`, used by the CQT).
    pub fn ones(n_fft: usize, hop: usize) -> Self {
        Self::with_window(vec![1.0; n_fft], hop)
    }

    fn with_window(window: Vec<f64>, hop: usize) -> Self {
        let n_fft = window.len();
        let mut planner = RealFftPlanner::<f64>::new();
        Self {
            n_fft,
            hop,
            window,
            fwd: planner.plan_fft_forward(n_fft),
            inv: planner.plan_fft_inverse(n_fft),
        }
    }

    /// `n_fft/2 + 1`.
    pub fn n_bins(&self) -> usize {
        self.n_fft / 2 + 1
    }

    /// Number of centred frames of a signal of `len` samples.
    pub fn n_frames(&self, len: usize) -> usize {
        1 + len / self.hop
    }

    /// Forward transform. `out` becomes (T, n_bins) row-major, T = `n_frames(y.len())`.
    /// `y` must not be empty.
    pub fn forward(&self, y: &[f32], out: &mut Vec<C32>) {
        let n_bins = self.n_bins();
        let t = self.n_frames(y.len());
        let mut padded = Vec::new(); // (len + n_fft,)
        reflect_pad_into(y, self.n_fft / 2, &mut padded);
        let mut frame = self.fwd.make_input_vec(); // (n_fft,)
        let mut spec = self.fwd.make_output_vec(); // (n_bins,)
        let mut scratch = self.fwd.make_scratch_vec();
        out.clear();
        out.resize(t * n_bins, C32::new(0.0, 0.0));
        for (i, row) in out.chunks_exact_mut(n_bins).enumerate() {
            let seg = &padded[i * self.hop..i * self.hop + self.n_fft];
            for ((f, &x), &w) in frame.iter_mut().zip(seg).zip(&self.window) {
                *f = x as f64 * w;
            }
            self.fwd
                .process_with_scratch(&mut frame, &mut spec, &mut scratch)
                .expect("fft sizes fixed at plan time");
            for (o, s) in row.iter_mut().zip(&spec) {
                *o = C32::new(s.re as f32, s.im as f32);
            }
        }
    }

    /// Inverse transform of (T, n_bins) frames to `length` samples
    /// (librosa `istft(..)` followed by `fix_length(.., length)`).
    pub fn inverse(&self, spec: &[C32], length: usize, out: &mut Vec<f32>) {
        let n_bins = self.n_bins();
        let t = spec.len() / n_bins;
        let total = self.n_fft + self.hop * (t.max(1) - 1);
        let mut acc = vec![0.0f64; total]; // (n_fft + hop*(T-1),) overlap-add
        let mut wss = vec![0.0f64; total]; // window sum-square
        let mut buf = self.inv.make_input_vec(); // (n_bins,)
        let mut frame = self.inv.make_output_vec(); // (n_fft,)
        let mut scratch = self.inv.make_scratch_vec();
        let norm = 1.0 / self.n_fft as f64;
        for (i, row) in spec.chunks_exact(n_bins).enumerate() {
            for (b, s) in buf.iter_mut().zip(row) {
                *b = Complex::new(s.re as f64, s.im as f64);
            }
            buf[0].im = 0.0;
            buf[n_bins - 1].im = 0.0;
            self.inv
                .process_with_scratch(&mut buf, &mut frame, &mut scratch)
                .expect("fft sizes fixed at plan time");
            let o = i * self.hop;
            for (j, (&x, &w)) in frame.iter().zip(&self.window).enumerate() {
                acc[o + j] += x * norm * w;
                wss[o + j] += w * w;
            }
        }
        let tiny = f32::MIN_POSITIVE as f64;
        for (a, &s) in acc.iter_mut().zip(&wss) {
            if s > tiny {
                *a /= s;
            }
        }
        out.clear();
        let start = self.n_fft / 2;
        out.extend(acc.iter().skip(start).take(length).map(|&x| x as f32));
        out.resize(length, 0.0);
    }
}

/// Periodic Hann window of length `n`.
pub fn periodic_hann(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_is_identity() {
        let stft = Stft::hann(2048, 512);
        let y: Vec<f32> = (0..10_000)
            .map(|i| ((i as f32) * 0.013).sin() + 0.1 * ((i * 7 % 13) as f32 - 6.0))
            .collect();
        let mut spec = Vec::new();
        stft.forward(&y, &mut spec);
        assert_eq!(spec.len(), stft.n_frames(y.len()) * 1025);
        let mut back = Vec::new();
        stft.inverse(&spec, y.len(), &mut back);
        let err = y
            .iter()
            .zip(&back)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(err < 1e-5, "round trip error {err}");
    }
}
