use crate::duolando::config::Part;
use crate::duolando::presets::duolando_published;
use crate::duolando::schema::{for_each_tensor, tensor_count};
use crate::limits::{ConfigError, ConfigField, LatField, LatWhich, VqField, VqWhich};
use crate::nn::names::{SchemaError, TensorSpec};

fn specs(cfg: &crate::duolando::config::ModelConfig) -> std::vec::Vec<TensorSpec> {
    let mut v = std::vec::Vec::new();
    for_each_tensor::<SchemaError>(cfg, &mut |s| {
        v.push(s.clone());
        Ok(())
    })
    .unwrap();
    v
}

fn find<'a>(v: &'a [TensorSpec], n: &str) -> &'a TensorSpec {
    v.iter()
        .find(|s| s.name.as_str() == n)
        .unwrap_or_else(|| panic!("missing {n}"))
}

#[test]
fn published_config_validates() {
    assert_eq!(duolando_published().validate(), Ok(()));
}

#[test]
fn published_schema_names_and_shapes() {
    let cfg = duolando_published();
    let v = specs(&cfg);
    // Names are unique.
    let mut names: std::vec::Vec<&str> = v.iter().map(|s| s.name.as_str()).collect();
    names.sort();
    let n = names.len();
    names.dedup();
    assert_eq!(names.len(), n);
    assert_eq!(tensor_count(&cfg), n);
    let d = |s: &str| find(&v, s).dims().to_vec();
    assert_eq!(d("gpt.music_trans.cond_emb.weight"), [768, 54]);
    assert_eq!(d("gpt.music_trans.blocks.2.attn.query.weight"), [768, 768]);
    assert_eq!(d("gpt.music_trans.downsample.weight"), [768, 3072]);
    assert_eq!(d("gpt.leader_rhand_trans.downsample.weight"), [768, 768]);
    assert_eq!(d("gpt.tok_emb_up.weight"), [512, 768]);
    assert_eq!(d("gpt.gpt_base.pos_emb"), [1, 300, 768]);
    assert_eq!(d("gpt.gpt_base.blocks.5.mlp.0.weight"), [3072, 768]);
    assert_eq!(d("gpt.gpt_head.blocks.5.mlp.2.bias"), [768]);
    assert_eq!(d("gpt.gpt_head.head_transl.weight"), [512, 768]);
    assert_eq!(
        d("motion.vqvae_up.encoders.0.level_blocks.0.model.0.0.weight"),
        [512, 48, 4]
    );
    assert_eq!(
        d("motion.vqvae_up.encoders.0.level_blocks.0.model.1.1.model.2.model.1.weight"),
        [512, 512, 3]
    );
    assert_eq!(
        d("motion.vqvae_up.encoders.0.level_blocks.0.model.1.1.model.2.model.3.weight"),
        [512, 512, 1]
    );
    assert_eq!(
        d("motion.vqvae_up.encoders.0.level_blocks.0.model.2.weight"),
        [512, 512, 3]
    );
    assert_eq!(d("motion.vqvae_up.bottleneck.level_blocks.0.k"), [512, 512]);
    assert_eq!(
        d("motion.vqvae_down.decoders.0.level_blocks.0.model.0.weight"),
        [512, 512, 3]
    );
    assert_eq!(
        d("motion.vqvae_down.decoders.0.level_blocks.0.model.2.1.weight"),
        [512, 512, 4]
    );
    assert_eq!(d("motion.vqvae_down.decoders.0.out.weight"), [27, 512, 3]);
    assert_eq!(
        d("motion.vqvae_down.decoders_rot.0.out.weight"),
        [81, 512, 3]
    );
    assert_eq!(d("motion.vqvae_lhand.decoders_rot.0.out.bias"), [135]);
    assert_eq!(
        d("transl.encoders.0.level_blocks.0.model.0.0.weight"),
        [512, 3, 4]
    );
    assert_eq!(d("transl.decoders.0.out.weight"), [3, 512, 3]);
    assert_eq!(d("transl.bottleneck.level_blocks.0.k"), [512, 512]);
    // Not stored: masks, LAT pos_emb, unused cond embeddings, root head, transl rot decoder.
    for absent in [
        "gpt.music_trans.pos_emb",
        "gpt.music_trans.blocks.0.attn.mask",
        "gpt.gpt_base.cond_emb.weight",
        "gpt.gpt_base.blocks.0.attn.mask",
        "motion.vqvae_down.decoders_root.0.out.weight",
        "transl.decoders_rot.0.out.weight",
    ] {
        assert!(!names.contains(&absent), "{absent}");
    }
    // Parameter count of the inference path (DESIGN.md: ~300M).
    let params: u64 = v
        .iter()
        .map(|s| s.dims().iter().map(|&x| x as u64).product::<u64>())
        .sum();
    assert!((250_000_000..350_000_000).contains(&params), "{params}");
    let gpt: u64 = v
        .iter()
        .filter(|s| s.name.starts_with("gpt."))
        .map(|s| s.dims().iter().map(|&x| x as u64).product::<u64>())
        .sum();
    assert!((200_000_000..212_000_000).contains(&gpt), "{gpt}");
}

