//! Slaney-style mel filter bank (librosa 0.8.1 `filters.mel`, `htk=False`,
//! `norm='slaney'`), stored sparsely: each filter is one contiguous band.

/// Hz -> mel, Slaney formula (linear below 1 kHz, logarithmic above).
pub fn hz_to_mel(f: f64) -> f64 {
    let f_sp = 200.0 / 3.0;
    let min_log_mel = 1000.0 / f_sp;
    let logstep = (6.4f64).ln() / 27.0;
    if f >= 1000.0 {
        min_log_mel + (f / 1000.0).ln() / logstep
    } else {
        f / f_sp
    }
}

/// mel -> Hz, inverse of [`hz_to_mel`].
pub fn mel_to_hz(m: f64) -> f64 {
    let f_sp = 200.0 / 3.0;
    let min_log_mel = 1000.0 / f_sp;
    let logstep = (6.4f64).ln() / 27.0;
    if m >= min_log_mel {
        1000.0 * (logstep * (m - min_log_mel)).exp()
    } else {
        f_sp * m
    }
}

/// A mel filter bank: `n_mels` triangular filters over `n_fft/2+1` bins.
pub struct MelBank {
    /// (n_mels,) first non-zero bin of each filter.
    start: Vec<usize>,
    /// (n_mels,) weights of each filter from `start` (f32, librosa's dtype).
    weights: Vec<Vec<f32>>,
}

impl MelBank {
    /// librosa `filters.mel(sr, n_fft, n_mels, fmin, fmax)`.
    pub fn new(sr: f64, n_fft: usize, n_mels: usize, fmin: f64, fmax: f64) -> Self {
        let n_bins = n_fft / 2 + 1;
        let fft_f: Vec<f64> = (0..n_bins).map(|k| k as f64 * sr / n_fft as f64).collect();
        let (lo, hi) = (hz_to_mel(fmin), hz_to_mel(fmax));
        let n_pts = n_mels + 2;
        // numpy linspace: start + i * step, last point exactly `hi`.
        let step = (hi - lo) / (n_pts - 1) as f64;
        let mel_f: Vec<f64> = (0..n_pts)
            .map(|i| {
                if i == n_pts - 1 {
                    mel_to_hz(hi)
                } else {
                    mel_to_hz(lo + i as f64 * step)
                }
            })
            .collect();
        let mut start = Vec::with_capacity(n_mels);
        let mut weights = Vec::with_capacity(n_mels);
        for i in 0..n_mels {
            let enorm = 2.0 / (mel_f[i + 2] - mel_f[i]);
            let row: Vec<f32> = fft_f
                .iter()
                .map(|&f| {
                    let lower = -(mel_f[i] - f) / (mel_f[i + 1] - mel_f[i]);
                    let upper = (mel_f[i + 2] - f) / (mel_f[i + 2] - mel_f[i + 1]);
                    // librosa stores the triangle in f32, then scales it by enorm (f64 op, f32 result).
                    ((lower.min(upper).max(0.0) as f32) as f64 * enorm) as f32
                })
                .collect();
            let first = row.iter().position(|&w| w != 0.0).unwrap_or(0);
            let last = row.iter().rposition(|&w| w != 0.0).map_or(0, |p| p + 1);
            start.push(first);
            weights.push(if last > first {
                row[first..last].to_vec()
            } else {
                Vec::new()
            });
        }
        Self { start, weights }
    }

    /// Number of filters.
    pub fn n_mels(&self) -> usize {
        self.start.len()
    }

    /// `out[m] = sum_k W[m,k] * power[k]`; `power` is (n_bins,), `out` is (n_mels,).
    pub fn apply(&self, power: &[f32], out: &mut [f32]) {
        for ((o, &s), w) in out.iter_mut().zip(&self.start).zip(&self.weights) {
            let p = &power[s..s + w.len()];
            *o = dot(w, p);
        }
    }
}

/// f32 dot product with four partial sums (vectorises, like BLAS).
#[inline]
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let ca = a.chunks_exact(8);
    let cb = b.chunks_exact(8);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for j in 0..8 {
            acc[j] += x[j] * y[j];
        }
    }
    let mut s: f32 = acc.iter().sum();
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}
