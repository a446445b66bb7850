//! The skeleton Transflower's motion features are decoded onto: joint
//! names (pymo's BVH names), parents and rest offsets. The features hold
//! rotations relative to the rest pose of the BVH skeleton the authors'
//! pymo pipeline was fit on, so the rest offsets decide where the joints
//! land; that pipeline (`motion_expmap_cr_scaled_20_data_pipe.sav`) and
//! its dataset (dance_combined) are not published.
//!
//! [`TfSkeleton::default`] is the body of the authors' `analysis/mixamo.bvh`
//! (metres, y up, T-pose, facing +z, the character's left on +x), the
//! skeleton their `feature_extraction/utils/smpl2mixamo.py` retargets
//! AIST++ onto before the features are computed: the 21 joints the
//! pipeline keeps plus `Spine2` (kept at its rest rotation, see
//! docs/TRANSFLOWER.md). Its fingers are left out (the pipeline drops
//! them too). [`TfSkeleton::from_bvh`] reads any BVH hierarchy instead.

use std::path::Path;

use anyhow::{bail, Context, Result};

use crate::cli::dance::leader_bvh::bare;
use crate::export::bvh;

/// (name, parent, rest offset in metres), parents first: the authors'
/// analysis/mixamo.bvh body joints in its file order (OFFSETs as written
/// there, 6 decimals).
pub const DEFAULT_TABLE: [(&str, Option<&str>, [f64; 3]); 22] = [
    ("Hips", None, [0.0, 0.0, 0.0]),
    ("LeftUpLeg", Some("Hips"), [0.082078, -0.067517, -0.015996]),
    ("LeftLeg", Some("LeftUpLeg"), [0.0, -0.443705, 0.002846]),
    ("LeftFoot", Some("LeftLeg"), [0.0, -0.444279, -0.029822]),
    ("LeftToeBase", Some("LeftFoot"), [0.0, -0.087287, 0.107106]),
    (
        "RightUpLeg",
        Some("Hips"),
        [-0.082078, -0.067517, -0.015996],
    ),
    ("RightLeg", Some("RightUpLeg"), [0.0, -0.443705, 0.002862]),
    ("RightFoot", Some("RightLeg"), [0.0, -0.444277, -0.029838]),
    (
        "RightToeBase",
        Some("RightFoot"),
        [0.0, -0.087287, 0.107106],
    ),
    ("Spine", Some("Hips"), [0.0, 0.101816, 0.001315]),
    ("Spine1", Some("Spine"), [0.0, 0.100835, -0.010008]),
    ("Spine2", Some("Spine1"), [0.0, 0.091000, -0.013734]),
    (
        "LeftShoulder",
        Some("Spine2"),
        [0.045704, 0.109460, -0.026280],
    ),
    (
        "LeftArm",
        Some("LeftShoulder"),
        [0.105924, -0.005246, -0.022321],
    ),
    ("LeftForeArm", Some("LeftArm"), [0.278415, -0.000001, 0.0]),
    ("LeftHand", Some("LeftForeArm"), [0.283288, 0.0, 0.0]),
    ("Neck", Some("Spine2"), [0.0, 0.166717, -0.025162]),
    ("Head", Some("Neck"), [0.0, 0.096179, 0.016850]),
    (
        "RightShoulder",
        Some("Spine2"),
        [-0.045700, 0.109462, -0.026280],
    ),
    (
        "RightArm",
        Some("RightShoulder"),
        [-0.105929, -0.005248, -0.022321],
    ),
    ("RightForeArm", Some("RightArm"), [-0.278415, 0.0, 0.0]),
    (
        "RightHand",
        Some("RightForeArm"),
        [-0.283288, 0.0, 0.000001],
    ),
];

/// A skeleton: joints in BVH file order (parents before children).
#[derive(Clone, Debug, PartialEq)]
pub struct TfSkeleton {
    pub names: Vec<String>,
    pub parents: Vec<Option<usize>>,
    pub offsets: Vec<[f64; 3]>, // (J, 3) in the parent's rest frame, file units
    /// File units per metre: 1 (metres) or 100 (centimetres).
    pub units_per_metre: f64,
    /// Where it came from, for messages and summaries.
    pub source: String,
}

impl Default for TfSkeleton {
    fn default() -> Self {
        let names: Vec<String> = DEFAULT_TABLE.iter().map(|r| r.0.to_string()).collect();
        let parents = DEFAULT_TABLE
            .iter()
            .map(|r| r.1.map(|p| names.iter().position(|n| n == p).unwrap_or(0)))
            .collect();
        TfSkeleton {
            names,
            parents,
            offsets: DEFAULT_TABLE.iter().map(|r| r.2).collect(),
            units_per_metre: 1.0,
            source: "built-in (the body of the authors' analysis/mixamo.bvh, metres)".into(),
        }
    }
}

