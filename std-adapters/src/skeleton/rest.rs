//! Our own adult rest pose in the SMPL-X joint layout (not SMPL-X data).
//!
//! Absolute rest joint positions in metres with the pelvis at the origin,
//! y up, facing +z, the subject's left on +x, arms in a T-pose along +-x
//! with palms down. Proportions follow an adult of about 1.75 m: pelvis
//! 0.935 m above the floor when standing, thigh 0.38 m, shin 0.41 m,
//! upper arm 0.26 m, forearm 0.25 m, hand 0.19 m. Right-side joints are
//! the left-side ones mirrored in x.

use super::JOINTS;

/// Left-side and centre joints (index, x, y, z); right-side joints are
/// derived by mirroring (see [`MIRROR`]).
const LEFT_AND_CENTRE: [(usize, [f32; 3]); 31] = [
    (0, [0.0, 0.0, 0.0]),         // pelvis
    (1, [0.058, -0.082, -0.018]), // left_hip
    (3, [0.0, 0.108, -0.026]),    // spine1
    (4, [0.100, -0.460, -0.010]), // left_knee
    (6, [0.0, 0.245, -0.012]),    // spine2
    (7, [0.085, -0.865, -0.045]), // left_ankle
    (9, [0.0, 0.300, 0.010]),     // spine3
    (10, [0.110, -0.920, 0.075]), // left_foot (ball of the foot)
    (12, [0.0, 0.530, -0.020]),   // neck
    (13, [0.075, 0.420, -0.005]), // left_collar
    (15, [0.0, 0.620, 0.030]),    // head
    (16, [0.170, 0.450, -0.020]), // left_shoulder
    (18, [0.430, 0.440, -0.040]), // left_elbow
    (20, [0.680, 0.440, -0.040]), // left_wrist
    (22, [0.0, 0.590, 0.060]),    // jaw
    (23, [0.031, 0.685, 0.090]),  // left_eye_smplhf
    (25, [0.768, 0.435, -0.015]), // left_index1
    (26, [0.801, 0.430, -0.013]), // left_index2
    (27, [0.823, 0.426, -0.012]), // left_index3
    (28, [0.775, 0.437, -0.038]), // left_middle1
    (29, [0.807, 0.432, -0.038]), // left_middle2
    (30, [0.831, 0.428, -0.038]), // left_middle3
    (31, [0.755, 0.430, -0.080]), // left_pinky1
    (32, [0.775, 0.426, -0.081]), // left_pinky2
    (33, [0.793, 0.423, -0.082]), // left_pinky3
    (34, [0.766, 0.433, -0.060]), // left_ring1
    (35, [0.796, 0.428, -0.061]), // left_ring2
    (36, [0.818, 0.425, -0.062]), // left_ring3
    (37, [0.705, 0.425, -0.010]), // left_thumb1
    (38, [0.735, 0.420, 0.015]),  // left_thumb2
    (39, [0.760, 0.417, 0.033]),  // left_thumb3
];

/// (right joint, left joint) pairs mirrored in x.
pub const MIRROR: [(usize, usize); 22] = [
    (2, 1),
    (5, 4),
    (8, 7),
    (11, 10),
    (14, 13),
    (17, 16),
    (19, 18),
    (21, 20),
    (24, 23),
    (40, 25),
    (41, 26),
    (42, 27),
    (43, 28),
    (44, 29),
    (45, 30),
    (46, 31),
    (47, 32),
    (48, 33),
    (49, 34),
    (50, 35),
    (51, 36),
    (52, 37),
];
/// The right thumb joints 53 and 54 mirror 38 and 39 (kept apart from
/// [`MIRROR`] only to keep that table on a few lines).
const MIRROR_THUMB: [(usize, usize); 2] = [(53, 38), (54, 39)];

/// Absolute rest positions of all 55 joints (pelvis at the origin).
pub fn rest_positions() -> [[f32; 3]; JOINTS] {
    let mut p = [[0.0f32; 3]; JOINTS];
    for (j, xyz) in LEFT_AND_CENTRE {
        p[j] = xyz;
    }
    for (r, l) in MIRROR.iter().chain(MIRROR_THUMB.iter()) {
        p[*r] = [-p[*l][0], p[*l][1], p[*l][2]];
    }
    p
}

/// Every joint that is the mirror image of another, as (joint, mirror).
pub fn mirror_of(j: usize) -> usize {
    for (r, l) in MIRROR.iter().chain(MIRROR_THUMB.iter()) {
        if *r == j {
            return *l;
        }
        if *l == j {
            return *r;
        }
    }
    j
}
