//! Bailando R mode against the goldens of the authors' own classes
//! (tools/make_bailando_fixtures.py; tools/reference/bailando/README.md):
//! tokens and seed codes exact, first-step logits and positions within
//! named tolerances, on both of the authors' eval paths (AIST++ test path
//! seeded from the encoded dance, music-only demo path), two configs,
//! the shortest valid inputs and windows that slide.

use std::collections::HashMap;
use std::path::Path;

use duolando::convert::parse_bailando_config;
use duolando::npy::{read_f32_2d, read_i64_2d};
use duolando_core::bailando::config::{BailandoConfig, POSE_DIM};
use duolando_core::bailando::exact::{
    dance_scratch_bytes, decode, decode_scratch_bytes, sample, sample_scratch_bytes,
    seed_from_dance, steps, MusicPadding,
};
use duolando_core::bailando::gpt::{logits_len, window_logits, GptScratch};
use duolando_core::bailando::model::Model;
use duolando_core::nn::bind::TensorSource;
use duolando_core::tensor::{DType, TensorRef};
use duolando_tests::{fixture, max_errors};

/// Positions (|pos| <= 6.2): the goldens are float32 torch, whose own
/// f32-vs-f64 difference is <= 1.5e-6; ours differ by <= 1.9e-6 (summation
/// order), measured on all eight goldens.
const POS_TOL: f32 = 1e-5;
/// Logits of the first step (reference f32-vs-f64 <= 9.2e-7).
const LOGIT_TOL: f32 = 1e-5;

/// The authors' checkpoints as a tensor source: `module.` stripped, behind
/// the component prefix (`gpt.`, `motion.`), f32 copies (aligned).
struct Weights {
    tensors: HashMap<String, (Vec<u32>, Vec<f32>)>,
}

impl Weights {
    fn load(dir: &Path) -> Weights {
        let mut tensors = HashMap::new();
        for (file, prefix) in [
            ("gpt.safetensors", "gpt."),
            ("vqvae.safetensors", "motion."),
        ] {
            let bytes = std::fs::read(dir.join(file)).unwrap();
            let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
            for (name, view) in st.tensors() {
                assert_eq!(view.dtype(), safetensors::Dtype::F32, "{name}");
                let data: Vec<f32> = view
                    .data()
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                    .collect();
                let shape = view.shape().iter().map(|&d| d as u32).collect();
                let key = format!("{prefix}{}", name.strip_prefix("module.").unwrap_or(&name));
                tensors.insert(key, (shape, data));
            }
        }
        Weights { tensors }
    }
}

impl<'a> TensorSource<'a> for &'a Weights {
    fn tensor(&self, name: &str) -> Option<TensorRef<'a>> {
        let (shape, data) = self.tensors.get(name)?;
        let mut s = [1u32; 4];
        s[..shape.len()].copy_from_slice(shape);
        Some(TensorRef {
            dtype: DType::F32,
            rank: shape.len() as u8,
            shape: s,
            data: bytemuck::cast_slice(data),
        })
    }
}

fn config(model: &str, yaml: &str) -> BailandoConfig {
    let path = fixture(&format!("bailando_{model}/{yaml}"));
    parse_bailando_config(&path, &std::fs::read_to_string(&path).unwrap()).unwrap()
}

