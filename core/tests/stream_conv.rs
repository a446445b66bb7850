//! Streaming conv stacks (`stream_conv`) against the full-prefix stacks
//! (`vq_encoder::encode_features`, `vq_decoder::decode`) on the fixture
//! models, after every push, at several lags; sizes (Planner = Arena, the
//! published model's rings vs docs/STREAMING.md §3.2/§3.7); errors.

use duolando_core::arena::{Arena, Carve, Planner};
use duolando_core::duolando::config::{ModelConfig, Part};
use duolando_core::duolando::model::Model;
use duolando_core::duolando::presets::duolando_published;
use duolando_core::duolando::vq_decoder::{decode, Output};
use duolando_core::duolando::vq_encoder::encode_features;
use duolando_core::error::Error;
use duolando_core::format::DuoFile;
use duolando_core::kernels::{ConvGeom, ConvTWeight, DenseRows, Matrix};
use duolando_core::nn::conv_stack::ConvScratch;
use duolando_core::nn::quantizer::dequantise;
use duolando_core::nn::stream_conv::{
    future_max, StackKind, StackPlan, StackW, StreamScratch, StreamStack,
};
use duolando_core::nn::vq_config::VqConfig;
use duolando_core::nn::weights::{ConvTW, ConvW, DecoderW, EncoderW, ResBlockW, ResnetW, VqW};

/// A fixture model, bound from a 64-byte aligned copy of its `.duo` file
/// (the decoder requires the alignment; leaked for the test's lifetime).
fn model(name: &str) -> &'static Model<'static> {
    let path = format!(
        "{}/../tests/fixtures/{name}/model.duo",
        env!("CARGO_MANIFEST_DIR")
    );
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let buf: &'static mut [u8] = Vec::leak(vec![0u8; bytes.len() + 64]);
    let off = (64 - buf.as_ptr() as usize % 64) % 64;
    let buf = &mut buf[off..off + bytes.len()];
    buf.copy_from_slice(&bytes);
    let file = DuoFile::parse(buf).unwrap_or_else(|e| panic!("{path}: {e:?}"));
    let file: &'static DuoFile<'static> = Box::leak(Box::new(file));
    Box::leak(Box::new(Model::from_duo(file).unwrap()))
}

/// splitmix64 (docs/STREAMING.md §3.6).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [-1, 1).
    fn sym(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    }
}

/// The VQ-VAEs of a model with names: (name, vq, stream id).
fn vqs<'m>(m: &'m Model<'static>) -> Vec<(&'static str, &'m VqW<'static>, u8)> {
    let mut v: Vec<_> = Part::ALL
        .iter()
        .map(|&p| (p.name(), &m.parts[p as usize], p as u8))
        .collect();
    v.push(("transl", &m.transl, 4));
    v
}

/// Lags tested: 0, an intermediate one, future_max, and one above.
fn lags(fmax: usize) -> [usize; 4] {
    [0, fmax / 2, fmax, fmax + 2]
}

/// Pushes per run: three times the receptive field in tokens plus the lag,
/// so every ring wraps many times.
fn pushes(fmax: usize, lag: usize) -> usize {
    3 * (2 * fmax + 2) + lag + 8
}

/// Largest |a - b|, split into settled / unsettled requested columns.
#[derive(Default, Debug, Clone, Copy)]
struct Err2 {
    settled: f32,
    tail: f32,
    n_settled: usize,
    n_tail: usize,
    /// Unsettled columns among the requests at the carved lag itself.
    n_tail_at_lag: usize,
}

impl Err2 {
    fn add(&mut self, settled: bool, a: &[f32], b: &[f32]) {
        assert_eq!(a.len(), b.len());
        let e = a
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0f32, f32::max);
        assert!(a.iter().all(|v| v.is_finite()));
        if settled {
            self.settled = self.settled.max(e);
            self.n_settled += 1;
        } else {
            self.tail = self.tail.max(e);
            self.n_tail += 1;
        }
    }
    fn merge(&mut self, o: Err2) {
        self.settled = self.settled.max(o.settled);
        self.tail = self.tail.max(o.tail);
        self.n_settled += o.n_settled;
        self.n_tail += o.n_tail;
        self.n_tail_at_lag += o.n_tail_at_lag;
    }
}

const TOL: f32 = 1e-5;

