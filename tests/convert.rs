//! The converter from the original checkpoints (issue #2 item 3): the
//! fixture checkpoints in tests/fixtures/{tiny,tiny2}/ convert to a valid
//! `.duo` identical to the committed `model.duo`; bad inputs (made here by
//! rewriting the safetensors in memory) give errors naming the tensor and
//! expected vs found.
//!
//! Run: `cargo test -p duolando-tests --test convert`.

use std::path::{Path, PathBuf};

use duolando::convert::yaml::Yaml;
use duolando::convert::{convert_bytes, parse_config, ConvertError, Sources};
use duolando::duo_writer::StoreAs;
use duolando::model_file::ModelFile;
use duolando_core::tensor::DType;
use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};

/// A model's fixture files, loaded into memory.
struct Fixture {
    dir: PathBuf,
    yaml: String,
    gpt: Vec<u8>,
    vqvae: Vec<u8>,
    transl: Vec<u8>,
}

fn fixture(model: &str) -> Fixture {
    let dir = duolando_tests::fixture(model);
    let read = |f: &str| {
        std::fs::read(dir.join(f)).unwrap_or_else(|e| panic!("{}: {e}", dir.join(f).display()))
    };
    Fixture {
        yaml: String::from_utf8(read("follower_gpt.yaml")).unwrap(),
        gpt: read("gpt.safetensors"),
        vqvae: read("vqvae.safetensors"),
        transl: read("transl.safetensors"),
        dir,
    }
}

impl Fixture {
    fn convert(&self, store_as: StoreAs) -> Result<Vec<u8>, ConvertError> {
        let (gp, vp, tp) = (
            self.dir.join("gpt.safetensors"),
            self.dir.join("vqvae.safetensors"),
            self.dir.join("transl.safetensors"),
        );
        let sources = Sources {
            gpt: (&gp, &self.gpt),
            vqvae: (&vp, &self.vqvae),
            transl: (&tp, &self.transl),
        };
        convert_bytes(
            (&self.dir.join("follower_gpt.yaml"), &self.yaml),
            &sources,
            store_as,
        )
        .map(|(b, _)| b)
    }
}

/// A safetensors file as editable (name, dtype, shape, bytes) records.
type Records = Vec<(String, Dtype, Vec<usize>, Vec<u8>)>;

fn records(bytes: &[u8]) -> Records {
    let st = SafeTensors::deserialize(bytes).unwrap();
    let mut out: Records = st
        .tensors()
        .into_iter()
        .map(|(n, v)| (n, v.dtype(), v.shape().to_vec(), v.data().to_vec()))
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

fn serialize(recs: &Records) -> Vec<u8> {
    let views: Vec<(String, TensorView<'_>)> = recs
        .iter()
        .map(|(n, d, s, b)| (n.clone(), TensorView::new(*d, s.clone(), b).unwrap()))
        .collect();
    safetensors::serialize(views, &None).unwrap()
}

fn edit(bytes: &mut Vec<u8>, f: impl FnOnce(&mut Records)) {
    let mut r = records(bytes);
    f(&mut r);
    *bytes = serialize(&r);
}

fn find<'r>(r: &'r mut Records, name: &str) -> &'r mut (String, Dtype, Vec<usize>, Vec<u8>) {
    r.iter_mut()
        .find(|t| t.0 == name)
        .unwrap_or_else(|| panic!("fixture has `{name}`"))
}

/// The error of a conversion that must fail (without dumping the bytes of
/// an unexpected success).
fn expect_err(r: Result<Vec<u8>, ConvertError>) -> ConvertError {
    match r {
        Ok(b) => panic!("conversion unexpectedly succeeded ({} bytes)", b.len()),
        Err(e) => e,
    }
}

