//! `duolando inspect model.duo [--frames N] [--json]`: what a `.duo` model
//! holds and what running it costs — the whole config, parameter count,
//! file size, dtypes, tensor count, R-mode scratch for one minute of input,
//! output frames for `--frames` input frames, and the latency and session
//! arena of streaming budgets.
//!
//! Reads only the header and tensor table (the file is validated as a whole
//! by [`ModelFile::open`]) and binds the model (no weight is read).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, Result};
use duolando_core::bailando::config::BailandoConfig;
use duolando_core::duolando::config::{LatConfig, ModelConfig};
use duolando_core::family::FamilyConfig;
use duolando_core::nn::vq_config::VqConfig;
use duolando_core::duolando::exact;
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::{dec_future_max, enc_future_max, CacheSchedule, Preset, SessionConfig};
use duolando_core::tensor::DType;
use duolando_core::transflower::config::TransflowerConfig;
use serde_json::{json, Value};

use crate::model_file::ModelFile;

/// Frames per second of the model's motion and music.
const FPS: usize = 30;
/// Input frames of "one minute" for the scratch estimate.
const ONE_MINUTE: usize = 60 * FPS;

/// Flags of `duolando inspect`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The `.duo` model.
    pub model: PathBuf,
    /// Input frames (30 fps) to size the R-mode run for.
    #[arg(long, default_value_t = ONE_MINUTE)]
    pub frames: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Stable lower-case name of a dtype.
fn dtype_name(d: DType) -> &'static str {
    match d {
        DType::F32 => "f32",
        DType::F16 => "f16",
        DType::Q8Block32 => "q8_block32",
        DType::Q8Block32x8 => "q8_block32x8",
        DType::Q4Block32x8 => "q4_block32x8",
        DType::Q4Block32 => "q4_block32",
    }
}

/// Tensor counts, parameters and payload bytes per dtype.
#[derive(Default, Clone, Copy)]
struct DtypeStats {
    tensors: usize,
    params: u64,
    bytes: u64,
}

/// Everything `inspect` reports, as one JSON value (the text output is
/// printed from the same value, so the two cannot disagree).
pub fn report(model: &std::path::Path, frames: usize) -> Result<Value> {
    let file_size = std::fs::metadata(model).with_context(|| format!("cannot read {}", model.display()))?.len();
    let file = ModelFile::open(model)?;
    let duo = file.duo()?;
    let mut per: BTreeMap<&'static str, DtypeStats> = BTreeMap::new();
    let mut params: u64 = 0;
    for e in duo.tensors() {
        let n: u64 = e.dims().iter().map(|&d| d as u64).product();
        let s = per.entry(dtype_name(e.dtype)).or_default();
        s.tensors += 1;
        s.params += n;
        s.bytes += e.nbytes;
        params += n;
    }
    let dtypes: serde_json::Map<String, Value> = per
        .iter()
        .map(|(k, s)| (k.to_string(), json!({ "tensors": s.tensors, "params": s.params, "bytes": s.bytes })))
        .collect();
    let prefix = duo.prefix();
    let common = json!({
        "model": model.display().to_string(),
        "family": duo.config().family().name(),
        "format_version": prefix.version,
        "file_bytes": file_size,
        "data_start": prefix.data_start,
        "tensors": duo.len(),
        "params": params,
        "dtypes": dtypes,
    });
    let specific = match duo.config() {
        FamilyConfig::Duolando(cfg) => duolando_report(&duo, cfg, frames)?,
        FamilyConfig::Bailando(cfg) => bailando_report(cfg, frames),
        FamilyConfig::Transflower(cfg) => transflower_report(&duo, cfg, frames)?,
    };
    let mut all = common;
    if let (Some(a), Value::Object(b)) = (all.as_object_mut(), specific) {
        a.extend(b);
    }
    Ok(all)
}

