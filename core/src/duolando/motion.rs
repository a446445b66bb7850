//! Motion representation around the VQ-VAEs (DESIGN.md §2; the original's
//! dataset normalisation and eval de-normalisation).
//!
//! A pose row is 165 floats: 55 SMPL-X joints x xyz. Normalised: every
//! joint minus the pelvis, the pelvis channel keeping the absolute root;
//! hand joints 25..54 as `(joint - wrist) * 10` (left wrist 20, right 21).
//! Parts are gathered by their joint lists (`Part::joints`), and the
//! pipeline zeroes each part's first joint before encoding.

use crate::duolando::config::{Part, N_JOINTS, POSE_DIM};

/// Left and right wrist joints (hand roots).
pub const LEFT_WRIST: usize = 20;
pub const RIGHT_WRIST: usize = 21;
/// Hand joint ranges (left 25..40, right 40..55).
pub const LEFT_HAND: core::ops::Range<usize> = 25..40;
pub const RIGHT_HAND: core::ops::Range<usize> = 40..55;
/// Scale of hand joints relative to their wrist.
pub const HAND_SCALE: f32 = 10.0;

/// Normalises one raw pose row (165) into `out` (165).
pub fn normalise(raw: &[f32], out: &mut [f32]) {
    let root = [raw[0], raw[1], raw[2]];
    for j in 0..N_JOINTS {
        for a in 0..3 {
            out[3 * j + a] = raw[3 * j + a] - root[a];
        }
    }
    out[..3].copy_from_slice(&root);
    for (hand, wrist) in [(LEFT_HAND, LEFT_WRIST), (RIGHT_HAND, RIGHT_WRIST)] {
        let w = [out[3 * wrist], out[3 * wrist + 1], out[3 * wrist + 2]];
        for j in hand {
            for a in 0..3 {
                out[3 * j + a] = (out[3 * j + a] - w[a]) * HAND_SCALE;
            }
        }
    }
}

/// Inverse of [`normalise`] in place, in the original eval's order: hands
/// `* 0.1 + wrist`, then every joint but the root channel `+ root`.
pub fn denormalise(pose: &mut [f32]) {
    for (hand, wrist) in [(LEFT_HAND, LEFT_WRIST), (RIGHT_HAND, RIGHT_WRIST)] {
        let w = [pose[3 * wrist], pose[3 * wrist + 1], pose[3 * wrist + 2]];
        for j in hand {
            for a in 0..3 {
                pose[3 * j + a] = pose[3 * j + a] * 0.1 + w[a];
            }
        }
    }
    let root = [pose[0], pose[1], pose[2]];
    for j in 1..N_JOINTS {
        for a in 0..3 {
            pose[3 * j + a] += root[a];
        }
    }
}

/// Gathers `part` from normalised rows `pose` (T, 165) into `out`
/// (T, 3J), zeroing the part's first joint (what `encode()` does).
pub fn gather_part(part: Part, pose: &[f32], out: &mut [f32]) {
    let joints = part.joints();
    let w = 3 * joints.len();
    for (row, o) in pose.chunks_exact(POSE_DIM).zip(out.chunks_exact_mut(w)) {
        for (i, &j) in joints.iter().enumerate() {
            o[3 * i..3 * i + 3].copy_from_slice(&row[3 * j as usize..3 * j as usize + 3]);
        }
        o[..3].fill(0.0);
    }
}

/// Scatters part rows `x` (T, per_joint * J) into full rows `out`
/// (T, per_joint * 55) (`per_joint` = 3 for positions, 9 for rotations).
pub fn scatter_part(part: Part, per_joint: usize, x: &[f32], out: &mut [f32]) {
    let joints = part.joints();
    let w = per_joint * joints.len();
    let full = per_joint * N_JOINTS;
    if w == 0 {
        return;
    }
    for (xr, o) in x.chunks_exact(w).zip(out.chunks_exact_mut(full)) {
        for (i, &j) in joints.iter().enumerate() {
            let j = j as usize;
            o[per_joint * j..per_joint * (j + 1)]
                .copy_from_slice(&xr[per_joint * i..per_joint * (i + 1)]);
        }
    }
}