/// One encoder at one lag: after every push, every request at lags
/// `0..=lag` (the carved one and all smaller) equals the full prefix encode.
fn run_encoder(mcfg: &ModelConfig, vq: &VqW<'static>, lag: usize, seed: u64) -> Err2 {
    let cfg = &vq.cfg;
    let (hop, c_in, emb) = (
        cfg.hop().unwrap() as usize,
        cfg.in_channels as usize,
        cfg.emb_width as usize,
    );
    let fmax = future_max(cfg, StackKind::Encoder);
    let n_push = pushes(fmax, lag);
    let mut mem = vec![0u8; 1 << 22];
    let mut a = Arena::new(&mut mem);
    let mut s = StreamScratch::for_model(&mut a, mcfg).unwrap();
    let mut st = StreamStack::carve(&mut a, cfg, StackKind::Encoder, lag).unwrap();
    let mut full_mem =
        vec![0u8; duolando_core::duolando::vq_encoder::scratch_bytes(mcfg, n_push * hop).unwrap()];
    let mut fa = Arena::new(&mut full_mem);
    let mut fs = ConvScratch::carve(&mut fa, &mcfg.vqs(), n_push * hop).unwrap();
    let mut rng = Rng(seed);
    let x: Vec<f32> = (0..n_push * hop * c_in).map(|_| rng.sym()).collect();
    let w = StackW::Encoder(&vq.encoder);
    let mut err = Err2::default();
    let mut got = vec![0f32; emb];
    for p in 1..=n_push {
        st.push(w, &x[(p - 1) * hop * c_in..p * hop * c_in], &mut s)
            .unwrap();
        assert_eq!(st.pushed(), p);
        assert_eq!(st.len(), p);
        let mut feat = vec![0f32; p * emb];
        encode_features(vq, &x[..p * hop * c_in], &mut fs, &mut feat).unwrap();
        for l in 0..=lag.min(p - 1) {
            let q = p - 1 - l;
            st.output(w, q, 1, &mut s, &mut got)
                .unwrap_or_else(|e| panic!("push {p} lag {l}/{lag}: {e:?}"));
            err.add(q < st.settled(), &got, &feat[q * emb..(q + 1) * emb]);
            err.n_tail_at_lag += usize::from(l == lag && q >= st.settled());
        }
    }
    err
}

/// One decoder at one lag, as [`run_encoder`].
fn run_decoder(
    mcfg: &ModelConfig,
    vq: &VqW<'static>,
    which: Output,
    stream: u8,
    lag: usize,
    seed: u64,
) -> Err2 {
    let cfg = &vq.cfg;
    let (hop, emb) = (cfg.hop().unwrap() as usize, cfg.emb_width as usize);
    let dec = match which {
        Output::Position => &vq.pos,
        Output::Rotation => vq.rot.as_ref().unwrap(),
    };
    let c_out = dec.out.c_out;
    let fmax = future_max(cfg, StackKind::Decoder);
    let n_push = pushes(fmax, lag);
    let mut mem = vec![0u8; 1 << 22];
    let mut a = Arena::new(&mut mem);
    let mut s = StreamScratch::for_model(&mut a, mcfg).unwrap();
    let mut st = StreamStack::carve(&mut a, cfg, StackKind::Decoder, lag).unwrap();
    let mut full_mem =
        vec![0u8; duolando_core::duolando::vq_decoder::scratch_bytes(mcfg, n_push).unwrap()];
    let mut fa = Arena::new(&mut full_mem);
    let mut fs = ConvScratch::carve(&mut fa, &mcfg.vqs(), n_push * hop).unwrap();
    let mut rng = Rng(seed);
    let codes: Vec<u32> = (0..n_push)
        .map(|_| (rng.next() % cfg.l_bins as u64) as u32)
        .collect();
    let w = StackW::Decoder(dec);
    let mut err = Err2::default();
    let (mut z, mut got) = (vec![0f32; emb], vec![0f32; hop * c_out]);
    for p in 1..=n_push {
        dequantise(&vq.codebook, &codes[p - 1..p], stream, &mut z).unwrap();
        st.push(w, &z, &mut s).unwrap();
        assert_eq!(st.len(), p * hop);
        let mut frames = vec![0f32; p * hop * c_out];
        decode(vq, which, &codes[..p], stream, &mut fs, &mut frames).unwrap();
        for l in 0..=lag.min(p - 1) {
            let q = p - 1 - l;
            st.output(w, hop * q, hop, &mut s, &mut got)
                .unwrap_or_else(|e| panic!("push {p} lag {l}/{lag}: {e:?}"));
            let settled = hop * (q + 1) <= st.settled();
            err.add(
                settled,
                &got,
                &frames[hop * q * c_out..hop * (q + 1) * c_out],
            );
            err.n_tail_at_lag += usize::from(l == lag && !settled);
        }
    }
    err
}

