//! Transflower as a `.duo` family (format version 2, tag 2): the
//! converter (the authors' hparams.yaml + the state dict) gives files whose
//! models reproduce the goldens of the authors' classes
//! (tools/make_transflower_fixtures.py) bit for bit against binding the
//! state dict directly; the committed paper model is that conversion;
//! families refuse each other by name; files of the other families open
//! unchanged; f16 / int8 weights bind and run (errors measured); the
//! converter refuses what it cannot represent, by name.
//!
//! Error metric (as meta.json's): rel = max |a - b| / max(1, max |b|).

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use duolando::convert::transflower::{convert_transflower, parse_transflower_config};
use duolando::convert::ConvertError;
use duolando::duo_writer::StoreAs;
use duolando::model_file::ModelFile;
use duolando_core::family::{Family, FamilyConfig};
use duolando_core::nn::bind::{BindError, TensorSource};
use duolando_core::tensor::{DType, TensorRef};
use duolando_core::transflower::config::TransflowerConfig;
use duolando_core::transflower::exact::{generate, generate_scratch_bytes, steps, Input, Replay};
use duolando_core::transflower::hparams::Hparams;
use duolando_core::transflower::model::{Model, ModelError};
use duolando_tests::fixture;

/// Frames vs the golden: 4 x the reference's own float32-vs-float64
/// difference on the case (as tests/transflower_exact.rs).
const OUTPUT_TOL_FACTOR: f32 = 4.0;
/// f16 weights (every matrix rounded to f16; vectors and the flow f32)
/// vs the golden, measured on the four cases (max 1.7e-3, slide).
const F16_TOL: f32 = 5e-3;
/// int8 on the fixtures: no row of theirs is a multiple of 32, so every
/// matrix falls back to f16 (measured as f16).
const INT8_FIXTURE_TOL: f32 = 5e-3;
/// int8 (Q8Block32x8 matrices) vs f32 on a 32-wide model with seeded
/// weights, 8 free-running frames: measured 1.8e-2.
const INT8_TOL: f32 = 5e-2;

const CASES: [&str; 4] = ["paper", "label", "min", "slide"];

fn dir(case: &str) -> PathBuf {
    fixture(&format!("transflower_{case}"))
}

fn npy_f32(path: &Path) -> (Vec<u64>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    let f = npyz::NpyFile::new(bytes.as_slice()).unwrap();
    (f.shape().to_vec(), f.into_vec::<f32>().unwrap())
}

fn rel_err(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    let (mut abs, mut scale) = (0f32, 1f32);
    for (&x, &y) in a.iter().zip(b) {
        assert!(x.is_finite(), "non-finite {x}");
        abs = abs.max((x - y).abs());
        scale = scale.max(y.abs());
    }
    abs / scale
}

fn config(case: &str) -> TransflowerConfig {
    let p = dir(case).join("hparams.yaml");
    parse_transflower_config(&p, &std::fs::read_to_string(&p).unwrap()).unwrap()
}

fn convert(
    case: &str,
    store_as: StoreAs,
) -> (Vec<u8>, duolando::convert::transflower::TransflowerReport) {
    let w = dir(case).join("model.safetensors");
    convert_transflower(
        &config(case),
        (&w, &std::fs::read(&w).unwrap()),
        store_as,
        Path::new("<memory>"),
    )
    .unwrap()
}

/// The state dict as a tensor source (f32, names unchanged).
struct Weights(HashMap<String, (Vec<u32>, Vec<f32>)>);

impl<'a> TensorSource<'a> for &'a Weights {
    fn tensor(&self, name: &str) -> Option<TensorRef<'a>> {
        let (shape, data) = self.0.get(name)?;
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

fn weights(case: &str) -> Weights {
    let bytes = std::fs::read(dir(case).join("model.safetensors")).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    Weights(
        st.tensors()
            .into_iter()
            .map(|(n, v)| {
                (
                    n,
                    (
                        v.shape().iter().map(|&d| d as u32).collect(),
                        v.data()
                            .chunks_exact(4)
                            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                            .collect(),
                    ),
                )
            })
            .collect(),
    )
}