fn f32s(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

// ------------------------------------------------------------ good inputs

#[test]
fn fixtures_convert_to_the_committed_models() {
    for m in ["tiny", "tiny2"] {
        let fx = fixture(m);
        let bytes = fx
            .convert(StoreAs::F32)
            .unwrap_or_else(|e| panic!("{m}: {e}"));
        let mf = ModelFile::from_bytes(bytes.clone()).unwrap();
        let duo = mf.duo().unwrap();
        assert_eq!(duo.len(), duo.config().tensor_count());
        let committed = std::fs::read(fx.dir.join("model.duo")).unwrap();
        assert!(
            bytes == committed,
            "{m}/model.duo is stale: regenerate it (command in tests/fixtures/README.md)"
        );
    }
}

#[test]
fn tiny_config_maps_the_yaml_sizes() {
    let fx = fixture("tiny");
    let cfg = parse_config(Path::new("follower_gpt.yaml"), &fx.yaml).unwrap();
    // Sizes of tests/fixtures/tiny/follower_gpt.yaml.
    assert_eq!(
        (
            cfg.gpt.n_embd,
            cfg.gpt.n_head,
            cfg.gpt.n_layer_base,
            cfg.gpt.n_layer_head
        ),
        (32, 4, 2, 2)
    );
    assert_eq!(
        (cfg.gpt.block_size, cfg.gpt.look_forward, cfg.gpt.vocab),
        (30, 29, [64; 5])
    );
    assert_eq!(
        (
            cfg.gpt.music.n_layer,
            cfg.gpt.leader.n_layer,
            cfg.gpt.music.downsample_rate
        ),
        (2, 2, 4)
    );
    for vq in cfg.parts.iter().chain([&cfg.transl]) {
        assert_eq!(
            (
                vq.width,
                vq.depth,
                vq.emb_width,
                vq.l_bins,
                vq.down_t,
                vq.stride_t
            ),
            (16, 3, 16, 64, 2, 2)
        );
        assert_eq!(
            (vq.dilation_growth_rate, vq.m_conv_num, vq.m_conv_den),
            (3, 1, 1)
        );
    }
    assert_eq!(cfg.parts.map(|p| p.in_channels), [48, 27, 45, 45]);
    assert_eq!(cfg.parts.map(|p| p.rot_channels), [144, 81, 135, 135]);
    assert_eq!((cfg.transl.in_channels, cfg.transl.rot_channels), (3, 0));
}

#[test]
fn converted_values_equal_the_source_tensors() {
    let fx = fixture("tiny");
    let mf = ModelFile::from_bytes(fx.convert(StoreAs::F32).unwrap()).unwrap();
    let duo = mf.duo().unwrap();
    let gpt = records(&fx.gpt);
    let vq = records(&fx.vqvae);
    for (duo_name, recs, src) in [
        ("gpt.tok_emb_up.weight", &gpt, "module.tok_emb_up.weight"),
        (
            "gpt.gpt_head.head_transl.weight",
            &gpt,
            "module.gpt_head.head_transl.weight",
        ),
        (
            "motion.vqvae_down.bottleneck.level_blocks.0.k",
            &vq,
            "vqvae_down.bottleneck.level_blocks.0.k",
        ),
    ] {
        let src = recs.iter().find(|r| r.0 == src).unwrap();
        let t = duo.tensor(duo_name).unwrap();
        assert_eq!(t.as_f32().unwrap(), &f32s(&src.3)[..], "{duo_name}");
    }
}

#[test]
fn f16_output_stores_rounded_weights() {
    let fx = fixture("tiny");
    let mf = ModelFile::from_bytes(fx.convert(StoreAs::F16).unwrap()).unwrap();
    let duo = mf.duo().unwrap();
    // Weight matrices f16; vectors (biases, LayerNorm) and pos_emb stay f32
    // (the engine adds them as they are; `convert::storage_for`).
    for e in duo.tensors() {
        let want = if e.rank < 2 || e.name.ends_with("pos_emb") {
            DType::F32
        } else {
            DType::F16
        };
        assert_eq!(e.dtype, want, "{}", e.name);
    }
    let src = records(&fx.gpt)
        .into_iter()
        .find(|r| r.0 == "module.tok_emb_up.weight")
        .unwrap();
    let t = duo.tensor("gpt.tok_emb_up.weight").unwrap();
    let got: Vec<f32> = t
        .data
        .chunks_exact(2)
        .map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32())
        .collect();
    let want: Vec<f32> = f32s(&src.3)
        .iter()
        .map(|&v| half::f16::from_f32(v).to_f32())
        .collect();
    assert_eq!(got, want);
}

#[test]
fn accepts_names_without_the_module_prefix() {
    let mut fx = fixture("tiny");
    let reference = fx.convert(StoreAs::F32).unwrap();
    edit(&mut fx.gpt, |r| {
        for t in r.iter_mut() {
            t.0 = t.0.strip_prefix("module.").unwrap().to_string();
        }
    });
    assert_eq!(fx.convert(StoreAs::F32).unwrap(), reference);
}

