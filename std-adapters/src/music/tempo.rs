//! Global tempo (librosa 0.8.1 `beat.tempo` with its defaults): the
//! autocorrelation tempogram of the onset envelope (8 s Hann windows,
//! centred with a linear ramp to zero, each frame's autocorrelation divided
//! by its maximum), averaged over time, weighted by a log-normal prior
//! around 120 BPM (one octave deviation), lags faster than 320 BPM excluded.

use realfft::RealFftPlanner;

use super::stft::periodic_hann;

/// Autocorrelation window in frames at 30 frames/s (`time_to_frames(8.0)`).
pub fn ac_window(frame_rate: f64) -> usize {
    (8.0 * frame_rate).floor() as usize
}

/// The tempogram averaged over time, (win,): `tg[lag]`.
pub fn mean_tempogram(onset: &[f32], win: usize) -> Vec<f64> {
    let n = onset.len();
    let half = win / 2;
    // linear_ramp padding (f32 like numpy on a float32 envelope)
    let mut padded = vec![0.0f32; n + 2 * half]; // (n + win,)
    let (first, last) = (onset[0], onset[n - 1]);
    for j in 0..half {
        padded[j] = first * (j as f32 / half as f32);
        padded[n + half + j] = last * ((half - 1 - j) as f32 / half as f32);
    }
    padded[half..half + n].copy_from_slice(onset);
    let window = periodic_hann(win);
    let nfft = (2 * win).next_power_of_two();
    let mut planner = RealFftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(nfft);
    let inv = planner.plan_fft_inverse(nfft);
    let mut buf = fwd.make_input_vec(); // (nfft,)
    let mut spec = fwd.make_output_vec(); // (nfft/2+1,)
    let mut sum = vec![0.0f64; win]; // (win,)
    for t in 0..n {
        buf.iter_mut().for_each(|v| *v = 0.0);
        for (j, b) in buf.iter_mut().take(win).enumerate() {
            *b = padded[t + j] as f64 * window[j];
        }
        fwd.process(&mut buf, &mut spec).expect("fixed fft size");
        for c in spec.iter_mut() {
            *c = realfft::num_complex::Complex::new(c.norm_sqr(), 0.0);
        }
        inv.process(&mut spec, &mut buf).expect("fixed fft size");
        let ac = &buf[..win];
        let m = ac.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        let scale = if m < f64::MIN_POSITIVE { 1.0 } else { 1.0 / m };
        for (s, &a) in sum.iter_mut().zip(ac) {
            *s += a * scale;
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
