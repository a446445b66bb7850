//! Each module of core against its ONNX export (from the Python reference,
//! `tools/make_fixtures.py`) run in tract, on random inputs: 256 proptest
//! cases per module family and model config. Float outputs within
//! `Tol::ModuleRel` (1e-4, relative to max(1, max|expected|)); codes exact
//! wherever the reference's nearest-code gap is not a near tie.

use std::sync::OnceLock;

use duolando::model_file::ModelFile;
use duolando_core::arena::Arena;
use duolando_core::duolando::config::Part;
use duolando_core::duolando::gpt::{self, GptScratch, Window};
use duolando_core::duolando::lat;
use duolando_core::duolando::model::Model;
use duolando_core::duolando::vq_decoder::{self, Output};
use duolando_core::duolando::vq_encoder;
use duolando_core::limits::VqWhich;
use duolando_tests::*;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

/// Cases per module family (issue #2 asks for >= 256); `DUO_CASES` overrides
/// it for quick local runs.
fn cases() -> u32 {
    std::env::var("DUO_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(256)
}

/// A loaded fixture model: its bytes (kept alive for the borrowed `Model`)
/// and the list of exported ONNX files.
struct Fixture {
    name: &'static str,
    file: &'static ModelFile,
    index: Vec<(String, Vec<Vec<usize>>)>,
}

impl Fixture {
    fn model(&self) -> Model<'static> {
        let duo: duolando_core::format::DuoFile<'static> = self.file.duo().unwrap();
        Model::from_duo(&duo).unwrap()
    }
    /// Files whose name starts with `prefix`, with their input shapes.
    fn files(&self, prefix: &str) -> Vec<(String, Vec<Vec<usize>>)> {
        let v: Vec<_> = self
            .index
            .iter()
            .filter(|(f, _)| f.starts_with(prefix))
            .cloned()
            .collect();
        assert!(
            !v.is_empty(),
            "{}: no ONNX export starting with {prefix}",
            self.name
        );
        v
    }
    fn onnx(&self, file: &str) -> &'static Onnx {
        // One tract plan per file for the whole test binary.
        static CACHE: OnceLock<std::sync::Mutex<std::collections::HashMap<String, &'static Onnx>>> =
            OnceLock::new();
        let key = format!("{}/{file}", self.name);
        let mut map = CACHE.get_or_init(Default::default).lock().unwrap();
        map.entry(key).or_insert_with(|| {
            Box::leak(Box::new(Onnx::load(&fixture(&format!(
                "{}/onnx/{file}",
                self.name
            )))))
        })
    }
}

fn load(name: &'static str) -> Fixture {
    let file: &'static ModelFile = Box::leak(Box::new(
        ModelFile::open(fixture(&format!("{name}/model.duo"))).unwrap(),
    ));
    let index: serde_json::Value = serde_json::from_slice(
        &std::fs::read(fixture(&format!("{name}/onnx/index.json"))).unwrap(),
    )
    .unwrap();
    let index = index
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            let shapes = e["inputs"]
                .as_array()
                .unwrap()
                .iter()
                .map(|i| {
                    i["shape"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|d| d.as_u64().unwrap() as usize)
                        .collect()
                })
                .collect();
            (e["file"].as_str().unwrap().to_string(), shapes)
        })
        .collect();
    Fixture { name, file, index }
}

fn fixtures() -> &'static [Fixture; 2] {
    static F: OnceLock<[Fixture; 2]> = OnceLock::new();
    F.get_or_init(|| [load("tiny"), load("tiny2")])
}

/// splitmix64: the inputs of a case come from its seed.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn uniform(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn normal(&mut self) -> f32 {
        let (u, v) = (self.uniform().max(1e-7), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f32::consts::TAU * v).cos()
    }
    fn normals(&mut self, n: usize, scale: f32) -> Vec<f32> {
        (0..n).map(|_| self.normal() * scale).collect()
    }
    fn tokens(&mut self, n: usize, vocab: u32) -> Vec<u32> {
        (0..n)
            .map(|_| (self.next() % vocab as u64) as u32)
            .collect()
    }
    fn pick<'a, T>(&mut self, v: &'a [T]) -> &'a T {
        &v[(self.next() % v.len() as u64) as usize]
    }
}

