//! S goldens: a session fed the leader frame by frame must reproduce the
//! full-sequence Python reference of S (`tools/reference/streaming.py`,
//! `generate_streaming`; contract in tests/fixtures/README.md "S goldens"):
//! tokens (and forced-mode predictions) and leader codes identical, the
//! step and frame readiness identical, positions/rotations within 1e-4.

use duolando::model_file::ModelFile;
use duolando::npy::{read_f32_2d, read_i64_2d};
use duolando::streaming::run_streaming;
use duolando_core::model::Model;
// The GPT cache schedules: the same values under each.
use duolando_core::session::CacheSchedule as Schedule;
use duolando_core::session::{Sampling, SessionConfig};
use duolando_tests::{fixture, max_errors, Tol};
use serde_json::Value;

fn ints(dir: &std::path::Path, name: &str) -> Vec<i64> {
    read_i64_2d(&dir.join(name), None, name).unwrap().data
}

fn as_i64<T: Copy + Into<i64>>(v: &[T]) -> Vec<i64> {
    v.iter().map(|&x| x.into()).collect()
}

fn check(name: &str) {
    check_schedule(name, Schedule::Reprefill);
    check_schedule(name, Schedule::Staggered);
    check_schedule(name, Schedule::Spread);
}

/// The golden's model, inputs, config and seed.
fn setup(name: &str) -> (Value, std::path::PathBuf, std::path::PathBuf) {
    let dir = fixture(&format!("streaming_{name}"));
    let text = std::fs::read_to_string(dir.join("meta.json")).unwrap().replace("-Infinity", "null").replace("Infinity", "null");
    let meta: Value = serde_json::from_str(&text).unwrap();
    let inputs = dir.join(meta["inputs"].as_str().unwrap());
    (meta, dir, inputs)
}