#[test]
fn future_max_matches_the_reference() {
    let p = duolando_published();
    for kind in [StackKind::Encoder, StackKind::Decoder] {
        assert_eq!(future_max(&p.parts[0], kind), 22);
        assert_eq!(future_max(&p.transl, kind), 22);
        for vq in vqs(model("tiny")) {
            assert_eq!(future_max(&vq.1.cfg, kind), 22, "tiny {}", vq.0);
        }
        for vq in vqs(model("tiny2")) {
            assert_eq!(future_max(&vq.1.cfg, kind), 8, "tiny2 {}", vq.0);
        }
    }
}

#[test]
fn streaming_encoders_equal_the_prefix_encoder() {
    for name in ["tiny", "tiny2"] {
        let m = model(name);
        let mut all = Err2::default();
        for (i, (part, vq, _)) in vqs(m).into_iter().enumerate() {
            let fmax = future_max(&vq.cfg, StackKind::Encoder);
            for lag in lags(fmax) {
                let e = run_encoder(&m.cfg, vq, lag, 1000 + i as u64 * 31 + lag as u64);
                eprintln!("{name} enc {part:6} lag {lag:2}: settled max err {:.3e} ({} cols), tail {:.3e} ({} cols)", e.settled, e.n_settled, e.tail, e.n_tail);
                assert!(
                    e.settled <= TOL && e.tail <= TOL,
                    "{name} {part} lag {lag}: {e:?}"
                );
                assert_eq!(
                    e.n_tail_at_lag == 0,
                    lag >= fmax,
                    "{name} {part} lag {lag}: settled at the lag iff lag >= future_max"
                );
                all.merge(e);
            }
        }
        eprintln!(
            "{name} encoders: settled {:.3e} over {} cols, tail {:.3e} over {} cols",
            all.settled, all.n_settled, all.tail, all.n_tail
        );
        assert!(all.n_tail > 0 && all.n_settled > 0);
    }
}

#[test]
fn streaming_decoders_equal_the_prefix_decoder() {
    for name in ["tiny", "tiny2"] {
        let m = model(name);
        let mut all = Err2::default();
        for (i, (part, vq, stream)) in vqs(m).into_iter().enumerate() {
            let fmax = future_max(&vq.cfg, StackKind::Decoder);
            let outs: &[Output] = if vq.rot.is_some() {
                &[Output::Position, Output::Rotation]
            } else {
                &[Output::Position]
            };
            for &which in outs {
                for lag in lags(fmax) {
                    let e = run_decoder(
                        &m.cfg,
                        vq,
                        which,
                        stream,
                        lag,
                        7000 + i as u64 * 17 + lag as u64,
                    );
                    eprintln!("{name} dec {part:6} {which:?} lag {lag:2}: settled max err {:.3e} ({} blocks), tail {:.3e} ({} blocks)", e.settled, e.n_settled, e.tail, e.n_tail);
                    assert!(
                        e.settled <= TOL && e.tail <= TOL,
                        "{name} {part} {which:?} lag {lag}: {e:?}"
                    );
                    assert_eq!(
                        e.n_tail_at_lag == 0,
                        lag >= fmax,
                        "{name} {part} lag {lag}: settled at the lag iff lag >= future_max"
                    );
                    all.merge(e);
                }
            }
        }
        eprintln!(
            "{name} decoders: settled {:.3e} over {} blocks, tail {:.3e} over {} blocks",
            all.settled, all.n_settled, all.tail, all.n_tail
        );
        assert!(all.n_tail > 0 && all.n_settled > 0);
    }
}

/// At lag >= future_max every request is settled: served from the output
/// ring, no tail computed (checked through the plan: zero tails).
#[test]
fn no_tail_at_future_max() {
    for cfg in [duolando_published(), model("tiny").cfg, model("tiny2").cfg] {
        for vq in cfg.parts.iter().chain([&cfg.transl]) {
            for kind in [StackKind::Encoder, StackKind::Decoder] {
                let f = future_max(vq, kind);
                let plan = StackPlan::new(vq, kind, f).unwrap();
                assert!(
                    plan.tails().iter().all(|&t| t == 0),
                    "{kind:?} {:?}",
                    plan.tails()
                );
                assert!(plan.out_ring > 0);
                let below = StackPlan::new(vq, kind, f - 1).unwrap();
                assert!(below.tails().iter().any(|&t| t > 0));
            }
        }
    }
}