fn check(name: &str) {
    let dir = fixture(&format!("bailando_rollout_{name}"));
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("meta.json")).unwrap()).unwrap();
    let model_name = meta["model"].as_str().unwrap();
    let cfg = config(model_name, meta["config"].as_str().unwrap());
    let weights = Weights::load(&fixture(&format!("bailando_{model_name}")));
    let model = Model::bind(&cfg, &&weights).unwrap();
    let music = read_f32_2d(&dir.join("music.npy"), None, "music").unwrap();
    let aist = meta["path"].as_str().unwrap() == "aist";
    let padding = if aist {
        MusicPadding::Aist
    } else {
        MusicPadding::Demo
    };
    let want_seed = [
        meta["seed_tokens"][0].as_u64().unwrap() as u32,
        meta["seed_tokens"][1].as_u64().unwrap() as u32,
    ];
    let seed = if aist {
        let dance = read_f32_2d(&dir.join("dance.npy"), Some(POSE_DIM), "dance").unwrap();
        let mut scratch = vec![0u8; dance_scratch_bytes(&cfg, dance.rows).unwrap()];
        let seed = seed_from_dance(&model, &dance.data, &mut scratch).unwrap();
        let codes = read_i64_2d(&dir.join("dance_codes.npy"), Some(2), "codes").unwrap();
        assert_eq!(
            [seed[0] as i64, seed[1] as i64],
            [codes.data[0], codes.data[1]],
            "{name}: seed = first dance codes"
        );
        seed
    } else {
        want_seed
    };
    assert_eq!(seed, want_seed, "{name}: seed");

    // First step's logits (window of one token, music row 1).
    let nm = cfg.gpt.n_music as usize;
    let mut s_bytes = vec![0u8; sample_scratch_bytes(&cfg).unwrap()];
    {
        let mut a = duolando_core::arena::Arena::new(&mut s_bytes);
        let mut gs = GptScratch::carve(&mut a, &cfg, 1).unwrap();
        let r = 1.min(music.rows - 1);
        let mut logits = vec![0f32; logits_len(&cfg)];
        window_logits(
            &model,
            &seed,
            &music.data[r * music.cols..r * music.cols + nm],
            &mut gs,
            &mut logits,
        )
        .unwrap();
        let want = read_f32_2d(&dir.join("logits_step0.npy"), None, "logits").unwrap();
        let (abs, _) = max_errors(&logits, &want.data);
        assert!(
            abs <= LOGIT_TOL,
            "{name}: logits step 0 max abs err {abs:e} > {LOGIT_TOL:e}"
        );
    }

    let k = steps(padding, music.rows);
    assert_eq!(k as u64, meta["K"].as_u64().unwrap(), "{name}: K");
    let mut tokens = vec![0u32; (k + 1) * 2];
    sample(
        &model,
        &music.data,
        music.cols,
        padding,
        seed,
        &mut s_bytes,
        &mut tokens,
    )
    .unwrap();
    let want = read_i64_2d(&dir.join("tokens.npy"), Some(2), "tokens").unwrap();
    let got: Vec<i64> = tokens.iter().map(|&t| t as i64).collect();
    let first = got.iter().zip(&want.data).position(|(a, b)| a != b);
    assert_eq!(
        first, None,
        "{name}: first token mismatch at flat index {first:?}"
    );
    assert_eq!(got.len(), want.data.len());

    let mut d_bytes = vec![0u8; decode_scratch_bytes(&cfg, k + 1).unwrap()];
    let mut pos = vec![0f32; (k + 1) * cfg.hop() * POSE_DIM];
    decode(&model, &tokens, &mut d_bytes, &mut pos).unwrap();
    let want = read_f32_2d(&dir.join("pos3d.npy"), Some(POSE_DIM), "pos3d").unwrap();
    assert_eq!(pos.len(), want.data.len(), "{name}: frames");
    let (abs, rel) = max_errors(&pos, &want.data);
    eprintln!(
        "{name}: K {k}, {} frames, positions max abs err {abs:.2e} (rel {rel:.2e})",
        want.rows
    );
    assert!(
        abs <= POS_TOL,
        "{name}: positions max abs err {abs:e} > {POS_TOL:e}"
    );
}

#[test]
fn btiny_aist_min() {
    check("btiny_aist_min");
}
#[test]
fn btiny_aist_slide() {
    check("btiny_aist_slide");
}
#[test]
fn btiny_demo_min() {
    check("btiny_demo_min");
}
#[test]
fn btiny_demo_odd() {
    check("btiny_demo_odd");
}
#[test]
fn btiny2_aist_odd() {
    check("btiny2_aist_odd");
}
#[test]
fn btiny2_aist_short() {
    check("btiny2_aist_short");
}
#[test]
fn btiny2_demo_slide() {
    check("btiny2_demo_slide");
}
#[test]
fn btiny2_demo_exact() {
    check("btiny2_demo_exact");
}

/// The schema lists exactly the inference weights of the authors'
/// checkpoints (everything but the critic and the attention masks), with
/// their shapes; the binder takes each from the schema.
#[test]
fn schema_lists_exactly_the_inference_weights() {
    for model in ["btiny", "btiny2"] {
        let cfg = config(model, "actor_critic.yaml");
        let w = Weights::load(&fixture(&format!("bailando_{model}")));
        let mut listed = Vec::new();
        duolando_core::bailando::schema::for_each_tensor::<duolando_core::nn::names::SchemaError>(
            &cfg,
            &mut |spec| {
                let (shape, _) = w
                    .tensors
                    .get(spec.name.as_str())
                    .unwrap_or_else(|| panic!("{model}: {} not in the checkpoint", spec.name));
                assert_eq!(shape.as_slice(), spec.dims(), "{model}: {}", spec.name);
                listed.push(spec.name.to_string());
                Ok(())
            },
        )
        .unwrap();
        let mut stored: Vec<String> = w
            .tensors
            .keys()
            .filter(|k| !k.starts_with("gpt.critic_net.") && !k.ends_with(".attn.mask"))
            .cloned()
            .collect();
        listed.sort();
        stored.sort();
        assert_eq!(listed, stored, "{model}");
        assert_eq!(
            listed.len(),
            duolando_core::bailando::schema::tensor_count(&cfg)
        );
    }
}

