//! The tiny2 fixture (tests/fixtures/tiny2, tests/fixtures/rollout_tiny2_frames),
//! loaded once per process and leaked (fuzz targets and tests share it).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use duolando::model_file::ModelFile;
use duolando::npy::{read_f32_2d, read_i64_2d};
use duolando_core::duolando::model::Model;
use duolando_core::format::DuoFile;

/// `tests/fixtures/` of the workspace.
pub fn fixtures_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("tests")
        .join("fixtures")
}

fn read(rel: &str) -> Vec<u8> {
    let p = fixtures_dir().join(rel);
    std::fs::read(&p).unwrap_or_else(|e| panic!("fixture {}: {e}", p.display()))
}

/// Bytes of tests/fixtures/tiny2/model.duo.
pub fn tiny2_duo_bytes() -> &'static [u8] {
    static B: OnceLock<Vec<u8>> = OnceLock::new();
    B.get_or_init(|| read("tiny2/model.duo"))
}

/// The btiny Bailando model (format version 2), as bytes: `duolando
/// convert` of tests/fixtures/bailando_btiny's checkpoints.
pub fn btiny_duo_bytes() -> &'static [u8] {
    static B: OnceLock<Vec<u8>> = OnceLock::new();
    B.get_or_init(|| read("bailando_btiny/model.duo"))
}

/// The tiny Transflower paper model (format version 2, family 2): `duolando
/// convert` of tests/fixtures/transflower_paper's hparams.yaml and state dict.
pub fn transflower_duo_bytes() -> &'static [u8] {
    static B: OnceLock<Vec<u8>> = OnceLock::new();
    B.get_or_init(|| read("transflower_paper/model.duo"))
}

/// The tiny2 model, bound once.
pub fn tiny2_model() -> &'static Model<'static> {
    // Statics, not `Box::leak`: LeakSanitizer (fuzz targets) reports a
    // leaked box nothing points to.
    static F: OnceLock<ModelFile> = OnceLock::new();
    static D: OnceLock<DuoFile<'static>> = OnceLock::new();
    static M: OnceLock<Model<'static>> = OnceLock::new();
    M.get_or_init(|| {
        let mf = F.get_or_init(|| {
            ModelFile::from_bytes(tiny2_duo_bytes().to_vec()).expect("tiny2 model.duo")
        });
        let duo = D.get_or_init(|| mf.duo().expect("tiny2 parses"));
        Model::from_duo(duo).expect("tiny2 binds")
    })
}

/// A recorded leader clip, its music and a valid seed for tiny2.
pub struct Clip {
    /// (T, 165) leader joint positions.
    pub leader: Vec<f32>,
    /// (T', n_music) music features.
    pub music: Vec<f32>,
    pub n_music: usize,
    pub seed: [u32; 5],
}

impl Clip {
    pub fn frames(&self) -> usize {
        self.leader.len() / 165
    }
    pub fn music_frames(&self) -> usize {
        self.music.len() / self.n_music
    }
    pub fn leader_frame(&self, i: usize) -> &[f32] {
        let i = i % self.frames();
        &self.leader[i * 165..(i + 1) * 165]
    }
    pub fn music_frame(&self, i: usize) -> &[f32] {
        let i = i % self.music_frames();
        &self.music[i * self.n_music..(i + 1) * self.n_music]
    }
}

pub fn tiny2_clip() -> &'static Clip {
    static C: OnceLock<Clip> = OnceLock::new();
    C.get_or_init(|| {
        let d = fixtures_dir();
        let leader = read_f32_2d(
            &d.join("rollout_tiny2_frames/leader_pos3d.npy"),
            Some(165),
            "leader",
        )
        .expect("leader")
        .data;
        let m =
            read_f32_2d(&d.join("rollout_tiny2_frames/music.npy"), None, "music").expect("music");
        let n_music = tiny2_model().cfg.gpt.music.n_in as usize;
        assert_eq!(m.data.len() % n_music, 0, "music width");
        let s = read_i64_2d(
            &d.join("streaming_tiny2_default/seed_tokens.npy"),
            None,
            "seed",
        )
        .expect("seed")
        .data;
        let seed = [
            s[0] as u32,
            s[1] as u32,
            s[2] as u32,
            s[3] as u32,
            s[4] as u32,
        ];
        Clip {
            leader,
            music: m.data,
            n_music,
            seed,
        }
    })
}

/// The converter's tiny2 inputs: follower-GPT YAML and three safetensors.
pub struct ConvertSources {
    pub yaml: String,
    pub gpt: Vec<u8>,
    pub vqvae: Vec<u8>,
    pub transl: Vec<u8>,
}

pub fn tiny2_convert_sources() -> &'static ConvertSources {
    static S: OnceLock<ConvertSources> = OnceLock::new();
    S.get_or_init(|| ConvertSources {
        yaml: String::from_utf8(read("tiny2/follower_gpt.yaml")).expect("utf-8 yaml"),
        gpt: read("tiny2/gpt.safetensors"),
        vqvae: read("tiny2/vqvae.safetensors"),
        transl: read("tiny2/transl.safetensors"),
    })
}
