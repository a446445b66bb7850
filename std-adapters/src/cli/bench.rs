//! `duolando bench`: speed of the engine on a FULL-size model (the
//! published config, `presets::duolando_published()`) built in memory from
//! seeded random weights, per weight type (f32, f16, int8 as
//! `duolando convert` would store them). No files needed.
//!
//! Measured, per weight type, on 1 thread and on 2 threads (one step
//! whose large GEMMs are split over a pool of that many threads,
//! `crate::workers`), medians and p99/median after warm-up, beside a
//! memcpy bandwidth measured in the same run (1 and 2 threads):
//! - the R step (one full window of the GPT at the largest context,
//!   `block_size - 1` = 29 tokens per stream, music and leader LATs
//!   included; exactly what `exact::generate` runs per step), the weight
//!   bytes it reads and the achieved GB/s;
//! - the S step (`core::session` with `SessionConfig::reference`, f16 K/V:
//!   the time of a `push_leader_frame` that runs a step, encoder and
//!   decoder streaming included), GB/s over the model's weight bytes (every
//!   layer runs each step), and the session arena bytes.
//! - `Session::step_many` over 1, 4 and 16 sessions (int8, one thread);
//! - tract running the full-size R step exported from tools/reference
//!   (`--tract-onnx`, built with the `tract` feature), and onnxruntime's
//!   time for the same step (`--ort-json` from tools/duolando_ort_r_step.py),
//!   for the ratios.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context};
use duolando_core::duolando::gpt::{self, Window};
use duolando_core::nn::bind::{BindError, TensorSource};
use duolando_core::duolando::model::Model;
use duolando_core::duolando::presets::duolando_published;
use duolando_core::family::FamilyConfig;
use duolando_core::nn::names::{SchemaError, TensorSpec};
use duolando_core::duolando::session::{CacheSchedule, FollowerFrame, KvType, Session, SessionConfig, StepBatch};
use duolando_core::tensor::{block_row, DType, TensorRef, MAX_RANK};

use crate::convert::{storage_for, stored_dims};
use crate::duo_writer::{quantise_q4_block32, quantise_q4_block32x8, quantise_q8_block32, quantise_q8_block32x8, StoreAs};

/// The `[isa | CPU] ` every printed line of the ISA being measured starts
/// with (empty without `--isa`).
static LABEL: std::sync::Mutex<String> = std::sync::Mutex::new(String::new());

/// `println!` with the ISA label in front.
macro_rules! say {
    ($($t:tt)*) => {
        println!("{}{}", LABEL.lock().map(|l| l.clone()).unwrap_or_default(), format!($($t)*))
    };
}

#[path = "bench_transflower.rs"]
mod transflower;

#[path = "bench_ort.rs"]
mod ort;

/// Flags of `duolando bench`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Timed R steps per weight type (after the warm-up).
    #[arg(long, default_value_t = 7, value_parser = at_least_one)]
    pub runs: usize,
    /// Timed S steps per weight type (after the warm-up steps).
    #[arg(long, default_value_t = 40, value_parser = at_least_one)]
    pub s_steps: usize,
    /// Thread counts to measure (comma separated): the large GEMMs of one
    /// step split over that many threads.
    #[arg(long, value_delimiter = ',', default_values_t = vec![1usize, 2], value_parser = at_least_one)]
    pub threads: Vec<usize>,
    /// Untimed warm-up R steps per weight type.
    #[arg(long, default_value_t = 1)]
    pub warmup: usize,
    /// Weight types to measure (comma separated: f32,f16,int8,q4; `--dtypes`
    /// with no value skips the model benches, e.g. for `--kernels` alone).
    #[arg(long, value_delimiter = ',', num_args = 0.., default_values_t = vec![String::from("int8"), String::from("f16"), String::from("f32")])]
    pub dtypes: Vec<String>,
    /// Use the scalar reference kernels instead of the detected SIMD ones.
    #[arg(long)]
    pub scalar: bool,
    /// Run the whole bench once per ISA, in this order, in one invocation
    /// (comma separated: scalar, avx2, avxvnni, avx512, avx512vnni, avx512amx =
    /// AVX512-VNNI with the AMX tiles, neon, neondot, neoni8mm = NEON dotprod
    /// with the i8mm packed GEMM); every line then starts
    /// with `[isa | CPU model]` and every JSON key ends in `_<isa>`. An ISA
    /// this CPU lacks is refused by name before anything runs. Default: the
    /// detected ISA (capped by `DUOLANDO_ISA`).
    #[arg(long, value_delimiter = ',')]
    pub isa: Vec<String>,
    /// Also measure the int8 multiply-accumulate peak of each ISA
    /// (register-only probes) and each int8 GEMM shape the engine runs
    /// (`linear`, `Q8Block32x8` weights: R step, re-prefill chunk, 16
    /// sessions, S step, LAT push) with its fraction of the ISA's peak
    /// (median of `--runs` calls per shape, at most 5 for 64 rows or more).
    #[arg(long)]
    pub kernels: bool,
    /// Which family's published model: duolando (default), bailando (its
    /// R step, the actor GPT over a full 28-token window, and its S step per
    /// preset, f16 K/V, with the session arena) or transflower (the paper
    /// config's R step and its S step per session preset, with the arena).
    #[arg(long, default_value = "duolando")]
    pub family: String,
    /// Session counts stepped together with `Session::step_many` (int8
    /// only; comma separated; `--batch` with no value skips them).
    #[arg(long, value_delimiter = ',', num_args = 0.., default_values_t = vec![1usize, 4, 16], value_parser = at_least_one)]
    pub batch: Vec<usize>,
    /// onnxruntime's time for the family's R step, measured right before
    /// by tools/<family>_ort_r_step.py (its JSON, checked before anything
    /// runs); the bench prints it and each weight type's and thread
    /// count's ratio onnxruntime / ours.
    #[arg(long)]
    pub ort_json: Option<std::path::PathBuf>,
    /// The full-size R step as ONNX (tools/reference/export_full_r_step.py),
    /// timed in tract in the same run (needs the `tract` cargo feature);
    /// default: /tmp/duolando_full/full_r_step.onnx when it exists.
    #[arg(long)]
    pub tract_onnx: Option<PathBuf>,
    /// The GPT window shift of every S budget measured (`--family duolando`
    /// or `bailando`; `1..=block_size - 1`). Default: the presets' (Duolando 15 at full
    /// size, 22 until 2026-12-07), so one run can time another shift's cost.
    #[arg(long, value_parser = at_least_one)]
    pub shift: Option<usize>,
    /// Also write the figures as one flat JSON object.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// A count flag's value: a whole number of at least 1 (0 runs, steps,
/// threads or sessions would leave nothing to time).
fn at_least_one(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(format!("not a whole number: {e}")),
    }
}