/// Carves everything a session would (scratch + one stack per decoder and
/// encoder) on `a`.
fn carve_all<'s, A: Carve<'s>>(a: &mut A, cfg: &ModelConfig, lag: usize) {
    StreamScratch::for_model(a, cfg).unwrap();
    for vq in cfg.parts.iter().chain([&cfg.transl]) {
        for kind in [StackKind::Encoder, StackKind::Decoder] {
            StreamStack::carve(a, vq, kind, lag).unwrap();
        }
    }
}

#[test]
fn planner_and_arena_agree() {
    for cfg in [model("tiny").cfg, model("tiny2").cfg, duolando_published()] {
        for lag in [0, 3, 8, 22, 30] {
            let mut p = Planner::new();
            carve_all(&mut p, &cfg, lag);
            let mut mem = vec![0u8; p.total_for_any_base().unwrap()];
            let mut a = Arena::new(&mut mem);
            let pad = a.used();
            carve_all(&mut a, &cfg, lag);
            assert_eq!(a.used() - pad, p.bytes(), "lag {lag}");
        }
    }
}

/// Ring and tail sizes of the published model vs docs/STREAMING.md §3.2 /
/// §3.7 (rings measured by the Python reference as the oldest age read;
/// its tails are the whole unsettled region, ours only the cone of the
/// requested columns, so ours are at most the doc's).
#[test]
fn published_sizes_match_the_doc() {
    let p = duolando_published();
    let doc_enc_ring = [7, 4, 8, 20, 5, 3, 7, 19, 3];
    let doc_enc_tail = [1, 2, 5, 14, 8, 9, 12, 21, 22];
    let doc_dec_ring = [3, 19, 7, 3, 2, 20, 8, 4, 3, 6];
    let doc_dec_tail = [1, 10, 13, 14, 29, 38, 41, 42, 85, 86];
    for (kind, ring, tail) in [
        (StackKind::Encoder, &doc_enc_ring[..], &doc_enc_tail[..]),
        (StackKind::Decoder, &doc_dec_ring[..], &doc_dec_tail[..]),
    ] {
        for vq in p.parts.iter().chain([&p.transl]) {
            let fmax = future_max(vq, kind);
            for lag in [0, 2, 11, fmax] {
                let plan = StackPlan::new(vq, kind, lag).unwrap();
                eprintln!(
                    "published {kind:?} lag {lag:2}: rings {:?} out ring {} tails {:?}",
                    plan.rings(),
                    plan.out_ring,
                    plan.tails()
                );
                assert_eq!(plan.rings(), ring, "{kind:?} lag {lag}");
                for (u, (&t, &d)) in plan.tails().iter().zip(tail).enumerate() {
                    assert!(t <= d, "{kind:?} lag {lag} unit {u}: tail {t} > doc {d}");
                }
            }
        }
    }
}