/// Bailando: config, frame and token rates, R mode's sizes for `rows`
/// music rows (7.5 per second) on the demo path; S mode's latency and
/// session arena per preset.
fn bailando_report(cfg: &BailandoConfig, rows: usize) -> Value {
    use duolando_core::bailando::exact;
    let run = |r: usize| -> Value {
        let k = exact::steps(exact::MusicPadding::Demo, r.max(1));
        json!({
            "music_rows": r,
            "steps": k,
            "token_rows": k + 1,
            "output_frames": (k + 1) * cfg.hop(),
            "scratch_bytes": exact::sample_scratch_bytes(cfg).zip(exact::decode_scratch_bytes(cfg, k + 1)).map(|(a, b)| a.max(b)),
        })
    };
    json!({
        "config": cfg,
        "derived": {
            "fps": duolando_core::bailando::config::FPS,
            "joints": duolando_core::bailando::config::N_JOINTS,
            "frames_per_token": cfg.hop(),
            "music_features": cfg.gpt.n_music,
            "window_tokens": cfg.gpt.block_size - 1,
        },
        "r_mode": {
            "one_minute": run(BAILANDO_MUSIC_ROWS_PER_MINUTE),
            "requested": run(rows),
            "latency": "R mode is offline: it needs the whole music before the first output frame",
        },
        "streaming": solo_streaming(cfg),
    })
}

/// Each solo preset's settings, latency and session arena (f32 and f16 K/V,
/// one cache and spread).
fn solo_streaming(cfg: &BailandoConfig) -> Value {
    use duolando_core::bailando::session::{dec_future_max, session_bytes_for, CacheSchedule, Preset, SessionConfig};
    use duolando_core::nn::kv_store::KvType;
    let presets: Vec<Value> = Preset::ALL
        .iter()
        .map(|&p| {
            let sc = SessionConfig::preset(cfg, p);
            let bytes = |kv, schedule| session_bytes_for(cfg, &SessionConfig { kv, schedule, ..sc }).ok();
            json!({
                "preset": p.name(),
                "dec_future": sc.dec_future,
                "shift": sc.shift,
                "latency_frames": sc.latency_frames(cfg.hop() as u32),
                "arena_bytes_f32kv": bytes(KvType::F32, CacheSchedule::Reprefill),
                "arena_bytes_f16kv": bytes(KvType::F16, CacheSchedule::Reprefill),
                "arena_bytes_f16kv_spread": bytes(KvType::F16, CacheSchedule::Spread),
            })
        })
        .collect();
    json!({ "dec_future_max": dec_future_max(cfg), "presets": presets })
}

/// Transflower: config (in the authors' option names), inputs, the flow,
/// R mode's sizes for `rows` rows of the last input (the audio, 20 per
/// second). S mode is not built yet.
fn transflower_report(duo: &duolando_core::format::DuoFile<'_>, cfg: &TransflowerConfig, rows: usize) -> Result<Value> {
    use duolando_core::transflower::config::{BaseDist, NormLayer, FPS};
    use duolando_core::transflower::exact::generate_scratch_bytes;
    duolando_core::transflower::model::Model::from_duo(duo).map_err(|e| anyhow::anyhow!("{}", crate::engine_errors::describe_transflower_model(&e)))?;
    let fps = FPS as usize;
    let max_l = cfg.max_window();
    let out = cfg.output as usize;
    let inputs: Vec<Value> = cfg
        .inputs()
        .iter()
        .enumerate()
        .map(|(i, c)| {
            json!({
                "name": c.name.as_str(),
                "kind": if c.is_discrete() { "label" } else if i == out { "motion (output, fed back)" } else { "features" },
                "dim": c.dim,
                "window_rows": c.length,
                "labels": if c.is_discrete() { json!(c.tokens) } else { Value::Null },
                "pos_emb_score_bias": cfg.input_has_bias(i),
            })
        })
        .collect();
    let f = &cfg.flow;
    let scratch = generate_scratch_bytes(cfg);
    let run = |r: usize| -> Value {
        let n = (r + 1).saturating_sub(max_l);
        json!({ "last_input_rows": r, "steps": n, "output_frames": n, "scratch_bytes": scratch })
    };
    Ok(json!({
        "config": {
            "input_modalities": inputs,
            "output_modality": cfg.output_input().name.as_str(),
            "douts": cfg.channels(),
            "output_lengths": cfg.output_length,
            "output_time_offsets": cfg.output_time_offset,
            "conditioning_seq_lens": cfg.cond_len,
            "dhid": cfg.dhid,
            "nhead": cfg.nhead,
            "nlayers": cfg.nlayers,
            "use_rel_pos_emb_inputs": cfg.rel_pos_emb_inputs,
            "use_pos_emb_output": cfg.pos_emb_output,
            "flow": {
                "steps": f.steps,
                "glow_norm_layer": match f.norm { NormLayer::None => "none", NormLayer::BatchNorm => "batchnorm", NormLayer::ActNorm => "actnorm" },
                "dhid_flow": f.dhid,
                "num_heads_flow": f.heads,
                "num_glow_coupling_blocks": f.layers,
                "cond_concat_dims": f.concat_dims,
                "use_pos_emb_coupling": f.pos_emb,
                "flow_dist": match f.base { BaseDist::Normal => json!("normal"), BaseDist::StudentT { df } => json!({ "studentT": { "df": df } }) },
            },
        },
        "derived": {
            "fps": fps,
            "latent_rows": cfg.latent_rows(),
            "longest_window_rows": max_l,
            "coupling_rows": cfg.coupling_rows(),
            "coupling_in": cfg.coupling_in(),
            "change_channels": cfg.change_channels(),
        },
        "r_mode": {
            "one_minute": run(60 * fps),
            "requested": run(rows),
            "latency": format!(
                "the first output frame needs {max_l} rows of the last input ({:.2} s at {fps} fps) and the motion seed's {} rows; then one frame per row",
                max_l as f64 / fps as f64,
                cfg.output_input().length
            ),
        },
        "streaming": {
            "lookahead_rows": duolando_core::transflower::session::lookahead_rows(cfg),
            "presets": duolando_core::transflower::session::Preset::ALL.iter().map(|&p| {
                let sc = duolando_core::transflower::session::SessionConfig::preset(p);
                json!({
                    "name": p.name(),
                    "refresh": sc.refresh,
                    "kv": format!("{:?}", sc.kv).to_lowercase(),
                    "rolling": sc.rolling,
                    "arena_bytes": duolando_core::transflower::session::session_bytes(cfg, &sc).ok(),
                })
            }).collect::<Vec<_>>(),
        },
    }))
}