#[test]
fn schema_follows_depth_and_down_t() {
    let mut cfg = duolando_published();
    for vq in cfg
        .parts
        .iter_mut()
        .chain(core::iter::once(&mut cfg.transl))
    {
        vq.depth = 2;
        vq.width = 64;
        vq.emb_width = 32;
    }
    cfg.gpt.n_layer_base = 1;
    assert_eq!(cfg.validate(), Ok(()));
    let v = specs(&cfg);
    let d = |s: &str| find(&v, s).dims().to_vec();
    assert_eq!(
        d("motion.vqvae_up.encoders.0.level_blocks.0.model.1.1.model.1.model.1.weight"),
        [64, 64, 3]
    );
    assert_eq!(
        d("motion.vqvae_up.encoders.0.level_blocks.0.model.2.weight"),
        [32, 64, 3]
    );
    assert_eq!(
        d("motion.vqvae_up.decoders.0.level_blocks.0.model.2.1.weight"),
        [64, 32, 4]
    );
    assert_eq!(
        d("motion.vqvae_up.decoders.0.level_blocks.0.model.1.1.weight"),
        [64, 64, 4]
    );
    assert!(!v.iter().any(|s| s.name.contains("model.2.model.1.weight")));
    assert!(!v
        .iter()
        .any(|s| s.name.starts_with("gpt.gpt_base.blocks.1.")));
    // A hop that differs between parts is rejected.
    cfg.parts[0].down_t = 3;
    assert!(matches!(
        cfg.validate(),
        Err(ConfigError::Mismatch {
            field: ConfigField::Vq(_, VqField::Hop),
            ..
        })
    ));
}

