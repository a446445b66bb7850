//! Which feature column is what. The authors' pipeline
//! (feature_extraction/process_motions.py) ends in pymo's Numpyfier, whose
//! column order follows from the steps before it:
//!
//! - `RootTransformer('pos_rot_deltas')` rewrites the root's position
//!   (x and z become 0: the trajectory moves into the deltas) and
//!   rotation (heading removed) in place and APPENDS `<root>_dXposition`,
//!   `<root>_dZposition`, `<root>_dYrotation`;
//! - `JointSelector(SELECTED, include_root=True)` keeps the root and the
//!   20 joints of [`SELECTED`], channels grouped per joint in that list's
//!   order (the root's: X/Y/Zposition, its 3 rotations, the 3 deltas);
//! - `MocapParameterizer('expmap')` walks the skeleton in BVH file order,
//!   drops each joint's 3 Euler columns and INSERTS `_alpha, _beta,
//!   _gamma` (the expmap's x, y, z) at column 0, so the expmaps come
//!   first, in REVERSE file order (the root's last);
//! - then the root's `Xposition, Yposition, Zposition, dXposition,
//!   dZposition, dYrotation`: 3 x 21 + 6 = 69 features (`expmap_scaled_20`);
//!   `ConstantsRemover(only_cols=[Hips_Xposition, Hips_Zposition])` drops
//!   the two constant ones: 67 (`expmap_cr_scaled_20`).
//!
//! With the authors' skeletons (mixamo.bvh, data/fixed_skeleton.bvh) the 67
//! columns are RightHand, RightForeArm, RightArm, RightShoulder, Head,
//! Neck, LeftHand, LeftForeArm, LeftArm, LeftShoulder, Spine1, Spine,
//! RightToeBase, RightFoot, RightLeg, RightUpLeg, LeftToeBase, LeftFoot,
//! LeftLeg, LeftUpLeg, Hips (3 each, 0..63), Hips_Yposition (63),
//! Hips_dXposition, Hips_dZposition, Hips_dYrotation (64..67).

use anyhow::{bail, Result};

use super::skeleton::TfSkeleton;

/// The joints process_motions.py's JointSelector keeps (besides the root),
/// in its list order.
pub const SELECTED: [&str; 20] = [
    "Spine",
    "Spine1",
    "Neck",
    "Head",
    "RightShoulder",
    "RightArm",
    "RightForeArm",
    "RightHand",
    "LeftShoulder",
    "LeftArm",
    "LeftForeArm",
    "LeftHand",
    "RightUpLeg",
    "RightLeg",
    "RightFoot",
    "RightToeBase",
    "LeftUpLeg",
    "LeftLeg",
    "LeftFoot",
    "LeftToeBase",
];

/// Columns of the root's position and per-frame deltas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RootColumns {
    /// `<root>_Xposition` / `_Zposition`: present in the 69-d layout only.
    pub x: Option<usize>,
    pub y: usize,
    pub z: Option<usize>,
    /// Per-frame translation in the heading frame, and heading change
    /// (radians about +y).
    pub dx: usize,
    pub dz: usize,
    pub dyaw: usize,
}

/// The column layout of one feature width on one skeleton.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    pub width: usize,
    /// (joint, first of its 3 expmap columns), for every kept joint.
    pub rotations: Vec<(usize, usize)>,
    pub root: RootColumns,
}

impl Layout {
    /// The layout of `width` features on `skel`: the skeleton must have
    /// every joint of [`SELECTED`]; `width` must be 3 n + 6 or 3 n + 4
    /// (n = kept joints, 21).
    pub fn new(skel: &TfSkeleton, width: usize) -> Result<Layout> {
        let missing: Vec<&str> = SELECTED
            .iter()
            .copied()
            .filter(|n| skel.find(n).is_none())
            .collect();
        if !missing.is_empty() {
            bail!("skeleton {}: lacks {} of the 20 joints the authors' pipeline keeps ({}); the features cannot be placed on it", skel.source, missing.len(), missing.join(", "));
        }
        let kept: Vec<usize> = (0..skel.joints())
            .filter(|&j| skel.parents[j].is_none() || SELECTED.contains(&skel.names[j].as_str()))
            .collect();
        let n = kept.len();
        let rotations: Vec<(usize, usize)> = kept
            .iter()
            .rev()
            .enumerate()
            .map(|(k, &j)| (j, 3 * k))
            .collect();
        let b = 3 * n;
        let root = if width == b + 6 {
            RootColumns {
                x: Some(b),
                y: b + 1,
                z: Some(b + 2),
                dx: b + 3,
                dz: b + 4,
                dyaw: b + 5,
            }
        } else if width == b + 4 {
            RootColumns {
                x: None,
                y: b,
                z: None,
                dx: b + 1,
                dz: b + 2,
                dyaw: b + 3,
            }
        } else {
            bail!(
                "{width} features per frame do not fit skeleton {}: its {n} kept joints give {} (expmap_scaled_20) or {} (expmap_cr_scaled_20, without the constant root x and z)",
                skel.source,
                b + 6,
                b + 4
            );
        };
        Ok(Layout {
            width,
            rotations,
            root,
        })
    }

    /// pymo's column names, in order (for checks against the pipeline).
    pub fn column_names(&self, skel: &TfSkeleton) -> Vec<String> {
        let mut out = vec![String::new(); self.width];
        for &(j, c) in &self.rotations {
            for (k, s) in ["alpha", "beta", "gamma"].iter().enumerate() {
                out[c + k] = format!("{}_{s}", skel.names[j]);
            }
        }
        let root = &skel.names[0];
        let r = &self.root;
        let named = [
            (r.x, "Xposition"),
            (Some(r.y), "Yposition"),
            (r.z, "Zposition"),
            (Some(r.dx), "dXposition"),
            (Some(r.dz), "dZposition"),
            (Some(r.dyaw), "dYrotation"),
        ];
        for (c, s) in named {
            if let Some(c) = c {
                out[c] = format!("{root}_{s}");
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_skeleton_widths() {
        let s = TfSkeleton::default();
        let l = Layout::new(&s, 67).unwrap();
        let names = l.column_names(&s);
        assert_eq!(
            &names[..3],
            ["RightHand_alpha", "RightHand_beta", "RightHand_gamma"]
        );
        assert_eq!(
            &names[60..67],
            [
                "Hips_alpha",
                "Hips_beta",
                "Hips_gamma",
                "Hips_Yposition",
                "Hips_dXposition",
                "Hips_dZposition",
                "Hips_dYrotation"
            ]
        );
        assert!(!names.iter().any(|n| n.starts_with("Spine2")));
        let l = Layout::new(&s, 69).unwrap();
        assert_eq!(
            l.root,
            RootColumns {
                x: Some(63),
                y: 64,
                z: Some(65),
                dx: 66,
                dz: 67,
                dyaw: 68
            }
        );
        let e = format!("{:#}", Layout::new(&s, 68).unwrap_err());
        assert!(
            e.contains("68 features per frame do not fit") && e.contains("69") && e.contains("67"),
            "{e}"
        );
    }

    #[test]
    fn missing_joints_are_named() {
        let mut s = TfSkeleton::default();
        s.names[17] = "Skull".into();
        let e = format!("{:#}", Layout::new(&s, 67).unwrap_err());
        assert!(
            e.contains("lacks 1 of the 20 joints") && e.contains("Head"),
            "{e}"
        );
    }
}