#[test]
fn accepts_f16_and_bf16_sources_by_upcasting() {
    let mut fx = fixture("tiny");
    let mut expected = Vec::new();
    edit(&mut fx.vqvae, |r| {
        for (i, t) in r.iter_mut().enumerate() {
            let vals = f32s(&t.3);
            if i % 2 == 0 {
                t.1 = Dtype::F16;
                t.3 = vals
                    .iter()
                    .flat_map(|&v| half::f16::from_f32(v).to_le_bytes())
                    .collect();
            } else {
                t.1 = Dtype::BF16;
                t.3 = vals
                    .iter()
                    .flat_map(|&v| half::bf16::from_f32(v).to_le_bytes())
                    .collect();
            }
        }
        let k = find(r, "vqvae_up.bottleneck.level_blocks.0.k");
        expected = match k.1 {
            Dtype::F16 => {
                k.3.chunks_exact(2)
                    .map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32())
                    .collect()
            }
            _ => {
                k.3.chunks_exact(2)
                    .map(|c| half::bf16::from_le_bytes([c[0], c[1]]).to_f32())
                    .collect()
            }
        };
        assert!(r.iter().any(|t| t.1 == Dtype::F16) && r.iter().any(|t| t.1 == Dtype::BF16));
    });
    let mf = ModelFile::from_bytes(fx.convert(StoreAs::F32).unwrap()).unwrap();
    let duo = mf.duo().unwrap();
    let t = duo
        .tensor("motion.vqvae_up.bottleneck.level_blocks.0.k")
        .unwrap();
    assert_eq!(t.as_f32().unwrap(), &expected[..]);
}

// ------------------------------------------------------------- bad inputs

#[test]
fn missing_tensor_is_named_with_its_expected_shape() {
    let mut fx = fixture("tiny");
    edit(&mut fx.gpt, |r| {
        r.retain(|t| t.0 != "module.gpt_head.head_up.weight")
    });
    let err = expect_err(fx.convert(StoreAs::F32));
    let ConvertError::Missing {
        ref tensor,
        ref duo_name,
        ref expected,
        ref path,
    } = err
    else {
        panic!("{err}")
    };
    assert_eq!(
        (tensor.as_str(), duo_name.as_str(), &expected[..]),
        (
            "gpt_head.head_up.weight",
            "gpt.gpt_head.head_up.weight",
            &[64, 32][..]
        )
    );
    assert!(path.ends_with("gpt.safetensors"));
    let msg = err.to_string();
    assert!(
        msg.contains("gpt.safetensors")
            && msg.contains("gpt_head.head_up.weight")
            && msg.contains("[64, 32]"),
        "{msg}"
    );
}

#[test]
fn extra_tensor_is_named() {
    let mut fx = fixture("tiny");
    edit(&mut fx.transl, |r| {
        r.push(("surprise.weight".into(), Dtype::F32, vec![2], vec![0; 8]))
    });
    let err = expect_err(fx.convert(StoreAs::F32));
    assert!(
        matches!(&err, ConvertError::Extra { tensors, path } if tensors == &["surprise.weight"] && path.ends_with("transl.safetensors")),
        "{err}"
    );
    assert!(err.to_string().contains("`surprise.weight`"));
}

#[test]
fn misshaped_tensor_names_expected_and_found() {
    let mut fx = fixture("tiny");
    edit(&mut fx.vqvae, |r| {
        let t = find(r, "vqvae_lhand.encoders.0.level_blocks.0.model.0.0.weight"); // (16, 45, 4)
        t.2 = vec![t.2[1], t.2[0], t.2[2]];
    });
    let err = expect_err(fx.convert(StoreAs::F32));
    let ConvertError::Shape {
        ref tensor,
        ref expected,
        ref found,
        ..
    } = err
    else {
        panic!("{err}")
    };
    assert_eq!(
        tensor,
        "vqvae_lhand.encoders.0.level_blocks.0.model.0.0.weight"
    );
    assert_eq!(
        expected.iter().map(|&d| d as usize).collect::<Vec<_>>(),
        vec![found[1], found[0], found[2]]
    );
    let msg = err.to_string();
    assert!(
        msg.contains(&format!("{found:?}")) && msg.contains(&format!("{expected:?}")),
        "{msg}"
    );
}

