//! Writes synthesized takes in the original DD100 layout:
//!
//! ```text
//! DIR/motion/pos3d/{train,test}/<Genre>_<CC>_<TT>_00.npy   follower (T, 165)
//! DIR/motion/pos3d/{train,test}/<Genre>_<CC>_<TT>_01.npy   leader   (T, 165)
//! DIR/motion/rotmat/{train,test}/<same names>              (T, 3 + 495)
//! DIR/music/feature/{train,test}/<Genre>_<CC>_<TT>.npy     (T, 54)
//! DIR/takes.json, DIR/README.md
//! ```
//! `_00` is the follower and `_01` the leader, as in DD100. `<CC>` numbers
//! choreographies across genres; those with `<CC>` a multiple of 5 go to
//! `test` (the original split rule applied to the name).

use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde_json::json;

use super::genre::{Genre, Hold};
use super::rng::Rng;
use super::take::{generate, Take, TakeSpec, FPS};
use super::MUSIC_DIM;
use crate::npy::write_f32;
use crate::skeleton::{POS_DIM, ROT_DIM};

/// What one `write_dataset` call produced.
#[derive(Clone, Debug)]
pub struct DatasetSummary {
    pub takes: usize,
    pub frames: usize,
    pub seconds: f32,
    pub files: Vec<PathBuf>,
}

/// One take to write: its file stem, split and spec.
#[derive(Clone, Debug)]
pub struct TakeEntry {
    pub stem: String,
    pub split: &'static str,
    pub spec: TakeSpec,
    pub choreography: usize,
    pub take: usize,
}

/// The take list for `minutes` of data from `seed`: takes of 20-45 s,
/// genres in rotation, half of the choreographies danced twice (the
/// second take shares the leader's figures and tempo, not the follower's
/// hidden answers). `beat_grid` (seconds): see [`TakeSpec::beat_grid`].
pub fn plan_takes(minutes: f32, seed: u64, beat_grid: Option<f32>) -> Vec<TakeEntry> {
    let mut rng = Rng::new(seed, 10);
    let mut out = Vec::new();
    let mut total = 0.0f32;
    let mut choreo = 0usize;
    let target = minutes.max(0.0) * 60.0;
    while total < target {
        choreo += 1;
        let genre = Genre::ALL[(choreo - 1) % Genre::ALL.len()];
        // The choreography number is global (genres rotate), so the original
        // split rule on the name's second field gives a test set at any size.
        let index = choreo;
        let seconds = rng.range(20.0, 45.0).min((target - total).max(8.0)).round();
        let choreo_seed = rng.next_u64();
        let takes = if rng.chance(0.5) { 2 } else { 1 };
        for take in 1..=takes {
            let spec = TakeSpec {
                genre,
                seconds,
                bpm: None,
                beat_grid,
                choreo_seed,
                take_seed: rng.next_u64(),
            };
            out.push(TakeEntry {
                stem: format!("{}_{:02}_{:02}", genre.name(), index, take),
                split: if index % 5 == 0 { "test" } else { "train" },
                spec,
                choreography: index,
                take,
            });
            total += seconds;
        }
    }
    out
}

fn mkdirs(dir: &Path) -> Result<()> {
    for split in ["train", "test"] {
        for sub in ["motion/pos3d", "motion/rotmat", "music/feature"] {
            let d = dir.join(sub).join(split);
            fs::create_dir_all(&d).with_context(|| format!("cannot create {}", d.display()))?;
        }
    }
    Ok(())
}

/// Writes one generated take's five arrays; returns their paths.
pub fn write_take(dir: &Path, entry: &TakeEntry, take: &Take) -> Result<Vec<PathBuf>> {
    let t = take.frames;
    let mut files = Vec::new();
    for (suffix, track) in [("_00", &take.follower), ("_01", &take.leader)] {
        let name = format!("{}{}.npy", entry.stem, suffix);
        let p = dir.join("motion/pos3d").join(entry.split).join(&name);
        write_f32(&p, &track.positions, &[t, POS_DIM])?;
        files.push(p);
        let r = dir.join("motion/rotmat").join(entry.split).join(&name);
        write_f32(&r, &track.rotmat_with_root(), &[t, 3 + ROT_DIM])?;
        files.push(r);
    }
    let m = dir
        .join("music/feature")
        .join(entry.split)
        .join(format!("{}.npy", entry.stem));
    write_f32(&m, &take.music, &[t, MUSIC_DIM])?;
    files.push(m);
    Ok(files)
}

fn hold_name(h: Hold) -> &'static str {
    match h {
        Hold::Closed => "closed",
        Hold::Open => "open",
        Hold::Underarm => "underarm",
    }
}