#[test]
fn config_rejections() {
    let ok = duolando_published();
    let mut c = ok;
    c.gpt.n_head = 7;
    assert_eq!(
        c.validate(),
        Err(ConfigError::NotDivisible {
            field: ConfigField::NEmbd,
            value: 768,
            divisor: 7
        })
    );
    let mut c = ok;
    c.gpt.n_embd = 0;
    assert_eq!(
        c.validate(),
        Err(ConfigError::Zero {
            field: ConfigField::NEmbd
        })
    );
    let mut c = ok;
    c.gpt.n_embd = 1 << 20;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::TooLarge {
            field: ConfigField::NEmbd,
            ..
        })
    ));
    let mut c = ok;
    c.gpt.vocab[0] = 511;
    assert!(matches!(c.validate(), Err(ConfigError::Mismatch { .. })));
    let mut c = ok;
    c.gpt.vocab[4] = 100;
    assert_eq!(
        c.validate(),
        Err(ConfigError::Mismatch {
            field: ConfigField::Vocab(4),
            value: 100,
            expected: 512
        })
    );
    let mut c = ok;
    c.parts[1].in_channels = 30;
    assert_eq!(
        c.validate(),
        Err(ConfigError::Mismatch {
            field: ConfigField::Vq(VqWhich::Part(Part::Down), VqField::InChannels),
            value: 30,
            expected: 27
        })
    );
    let mut c = ok;
    c.transl.stride_t = 3;
    assert_eq!(
        c.validate(),
        Err(ConfigError::Unsupported {
            field: ConfigField::Vq(VqWhich::Transl, VqField::StrideT),
            value: 3
        })
    );
    let mut c = ok;
    c.gpt.final_ln = true;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::Unsupported {
            field: ConfigField::FinalLn,
            ..
        })
    ));
    let mut c = ok;
    c.gpt.n_streams = 3;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::Unsupported {
            field: ConfigField::NStreams,
            ..
        })
    ));
    let mut c = ok;
    c.gpt.leader.downsample_rate = 2;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::Mismatch {
            field: ConfigField::Lat(LatWhich::Leader, LatField::DownsampleRate),
            ..
        })
    ));
    let mut c = ok;
    c.gpt.music.downsample_rate = 8;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::Mismatch {
            field: ConfigField::Lat(LatWhich::Music, LatField::DownsampleRate),
            ..
        })
    ));
    let mut c = ok;
    c.gpt.look_forward = 0;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::Zero {
            field: ConfigField::LookForward
        })
    ));
    let mut c = ok;
    c.gpt.block_size = 1;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::TooSmall {
            field: ConfigField::BlockSize,
            ..
        })
    ));
    let mut c = ok;
    c.parts[2].dilation_growth_rate = 100;
    c.parts[2].depth = 8;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::TooLarge {
            field: ConfigField::Vq(_, VqField::MaxDilation),
            ..
        })
    ));
    let mut c = ok;
    c.parts[2].m_conv_den = 0;
    assert!(matches!(c.validate(), Err(ConfigError::Zero { .. })));
    let mut c = ok;
    c.music_motion_rate = 0;
    assert!(matches!(
        c.validate(),
        Err(ConfigError::Zero {
            field: ConfigField::MusicMotionRate
        })
    ));
}

/// Blocked rows run over every axis but the first: a Conv1d (out, in, k)
/// blocks its `in * k` values; the byte count is the same block count as
/// the old last-axis rule wherever that rule accepted a shape.
#[test]
fn block_rows_span_all_axes_but_the_first() {
    use crate::tensor::{block_row, DType};
    assert_eq!(block_row(&[512, 512, 3]), 1536);
    assert_eq!(block_row(&[768, 3072]), 3072);
    assert_eq!(block_row(&[96]), 96);
    assert_eq!(block_row(&[]), 0);
    assert_eq!(
        block_row(&[2, u32::MAX, u32::MAX, u32::MAX]),
        0,
        "overflow reads as no row"
    );
    assert_eq!(
        DType::Q8Block32.bytes_for(512 * 512 * 3, block_row(&[512, 512, 3])),
        Some(512 * 48 * 34)
    );
    assert_eq!(
        DType::Q4Block32.bytes_for(64 * 64 * 3, block_row(&[64, 64, 3])),
        Some(64 * 6 * 18)
    );
    // 16 * 3 = 48 values per row do not make whole blocks.
    assert_eq!(
        DType::Q8Block32.bytes_for(16 * 16 * 3, block_row(&[16, 16, 3])),
        None
    );
    // Roles: the published model's first decoder conv is a Conv, the
    // first encoder conv an EncoderConv, a decoder upsampler a ConvTranspose.
    let v = specs(&duolando_published());
    use crate::nn::names::Role;
    assert_eq!(
        find(&v, "motion.vqvae_up.decoders.0.out.weight").role,
        Role::Conv
    );
    assert_eq!(
        find(
            &v,
            "motion.vqvae_up.encoders.0.level_blocks.0.model.0.0.weight"
        )
        .role,
        Role::EncoderConv
    );
    assert_eq!(
        find(
            &v,
            "motion.vqvae_up.decoders.0.level_blocks.0.model.1.1.weight"
        )
        .role,
        Role::ConvTranspose
    );
    assert_eq!(find(&v, "gpt.gpt_base.pos_emb").role, Role::PosEmb);
    assert_eq!(
        find(&v, "motion.vqvae_up.bottleneck.level_blocks.0.k").role,
        Role::Codebook
    );
}
