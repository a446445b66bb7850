//! Motion export for people: glTF 2.0 binary (both dancers as joint
//! hierarchies), BVH per dancer, and npy arrays for researchers.
//!
//! Everything goes through [`Motion`]: a rig plus per-frame root
//! translation and proper local rotations whose FK gives `positions`.
//! Build it from raw joint positions ([`Motion::from_positions`], rotations
//! by retargeting), from rotations ([`Motion::from_rotations`], each 3x3
//! first projected to the nearest rotation), or from the model's decoded
//! outputs ([`Motion::from_decoded`]).

pub mod bvh;
pub mod glb;
pub mod mannequin;
pub mod npy;

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

use crate::skeleton::fk::positions_of_clip;
use crate::skeleton::math::{flatten, norm, sub, unflatten, Vec3};
use crate::skeleton::retarget::{measure_skeleton, retarget};
use crate::skeleton::{nearest_rotation, Skeleton, JOINTS, POS_DIM, ROT_DIM};
use crate::synth::DancerTrack;

/// Frames per second of exported motion.
pub const FPS: f32 = 30.0;

/// One dancer's exportable motion.
#[derive(Clone, Debug)]
pub struct Motion {
    pub skeleton: Skeleton,
    pub frames: usize,
    pub roots: Vec<f32>,     // (T, 3) pelvis world position, metres
    pub rotmats: Vec<f32>,   // (T, 495) proper local rotations, row-major
    pub positions: Vec<f32>, // (T, 165) FK(skeleton, roots, rotmats)
    /// Largest distance (m) between `positions` and the input positions it
    /// was fitted to (0 when built from rotations alone).
    pub fit_error_m: f32,
}

fn check_finite(data: &[f32], what: &str) -> Result<()> {
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        bail!("{what}: value {i} is not finite ({})", data[i]);
    }
    Ok(())
}

fn frames_of(len: usize, width: usize, what: &str) -> Result<usize> {
    if len == 0 || len % width != 0 {
        bail!("{what}: expected (T, {width}) values with T >= 1, got {len} values");
    }
    Ok(len / width)
}

/// (T, 165) positions as T frames of 55 joints.
pub fn as_frames(positions: &[f32]) -> Vec<[Vec3; JOINTS]> {
    positions
        .chunks_exact(POS_DIM)
        .map(|row| {
            let mut f = [[0.0; 3]; JOINTS];
            for (j, p) in f.iter_mut().enumerate() {
                *p = [row[3 * j], row[3 * j + 1], row[3 * j + 2]];
            }
            f
        })
        .collect()
}

fn max_distance(a: &[f32], b: &[f32]) -> f32 {
    a.chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(p, q)| norm(sub([p[0], p[1], p[2]], [q[0], q[1], q[2]])))
        .fold(0.0, f32::max)
}

/// Joint groups of the SMPL-X layout for error reports: `body` = joints
/// 0..=24 (trunk, legs, arms to the wrists, head, jaw, eyes), `hands` =
/// 25..=54 (fingers).
pub const BODY_JOINTS: std::ops::Range<usize> = 0..25;
pub const HAND_JOINTS: std::ops::Range<usize> = 25..JOINTS;

/// Distances between two (T, 165) position arrays over a set of joints:
/// mean, 95th percentile (nearest rank) and maximum, in metres.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ErrorStats {
    pub mean: f32,
    pub p95: f32,
    pub max: f32,
}

impl ErrorStats {
    /// Over `joints` of every frame of `a` and `b` ((T, 165) each; the
    /// shorter length is used). All zero when there is nothing to compare.
    pub fn between(a: &[f32], b: &[f32], joints: std::ops::Range<usize>) -> ErrorStats {
        let mut d: Vec<f32> = a
            .chunks_exact(POS_DIM)
            .zip(b.chunks_exact(POS_DIM))
            .flat_map(|(fa, fb)| {
                joints.clone().map(move |j| {
                    norm(sub(
                        [fa[3 * j], fa[3 * j + 1], fa[3 * j + 2]],
                        [fb[3 * j], fb[3 * j + 1], fb[3 * j + 2]],
                    ))
                })
            })
            .collect();
        ErrorStats::of(&mut d)
    }

    /// Mean, p95 (nearest rank) and max of `values` (sorted in place).
    pub fn of(values: &mut [f32]) -> ErrorStats {
        if values.is_empty() {
            return ErrorStats::default();
        }
        values.sort_unstable_by(f32::total_cmp);
        let n = values.len();
        let mean = (values.iter().map(|&v| v as f64).sum::<f64>() / n as f64) as f32;
        let rank = ((0.95 * n as f64).ceil() as usize).clamp(1, n);
        ErrorStats {
            mean,
            p95: values[rank - 1],
            max: values[n - 1],
        }
    }
}

/// [`ErrorStats`] per joint group (`body`, `hands`, `all`) between an
/// export's FK positions and the positions it should reproduce.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct GroupErrors {
    pub body: ErrorStats,
    pub hands: ErrorStats,
    pub all: ErrorStats,
}

impl GroupErrors {
    pub fn between(a: &[f32], b: &[f32]) -> GroupErrors {
        GroupErrors {
            body: ErrorStats::between(a, b, BODY_JOINTS),
            hands: ErrorStats::between(a, b, HAND_JOINTS),
            all: ErrorStats::between(a, b, 0..JOINTS),
        }
    }
}

