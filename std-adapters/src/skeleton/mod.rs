//! The SMPL-X 55-joint skeleton: joint names and tree, our own rest
//! offsets, forward kinematics, rotation conversions, and retargeting of
//! raw joint positions onto the rig. See docs/SKELETON.md.
//!
//! Conventions: metres, y up, a dancer at rest faces +z with the left side
//! on +x; rotations are row-major 3x3 matrices acting on column vectors;
//! `local[j]` rotates joint `j`'s frame relative to its parent's;
//! world rotation `G[j] = G[parent] local[j]`, world position
//! `P[j] = P[parent] + G[parent] offset[j]`, and `P[0]` (pelvis) is the
//! root translation.

pub mod body;
pub mod fk;
pub mod ik;
pub mod rest;
pub mod retarget;
pub mod smpl24;
// Rotation helpers shared with the C library (duolando-runtime).
pub use duolando_runtime::skeleton::{math, rotation};

pub use fk::forward_kinematics;
pub use math::{Mat3, Vec3};
pub use retarget::retarget;
pub use rotation::{mat_from_quat, nearest_rotation, quat_from_mat, Quat};

/// Number of SMPL-X joints.
pub const JOINTS: usize = 55;
/// Floats per frame of world positions (55 x xyz).
pub const POS_DIM: usize = JOINTS * 3;
/// Floats per frame of local rotations (55 row-major 3x3).
pub const ROT_DIM: usize = JOINTS * 9;

/// SMPL-X joint names in index order (as in the original code).
pub const JOINT_NAMES: [&str; JOINTS] = [
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "jaw",
    "left_eye_smplhf",
    "right_eye_smplhf",
    "left_index1",
    "left_index2",
    "left_index3",
    "left_middle1",
    "left_middle2",
    "left_middle3",
    "left_pinky1",
    "left_pinky2",
    "left_pinky3",
    "left_ring1",
    "left_ring2",
    "left_ring3",
    "left_thumb1",
    "left_thumb2",
    "left_thumb3",
    "right_index1",
    "right_index2",
    "right_index3",
    "right_middle1",
    "right_middle2",
    "right_middle3",
    "right_pinky1",
    "right_pinky2",
    "right_pinky3",
    "right_ring1",
    "right_ring2",
    "right_ring3",
    "right_thumb1",
    "right_thumb2",
    "right_thumb3",
];

/// Parent of each joint (-1 for the pelvis). Parents precede children.
pub const PARENTS: [i8; JOINTS] = [
    -1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15, 20, 25,
    26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38, 21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49,
    50, 21, 52, 53,
];

/// Named joint indices used across the crate.
pub mod joint {
    pub const PELVIS: usize = 0;
    pub const L_HIP: usize = 1;
    pub const R_HIP: usize = 2;
    pub const SPINE1: usize = 3;
    pub const L_KNEE: usize = 4;
    pub const R_KNEE: usize = 5;
    pub const SPINE2: usize = 6;
    pub const L_ANKLE: usize = 7;
    pub const R_ANKLE: usize = 8;
    pub const SPINE3: usize = 9;
    pub const L_FOOT: usize = 10;
    pub const R_FOOT: usize = 11;
    pub const NECK: usize = 12;
    pub const L_COLLAR: usize = 13;
    pub const R_COLLAR: usize = 14;
    pub const HEAD: usize = 15;
    pub const L_SHOULDER: usize = 16;
    pub const R_SHOULDER: usize = 17;
    pub const L_ELBOW: usize = 18;
    pub const R_ELBOW: usize = 19;
    pub const L_WRIST: usize = 20;
    pub const R_WRIST: usize = 21;
    pub const L_MIDDLE1: usize = 28;
    pub const R_MIDDLE1: usize = 43;
}

/// The parent of `j`, or `None` for the pelvis.
pub fn parent(j: usize) -> Option<usize> {
    usize::try_from(PARENTS[j]).ok()
}

/// The children of `j` in index order.
pub fn children(j: usize) -> impl Iterator<Item = usize> {
    (0..JOINTS).filter(move |&c| parent(c) == Some(j))
}

/// A rig: per-joint rest offsets from the parent (the pelvis offset is
/// unused and zero). Cheap to copy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Skeleton {
    pub offsets: [Vec3; JOINTS], // (55, 3) metres, in the parent's rest frame
}

impl Skeleton {
    /// Our adult rest rig (see [`rest`]) uniformly scaled by `scale`
    /// (1.0 is about 1.75 m tall).
    pub fn adult(scale: f32) -> Skeleton {
        let p = rest::rest_positions();
        let mut offsets = [[0.0; 3]; JOINTS];
        for j in 1..JOINTS {
            let par = parent(j).unwrap_or(0);
            offsets[j] = math::scale(math::sub(p[j], p[par]), scale);
        }
        Skeleton { offsets }
    }

    /// Absolute rest positions (pelvis at the origin, all rotations identity).
    pub fn rest_positions(&self) -> [Vec3; JOINTS] {
        let mut p = [[0.0; 3]; JOINTS];
        for j in 1..JOINTS {
            p[j] = math::add(p[parent(j).unwrap_or(0)], self.offsets[j]);
        }
        p
    }

    /// Length of the bone from `j`'s parent to `j`.
    pub fn bone_length(&self, j: usize) -> f32 {
        math::norm(self.offsets[j])
    }

    /// Pelvis height above the floor when standing at rest: the lower of
    /// the two `foot` (ball) joints sits 1.5 cm above the floor.
    pub fn standing_pelvis_height(&self) -> f32 {
        let p = self.rest_positions();
        -p[joint::L_FOOT][1].min(p[joint::R_FOOT][1]) + 0.015 * self.scale_hint()
    }

    /// Ratio of this rig's thigh length to the adult rig's.
    pub fn scale_hint(&self) -> f32 {
        self.bone_length(joint::L_KNEE) / Skeleton::adult(1.0).bone_length(joint::L_KNEE)
    }
}

impl Default for Skeleton {
    fn default() -> Self {
        Skeleton::adult(1.0)
    }
}
