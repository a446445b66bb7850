//! Cross-distance features of a duet (FID_cd / Div_cd, Duolando): for ten
//! joints of each dancer (pelvis, ankles, feet, head, shoulders, wrists:
//! SMPL-X 0, 7, 8, 10, 11, 15, 16, 17, 20, 21) the distance from every
//! follower joint to every leader joint (10 x 10, follower-major), averaged
//! over the frames both clips have. World positions as stored, no rooting.

use super::{frames, EvalError, POSE_DIM};

/// The joints the cross distances are measured between.
pub const POINTS: [usize; 10] = [0, 7, 8, 10, 11, 15, 16, 17, 20, 21];
/// Features per duet.
pub const DIM: usize = 100;

/// The 100 cross distances of one duet, as f32 (the authors' float32 file).
pub fn features(follower: &[f32], leader: &[f32]) -> Result<Vec<f32>, EvalError> {
    let t_len = frames(follower)?.min(frames(leader)?);
    if t_len == 0 {
        return Err(EvalError::TooShort {
            what: "cross-distance features",
            frames: 0,
            need: 1,
        });
    }
    let mut acc = vec![0.0f64; DIM];
    for t in 0..t_len {
        let (f, l) = (&follower[t * POSE_DIM..], &leader[t * POSE_DIM..]);
        for (a, &ja) in POINTS.iter().enumerate() {
            for (b, &jb) in POINTS.iter().enumerate() {
                let d2: f64 = (0..3)
                    .map(|c| (f[ja * 3 + c] - l[jb * 3 + c]) as f64)
                    .map(|v| v * v)
                    .sum();
                acc[a * 10 + b] += d2.sqrt();
            }
        }
    }
    Ok(acc.into_iter().map(|s| (s / t_len as f64) as f32).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shifted_partner_distance() {
        let f = vec![0.0f32; 3 * 165];
        let mut l = vec![0.0f32; 4 * 165];
        for t in 0..4 {
            for j in 0..55 {
                l[t * 165 + j * 3] = 1.5;
            }
        }
        let c = features(&f, &l).unwrap();
        assert!(c.iter().all(|&v| v == 1.5));
        assert_eq!(
            features(&[], &l),
            Err(EvalError::TooShort {
                what: "cross-distance features",
                frames: 0,
                need: 1
            })
        );
    }
}