/// The case's inputs: rows per continuous input, the label of a discrete one.
fn inputs(case: &str, cfg: &TransflowerConfig) -> Vec<Result<Vec<f32>, u32>> {
    cfg.inputs()
        .iter()
        .map(|i| {
            let p = dir(case).join(format!("in_{}.npy", i.name.as_str()));
            if i.is_discrete() {
                let b = std::fs::read(p).unwrap();
                Err(npyz::NpyFile::new(b.as_slice())
                    .unwrap()
                    .into_vec::<i64>()
                    .unwrap()[0] as u32)
            } else {
                Ok(npy_f32(&p).1)
            }
        })
        .collect()
}

/// R mode of `model` on the case's inputs with its recorded noise.
fn run(case: &str, model: &Model<'_>) -> Vec<f32> {
    let raw = inputs(case, &model.cfg);
    let ins: Vec<Input<'_>> = raw
        .iter()
        .map(|x| {
            x.as_ref()
                .map_or_else(|l| Input::Label(*l), |r| Input::Rows(r))
        })
        .collect();
    let n = steps(&model.cfg, &ins).unwrap();
    let noise = npy_f32(&dir(case).join("noise.npy")).1;
    let mut scratch = vec![0u8; generate_scratch_bytes(&model.cfg).unwrap()];
    let mut out = vec![0f32; n * model.cfg.channels()];
    generate(
        model,
        &ins,
        &mut Replay { noise: &noise },
        &mut scratch,
        &mut out,
    )
    .unwrap();
    out
}

fn golden_tol(case: &str) -> f32 {
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir(case).join("meta.json")).unwrap()).unwrap();
    OUTPUT_TOL_FACTOR
        * meta["f32_vs_f64_output_max_rel_err_per_step"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .fold(0.0, f32::max)
}

/// Every case: the converted f32 file gives the same frames, bit for bit,
/// as binding the state dict directly, and so matches the golden; the
/// config read by the converter is core's `from_hparams`; the skipped
/// buffers are counted.
#[test]
fn converted_models_reproduce_the_goldens() {
    for case in CASES {
        let cfg = config(case);
        let text = std::fs::read_to_string(dir(case).join("hparams.yaml")).unwrap();
        assert_eq!(
            cfg,
            TransflowerConfig::from_hparams(&Hparams::parse(&text).unwrap()).unwrap(),
            "{case}"
        );
        let (bytes, r) = convert(case, StoreAs::F32);
        let w = weights(case);
        let buffers =
            w.0.keys()
                .filter(|k| k.ends_with(".is_initialized") || k.ends_with(".bounds"))
                .count();
        assert_eq!(r.report.skipped, buffers, "{case}");
        assert_eq!(
            r.is_initialized_skipped + r.bounds_skipped,
            buffers,
            "{case}"
        );
        assert_eq!(r.report.written + r.report.skipped, w.0.len(), "{case}");
        let file = ModelFile::from_bytes(bytes).unwrap();
        let duo = file.duo().unwrap();
        assert_eq!(duo.prefix().version, 2);
        assert_eq!(duo.config().family(), Family::Transflower);
        assert_eq!(duo.config().transflower(), Some(&cfg));
        let from_file = run(case, &Model::from_duo(&duo).unwrap());
        let direct = run(case, &Model::bind(&cfg, &&w).unwrap());
        assert!(
            from_file == direct,
            "{case}: the .duo model differs from the state dict's"
        );
        let (shape, want) = npy_f32(&dir(case).join("output.npy"));
        assert_eq!(
            shape,
            [
                (from_file.len() / cfg.channels()) as u64,
                1,
                cfg.channels() as u64
            ]
        );
        let e = rel_err(&from_file, &want);
        eprintln!(
            "{case}: {} tensors, {} skipped, max rel err {e:.2e}",
            r.report.written, r.report.skipped
        );
        assert!(e <= golden_tol(case), "{case}: {e:e}");
    }
}

