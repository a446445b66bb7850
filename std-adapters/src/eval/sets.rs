//! Folders of motions as the authors' evaluation reads them, and the saved
//! real-set statistics.
//!
//! A folder holds `<name>_00.npy` (the dancer under test: the follower) and,
//! for the duet metrics, `<name>_01.npy` (its leader); `.bvh` is read too
//! (`duolando dance`'s leader loader: SMPL-X or Mixamo names, resampled to
//! 30 fps). Music features for BAS are `<music dir>/<a>_<b>_<c>.npy`, the
//! first three `_`-separated fields of the clip name (the DD100 naming
//! `<Genre>_<CC>_<TT>_00.npy`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use super::{bas, bed, cd, footskate, kinetic, manual};
use crate::cli::dance::inputs::load_leader;
use crate::npy::read_f32_2d;

/// Per-clip features of one folder.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct SetFeatures {
    /// Tag of this file layout.
    pub format: String,
    /// Clip names (file stems without `_00`), sorted.
    pub clips: Vec<String>,
    /// 72 kinetic features per clip.
    pub kinetic: Vec<Vec<f32>>,
    /// 32 geometric features per clip.
    pub geometric: Vec<Vec<f32>>,
    /// Names of the clips with a leader, and their 100 cross-distance features.
    pub duets: Vec<String>,
    pub cd: Vec<Vec<f32>>,
}

/// The `format` tag of real-set statistics files.
pub const STATS_FORMAT: &str = "duolando-eval-features/1";

/// Per-clip figures of one folder that are not features.
#[derive(Clone, Debug, Default)]
pub struct SetExtras {
    /// BED per duet.
    pub bed: Vec<f64>,
    /// The first duet whose BED is undefined, and why.
    pub bed_error: Option<String>,
    /// The first clip whose BAS is undefined, and why.
    pub bas_error: Option<String>,
    /// BAS per clip (when music was given).
    pub bas: Vec<f64>,
    /// Foot-skating counts over every `.npy` motion in the folder.
    pub fs_all: Vec<(usize, usize)>,
    /// Foot-skating counts over the `_00` clips only.
    pub fs_00: Vec<(usize, usize)>,
}

fn is_motion(p: &Path) -> bool {
    matches!(p.extension().and_then(|e| e.to_str()), Some("npy" | "bvh"))
}

fn load(path: &Path) -> Result<Vec<f32>> {
    if path.extension().and_then(|e| e.to_str()) == Some("bvh") {
        return Ok(load_leader(path)?.pos3d);
    }
    let a = read_f32_2d(
        path,
        Some(super::POSE_DIM),
        "SMPL-X joint positions (T, 165), metres, y up, 30 fps",
    )?;
    if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
        bail!(
            "{}: value [{}, {}] is not finite ({})",
            path.display(),
            i / a.cols,
            i % a.cols,
            a.data[i]
        );
    }
    Ok(a.data)
}

/// The music features file of a clip name, as the authors derive it.
pub fn music_path(music_dir: &Path, clip: &str) -> Result<PathBuf> {
    let fields: Vec<&str> = clip.split('_').collect();
    if fields.len() < 3 {
        bail!("clip name '{clip}' has fewer than three '_'-separated fields; the music file is <a>_<b>_<c>.npy (DD100 naming <Genre>_<CC>_<TT>_00.npy)");
    }
    Ok(music_dir.join(format!("{}_{}_{}.npy", fields[0], fields[1], fields[2])))
}

