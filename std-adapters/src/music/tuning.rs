//! Tuning estimate (librosa 0.8.1 `estimate_tuning` via `piptrack` and
//! `pitch_tuning`): parabolic-interpolated spectral peaks between 150 Hz and
//! 4 kHz above 10% of each frame's maximum, kept if their magnitude reaches
//! the median, folded to a fraction of a CQT bin and histogrammed in steps
//! of 0.01 bin. Returns the left edge of the fullest histogram bin.

/// `estimate_tuning(S=|stft|, sr, n_fft, bins_per_octave)` on a magnitude
/// spectrogram `mag` (T, n_fft/2+1).
pub fn estimate_tuning(mag: &[f32], n_fft: usize, sr: f64, bins_per_octave: usize) -> f64 {
    let nb = n_fft / 2 + 1;
    let bin_hz = sr / n_fft as f64;
    let fmax = 4000.0f64.min(sr / 2.0);
    // bins with 150 <= f < fmax; the first and last bins are never peaks (edge pads)
    let k_lo = (1..nb - 1)
        .find(|&k| k as f64 * bin_hz >= 150.0)
        .unwrap_or(nb - 1);
    let k_hi = (1..nb - 1)
        .take_while(|&k| (k as f64 * bin_hz) < fmax)
        .last()
        .map_or(0, |k| k + 1);
    let mut pitches = Vec::new();
    let mut mags = Vec::new();
    for s in mag.chunks_exact(nb) {
        let max = s.iter().fold(0.0f32, |a, &b| a.max(b));
        let r = 0.1 * max;
        let gated = |k: usize| if s[k] > r { s[k] } else { 0.0 };
        for k in k_lo..k_hi {
            let (a, b, c) = (gated(k - 1), gated(k), gated(k + 1));
            if !(b > a && b >= c) {
                continue;
            }
            let avg = 0.5 * (s[k + 1] - s[k - 1]);
            let mut shift = 2.0 * s[k] - s[k + 1] - s[k - 1];
            if shift.abs() < f32::MIN_POSITIVE {
                shift += 1.0;
            }
            let shift = avg / shift;
            let pitch = ((k as f64 + shift as f64) * sr / n_fft as f64) as f32;
            let m = s[k] + 0.5 * avg * shift;
            if pitch > 0.0 {
                pitches.push(pitch);
                mags.push(m);
            }
        }
    }
    if pitches.is_empty() {
        return 0.0;
    }
    let threshold = median_f32(&mut mags.clone());
    let freqs: Vec<f32> = pitches
        .iter()
        .zip(&mags)
        .filter(|(_, &m)| m >= threshold)
        .map(|(&p, _)| p)
        .collect();
    pitch_tuning(&freqs, bins_per_octave)
}

/// numpy `median` of f32 values (mean of the middle two for even counts).
pub fn median_f32(v: &mut [f32]) -> f32 {
    let n = v.len();
    let mid = n / 2;
    let (_, &mut hi, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    if n % 2 == 1 {
        hi
    } else {
        let lo = v[..mid].iter().copied().fold(f32::NEG_INFINITY, f32::max);
        (lo + hi) / 2.0
    }
}

/// librosa `pitch_tuning(frequencies, resolution=0.01, bins_per_octave)`.
pub fn pitch_tuning(freqs: &[f32], bins_per_octave: usize) -> f64 {
    const N_BINS: usize = 100;
    let edge = |j: usize| {
        if j == N_BINS {
            0.5
        } else {
            j as f64 * (1.0 / N_BINS as f64) - 0.5
        }
    };
    let mut counts = [0usize; N_BINS];
    let mut any = false;
    for &f in freqs.iter().filter(|&&f| f > 0.0) {
        any = true;
        // float32 arithmetic as numpy does it on a float32 array
        let octs = (f / 27.5f32).log2();
        let mut r = (bins_per_octave as f32 * octs).rem_euclid(1.0);
        if r >= 0.5 {
            r -= 1.0;
        }
        let r = r as f64;
        if !(-0.5..=0.5).contains(&r) {
            continue;
        }
        let mut j = (((r + 0.5) * N_BINS as f64) as usize).min(N_BINS - 1);
        if r < edge(j) {
            j -= 1;
        } else if j + 1 < N_BINS && r >= edge(j + 1) {
            j += 1;
        }
        counts[j] += 1;
    }
    if !any {
        return 0.0;
    }
    let best = counts
        .iter()
        .enumerate()
        .fold(0, |b, (j, &c)| if c > counts[b] { j } else { b });
    edge(best)
}