#[test]
fn unsupported_source_dtype_is_named() {
    let mut fx = fixture("tiny");
    edit(&mut fx.gpt, |r| {
        find(r, "module.tok_emb_transl.weight").1 = Dtype::I32
    });
    let err = expect_err(fx.convert(StoreAs::F32));
    assert!(
        matches!(&err, ConvertError::Dtype { tensor, found, .. } if tensor == "tok_emb_transl.weight" && found == "I32"),
        "{err}"
    );
}

#[test]
fn mixed_module_prefix_is_rejected() {
    let mut fx = fixture("tiny");
    edit(&mut fx.gpt, |r| {
        let t = find(r, "module.tok_emb_up.weight");
        t.0 = "tok_emb_up.weight".into();
    });
    let err = expect_err(fx.convert(StoreAs::F32));
    assert!(matches!(err, ConvertError::MixedPrefix { .. }), "{err}");
}

#[test]
fn attention_mask_with_other_values_is_rejected() {
    let mut fx = fixture("tiny");
    edit(&mut fx.gpt, |r| {
        let t = find(r, "module.music_trans.blocks.0.attn.mask");
        assert_eq!(t.1, Dtype::F32);
        t.3.iter_mut().for_each(|b| *b = 0); // all masked: not the band
    });
    let err = expect_err(fx.convert(StoreAs::F32));
    assert!(
        matches!(&err, ConvertError::Mask { tensor, row: 0, col: 0, expected, found, .. } if tensor == "music_trans.blocks.0.attn.mask" && *expected == 1.0 && *found == 0.0),
        "{err}"
    );
}

#[test]
fn non_finite_weight_is_rejected() {
    let mut fx = fixture("tiny");
    edit(&mut fx.transl, |r| {
        let t = find(r, "bottleneck.level_blocks.0.k");
        t.3[8..12].copy_from_slice(&f32::INFINITY.to_le_bytes());
    });
    let err = expect_err(fx.convert(StoreAs::F32));
    assert!(
        matches!(&err, ConvertError::NonFinite { tensor, index: 2, .. } if tensor == "bottleneck.level_blocks.0.k"),
        "{err}"
    );
}

#[test]
fn garbage_safetensors_is_rejected() {
    let mut fx = fixture("tiny");
    fx.vqvae.truncate(100);
    let err = expect_err(fx.convert(StoreAs::F32));
    assert!(
        matches!(&err, ConvertError::Safetensors { path, .. } if path.ends_with("vqvae.safetensors")),
        "{err}"
    );
}

// ------------------------------------------------------------- YAML rules

fn yaml_err(yaml: &str) -> ConvertError {
    parse_config(Path::new("cfg.yaml"), yaml).unwrap_err()
}

fn key_of(err: &ConvertError) -> &str {
    match err {
        ConvertError::ConfigKey { key, .. } => key,
        other => panic!("expected ConfigKey, got {other}"),
    }
}

#[test]
fn yaml_levels_other_than_one_are_rejected() {
    let fx = fixture("tiny");
    let yaml = fx.yaml.replacen("levels: 1", "levels: 2", 1);
    assert_ne!(yaml, fx.yaml);
    assert_eq!(key_of(&yaml_err(&yaml)), "structure.up_half.levels");
}

#[test]
fn yaml_missing_key_is_named() {
    let fx = fixture("tiny");
    let yaml = fx
        .yaml
        .replacen("music_motion_rate:", "music_motion_rate_renamed:", 1);
    assert_ne!(yaml, fx.yaml);
    let err = yaml_err(&yaml);
    assert_eq!(key_of(&err), "music_motion_rate");
    assert!(err.to_string().contains("missing"), "{err}");
}

#[test]
fn yaml_config_failing_validation_is_reported() {
    let fx = fixture("tiny");
    // A transl VQ-VAE with 4 input channels: validate wants 3.
    let root = Yaml::parse(&fx.yaml).unwrap();
    let dim = match root
        .get("structure_transl_vqvae")
        .and_then(|s| s.get("input_dim"))
    {
        Some(Yaml::Int(d)) => *d,
        other => panic!("fixture input_dim: {other:?}"),
    };
    assert_eq!(dim, 3);
    let yaml = fx.yaml.replacen("input_dim: 3", "input_dim: 4", 1);
    assert_ne!(yaml, fx.yaml);
    assert!(matches!(yaml_err(&yaml), ConvertError::Config { .. }));
}