/// Reads every clip of `dir` and computes its features; with `scores`
/// also BED, foot skating and (with `music`) BAS, which the authors compute
/// on the generated set only. A clip without beats leaves BAS or BED
/// uncomputed (the reason in `bas_error` / `bed_error`), not the features.
pub fn compute(dir: &Path, music: Option<&Path>, scores: bool) -> Result<(SetFeatures, SetExtras)> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read the motion folder {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && is_motion(p))
        .collect();
    entries.sort();
    let mut set = SetFeatures {
        format: STATS_FORMAT.into(),
        ..Default::default()
    };
    let mut extra = SetExtras::default();
    for path in &entries {
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default()
            .to_string();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or_default();
        let pos = load(path)?;
        let shown = path.display().to_string();
        if scores && ext == "npy" {
            let counts = footskate::clip_counts(&pos).with_context(|| shown.clone())?;
            extra.fs_all.push(counts);
            if stem.ends_with("_00") {
                extra.fs_00.push(counts);
            }
        }
        let Some(name) = stem.strip_suffix("_00") else {
            continue;
        };
        set.clips.push(name.to_string());
        set.kinetic
            .push(kinetic::features(&pos).with_context(|| format!("{shown}: kinetic features"))?);
        set.geometric
            .push(manual::features(&pos).with_context(|| format!("{shown}: geometric features"))?);
        let leader_path = path.with_file_name(format!("{name}_01.{ext}"));
        if leader_path.is_file() {
            let leader = load(&leader_path)?;
            set.duets.push(name.to_string());
            set.cd.push(
                cd::features(&pos, &leader)
                    .with_context(|| format!("{shown}: cross-distance features"))?,
            );
            if scores {
                match bed::duet_score(&pos, &leader) {
                    Ok(v) => extra.bed.push(v),
                    Err(e) => {
                        extra
                            .bed_error
                            .get_or_insert(format!("{shown} with {}: {e}", leader_path.display()));
                    }
                }
            }
        }
        if let (true, Some(mdir)) = (scores, music) {
            let mpath = music_path(mdir, name)?;
            let m = read_f32_2d(
                &mpath,
                Some(bas::MUSIC_DIM),
                "music features (T, 54), beat in column 53",
            )
            .with_context(|| format!("music of {shown}"))?;
            match bas::clip_score(&pos, &m.data, m.cols) {
                Ok(v) => extra.bas.push(v),
                Err(e) => {
                    extra.bas_error.get_or_insert(format!("{shown}: {e}"));
                }
            }
        }
    }
    if set.clips.is_empty() {
        bail!(
            "{}: no <name>_00.npy or <name>_00.bvh motion files",
            dir.display()
        );
    }
    Ok((set, extra))
}

/// Writes a set's features as JSON (the real-set statistics file).
pub fn save(set: &SetFeatures, path: &Path) -> Result<()> {
    let text = serde_json::to_string(set)?;
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Reads a real-set statistics file written by [`save`].
pub fn load_stats(path: &Path) -> Result<SetFeatures> {
    let text = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let set: SetFeatures = serde_json::from_slice(&text).with_context(|| {
        format!(
            "{}: not a real-set statistics file (JSON written by `duolando eval --save-real`)",
            path.display()
        )
    })?;
    if set.format != STATS_FORMAT {
        bail!(
            "{}: format '{}', expected '{STATS_FORMAT}'",
            path.display(),
            set.format
        );
    }
    let bad = |rows: &[Vec<f32>], d: usize| rows.iter().any(|r| r.len() != d);
    if set.kinetic.len() != set.clips.len()
        || set.geometric.len() != set.clips.len()
        || set.cd.len() != set.duets.len()
        || bad(&set.kinetic, kinetic::DIM)
        || bad(&set.geometric, manual::DIM)
        || bad(&set.cd, cd::DIM)
    {
        bail!(
            "{}: inconsistent statistics (expected one {}-d kinetic and {}-d geometric row per clip, one {}-d cross-distance row per duet)",
            path.display(),
            kinetic::DIM,
            manual::DIM,
            cd::DIM
        );
    }
    Ok(set)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn music_file_is_named_by_the_first_three_fields() {
        let p = music_path(Path::new("m"), "Waltz_05_03").unwrap();
        assert_eq!(p, Path::new("m/Waltz_05_03.npy"));
        let p = music_path(Path::new("m"), "Waltz_05_03_extra").unwrap();
        assert_eq!(p, Path::new("m/Waltz_05_03.npy"));
        let err = music_path(Path::new("m"), "clip").unwrap_err().to_string();
        assert!(err.contains("fewer than three"), "{err}");
    }

    #[test]
    fn stats_round_trip_and_inconsistent_files_are_rejected() {
        let dir = std::env::temp_dir().join(format!("duo-eval-stats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.json");
        let mut set = SetFeatures {
            format: STATS_FORMAT.into(),
            clips: vec!["a".into()],
            kinetic: vec![vec![0.25; kinetic::DIM]],
            geometric: vec![vec![0.5; manual::DIM]],
            duets: vec![],
            cd: vec![],
        };
        save(&set, &path).unwrap();
        assert_eq!(load_stats(&path).unwrap().kinetic, set.kinetic);
        set.geometric[0].pop();
        save(&set, &path).unwrap();
        assert!(load_stats(&path)
            .unwrap_err()
            .to_string()
            .contains("inconsistent statistics"));
        set.format = "other".into();
        save(&set, &path).unwrap();
        assert!(load_stats(&path)
            .unwrap_err()
            .to_string()
            .contains("expected 'duolando-eval-features/1'"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
