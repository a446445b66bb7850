//! Onset strength (librosa 0.8.1 `onset_strength(aggregate=np.median)`):
//! a 128-band mel power spectrogram whose bank reaches 11025 Hz (0.8.1's
//! default `fmax` even at 15360 Hz, so the top bands are empty), converted
//! to dB (ref 1, floor at max - 80 dB), first difference over time, negative
//! changes dropped, median over bands, shifted right by 3 frames (lag 1 +
//! centring `n_fft / (2 hop)`), zeros in front.

use super::mel::MelBank;
use super::mfcc::power_to_db_with_top;
use super::tuning::median_f32;

/// The onset mel bank's upper edge in librosa 0.8.1.
pub const ONSET_FMAX: f64 = 11025.0;
/// Mel bands of the onset spectrogram.
pub const ONSET_MELS: usize = 128;
/// Frames the envelope is delayed by (lag 1 + n_fft/(2 hop) = 2).
pub const ONSET_SHIFT: usize = 3;

/// `mel_db` (T, 128) is the dB mel spectrogram; `out` becomes (T,).
pub fn onset_from_mel_db(mel_db: &[f32], out: &mut Vec<f32>) {
    let n = ONSET_MELS;
    let t = mel_db.len() / n;
    out.clear();
    out.resize(t, 0.0);
    let mut diff = vec![0.0f32; n]; // (128,)
    for i in 1..t {
        let (prev, cur) = (&mel_db[(i - 1) * n..i * n], &mel_db[i * n..(i + 1) * n]);
        for ((d, &a), &b) in diff.iter_mut().zip(cur).zip(prev) {
            *d = (a - b).max(0.0);
        }
        let v = median_f32(&mut diff);
        // diff i (between frames i-1 and i) lands at frame (i - 1) + ONSET_SHIFT
        let dst = i - 1 + ONSET_SHIFT;
        if dst < t {
            out[dst] = v;
        }
    }
}

/// Onset envelope from a power spectrogram `power` (T, n_bins).
pub fn onset_strength(power: &[f32], n_bins: usize, bank: &MelBank, out: &mut Vec<f32>) {
    onset_strength_with_top(power, n_bins, bank, |top| top, out);
}

/// As [`onset_strength`], with the 80 dB floor hung from `top(max dB)`
/// (offline: the max itself; streaming: a running max).
pub fn onset_strength_with_top(
    power: &[f32],
    n_bins: usize,
    bank: &MelBank,
    top: impl FnOnce(f32) -> f32,
    out: &mut Vec<f32>,
) {
    let t = power.len() / n_bins;
    let mut mel = vec![0.0f32; t * ONSET_MELS]; // (T, 128)
    for (p, m) in power
        .chunks_exact(n_bins)
        .zip(mel.chunks_exact_mut(ONSET_MELS))
    {
        bank.apply(p, m);
    }
    power_to_db_with_top(&mut mel, 1.0, top);
    onset_from_mel_db(&mel, out);
}