impl TfSkeleton {
    /// The hierarchy of a BVH file (its motion, if any, is ignored). Names lose any
    /// `prefix:` (`mixamorig:Hips` -> `Hips`); a name used twice is refused.
    /// Units: centimetres when the rest pose is taller than 5 units (as
    /// `duolando dance` reads a leader BVH), else metres.
    pub fn from_bvh(path: &Path) -> Result<TfSkeleton> {
        let mut text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the skeleton {}", path.display()))?;
        let what = path.display().to_string();
        if !text.split_whitespace().any(|t| t == "MOTION") {
            // A hierarchy alone (as the authors' data/fixed_skeleton.bvh).
            text.push_str("\nMOTION\nFrames: 0\nFrame Time: 0.05\n");
        }
        let clip = bvh::parse(&text, &what)?;
        let names: Vec<String> = clip
            .joints
            .iter()
            .map(|j| bare(&j.name).to_string())
            .collect();
        for (i, n) in names.iter().enumerate() {
            if names[..i].contains(n) {
                bail!("{what}: joint name {n:?} is used twice");
            }
        }
        let offsets: Vec<[f64; 3]> = clip.joints.iter().map(|j| j.offset_f64).collect();
        if let Some(i) = offsets
            .iter()
            .position(|o| o.iter().any(|v| !v.is_finite()))
        {
            bail!("{what}: joint {:?} has a non-finite OFFSET", names[i]);
        }
        let mut s = TfSkeleton {
            names,
            parents: clip.joints.iter().map(|j| j.parent).collect(),
            offsets,
            units_per_metre: 1.0,
            source: what,
        };
        let ys: Vec<f64> = s.rest_positions().iter().map(|p| p[1]).collect();
        let height = ys.iter().cloned().fold(f64::MIN, f64::max)
            - ys.iter().cloned().fold(f64::MAX, f64::min);
        if height > 5.0 {
            s.units_per_metre = 100.0;
        }
        Ok(s)
    }

    pub fn joints(&self) -> usize {
        self.names.len()
    }

    /// The joint called `name`, if any.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Rest positions with the root at the origin (file units).
    pub fn rest_positions(&self) -> Vec<[f64; 3]> {
        let mut p: Vec<[f64; 3]> = Vec::with_capacity(self.joints());
        for (j, o) in self.offsets.iter().enumerate() {
            let base = self.parents[j].map_or([0.0; 3], |q| p[q]);
            p.push(if self.parents[j].is_some() {
                [base[0] + o[0], base[1] + o[1], base[2] + o[2]]
            } else {
                [0.0; 3]
            });
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_table_is_a_tree_of_adult_size() {
        let s = TfSkeleton::default();
        assert_eq!(s.joints(), 22);
        for (j, p) in s.parents.iter().enumerate() {
            assert_eq!(p.is_none(), j == 0);
            assert!(p.is_none_or(|q| q < j));
        }
        let p = s.rest_positions();
        let (head, toe) = (
            p[s.find("Head").unwrap()][1],
            p[s.find("LeftToeBase").unwrap()][1],
        );
        assert!(
            (1.4..1.9).contains(&(head - toe)),
            "head to toe {}",
            head - toe
        );
    }

    #[test]
    fn reads_the_hand_made_bvh() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../tests/fixtures/transflower_motion/hand.bvh");
        let s = TfSkeleton::from_bvh(&p).unwrap();
        assert_eq!(s.joints(), 23);
        assert_eq!(s.units_per_metre, 1.0);
        assert_eq!(s.names[11], "Spine2");
        assert_eq!(s.parents[12], Some(11));
    }

    /// A hierarchy without MOTION (as data/fixed_skeleton.bvh), in
    /// centimetres, with `mixamorig:` names.
    #[test]
    fn reads_a_bare_hierarchy_in_centimetres() {
        let p = std::env::temp_dir().join(format!("tf-skel-{}.bvh", std::process::id()));
        let text = "HIERARCHY\nROOT mixamorig:Hips\n{\nOFFSET 0 90 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\nJOINT mixamorig:Spine\n{\nOFFSET 0 10.5 0\nCHANNELS 3 Zrotation Xrotation Yrotation\nEnd site\n{\nOFFSET 0 0 0\n}\n}\n}\n";
        std::fs::write(&p, text).unwrap();
        let s = TfSkeleton::from_bvh(&p).unwrap();
        std::fs::remove_file(&p).ok();
        assert_eq!(s.names, ["Hips", "Spine"]);
        assert_eq!(s.offsets[1], [0.0, 10.5, 0.0]);
        assert_eq!(s.units_per_metre, 100.0);
    }
}