/// Timing summary of repeated runs.
#[derive(Clone, Copy, Debug)]
struct Stats {
    median_ms: f64,
    p99_ms: f64,
    /// The mean: for S steps the amortised cost, re-prefills included.
    mean_ms: f64,
}

fn stats(mut t: Vec<Duration>) -> Stats {
    t.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let n = t.len();
    // p99 by nearest rank: with fewer than 100 runs it is the maximum.
    let p99 = ((0.99 * n as f64).ceil() as usize).clamp(1, n) - 1;
    let mean_ms = t.iter().map(|&d| ms(d)).sum::<f64>() / n.max(1) as f64;
    Stats { median_ms: if n % 2 == 1 { ms(t[n / 2]) } else { 0.5 * (ms(t[n / 2 - 1]) + ms(t[n / 2])) }, p99_ms: ms(t[p99]), mean_ms }
}

/// memcpy bandwidth over `threads` threads (each copying its own half /
/// third / ... at once): bytes copied per second, 256 MiB buffers (far
/// beyond the caches), median of 9 copies.
fn memcpy_gbps(threads: usize) -> f64 {
    let n = 256 << 20;
    let src = vec![1u8; n];
    let mut dst = vec![0u8; n];
    dst.copy_from_slice(&src);
    let per = n.div_ceil(threads.max(1));
    let mut t = Vec::new();
    for _ in 0..9 {
        let s = Instant::now();
        std::thread::scope(|sc| {
            let mut parts = dst.chunks_mut(per).zip(src.chunks(per));
            let first = parts.next();
            for (d, c) in parts {
                sc.spawn(move || d.copy_from_slice(std::hint::black_box(c)));
            }
            if let Some((d, c)) = first {
                d.copy_from_slice(std::hint::black_box(c));
            }
        });
        t.push(s.elapsed());
        std::hint::black_box(&dst);
    }
    n as f64 / (stats(t).median_ms * 1e-3) / 1e9
}

/// Read-only bandwidth on one thread: bytes read per second over a 256
/// MiB buffer (far beyond the caches) by the selected ISA's f32 dot kernel
/// dotting the buffer with itself (one stream of loads, several
/// accumulators), median of 9 passes. What a step that only streams its
/// weights could reach; memcpy also writes every byte.
fn read_gbps() -> f64 {
    let n = 256 << 20;
    let buf: Vec<f32> = (0..n / 4).map(|i| (i % 7) as f32 * 0.125).collect();
    let mut t = Vec::new();
    for _ in 0..9 {
        let s = Instant::now();
        let b = std::hint::black_box(&buf[..]);
        std::hint::black_box(duolando_core::kernels::dot(b, b));
        t.push(s.elapsed());
    }
    n as f64 / (stats(t).median_ms * 1e-3) / 1e9
}

/// A full-size model's tensors, stored in one 64-byte aligned buffer.
struct RandomModel {
    buf: Vec<u64>,
    /// name -> (dtype, shape, rank, byte range)
    table: HashMap<String, (DType, [u32; MAX_RANK], u8, std::ops::Range<usize>)>,
}

/// xorshift64* uniform in [-1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let v = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
        (v >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    }
}

impl RandomModel {
    fn build(cfg: &FamilyConfig, requested: StoreAs, seed: u64) -> anyhow::Result<RandomModel> {
        let mut specs: Vec<TensorSpec> = Vec::new();
        cfg.for_each_tensor::<SchemaError>(&mut |s| {
            specs.push(s.clone());
            Ok(())
        })
        .map_err(|e| anyhow!("schema: {e:?}"))?;
        let mut layout = Vec::new();
        let mut off = 0usize;
        for s in &specs {
            let stored = storage_for(requested, s);
            let dims = &stored_dims(s, stored)[..];
            let dtype = match stored {
                StoreAs::F32 => DType::F32,
                StoreAs::F16 => DType::F16,
                StoreAs::Q8Block32 => DType::Q8Block32,
                StoreAs::Q8Block32x8 => DType::Q8Block32x8,
                StoreAs::Q4Block32x8 => DType::Q4Block32x8,
                StoreAs::Q4Block32 => DType::Q4Block32,
            };
            let numel: usize = dims.iter().map(|&d| d as usize).product();
            let bytes = dtype.bytes_for(numel, block_row(dims)).ok_or_else(|| anyhow!("size of {}", s.name))?;
            let mut shape = [1u32; MAX_RANK];
            shape[..dims.len()].copy_from_slice(dims);
            layout.push((dtype, shape, dims.len() as u8, off..off + bytes));
            off = (off + bytes).next_multiple_of(64);
        }
        let mut buf = vec![0u64; off / 8 + 8];
        // Start the tensor data at a 64-byte boundary of the allocation.
        let base = (64 - (buf.as_ptr() as usize % 64)) % 64;
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut buf);
        let mut rng = Rng(seed | 1);
        let mut table = HashMap::new();
        for (s, (dtype, shape, rank, range)) in specs.iter().zip(layout) {
            let dims = &shape[..rank as usize];
            let numel: usize = dims.iter().map(|&d| d as usize).product();
            let name = s.name.as_str();
            // Weights ~ U(-0.05, 0.05); LayerNorm weights 1, biases small.
            let scale = if dims.len() == 1 { 0.01 } else { 0.05 };
            let ln_weight = dims.len() == 1 && name.contains(".ln") && name.ends_with(".weight");
            let values: Vec<f32> = (0..numel).map(|_| if ln_weight { 1.0 } else { rng.next() * scale }).collect();
            let dst = &mut bytes[base + range.start..base + range.end];
            match dtype {
                DType::F32 => dst.copy_from_slice(bytemuck::cast_slice(&values)),
                DType::F16 => {
                    for (d, v) in dst.chunks_exact_mut(2).zip(&values) {
                        d.copy_from_slice(&half::f16::from_f32(*v).to_le_bytes());
                    }
                }
                DType::Q8Block32 => dst.copy_from_slice(&quantise_q8_block32(&values)),
                DType::Q8Block32x8 => dst.copy_from_slice(&quantise_q8_block32x8(&values, block_row(dims))),
                DType::Q4Block32x8 => dst.copy_from_slice(&quantise_q4_block32x8(&values, block_row(dims))),
                DType::Q4Block32 => dst.copy_from_slice(&quantise_q4_block32(&values)),
            }
            table.insert(name.to_string(), (dtype, shape, rank, base + range.start..base + range.end));
        }
        Ok(RandomModel { buf, table })
    }

    /// Bytes of every stored tensor.
    fn weight_bytes(&self) -> usize {
        self.table.values().map(|(_, _, _, r)| r.len()).sum()
    }

    /// Bytes of the stored tensors whose names `keep` accepts.
    fn weight_bytes_of(&self, keep: impl Fn(&str) -> bool) -> usize {
        self.table.iter().filter(|(n, _)| keep(n)).map(|(_, (_, _, _, r))| r.len()).sum()
    }
}