fn transflower_text(r: &Value) -> String {
    let mut s = head_text(r);
    let mut line = |l: String| {
        s.push_str(&l);
        s.push('\n');
    };
    let c = &r["config"];
    let f = &c["flow"];
    line("config (Transflower)".into());
    for i in c["input_modalities"].as_array().into_iter().flatten() {
        line(format!(
            "  input {:<28} {:<26} dim {} window {} rows{}{}",
            i["name"].as_str().unwrap_or(""),
            i["kind"].as_str().unwrap_or(""),
            i["dim"],
            i["window_rows"],
            if i["labels"].is_null() { String::new() } else { format!(", {} labels", i["labels"]) },
            if i["pos_emb_score_bias"] == true { ", pos_emb score bias" } else { "" }
        ));
    }
    line(format!(
        "  output {} ({} channels), {} frames per flow sample (row 0 kept), offset {}, cond rows {}",
        c["output_modality"].as_str().unwrap_or(""),
        c["douts"],
        c["output_lengths"],
        c["output_time_offsets"],
        c["conditioning_seq_lens"]
    ));
    line(format!("  transformers dhid {} heads {} cross-modal layers {} (inputs 2), post-LN, FFN = dhid", c["dhid"], c["nhead"], c["nlayers"]));
    line(format!(
        "  flow {} steps, norm {}, couplings {} layers x {} wide, {} heads, cond_concat_dims {}, base {}",
        f["steps"],
        f["glow_norm_layer"].as_str().unwrap_or(""),
        f["num_glow_coupling_blocks"],
        f["dhid_flow"],
        f["num_heads_flow"],
        f["cond_concat_dims"],
        f["flow_dist"]
    ));
    line(format!("R mode (exact, {} fps)", r["derived"]["fps"]));
    for (label, key) in [("1 min", "one_minute"), ("--frames (last input rows)", "requested")] {
        let x = &r["r_mode"][key];
        line(format!(
            "  {label}: {} rows -> {} frames; scratch {}",
            x["last_input_rows"],
            x["output_frames"],
            x["scratch_bytes"].as_u64().map(mib).unwrap_or_else(|| "overflow".into())
        ));
    }
    line(format!("  latency: {}", r["r_mode"]["latency"].as_str().unwrap_or("")));
    let st = &r["streaming"];
    line(format!(
        "streaming (S): frame t (song row offset + t) is made once the last input has row t + {} ({} rows after the frame's own row)",
        r["derived"]["longest_window_rows"].as_u64().unwrap_or(0).saturating_sub(1),
        st["lookahead_rows"]
    ));
    for p in st["presets"].as_array().into_iter().flatten() {
        line(format!(
            "  {:<10} refresh {:>3}{} ({} kept keys/values): arena {}",
            p["name"].as_str().unwrap_or(""),
            p["refresh"].as_u64().unwrap_or(0),
            if p["rolling"] == true { " rolling" } else { "" },
            p["kv"].as_str().unwrap_or(""),
            p["arena_bytes"].as_u64().map(mib).unwrap_or_else(|| "overflow".into())
        ));
    }
    s
}

