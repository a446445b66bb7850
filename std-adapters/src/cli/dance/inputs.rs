//! Inputs of `duolando dance`: the bundled assets, the leader (npy or BVH),
//! the music (audio or npy) and the default seed. Every error names the file
//! and what was expected.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use duolando_core::duolando::config::{ModelConfig, POSE_DIM};

use crate::cli::generate::parse_seed_tokens;

use crate::music::{Extractor, SAMPLE_RATE};
use crate::npy::read_f32_2d;

/// Frames per second of the model's motion and music.
pub const FPS: f64 = 30.0;
/// Largest relative difference from 1/30 s accepted for a BVH frame time.
pub const FRAME_TIME_TOLERANCE: f64 = 0.005;
/// Distance between the dancers' pelvises in the default seed, metres.
pub const DEFAULT_SEED_DISTANCE_M: f32 = 0.45;

/// The repository's `assets/` directory as seen when this binary was compiled.
pub const COMPILED_ASSETS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../assets");

/// The bundled demo files.
pub const DEMO_MODEL: &str = "demo.duo";
pub const DEMO_LEADER: &str = "demo_leader_pos3d.npy";
pub const DEMO_MUSIC: &str = "demo_music.npy";
pub const DEMO_FOLLOWER_START: &str = "demo_follower_start.npy";

/// Finds `assets/<name>`: first under the current directory, then under the
/// compile-time workspace root. Returns the places looked at on failure.
pub fn find_asset(name: &str) -> std::result::Result<PathBuf, Vec<PathBuf>> {
    let candidates = [Path::new("assets").join(name), Path::new(COMPILED_ASSETS).join(name)];
    match candidates.iter().find(|p| p.is_file()) {
        Some(p) => Ok(p.clone()),
        None => Err(candidates.to_vec()),
    }
}

/// Like [`find_asset`], with an error that says what to pass instead.
pub fn require_asset(name: &str, role: &str) -> Result<PathBuf> {
    find_asset(name).map_err(|looked| {
        let looked: Vec<String> = looked.iter().map(|p| p.display().to_string()).collect();
        anyhow::anyhow!(
            "the bundled demo {role} `assets/{name}` is missing (looked at {}); the demo assets are not in this checkout yet. \
             Pass your own: --model M.duo --leader L.npy|L.bvh --music song.wav|music.npy \
             (for a quick try: --model tests/fixtures/tiny/model.duo --leader tests/fixtures/rollout_tiny_long/leader_pos3d.npy \
             --music tests/fixtures/rollout_tiny_long/music.npy)",
            looked.join(" and ")
        )
    })
}

/// Lower-case extension of a path ("" when none).
pub fn extension(p: &Path) -> String {
    p.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase()
}

/// Fails with the file, frame and channel of the first non-finite value.
pub(crate) fn check_finite(path: &Path, data: &[f32], cols: usize, what: &str) -> Result<()> {
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        bail!("{}: {what}[{}, {}] is not finite ({}); expected finite values", path.display(), i / cols, i % cols, data[i]);
    }
    Ok(())
}

/// The leader clip: (frames, 165) world joint positions, metres, 30 fps.
#[derive(Debug)]
pub struct Leader {
    pub pos3d: Vec<f32>,
    pub frames: usize,
    /// "npy" or "bvh (centimetres)" etc., for messages and the summary.
    pub source: String,
}

/// Reads the leader from `.npy` ((T, 165) or (T, 55, 3) float) or `.bvh`.
pub fn load_leader(path: &Path) -> Result<Leader> {
    match extension(path).as_str() {
        "npy" => {
            let a = read_f32_2d(path, Some(POSE_DIM), "leader joint positions (T, 165), metres, 30 fps")?;
            if a.rows == 0 {
                bail!("{}: the leader clip has 0 frames; expected (T, 165) with T > 0", path.display());
            }
            check_finite(path, &a.data, POSE_DIM, "leader")?;
            Ok(Leader { pos3d: a.data, frames: a.rows, source: "npy".into() })
        }
        "bvh" => super::leader_bvh::load(path),
        other => bail!(
            "{}: unknown leader format '.{other}'; expected .npy (T, 165) joint positions or .bvh (SMPL-X or Mixamo joint names, any frame rate; docs/LEADER_INPUT.md)",
            path.display()
        ),
    }
}

/// The music: (frames, n_music) features at 30 fps.
pub struct Music {
    pub features: Vec<f32>,
    pub frames: usize,
    pub cols: usize,
    /// Set when the input was audio: the file to copy next to the viewer.
    pub audio: Option<PathBuf>,
    /// Global tempo found in the audio (None for npy input).
    pub tempo_bpm: Option<f64>,
}