impl<'a> TensorSource<'a> for &'a RandomModel {
    fn tensor(&self, name: &str) -> Option<TensorRef<'a>> {
        let (dtype, shape, rank, range) = self.table.get(name)?;
        let bytes: &'a [u8] = bytemuck::cast_slice(&self.buf);
        Some(TensorRef { dtype: *dtype, rank: *rank, shape: *shape, data: &bytes[range.clone()] })
    }
}

/// Weight bytes one R step reads: every Linear of the LATs and of the
/// coordinated-attention blocks, the 5 heads (matrices + f32 biases and
/// LayerNorm), the embedding rows it looks up and the `pos_emb` rows.
fn r_step_weight_bytes(m: &Model<'_>, c: usize) -> usize {
    let lin = |l: &duolando_core::nn::weights::Linear<'_>| l.w.weight_bytes() + l.b.map_or(0, |b| b.len() * 4);
    let block = |b: &duolando_core::nn::weights::BlockW<'_>| {
        lin(&b.query) + lin(&b.key) + lin(&b.value) + lin(&b.proj) + lin(&b.fc) + lin(&b.fc_out) + 4 * 4 * b.ln1.w.len()
    };
    let lat = |l: &duolando_core::duolando::model::LatW<'_>| lin(&l.cond_emb) + lin(&l.downsample) + l.blocks.iter().map(block).sum::<usize>();
    let g = &m.gpt;
    let n_embd = m.cfg.gpt.n_embd as usize;
    let lf = m.cfg.gpt.look_forward as usize;
    let emb_row = |t: &duolando_core::kernels::Matrix<'_>| t.weight_bytes() / t.rows().max(1);
    lat(&g.music)
        + g.leaders.iter().map(lat).sum::<usize>()
        + g.base.iter().chain(g.head.iter()).map(block).sum::<usize>()
        + g.heads.iter().map(|h| h.weight_bytes()).sum::<usize>()
        + g.tok_emb[..4].iter().map(|t| (c + lf) * emb_row(t)).sum::<usize>()
        + 5 * c * emb_row(&g.tok_emb[0])
        + 10 * c * n_embd * 4
}

struct DtypeResult {
    name: &'static str,
    /// Per thread count: R step timing.
    r: Vec<(usize, Stats)>,
    /// Per thread count: S step timing.
    s: Vec<(usize, Stats)>,
    weight_bytes: usize,
    model_bytes: usize,
    arena_bytes: usize,
    /// The same session's state alone (`Model::batched_session_bytes`: a
    /// session stepped only through a `StepBatch`).
    state_bytes: usize,
    /// Per session count: one `step_many` call that steps every session.
    batch: Vec<(usize, Stats)>,
    /// The same with spread GPT caches, after start-up.
    batch_spread: Vec<(usize, Stats)>,
    /// int8: the S step under each of [`SCHEDULES`] (one thread) and its arena bytes.
    schedules: Vec<(&'static str, Stats, usize)>,
}

/// The R-step inputs of a full window (fixed pseudo-random tokens/features).
struct RInputs {
    c: usize,
    music: Vec<f32>,
    leader: Vec<Vec<u32>>,
    follower: Vec<u32>,
}

impl RInputs {
    fn new(model: &Model<'_>) -> RInputs {
        let cfg = &model.cfg;
        let g = &cfg.gpt;
        let c = gpt::max_context(cfg);
        let lf = g.look_forward as usize;
        let ds = g.music.downsample_rate as usize;
        let mut rng = Rng(42);
        let music: Vec<f32> = (0..(c + lf) * ds * g.music.n_in as usize).map(|_| rng.next()).collect();
        let leader: Vec<Vec<u32>> =
            (0..4).map(|p| (0..c + lf).map(|i| ((i * 37 + p * 11) % g.vocab[p] as usize) as u32).collect()).collect();
        let follower: Vec<u32> = (0..c * 5).map(|i| ((i * 13) % g.vocab[i % 5] as usize) as u32).collect();
        RInputs { c, music, leader, follower }
    }
}

/// `runs` timed R steps after `warmup` untimed ones (one thread).
fn r_steps(model: &Model<'_>, inp: &RInputs, warmup: usize, runs: usize) -> anyhow::Result<Vec<Duration>> {
    let cfg = &model.cfg;
    let win = Window { c: inp.c, music: &inp.music, leader: [&inp.leader[0], &inp.leader[1], &inp.leader[2], &inp.leader[3]], follower: &inp.follower };
    let mut scratch = vec![0u8; gpt::scratch_bytes(cfg, inp.c).context("scratch size")?];
    let mut logits = vec![0.0f32; gpt::logits_len(cfg)];
    for _ in 0..warmup {
        gpt::step_logits(model, &win, &mut scratch, &mut logits).map_err(|e| anyhow!("{e:?}"))?;
    }
    let mut times = Vec::new();
    for _ in 0..runs.max(1) {
        let s = Instant::now();
        gpt::step_logits(model, &win, &mut scratch, &mut logits).map_err(|e| anyhow!("{e:?}"))?;
        times.push(s.elapsed());
    }
    if !logits.iter().all(|v| v.is_finite()) {
        return Err(anyhow!("non-finite logits"));
    }
    Ok(times)
}

/// The settings the bench times again after start-up (int8, one thread,
/// steady state): the GPT cache schedules at the reference budget (the
/// re-prefill, the least memory; one cache per live window; two caches
/// with the next window filled ahead, the presets' schedule), and the
/// interactive preset as the presets give it (spread), whose encoders and
/// decoders compute unsettled tails every step.
const SCHEDULES: [&str; 4] = ["reprefill", "staggered", "spread", "interactive"];

/// What [`SCHEDULES`] entry `schedule` is, for the printed line.
fn schedule_label(schedule: &str) -> &'static str {
    match schedule {
        "staggered" => "staggered caches",
        "spread" => "spread (default)",
        "interactive" => "interactive preset",
        _ => "reprefill (lean)",
    }
}

/// The session configuration measured: reference budget (the interactive
/// preset for "interactive", with the presets' schedule), f16 K/V, the GPT
/// cache `schedule` ("reprefill" or one of [`SCHEDULES`]), the window
/// `shift` if given (`--shift`).
fn s_config(model: &Model<'_>, schedule: &str, shift: Option<usize>) -> SessionConfig {
    let mut cfg = if schedule == "interactive" {
        SessionConfig::preset(&model.cfg, duolando_core::duolando::session::Preset::Interactive)
    } else {
        SessionConfig::reference(&model.cfg)
    };
    cfg.kv = KvType::F16;
    if let Some(s) = shift {
        cfg.shift = s as u32;
    }
    cfg.schedule = match schedule {
        "staggered" => CacheSchedule::Staggered,
        "spread" => CacheSchedule::Spread,
        "interactive" => cfg.schedule,
        _ => CacheSchedule::Reprefill,
    };
    cfg
}

