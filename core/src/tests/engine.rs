//! Binding agrees with the schema; R mode runs end to end on a tiny
//! synthetic model, within its planned scratch, and rejects bad input.
use std::collections::HashMap;

use crate::duolando::config::ModelConfig;
use crate::duolando::exact::{
    generate, output_shape, scratch_bytes, ExactInputs, ExactOutputs, Seed,
};
use crate::duolando::model::Model;
use crate::duolando::presets::{duolando_published, published_vq};
use crate::duolando::schema::for_each_tensor;
use crate::error::{Buffer, Error};
use crate::nn::bind::{BindError, TensorSource};
use crate::nn::names::SchemaError;
use crate::tensor::{DType, TensorRef};

fn tiny() -> ModelConfig {
    let mut c = duolando_published();
    c.gpt.n_embd = 16;
    c.gpt.n_head = 2;
    c.gpt.n_layer_base = 1;
    c.gpt.n_layer_head = 2;
    c.gpt.block_size = 6;
    c.gpt.look_forward = 3;
    c.gpt.vocab = [8; 5];
    c.gpt.music = crate::duolando::config::LatConfig {
        n_in: 5,
        n_layer: 1,
        n_head: 2,
        downsample_rate: 4,
    };
    c.gpt.leader = crate::duolando::config::LatConfig {
        n_in: 16,
        n_layer: 1,
        n_head: 4,
        downsample_rate: 1,
    };
    c.gpt.music.n_in = 5;
    for vq in c.parts.iter_mut().chain(core::iter::once(&mut c.transl)) {
        let base = published_vq(vq.in_channels, vq.rot_channels);
        *vq = crate::duolando::config::VqConfig {
            width: 8,
            emb_width: 4,
            l_bins: 8,
            depth: 2,
            ..base
        };
    }
    c
}

/// Schema tensors filled with a deterministic pattern, counting lookups.
struct Fake {
    data: HashMap<String, (Vec<f32>, [u32; 4], u8)>,
    hits: std::cell::RefCell<std::collections::HashSet<String>>,
}

impl Fake {
    fn new(cfg: &ModelConfig) -> Fake {
        let mut data = HashMap::new();
        let mut k = 0u32;
        for_each_tensor::<SchemaError>(cfg, &mut |s| {
            let n: usize = s.dims().iter().map(|&d| d as usize).product();
            let v = (0..n)
                .map(|i| {
                    k = k.wrapping_mul(1664525).wrapping_add(1013904223 ^ i as u32);
                    ((k >> 8) as f32 / (1u32 << 24) as f32 - 0.5) * 0.8
                })
                .collect();
            data.insert(s.name.as_str().to_string(), (v, s.shape, s.rank));
            Ok(())
        })
        .unwrap();
        Fake {
            data,
            hits: Default::default(),
        }
    }
}

impl<'a> TensorSource<'a> for &'a Fake {
    fn tensor(&self, name: &str) -> Option<TensorRef<'a>> {
        let (v, shape, rank) = self.data.get(name)?;
        self.hits.borrow_mut().insert(name.to_string());
        Some(TensorRef {
            dtype: DType::F32,
            rank: *rank,
            shape: *shape,
            data: bytemuck::cast_slice(v),
        })
    }
}

#[test]
fn binding_reads_exactly_the_schema() {
    let cfg = tiny();
    assert_eq!(cfg.validate(), Ok(()));
    let fake = Fake::new(&cfg);
    let src = &fake;
    let model = Model::bind(&cfg, &src).unwrap();
    assert_eq!(fake.hits.borrow().len(), fake.data.len());
    assert_eq!(model.gpt.base.len(), 1);
    // Missing and mis-shaped tensors are named.
    let mut broken = Fake::new(&cfg);
    broken.data.remove("gpt.gpt_head.head_rhand.weight");
    let b = &broken;
    match Model::bind(&cfg, &b) {
        Err(BindError::Missing { name }) => {
            assert_eq!(name.as_str(), "gpt.gpt_head.head_rhand.weight")
        }
        other => panic!("{other:?}"),
    }
    let mut broken = Fake::new(&cfg);
    broken
        .data
        .get_mut("transl.decoders.0.out.weight")
        .unwrap()
        .1[0] = 4;
    let b = &broken;
    assert!(matches!(
        Model::bind(&cfg, &b),
        Err(BindError::Shape { .. })
    ));
}

fn inputs(t: usize, n_music: usize) -> (Vec<f32>, Vec<f32>) {
    let leader = (0..t * 165)
        .map(|i| ((i * 37 % 101) as f32 / 101.0 - 0.5) + (i / 165) as f32 * 0.01)
        .collect();
    let music = (0..t * n_music)
        .map(|i| ((i * 13 % 29) as f32 / 29.0) - 0.5)
        .collect();
    (leader, music)
}