/// tests/fixtures/transflower_paper/model.duo is the f32 conversion of the
/// paper case, byte for byte (`duolando convert --config hparams.yaml
/// --weights model.safetensors -o model.duo`).
#[test]
fn committed_paper_model_is_the_conversion() {
    let (bytes, _) = convert("paper", StoreAs::F32);
    assert!(
        std::fs::read(dir("paper").join("model.duo")).unwrap() == bytes,
        "tests/fixtures/transflower_paper/model.duo is stale: regenerate it with duolando convert"
    );
}

/// A Transflower file binds only as Transflower; the other families'
/// binders refuse it by family, and Transflower's binder refuses theirs;
/// their committed files open unchanged (version 1 Duolando, version 2
/// Bailando).
#[test]
fn families_refuse_each_other() {
    let tf = ModelFile::open(&dir("paper").join("model.duo")).unwrap();
    let duo = tf.duo().unwrap();
    match duolando_core::duolando::model::Model::from_duo(&duo) {
        Err(BindError::Family {
            expected: Family::Duolando,
            found: Family::Transflower,
        }) => {}
        other => panic!("{:?}", other.map(|_| ())),
    }
    match duolando_core::bailando::model::Model::from_duo(&duo) {
        Err(BindError::Family {
            expected: Family::Bailando,
            found: Family::Transflower,
        }) => {}
        other => panic!("{:?}", other.map(|_| ())),
    }
    for (path, version, family) in [
        ("tiny/model.duo", 1, Family::Duolando),
        ("bailando_btiny/model.duo", 2, Family::Bailando),
    ] {
        let f = ModelFile::open(&fixture(path)).unwrap();
        let d = f.duo().unwrap();
        assert_eq!(
            (d.prefix().version, d.config().family()),
            (version, family),
            "{path}"
        );
        let r = Model::from_duo(&d).map(|_| ());
        match r {
            Err(ModelError::Bind(BindError::Family {
                expected: Family::Transflower,
                found,
            })) => assert_eq!(found, family),
            other => panic!("{path}: {other:?}"),
        }
    }
    assert_eq!(
        duolando_core::family::Family::from_tag(2),
        Some(Family::Transflower)
    );
    assert_eq!(Family::Transflower as u32, 2);
}

/// The header's config round-trips through postcard (tag 2 first), for
/// both published structures (paper: channel concat, BatchNorm, normal;
/// label: a style label, stacked rows, ActNorm, Student-t).
#[test]
fn config_round_trips_through_the_header() {
    for case in ["paper", "label"] {
        let fc = FamilyConfig::Transflower(config(case));
        let bytes = postcard::to_stdvec(&fc).unwrap();
        assert_eq!(bytes[0], 2, "{case}: the family tag");
        let back: FamilyConfig = postcard::from_bytes(&bytes).unwrap();
        assert_eq!(back, fc, "{case}");
        assert!(back.validate().is_ok());
        assert_eq!(
            fc.tensor_count(),
            duolando_core::transflower::schema::tensor_count(&config(case))
        );
    }
}

/// f16 and int8 files bind and run; their frames stay within the measured
/// errors of the golden (the flow's parameters, biases and norms stay f32).
#[test]
fn f16_and_int8_weights_bind_and_run() {
    for case in CASES {
        for (store, tol, label) in [
            (StoreAs::F16, F16_TOL, "f16"),
            (StoreAs::Q8Block32, INT8_FIXTURE_TOL, "int8"),
        ] {
            let (bytes, _) = convert(case, store);
            let file = ModelFile::from_bytes(bytes).unwrap();
            let duo = file.duo().unwrap();
            let mut dtypes: BTreeMap<String, usize> = BTreeMap::new();
            for e in duo.tensors() {
                *dtypes.entry(format!("{:?}", e.dtype)).or_default() += 1;
            }
            let got = run(case, &Model::from_duo(&duo).unwrap());
            let want = npy_f32(&dir(case).join("output.npy")).1;
            let e = rel_err(&got, &want);
            eprintln!("{case} {label}: {dtypes:?}, max rel err {e:.2e}");
            assert!(e <= tol, "{case} {label}: {e:e} > {tol:e}");
        }
    }
}