#[test]
fn yaml_duplicate_keys_resolve_last_wins_like_pyyaml() {
    let y = Yaml::parse("a: 1\nb: {c: 2, c: 3}\na: 4\n").unwrap();
    assert_eq!(y.get("a"), Some(&Yaml::Int(4)));
    assert_eq!(y.get("b").and_then(|b| b.get("c")), Some(&Yaml::Int(3)));
}

#[test]
fn yaml_syntax_error_names_the_file() {
    let err = yaml_err("structure: [unclosed\n");
    assert!(matches!(err, ConvertError::Yaml { .. }));
    assert!(err.to_string().contains("cfg.yaml"), "{err}");
}

/// `storage_for(int8)` over the published config, by schema role: the
/// decoders' convs int8 (rows of `in * k`) and their ConvTranspose1d
/// weights int8 in GEMM order (rows of `in`, shape `(out * k, in)`), the
/// encoders' convs and codebooks f16, vectors and `pos_emb` f32, Linear and
/// embeddings int8 (the GEMM matrices, Linear, Conv and ConvTranspose, as
/// `Q8Block32x8` row groups, the embeddings as `Q8Block32` rows; requesting
/// x8 is the same); every int8 tensor's row a multiple of 32.
#[test]
fn int8_storage_by_role_on_the_published_config() {
    use duolando_core::duolando::schema::for_each_tensor;
    use duolando_core::nn::names::{Role, SchemaError};
    use duolando_core::tensor::block_row;
    let cfg = duolando_core::duolando::presets::duolando_published();
    let mut by_role: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> =
        Default::default();
    for_each_tensor::<SchemaError>(&cfg, &mut |s| {
        let got = duolando::convert::storage_for(StoreAs::Q8Block32, s);
        let blockable = block_row(s.dims()) % 32 == 0;
        let want = match (s.role, s.dims()) {
            (Role::Vector | Role::PosEmb, _) => StoreAs::F32,
            (Role::Embedding, _) if blockable => StoreAs::Q8Block32,
            (Role::Linear | Role::Conv, _) if blockable => StoreAs::Q8Block32x8,
            (Role::ConvTranspose, &[c_in, _, _]) if c_in % 32 == 0 => StoreAs::Q8Block32x8,
            _ => StoreAs::F16,
        };
        assert_eq!(got, want, "{}", s.name);
        // Written in GEMM order exactly when a ConvTranspose1d weight is blocked.
        let shape = duolando::convert::stored_dims(s, got);
        match (s.role, s.dims()) {
            (Role::ConvTranspose, &[c_in, c_out, k]) => {
                assert_eq!(shape, [c_out * k, c_in], "{}", s.name)
            }
            _ => assert_eq!(shape, s.dims(), "{}", s.name),
        }
        assert_eq!(
            duolando::convert::stored_dims(s, StoreAs::F16),
            s.dims(),
            "{} (f16)",
            s.name
        );
        assert_eq!(
            duolando::convert::storage_for(StoreAs::Q8Block32x8, s),
            want,
            "{} (x8 requested)",
            s.name
        );
        // 4-bit: the same tensors, in the 4-bit layouts.
        let want4 = match want {
            StoreAs::Q8Block32 => StoreAs::Q4Block32,
            StoreAs::Q8Block32x8 => StoreAs::Q4Block32x8,
            other => other,
        };
        assert_eq!(
            duolando::convert::storage_for(StoreAs::Q4Block32, s),
            want4,
            "{} (q4)",
            s.name
        );
        by_role
            .entry(format!("{:?}", s.role))
            .or_default()
            .insert(format!("{got:?}"));
        Ok(())
    })
    .unwrap();
    // Every role occurs; the published decoders' convs are all blockable.
    assert_eq!(by_role.len(), 8, "{by_role:?}");
    assert_eq!(by_role["Conv"].iter().collect::<Vec<_>>(), ["Q8Block32x8"]);
    assert_eq!(
        by_role["Linear"].iter().collect::<Vec<_>>(),
        ["F16", "Q8Block32x8"],
        "music_trans' input rows are not in blocks of 32"
    );
    assert_eq!(
        by_role["Embedding"].iter().collect::<Vec<_>>(),
        ["Q8Block32"]
    );
    assert_eq!(by_role["EncoderConv"].iter().collect::<Vec<_>>(), ["F16"]);
    assert_eq!(
        by_role["ConvTranspose"].iter().collect::<Vec<_>>(),
        ["Q8Block32x8"]
    );
    assert_eq!(by_role["Codebook"].iter().collect::<Vec<_>>(), ["F16"]);
}
