//! The input of madmom's downbeat networks: three framed STFTs of the
//! 44.1 kHz int16 signal (1024, 2048, 4096 samples), each through a
//! logarithmic triangular filterbank (3, 6, 12 bands per octave, 30 Hz to
//! 17 kHz, filters of area 1), `log10(1 + x)`, and its positive difference
//! over `diff_frames`, side by side: (frames, 314) at 44.1 kHz.
//!
//! madmom 0.16.1 facts (`audio/signal.py`, `stft.py`, `filters.py`,
//! `spectrogram.py`): frame `i` is centred on sample `int(i * hop)` with
//! `hop = 44100 / fps`, zero-padded at both ends, `ceil(len / hop)` frames;
//! the window is numpy's symmetric `hanning(n)` divided by 32767 (the int16
//! range: the signal stays integer); `n / 2` bins (no Nyquist bin) of an
//! f64 FFT, magnitudes stored as f32; the filterbank's centre bins are the
//! FFT bins nearest to `440 * 2^(k / bands)` Hz, duplicates dropped.

use std::sync::Arc;

use realfft::{RealFftPlanner, RealToComplex};

/// Sample rate madmom's downbeat processor works at.
pub const SAMPLE_RATE: u32 = 44_100;
/// Frame sizes and bands per octave of the three resolutions.
pub const RESOLUTIONS: [(usize, usize); 3] = [(1024, 3), (2048, 6), (4096, 12)];
/// Filterbank range (Hz) and tuning.
pub const FMIN: f64 = 30.0;
pub const FMAX: f64 = 17_000.0;
pub const FREF: f64 = 440.0;
/// The difference looks back to where the window first exceeds this fraction of its maximum.
pub const DIFF_RATIO: f64 = 0.5;

/// One resolution: window, FFT, sparse filterbank.
struct Resolution {
    n: usize,
    /// (n,) symmetric Hann / 32767.
    window: Vec<f64>,
    fft: Arc<dyn RealToComplex<f64>>,
    /// Per band: (first bin, weights) of its triangular filter (f32, area 1).
    bands: Vec<(usize, Vec<f32>)>,
    /// numpy's `hanning(n)` (the difference's look-back is read off it).
    hann: Vec<f64>,
}

/// The three resolutions' plans; immutable, reusable.
pub struct Frontend {
    res: Vec<Resolution>,
}

/// numpy `hanning(n)`: `0.5 - 0.5 cos(2 pi k / (n - 1))`.
fn hanning(n: usize) -> Vec<f64> {
    if n == 1 {
        return vec![1.0];
    }
    (0..n)
        .map(|k| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / (n - 1) as f64).cos())
        .collect()
}

/// madmom `log_frequencies(bands, fmin, fmax, fref)`.
fn log_frequencies(bands: usize, fmin: f64, fmax: f64, fref: f64) -> Vec<f64> {
    let b = bands as f64;
    let left = ((fmin / fref).log2() * b).floor() as i64;
    let right = ((fmax / fref).log2() * b).ceil() as i64;
    let all: Vec<f64> = (left..right)
        .map(|k| fref * 2f64.powf(k as f64 / b))
        .collect();
    // searchsorted(fmin) (left) .. searchsorted(fmax, 'right')
    let lo = all.partition_point(|&f| f < fmin);
    let hi = all.partition_point(|&f| f <= fmax);
    all[lo..hi.max(lo)].to_vec()
}

/// madmom `frequencies2bins(freqs, bin_freqs, unique_bins=True)`.
fn frequencies_to_bins(freqs: &[f64], bin_freqs: &[f64]) -> Vec<usize> {
    let last = bin_freqs.len() - 1;
    let mut bins: Vec<usize> = freqs
        .iter()
        .map(|&f| {
            let i = bin_freqs.partition_point(|&b| b < f).clamp(1, last);
            let (l, r) = (bin_freqs[i - 1], bin_freqs[i]);
            if f - l < r - f {
                i - 1
            } else {
                i
            }
        })
        .collect();
    bins.sort_unstable();
    bins.dedup();
    bins
}

/// madmom's overlapping `TriangularFilter`s over consecutive bin triples,
/// normalised to area 1 (in f32, as madmom's `Filter`), truncated to `n_bins`.
fn triangular_filters(bins: &[usize], n_bins: usize) -> Vec<(usize, Vec<f32>)> {
    bins.windows(3)
        .map(|t| {
            let (start, mut center, mut stop) = (t[0], t[1], t[2]);
            if stop - start < 2 {
                center = start;
                stop = start + 1;
            }
            let (c, s) = (center - start, stop - start);
            let mut w: Vec<f32> = (0..s)
                .map(|k| {
                    if k < c {
                        (k as f64 / c as f64) as f32
                    } else {
                        (1.0 - (k - c) as f64 / (s - c) as f64) as f32
                    }
                })
                .collect();
            let sum: f32 = w.iter().sum();
            if sum > 0.0 {
                w.iter_mut().for_each(|v| *v /= sum);
            }
            w.truncate(n_bins.saturating_sub(start));
            (start, w)
        })
        .collect()
}

