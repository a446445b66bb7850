//! `duolando generate --scaler FILE [--skeleton FILE.bvh]` on a Transflower
//! model: the generated frames unscaled and placed on a skeleton
//! (`transflower_motion`), then shown and exported like the other
//! families' dancers: SMPL's 24 joints lifted onto the SMPL-X rig
//! (`skeleton::smpl24`), `export::write_dancers`, the viewer page.
//!
//! Written beside `output.npy`: `output_unscaled.npy` (N, 1, C) float32
//! (what generate.py saves with its scalers), `positions.npy` (N, J, 3)
//! float32 in the skeleton's units (joints in BVH file order, named in
//! `motion.json`), `dancer_smpl24.npy` (N, 72) metres, `dancer.glb`,
//! `dancer.bvh`, `dancer_pos3d.npy`, `dancer_rotmat.npy`, `index.html`
//! and `motion.json`, all at 20 fps.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde_json::json;

use super::generate::Args;
use crate::export::{write_dancers, GroupErrors, Motion};
use crate::npy::write_f32;
use crate::skeleton::smpl24::to_smplx;
use crate::transflower_motion::layout::Layout;
use crate::transflower_motion::scaler::Scaler;
use crate::transflower_motion::skeleton::TfSkeleton;
use crate::transflower_motion::{decode, smpl24, FPS};
use crate::viewer::{write_index_html, ViewerData};

/// What `--scaler` / `--skeleton` ask for, checked before anything runs.
pub struct MotionPlan {
    scaler_path: PathBuf,
    scaler: Scaler,
    skeleton: TfSkeleton,
    layout: Layout,
}

/// Reads and checks `--scaler` and `--skeleton` against the model's
/// output width `channels` (`output` names the modality). `None` without
/// `--scaler`.
pub fn plan(args: &Args, channels: usize, output: &str) -> Result<Option<MotionPlan>> {
    let Some(scaler_path) = &args.scaler else {
        if let Some(s) = &args.skeleton {
            bail!("--skeleton {}: the skeleton places the motion that --scaler unscales; give --scaler too (tools/transflower_scalers.py writes it)", s.display());
        }
        return Ok(None);
    };
    let scaler = Scaler::read(scaler_path)?;
    if scaler.width() != channels {
        bail!(
            "scaler {}: {} columns, the model's output `{output}` has {channels}: it is the scaler of another feature set (the authors' `{output}_scaler.pkl` is the one)",
            scaler_path.display(),
            scaler.width()
        );
    }
    let skeleton = match &args.skeleton {
        Some(p) => TfSkeleton::from_bvh(p)?,
        None => TfSkeleton::default(),
    };
    let layout = Layout::new(&skeleton, channels)
        .with_context(|| format!("the model's output `{output}`"))?;
    Ok(Some(MotionPlan {
        scaler_path: scaler_path.clone(),
        scaler,
        skeleton,
        layout,
    }))
}

/// Writes the motion outputs of `out` ((N, C) scaled frames) into `dir`;
/// returns the file names.
pub fn write(
    plan: &MotionPlan,
    dir: &Path,
    out: &[f32],
    frames: usize,
    title: &str,
) -> Result<Vec<String>> {
    let (c, skel) = (plan.layout.width, &plan.skeleton);
    let unscaled = plan.scaler.unscale(out);
    let f32s: Vec<f32> = unscaled.iter().map(|&v| v as f32).collect();
    if let Some(k) = f32s.iter().position(|v| !v.is_finite()) {
        bail!(
            "scaler {}: unscaled frame {} column {} is {} (outside float32)",
            plan.scaler_path.display(),
            k / c,
            k % c,
            f32s[k]
        );
    }
    write_f32(&dir.join("output_unscaled.npy"), &f32s, &[frames, 1, c])?;
    let d = decode(&unscaled, &plan.layout, skel);
    let pos: Vec<f32> = d.positions.iter().map(|&v| v as f32).collect();
    if let Some(k) = pos.iter().position(|v| !v.is_finite()) {
        bail!("the decoded joint positions overflow float32 (frame {}): the unscaled features are out of any dancer's range", k / (3 * d.joints));
    }
    write_f32(&dir.join("positions.npy"), &pos, &[frames, d.joints, 3])?;
    let pos24 = smpl24(&d, skel)?;
    write_f32(&dir.join("dancer_smpl24.npy"), &pos24, &[frames, 72])?;
    let smplx = to_smplx(&pos24);
    let motion = Motion::from_positions(&smplx, "generated Transflower dancer")?;
    let export_err = GroupErrors::between(&motion.positions, &smplx);
    write_dancers(dir, "dancer.glb", &[("dancer", &motion)], FPS)?;
    write_index_html(
        dir,
        &ViewerData {
            title,
            fps: FPS,
            leader_pos3d: None,
            follower_pos3d: &smplx,
            beats: None,
            tokens: None,
            audio_file: None,
            see_also: None,
        },
    )
    .with_context(|| format!("cannot write the viewer into {}", dir.display()))?;
    let files: Vec<String> = [
        "output_unscaled.npy",
        "positions.npy",
        "dancer_smpl24.npy",
        "dancer.glb",
        "dancer.bvh",
        "dancer_pos3d.npy",
        "dancer_rotmat.npy",
        "index.html",
        "motion.json",
    ]
    .map(String::from)
    .to_vec();
    let layout = if plan.layout.root.x.is_some() {
        "expmap_scaled_20: root x, y, z kept"
    } else {
        "expmap_cr_scaled_20: root x and z removed as constants"
    };
    let summary = json!({
        "fps": FPS,
        "frames": frames,
        "scaler": plan.scaler_path.display().to_string(),
        "skeleton": skel.source,
        "units": if skel.units_per_metre == 1.0 { "metres" } else { "centimetres" },
        "joints": skel.names,
        "features": { "width": c, "layout": layout },
        "export_error_m": export_err,
        "files": files,
    });
    let path = dir.join("motion.json");
    std::fs::write(&path, serde_json::to_string_pretty(&summary)? + "\n")
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(files)
}