/// The converter refuses, by name: an option the engine does not
/// implement, a value of the wrong kind, a tensor the model does not use,
/// a missing tensor, a wrong shape.
#[test]
fn converter_refusals_name_what_is_wrong() {
    let p = dir("paper").join("hparams.yaml");
    let text = std::fs::read_to_string(&p).unwrap();
    for (key, value, words) in [
        ("residual", "true", "residual"),
        ("scales", "'[[8,0],[8,0]]'", "scales"),
        ("num_mixture_components", "4", "num_mixture_components"),
        ("use_rel_pos_emb_output", "true", "use_rel_pos_emb_output"),
        ("glow_norm_layer", "layernorm", "glow_norm_layer"),
        ("model", "transformer", "`model` is not `transflower`"),
        ("nhead", "3", "`dhid` = 16 is not a multiple of 3"),
    ] {
        let edited: String = text
            .lines()
            .map(|l| {
                if l.starts_with(&format!("{key}:")) {
                    format!("{key}: {value}\n")
                } else {
                    format!("{l}\n")
                }
            })
            .collect();
        match parse_transflower_config(&p, &edited) {
            Err(e @ ConvertError::TransflowerConfig { .. }) => {
                assert!(e.to_string().contains(words), "{key}: {e}")
            }
            other => panic!("{key}: {other:?}"),
        }
    }
    let edited = text.replace("dhid: 16", "dhid: sixteen");
    match parse_transflower_config(&p, &edited) {
        Err(ConvertError::ConfigKey { key, .. }) => assert_eq!(key, "dhid"),
        other => panic!("{other:?}"),
    }
    // Weights: one extra, one missing, one with another shape.
    let cfg = config("paper");
    let w = weights("paper");
    let save = |edit: &dyn Fn(&mut BTreeMap<String, (Vec<usize>, Vec<u8>)>)| -> Vec<u8> {
        let mut m: BTreeMap<String, (Vec<usize>, Vec<u8>)> =
            w.0.iter()
                .map(|(n, (s, v))| {
                    (
                        n.clone(),
                        (
                            s.iter().map(|&d| d as usize).collect(),
                            v.iter().flat_map(|x| x.to_le_bytes()).collect(),
                        ),
                    )
                })
                .collect();
        edit(&mut m);
        let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = m
            .iter()
            .map(|(n, (s, b))| {
                (
                    n.clone(),
                    safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b)
                        .unwrap(),
                )
            })
            .collect();
        safetensors::serialize(views, &None).unwrap()
    };
    let conv = |bytes: &[u8]| {
        convert_transflower(
            &cfg,
            (Path::new("w.safetensors"), bytes),
            StoreAs::F32,
            Path::new("<memory>"),
        )
    };
    let bias = "net_input_audio_feats_scaled_20.decoder.bias";
    match conv(&save(&|m| {
        m.insert(
            "net_output_expmap_scaled_20.mean_encoder.weight".into(),
            (vec![2], vec![0; 8]),
        );
    })) {
        Err(ConvertError::Extra { tensors, .. }) => {
            assert_eq!(tensors, ["net_output_expmap_scaled_20.mean_encoder.weight"])
        }
        other => panic!("{:?}", other.map(|_| ())),
    }
    match conv(&save(&|m| {
        m.remove(bias);
    })) {
        Err(ConvertError::Missing { tensor, .. }) => assert_eq!(tensor, bias),
        other => panic!("{:?}", other.map(|_| ())),
    }
    match conv(&save(&|m| {
        m.insert(bias.into(), (vec![15], vec![0; 60]));
    })) {
        Err(ConvertError::Shape { tensor, .. }) => assert_eq!(tensor, bias),
        other => panic!("{:?}", other.map(|_| ())),
    }
}