impl Resolution {
    fn new(n: usize, bands_per_octave: usize) -> Self {
        let hann = hanning(n);
        let window = hann.iter().map(|&w| w / 32767.0).collect();
        let n_bins = n / 2;
        let bin_freqs: Vec<f64> = (0..n_bins)
            .map(|k| k as f64 * SAMPLE_RATE as f64 / n as f64)
            .collect();
        let bins = frequencies_to_bins(
            &log_frequencies(bands_per_octave, FMIN, FMAX, FREF),
            &bin_freqs,
        );
        let bands = triangular_filters(&bins, n_bins);
        Resolution {
            n,
            window,
            fft: RealFftPlanner::<f64>::new().plan_fft_forward(n),
            bands,
            hann,
        }
    }

    /// madmom `_diff_frames(0.5, hop, n, hanning)`: Python's `round` (ties to even), at least 1.
    fn diff_frames(&self, hop: f64) -> usize {
        let max = self.hann.iter().cloned().fold(f64::MIN, f64::max);
        let sample = self
            .hann
            .iter()
            .position(|&w| w > DIFF_RATIO * max)
            .unwrap_or(0);
        let diff_samples = self.n as f64 / 2.0 - sample as f64;
        ((diff_samples / hop).round_ties_even() as i64).max(1) as usize
    }

    /// Log-filtered magnitudes of every frame: (frames, bands) row-major.
    fn log_spec(&self, signal: &[i16], hop: f64, frames: usize) -> Vec<f32> {
        let nb = self.bands.len();
        let mut out = vec![0f32; frames * nb];
        let mut buf = self.fft.make_input_vec();
        let mut spec = self.fft.make_output_vec();
        let mut mag = vec![0f32; self.n / 2];
        let len = signal.len() as i64;
        for f in 0..frames {
            let start = (f as f64 * hop) as i64 - (self.n / 2) as i64;
            for (k, b) in buf.iter_mut().enumerate() {
                let i = start + k as i64;
                let x = if (0..len).contains(&i) {
                    signal[i as usize] as f64
                } else {
                    0.0
                };
                *b = x * self.window[k];
            }
            self.fft
                .process(&mut buf, &mut spec)
                .expect("FFT buffers of the plan's size");
            for (m, c) in mag.iter_mut().zip(&spec) {
                // madmom stores the STFT as complex64, then |.| in f32
                let (re, im) = (c.re as f32, c.im as f32);
                *m = re.hypot(im);
            }
            let row = &mut out[f * nb..(f + 1) * nb];
            for (o, (start, w)) in row.iter_mut().zip(&self.bands) {
                let s: f32 = w.iter().zip(&mag[*start..]).map(|(a, b)| a * b).sum();
                *o = (s + 1.0).log10();
            }
        }
        out
    }
}

impl Default for Frontend {
    fn default() -> Self {
        Self::new()
    }
}

impl Frontend {
    pub fn new() -> Self {
        Frontend {
            res: RESOLUTIONS
                .iter()
                .map(|&(n, b)| Resolution::new(n, b))
                .collect(),
        }
    }

    /// Width of one row: spectrogram and difference of each resolution (314).
    pub fn width(&self) -> usize {
        self.res.iter().map(|r| 2 * r.bands.len()).sum()
    }

    /// Frames madmom makes of `len` samples at `fps`: `ceil(len / hop)`.
    pub fn frames(len: usize, fps: f64) -> usize {
        (len as f64 / (SAMPLE_RATE as f64 / fps)).ceil() as usize
    }

    /// The networks' input for `signal` (mono, 44.1 kHz, int16) at `fps`:
    /// (frames, [`Self::width`]) row-major, per resolution its log-filtered
    /// spectrogram then the positive difference (0 in the first
    /// `diff_frames` rows).
    pub fn features(&self, signal: &[i16], fps: f64) -> Vec<f32> {
        let hop = SAMPLE_RATE as f64 / fps;
        let frames = Self::frames(signal.len(), fps);
        let width = self.width();
        let mut out = vec![0f32; frames * width];
        let mut col = 0;
        for r in &self.res {
            let nb = r.bands.len();
            let spec = r.log_spec(signal, hop, frames);
            let df = r.diff_frames(hop);
            for f in 0..frames {
                let row = &mut out[f * width + col..f * width + col + 2 * nb];
                let cur = &spec[f * nb..(f + 1) * nb];
                row[..nb].copy_from_slice(cur);
                if f >= df {
                    let prev = &spec[(f - df) * nb..(f - df + 1) * nb];
                    for ((d, &c), &p) in row[nb..].iter_mut().zip(cur).zip(prev) {
                        *d = (c - p).max(0.0);
                    }
                }
            }
            col += 2 * nb;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_three_resolutions_give_madmoms_314_inputs() {
        let f = Frontend::new();
        let bands: Vec<usize> = f.res.iter().map(|r| r.bands.len()).collect();
        assert_eq!(f.width(), 314, "{bands:?}");
        // at madmom's own 100 fps the 4096-sample frames look back 2 frames, at 20 fps 1
        let d100: Vec<usize> = f.res.iter().map(|r| r.diff_frames(441.0)).collect();
        let d20: Vec<usize> = f.res.iter().map(|r| r.diff_frames(2205.0)).collect();
        assert_eq!(d100, [1, 1, 2]);
        assert_eq!(d20, [1, 1, 1]);
        for r in &f.res {
            for (_, w) in &r.bands {
                let s: f32 = w.iter().sum();
                assert!((s - 1.0).abs() < 1e-5, "{s}");
            }
        }
    }
}