/// Streams pseudo-random leader and music frames into a fresh session and
/// times each `push_leader_frame` that runs a GPT step; the first
/// `warmup` steps are dropped, then `steps` are kept (one thread).
fn s_steps(model: &Model<'_>, schedule: &str, shift: Option<usize>, warmup: usize, steps: usize) -> anyhow::Result<Vec<Duration>> {
    let cfg = s_config(model, schedule, shift);
    let mut arena = vec![0u8; model.session_bytes(&cfg).map_err(|e| anyhow!("session bytes: {e:?}"))?];
    let mut sess = Session::new(model, &mut arena, &cfg, [0; 5]).map_err(|e| anyhow!("session: {e:?}"))?;
    let n_music = model.cfg.gpt.music.n_in as usize;
    let mut rng = Rng(7);
    let mut music = vec![0.0f32; n_music];
    let mut leader = vec![0.0f32; 165];
    let mut out = FollowerFrame::default();
    let mut times = Vec::new();
    let mut frames = 0usize;
    // Music known ahead (a track), as far as the session holds it: a budget
    // whose latency is shorter than its music look-ahead needs it.
    for _ in 0..4096 {
        music.iter_mut().for_each(|v| *v = rng.next());
        if sess.push_music_frame(&music).is_err() {
            break;
        }
    }
    // Generous cap: the pipeline fills after the latency, then one step per hop.
    let max_frames = 4 * (warmup + steps) + 4096;
    while times.len() < warmup + steps && frames < max_frames {
        music.iter_mut().for_each(|v| *v = rng.next());
        // Music may be refused while the session holds enough (Backlog): fine.
        let _ = sess.push_music_frame(&music);
        for (i, v) in leader.iter_mut().enumerate() {
            *v = 0.3 * rng.next() + if i % 3 == 1 { 1.0 } else { 0.0 };
        }
        let before = sess.steps();
        let t = Instant::now();
        sess.push_leader_frame(&leader).map_err(|e| anyhow!("push_leader_frame: {e:?}"))?;
        let dt = t.elapsed();
        if sess.steps() > before {
            times.push(dt);
        }
        while sess.pull_follower_frame(&mut out).map_err(|e| anyhow!("pull: {e:?}"))? {}
        frames += 1;
    }
    if times.len() < warmup + steps {
        return Err(anyhow!("session ran only {} steps in {frames} frames", times.len()));
    }
    Ok(times.split_off(warmup))
}

/// `n` sessions stepped together: per frame, music pushed into each, then
/// one `Session::step_many` with a pseudo-random leader frame per session;
/// times the calls that run a step in every session (one thread).
fn batched_steps(model: &Model<'_>, schedule: &str, shift: Option<usize>, n: usize, warmup: usize, steps: usize) -> anyhow::Result<Vec<Duration>> {
    let cfg = s_config(model, schedule, shift);
    let mut batch_arena = vec![0u8; StepBatch::bytes(&model.cfg, &cfg, n).map_err(|e| anyhow!("batch bytes: {e:?}"))?];
    let mut batch = StepBatch::new(&model.cfg, &cfg, n, &mut batch_arena).map_err(|e| anyhow!("batch: {e:?}"))?;
    // Sessions stepped only together hold their state alone (`new_batched`):
    // every step runs in the batch's memory.
    let bytes = model.batched_session_bytes(&cfg).map_err(|e| anyhow!("session bytes: {e:?}"))?;
    let mut arenas: Vec<Vec<u8>> = (0..n).map(|_| vec![0u8; bytes]).collect();
    let mut sessions = Vec::with_capacity(n);
    for a in arenas.iter_mut() {
        sessions.push(Session::new_batched(model, a, &cfg, [0; 5], &mut batch).map_err(|e| anyhow!("session: {e:?}"))?);
    }
    let n_music = model.cfg.gpt.music.n_in as usize;
    let mut rng = Rng(11);
    let mut music = vec![0.0f32; n_music];
    let mut leaders = vec![0.0f32; 165 * n];
    let mut out = FollowerFrame::default();
    let mut times = Vec::new();
    let mut frames = 0usize;
    let max_frames = 4 * (warmup + steps) + 4096;
    while times.len() < warmup + steps && frames < max_frames {
        for s in sessions.iter_mut() {
            music.iter_mut().for_each(|v| *v = rng.next());
            // A refusal (music too far ahead) is fine: the frame is dropped.
            let _ = s.with_batch(&mut batch, |s| s.push_music_frame(&music)).map_err(|e| anyhow!("music push: {e:?}"))?;
        }
        for (i, v) in leaders.iter_mut().enumerate() {
            *v = 0.3 * rng.next() + if i % 3 == 1 { 1.0 } else { 0.0 };
        }
        let rows: Vec<&[f32]> = leaders.chunks(165).collect();
        let before: Vec<usize> = sessions.iter().map(|s| s.steps()).collect();
        let mut refs: Vec<&mut Session<'_>> = sessions.iter_mut().collect();
        let t = Instant::now();
        Session::step_many(&mut refs, &rows, &mut batch).map_err(|(i, e)| anyhow!("step_many, session {i}: {e:?}"))?;
        let dt = t.elapsed();
        if sessions.iter().zip(&before).all(|(s, &b)| s.steps() > b) {
            times.push(dt);
        }
        for s in sessions.iter_mut() {
            while s.pull_follower_frame(&mut out).map_err(|e| anyhow!("pull: {e:?}"))? {}
        }
        frames += 1;
    }
    if times.len() < warmup + steps {
        return Err(anyhow!("{n} sessions stepped together only {} times in {frames} frames", times.len()));
    }
    Ok(times.split_off(warmup))
}

/// One line per session count of a `step_many` measurement, with its ratio
/// to one session of the same measurement.
fn print_batch(name: &str, what: &str, v: &[(usize, Stats)]) {
    let one = v.iter().find(|(n, _)| *n == 1).map(|(_, st)| st.median_ms);
    for (n, st) in v {
        say!(
            "S step {name:>4} x{n:<2} {what} median {:8.2} ms  p99 {:8.2} ms  mean {:8.2} ms  = {:.2} ms per session{}",
            st.median_ms,
            st.p99_ms,
            st.mean_ms,
            st.median_ms / *n as f64,
            one.map(|o| format!("  ({:.2}x the time of 1 session)", st.median_ms / o)).unwrap_or_default()
        );
    }
}