fn close(what: &str, actual: &[f32], expected: &[f32]) -> Result<(), TestCaseError> {
    let (abs, rel) = max_errors(actual, expected);
    // Report each new worst error per file (run with --nocapture to see the maxima).
    static WORST: OnceLock<std::sync::Mutex<std::collections::HashMap<String, f32>>> =
        OnceLock::new();
    let mut worst = WORST.get_or_init(Default::default).lock().unwrap();
    let w = worst.entry(what.to_string()).or_insert(-1.0);
    if rel > *w {
        *w = rel;
        eprintln!("worst so far {what}: rel {rel:.3e} abs {abs:.3e}");
    }
    prop_assert!(
        rel <= Tol::ModuleRel.limit(),
        "{what}: rel err {rel:.3e} (abs {abs:.3e})"
    );
    Ok(())
}

fn i64s(v: &[u32]) -> Vec<i64> {
    v.iter().map(|&t| t as i64).collect()
}

fn music_lat_case(fx: &Fixture, rng: &mut Rng) -> Result<(), TestCaseError> {
    let model = fx.model();
    let (file, shapes) = rng.pick(&fx.files("music_lat_")).clone();
    let shape = &shapes[0]; // (1, (c+lf)*4, 54)
    let scale = 0.5 + 2.0 * rng.uniform();
    let music = rng.normals(shape[1] * shape[2], scale);
    let want = as_f32(&fx.onnx(&file).run(vec![tensor_f32(shape, &music)])[0]);
    let e = model.cfg.gpt.n_embd as usize;
    let c = want.len() / e;
    let mut out = vec![0f32; c * e];
    let mut scratch = vec![0u8; lat::scratch_bytes(&model.cfg, c).unwrap()];
    lat::music_lat(&model, &music, &mut scratch, &mut out)
        .map_err(|e| TestCaseError::fail(format!("{e:?}")))?;
    close(&format!("{}/{file}", fx.name), &out, &want)
}

fn leader_lat_case(fx: &Fixture, rng: &mut Rng) -> Result<(), TestCaseError> {
    let model = fx.model();
    for part in Part::ALL {
        let (file, shapes) = rng
            .pick(&fx.files(&format!("leader_lat_{}_", part.name())))
            .clone();
        let n = shapes[0][1];
        let tokens = rng.tokens(n, model.cfg.gpt.vocab[part as usize]);
        let want = as_f32(
            &fx.onnx(&file)
                .run(vec![tensor_i64(&shapes[0], &i64s(&tokens))])[0],
        );
        let e = model.cfg.gpt.n_embd as usize;
        let c = want.len() / e;
        let mut out = vec![0f32; c * e];
        let mut scratch = vec![0u8; lat::scratch_bytes(&model.cfg, c).unwrap()];
        lat::leader_lat(&model, part, &tokens, &mut scratch, &mut out)
            .map_err(|e| TestCaseError::fail(format!("{e:?}")))?;
        close(&format!("{}/{file}", fx.name), &out, &want)?;
    }
    Ok(())
}