#[test]
fn errors_not_panics() {
    let m = model("tiny2");
    let vq = &m.parts[0];
    let cfg = &vq.cfg;
    let (hop, c_in, emb) = (
        cfg.hop().unwrap() as usize,
        cfg.in_channels as usize,
        cfg.emb_width as usize,
    );
    let mut mem = vec![0u8; 1 << 22];
    let mut a = Arena::new(&mut mem);
    let mut s = StreamScratch::for_model(&mut a, &m.cfg).unwrap();
    let lag = 3;
    let mut enc = StreamStack::carve(&mut a, cfg, StackKind::Encoder, lag).unwrap();
    let mut dec = StreamStack::carve(&mut a, cfg, StackKind::Decoder, lag).unwrap();
    let we = StackW::Encoder(&vq.encoder);
    let wd = StackW::Decoder(&vq.pos);
    let x = vec![0.25f32; hop * c_in + 1];
    let len = |r: Result<(), Error>| matches!(r, Err(Error::Length { .. }));
    // Wrong input lengths.
    assert!(len(enc.push(we, &x, &mut s)));
    assert!(len(enc.push(we, &x[..hop * c_in - 1], &mut s)));
    assert!(len(enc.push(we, &[], &mut s)));
    assert!(len(dec.push(wd, &x[..emb + 1], &mut s)));
    assert_eq!((enc.pushed(), dec.pushed()), (0, 0));
    // Wrong weights (kind, or another VQ-VAE's geometry).
    assert!(enc.push(wd, &x[..hop * c_in], &mut s).is_err());
    assert!(dec.push(we, &x[..emb], &mut s).is_err());
    assert!(
        enc.push(
            StackW::Encoder(&m.parts[2].encoder),
            &x[..hop * c_in],
            &mut s
        )
        .is_err()
            || m.parts[2].cfg == *cfg
    );
    assert_eq!(enc.pushed(), 0);
    // Nothing pushed: no output.
    let mut out = vec![0f32; emb];
    assert!(enc.output(we, 0, 1, &mut s, &mut out).is_err());
    for _ in 0..40 {
        enc.push(we, &x[..hop * c_in], &mut s).unwrap();
        dec.push(wd, &x[..emb], &mut s).unwrap();
    }
    // Past the end, wrong out length, far too old (evicted): errors.
    assert!(enc.output(we, 40, 1, &mut s, &mut out).is_err());
    assert!(enc.output(we, 39, 2, &mut s, &mut out).is_err());
    assert!(enc
        .output(we, usize::MAX, 2, &mut s, &mut vec![0f32; 2 * emb])
        .is_err());
    assert!(enc.output(we, 39, 1, &mut s, &mut out[..emb - 1]).is_err());
    assert!(enc.output(we, 0, 1, &mut s, &mut out).is_err());
    assert!(enc.output(we, 39, 1, &mut s, &mut out).is_ok());
    // Rotation weights after pushing with position weights: refused.
    let rot = vq.rot.as_ref().unwrap();
    let mut fr = vec![0f32; hop * rot.out.c_out];
    assert!(dec
        .output(StackW::Decoder(rot), 0, hop, &mut s, &mut fr)
        .is_err());
    assert!(dec.push(StackW::Decoder(rot), &x[..emb], &mut s).is_err());
    // Too small a scratch: an error before anything changes.
    let mut small = vec![0u8; 4096];
    let mut sa = Arena::new(&mut small);
    let mut tiny_s = StreamScratch::for_model(
        &mut sa,
        &duolando_core::duolando::presets::duolando_published(),
    )
    .err();
    assert!(
        tiny_s.take().is_some(),
        "a 4 KiB arena cannot hold the published scratch"
    );
    let mut p = Planner::new();
    let _ = StreamScratch::for_model(&mut p, &m.cfg).unwrap();
    // A stack carved by a Planner holds no memory: errors, no panic.
    let mut pl = Planner::new();
    let mut ghost = StreamStack::carve(&mut pl, cfg, StackKind::Encoder, lag).unwrap();
    assert!(ghost.push(we, &x[..hop * c_in], &mut s).is_err());
    let mut ghost_s = StreamScratch::for_model(&mut pl, &m.cfg).unwrap();
    assert!(enc.push(we, &x[..hop * c_in], &mut ghost_s).is_err());
    assert!(
        enc.output(we, 39, 1, &mut ghost_s, &mut out).is_err(),
        "a tail needs scratch"
    );
    // reset: back to zero, works again.
    enc.reset();
    assert_eq!((enc.pushed(), enc.len()), (0, 0));
    enc.push(we, &x[..hop * c_in], &mut s).unwrap();
    assert!(enc.output(we, 0, 1, &mut s, &mut out).is_ok());
}

// ---------------------------------------------------------------------------
// Other geometries (stride 4, three stages, deep resnets) on random weights
// ---------------------------------------------------------------------------

/// Leaked random floats scaled by `scale`.
fn rand_leak(rng: &mut Rng, n: usize, scale: f32) -> &'static [f32] {
    Vec::leak((0..n).map(|_| rng.sym() * scale).collect::<Vec<f32>>())
}

fn synth_conv(rng: &mut Rng, c_out: usize, c_in: usize, geom: ConvGeom) -> ConvW<'static> {
    let k = geom.kernel;
    let data = rand_leak(rng, c_out * c_in * k, 1.5 / ((c_in * k) as f32).sqrt());
    ConvW {
        w: Matrix::F32(DenseRows::new(data, c_out, c_in * k).unwrap()),
        b: rand_leak(rng, c_out, 0.3),
        c_in,
        c_out,
        geom,
    }
}

