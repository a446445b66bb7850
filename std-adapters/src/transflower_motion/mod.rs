//! Transflower's generated motion features -> a skeleton: the reverse of
//! the authors' pymo feature pipeline (feature_extraction/process_motions.py
//! with analysis/pymo/preprocessing.py), so that `duolando generate` can
//! show and export what a Transflower model dances. docs/TRANSFLOWER.md
//! "Motion to a skeleton".
//!
//! - [`scaler`]: the StandardScaler undone (`z * scale + mean`);
//! - [`layout`]: which of the 69 / 67 columns is which;
//! - [`expmap`]: each joint's exponential map -> rotation;
//! - [`decode`] (here): the root integrated from its per-frame deltas as
//!   pymo's `RootTransformer('pos_rot_deltas').inverse_transform` does,
//!   then forward kinematics on a [`skeleton::TfSkeleton`];
//! - [`smpl24`] (here): the joints named as SMPL's 24, which the existing
//!   exports lift onto the SMPL-X rig (`skeleton::smpl24`).

pub mod expmap;
pub mod layout;
pub mod scaler;
pub mod skeleton;

use anyhow::{bail, Result};

use expmap::{about_y, apply, mul, rotation, Mat3d};
use layout::Layout;
use skeleton::TfSkeleton;

/// Frames per second of Transflower's motion features (`*_20`).
pub const FPS: f32 = 20.0;

/// Joint positions and world rotations of a decoded clip.
#[derive(Clone, Debug)]
pub struct Decoded {
    pub frames: usize,
    pub joints: usize,
    pub positions: Vec<f64>, // (N, J, 3) skeleton units
    pub world: Vec<Mat3d>,   // (N, J) world rotations
}

/// Decodes `features` ((N, C) unscaled, pymo's feature space) on `skel`.
///
/// The root, as pymo's inverse: heading `h_0 = 0`, `h_t = h_{t-1} +
/// dYrotation_t`; trajectory `a_0 = 0`, `a_t = a_{t-1} + R_y(h_t)
/// (dXposition_t, 0, dZposition_t)` (frame 0's deltas are never used);
/// root position `a_t + R_y(h_t) (Xposition_t, 0, Zposition_t)` with
/// height `Yposition_t` (x and z are 0 in the 67-d layout, as pymo's
/// ConstantsRemover restores them); root rotation `R_y(h_t)
/// R(expmap_root)`. Every other joint: `G_j = G_parent R(expmap_j)`,
/// `P_j = P_parent + G_parent offset_j`; joints the pipeline drops
/// (Spine2, fingers) keep their rest rotation.
pub fn decode(features: &[f64], layout: &Layout, skel: &TfSkeleton) -> Decoded {
    let (c, nj) = (layout.width, skel.joints());
    let frames = features.len() / c;
    let mut local: Vec<Option<usize>> = vec![None; nj];
    for &(j, col) in &layout.rotations {
        local[j] = Some(col);
    }
    let r = layout.root;
    let mut positions = Vec::with_capacity(frames * nj * 3);
    let mut world = Vec::with_capacity(frames * nj);
    let (mut heading, mut traj) = (0.0f64, [0.0f64; 3]);
    for t in 0..frames {
        let row = &features[t * c..(t + 1) * c];
        if t > 0 {
            heading += row[r.dyaw];
            let d = apply(&about_y(heading), [row[r.dx], 0.0, row[r.dz]]);
            traj = [traj[0] + d[0], 0.0, traj[2] + d[2]];
        }
        let hy = about_y(heading);
        let own = apply(
            &hy,
            [
                r.x.map_or(0.0, |k| row[k]),
                0.0,
                r.z.map_or(0.0, |k| row[k]),
            ],
        );
        let root = [traj[0] + own[0], row[r.y], traj[2] + own[2]];
        let base = world.len();
        for ((cols, parent), offset) in local.iter().zip(&skel.parents).zip(&skel.offsets) {
            let rot = cols.map_or(about_y(0.0), |k| rotation([row[k], row[k + 1], row[k + 2]]));
            let (p, g) = match *parent {
                None => (root, mul(&hy, &rot)),
                Some(q) => {
                    let gq = world[base + q];
                    let o = apply(&gq, *offset);
                    let pq = &positions[(base + q) * 3..(base + q) * 3 + 3];
                    ([pq[0] + o[0], pq[1] + o[1], pq[2] + o[2]], mul(&gq, &rot))
                }
            };
            positions.extend_from_slice(&p);
            world.push(g);
        }
    }
    Decoded {
        frames,
        joints: nj,
        positions,
        world,
    }
}

/// SMPL's 24 joint names in the Mixamo naming of the authors' skeleton
/// (smpl2mixamo.py's map): SMPL joints 0..=21, in SMPL order.
pub use crate::cli::dance::leader_bvh::MIXAMO_BODY;

/// Distance (metres) from the wrist to SMPL's hand joint when the skeleton
/// has no `<Side>HandMiddle1` (mixamo.bvh's middle-finger base: 0.095 m
/// along the forearm).
pub const HAND_REACH_M: f64 = 0.095;