/// Music rows of one minute at Bailando's 7.5 rows per second.
const BAILANDO_MUSIC_ROWS_PER_MINUTE: usize = 450;

fn bailando_text(r: &Value, cfg: &BailandoConfig) -> String {
    let g = &cfg.gpt;
    let mut s = head_text(r);
    let mut line = |l: String| {
        s.push_str(&l);
        s.push('\n');
    };
    line("config (Bailando)".into());
    line(format!(
        "  gpt n_embd {} heads {} base {} head {} block_size {} vocab up/down {:?} n_music {}",
        g.n_embd, g.n_head, g.n_layer_base, g.n_layer_head, g.block_size, g.vocab, g.n_music
    ));
    for (name, v) in ["up", "down"].iter().zip(&cfg.parts) {
        line(vq_line(name, v));
    }
    line(format!("  {} frames per token at 60 fps, SMPL 24 joints", cfg.hop()));
    line("R mode (exact, demo path)".into());
    for (label, key) in [("1 min", "one_minute"), ("--frames (music rows)", "requested")] {
        let x = &r["r_mode"][key];
        line(format!(
            "  {label}: {} music rows -> {} steps, {} output frames; scratch {}",
            x["music_rows"],
            x["steps"],
            x["output_frames"],
            x["scratch_bytes"].as_u64().map(mib).unwrap_or_else(|| "overflow".into())
        ));
    }
    let st = &r["streaming"];
    line(format!("streaming (S): latency = 8 x dec_future frames; dec_future_max {}", st["dec_future_max"]));
    for p in st["presets"].as_array().into_iter().flatten() {
        let b = |k: &str| p[k].as_u64().map(mib).unwrap_or_else(|| "-".into());
        line(format!(
            "  {:<11} dec_future {:>2} shift {:>2}: latency {:>3} frames; arena {} (f32 K/V, --reprefill), {} (f16, --reprefill), {} (f16, spread: the preset's schedule)",
            p["preset"].as_str().unwrap_or("?"),
            p["dec_future"],
            p["shift"],
            p["latency_frames"],
            b("arena_bytes_f32kv"),
            b("arena_bytes_f16kv"),
            b("arena_bytes_f16kv_spread")
        ));
    }
    s
}

fn duolando_report(duo: &duolando_core::format::DuoFile<'_>, cfg: &ModelConfig, frames: usize) -> Result<Value> {
    let cfg = *cfg;
    let run = |t: usize| -> Value {
        match exact::output_shape(&cfg, t) {
            Some(sh) => json!({
                "input_frames": t,
                "frames_used": sh.frames_in,
                "steps": sh.steps,
                "token_rows": sh.token_rows,
                "output_frames": sh.frames_out,
                "scratch_bytes": exact::scratch_bytes(&cfg, t),
            }),
            None => json!({ "input_frames": t, "error": format!("fewer than {} frames (one token)", cfg.hop()) }),
        }
    };
    Ok(json!({
        "config": cfg,
        "derived": {
            "fps": FPS,
            "frames_per_token": cfg.hop(),
            "min_frames_for_one_step": min_frames(&cfg),
        },
        "r_mode": {
            "one_minute": run(ONE_MINUTE),
            "requested": run(frames),
            "latency": "R mode is offline: it needs the whole leader clip and music before the first output frame",
        },
        "streaming": streaming(duo)?,
    }))
}