#[test]
fn exact_runs_within_plan_and_is_deterministic() {
    let cfg = tiny();
    let fake = Fake::new(&cfg);
    let src = &fake;
    let model = Model::bind(&cfg, &src).unwrap();
    let t = 83; // truncated to 80; K = (80-4)/4 - 3 = 16
    let sh = output_shape(&cfg, t).unwrap();
    assert_eq!(
        (sh.frames_in, sh.steps, sh.token_rows, sh.frames_out),
        (80, 16, 17, 68)
    );
    let (leader, music) = inputs(t, 5);
    let need = scratch_bytes(&cfg, t).unwrap();
    let run = |scratch: &mut [u8], seed: Seed<'_>| {
        let mut tokens = vec![0u32; sh.token_rows * 5];
        let mut pos = vec![0f32; sh.frames_out * 165];
        let mut rot = vec![0f32; sh.frames_out * 495];
        let mut calls = 0;
        let mut out = ExactOutputs {
            tokens: &mut tokens,
            follower_pos3d: &mut pos,
            follower_rotmat: &mut rot,
            leader_tokens: None,
        };
        let r = generate(
            &model,
            &ExactInputs {
                leader_pos3d: &leader,
                music: &music,
                seed,
            },
            scratch,
            &mut out,
            &mut |_, _| calls += 1,
        );
        (r, tokens, pos, rot, calls)
    };
    let mut scratch = vec![0u8; need];
    let (r, tokens, pos, rot, calls) = run(&mut scratch, Seed::Tokens([1, 2, 3, 4, 5]));
    let sum = r.unwrap();
    assert!(sum.scratch_used <= need);
    assert_eq!(calls, 16);
    assert_eq!(&tokens[..5], &[1, 2, 3, 4, 5]);
    assert!(tokens.iter().all(|&v| v < 8));
    assert!(pos.iter().chain(&rot).all(|v| v.is_finite()));
    // Same again: bit-identical.
    let (_, tokens2, pos2, _, _) = run(&mut scratch, Seed::Tokens([1, 2, 3, 4, 5]));
    assert_eq!((tokens.clone(), pos.clone()), (tokens2, pos2));
    // Seeding from frames works (the leader itself as the follower).
    let (r, ..) = run(&mut scratch, Seed::FollowerFrames(&leader[..8 * 165]));
    assert!(r.is_ok());
    // Too little scratch is an error, not a panic.
    let mut small = vec![0u8; need / 2];
    assert!(matches!(
        run(&mut small, Seed::Tokens([0; 5])).0,
        Err(Error::Arena(_))
    ));
    // Bad inputs.
    assert!(matches!(
        run(&mut scratch, Seed::Tokens([0, 0, 0, 0, 8])).0,
        Err(Error::Token {
            stream: 4,
            token: 8,
            vocab: 8
        })
    ));
    assert!(matches!(
        run(&mut scratch, Seed::FollowerFrames(&leader[..3 * 165])).0,
        Err(Error::TooShort {
            buffer: Buffer::SeedFrames,
            ..
        })
    ));
    let mut tokens = vec![0u32; 3];
    let mut pos = vec![0f32; 1];
    let mut rot = vec![0f32; 1];
    let mut out = ExactOutputs {
        tokens: &mut tokens,
        follower_pos3d: &mut pos,
        follower_rotmat: &mut rot,
        leader_tokens: None,
    };
    let e = generate(
        &model,
        &ExactInputs {
            leader_pos3d: &leader,
            music: &music,
            seed: Seed::Tokens([0; 5]),
        },
        &mut scratch,
        &mut out,
        &mut |_, _| {},
    );
    assert!(matches!(
        e,
        Err(Error::Length {
            buffer: Buffer::Tokens,
            ..
        })
    ));
    let mut nan = leader.clone();
    nan[500] = f32::NAN;
    let e = generate(
        &model,
        &ExactInputs {
            leader_pos3d: &nan,
            music: &music,
            seed: Seed::Tokens([0; 5]),
        },
        &mut scratch,
        &mut out,
        &mut |_, _| {},
    );
    assert!(matches!(
        e,
        Err(Error::NonFinite { .. }) | Err(Error::Length { .. })
    ));
    let e = generate(
        &model,
        &ExactInputs {
            leader_pos3d: &leader[..2 * 165],
            music: &music,
            seed: Seed::Tokens([0; 5]),
        },
        &mut scratch,
        &mut out,
        &mut |_, _| {},
    );
    assert!(matches!(e, Err(Error::TooShort { .. })));
    let e = generate(
        &model,
        &ExactInputs {
            leader_pos3d: &leader,
            music: &music[..10 * 5],
            seed: Seed::Tokens([0; 5]),
        },
        &mut scratch,
        &mut out,
        &mut |_, _| {},
    );
    assert!(matches!(
        e,
        Err(Error::TooShort {
            buffer: Buffer::Music,
            ..
        })
    ));
}