/// Runs `f` with the GEMMs split over `threads` threads (the pool of
/// `crate::workers`), then back to one thread.
fn on_threads<F>(threads: usize, f: F) -> anyhow::Result<Vec<Duration>>
where
    F: Fn() -> anyhow::Result<Vec<Duration>>,
{
    crate::workers::set_threads(threads).context("starting the GEMM threads")?;
    let jobs = crate::workers::split_jobs();
    let times = f();
    let split = crate::workers::split_jobs() - jobs;
    crate::workers::set_threads(1)?;
    if threads > 1 && split == 0 {
        return Err(anyhow!("no GEMM was split over {threads} threads"));
    }
    times
}

fn bench_dtype(name: &'static str, store_as: StoreAs, args: &Args) -> anyhow::Result<DtypeResult> {
    let t0 = Instant::now();
    let rm = RandomModel::build(&duolando_published().into(), store_as, 0x5eed_0000 ^ store_as as u64)?;
    let model = Model::bind(&duolando_published(), &&rm).map_err(|e: BindError| anyhow!("bind: {e:?}"))?;
    eprintln!("{name}: model built and bound in {:.1} s", t0.elapsed().as_secs_f64());
    let inp = RInputs::new(&model);
    let mut r = Vec::new();
    let mut s = Vec::new();
    for &t in &args.threads {
        let times = on_threads(t, || r_steps(&model, &inp, args.warmup, args.runs)).with_context(|| format!("{name} R step, {t} threads"))?;
        r.push((t, stats(times)));
        let times = on_threads(t, || s_steps(&model, "reprefill", args.shift, 3, args.s_steps)).with_context(|| format!("{name} S step, {t} threads"))?;
        s.push((t, stats(times)));
    }
    let arena_bytes = model.session_bytes(&s_config(&model, "reprefill", args.shift)).map_err(|e| anyhow!("{e:?}"))?;
    let state_bytes = model.batched_session_bytes(&s_config(&model, "reprefill", args.shift)).map_err(|e| anyhow!("{e:?}"))?;
    let mut batch = Vec::new();
    let mut schedules = Vec::new();
    let mut batch_spread = Vec::new();
    if name == "int8" {
        // After start-up (the first full window, step m: a spread schedule's
        // one re-prefill): the steady state.
        let steady = model.cfg.gpt.block_size as usize + 2;
        for sched in SCHEDULES {
            let times = s_steps(&model, sched, args.shift, steady, args.s_steps).with_context(|| format!("{name} S step, {sched} caches"))?;
            schedules.push((sched, stats(times), model.session_bytes(&s_config(&model, sched, args.shift)).map_err(|e| anyhow!("{e:?}"))?));
        }
        for &n in &args.batch {
            let times = batched_steps(&model, "reprefill", args.shift, n, 3, args.s_steps).with_context(|| format!("{name}, {n} sessions stepped together"))?;
            batch.push((n, stats(times)));
        }
        // The batch with spread caches, after start-up: no step where every
        // session re-prefills at once.
        for &n in &args.batch {
            let times = batched_steps(&model, "spread", args.shift, n, steady, args.s_steps).with_context(|| format!("{name}, {n} spread sessions stepped together"))?;
            batch_spread.push((n, stats(times)));
        }
    }
    Ok(DtypeResult { name, r, s, weight_bytes: r_step_weight_bytes(&model, inp.c), model_bytes: rm.weight_bytes(), arena_bytes, state_bytes, batch, batch_spread, schedules })
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let cpu = crate::kernel_bench::cpu_name();
    anyhow::ensure!(!args.scalar || args.isa.is_empty(), "--scalar and --isa: give one (--isa scalar is --scalar)");
    // Refuse every ISA this CPU lacks before anything runs.
    for name in &args.isa {
        crate::simd::select(name).map_err(|e| anyhow!("{e} [{cpu}]"))?;
    }
    // A shift is a GPT window's (Duolando, Bailando) and within it:
    // refused before anything runs.
    if let Some(sh) = args.shift {
        let m = match args.family.as_str() {
            "duolando" => duolando_published().gpt.block_size as usize - 1,
            "bailando" => duolando_core::bailando::session::window_rows(&duolando_core::bailando::config::published()),
            other => anyhow::bail!("--shift is the S budget's GPT window shift (duolando, bailando); not for --family {other}"),
        };
        anyhow::ensure!(sh <= m, "--shift {sh}: the published {} model's window shift is 1..={m}", args.family);
    }
    // A missing or wrong onnxruntime JSON is refused before anything runs.
    let ort = ort::from_args(args.ort_json.as_deref(), &args.family)?;
    let weights = args.kernels.then(|| crate::kernel_bench::Weights::new(false));
    if args.kernels {
        let mut line = format!("int8 MAC peaks on {cpu} (register-only probes, 1 thread):");
        for p in crate::kernel_bench::probes() {
            line += &format!("  {} {:.1} GMAC/s", p.name(), crate::kernel_bench::peak_gmacs(p)?);
        }
        println!("{line}");
    }
    let mut j = serde_json::Map::new();
    j.insert("cpu".into(), cpu.clone().into());
    if args.isa.is_empty() {
        if args.scalar {
            crate::simd::force_scalar();
        } else {
            crate::simd::init();
        }
        j.extend(run_one(&args, weights.as_ref(), ort.as_ref())?);
    } else {
        let mut names = Vec::new();
        for name in &args.isa {
            crate::simd::select(name).map_err(|e| anyhow!("{e}"))?;
            let label = crate::simd::name(crate::simd::active());
            names.push(serde_json::Value::from(label));
            *LABEL.lock().map_err(|_| anyhow!("label lock"))? = format!("[{label} | {cpu}] ");
            let one = run_one(&args, weights.as_ref(), ort.as_ref());
            *LABEL.lock().map_err(|_| anyhow!("label lock"))? = String::new();
            for (k, v) in one? {
                j.insert(format!("{k}_{label}"), v);
            }
        }
        j.insert("isas".into(), names.into());
        crate::simd::init();
    }
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&serde_json::Value::Object(j))?).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// The whole bench under the ISA selected now; its JSON entries.
fn run_one(args: &Args, weights: Option<&crate::kernel_bench::Weights>, ort: Option<&ort::OrtBaseline>) -> anyhow::Result<serde_json::Map<String, serde_json::Value>> {
    let mut j = serde_json::Map::new();
    let isa = crate::simd::describe();
    // The JSON names the ISA as `--isa` and `DUOLANDO_ISA` spell it.
    j.insert("isa".into(), crate::simd::name(crate::simd::active()).into());
    if let Some(w) = weights {
        let rep = crate::kernel_bench::run(w, args.runs)?;
        for l in rep.lines("") {
            say!("{l}");
        }
        rep.json(&mut j, "");
    }
    if args.dtypes.is_empty() {
        // No model bench: onnxruntime's figure alone, no ratio.
        if let Some(o) = ort {
            o.print(&format!("{} R step", family_title(&args.family)));
            o.json(&mut j, &[]);
        }
        return Ok(j);
    }
    let memcpy = memcpy_gbps(1);
    let memcpy_t2 = memcpy_gbps(2);
    let read = read_gbps();
    say!(
        "kernels: {isa}; threads: {:?}; memcpy bandwidth (256 MiB): {memcpy:.1} GB/s on 1 thread, {memcpy_t2:.1} GB/s on 2; read-only: {read:.1} GB/s on 1 thread",
        args.threads
    );
    if args.family == "bailando" {
        bench_bailando(args, ort, memcpy, &mut j)?;
        return Ok(j);
    } else if args.family == "transflower" {
        transflower::run(args, ort, &mut j)?;
        return Ok(j);
    } else if args.family != "duolando" {
        return Err(anyhow!("unknown family '{}' (duolando, bailando, transflower)", args.family));
    }
    if let Some(o) = ort {
        o.print("R step");
    }
    let mut medians = ort::RStepMedians::default();
    let mut results = Vec::new();
    // The window shift of every S budget below (the presets' unless --shift).
    let shift = args.shift.unwrap_or(SessionConfig::reference(&duolando_published()).shift as usize);
    for d in &args.dtypes {
        let (name, store_as) = match d.as_str() {
            "f32" => ("f32", StoreAs::F32),
            "f16" => ("f16", StoreAs::F16),
            "int8" => ("int8", StoreAs::Q8Block32),
            "q4" => ("q4", StoreAs::Q4Block32),
            other => return Err(anyhow!("unknown dtype '{other}' (f32, f16, int8, q4)")),
        };
        let r = bench_dtype(name, store_as, args)?;
        for (t, st) in &r.r {
            let gbps = r.weight_bytes as f64 / (st.median_ms * 1e-3) / 1e9;
            let note = medians.record(r.name, *t, st.median_ms, ort);
            say!(
                "R step {:>4} t{t} (29-token window, LATs incl.): median {:8.1} ms  p99 {:8.1} ms  p99/median {:.2}  weights {:7.1} MB/step  {:5.2} GB/s ({:.0}% of memcpy){note}",
                r.name,
                st.median_ms,
                st.p99_ms,
                st.p99_ms / st.median_ms,
                r.weight_bytes as f64 / 1e6,
                gbps,
                100.0 * gbps / memcpy
            );
        }
        for (t, st) in &r.s {
            let gbps = r.model_bytes as f64 / (st.median_ms * 1e-3) / 1e9;
            say!(
                "S step {:>4} t{t} (reference budget, shift {shift}, f16 K/V):   median {:8.2} ms  p99 {:8.2} ms  p99/median {:.2}  mean {:8.2} ms  weights {:7.1} MB/step  {:5.2} GB/s ({:.0}% of memcpy, {:.0}% of read)  arena {:.2} MB ({:.2} MB stepped only in a StepBatch)",
                r.name,
                st.median_ms,
                st.p99_ms,
                st.p99_ms / st.median_ms,
                st.mean_ms,
                r.model_bytes as f64 / 1e6,
                gbps,
                100.0 * gbps / memcpy,
                100.0 * gbps / read,
                r.arena_bytes as f64 / 1e6,
                r.state_bytes as f64 / 1e6
            );
        }
        for (sched, st, bytes) in &r.schedules {
            say!(
                "S step {:>4} t1 {:<18}, after start-up: median {:8.2} ms  p99 {:8.2} ms  p99/median {:.2}  mean {:8.2} ms  arena {:.1} MB",
                r.name,
                schedule_label(sched),
                st.median_ms,
                st.p99_ms,
                st.p99_ms / st.median_ms,
                st.mean_ms,
                *bytes as f64 / 1e6
            );
        }
        print_batch(r.name, "sessions in one step_many call:", &r.batch);
        print_batch(r.name, "spread sessions, one step_many, after start-up:", &r.batch_spread);
        results.push(r);
    }
    say!("tN = one step with its large GEMMs split over N threads (duolando::workers); % of memcpy is against the 1-thread memcpy.");
    if let Some(o) = ort {
        o.print_ratios("R step", &medians.ours);
        o.json(&mut j, &medians.ours);
    }
    let tract = match super::bench_tract::onnx_path(args.tract_onnx.as_deref()) {
        None => {
            say!("tract ratio: not measured (no full-size R-step ONNX; make it with: {})", super::bench_tract::HOW);
            None
        }
        Some(path) => match super::bench_tract::r_steps(&path, args.warmup, args.runs) {
            Ok((times, err)) => {
                let st = stats(times);
                say!(
                    "R step tract t1 (same window, f32, {}): median {:8.1} ms  p99 {:8.1} ms  p99/median {:.2}  (logits vs torch: max rel diff {err:.1e})",
                    path.display(),
                    st.median_ms,
                    st.p99_ms,
                    st.p99_ms / st.median_ms
                );
                for r in &results {
                    let at = |v: &[(usize, Stats)]| v.iter().find(|(t, _)| *t == 1).map(|(_, s)| s.median_ms);
                    if let (Some(rr), Some(ss)) = (at(&r.r), at(&r.s)) {
                        say!("  {:>4}: tract R step / our R step = {:.2}x; tract R step / our S step = {:.1}x", r.name, st.median_ms / rr, st.median_ms / ss);
                    }
                }
                Some((st, err))
            }
            Err(e) => {
                say!("tract ratio: not measured: {e:#}");
                None
            }
        },
    };
    {
        let null = serde_json::Value::Null;
        for k in [
            "s_step_ms_int8_t1",
            "s_step_ms_f16_t1",
            "s_step_ms_f32_t1",
            "s_step_ms_int8_t2",
            "tract_r_step_ms_t1",
            "s_step_gbps_int8_t1",
            "batch16_over_batch1_int8",
            "arena_bytes_f16kv",
            "r_step_ms_f32_t1",
            "r_step_ms_f16_t1",
            "r_step_ms_int8_t1",
        ] {
            j.insert(k.into(), null.clone());
        }
        j.insert("s_shift".into(), shift.into());
        j.insert("memcpy_gbps_t1".into(), memcpy.into());
        j.insert("memcpy_gbps_t2".into(), memcpy_t2.into());
        j.insert("read_gbps_t1".into(), read.into());
        match &tract {
            Some((st, err)) => {
                j.insert("tract_r_step_ms_t1".into(), st.median_ms.into());
                j.insert("tract_r_step_p99_ms_t1".into(), st.p99_ms.into());
                j.insert("tract_logits_max_rel_diff".into(), (*err as f64).into());
            }
            None => {
                j.insert("not_yet".into(), "tract_r_step_ms_t1 (no full-size R-step ONNX, or built without the tract feature)".into());
            }
        }
        for r in &results {
            for (t, st) in &r.r {
                j.insert(format!("r_step_ms_{}_t{t}", r.name), st.median_ms.into());
                j.insert(format!("r_step_p99_ms_{}_t{t}", r.name), st.p99_ms.into());
                j.insert(format!("r_step_gbps_{}_t{t}", r.name), (r.weight_bytes as f64 / (st.median_ms * 1e-3) / 1e9).into());
            }
            for (t, st) in &r.s {
                j.insert(format!("s_step_ms_{}_t{t}", r.name), st.median_ms.into());
                j.insert(format!("s_step_p99_ms_{}_t{t}", r.name), st.p99_ms.into());
                j.insert(format!("s_step_mean_ms_{}_t{t}", r.name), st.mean_ms.into());
                j.insert(format!("s_step_gbps_{}_t{t}", r.name), (r.model_bytes as f64 / (st.median_ms * 1e-3) / 1e9).into());
            }
            j.insert(format!("r_step_weight_bytes_{}", r.name), r.weight_bytes.into());
            j.insert(format!("s_step_weight_bytes_{}", r.name), r.model_bytes.into());
            j.insert("arena_bytes_f16kv".into(), r.arena_bytes.into());
            j.insert("batched_session_bytes_f16kv".into(), r.state_bytes.into());
            for (sched, st, bytes) in &r.schedules {
                j.insert(format!("s_step_ms_{}_t1_{sched}", r.name), st.median_ms.into());
                j.insert(format!("s_step_p99_ms_{}_t1_{sched}", r.name), st.p99_ms.into());
                j.insert(format!("s_step_mean_ms_{}_t1_{sched}", r.name), st.mean_ms.into());
                j.insert(format!("arena_bytes_f16kv_{sched}"), (*bytes).into());
            }
            for (n, st) in &r.batch {
                j.insert(format!("batch{n}_step_ms_{}", r.name), st.median_ms.into());
                j.insert(format!("batch{n}_step_p99_ms_{}", r.name), st.p99_ms.into());
            }
            for (n, st) in &r.batch_spread {
                j.insert(format!("batch{n}_step_ms_{}_spread", r.name), st.median_ms.into());
                j.insert(format!("batch{n}_step_p99_ms_{}_spread", r.name), st.p99_ms.into());
                j.insert(format!("batch{n}_step_mean_ms_{}_spread", r.name), st.mean_ms.into());
            }
            if let (Some((tr, _)), Some((_, ss))) = (&tract, r.s.iter().find(|(t, _)| *t == 1)) {
                j.insert(format!("tract_r_over_s_step_{}_t1", r.name), (tr.median_ms / ss.median_ms).into());
            }
            if let (Some((tr, _)), Some((_, rr))) = (&tract, r.r.iter().find(|(t, _)| *t == 1)) {
                j.insert(format!("tract_r_over_r_step_{}_t1", r.name), (tr.median_ms / rr.median_ms).into());
            }
            let at = |n: usize| r.batch.iter().find(|(m, _)| *m == n).map(|(_, st)| st.median_ms);
            if let (Some(a), Some(b)) = (at(16), at(1)) {
                j.insert(format!("batch16_over_batch1_{}", r.name), (a / b).into());
            }
        }
    }
    Ok(j)
}

