//! Beat tracking, librosa 0.8.1 `beat_track(onset_envelope, sr)` with
//! `tightness=100`, `trim=True`: Ellis' dynamic programme over the onset
//! envelope (normalised by its standard deviation and smoothed by a
//! Gaussian of one beat period), backtracked from the last strong cumulative
//! score, then trimmed of weak edge beats with 0.8.1's rule: the last beat
//! above the threshold is dropped too (`beats[valid.min():valid.max()]`).

/// Python's `round()` / `np.round` (half to even).
fn round_half_even(x: f64) -> f64 {
    x.round_ties_even()
}

/// Beat frames for `onset` (T,) at `frame_rate` and `bpm`.
pub fn beat_track(onset: &[f32], frame_rate: f64, bpm: f64) -> Vec<usize> {
    if !onset.iter().any(|&v| v != 0.0) || bpm <= 0.0 {
        return Vec::new();
    }
    let period = (60.0 * frame_rate / bpm).round_ties_even() as i64;
    let period = period.max(1);
    let local = local_score(onset, period as usize);
    let (backlink, cum) = dynamic_programme(&local, period);
    let Some(last) = last_beat(&cum) else {
        return Vec::new();
    };
    let mut beats = vec![last];
    while backlink[*beats.last().expect("non-empty")] >= 0 {
        let b = backlink[*beats.last().expect("non-empty")] as usize;
        beats.push(b);
    }
    beats.reverse();
    trim_beats(&local, &beats)
}

/// Onsets divided by their sample standard deviation (ddof 1), convolved
/// ('same') with `exp(-0.5 (32 k / period)^2)`, k in -period..=period.
pub fn local_score(onset: &[f32], period: usize) -> Vec<f64> {
    let n = onset.len();
    let mean = onset.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
    let var = if n > 1 {
        onset
            .iter()
            .map(|&v| (v as f64 - mean).powi(2))
            .sum::<f64>()
            / (n - 1) as f64
    } else {
        0.0
    };
    let std = var.sqrt() as f32;
    let norm: Vec<f32> = if std > 0.0 {
        onset.iter().map(|&v| v / std).collect()
    } else {
        onset.to_vec()
    };
    let p = period as i64;
    let window: Vec<f64> = (-p..=p)
        .map(|k| (-0.5 * (k as f64 * 32.0 / p as f64).powi(2)).exp())
        .collect();
    (0..n as i64)
        .map(|i| {
            let mut s = 0.0;
            for (j, &w) in window.iter().enumerate() {
                let src = i + p - j as i64;
                if src >= 0 && src < n as i64 {
                    s += norm[src as usize] as f64 * w;
                }
            }
            s
        })
        .collect()
}

/// Ellis' DP: `cum[i] = local[i] + max_j (cum[i+d_j] - 100 log(-d_j/period)^2)`
/// over `d_j` in `-2 period ..= -round(period/2)`; returns (backlink, cum).
pub fn dynamic_programme(local: &[f64], period: i64) -> (Vec<i64>, Vec<f64>) {
    let n = local.len();
    let hi = -(round_half_even(period as f64 / 2.0) as i64);
    let offsets: Vec<i64> = (-2 * period..=hi).collect();
    let txwt: Vec<f64> = offsets
        .iter()
        .map(|&d| -100.0 * ((-d as f64) / period as f64).ln().powi(2))
        .collect();
    let max_local = local.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut backlink = vec![0i64; n];
    let mut cum = vec![0.0f64; n];
    let mut first_beat = true;
    for i in 0..n {
        let mut best = 0usize;
        let mut best_v = f64::NEG_INFINITY;
        for (j, (&d, &w)) in offsets.iter().zip(&txwt).enumerate() {
            let src = i as i64 + d;
            let v = if src >= 0 { w + cum[src as usize] } else { w };
            if v > best_v {
                best_v = v;
                best = j;
            }
        }
        cum[i] = local[i] + best_v;
        if first_beat && local[i] < 0.01 * max_local {
            backlink[i] = -1;
        } else {
            backlink[i] = i as i64 + offsets[best];
            first_beat = false;
        }
    }
    (backlink, cum)
}

/// Last frame whose cumulative score exceeds half the median of the local maxima.
pub fn last_beat(cum: &[f64]) -> Option<usize> {
    let n = cum.len();
    let is_max = |i: usize| {
        let prev = cum[i.saturating_sub(1)];
        let next = cum[(i + 1).min(n - 1)];
        cum[i] > prev && cum[i] >= next
    };
    let mut maxima: Vec<f64> = (0..n).filter(|&i| is_max(i)).map(|i| cum[i]).collect();
    if maxima.is_empty() {
        return None;
    }
    maxima.sort_by(f64::total_cmp);
    let m = maxima.len();
    let med = if m % 2 == 1 {
        maxima[m / 2]
    } else {
        (maxima[m / 2 - 1] + maxima[m / 2]) / 2.0
    };
    // `cum * maxes * 2 > med`: frames that are not maxima count as 0.
    (0..n)
        .rev()
        .find(|&i| (if is_max(i) { cum[i] * 2.0 } else { 0.0 }) > med)
}

/// 0.8.1 trimming: smooth the beats' local scores with Hann(5) = [0,.5,1,.5,0],
/// keep `beats[first_valid .. last_valid]` (exclusive end) where valid means
/// above half the RMS of the smoothed scores.
pub fn trim_beats(local: &[f64], beats: &[usize]) -> Vec<usize> {
    let x: Vec<f64> = beats.iter().map(|&b| local[b]).collect();
    let nb = x.len();
    let smooth: Vec<f64> = (0..nb)
        .map(|i| {
            let l = if i > 0 { 0.5 * x[i - 1] } else { 0.0 };
            let r = if i + 1 < nb { 0.5 * x[i + 1] } else { 0.0 };
            l + x[i] + r
        })
        .collect();
    let rms = (smooth.iter().map(|v| v * v).sum::<f64>() / nb as f64).sqrt();
    let thr = 0.5 * rms;
    let valid: Vec<usize> = (0..nb).filter(|&i| smooth[i] > thr).collect();
    match (valid.first(), valid.last()) {
        (Some(&a), Some(&b)) => beats[a..b].to_vec(),
        _ => Vec::new(),
    }
}