fn synth_resnet(rng: &mut Rng, cfg: &VqConfig, reversed: bool) -> ResnetW<'static> {
    let (w, inner) = (cfg.width as usize, cfg.res_inner().unwrap() as usize);
    let mut v = ResnetW::new();
    for d in 0..cfg.depth {
        let dil = cfg
            .dilation_growth_rate
            .pow(if reversed { cfg.depth - 1 - d } else { d }) as usize;
        let g3 = ConvGeom {
            kernel: 3,
            stride: 1,
            pad: dil,
            dilation: dil,
        };
        let g1 = ConvGeom {
            kernel: 1,
            stride: 1,
            pad: 0,
            dilation: 1,
        };
        let blk = ResBlockW {
            conv_dil: synth_conv(rng, inner, w, g3),
            conv_1x1: synth_conv(rng, w, inner, g1),
        };
        v.push(blk).ok().unwrap();
    }
    v
}

/// `gemm`: the ConvTranspose1d weights in GEMM order (as blocked files
/// store them), else in PyTorch order.
fn synth_decoder(rng: &mut Rng, cfg: &VqConfig, c_out: usize, gemm: bool) -> DecoderW<'static> {
    let (w, s, emb) = (
        cfg.width as usize,
        cfg.stride_t as usize,
        cfg.emb_width as usize,
    );
    let g3 = ConvGeom {
        kernel: 3,
        stride: 1,
        pad: 1,
        dilation: 1,
    };
    let input = synth_conv(rng, w, emb, g3);
    let mut stages = heapless::Vec::new();
    for i in 0..cfg.down_t {
        let res = synth_resnet(rng, cfg, true);
        let out = if i + 1 == cfg.down_t { emb } else { w };
        let data = rand_leak(rng, w * out * 2 * s, 1.5 / ((w * 2) as f32).sqrt());
        let up = ConvTW {
            w: if gemm {
                ConvTWeight::Gemm(Matrix::F32(DenseRows::new(data, out * 2 * s, w).unwrap()))
            } else {
                ConvTWeight::Rows(Matrix::F32(DenseRows::new(data, w, out * 2 * s).unwrap()))
            },
            b: rand_leak(rng, out, 0.3),
            c_in: w,
            c_out: out,
            kernel: 2 * s,
            stride: s,
            pad: s / 2,
        };
        stages.push((res, up)).ok().unwrap();
    }
    DecoderW {
        input,
        stages,
        out: synth_conv(rng, c_out, emb, g3),
    }
}

/// A whole VQ-VAE with random weights in the layout `Model::bind` produces.
fn synth_vq(cfg: VqConfig, seed: u64) -> &'static VqW<'static> {
    let mut rng = Rng(seed);
    let (w, s) = (cfg.width as usize, cfg.stride_t as usize);
    let mut stages = heapless::Vec::new();
    for i in 0..cfg.down_t {
        let c_in = if i == 0 { cfg.in_channels as usize } else { w };
        let g = ConvGeom {
            kernel: 2 * s,
            stride: s,
            pad: s / 2,
            dilation: 1,
        };
        let conv = synth_conv(&mut rng, w, c_in, g);
        stages
            .push((conv, synth_resnet(&mut rng, &cfg, false)))
            .ok()
            .unwrap();
    }
    let g3 = ConvGeom {
        kernel: 3,
        stride: 1,
        pad: 1,
        dilation: 1,
    };
    let out = synth_conv(&mut rng, cfg.emb_width as usize, w, g3);
    let (bins, emb) = (cfg.l_bins as usize, cfg.emb_width as usize);
    let codebook =
        Matrix::F32(DenseRows::new(rand_leak(&mut rng, bins * emb, 1.0), bins, emb).unwrap());
    let pos = synth_decoder(&mut rng, &cfg, cfg.in_channels as usize, false);
    let rot = Some(synth_decoder(
        &mut rng,
        &cfg,
        cfg.rot_channels as usize,
        true,
    ));
    Box::leak(Box::new(VqW {
        cfg,
        encoder: EncoderW { stages, out },
        codebook,
        pos,
        rot,
    }))
}

