//! Harmonic/percussive source separation (librosa 0.8.1 `effects.hpss`):
//! median filters of width 31 across time (harmonic) and across frequency
//! (percussive) of the STFT magnitude, soft masks with power 2 (ties at zero
//! split 0.5/0.5), masked STFTs inverted back to audio.

use super::median::RunningMedian;
use super::stft::{Stft, C32};

/// Median filter width in frames (harmonic) and bins (percussive).
pub const KERNEL: usize = 31;

/// librosa `util.softmask(X, X_ref, power=2, split_zeros=True)` for one pair,
/// returning `(mask_x, mask_ref)`.
#[inline]
pub fn soft_masks(h: f32, p: f32) -> (f32, f32) {
    let z = h.max(p);
    if z < f32::MIN_POSITIVE {
        return (0.5, 0.5);
    }
    let mh = (h / z) * (h / z);
    let mp = (p / z) * (p / z);
    (mh / (mh + mp), mp / (mp + mh))
}

/// Splits the STFT `d` (T, n_bins) of a signal of `len` samples into harmonic
/// and percussive signals (each `len` samples).
pub fn hpss(
    stft: &Stft,
    d: &[C32],
    len: usize,
    harmonic: &mut Vec<f32>,
    percussive: &mut Vec<f32>,
) {
    let nb = stft.n_bins();
    let t = d.len() / nb;
    let mag: Vec<f32> = d.iter().map(|c| c.norm()).collect(); // (T, n_bins)
    let mut harm = vec![0.0f32; mag.len()]; // (T, n_bins) median across time
    let mut perc = vec![0.0f32; mag.len()]; // (T, n_bins) median across frequency
    let mut rm = RunningMedian::new(KERNEL);
    for (m, p) in mag.chunks_exact(nb).zip(perc.chunks_exact_mut(nb)) {
        rm.filter(m, p);
    }
    let mut col = vec![0.0f32; t]; // (T,) one bin over time
    let mut col_out = vec![0.0f32; t];
    for k in 0..nb {
        for (i, c) in col.iter_mut().enumerate() {
            *c = mag[i * nb + k];
        }
        rm.filter(&col, &mut col_out);
        for (i, &v) in col_out.iter().enumerate() {
            harm[i * nb + k] = v;
        }
    }
    let mut dh = Vec::with_capacity(d.len()); // (T, n_bins)
    let mut dp = Vec::with_capacity(d.len()); // (T, n_bins)
    for ((&c, &h), &p) in d.iter().zip(&harm).zip(&perc) {
        let (mh, mp) = soft_masks(h, p);
        dh.push(c * mh);
        dp.push(c * mp);
    }
    stft.inverse(&dh, len, harmonic);
    stft.inverse(&dp, len, percussive);
}
