//! npy export for researchers: `<name>_pos3d.npy` (T, 165) world joint
//! positions and `<name>_rotmat.npy` (T, 495) local rotations (row-major
//! 3x3, proper rotations), float32. The root translation is
//! `pos3d[:, 0:3]` (the pelvis).

use std::path::{Path, PathBuf};

use anyhow::Result;

use super::Motion;
use crate::npy::write_f32;
use crate::skeleton::{POS_DIM, ROT_DIM};

/// Writes both arrays into `dir`; returns their paths.
pub fn write(dir: &Path, name: &str, m: &Motion) -> Result<Vec<PathBuf>> {
    let pos = dir.join(format!("{name}_pos3d.npy"));
    write_f32(&pos, &m.positions, &[m.frames, POS_DIM])?;
    let rot = dir.join(format!("{name}_rotmat.npy"));
    write_f32(&rot, &m.rotmats, &[m.frames, ROT_DIM])?;
    Ok(vec![pos, rot])
}