#[test]
fn other_geometries_equal_the_prefix_stacks() {
    let base = VqConfig {
        in_channels: 6,
        rot_channels: 9,
        width: 7,
        depth: 2,
        dilation_growth_rate: 3,
        down_t: 1,
        stride_t: 4,
        emb_width: 5,
        l_bins: 16,
        m_conv_num: 1,
        m_conv_den: 1,
    };
    let cases = [
        base,
        VqConfig {
            stride_t: 2,
            down_t: 3,
            depth: 1,
            ..base
        },
        VqConfig {
            stride_t: 2,
            down_t: 1,
            depth: 4,
            dilation_growth_rate: 2,
            m_conv_num: 3,
            m_conv_den: 2,
            ..base
        },
        VqConfig {
            stride_t: 6,
            down_t: 2,
            depth: 3,
            dilation_growth_rate: 1,
            ..base
        },
    ];
    for (i, cfg) in cases.into_iter().enumerate() {
        let mut mcfg = duolando_published();
        mcfg.parts = [cfg; 4];
        mcfg.transl = cfg;
        let vq = synth_vq(cfg, 99 + i as u64);
        for kind in [StackKind::Encoder, StackKind::Decoder] {
            let fmax = future_max(&cfg, kind);
            for lag in [0, fmax / 2, fmax] {
                let errs = match kind {
                    StackKind::Encoder => vec![run_encoder(&mcfg, vq, lag, 5 + lag as u64)],
                    StackKind::Decoder => [Output::Position, Output::Rotation]
                        .map(|o| run_decoder(&mcfg, vq, o, 0, lag, 9 + lag as u64))
                        .to_vec(),
                };
                for e in errs {
                    eprintln!("case {i} {kind:?} (future_max {fmax}) lag {lag:2}: settled {:.3e} ({}), tail {:.3e} ({})", e.settled, e.n_settled, e.tail, e.n_tail);
                    assert!(
                        e.settled <= TOL && e.tail <= TOL,
                        "case {i} {kind:?} lag {lag}: {e:?}"
                    );
                    assert_eq!(
                        e.n_tail_at_lag == 0,
                        lag >= fmax,
                        "case {i} {kind:?} lag {lag}"
                    );
                }
            }
        }
    }
}

/// Bytes a session's conv streaming state takes for the published model
/// (printed; the planner is exact), and time per push at full width.
/// `cargo test --release -p duolando-core --test stream_conv -- --ignored --nocapture`
#[test]
#[ignore]
fn published_bytes_and_speed() {
    let p = duolando_published();
    let mut sp = Planner::new();
    StreamScratch::for_model(&mut sp, &p).unwrap();
    eprintln!("published: shared scratch {} bytes", sp.bytes());
    for lag in [0, 2, 22] {
        for kind in [StackKind::Encoder, StackKind::Decoder] {
            let mut pl = Planner::new();
            StreamStack::carve(&mut pl, &p.parts[0], kind, lag).unwrap();
            eprintln!(
                "published: {kind:?} stack (up) lag {lag}: {} bytes",
                pl.bytes()
            );
        }
    }
    eprintln!(
        "StreamStack struct: {} bytes",
        std::mem::size_of::<StreamStack<'static>>()
    );
    let mut mcfg = p;
    mcfg.parts = [p.parts[0]; 4];
    mcfg.transl = p.parts[0];
    let vq = synth_vq(p.parts[0], 3);
    let cfg = &vq.cfg;
    let (hop, c_in, emb) = (
        cfg.hop().unwrap() as usize,
        cfg.in_channels as usize,
        cfg.emb_width as usize,
    );
    let mut mem = vec![0u8; 64 << 20];
    let mut a = Arena::new(&mut mem);
    let mut s = StreamScratch::for_model(&mut a, &mcfg).unwrap();
    let mut rng = Rng(1);
    for lag in [22, 11, 0] {
        let mut enc = StreamStack::carve(&mut a, cfg, StackKind::Encoder, lag).unwrap();
        let mut dec = StreamStack::carve(&mut a, cfg, StackKind::Decoder, lag).unwrap();
        let (we, wd) = (StackW::Encoder(&vq.encoder), StackW::Decoder(&vq.pos));
        let x: Vec<f32> = (0..hop * c_in).map(|_| rng.sym()).collect();
        let z: Vec<f32> = (0..emb).map(|_| rng.sym()).collect();
        let (mut f, mut fr) = (vec![0f32; emb], vec![0f32; hop * c_in]);
        let n = 200;
        let (mut te, mut td) = (std::time::Duration::ZERO, std::time::Duration::ZERO);
        for push in 1..=n {
            let t0 = std::time::Instant::now();
            enc.push(we, &x, &mut s).unwrap();
            if push > lag {
                enc.output(we, push - 1 - lag, 1, &mut s, &mut f).unwrap();
            }
            let t1 = std::time::Instant::now();
            dec.push(wd, &z, &mut s).unwrap();
            if push > lag {
                dec.output(wd, hop * (push - 1 - lag), hop, &mut s, &mut fr)
                    .unwrap();
            }
            let t2 = std::time::Instant::now();
            if push > 50 {
                te += t1 - t0;
                td += t2 - t1;
            }
        }
        let k = (n - 50) as u32;
        eprintln!(
            "published width 512, lag {lag:2}: encoder {:?}/push+output, decoder {:?}/push+output",
            te / k,
            td / k
        );
    }
}