/// Bailando's published model (`bailando::config::published`, seeded random
/// weights) per weight type: one R step (the actor GPT over a full window of
/// `block_size - 1` = 28 tokens and their music rows, as `AC.eval` runs it
/// once the window slides) per thread count, against real time (one token
/// per 8 frames at 60 fps: 133.3 ms) and against f32 in the same run.
fn bench_bailando(args: &Args, ort: Option<&ort::OrtBaseline>, memcpy: f64, j: &mut serde_json::Map<String, serde_json::Value>) -> anyhow::Result<()> {
    use duolando_core::bailando::session::{Preset as SoloPreset, SessionConfig as SoloConfig};
    use duolando_core::bailando::config::published;
    use duolando_core::bailando::gpt::{logits_len, max_context, window_logits, GptScratch};
    use duolando_core::bailando::model::Model as BModel;
    let cfg = published();
    let c = max_context(&cfg);
    let nm = cfg.gpt.n_music as usize;
    let mut rng = Rng(0xba11_a4d0);
    let tokens: Vec<u32> = (0..2 * c).map(|i| ((rng.next() + 1.0) * 255.0) as u32 % cfg.gpt.vocab[i % 2]).collect();
    let music: Vec<f32> = (0..c * nm).map(|_| rng.next()).collect();
    let mut medians = ort::RStepMedians::default();
    let real_time_ms = 1000.0 * cfg.hop() as f64 / duolando_core::bailando::config::FPS as f64;
    if let Some(o) = ort {
        o.print("Bailando R step");
    }
    for d in &args.dtypes {
        let store_as = match d.as_str() {
            "f32" => StoreAs::F32,
            "f16" => StoreAs::F16,
            "int8" => StoreAs::Q8Block32,
            "q4" => StoreAs::Q4Block32,
            other => return Err(anyhow!("unknown dtype '{other}' (f32, f16, int8, q4)")),
        };
        let t0 = Instant::now();
        let rm = RandomModel::build(&cfg.into(), store_as, 0xba11_0000 ^ store_as as u64)?;
        let model = BModel::bind(&cfg, &&rm).map_err(|e: BindError| anyhow!("bind: {e:?}"))?;
        eprintln!("Bailando {d}: model built and bound in {:.1} s ({:.1} MB of weights)", t0.elapsed().as_secs_f64(), rm.weight_bytes() as f64 / 1e6);
        // What an S step between window jumps reads: every GPT block (one
        // pass for the 3 new rows), ln_f and the heads, and the three
        // streaming decoders (up, down, root) for one token.
        let gpt_bytes = rm.weight_bytes_of(|n| n.contains(".blocks.") || n.starts_with("gpt.gpt_head.head_") || n.starts_with("gpt.gpt_head.ln_f"));
        let dec_bytes = rm.weight_bytes_of(|n| n.contains(".decoders"));
        let step_bytes = gpt_bytes + dec_bytes;
        say!("Bailando S step {d:>4}: an S step between window jumps reads {:.1} MB of weights (GPT blocks and heads {:.1} MB, the three decoders {:.1} MB)", step_bytes as f64 / 1e6, gpt_bytes as f64 / 1e6, dec_bytes as f64 / 1e6);
        for &t in &args.threads {
            let times = on_threads(t, || {
                let mut bytes = vec![0u8; duolando_core::bailando::exact::sample_scratch_bytes(&cfg).unwrap_or(0)];
                let mut a = duolando_core::arena::Arena::new(&mut bytes);
                let mut s = GptScratch::carve(&mut a, &cfg, c).map_err(|e| anyhow!("{e:?}"))?;
                let mut logits = vec![0f32; logits_len(&cfg)];
                let mut v = Vec::new();
                for i in 0..args.warmup + args.runs {
                    let t0 = Instant::now();
                    window_logits(&model, &tokens, &music, &mut s, &mut logits).map_err(|e| anyhow!("{e:?}"))?;
                    if i >= args.warmup {
                        v.push(t0.elapsed());
                    }
                }
                Ok(v)
            })?;
            let st = stats(times);
            let vs_f32 = medians.record(d, t, st.median_ms, ort);
            r_step_json(j, d, t, &st);
            say!(
                "Bailando R step {d:>4} t{t} ({c}-token window): median {:8.1} ms  p99 {:8.1} ms  {:.2}x real time ({real_time_ms:.1} ms per token){vs_f32}",
                st.median_ms,
                st.p99_ms,
                real_time_ms / st.median_ms
            );
        }
        let schedules = [(SoloPreset::Reference, false), (SoloPreset::Reference, true), (SoloPreset::Interactive, false), (SoloPreset::Interactive, true), (SoloPreset::Minimum, false)];
        for (preset, spread) in schedules {
            let schedule = if spread { duolando_core::nn::window::CacheSchedule::Spread } else { duolando_core::nn::window::CacheSchedule::Reprefill };
            let mut sc = SoloConfig { kv: duolando_core::nn::kv_store::KvType::F16, schedule, ..SoloConfig::preset(&cfg, preset) };
            if let Some(sh) = args.shift {
                sc.shift = sh as u32;
            }
            let bytes = duolando_core::bailando::session::session_bytes_for(&cfg, &sc).map_err(|e| anyhow!("{e:?}"))?;
            // After start-up (the first full window, step c: a spread
            // schedule's one re-prefill of a whole window), as Duolando's
            // schedules: the steady state. At least four window jumps
            // (every c + 1 - shift steps), so p99 sees the re-prefills.
            let period = (c + 1 - sc.shift as usize).max(1);
            let steady = (c + 2).max(args.warmup);
            let n = args.s_steps.max(4 * period + 1);
            let times = on_threads(1, || solo_s_steps(&model, &sc, n, steady, &music[..nm]))?;
            let st = stats(times);
            let setting = format!("{}{}", preset.name(), if spread { "_spread" } else { "" });
            s_step_json(j, d, 1, &setting, &st, bytes);
            let gbps = step_bytes as f64 / (st.median_ms * 1e-3) / 1e9;
            j.insert(format!("s_step_gbps_{d}_t1_{setting}"), gbps.into());
            say!(
                "Bailando S step {d:>4} t1 {:<11} {:<9} (dec_future {:>2}, shift {}, f16 K/V), after start-up: median {:8.2} ms  p99 {:8.2} ms  p99/median {:.1}  mean {:8.2} ms  {:.0}x real time  arena {:.2} MB  median reads {gbps:.1} GB/s ({:.0}% of memcpy)",
                preset.name(),
                if spread { "spread" } else { "reprefill" },
                sc.dec_future,
                sc.shift,
                st.median_ms,
                st.p99_ms,
                st.p99_ms / st.median_ms,
                st.mean_ms,
                real_time_ms / st.median_ms,
                bytes as f64 / 1e6,
                100.0 * gbps / memcpy
            );
        }
    }
    if let Some(o) = ort {
        o.print_ratios("Bailando R step", &medians.ours);
        o.json(j, &medians.ours);
    }
    say!("Bailando: published config (actor_critic.yaml), seeded random weights; S step = one session step (GPT row or re-prefill at a window jump, heads, decoders), frames pulled; onnxruntime: --ort-json from tools/bailando_ort_r_step.py.");
    Ok(())
}

