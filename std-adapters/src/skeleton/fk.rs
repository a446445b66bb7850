//! Forward kinematics: local rotations + root translation -> world
//! positions and rotations.

use super::math::{add, mat_mul, mat_vec, unflatten, Mat3, Vec3};
use super::{parent, Skeleton, JOINTS, POS_DIM, ROT_DIM};

/// World positions and rotations of one frame.
#[derive(Clone, Debug)]
pub struct Pose {
    pub positions: [Vec3; JOINTS], // (55, 3) metres
    pub world: [Mat3; JOINTS],     // (55, 3, 3) world rotations
}

/// One frame of FK: `root` is the pelvis world position, `local[j]` the
/// rotation of joint `j` relative to its parent (`local[0]` is the pelvis
/// world rotation).
pub fn forward_kinematics(skel: &Skeleton, root: Vec3, local: &[Mat3; JOINTS]) -> Pose {
    let mut positions = [[0.0; 3]; JOINTS];
    let mut world = [[[0.0; 3]; 3]; JOINTS];
    positions[0] = root;
    world[0] = local[0];
    for j in 1..JOINTS {
        let p = parent(j).unwrap_or(0);
        positions[j] = add(positions[p], mat_vec(&world[p], skel.offsets[j]));
        world[j] = mat_mul(&world[p], &local[j]);
    }
    Pose { positions, world }
}

/// Reads frame `t`'s 55 local rotations from a (T, 495) row-major buffer.
pub fn frame_rotations(rotmats: &[f32], t: usize) -> [Mat3; JOINTS] {
    let mut out = [[[0.0; 3]; 3]; JOINTS];
    let row = &rotmats[t * ROT_DIM..(t + 1) * ROT_DIM];
    for (j, m) in out.iter_mut().enumerate() {
        *m = unflatten(&row[j * 9..j * 9 + 9]);
    }
    out
}

/// FK over a clip: `roots` (T, 3) and `rotmats` (T, 495) -> positions
/// (T, 165). The caller guarantees matching lengths.
pub fn positions_of_clip(skel: &Skeleton, roots: &[f32], rotmats: &[f32]) -> Vec<f32> {
    let frames = roots.len() / 3;
    let mut out = Vec::with_capacity(frames * POS_DIM); // (T, 165)
    for t in 0..frames {
        let local = frame_rotations(rotmats, t);
        let root = [roots[3 * t], roots[3 * t + 1], roots[3 * t + 2]];
        let pose = forward_kinematics(skel, root, &local);
        out.extend(pose.positions.iter().flatten());
    }
    out
}