/// The decoded clip as SMPL 24-joint positions, (N, 72) float32 METRES,
/// for the SMPL-X exports (`skeleton::smpl24::to_smplx`). Joints 0..=21
/// are the skeleton's joints of [`MIXAMO_BODY`] (a missing `Spine2`, as in
/// the authors' data/fixed_skeleton.bvh, sits halfway between `Spine1` and
/// `Neck`); the hands (22, 23) sit at the skeleton's `<Side>HandMiddle1`
/// rest offset from the wrist, turned with it, or [`HAND_REACH_M`] along
/// the rest forearm.
pub fn smpl24(d: &Decoded, skel: &TfSkeleton) -> Result<Vec<f32>> {
    let find = |n: &str| skel.find(n);
    let mut src: Vec<Option<usize>> = MIXAMO_BODY.iter().map(|n| find(n)).collect();
    let missing: Vec<&str> = MIXAMO_BODY
        .iter()
        .zip(&src)
        .filter(|(n, s)| s.is_none() && **n != "Spine2")
        .map(|(n, _)| *n)
        .collect();
    if !missing.is_empty() {
        bail!(
            "skeleton {}: no joint {} to show as SMPL's body",
            skel.source,
            missing.join(", ")
        );
    }
    let spine2_between = if src[9].is_none() {
        Some((find("Spine1"), find("Neck")))
    } else {
        None
    };
    src[9] = src[9].or(Some(0));
    let mut hands = Vec::with_capacity(2);
    for side in ["Left", "Right"] {
        let wrist = find(&format!("{side}Hand")).unwrap_or(0);
        let h =
            match find(&format!("{side}HandMiddle1")).filter(|&m| skel.parents[m] == Some(wrist)) {
                Some(m) => skel.offsets[m],
                None => {
                    let o = skel.offsets[wrist];
                    let n = (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt();
                    if n == 0.0 {
                        [0.0; 3]
                    } else {
                        o.map(|v| v / n * HAND_REACH_M * skel.units_per_metre)
                    }
                }
            };
        hands.push((wrist, h));
    }
    let per_m = skel.units_per_metre;
    let mut out = Vec::with_capacity(d.frames * 72);
    for t in 0..d.frames {
        let at = |j: usize| {
            let k = (t * d.joints + j) * 3;
            [d.positions[k], d.positions[k + 1], d.positions[k + 2]]
        };
        for (i, s) in src.iter().enumerate() {
            let p = match (i, spine2_between) {
                (9, Some((Some(a), Some(b)))) => {
                    let (a, b) = (at(a), at(b));
                    [
                        0.5 * (a[0] + b[0]),
                        0.5 * (a[1] + b[1]),
                        0.5 * (a[2] + b[2]),
                    ]
                }
                _ => at(s.unwrap_or(0)),
            };
            out.extend(p.map(|v| (v / per_m) as f32));
        }
        for &(w, h) in &hands {
            let (p, o) = (at(w), apply(&d.world[t * d.joints + w], h));
            out.extend([0, 1, 2].map(|k| ((p[k] + o[k]) / per_m) as f32));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At rest with no deltas every joint is where the table puts it, the
    /// root at its height; a constant heading step turns the dancer and the
    /// trajectory follows the turned deltas.
    #[test]
    fn rest_and_turning_root() {
        let s = TfSkeleton::default();
        let l = Layout::new(&s, 67).unwrap();
        let mut f = vec![0.0f64; 3 * 67];
        for t in 0..3 {
            f[t * 67 + l.root.y] = 1.0;
            f[t * 67 + l.root.dx] = 0.1;
            f[t * 67 + l.root.dyaw] = std::f64::consts::FRAC_PI_2;
        }
        let d = decode(&f, &l, &s);
        let rest = s.rest_positions();
        for (j, r) in rest.iter().enumerate() {
            for (k, &v) in r.iter().enumerate() {
                let want = v + if k == 1 { 1.0 } else { 0.0 };
                assert!((d.positions[j * 3 + k] - want).abs() < 1e-12, "joint {j}");
            }
        }
        // Frame 1: heading 90 degrees, moved 0.1 along R_y(90) x = -z.
        let root1 = &d.positions[22 * 3..22 * 3 + 3];
        assert!(
            (root1[0]).abs() < 1e-12 && (root1[2] + 0.1).abs() < 1e-12,
            "{root1:?}"
        );
        // Frame 2: heading 180 degrees, the next 0.1 along -x.
        let root2 = &d.positions[44 * 3..44 * 3 + 3];
        assert!(
            (root2[0] + 0.1).abs() < 1e-12 && (root2[2] + 0.1).abs() < 1e-12,
            "{root2:?}"
        );
        // The left hip (+x at rest) points along -z... turned by 180 degrees: -x.
        let hip = s.find("LeftUpLeg").unwrap();
        assert!(d.positions[(44 + hip) * 3] < root2[0] - 0.08);
    }

    #[test]
    fn smpl24_of_the_rest_pose() {
        let s = TfSkeleton::default();
        let l = Layout::new(&s, 67).unwrap();
        let d = decode(&vec![0.0; 67], &l, &s);
        let p = smpl24(&d, &s).unwrap();
        assert_eq!(p.len(), 72);
        let rest = s.rest_positions();
        let lw = s.find("LeftHand").unwrap();
        assert!(
            (p[22 * 3] as f64 - (rest[lw][0] + HAND_REACH_M)).abs() < 1e-6,
            "left hand point along +x"
        );
        assert!((p[9 * 3 + 1] as f64 - rest[s.find("Spine2").unwrap()][1]).abs() < 1e-6);
    }
}