/// Latency and session arena per streaming budget (docs/STREAMING.md §2):
/// every preset of the one list (`Preset::ALL`, what `--preset` takes).
fn streaming(duo: &duolando_core::format::DuoFile<'_>) -> Result<Value> {
    let model = Model::from_duo(duo).map_err(|e| anyhow::anyhow!("{}", crate::engine_errors::describe_bind(&e)))?;
    let cfg = &model.cfg;
    let hop = cfg.hop() as u32;
    let budgets: Vec<Value> = Preset::ALL
        .iter()
        .map(|&p| {
            let sc = SessionConfig::preset(cfg, p);
            let lat = sc.latency_frames(hop);
            json!({
                "budget": p.name(),
                "lookahead": sc.lookahead,
                "enc_future": sc.enc_future,
                "dec_future": sc.dec_future,
                "shift": sc.shift,
                "music_lookahead": sc.music_lookahead,
                "latency_frames": lat,
                "latency_seconds": lat as f64 / FPS as f64,
                "live_latency_frames": sc.live_latency_frames(hop),
                "arena_bytes": model.session_bytes(&sc).ok(),
                // The same budget with one GPT cache (`--reprefill`): the least memory.
                "arena_bytes_reprefill": model.session_bytes(&SessionConfig { schedule: CacheSchedule::Reprefill, ..sc }).ok(),
                // That one bound to a step batch (its state alone: `Session::new_batched`,
                // C `duo_session_new_batched`).
                "arena_bytes_reprefill_bound": model.batched_session_bytes(&SessionConfig { schedule: CacheSchedule::Reprefill, ..sc }).ok(),
                // GPT window rows a spread step computes after start-up (its own
                // and its share of the next window's): what a larger shift costs.
                "gpt_rows_per_step": duolando_core::nn::window::spread_rows(cfg.gpt.block_size as usize - 1, sc.shift as usize),
            })
        })
        .collect();
    Ok(json!({
        "enc_future_max": enc_future_max(cfg),
        "dec_future_max": dec_future_max(cfg),
        "latency": "hop * (lookahead + enc_future + dec_future) - 1 frames (at least 0) with a music track; with music pushed live music_lookahead tokens ahead, at least hop * (dec_future + 1) - 1",
        "budgets": budgets,
    }))
}

/// Smallest input that gives at least one generation step.
fn min_frames(cfg: &ModelConfig) -> usize {
    let ds = cfg.gpt.music.downsample_rate as usize;
    cfg.music_motion_rate as usize + ds * (cfg.gpt.look_forward as usize + 1)
}

fn mib(b: u64) -> String {
    format!("{:.2} MiB", b as f64 / (1024.0 * 1024.0))
}

fn vq_line(name: &str, v: &VqConfig) -> String {
    format!(
        "  vq {name:<6} in {} rot {} width {} depth {} growth {} down {}x stride {} emb {} bins {} m_conv {}/{}",
        v.in_channels,
        v.rot_channels,
        v.width,
        v.depth,
        v.dilation_growth_rate,
        v.down_t,
        v.stride_t,
        v.emb_width,
        v.l_bins,
        v.m_conv_num,
        v.m_conv_den
    )
}

fn lat_line(name: &str, l: &LatConfig) -> String {
    format!("  lat {name:<6} n_in {} layers {} heads {} downsample {}", l.n_in, l.n_layer, l.n_head, l.downsample_rate)
}

fn run_lines(r: &Value) -> String {
    match r.get("error") {
        Some(e) => format!("{} input frames: {}", r["input_frames"], e.as_str().unwrap_or("")),
        None => format!(
            "{} input frames -> {} used, {} steps, {} token rows, {} output frames; scratch {}",
            r["input_frames"],
            r["frames_used"],
            r["steps"],
            r["token_rows"],
            r["output_frames"],
            r["scratch_bytes"].as_u64().map(mib).unwrap_or_else(|| "overflow".into())
        ),
    }
}