fn gpt_step_case(fx: &Fixture, rng: &mut Rng) -> Result<(), TestCaseError> {
    let model = fx.model();
    let cfg = &model.cfg;
    let (file, shapes) = rng.pick(&fx.files("gpt_step_")).clone();
    // inputs: f_up, f_down, f_lhand, f_rhand, f_transl (1,c); music; l_up..l_rhand (1,c+lf); one (1,)
    let c = shapes[0][1];
    let v = cfg.gpt.vocab;
    // Follower rhand is embedded with the lhand table: draw it within that vocabulary.
    let follower_vocab = [v[0], v[1], v[2], v[2].min(v[3]), v[4]];
    let f: Vec<Vec<u32>> = follower_vocab
        .iter()
        .map(|&voc| rng.tokens(c, voc))
        .collect();
    let scale = 0.5 + 2.0 * rng.uniform();
    let music = rng.normals(shapes[5][1] * shapes[5][2], scale);
    let l: Vec<Vec<u32>> = (0..4).map(|p| rng.tokens(shapes[6][1], v[p])).collect();
    let mut inputs: Vec<_> = f.iter().map(|t| tensor_i64(&[1, c], &i64s(t))).collect();
    inputs.push(tensor_f32(&shapes[5], &music));
    inputs.extend(l.iter().map(|t| tensor_i64(&shapes[6], &i64s(t))));
    inputs.push(tensor_f32(&[1], &[1.0])); // `one`: the runtime embedding tables' factor
    let want = as_f32(&fx.onnx(&file).run(inputs)[0]);
    let follower: Vec<u32> = (0..c)
        .flat_map(|i| (0..5).map(|s| f[s][i]).collect::<Vec<_>>())
        .collect();
    let win = Window {
        c,
        music: &music,
        leader: [&l[0], &l[1], &l[2], &l[3]],
        follower: &follower,
    };
    let mut buf = vec![0u8; gpt::scratch_bytes(cfg, c).unwrap()];
    let mut arena = Arena::new(&mut buf);
    let mut s = GptScratch::carve(&mut arena, cfg, c).unwrap();
    let mut logits = vec![0f32; gpt::logits_len(cfg)];
    gpt::window_logits(&model, &win, &mut s, &mut logits)
        .map_err(|e| TestCaseError::fail(format!("{e:?}")))?;
    prop_assert_eq!(logits.len(), want.len());
    close(&format!("{}/{file}", fx.name), &logits, &want)
}

/// Gap between the two nearest codebook rows of `x`, relative to the scale.
fn code_gap(codebook: &[f32], emb: usize, x: &[f32]) -> f32 {
    let (mut d1, mut d2) = (f32::INFINITY, f32::INFINITY);
    let xx: f32 = x.iter().map(|v| v * v).sum();
    let mut scale = xx;
    for k in codebook.chunks(emb) {
        let d: f32 = x.iter().zip(k).map(|(a, b)| (a - b) * (a - b)).sum();
        scale = scale.max(k.iter().map(|v| v * v).sum());
        if d < d1 {
            d2 = d1;
            d1 = d;
        } else if d < d2 {
            d2 = d;
        }
    }
    (d2 - d1) / scale.max(1e-12)
}

fn vq_names(which: VqWhich) -> (String, String) {
    match which {
        VqWhich::Part(p) => (
            format!("vq_{}_", p.name()),
            format!("motion.vqvae_{}.bottleneck.level_blocks.0.k", p.name()),
        ),
        VqWhich::Transl => (
            "transl_".to_string(),
            "transl.bottleneck.level_blocks.0.k".to_string(),
        ),
    }
}

const ALL_VQ: [VqWhich; 5] = [
    VqWhich::Part(Part::Up),
    VqWhich::Part(Part::Down),
    VqWhich::Part(Part::LHand),
    VqWhich::Part(Part::RHand),
    VqWhich::Transl,
];