/// "Bailando" for "bailando".
fn family_title(family: &str) -> String {
    let mut c = family.chars();
    c.next().map(|f| f.to_uppercase().chain(c).collect()).unwrap_or_default()
}

/// A family's R step in the JSON: `r_step_ms_<dtype>_t<N>`,
/// `r_step_p99_ms_<dtype>_t<N>` (the duolando family's names).
fn r_step_json(j: &mut serde_json::Map<String, serde_json::Value>, dtype: &str, threads: usize, st: &Stats) {
    j.insert(format!("r_step_ms_{dtype}_t{threads}"), st.median_ms.into());
    j.insert(format!("r_step_p99_ms_{dtype}_t{threads}"), st.p99_ms.into());
}

/// A family's S step under a named setting in the JSON:
/// `s_step_{ms,p99_ms,mean_ms}_<dtype>_t<N>_<setting>` and
/// `arena_bytes_<dtype>_<setting>` (the duolando family's key shapes with
/// the setting appended: a preset, `_spread` where that schedule ran).
fn s_step_json(j: &mut serde_json::Map<String, serde_json::Value>, dtype: &str, threads: usize, setting: &str, st: &Stats, arena: usize) {
    j.insert(format!("s_step_ms_{dtype}_t{threads}_{setting}"), st.median_ms.into());
    j.insert(format!("s_step_p99_ms_{dtype}_t{threads}_{setting}"), st.p99_ms.into());
    j.insert(format!("s_step_mean_ms_{dtype}_t{threads}_{setting}"), st.mean_ms.into());
    j.insert(format!("arena_bytes_{dtype}_{setting}"), arena.into());
}