/// Bad configs and weights are refused by name, before anything runs.
#[test]
fn bad_configs_and_missing_weights_are_refused() {
    use duolando_core::limits::{ConfigError, ConfigField};
    use duolando_core::nn::bind::BindError;
    let cfg = config("btiny", "actor_critic.yaml");
    let mut c = cfg;
    c.gpt.vocab[1] += 1;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::Mismatch {
            field: ConfigField::Vocab(1),
            ..
        })
    ));
    let mut c = cfg;
    c.gpt.n_head = 5;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::NotDivisible {
            field: ConfigField::NEmbd,
            ..
        })
    ));
    let mut c = cfg;
    c.gpt.n_music = 0;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::Zero {
            field: ConfigField::NMusic
        })
    ));
    let mut w = Weights::load(&fixture("bailando_btiny"));
    w.tensors
        .remove("motion.vqvae_down.decoders_root.0.out.weight");
    match Model::bind(&cfg, &&w) {
        Err(BindError::Missing { name }) => assert_eq!(
            name.as_str(),
            "motion.vqvae_down.decoders_root.0.out.weight"
        ),
        other => panic!("expected Missing, got {:?}", other.map(|_| ())),
    }
    // A Duolando YAML is not read as Bailando's, and the reverse.
    let duo = std::fs::read_to_string(fixture("tiny/follower_gpt.yaml")).unwrap();
    assert!(!duolando::convert::is_bailando(&duo));
    assert!(duolando::convert::is_bailando(
        &std::fs::read_to_string(fixture("bailando_btiny/actor_critic.yaml")).unwrap()
    ));
}

/// Bad input at run time: a named error, no panic.
#[test]
fn bad_music_seed_and_tokens_are_refused() {
    use duolando_core::error::Error;
    let cfg = config("btiny", "actor_critic.yaml");
    let w = Weights::load(&fixture("bailando_btiny"));
    let model = Model::bind(&cfg, &&w).unwrap();
    let nm = cfg.gpt.n_music as usize;
    let mut s = vec![0u8; sample_scratch_bytes(&cfg).unwrap()];
    let mut tokens = vec![0u32; 4];
    let music = vec![0.1f32; nm];
    assert!(matches!(
        sample(
            &model,
            &music[..nm - 1],
            nm - 1,
            MusicPadding::Aist,
            [0, 0],
            &mut s,
            &mut tokens
        ),
        Err(Error::Ragged { .. })
    ));
    assert!(matches!(
        sample(
            &model,
            &music,
            nm,
            MusicPadding::Aist,
            [cfg.gpt.vocab[0], 0],
            &mut s,
            &mut tokens
        ),
        Err(Error::Token { stream: 0, .. })
    ));
    let mut nan = music.clone();
    nan[3] = f32::NAN;
    assert!(matches!(
        sample(
            &model,
            &nan,
            nm,
            MusicPadding::Aist,
            [0, 0],
            &mut s,
            &mut tokens
        ),
        Err(Error::NonFinite { index: 3, .. })
    ));
    assert!(matches!(
        sample(
            &model,
            &music,
            nm,
            MusicPadding::Aist,
            [0, 0],
            &mut s[..16],
            &mut tokens
        ),
        Err(Error::Arena(_))
    ));
    assert!(matches!(
        sample(
            &model,
            &music,
            nm,
            MusicPadding::Aist,
            [0, 0],
            &mut s,
            &mut tokens[..3]
        ),
        Err(Error::Length { .. })
    ));
    let mut d = vec![0u8; decode_scratch_bytes(&cfg, 2).unwrap()];
    let mut pos = vec![0f32; 2 * cfg.hop() * POSE_DIM];
    assert!(matches!(
        decode(&model, &[0, 0, cfg.gpt.vocab[0], 0], &mut d, &mut pos),
        Err(Error::Token { .. })
    ));
    let mut ds = vec![0u8; dance_scratch_bytes(&cfg, 1).unwrap()];
    assert!(matches!(
        seed_from_dance(&model, &[0.0; POSE_DIM - 1], &mut ds),
        Err(Error::Ragged { .. })
    ));
}