fn encoder_case(fx: &Fixture, rng: &mut Rng, near_ties: &mut usize) -> Result<(), TestCaseError> {
    let model = fx.model();
    let duo = fx.file.duo().unwrap();
    for which in ALL_VQ {
        let (prefix, k_name) = vq_names(which);
        let (file, shapes) = rng.pick(&fx.files(&format!("{prefix}encoder_t"))).clone();
        let scale = 0.1 + 0.6 * rng.uniform();
        let x = rng.normals(shapes[0][1] * shapes[0][2], scale);
        let outs = fx.onnx(&file).run(vec![tensor_f32(&shapes[0], &x)]);
        let (want_feat, want_codes) = (as_f32(&outs[0]), as_i64(&outs[1]));
        let emb = model.vq(which).cfg.emb_width as usize;
        let mut feat = vec![0f32; want_feat.len()];
        let mut codes = vec![0u32; want_codes.len()];
        let mut scratch = vec![0u8; vq_encoder::scratch_bytes(&model.cfg, shapes[0][1]).unwrap()];
        vq_encoder::encode_part(&model, which, &x, &mut scratch, &mut feat, &mut codes)
            .map_err(|e| TestCaseError::fail(format!("{e:?}")))?;
        close(&format!("{}/{file} features", fx.name), &feat, &want_feat)?;
        let codebook = duo.tensor(&k_name).unwrap().as_f32().unwrap();
        for (i, (&got, &want)) in codes.iter().zip(&want_codes).enumerate() {
            let gap = code_gap(codebook, emb, &want_feat[i * emb..(i + 1) * emb]);
            if gap < 1e-5 {
                *near_ties += 1; // f32 round-off may legitimately pick either row
                continue;
            }
            prop_assert_eq!(
                got as i64,
                want,
                "{}/{} code {} (gap {:.2e})",
                fx.name,
                file,
                i,
                gap
            );
        }
    }
    Ok(())
}

fn decoder_case(fx: &Fixture, rng: &mut Rng) -> Result<(), TestCaseError> {
    let model = fx.model();
    for which in ALL_VQ {
        let (prefix, _) = vq_names(which);
        let outputs: &[(&str, Output)] = match which {
            VqWhich::Transl => &[("decoder_q", Output::Position)],
            _ => &[
                ("decoder_pos_q", Output::Position),
                ("decoder_rot_q", Output::Rotation),
            ],
        };
        for (suffix, output) in outputs {
            let (file, shapes) = rng.pick(&fx.files(&format!("{prefix}{suffix}"))).clone();
            let codes = rng.tokens(shapes[0][1], model.vq(which).cfg.l_bins);
            let want = as_f32(
                &fx.onnx(&file)
                    .run(vec![tensor_i64(&shapes[0], &i64s(&codes))])[0],
            );
            let mut out = vec![0f32; want.len()];
            let mut scratch =
                vec![0u8; vq_decoder::scratch_bytes(&model.cfg, codes.len()).unwrap()];
            vq_decoder::decode_codes(&model, which, *output, &codes, &mut scratch, &mut out)
                .map_err(|e| TestCaseError::fail(format!("{e:?}")))?;
            close(&format!("{}/{file}", fx.name), &out, &want)?;
        }
    }
    Ok(())
}

macro_rules! module_test {
    ($name:ident, $case:ident) => {
        proptest! {
            #![proptest_config(ProptestConfig { cases: cases(), failure_persistence: None, max_shrink_iters: 16, ..ProptestConfig::default() })]
            #[test]
            fn $name(seed in any::<u64>()) {
                for fx in fixtures() {
                    $case(fx, &mut Rng(seed))?;
                }
            }
        }
    };
}

module_test!(music_lat_matches_tract, music_lat_case);
module_test!(leader_lats_match_tract, leader_lat_case);
module_test!(gpt_window_step_logits_match_tract, gpt_step_case);
module_test!(vq_decoders_match_tract, decoder_case);

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(), failure_persistence: None, max_shrink_iters: 16, ..ProptestConfig::default() })]
    #[test]
    fn vq_encoders_features_and_codes_match_tract(seed in any::<u64>()) {
        let mut near_ties = 0;
        for fx in fixtures() {
            encoder_case(fx, &mut Rng(seed), &mut near_ties)?;
        }
        // Near ties must stay rare, or the code comparison would be vacuous.
        prop_assert!(near_ties <= 2, "{} near-tie codes in one case", near_ties);
    }
}