/// Times `n` steps of one Bailando session (after `warmup`), a music row
/// pushed before each and every frame pulled after.
fn solo_s_steps(model: &duolando_core::bailando::model::Model<'_>, sc: &duolando_core::bailando::session::SessionConfig, n: usize, warmup: usize, row: &[f32]) -> anyhow::Result<Vec<std::time::Duration>> {
    use duolando_core::bailando::session::Session as SoloSession;
    let mut arena = vec![0u8; model.session_bytes(sc).map_err(|e| anyhow!("{e:?}"))?];
    let mut s = SoloSession::new(model, &mut arena, sc, [0, 0]).map_err(|e| anyhow!("{e:?}"))?;
    s.push_music(row).map_err(|e| anyhow!("{e:?}"))?;
    let mut f = [0f32; duolando_core::bailando::config::POSE_DIM];
    let mut v = Vec::with_capacity(n);
    for i in 0..n + warmup {
        s.push_music(row).map_err(|e| anyhow!("{e:?}"))?;
        let t0 = Instant::now();
        let r = s.step().map_err(|e| anyhow!("{e:?}"))?;
        let dt = t0.elapsed();
        if r.is_none() {
            return Err(anyhow!("the session did not step at {i}"));
        }
        if i >= warmup {
            v.push(dt);
        }
        while s.pull(&mut f).map_err(|e| anyhow!("{e:?}"))?.is_some() {}
    }
    Ok(v)
}