/// Generates `minutes` of duets from `seed` into `dir` (every beat on
/// `beat_grid` seconds when given). `progress` is called after each take
/// with (done, total).
pub fn write_dataset(
    dir: &Path,
    minutes: f32,
    seed: u64,
    beat_grid: Option<f32>,
    mut progress: impl FnMut(usize, usize),
) -> Result<DatasetSummary> {
    mkdirs(dir)?;
    let entries = plan_takes(minutes, seed, beat_grid);
    let mut files = Vec::new();
    let mut meta = Vec::new();
    let mut frames = 0;
    for (i, e) in entries.iter().enumerate() {
        let take = generate(&e.spec);
        files.extend(write_take(dir, e, &take)?);
        frames += take.frames;
        meta.push(json!({
            "name": e.stem, "split": e.split, "genre": e.spec.genre.name(),
            "choreography": e.choreography, "take": e.take, "frames": take.frames,
            "bpm": take.bpm, "beats_per_bar": take.beats_per_bar,
            "beats_s": take.beats.iter().filter(|b| **b * FPS < take.frames as f32).collect::<Vec<_>>(),
            "leader_scale": take.leader.skeleton.scale_hint(), "follower_scale": take.follower.skeleton.scale_hint(),
            "figures": take.figures.iter().map(|f| json!({
                "name": f.name, "hold": hold_name(f.hold), "start_frame": f.start_frame, "end_frame": f.end_frame,
                "follower_spin": f.response.spin, "follower_arm_style": f.response.arm_style,
                "follower_swap_accent": f.response.swap_accent,
            })).collect::<Vec<_>>(),
        }));
        progress(i + 1, entries.len());
    }
    let index = json!({
        "generator": "duolando synth", "seed": seed, "minutes_requested": minutes, "fps": FPS,
        "beat_grid_s": beat_grid,
        "layout": {
            "motion/pos3d/<split>/<name>_00.npy": "follower world joint positions, float32 (T, 165) = 55 SMPL-X joints x xyz, metres, y up",
            "motion/pos3d/<split>/<name>_01.npy": "leader, same layout",
            "motion/rotmat/<split>/<name>_0X.npy": "float32 (T, 498): pelvis world position (3) then 55 local rotations, row-major 3x3",
            "music/feature/<split>/<name>.npy": "float32 (T, 54): mfcc 20 | mfcc delta 20 | chroma 12 | onset envelope 1 | beat one-hot 1 (synthetic, see docs/SYNTH.md)",
        },
        "takes": meta,
    });
    let json_path = dir.join("takes.json");
    fs::write(&json_path, serde_json::to_string_pretty(&index)?)
        .with_context(|| format!("cannot write {}", json_path.display()))?;
    files.push(json_path);
    let readme = dir.join("README.md");
    fs::write(&readme, readme_text(seed, minutes, entries.len(), frames))
        .with_context(|| format!("cannot write {}", readme.display()))?;
    files.push(readme);
    Ok(DatasetSummary {
        takes: entries.len(),
        frames,
        seconds: frames as f32 / FPS,
        files,
    })
}

fn readme_text(seed: u64, minutes: f32, takes: usize, frames: usize) -> String {
    format!(
        "# Synthetic duet dataset (duolando synth)\n\n\
Generated by `duolando synth --minutes {minutes} --seed {seed}`: {takes} takes, {frames} frames at 30 fps.\n\
Procedural, not motion capture: see docs/SYNTH.md in the duolando repository.\n\n\
Layout (the original DD100 layout after `_prepare_motion_data.py` / `_prepare_music_data.py`):\n\n\
    motion/pos3d/{{train,test}}/<Genre>_<CC>_<TT>_00.npy   follower joint positions (T, 165) float32\n\
    motion/pos3d/{{train,test}}/<Genre>_<CC>_<TT>_01.npy   leader joint positions   (T, 165) float32\n\
    motion/rotmat/{{train,test}}/<same names>              (T, 3 + 495): root translation + 55 local 3x3 (row-major)\n\
    music/feature/{{train,test}}/<Genre>_<CC>_<TT>.npy     (T, 54) synthetic music features\n\
    takes.json                                             per take: genre, tempo, beats, figures, follower's hidden choices\n\n\
Units: metres, y up. Joint order: SMPL-X (pelvis, left_hip, right_hip, ...), 55 joints.\n\
The root translation is the pelvis world position (our rig has the pelvis at its origin).\n\
Split: choreographies whose index is a multiple of 5 are in `test`.\n"
    )
}
