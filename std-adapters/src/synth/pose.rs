//! Turns per-frame targets (pelvis, feet, hands, spine and head angles,
//! finger curl) into the 55 local rotations of one dancer, solving legs
//! and arms with two-bone IK.

use super::feet::FootPlace;
use crate::skeleton::fk::{forward_kinematics, Pose};
use crate::skeleton::ik::{self, Chain};
use crate::skeleton::math::{
    add, mat_mul, mat_vec, norm, normalize_or, rot_x, rot_y, rot_z, sub, transpose, Mat3, Vec3,
    IDENTITY,
};
use crate::skeleton::{joint, Skeleton, JOINTS};

/// Everything that defines one frame of a dancer.
#[derive(Clone, Copy, Debug)]
pub struct Targets {
    /// Desired pelvis position; lowered when a foot would be out of reach.
    pub pelvis: Vec3,
    pub heading: f32,
    /// Hip roll (about the forward axis) and pelvis pitch, radians.
    pub roll: f32,
    pub pitch: f32,
    /// Upper-body forward lean and twist (radians, split over 3 spine joints).
    pub lean: f32,
    pub twist: f32,
    pub head_yaw: f32,
    pub head_pitch: f32,
    /// Left, right.
    pub feet: [FootPlace; 2],
    /// Wrist targets (world), left and right.
    pub hands: [Vec3; 2],
    /// Finger curl (radians per segment), left and right.
    pub curl: [f32; 2],
    /// Shoulder raise at the collars (radians), left and right.
    pub collar: [f32; 2],
}

const LEGS: [Chain; 2] = [
    Chain {
        root: joint::L_HIP,
        mid: joint::L_KNEE,
        end: joint::L_ANKLE,
        rest_pole: [0.0, 0.0, 1.0],
    },
    Chain {
        root: joint::R_HIP,
        mid: joint::R_KNEE,
        end: joint::R_ANKLE,
        rest_pole: [0.0, 0.0, 1.0],
    },
];
const ARMS: [Chain; 2] = [
    Chain {
        root: joint::L_SHOULDER,
        mid: joint::L_ELBOW,
        end: joint::L_WRIST,
        rest_pole: [0.0, 0.0, -1.0],
    },
    Chain {
        root: joint::R_SHOULDER,
        mid: joint::R_ELBOW,
        end: joint::R_WRIST,
        rest_pole: [0.0, 0.0, -1.0],
    },
];
/// Fraction of full leg reach allowed before the pelvis is lowered.
const LEG_SLACK: f32 = 0.985;

fn pelvis_rotation(t: &Targets) -> Mat3 {
    mat_mul(&rot_y(t.heading), &mat_mul(&rot_x(t.pitch), &rot_z(t.roll)))
}

/// The pelvis height that keeps both ankle targets within reach.
fn reachable_pelvis(skel: &Skeleton, t: &Targets, g0: &Mat3) -> Vec3 {
    let mut p = t.pelvis;
    for (leg, foot) in LEGS.iter().zip(t.feet.iter()) {
        let hip = add(p, mat_vec(g0, skel.offsets[leg.root]));
        let d = sub(hip, foot.ankle);
        let horiz2 = d[0] * d[0] + d[2] * d[2];
        let r = LEG_SLACK * ik::reach(skel, *leg);
        let max_dy = (r * r - horiz2).max(0.0).sqrt();
        if d[1] > max_dy {
            p[1] -= d[1] - max_dy;
        }
    }
    p
}

/// Local rotations of every finger joint for a curl `c` (left hand `side`
/// = 0 bends about -z, right hand about +z; thumbs fold across the palm).
fn finger_local(j: usize, c: f32) -> Mat3 {
    let (left, k) = if (25..40).contains(&j) {
        (true, j - 25)
    } else {
        (false, j - 40)
    };
    let s = if left { -1.0 } else { 1.0 };
    let thumb = k >= 12;
    match (thumb, k % 3) {
        (false, _) => rot_z(s * c),
        (true, 0) => rot_y(s * 0.6 * c),
        (true, _) => rot_z(s * 0.5 * c),
    }
}

/// Solves one frame. Returns the local rotations and the FK pose.
pub fn solve(skel: &Skeleton, t: &Targets) -> ([Mat3; JOINTS], Pose) {
    let g0 = pelvis_rotation(t);
    let root = reachable_pelvis(skel, t, &g0);
    let mut local = [IDENTITY; JOINTS];
    local[0] = g0;
    let third = |a: f32| a / 3.0;
    for j in [joint::SPINE1, joint::SPINE2, joint::SPINE3] {
        local[j] = mat_mul(&rot_x(third(t.lean)), &rot_y(third(t.twist)));
    }
    local[joint::NECK] = rot_x(0.5 * t.head_pitch);
    local[joint::HEAD] = mat_mul(&rot_y(t.head_yaw), &rot_x(0.5 * t.head_pitch));
    local[joint::L_COLLAR] = rot_z(t.collar[0]);
    local[joint::R_COLLAR] = rot_z(-t.collar[1]);
    for j in 25..JOINTS {
        local[j] = finger_local(j, t.curl[if j < 40 { 0 } else { 1 }]);
    }
    // World frames of the trunk (pelvis and spine, collars) from the locals so far.
    let trunk = forward_kinematics(skel, root, &local);
    let heading_fwd = mat_vec(&rot_y(t.heading), [0.0, 0.0, 1.0]);
    for (i, leg) in LEGS.iter().enumerate() {
        let foot = t.feet[i];
        let foot_rot = rot_y(foot.yaw);
        let toe = mat_vec(&foot_rot, [0.0, 0.0, 1.0]);
        let pole = normalize_or(add(toe, heading_fwd), toe);
        let sol = ik::solve(skel, *leg, trunk.positions[leg.root], foot.ankle, pole);
        local[leg.root] = mat_mul(&transpose(&g0), &sol.root_world);
        local[leg.mid] = mat_mul(&transpose(&sol.root_world), &sol.mid_world);
        local[leg.end] = mat_mul(&transpose(&sol.mid_world), &foot_rot);
    }
    let body = rot_y(t.heading);
    for (i, arm) in ARMS.iter().enumerate() {
        let side = if i == 0 { 1.0 } else { -1.0 };
        let collar = if i == 0 {
            joint::L_COLLAR
        } else {
            joint::R_COLLAR
        };
        let shoulder = trunk.positions[arm.root];
        let reach_dir = sub(t.hands[i], shoulder);
        // Elbow points down, back and out; more out when the hand is high.
        let up = if norm(reach_dir) > 1e-6 {
            reach_dir[1] / norm(reach_dir)
        } else {
            0.0
        };
        let pole = mat_vec(&body, [side * (0.3 + 0.7 * up.max(0.0)), -1.0, -0.4]);
        let sol = ik::solve(skel, *arm, shoulder, t.hands[i], pole);
        local[arm.root] = mat_mul(&transpose(&trunk.world[collar]), &sol.root_world);
        local[arm.mid] = mat_mul(&transpose(&sol.root_world), &sol.mid_world);
    }
    let pose = forward_kinematics(skel, root, &local);
    (local, pose)
}