/// The authors' checkpoints through `convert` (format version 2, family
/// Bailando; the critic skipped and counted, the masks checked) give a
/// `.duo` whose model samples the same tokens; a Duolando binder refuses
/// it by family.
#[test]
fn converted_file_samples_the_same_tokens() {
    use duolando::convert::bailando::convert_bailando;
    use duolando::duo_writer::StoreAs;
    use duolando::model_file::ModelFile;
    use duolando_core::family::Family;
    use duolando_core::nn::bind::BindError;
    let dir = fixture("bailando_btiny");
    let cfg = config("btiny", "actor_critic.yaml");
    let (g, v) = (
        std::fs::read(dir.join("gpt.safetensors")).unwrap(),
        std::fs::read(dir.join("vqvae.safetensors")).unwrap(),
    );
    let (bytes, r) = convert_bailando(
        &cfg,
        (&dir.join("gpt.safetensors"), &g),
        (&dir.join("vqvae.safetensors"), &v),
        StoreAs::F32,
        Path::new("<memory>"),
    )
    .unwrap();
    assert_eq!(
        r.critic_skipped, 21,
        "the critic_net tensors of the btiny checkpoint"
    );
    assert_eq!(r.report.masks_checked, 2);
    // The committed model.duo (the fuzz targets' Bailando base) is this
    // conversion, byte for byte: `duolando convert --config
    // actor_critic.yaml --gpt gpt.safetensors --vqvae vqvae.safetensors`.
    assert!(
        std::fs::read(dir.join("model.duo")).unwrap() == bytes,
        "tests/fixtures/bailando_btiny/model.duo is stale: regenerate it with duolando convert"
    );
    let file = ModelFile::from_bytes(bytes).unwrap();
    let duo = file.duo().unwrap();
    assert_eq!(duo.prefix().version, 2);
    assert_eq!(duo.config().family(), Family::Bailando);
    assert_eq!(duo.config().bailando(), Some(&cfg));
    match duolando_core::duolando::model::Model::from_duo(&duo) {
        Err(BindError::Family {
            expected: Family::Duolando,
            found: Family::Bailando,
        }) => {}
        other => panic!("expected a family refusal, got {:?}", other.map(|_| ())),
    }
    let model = Model::from_duo(&duo).unwrap();
    let rdir = fixture("bailando_rollout_btiny_demo_odd");
    let music = read_f32_2d(&rdir.join("music.npy"), None, "music").unwrap();
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(rdir.join("meta.json")).unwrap()).unwrap();
    let seed = [
        meta["seed_tokens"][0].as_u64().unwrap() as u32,
        meta["seed_tokens"][1].as_u64().unwrap() as u32,
    ];
    let k = steps(MusicPadding::Demo, music.rows);
    let mut tokens = vec![0u32; (k + 1) * 2];
    let mut s = vec![0u8; sample_scratch_bytes(&cfg).unwrap()];
    sample(
        &model,
        &music.data,
        music.cols,
        MusicPadding::Demo,
        seed,
        &mut s,
        &mut tokens,
    )
    .unwrap();
    let want = read_i64_2d(&rdir.join("tokens.npy"), Some(2), "tokens").unwrap();
    assert_eq!(
        tokens.iter().map(|&t| t as i64).collect::<Vec<_>>(),
        want.data
    );
}

/// The published config's schema holds exactly the authors' published
/// parameter counts (tools/reference/bailando/README.md, from their
/// classes on configs/actor_critic.yaml): the VQ-VAE's 65,068,619
/// parameters plus its two 512 x 512 codebooks (buffers, not parameters);
/// the GPT's 108,299,520 parameters less the critic's.
#[test]
fn published_config_has_the_published_sizes() {
    let cfg = duolando_core::bailando::config::published();
    cfg.validate().unwrap();
    let (mut gpt, mut motion) = (0u64, 0u64);
    duolando_core::bailando::schema::for_each_tensor::<duolando_core::nn::names::SchemaError>(
        &cfg,
        &mut |s| {
            let n: u64 = s.dims().iter().map(|&d| d as u64).product();
            if s.name.starts_with("gpt.") {
                gpt += n;
            } else {
                motion += n;
            }
            Ok(())
        },
    )
    .unwrap();
    eprintln!("published Bailando: gpt {gpt}, motion {motion}");
    assert_eq!(motion, 65_068_619 + 2 * 512 * 512);
    // The reference README gives the critic as 21.3 M (rounded).
    let critic = 108_299_520 - gpt;
    assert!(
        (21_250_000..21_350_000).contains(&critic),
        "critic {critic}"
    );
}
