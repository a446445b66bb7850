//! Kinetic features (the "k" of FID_k / Div_k): 72 floats per clip, for
//! each of the 24 SMPL joints (see [`super::smpl24_rooted`]) the mean
//! horizontal kinetic energy, the mean vertical kinetic energy and the mean
//! "energy expenditure" (acceleration magnitude), as the AIST++ / Bailando
//! extractor the Duolando evaluation imports computes them:
//!
//! - frame time hard-coded to 1/60 s although the data is 30 fps;
//! - velocities averaged over a sliding window of +-2 frame differences
//!   (only the differences that exist near the ends), y up;
//! - the acceleration term divides only the previous position by the frame
//!   time: `v1 = p[i] - p[i-1] / dt` (so it depends on the absolute
//!   position, which is why the clip is first made relative to its first
//!   pelvis);
//! - each feature is a sum over frames 1..T-1 divided by T-1, and the
//!   72-vector is rounded to f32.

use super::{smpl24_rooted, EvalError, V3};

/// The extractor's frame time (s): 1/60 even for 30 fps data.
pub const FRAME_TIME: f64 = 1.0 / 60.0;
/// Half-width of the velocity / acceleration averaging window (frames).
pub const WINDOW: isize = 2;
/// Features per clip: 24 joints x (horizontal, vertical, expenditure).
pub const DIM: usize = 72;
/// Shortest clip with a defined acceleration window everywhere.
pub const MIN_FRAMES: usize = 3;

/// What each of the three features of a joint measures, in column order.
pub const KINDS: [&str; 3] = ["horizontal kinetic energy", "vertical kinetic energy", "energy expenditure"];

/// Name of kinetic feature `i` (joint `i / 3` of SMPL's 24, kind `i % 3`),
/// e.g. "pelvis horizontal kinetic energy"; `None` past [`DIM`]. Joints 22
/// and 23 are the hands (the means of the finger bases, as the extractor's
/// SMPL-24 takes them).
pub fn feature_name(i: usize) -> Option<String> {
    const HANDS: [&str; 2] = ["left_hand", "right_hand"];
    let j = i / 3;
    let joint = match j {
        0..22 => crate::skeleton::JOINT_NAMES[j],
        22 | 23 => HANDS[j - 22],
        _ => return None,
    };
    Some(format!("{joint} {}", KINDS[i % 3]))
}

/// Kinetic features of one SMPL-X clip ((T, 165) positions).
pub fn features(pos: &[f32]) -> Result<Vec<f32>, EvalError> {
    let joints = smpl24_rooted(pos)?;
    features_smpl24(&joints)
}

/// Kinetic features of 24-joint positions (already rooted as the authors do).
pub fn features_smpl24(p: &[[V3; 24]]) -> Result<Vec<f32>, EvalError> {
    let t_len = p.len();
    if t_len < MIN_FRAMES {
        return Err(EvalError::TooShort {
            what: "kinetic features",
            frames: t_len,
            need: MIN_FRAMES,
        });
    }
    let n = t_len as isize;
    let mut out = Vec::with_capacity(DIM);
    for j in 0..24 {
        let (mut horiz, mut vert, mut expend) = (0.0f64, 0.0f64, 0.0f64);
        for i in 1..n {
            // Window-averaged velocity (sum of differences, then / (count * dt)).
            let mut v = [0.0f64; 3];
            let mut count = 0.0f64;
            for w in -WINDOW..=WINDOW {
                let k = i + w;
                if k - 1 < 0 || k >= n {
                    continue;
                }
                for c in 0..3 {
                    v[c] += p[k as usize][j][c] - p[k as usize - 1][j][c];
                }
                count += 1.0;
            }
            let scale = count * FRAME_TIME;
            let h = ((v[0] / scale).powi(2) + (v[2] / scale).powi(2)).sqrt();
            horiz += h * h;
            let vy = (v[1] / scale).abs();
            vert += vy * vy;
            // Window-averaged acceleration with the authors' v1 quirk.
            let mut a = [0.0f64; 3];
            let mut count = 0.0f64;
            for w in -WINDOW..=WINDOW {
                let k = i + w;
                if k - 1 < 0 || k + 1 >= n {
                    continue;
                }
                let (prev, cur, next) =
                    (p[k as usize - 1][j], p[k as usize][j], p[k as usize + 1][j]);
                for c in 0..3 {
                    let v2 = (next[c] - cur[c]) / FRAME_TIME;
                    let v1 = cur[c] - prev[c] / FRAME_TIME;
                    a[c] += (v2 - v1) / FRAME_TIME;
                }
                count += 1.0;
            }
            expend += super::norm([a[0] / count, a[1] / count, a[2] / count]);
        }
        let denom = (t_len - 1) as f64;
        out.push((horiz / denom) as f32);
        out.push((vert / denom) as f32);
        out.push((expend / denom) as f32);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feature_names_follow_the_columns() {
        assert_eq!(feature_name(0).as_deref(), Some("pelvis horizontal kinetic energy"));
        assert_eq!(feature_name(4).as_deref(), Some("left_hip vertical kinetic energy"));
        assert_eq!(feature_name(65).as_deref(), Some("right_wrist energy expenditure"));
        assert_eq!(feature_name(71).as_deref(), Some("right_hand energy expenditure"));
        assert_eq!(feature_name(DIM), None);
    }

    fn still(t: usize) -> Vec<f32> {
        let mut v = vec![0.0f32; t * 165];
        for (i, x) in v.iter_mut().enumerate() {
            *x = (i % 165) as f32 * 0.01;
        }
        v
    }

    #[test]
    fn still_pose_has_no_energy_but_the_quirk_gives_expenditure() {
        let f = features(&still(10)).unwrap();
        assert_eq!(f.len(), DIM);
        for j in 0..24 {
            assert_eq!(f[3 * j], 0.0);
            assert_eq!(f[3 * j + 1], 0.0);
        }
        // v1 = p - p/dt is not zero for a still joint away from the first pelvis.
        assert!(f[3 * 5 + 2] > 0.0);
        // The first pelvis is the origin, so its expenditure is zero.
        assert_eq!(f[2], 0.0);
    }

    #[test]
    fn short_and_ragged_clips_are_named_errors() {
        assert_eq!(
            features(&still(2)).unwrap_err(),
            EvalError::TooShort {
                what: "kinetic features",
                frames: 2,
                need: 3
            }
        );
        assert_eq!(
            features(&[0.0; 7]).unwrap_err(),
            EvalError::Ragged { values: 7 }
        );
    }
}