/// `push_output` (each unit's tail computed in the same pass as its
/// settled columns) gives what `push` then `output` give, bit for bit, at
/// every lag, alone and for two stacks at once (`push_output_many`); a
/// request beyond the prefix is refused before anything changes.
#[test]
fn push_output_equals_push_then_output_bit_for_bit() {
    for name in ["tiny", "tiny2"] {
        let m = model(name);
        for (part, vq, stream) in vqs(m) {
            let cfg = &vq.cfg;
            let (hop, emb) = (cfg.hop().unwrap() as usize, cfg.emb_width as usize);
            let c_out = vq.pos.out.c_out;
            let w = StackW::Decoder(&vq.pos);
            let fmax = future_max(cfg, StackKind::Decoder);
            for lag in lags(fmax) {
                let mut mem = vec![0u8; 1 << 23];
                let mut a = Arena::new(&mut mem);
                let mut s = StreamScratch::carve(
                    &mut a,
                    duolando_core::nn::stream_conv::ScratchNeed::for_model(&m.cfg).unwrap(),
                    2,
                )
                .unwrap();
                let mut st: Vec<StreamStack<'_>> = (0..4)
                    .map(|_| StreamStack::carve(&mut a, cfg, StackKind::Decoder, lag).unwrap())
                    .collect();
                let mut rng = Rng(31 + lag as u64);
                let n_push = pushes(fmax, lag);
                let (mut z, mut z2) = (vec![0f32; emb], vec![0f32; emb]);
                let mut tails = 0;
                for p in 1..=n_push {
                    let code = [(rng.next() % cfg.l_bins as u64) as u32];
                    let code2 = [(rng.next() % cfg.l_bins as u64) as u32];
                    dequantise(&vq.codebook, &code, stream, &mut z).unwrap();
                    dequantise(&vq.codebook, &code2, stream, &mut z2).unwrap();
                    // The oldest token the carved lag serves after this push.
                    let q = p - 1 - lag.min(p - 1);
                    let (t, n) = (hop * q, hop);
                    let (mut want, mut want2) = (vec![0f32; n * c_out], vec![0f32; n * c_out]);
                    let (mut got, mut got2) = (vec![0f32; n * c_out], vec![0f32; n * c_out]);
                    let (s0, rest) = st.split_at_mut(1);
                    let (s1, rest) = rest.split_at_mut(1);
                    let (s2, s3) = rest.split_at_mut(1);
                    // A refused request (beyond the prefix) changes nothing.
                    let far = s2[0].len() + 2 * hop;
                    assert!(s2[0].push_output(w, &z, far, n, &mut s, &mut got).is_err());
                    s0[0].push(w, &z, &mut s).unwrap();
                    s0[0].output(w, t, n, &mut s, &mut want).unwrap();
                    s1[0].push(w, &z2, &mut s).unwrap();
                    s1[0].output(w, t, n, &mut s, &mut want2).unwrap();
                    tails += usize::from(p > lag && t + n > s0[0].settled());
                    StreamStack::push_output_many(
                        &mut [&mut s2[0], &mut s3[0]],
                        w,
                        &[&z, &z2],
                        &[t, t],
                        n,
                        &mut s,
                        &mut [&mut got, &mut got2],
                    )
                    .unwrap_or_else(|e| panic!("{name} {part} lag {lag} push {p}: {e:?}"));
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&got), bits(&want), "{name} {part} lag {lag} push {p}");
                    assert_eq!(
                        bits(&got2),
                        bits(&want2),
                        "{name} {part} lag {lag} push {p} (2nd)"
                    );
                    assert_eq!(s2[0].settled(), s0[0].settled());
                    assert_eq!(s2[0].len(), s0[0].len());
                }
                assert_eq!(
                    tails > 0,
                    lag < fmax,
                    "{name} {part} lag {lag}: tails {tails}"
                );
            }
        }
    }
}
