//! Foot-skating ratio (Duolando `metric_footskating_dur.py`): the share of
//! frames where the pelvis moves but neither ankle moves relative to the
//! pelvis, as the authors count it:
//!
//! - per frame pair: pelvis displacement with its THIRD coordinate zeroed
//!   (the script assumes z up; on the y-up data it drops a horizontal axis
//!   and keeps the vertical one) above 0.03 m, and both ankle-minus-pelvis
//!   displacements below 0.01 m (per frame, although the comments say m/s);
//! - the first frame pair is never counted, but is in the denominator;
//! - ratio = skating pairs / frame pairs x 100 (percent), summed over every
//!   `.npy` in the folder (the leaders' `_01` files included).

use super::{frames, EvalError, POSE_DIM};

/// Pelvis displacement per frame above which the body travels (m).
pub const PELVIS_THRESHOLD: f64 = 0.03;
/// Ankle-to-pelvis displacement per frame below which a foot is planted (m).
pub const LEG_THRESHOLD: f64 = 0.01;
const PELVIS: usize = 0;
const LANKLE: usize = 7;
const RANKLE: usize = 8;

/// (skating frame pairs, frame pairs) of one (T, 165) clip.
pub fn clip_counts(pos: &[f32]) -> Result<(usize, usize), EvalError> {
    let t_len = frames(pos)?;
    let joint = |t: usize, j: usize| -> [f32; 3] {
        let o = t * POSE_DIM + j * 3;
        [pos[o], pos[o + 1], pos[o + 2]]
    };
    let n_pairs = t_len.saturating_sub(1);
    let mut dur = 0;
    for i in 1..n_pairs {
        // diff between frame i and i + 1 (the authors' np.diff index i).
        let (p0, p1) = (joint(i, PELVIS), joint(i + 1, PELVIS));
        let pv = (((p1[0] - p0[0]) as f64).powi(2) + ((p1[1] - p0[1]) as f64).powi(2)).sqrt();
        let leg = |a: usize| {
            let (a0, a1) = (joint(i, a), joint(i + 1, a));
            let d: f64 = (0..3)
                .map(|c| ((a1[c] - p1[c]) - (a0[c] - p0[c])) as f64)
                .map(|v| v * v)
                .sum();
            d.sqrt()
        };
        if pv > PELVIS_THRESHOLD && leg(LANKLE) < LEG_THRESHOLD && leg(RANKLE) < LEG_THRESHOLD {
            dur += 1;
        }
    }
    Ok((dur, n_pairs))
}

/// Percent of skating frame pairs over clips (sum of counts / sum of pairs).
pub fn ratio(counts: &[(usize, usize)]) -> f64 {
    let (d, n) = counts.iter().fold((0, 0), |(d, n), &(a, b)| (d + a, n + b));
    if n == 0 {
        return 0.0;
    }
    d as f64 / n as f64 * 100.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sliding_body_skates_except_first_pair() {
        // The whole body slides 5 cm per frame along x: feet fixed relative to the pelvis.
        let t = 6;
        let mut pos = vec![0.0f32; t * 165];
        for f in 0..t {
            for j in 0..55 {
                pos[f * 165 + j * 3] = f as f32 * 0.05;
                pos[f * 165 + j * 3 + 1] = j as f32 * 0.01;
            }
        }
        assert_eq!(clip_counts(&pos).unwrap(), (4, 5));
        // Sliding along z is invisible to the authors' test (z is zeroed).
        for f in 0..t {
            for j in 0..55 {
                pos[f * 165 + j * 3] = 0.0;
                pos[f * 165 + j * 3 + 2] = f as f32 * 0.05;
            }
        }
        assert_eq!(clip_counts(&pos).unwrap(), (0, 5));
        assert_eq!(ratio(&[(1, 4), (1, 6)]), 20.0);
    }
}