/// int8 where it applies: a 32-wide variant of the paper config (every
/// transformer matrix a multiple of 32 wide) with seeded weights (valid
/// flow values: `p` a permutation, `sign_s` +-1, positive scales) written
/// as f32 and as int8; the int8 frames follow the f32 ones.
#[test]
fn int8_matrices_run_the_flow() {
    use duolando::duo_writer::{write_model, Tensor};
    use duolando_core::nn::names::{SchemaError, TensorSpec};
    let text = std::fs::read_to_string(dir("paper").join("hparams.yaml")).unwrap();
    let mut h = Hparams::parse(&text).unwrap();
    for (k, v) in [
        ("dhid", "64"),
        ("dhid_flow", "32"),
        ("num_heads_flow", "2"),
        ("dins", "11,32"),
    ] {
        h.set(k, v).unwrap();
    }
    let cfg = TransflowerConfig::from_hparams(&h).unwrap();
    let mut state = 0x9e3779b97f4a7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    };
    // (tensor, its spec's storage for int8)
    let mut f32s: Vec<Tensor> = Vec::new();
    let mut q8s: Vec<Tensor> = Vec::new();
    FamilyConfig::Transflower(cfg)
        .for_each_tensor::<SchemaError>(&mut |spec: &TensorSpec| {
            let n: usize = spec.dims().iter().map(|&d| d as usize).product();
            let name = spec.name.as_str();
            let c = spec.dims()[0] as usize;
            let values: Vec<f32> = if name.ends_with(".p") {
                // The reversal permutation.
                (0..n)
                    .map(|i| if i / c == c - 1 - i % c { 1.0 } else { 0.0 })
                    .collect()
            } else if name.ends_with(".sign_s") {
                (0..n)
                    .map(|i| if i % 3 == 0 { -1.0 } else { 1.0 })
                    .collect()
            } else if [
                "gamma",
                "inv_std",
                "weight_v",
                "weight_g",
                "running_var",
                "norm1.weight",
                "norm2.weight",
            ]
            .iter()
            .any(|k| name.ends_with(k))
            {
                (0..n).map(|_| 1.0 + 0.3 * next()).collect()
            } else {
                (0..n).map(|_| 0.3 * next()).collect()
            };
            let q8 = duolando::convert::storage_for(StoreAs::Q8Block32, spec);
            let (shape, v) = duolando::convert::to_stored_order(spec, q8, values.clone());
            q8s.push(Tensor {
                name: name.to_string(),
                shape,
                values: v,
                store_as: q8,
            });
            f32s.push(Tensor {
                name: name.to_string(),
                shape: spec.dims().to_vec(),
                values,
                store_as: StoreAs::F32,
            });
            Ok(())
        })
        .unwrap();
    let fc = FamilyConfig::Transflower(cfg);
    let (fa, qa) = (
        ModelFile::from_bytes(write_model(&fc, &f32s).unwrap()).unwrap(),
        ModelFile::from_bytes(write_model(&fc, &q8s).unwrap()).unwrap(),
    );
    let (fd, qd) = (fa.duo().unwrap(), qa.duo().unwrap());
    let blocked = qd
        .tensors()
        .filter(|e| e.dtype == DType::Q8Block32x8)
        .count();
    assert!(blocked >= 20, "only {blocked} int8 matrices");
    // Motion seed 12 rows x 11, audio 21 rows x 32: 8 steps, seeded base.
    let mut r = duolando_tests::Rng(5);
    let (motion, audio) = (r.vec(12 * 11), r.vec(21 * 32));
    let ins = [Input::Rows(&motion), Input::Rows(&audio)];
    let run = |m: &Model<'_>| {
        let n = steps(&cfg, &ins).unwrap();
        let mut scratch = vec![0u8; generate_scratch_bytes(&cfg).unwrap()];
        let mut out = vec![0f32; n * cfg.channels()];
        generate(
            m,
            &ins,
            &mut duolando_core::transflower::exact::Seeded::new(3, &cfg),
            &mut scratch,
            &mut out,
        )
        .unwrap();
        out
    };
    let (a, b) = (
        run(&Model::from_duo(&fd).unwrap()),
        run(&Model::from_duo(&qd).unwrap()),
    );
    assert_eq!(a.len(), 8 * 11);
    let e = rel_err(&b, &a);
    eprintln!("int8 ({blocked} Q8Block32x8 matrices) vs f32: max rel err {e:.2e} over 8 frames");
    assert!(e <= INT8_TOL, "{e:e}");
}
