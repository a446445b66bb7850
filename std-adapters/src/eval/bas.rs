//! Beat align score (BAS): how close the motion's beats come to the music's
//! beats, as the Duolando evaluation computes it:
//!
//! - motion beats: the mean over all 55 joints of the per-frame joint
//!   displacement (T - 1 values), smoothed with a Gaussian of sigma 5 frames
//!   (scipy `gaussian_filter`: truncated at 4 sigma, `reflect` edges, the
//!   result stored in the input's float32), then every strict local minimum
//!   (never the first or last value);
//! - music beats: the frames whose beat column (53 of the 54-d features) is
//!   non-zero, among the first T - 1 frames of the music, after motion and
//!   music are cut to the shorter of the two;
//! - score = mean over music beats of exp(-d^2 / (2 * 9)), d the distance
//!   in frames to the nearest motion beat; BAS = mean over clips.

use super::{frames, EvalError, JOINTS, POSE_DIM};

/// Gaussian sigma (frames) of the velocity smoothing.
pub const SIGMA: f64 = 5.0;
/// scipy's default truncation of the Gaussian, in sigmas.
pub const TRUNCATE: f64 = 4.0;
/// The beat column of the 54-d music features.
pub const BEAT_COLUMN: usize = 53;
/// Width of the music features.
pub const MUSIC_DIM: usize = 54;
/// sigma^2 of the score's Gaussian, in frames^2 (the authors' `/ 2 / 9`).
pub const SCORE_VAR: f64 = 9.0;

/// scipy.ndimage `reflect` index: (d c b a | a b c d | d c b a), any distance.
fn reflect(i: isize, n: usize) -> usize {
    let n = n as isize;
    let period = 2 * n;
    let m = i.rem_euclid(period);
    (if m < n { m } else { period - 1 - m }) as usize
}

/// `scipy.ndimage.gaussian_filter1d(x, sigma)` with the defaults, in f64.
pub fn gaussian_filter(x: &[f64], sigma: f64) -> Vec<f64> {
    let radius = (TRUNCATE * sigma + 0.5) as isize;
    let mut w: Vec<f64> = (-radius..=radius)
        .map(|k| (-0.5 / (sigma * sigma) * (k * k) as f64).exp())
        .collect();
    let s: f64 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= s);
    let n = x.len();
    (0..n as isize)
        .map(|i| {
            (-radius..=radius)
                .zip(&w)
                .map(|(k, wk)| wk * x[reflect(i + k, n)])
                .sum()
        })
        .collect()
}

/// Mean joint displacement per frame pair (T - 1 values) of a (T, 165) clip.
pub fn kinetic_velocity(pos: &[f32]) -> Result<Vec<f64>, EvalError> {
    let t_len = frames(pos)?;
    Ok((1..t_len)
        .map(|t| {
            let (a, b) = (
                &pos[(t - 1) * POSE_DIM..t * POSE_DIM],
                &pos[t * POSE_DIM..(t + 1) * POSE_DIM],
            );
            let sum: f64 = (0..JOINTS)
                .map(|j| {
                    let d: f64 = (0..3)
                        .map(|c| (b[j * 3 + c] - a[j * 3 + c]) as f64)
                        .map(|v| v * v)
                        .sum();
                    d.sqrt()
                })
                .sum();
            sum / JOINTS as f64
        })
        .collect())
}

/// Motion beats of a (T, 165) clip: frames (indices into the T - 1
/// velocities) of the strict local minima of the smoothed velocity.
pub fn motion_beats(pos: &[f32]) -> Result<Vec<usize>, EvalError> {
    let vel = kinetic_velocity(pos)?;
    // The authors' float32 files give a float32 filter output: compare in f32.
    let s: Vec<f32> = gaussian_filter(&vel, SIGMA)
        .into_iter()
        .map(|v| v as f32)
        .collect();
    Ok((1..s.len().saturating_sub(1))
        .filter(|&i| s[i] < s[i - 1] && s[i] < s[i + 1])
        .collect())
}

/// Beat frames of (T, 54) music features among the first `length` frames.
pub fn music_beats(music: &[f32], cols: usize, length: usize) -> Result<Vec<usize>, EvalError> {
    if cols != MUSIC_DIM {
        return Err(EvalError::MusicColumns { cols });
    }
    let rows = music.len() / cols;
    Ok((0..rows.min(length))
        .filter(|&t| music[t * cols + BEAT_COLUMN] != 0.0)
        .collect())
}

/// The score of `reference` beats against `motion` beats (the authors' `BA`).
pub fn align(reference: &[usize], motion: &[usize], what: &'static str) -> Result<f64, EvalError> {
    if reference.is_empty() {
        return Err(EvalError::NoReferenceBeats { what });
    }
    if motion.is_empty() {
        return Err(EvalError::NoMotionBeats { what });
    }
    let total: f64 = reference
        .iter()
        .map(|&b| {
            let d2 = motion
                .iter()
                .map(|&m| (m as i64 - b as i64).pow(2))
                .min()
                .unwrap_or(0);
            (-(d2 as f64) / 2.0 / SCORE_VAR).exp()
        })
        .sum();
    Ok(total / reference.len() as f64)
}

/// BAS of one clip against its music features ((T_m, 54)).
pub fn clip_score(pos: &[f32], music: &[f32], music_cols: usize) -> Result<f64, EvalError> {
    let t_len = frames(pos)?;
    if music_cols != MUSIC_DIM {
        return Err(EvalError::MusicColumns { cols: music_cols });
    }
    let n = t_len.min(music.len() / music_cols);
    if n < 2 {
        return Err(EvalError::TooShort {
            what: "beat align score (motion and music)",
            frames: n,
            need: 2,
        });
    }
    let beats = motion_beats(&pos[..n * POSE_DIM])?;
    let mb = music_beats(music, music_cols, n - 1)?;
    align(&mb, &beats, "beat align score")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflect_matches_scipy_layout() {
        // n = 3: ... 2 1 0 | 0 1 2 | 2 1 0 | 0 1 2 ...
        let got: Vec<usize> = (-7..10).map(|i| reflect(i, 3)).collect();
        assert_eq!(got, vec![0, 0, 1, 2, 2, 1, 0, 0, 1, 2, 2, 1, 0, 0, 1, 2, 2]);
        assert_eq!(reflect(5, 1), 0);
    }

    #[test]
    fn gaussian_keeps_constants_and_mass() {
        let x = vec![2.5; 13];
        for v in gaussian_filter(&x, SIGMA) {
            assert!((v - 2.5).abs() < 1e-12);
        }
    }

    #[test]
    fn align_scores() {
        assert_eq!(align(&[10, 20], &[10, 20], "t").unwrap(), 1.0);
        let s = align(&[10], &[13], "t").unwrap();
        assert!((s - (-0.5f64).exp()).abs() < 1e-15);
        assert_eq!(
            align(&[], &[1], "t"),
            Err(EvalError::NoReferenceBeats { what: "t" })
        );
        assert_eq!(
            align(&[1], &[], "t"),
            Err(EvalError::NoMotionBeats { what: "t" })
        );
    }

    #[test]
    fn music_must_be_54_wide() {
        assert_eq!(
            music_beats(&[0.0; 10], 5, 2),
            Err(EvalError::MusicColumns { cols: 5 })
        );
    }
}