impl Motion {
    /// From raw world joint positions (T, 165) in metres: the rig takes our
    /// rest directions with the clip's median bone lengths (one per bone for
    /// the whole clip), rotations come
    /// from [`retarget`]. `what` names the input in errors.
    pub fn from_positions(positions: &[f32], what: &str) -> Result<Motion> {
        let frames = frames_of(positions.len(), POS_DIM, what)?;
        check_finite(positions, what)?;
        let clip = as_frames(positions);
        let skeleton = measure_skeleton(&Skeleton::default(), &clip);
        let mut roots = Vec::with_capacity(frames * 3); // (T, 3)
        let mut rotmats = Vec::with_capacity(frames * ROT_DIM); // (T, 495)
        for f in &clip {
            roots.extend_from_slice(&f[0]);
            for m in retarget(&skeleton, f).iter() {
                rotmats.extend_from_slice(&flatten(m));
            }
        }
        let fk = positions_of_clip(&skeleton, &roots, &rotmats);
        let fit_error_m = max_distance(&fk, positions);
        Ok(Motion {
            skeleton,
            frames,
            roots,
            rotmats,
            positions: fk,
            fit_error_m,
        })
    }

    /// From root translations (T, 3) and local rotation matrices (T, 495)
    /// on `skeleton`; every 3x3 is projected to the nearest rotation.
    pub fn from_rotations(
        roots: &[f32],
        rotmats: &[f32],
        skeleton: Skeleton,
        what: &str,
    ) -> Result<Motion> {
        let frames = frames_of(rotmats.len(), ROT_DIM, what)?;
        if roots.len() != frames * 3 {
            bail!(
                "{what}: {frames} frames of rotations but {} root values (expected (T, 3) = {})",
                roots.len(),
                frames * 3
            );
        }
        check_finite(roots, what)?;
        check_finite(rotmats, what)?;
        let mut proper = Vec::with_capacity(rotmats.len()); // (T, 495)
        for m in rotmats.chunks_exact(9) {
            proper.extend_from_slice(&flatten(&nearest_rotation(&unflatten(m))));
        }
        let positions = positions_of_clip(&skeleton, roots, &proper);
        Ok(Motion {
            skeleton,
            frames,
            roots: roots.to_vec(),
            rotmats: proper,
            positions,
            fit_error_m: 0.0,
        })
    }

    /// From the model's decoded outputs: positions (T, 165) and, optionally,
    /// the rotation head's (T, 495) unconstrained 3x3s. With rotations, the
    /// rig is measured from the positions, the root is the decoded pelvis,
    /// and the rotations (projected) drive FK; `fit_error_m` then reports how
    /// far that FK lands from the decoded positions. Without, see
    /// [`Motion::from_positions`].
    pub fn from_decoded(positions: &[f32], rotmats: Option<&[f32]>, what: &str) -> Result<Motion> {
        let Some(rotmats) = rotmats else {
            return Motion::from_positions(positions, what);
        };
        let frames = frames_of(positions.len(), POS_DIM, what)?;
        check_finite(positions, what)?;
        if rotmats.len() != frames * ROT_DIM {
            bail!("{what}: {frames} frames of positions but {} rotation values (expected (T, 495) = {})", rotmats.len(), frames * ROT_DIM);
        }
        let skeleton = measure_skeleton(&Skeleton::default(), &as_frames(positions));
        let roots: Vec<f32> = positions
            .chunks_exact(POS_DIM)
            .flat_map(|r| [r[0], r[1], r[2]])
            .collect();
        let mut m = Motion::from_rotations(&roots, rotmats, skeleton, what)?;
        m.fit_error_m = max_distance(&m.positions, positions);
        Ok(m)
    }

    /// A synthesized dancer as-is (rotations already proper).
    pub fn from_track(track: &DancerTrack) -> Motion {
        Motion {
            skeleton: track.skeleton,
            frames: track.contacts.len(),
            roots: track.roots.clone(),
            rotmats: track.rotmats.clone(),
            positions: track.positions.clone(),
            fit_error_m: 0.0,
        }
    }
}

/// Writes the standard export set into `dir` (created):
/// `follower.glb` (the follower and, when given, the leader, as two joint
/// hierarchies), `<name>.bvh` (centimetres) and `<name>_pos3d.npy` /
/// `<name>_rotmat.npy` for each dancer. Returns the written paths.
pub fn write_all(dir: &Path, leader: Option<&Motion>, follower: &Motion) -> Result<Vec<PathBuf>> {
    let mut dancers: Vec<(&str, &Motion)> = Vec::new();
    if let Some(l) = leader {
        dancers.push(("leader", l));
    }
    dancers.push(("follower", follower));
    write_dancers(dir, "follower.glb", &dancers, FPS)
}

/// [`write_all`] for any named dancers at any frame rate: `glb` holds them
/// all, each gets `<name>.bvh`, `<name>_pos3d.npy`, `<name>_rotmat.npy`.
pub fn write_dancers(
    dir: &Path,
    glb: &str,
    dancers: &[(&str, &Motion)],
    fps: f32,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)
        .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
    let mut out = Vec::new();
    let glb_path = dir.join(glb);
    glb::write(&glb_path, dancers, fps)?;
    out.push(glb_path);
    for (name, m) in dancers {
        let b = dir.join(format!("{name}.bvh"));
        bvh::write(&b, m, fps, bvh::Units::Centimetres)?;
        out.push(b);
        out.extend(npy::write(dir, name, m)?);
    }
    Ok(out)
}