#[test]
fn short_sequences_decode_the_seed_only() {
    let cfg = tiny();
    let fake = Fake::new(&cfg);
    let src = &fake;
    let model = Model::bind(&cfg, &src).unwrap();
    for t in [4usize, 7, 16] {
        let sh = output_shape(&cfg, t).unwrap();
        assert_eq!(sh.steps, 0);
        let (leader, music) = inputs(t, 5);
        let mut scratch = vec![0u8; scratch_bytes(&cfg, t).unwrap()];
        let mut tokens = vec![0u32; 5];
        let mut pos = vec![0f32; 4 * 165];
        let mut rot = vec![0f32; 4 * 495];
        let mut out = ExactOutputs {
            tokens: &mut tokens,
            follower_pos3d: &mut pos,
            follower_rotmat: &mut rot,
            leader_tokens: None,
        };
        generate(
            &model,
            &ExactInputs {
                leader_pos3d: &leader,
                music: &music,
                seed: Seed::Tokens([7; 5]),
            },
            &mut scratch,
            &mut out,
            &mut |_, _| {},
        )
        .unwrap();
    }
    assert!(output_shape(&cfg, 3).is_none());
}

/// A LAT's last block runs only for the rows its downsample reads
/// (`block_forward_prefix`); its output must be what every block over every
/// row then the downsample give, bit for bit: the music LAT with two
/// blocks (the others full, the last trimmed) and a leader LAT with one.
#[test]
fn lat_last_block_for_kept_rows_only_is_bit_identical() {
    use crate::arena::Arena;
    use crate::duolando::config::Part;
    use crate::duolando::lat::{leader_lat, music_lat, scratch_bytes};
    use crate::duolando::model::LatW;
    use crate::kernels::{linear, BandMask};
    use crate::nn::block::{block_forward, BlockScratch};

    let mut cfg = tiny();
    cfg.gpt.music.n_layer = 2;
    let fake = Fake::new(&cfg);
    let src = &fake;
    let model = Model::bind(&cfg, &src).unwrap();
    let (e, lf) = (cfg.gpt.n_embd as usize, cfg.gpt.look_forward as usize);
    // Every block over every row, then the downsample of the kept rows.
    let full = |w: &LatW<'_>, x0: Vec<f32>, n: usize| -> Vec<f32> {
        let ds = w.cfg.downsample_rate as usize;
        let rows = n / ds - lf;
        let mut x = x0;
        let mut bytes = vec![0u8; 1 << 20];
        let mut a = Arena::new(&mut bytes);
        let mut bs = BlockScratch::carve(&mut a, n, e).unwrap();
        let mask = BandMask {
            radius: lf * ds,
            q_pos0: 0,
            k_pos0: 0,
        };
        for b in &w.blocks {
            block_forward(b, &mut x, e, w.cfg.n_head as usize, &mask, &mut bs);
        }
        let mut out = vec![0f32; rows * e];
        linear(
            &x[..rows * ds * e],
            &w.downsample.w,
            w.downsample.b,
            &mut out,
        );
        out
    };
    for c in [1usize, 4, 9] {
        let mut scratch = vec![0u8; scratch_bytes(&cfg, c).unwrap()];
        // Music: (c + lf) * 4 frames of 5 features.
        let n = (c + lf) * 4;
        let music: Vec<f32> = (0..n * 5)
            .map(|i| ((i * 13 % 29) as f32 / 29.0) - 0.5)
            .collect();
        let mut got = vec![0f32; c * e];
        assert_eq!(
            music_lat(&model, &music, &mut scratch, &mut got).unwrap(),
            c
        );
        let w = &model.gpt.music;
        let mut x0 = vec![0f32; n * e];
        linear(&music, &w.cond_emb.w, w.cond_emb.b, &mut x0);
        let want = full(w, x0, n);
        assert!(
            got.iter()
                .zip(&want)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "music LAT, c = {c}"
        );
        // Leader (up): c + lf tokens.
        let n = c + lf;
        let tokens: Vec<u32> = (0..n as u32).map(|i| (i * 5 + 3) % 8).collect();
        let mut got = vec![0f32; c * e];
        assert_eq!(
            leader_lat(&model, Part::Up, &tokens, &mut scratch, &mut got).unwrap(),
            c
        );
        let w = &model.gpt.leaders[Part::Up as usize];
        let table = &model.gpt.tok_emb[Part::Up as usize];
        let mut emb = vec![0f32; n * e];
        for (i, &t) in tokens.iter().enumerate() {
            table.row_into(t as usize, &mut emb[i * e..(i + 1) * e]);
        }
        let mut x0 = vec![0f32; n * e];
        linear(&emb, &w.cond_emb.w, w.cond_emb.b, &mut x0);
        let want = full(w, x0, n);
        assert!(
            got.iter()
                .zip(&want)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "leader LAT, c = {c}"
        );
    }
}
