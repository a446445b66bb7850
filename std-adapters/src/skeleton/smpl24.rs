//! Bailando's SMPL 24-joint poses on the SMPL-X rig the viewer, glTF and
//! BVH exports use. SMPL's joints 0-21 are SMPL-X's 0-21 (same names,
//! same order); SMPL's 22 and 23 are the hands (a point in the palm, near
//! the middle finger's base). The SMPL-X joints SMPL lacks are placed
//! rigidly from our rest rig: the fingers of each hand in the frame that
//! takes the rest wrist->middle1 direction onto the pose's wrist->hand
//! direction (the forearm fixing the twist), the jaw and eyes in the frame
//! that takes the rest neck->head direction onto the pose's. So joints
//! 0-21 are the model's own, and the hands point where SMPL's hands are.

use super::math::{self, Vec3};
use super::{joint, rest, JOINTS};

/// SMPL joints per pose.
pub const SMPL_JOINTS: usize = 24;
/// SMPL's hand joints (left, right).
const SMPL_HANDS: [usize; 2] = [22, 23];
/// SMPL-X joints of the face: jaw, left eye, right eye.
const FACE: [usize; 3] = [22, 23, 24];
/// SMPL-X finger joints of the left (25..40) and right (40..55) hand.
const FINGERS: [std::ops::Range<usize>; 2] = [25..40, 40..55];

fn at(p: &[f32], j: usize) -> Vec3 {
    [p[3 * j], p[3 * j + 1], p[3 * j + 2]]
}

/// `(T, 72)` SMPL world positions -> `(T, 165)` SMPL-X world positions.
pub fn to_smplx(pos24: &[f32]) -> Vec<f32> {
    let rest = rest::rest_positions();
    let frames = pos24.len() / (3 * SMPL_JOINTS);
    let mut out = vec![0f32; frames * 3 * JOINTS];
    let wrists = [joint::L_WRIST, joint::R_WRIST];
    let elbows = [joint::L_ELBOW, joint::R_ELBOW];
    let middles = [joint::L_MIDDLE1, joint::R_MIDDLE1];
    for f in 0..frames {
        let p = &pos24[f * 3 * SMPL_JOINTS..(f + 1) * 3 * SMPL_JOINTS];
        let o = &mut out[f * 3 * JOINTS..(f + 1) * 3 * JOINTS];
        o[..22 * 3].copy_from_slice(&p[..22 * 3]);
        let put = |o: &mut [f32], j: usize, v: Vec3| o[3 * j..3 * j + 3].copy_from_slice(&v);
        for side in 0..2 {
            let (w, e) = (at(p, wrists[side]), at(p, elbows[side]));
            let r = math::align(
                math::sub(rest[middles[side]], rest[wrists[side]]),
                math::sub(rest[wrists[side]], rest[elbows[side]]),
                math::sub(at(p, SMPL_HANDS[side]), w),
                math::sub(w, e),
            );
            for j in FINGERS[side].clone() {
                put(
                    o,
                    j,
                    math::add(w, math::mat_vec(&r, math::sub(rest[j], rest[wrists[side]]))),
                );
            }
        }
        let (neck, head) = (at(p, joint::NECK), at(p, joint::HEAD));
        let r = math::swing(
            math::sub(rest[joint::HEAD], rest[joint::NECK]),
            math::sub(head, neck),
        );
        for j in FACE {
            put(
                o,
                j,
                math::add(
                    head,
                    math::mat_vec(&r, math::sub(rest[j], rest[joint::HEAD])),
                ),
            );
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rest rig's own SMPL joints lift back to the rest rig (hands at
    /// rest point along the rest fingers), and a turned pose keeps every
    /// finger at its rest distance from the wrist, the body joints as given.
    #[test]
    fn rest_lifts_to_rest_and_fingers_keep_their_lengths() {
        let rest = rest::rest_positions();
        let mut p24 = vec![0f32; 72];
        for j in 0..22 {
            p24[3 * j..3 * j + 3].copy_from_slice(&rest[j]);
        }
        p24[66..69].copy_from_slice(&rest[joint::L_MIDDLE1]);
        p24[69..72].copy_from_slice(&rest[joint::R_MIDDLE1]);
        let x = to_smplx(&p24);
        for j in 0..JOINTS {
            let d = math::norm(math::sub(at(&x, j), rest[j]));
            assert!(d < 1e-5, "joint {j}: {d} m from rest");
        }
        // The left hand bent 90 degrees at the wrist.
        let w = rest[joint::L_WRIST];
        let mut bent = p24.clone();
        let down = math::add(
            w,
            [0.0, -math::norm(math::sub(rest[joint::L_MIDDLE1], w)), 0.0],
        );
        bent[66..69].copy_from_slice(&down);
        let x = to_smplx(&bent);
        assert!(
            math::norm(math::sub(at(&x, joint::L_MIDDLE1), down)) < 1e-5,
            "the middle finger points where SMPL's hand is"
        );
        for j in 25..40 {
            let want = math::norm(math::sub(rest[j], w));
            let got = math::norm(math::sub(at(&x, j), w));
            assert!((want - got).abs() < 1e-5, "finger joint {j}");
        }
        assert_eq!(&x[..66], &bent[..66]);
    }
}