/// An f16 K/V cache on every golden: tokens agreement and motion error
/// against the f32 golden (a measurement with a floor, not exactness:
/// random-weight decisions have margins down to 1e-3).
#[test]
fn f16_kv_cache_tracks_the_goldens() {
    let (mut agree, mut total, mut worst) = (0usize, 0usize, 0.0f32);
    for name in ["tiny_default", "tiny_long_low", "tiny_minimum", "tiny_mid_odd", "tiny2_default"] {
        let (meta, dir, inputs) = setup(name);
        let file = ModelFile::open(fixture(&format!("{}/model.duo", meta["model"].as_str().unwrap()))).unwrap();
        let duo = file.duo().unwrap();
        let model = Model::from_duo(&duo).unwrap();
        let leader = read_f32_2d(&inputs.join("leader_pos3d.npy"), Some(165), "leader").unwrap();
        let music = read_f32_2d(&inputs.join("music.npy"), None, "music").unwrap();
        let c = &meta["config"];
        let get = |k: &str| c[k].as_u64().unwrap() as u32;
        let mut cfg = SessionConfig::with(&model.cfg, get("lookahead"), get("enc_future"), get("dec_future"), get("shift"));
        let f32_bytes = model.session_bytes(&cfg).unwrap();
        cfg.kv = duolando_core::session::KvType::F16;
        let f16_bytes = model.session_bytes(&cfg).unwrap();
        assert!(f16_bytes < f32_bytes, "{name}: f16 K/V arena {f16_bytes} >= f32 {f32_bytes}");
        let seed: [u32; 5] = ints(&dir, "seed_tokens.npy").iter().map(|&t| t as u32).collect::<Vec<_>>().try_into().unwrap();
        let t4 = meta["T4"].as_u64().unwrap() as usize;
        let run = run_streaming(&model, &leader.data[..t4 * 165], &music.data, &cfg, seed, None, &mut |_, _| {}).unwrap();
        let want = ints(&dir, "tokens.npy");
        let got = as_i64(&run.tokens);
        let n = got.len().min(want.len());
        let same = got[..n].iter().zip(&want[..n]).filter(|(a, b)| a == b).count();
        let first = got.iter().zip(&want).position(|(a, b)| a != b);
        let pos = read_f32_2d(&dir.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
        let (err, _) = max_errors(&run.pos[..run.pos.len().min(pos.data.len())], &pos.data[..run.pos.len().min(pos.data.len())]);
        eprintln!("{name} f16 kv (arena {f16_bytes} vs {f32_bytes} bytes): {same}/{n} tokens equal (first difference at flat index {first:?}), max |pos err| {err:.2e} m");
        if first.is_none() {
            worst = worst.max(err);
        }
        agree += same;
        total += n;
    }
    let rate = agree as f64 / total as f64;
    eprintln!("f16 kv: token agreement {rate:.4} over {total} tokens; max |pos err| where tokens agree {worst:.2e} m");
    assert!(rate >= 0.9, "f16 K/V agreement {rate}");
    assert!(worst <= 1e-3, "f16 K/V motion error {worst}");
}

/// `schedule`: one cache re-prefilled at each window jump, one cache per
/// live window, or two caches with the next window filled ahead (same
/// values; spread: at most `1 + ceil((s - 1) / min(p, s - 1))` window rows
/// per step after start-up, `p = m + 1 - s`).
fn check_schedule(name: &str, schedule: Schedule) {
    let dir = fixture(&format!("streaming_{name}"));
    // The generator writes Python's `Infinity` for "no top-k decision": not JSON.
    let text = std::fs::read_to_string(dir.join("meta.json")).unwrap().replace("-Infinity", "null").replace("Infinity", "null");
    let meta: Value = serde_json::from_str(&text).unwrap();
    let file = ModelFile::open(fixture(&format!("{}/model.duo", meta["model"].as_str().unwrap()))).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let inputs = dir.join(meta["inputs"].as_str().unwrap());
    let leader = read_f32_2d(&inputs.join("leader_pos3d.npy"), Some(165), "leader").unwrap();
    let music = read_f32_2d(&inputs.join("music.npy"), None, "music").unwrap();
    let t4 = meta["T4"].as_u64().unwrap() as usize;
    let c = &meta["config"];
    let get = |k: &str| c[k].as_u64().unwrap() as u32;
    let mut cfg = SessionConfig::with(&model.cfg, get("lookahead"), get("enc_future"), get("dec_future"), get("shift"));
    cfg.music_lookahead = get("music_lookahead");
    cfg.schedule = schedule;
    if let Some(tk) = meta["sampling"].get("topk") {
        cfg.sampling = Sampling::TopK { k: tk.as_u64().unwrap() as u32, rng_seed: meta["sampling"]["rng_seed"].as_u64().unwrap() };
    }
    // The seed, in the contract's order of precedence.
    let forced: Option<Vec<u32>> = meta["forced_file"].as_str().map(|f| ints(&dir, f).iter().map(|&t| t as u32).collect());
    let seed: [u32; 5] = if let Some(f) = &forced {
        f[..5].try_into().unwrap()
    } else if dir.join("seed_tokens.npy").exists() {
        ints(&dir, "seed_tokens.npy").iter().map(|&t| t as u32).collect::<Vec<_>>().try_into().unwrap()
    } else if inputs.join("seed_tokens.npy").exists() {
        ints(&inputs, "seed_tokens.npy").iter().map(|&t| t as u32).collect::<Vec<_>>().try_into().unwrap()
    } else {
        let start = read_f32_2d(&inputs.join("follower_start.npy"), Some(165), "start").unwrap();
        let mut scratch = vec![0u8; duolando_core::exact::seed_scratch_bytes(&model.cfg, start.rows).unwrap()];
        duolando_core::exact::seed_tokens(&model, &start.data, &leader.data, &mut scratch).unwrap()
    };
    let run = run_streaming(&model, &leader.data[..t4 * 165], &music.data, &cfg, seed, forced.as_deref(), &mut |_, _| {}).unwrap();

    assert_eq!(run.latency_frames as u64, meta["latency_frames"].as_u64().unwrap(), "{name}: latency");
    assert_eq!(run.steps() as u64, meta["K"].as_u64().unwrap(), "{name}: steps");
    assert_eq!(as_i64(&run.tokens), ints(&dir, "tokens.npy"), "{name}: tokens");
    if dir.join("pred.npy").exists() {
        assert_eq!(as_i64(&run.pred), ints(&dir, "pred.npy"), "{name}: forced-mode predictions");
    }
    let want_codes = ints(&dir, "leader_tokens.npy");
    assert!(run.leader_codes.len() >= want_codes.len(), "{name}: {} leader codes, golden has {}", run.leader_codes.len() / 4, want_codes.len() / 4);
    assert_eq!(as_i64(&run.leader_codes[..want_codes.len()]), want_codes, "{name}: leader codes");
    let usz = |v: &[usize]| v.iter().map(|&x| x as i64).collect::<Vec<_>>();
    assert_eq!(usz(&run.step_ready), ints(&dir, "step_ready.npy"), "{name}: step readiness");
    assert_eq!(usz(&run.context), ints(&dir, "context.npy"), "{name}: window context");
    assert_eq!(usz(&run.window_lo), ints(&dir, "window_lo.npy"), "{name}: window start");
    assert_eq!(usz(&run.frame_ready), ints(&dir, "frame_ready.npy"), "{name}: frame readiness");
    let want_pos = read_f32_2d(&dir.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
    assert_eq!(run.frames_out(), want_pos.rows, "{name}: follower frames");
    let (pos_err, _) = max_errors(&run.pos, &want_pos.data);
    let tag = match schedule {
        Schedule::Reprefill => "",
        Schedule::Staggered => " (staggered)",
        Schedule::Spread => " (spread)",
    };
    let mut msg = format!("{name}{tag}: {} steps, {} frames, max |pos err| {pos_err:.2e} m", run.steps(), run.frames_out());
    assert!(pos_err <= Tol::MotionAbs.limit(), "{msg}");
    if dir.join("follower_rotmat.npy").exists() {
        let want_rot = read_f32_2d(&dir.join("follower_rotmat.npy"), Some(495), "rot").unwrap();
        let (rot_err, _) = max_errors(&run.rot, &want_rot.data);
        msg += &format!(", max |rot err| {rot_err:.2e}");
        assert!(rot_err <= Tol::MotionAbs.limit(), "{msg}");
    }
    let rows: usize = run.rows_computed.iter().sum();
    let m = model.cfg.gpt.block_size as usize - 1;
    let most = run.rows_computed.iter().skip(run.steps().min(m + 2)).max().copied().unwrap_or(0);
    eprintln!("{msg}; {:.2} GPT rows per step, at most {most} after start-up; arena {} bytes", rows as f64 / run.steps().max(1) as f64, run.arena_bytes);
    if schedule == Schedule::Spread && run.steps() > m + 2 {
        let s = cfg.shift as usize;
        let p = m + 1 - s;
        let bound = 1 + (s - 1).div_ceil(p.min(s - 1).max(1));
        assert!(most <= bound, "{name} (spread): {most} window rows in one step after start-up, bound {bound} (m {m}, s {s})");
    }
}

#[test]
fn tiny_default_budget() {
    check("tiny_default");
}

#[test]
fn tiny_long_run_low_latency() {
    check("tiny_long_low");
}

#[test]
fn tiny_forced_history() {
    check("tiny_forced");
}

#[test]
fn tiny_minimum_budget() {
    check("tiny_minimum");
}

#[test]
fn tiny_mid_budget_odd_length() {
    check("tiny_mid_odd");
}

#[test]
fn tiny_topk_seeded_from_frames() {
    check("tiny_topk");
}

#[test]
fn tiny2_default_budget() {
    check("tiny2_default");
}

#[test]
fn tiny2_sliding_window_topk() {
    check("tiny2_sliding");
}