/// Reads `.npy` features ((T, n_music) float) or decodes an audio file and
/// computes the 54-d features (`n_music` must then be 54).
pub fn load_music(path: &Path, n_music: usize, model: &Path) -> Result<Music> {
    if extension(path) == "npy" {
        let what = format!("music features (T, {n_music}) at 30 fps, as `duolando features` writes");
        let a = read_f32_2d(path, Some(n_music), &what)
            .with_context(|| format!("the model {} expects {n_music} music features per frame", model.display()))?;
        check_finite(path, &a.data, n_music, "music")?;
        return Ok(Music { features: a.data, frames: a.rows, cols: n_music, audio: None, tempo_bpm: None });
    }
    if n_music != crate::music::FEATURE_DIM {
        bail!(
            "{}: audio gives {} music features per frame but the model {} expects {n_music}; pass a (T, {n_music}) .npy",
            path.display(),
            crate::music::FEATURE_DIM,
            model.display()
        );
    }
    let y = crate::audio::load_mono(path, SAMPLE_RATE)?;
    let f = Extractor::new()
        .features(&y)
        .with_context(|| format!("{}: cannot compute music features from this audio", path.display()))?;
    Ok(Music {
        features: f.data,
        frames: f.frames,
        cols: crate::music::FEATURE_DIM,
        audio: Some(path.to_path_buf()),
        tempo_bpm: Some(f.tempo_bpm),
    })
}

/// The default seed when none is given: the leader's first `hop` frames
/// turned 180 degrees about the vertical (y) axis through the point
/// [`DEFAULT_SEED_DISTANCE_M`]/2 in front of the leader's pelvis, so the
/// follower starts in the leader's pose, face to face, 0.45 m away. The
/// leader's facing is the horizontal direction `left_hip - right_hip`
/// turned 90 degrees (our rig: left = +x, facing +z); +z if degenerate.
pub fn face_to_face_start(leader: &[f32], hop: usize) -> Vec<f32> {
    let f0 = &leader[..POSE_DIM];
    let (lx, lz) = (f0[3] - f0[6], f0[5] - f0[8]);
    let n = (lx * lx + lz * lz).sqrt();
    let (fx, fz) = if n > 1e-6 { (-lz / n, lx / n) } else { (0.0, 1.0) };
    let half = DEFAULT_SEED_DISTANCE_M / 2.0;
    let (cx, cz) = (f0[0] + half * fx, f0[2] + half * fz);
    let mut out = leader[..hop * POSE_DIM].to_vec();
    for p in out.chunks_exact_mut(3) {
        p[0] = 2.0 * cx - p[0];
        p[2] = 2.0 * cz - p[2];
    }
    out
}

/// How the follower starts.
pub enum SeedChoice {
    Tokens([u32; 5]),
    Frames(Vec<f32>),
}

/// Picks the seed (shared by `dance` and `live`): `seed_tokens`
/// (--seed-tokens), `follower_start` (--follower-start), the demo start
/// (demo clip only), else [`face_to_face_start`]. Returns it and a line
/// describing it.
pub fn choose_seed(
    seed_tokens: Option<&str>,
    follower_start: Option<&Path>,
    demo: bool,
    leader: &Leader,
    cfg: &ModelConfig,
    model: &Path,
) -> Result<(SeedChoice, String)> {
    let hop = cfg.hop();
    if let Some(s) = seed_tokens {
        let t = parse_seed_tokens(s)?;
        const NAMES: [&str; 5] = ["up", "down", "lhand", "rhand", "transl"];
        for i in 0..5 {
            if t[i] >= cfg.gpt.vocab[i] {
                bail!(
                    "--seed-tokens: the {} token {} is out of range for the model {} (vocabulary {}; expected 0..{})",
                    NAMES[i],
                    t[i],
                    model.display(),
                    cfg.gpt.vocab[i],
                    cfg.gpt.vocab[i] - 1
                );
            }
        }
        return Ok((SeedChoice::Tokens(t), format!("tokens {s} (--seed-tokens)")));
    }
    let (path, why) = match follower_start {
        Some(p) => (p.to_path_buf(), "--follower-start"),
        None if demo => (require_asset(DEMO_FOLLOWER_START, "follower start")?, "the demo's follower start"),
        None => {
            let how = format!(
                "default: the leader's first {hop} frames turned 180 degrees about the vertical axis, face to face, {DEFAULT_SEED_DISTANCE_M} m in front of the leader \
                 (pass --follower-start or --seed-tokens to choose)"
            );
            return Ok((SeedChoice::Frames(face_to_face_start(&leader.pos3d, hop)), how));
        }
    };
    let a = read_f32_2d(&path, Some(POSE_DIM), "follower start frames (F, 165), metres")?;
    if a.rows < hop || a.rows > leader.frames {
        bail!(
            "{}: {} follower start frames; expected between {hop} (one token) and {} (the leader's length)",
            path.display(),
            a.rows,
            leader.frames
        );
    }
    if a.data.iter().any(|v| !v.is_finite()) {
        bail!("{}: follower start frames hold non-finite values; expected finite positions", path.display());
    }
    Ok((SeedChoice::Frames(a.data), format!("{} frames from {} ({why})", a.rows, path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn face_to_face_start_faces_the_leader_at_the_distance() {
        // A leader at the origin facing +z: left hip on +x.
        let mut l = vec![0.0f32; POSE_DIM];
        l[3] = 0.1; // left_hip x
        l[6] = -0.1; // right_hip x
        let s = face_to_face_start(&l, 1);
        assert!((s[2] - DEFAULT_SEED_DISTANCE_M).abs() < 1e-6 && s[0].abs() < 1e-6, "{:?}", &s[..3]);
        // The follower's left hip is on -x: it faces -z, towards the leader.
        assert!(s[3] < 0.0 && s[6] > 0.0);
    }
}