/// The lines every family's text starts with: file, format, dtypes.
fn head_text(r: &Value) -> String {
    let mut s = String::new();
    let mut line = |l: String| {
        s.push_str(&l);
        s.push('\n');
    };
    line(r["model"].as_str().unwrap_or("").to_string());
    line(format!(
        "  {} model, file {} ({} bytes), format v{}, {} tensors, {} parameters",
        r["family"].as_str().unwrap_or("?"),
        mib(r["file_bytes"].as_u64().unwrap_or(0)),
        r["file_bytes"],
        r["format_version"],
        r["tensors"],
        r["params"]
    ));
    if let Some(d) = r["dtypes"].as_object() {
        for (k, v) in d {
            line(format!(
                "  dtype {k:<10} {} tensors, {} params, {}",
                v["tensors"],
                v["params"],
                mib(v["bytes"].as_u64().unwrap_or(0))
            ));
        }
    }
    s
}

/// The human-readable form of [`report`] for a Duolando model.
fn text(r: &Value, cfg: &ModelConfig) -> String {
    let g = &cfg.gpt;
    let mut s = head_text(r);
    let mut line = |l: String| {
        s.push_str(&l);
        s.push('\n');
    };
    line("config".into());
    line(format!(
        "  gpt n_embd {} heads {} base {} head {} block_size {} look_forward {} streams {} final_ln {}",
        g.n_embd, g.n_head, g.n_layer_base, g.n_layer_head, g.block_size, g.look_forward, g.n_streams, g.final_ln
    ));
    line(format!("  vocab up/down/lhand/rhand/transl {:?}", g.vocab));
    line(lat_line("music", &g.music));
    line(lat_line("leader", &g.leader));
    for (name, v) in ["up", "down", "lhand", "rhand"].iter().zip(&cfg.parts) {
        line(vq_line(name, v));
    }
    line(vq_line("transl", &cfg.transl));
    line(format!(
        "  music_motion_rate {}, {} frames per token, >= {} input frames for one step",
        cfg.music_motion_rate,
        cfg.hop(),
        min_frames(cfg)
    ));
    line("R mode (exact)".into());
    line(format!("  1 min: {}", run_lines(&r["r_mode"]["one_minute"])));
    line(format!("  --frames: {}", run_lines(&r["r_mode"]["requested"])));
    line(format!("  latency: {}", r["r_mode"]["latency"].as_str().unwrap_or("")));
    let st = &r["streaming"];
    line(format!(
        "streaming (S): latency = {}; enc_future_max {}, dec_future_max {}",
        st["latency"].as_str().unwrap_or(""),
        st["enc_future_max"],
        st["dec_future_max"]
    ));
    for b in st["budgets"].as_array().into_iter().flatten() {
        line(format!(
            "  {:<12} a {} e {} d {} shift {}: latency {} frames ({:.2} s), session arena {} ({} with --reprefill, {} bound to a step batch); music look-ahead {}, latency with music pushed live {} frames; {} GPT window rows a step",
            b["budget"].as_str().unwrap_or(""),
            b["lookahead"],
            b["enc_future"],
            b["dec_future"],
            b["shift"],
            b["latency_frames"],
            b["latency_seconds"].as_f64().unwrap_or(0.0),
            b["arena_bytes"].as_u64().map(mib).unwrap_or_else(|| "?".into()),
            b["arena_bytes_reprefill"].as_u64().map(mib).unwrap_or_else(|| "?".into()),
            b["arena_bytes_reprefill_bound"].as_u64().map(mib).unwrap_or_else(|| "?".into()),
            b["music_lookahead"],
            b["live_latency_frames"],
            b["gpt_rows_per_step"]
        ));
    }
    s
}

pub fn run(args: Args) -> Result<()> {
    let r = report(&args.model, args.frames)?;
    super::print_kernels();
    let out = if args.json {
        serde_json::to_string_pretty(&r)? + "\n"
    } else {
        if r["family"] == "Transflower" {
            transflower_text(&r)
        } else if r["family"] == "Bailando" {
            let cfg: BailandoConfig = serde_json::from_value(r["config"].clone()).context("internal: config round trip")?;
            bailando_text(&r, &cfg)
        } else {
            let cfg: ModelConfig = serde_json::from_value(r["config"].clone()).context("internal: config round trip")?;
            text(&r, &cfg)
        }
    };
    print_stdout(&out)
}

/// Writes to stdout; a closed pipe (`| head`) is not an error.
pub(crate) fn print_stdout(s: &str) -> Result<()> {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    match o.write_all(s.as_bytes()).and_then(|_| o.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e).context("cannot write to stdout"),
        _ => Ok(()),
    }
}
