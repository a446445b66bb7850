//! S goldens: a session fed the leader frame by frame must reproduce the
//! full-sequence Python reference of S (`tools/reference/streaming.py`,
//! `generate_streaming`; contract in tests/fixtures/README.md "S goldens"):
//! tokens (and forced-mode predictions) and leader codes identical, the
//! step and frame readiness identical, positions/rotations within 1e-4.

use duolando::model_file::ModelFile;
use duolando::npy::{read_f32_2d, read_i64_2d};
use duolando::streaming::run_streaming;
use duolando_core::duolando::model::Model;
// The GPT cache schedules: the same values under each.
use duolando_core::duolando::session::CacheSchedule as Schedule;
use duolando_core::duolando::session::{Sampling, SessionConfig};
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
    let text = std::fs::read_to_string(dir.join("meta.json"))
        .unwrap()
        .replace("-Infinity", "null")
        .replace("Infinity", "null");
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
    for name in [
        "tiny_default",
        "tiny_long_low",
        "tiny_minimum",
        "tiny_mid_odd",
        "tiny2_default",
    ] {
        let (meta, dir, inputs) = setup(name);
        let file = ModelFile::open(fixture(&format!(
            "{}/model.duo",
            meta["model"].as_str().unwrap()
        )))
        .unwrap();
        let duo = file.duo().unwrap();
        let model = Model::from_duo(&duo).unwrap();
        let leader = read_f32_2d(&inputs.join("leader_pos3d.npy"), Some(165), "leader").unwrap();
        let music = read_f32_2d(&inputs.join("music.npy"), None, "music").unwrap();
        let c = &meta["config"];
        let get = |k: &str| c[k].as_u64().unwrap() as u32;
        let mut cfg = SessionConfig::with(
            &model.cfg,
            get("lookahead"),
            get("enc_future"),
            get("dec_future"),
            get("shift"),
        );
        let f32_bytes = model.session_bytes(&cfg).unwrap();
        cfg.kv = duolando_core::duolando::session::KvType::F16;
        let f16_bytes = model.session_bytes(&cfg).unwrap();
        assert!(
            f16_bytes < f32_bytes,
            "{name}: f16 K/V arena {f16_bytes} >= f32 {f32_bytes}"
        );
        let seed: [u32; 5] = ints(&dir, "seed_tokens.npy")
            .iter()
            .map(|&t| t as u32)
            .collect::<Vec<_>>()
            .try_into()
            .unwrap();
        let t4 = meta["T4"].as_u64().unwrap() as usize;
        let run = run_streaming(
            &model,
            &leader.data[..t4 * 165],
            &music.data,
            &cfg,
            seed,
            None,
            &mut |_, _| {},
        )
        .unwrap();
        let want = ints(&dir, "tokens.npy");
        let got = as_i64(&run.tokens);
        let n = got.len().min(want.len());
        let same = got[..n]
            .iter()
            .zip(&want[..n])
            .filter(|(a, b)| a == b)
            .count();
        let first = got.iter().zip(&want).position(|(a, b)| a != b);
        let pos = read_f32_2d(&dir.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
        let (err, _) = max_errors(
            &run.pos[..run.pos.len().min(pos.data.len())],
            &pos.data[..run.pos.len().min(pos.data.len())],
        );
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
    let text = std::fs::read_to_string(dir.join("meta.json"))
        .unwrap()
        .replace("-Infinity", "null")
        .replace("Infinity", "null");
    let meta: Value = serde_json::from_str(&text).unwrap();
    let file = ModelFile::open(fixture(&format!(
        "{}/model.duo",
        meta["model"].as_str().unwrap()
    )))
    .unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let inputs = dir.join(meta["inputs"].as_str().unwrap());
    let leader = read_f32_2d(&inputs.join("leader_pos3d.npy"), Some(165), "leader").unwrap();
    let music = read_f32_2d(&inputs.join("music.npy"), None, "music").unwrap();
    let t4 = meta["T4"].as_u64().unwrap() as usize;
    let c = &meta["config"];
    let get = |k: &str| c[k].as_u64().unwrap() as u32;
    let mut cfg = SessionConfig::with(
        &model.cfg,
        get("lookahead"),
        get("enc_future"),
        get("dec_future"),
        get("shift"),
    );
    cfg.music_lookahead = get("music_lookahead");
    cfg.schedule = schedule;
    if let Some(tk) = meta["sampling"].get("topk") {
        cfg.sampling = Sampling::TopK {
            k: tk.as_u64().unwrap() as u32,
            rng_seed: meta["sampling"]["rng_seed"].as_u64().unwrap(),
        };
    }
    // The seed, in the contract's order of precedence.
    let forced: Option<Vec<u32>> = meta["forced_file"]
        .as_str()
        .map(|f| ints(&dir, f).iter().map(|&t| t as u32).collect());
    let seed: [u32; 5] = if let Some(f) = &forced {
        f[..5].try_into().unwrap()
    } else if dir.join("seed_tokens.npy").exists() {
        ints(&dir, "seed_tokens.npy")
            .iter()
            .map(|&t| t as u32)
            .collect::<Vec<_>>()
            .try_into()
            .unwrap()
    } else if inputs.join("seed_tokens.npy").exists() {
        ints(&inputs, "seed_tokens.npy")
            .iter()
            .map(|&t| t as u32)
            .collect::<Vec<_>>()
            .try_into()
            .unwrap()
    } else {
        let start = read_f32_2d(&inputs.join("follower_start.npy"), Some(165), "start").unwrap();
        let mut scratch =
            vec![
                0u8;
                duolando_core::duolando::exact::seed_scratch_bytes(&model.cfg, start.rows).unwrap()
            ];
        duolando_core::duolando::exact::seed_tokens(&model, &start.data, &leader.data, &mut scratch)
            .unwrap()
    };
    let run = run_streaming(
        &model,
        &leader.data[..t4 * 165],
        &music.data,
        &cfg,
        seed,
        forced.as_deref(),
        &mut |_, _| {},
    )
    .unwrap();

    assert_eq!(
        run.latency_frames as u64,
        meta["latency_frames"].as_u64().unwrap(),
        "{name}: latency"
    );
    assert_eq!(
        run.steps() as u64,
        meta["K"].as_u64().unwrap(),
        "{name}: steps"
    );
    assert_eq!(
        as_i64(&run.tokens),
        ints(&dir, "tokens.npy"),
        "{name}: tokens"
    );
    if dir.join("pred.npy").exists() {
        assert_eq!(
            as_i64(&run.pred),
            ints(&dir, "pred.npy"),
            "{name}: forced-mode predictions"
        );
    }
    let want_codes = ints(&dir, "leader_tokens.npy");
    assert!(
        run.leader_codes.len() >= want_codes.len(),
        "{name}: {} leader codes, golden has {}",
        run.leader_codes.len() / 4,
        want_codes.len() / 4
    );
    assert_eq!(
        as_i64(&run.leader_codes[..want_codes.len()]),
        want_codes,
        "{name}: leader codes"
    );
    let usz = |v: &[usize]| v.iter().map(|&x| x as i64).collect::<Vec<_>>();
    assert_eq!(
        usz(&run.step_ready),
        ints(&dir, "step_ready.npy"),
        "{name}: step readiness"
    );
    assert_eq!(
        usz(&run.context),
        ints(&dir, "context.npy"),
        "{name}: window context"
    );
    assert_eq!(
        usz(&run.window_lo),
        ints(&dir, "window_lo.npy"),
        "{name}: window start"
    );
    assert_eq!(
        usz(&run.frame_ready),
        ints(&dir, "frame_ready.npy"),
        "{name}: frame readiness"
    );
    let want_pos = read_f32_2d(&dir.join("follower_pos3d.npy"), Some(165), "pos").unwrap();
    assert_eq!(run.frames_out(), want_pos.rows, "{name}: follower frames");
    let (pos_err, _) = max_errors(&run.pos, &want_pos.data);
    let tag = match schedule {
        Schedule::Reprefill => "",
        Schedule::Staggered => " (staggered)",
        Schedule::Spread => " (spread)",
    };
    let mut msg = format!(
        "{name}{tag}: {} steps, {} frames, max |pos err| {pos_err:.2e} m",
        run.steps(),
        run.frames_out()
    );
    assert!(pos_err <= Tol::MotionAbs.limit(), "{msg}");
    if dir.join("follower_rotmat.npy").exists() {
        let want_rot = read_f32_2d(&dir.join("follower_rotmat.npy"), Some(495), "rot").unwrap();
        let (rot_err, _) = max_errors(&run.rot, &want_rot.data);
        msg += &format!(", max |rot err| {rot_err:.2e}");
        assert!(rot_err <= Tol::MotionAbs.limit(), "{msg}");
    }
    let rows: usize = run.rows_computed.iter().sum();
    let m = model.cfg.gpt.block_size as usize - 1;
    let most = run
        .rows_computed
        .iter()
        .skip(run.steps().min(m + 2))
        .max()
        .copied()
        .unwrap_or(0);
    eprintln!(
        "{msg}; {:.2} GPT rows per step, at most {most} after start-up; arena {} bytes",
        rows as f64 / run.steps().max(1) as f64,
        run.arena_bytes
    );
    if schedule == Schedule::Spread && run.steps() > m + 2 {
        let s = cfg.shift as usize;
        let bound = duolando_core::nn::window::spread_rows(m, s);
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

// ---------------------------------------------------------------------------
// Drain (Session::finish): the end of the leader, checked against R
// (core's exact.rs, itself golden-tested: rollout_tiny_long).
// ---------------------------------------------------------------------------

struct Roll {
    leader: Vec<f32>,
    music: Vec<f32>,
    /// R's tokens (K + 1, 5), frames (4 (K + 1), 165) and (.., 495).
    tokens: Vec<u32>,
    pos: Vec<f32>,
    rot: Vec<f32>,
    seed: [u32; 5],
}

fn roll(name: &str) -> Roll {
    let dir = fixture(name);
    let leader = read_f32_2d(&dir.join("leader_pos3d.npy"), Some(165), "leader")
        .unwrap()
        .data;
    let music = read_f32_2d(&dir.join("music.npy"), None, "music")
        .unwrap()
        .data;
    let tokens: Vec<u32> = ints(&dir, "tokens.npy").iter().map(|&t| t as u32).collect();
    let pos = read_f32_2d(&dir.join("follower_pos3d.npy"), Some(165), "pos")
        .unwrap()
        .data;
    let rot = read_f32_2d(&dir.join("follower_rotmat.npy"), Some(495), "rot")
        .unwrap()
        .data;
    let seed = tokens[..5].try_into().unwrap();
    Roll {
        leader,
        music,
        tokens,
        pos,
        rot,
        seed,
    }
}

fn tiny_model() -> ModelFile {
    ModelFile::open(fixture("tiny/model.duo")).unwrap()
}

/// Fed R's own tokens (forced history) at e = e_max, d = d_max, a drained
/// session outputs R's frames: all 4 (K + 1) of them (K = 120 on
/// rollout_tiny_long), the last d tokens' frames from the whole token
/// sequence as R decodes them. Without the drain the last 21 steps and the
/// frames of the last 43 tokens never come. At a smaller decoder budget
/// (d = 5) the frames of the last 5 tokens still equal R's (decoded at the
/// end), the others are S's truncated-prefix frames.
#[test]
fn drained_session_fed_r_tokens_outputs_r_frames() {
    let file = tiny_model();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let r = roll("rollout_tiny_long");
    let k_r = r.tokens.len() / 5 - 1;
    assert_eq!(k_r, 120);
    let cfg = SessionConfig::reference(&model.cfg);
    let open = duolando::streaming::run_streaming_with(
        &model,
        &r.leader,
        &r.music,
        &cfg,
        r.seed,
        Some(&r.tokens),
        false,
        &mut |_, _| {},
    )
    .unwrap();
    let run = duolando::streaming::run_streaming_with(
        &model,
        &r.leader,
        &r.music,
        &cfg,
        r.seed,
        Some(&r.tokens),
        true,
        &mut |_, _| {},
    )
    .unwrap();
    eprintln!("reference budget, R's tokens: {} steps / {} frames without the drain, {} / {} drained, R {} / {}", open.steps(), open.frames_out(), run.steps(), run.frames_out(), k_r, r.pos.len() / 165);
    assert_eq!(open.steps(), k_r - 21);
    assert_eq!(open.frames_out(), 4 * (k_r + 1 - 43));
    assert_eq!(run.steps(), k_r);
    assert_eq!(run.frames_out(), 4 * (k_r + 1));
    assert_eq!(run.tokens, r.tokens);
    // The streamed part is unchanged by the drain.
    assert_eq!(&run.pos[..open.pos.len()], &open.pos[..]);
    let (pos_err, _) = max_errors(&run.pos, &r.pos);
    let (rot_err, _) = max_errors(&run.rot, &r.rot);
    eprintln!("  every frame vs R: max |pos err| {pos_err:.2e} m, max |rot err| {rot_err:.2e}");
    assert!(pos_err <= Tol::MotionAbs.limit() && rot_err <= Tol::MotionAbs.limit());

    let d = 5;
    let cfg = SessionConfig::with(&model.cfg, 5, 5, d, cfg.shift);
    let run = duolando::streaming::run_streaming_with(
        &model,
        &r.leader,
        &r.music,
        &cfg,
        r.seed,
        Some(&r.tokens),
        true,
        &mut |_, _| {},
    )
    .unwrap();
    assert_eq!((run.steps(), run.frames_out()), (k_r, 4 * (k_r + 1)));
    let tail = 4 * (k_r + 1 - d as usize) * 165;
    let (tail_err, _) = max_errors(&run.pos[tail..], &r.pos[tail..]);
    let (head_err, _) = max_errors(&run.pos[..tail], &r.pos[..tail]);
    eprintln!("  a = e = d = 5: the last {d} tokens' frames vs R max |pos err| {tail_err:.2e} m; the frames before them (truncated prefix) {head_err:.2e} m");
    assert!(tail_err <= Tol::MotionAbs.limit());
    assert!(
        head_err > 1e-3,
        "d = 5 < d_max should differ from R before the tail"
    );
}

/// Free-running (S's own tokens) on rollout_tiny_long: drained, every
/// budget whose music look-ahead is R's outputs R's frame count; the tail
/// agreement with R is printed (random weights: a measurement, not a bound).
#[test]
fn drained_free_running_sessions_output_r_frame_count() {
    let file = tiny_model();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let r = roll("rollout_tiny_long");
    let k_r = r.tokens.len() / 5 - 1;
    let m = &model.cfg;
    let s = SessionConfig::reference(m).shift;
    for (name, cfg) in [
        ("reference", SessionConfig::reference(m)),
        ("exact-window", SessionConfig::with(m, 29, 22, 22, 29)),
        ("mid", SessionConfig::with(m, 5, 5, 5, s)),
        ("minimum", SessionConfig::minimum(m)),
    ] {
        let open = run_streaming(
            &model,
            &r.leader,
            &r.music,
            &cfg,
            r.seed,
            None,
            &mut |_, _| {},
        )
        .unwrap();
        let run = duolando::streaming::run_streaming_with(
            &model,
            &r.leader,
            &r.music,
            &cfg,
            r.seed,
            None,
            true,
            &mut |_, _| {},
        )
        .unwrap();
        assert_eq!(
            (run.steps(), run.frames_out()),
            (k_r, 4 * (k_r + 1)),
            "{name}"
        );
        assert_eq!(&run.tokens[..open.tokens.len()], &open.tokens[..], "{name}");
        let drained = open.steps()..k_r;
        let same = drained
            .clone()
            .filter(|&k| run.tokens[(k + 1) * 5..(k + 2) * 5] == r.tokens[(k + 1) * 5..(k + 2) * 5])
            .count();
        let all = (0..k_r)
            .filter(|&k| run.tokens[(k + 1) * 5..(k + 2) * 5] == r.tokens[(k + 1) * 5..(k + 2) * 5])
            .count();
        let tail = open.frames_out() * 165;
        let mean = |a: &[f32], b: &[f32]| {
            a.chunks(3)
                .zip(b.chunks(3))
                .map(|(x, y)| {
                    ((x[0] - y[0]).powi(2) + (x[1] - y[1]).powi(2) + (x[2] - y[2]).powi(2)).sqrt()
                })
                .sum::<f32>()
                / (a.len() / 3).max(1) as f32
        };
        eprintln!(
            "{name}: {} -> {} frames (R {}), drained steps {} with {same} token rows equal to R's ({all}/{k_r} over all steps); mean joint distance to R {:.0} mm streamed, {:.0} mm drained tail",
            open.frames_out(),
            run.frames_out(),
            4 * (k_r + 1),
            drained.len(),
            1e3 * mean(&run.pos[..tail], &r.pos[..tail]),
            1e3 * mean(&run.pos[tail..], &r.pos[tail..]),
        );
    }
}

/// After `finish`, leader frames and a forced history are refused with
/// `Error::Ended` and change nothing; `finish` again does nothing; pulls
/// go on; `reset` starts a session that equals a fresh one.
#[test]
fn pushes_after_the_end_are_refused_and_reset_restarts() {
    use duolando_core::duolando::session::{FollowerFrame, Session};
    use duolando_core::error::Error;
    let file = tiny_model();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let r = roll("rollout_tiny_long");
    let cfg = SessionConfig::with(&model.cfg, 3, 2, 2, 22);
    let mut arena = vec![0u8; model.session_bytes(&cfg).unwrap()];
    let mut s = Session::new(&model, &mut arena, &cfg, r.seed).unwrap();
    // The music ends with the leader, as R reads it (a longer track lets
    // the stream run beyond R's K: those steps are kept, docs/STREAMING.md §2).
    s.set_music_track(&r.music[..300 * 54]).unwrap();
    let mut f = FollowerFrame::default();
    // Leader frames until the clip ends or the session refuses one for
    // backlog (the track's end stops the steps: the frames pile up).
    let drive = |s: &mut Session<'_>, out: &mut Vec<[f32; 165]>| {
        let mut f = FollowerFrame::default();
        let mut n = 0;
        while n < 300 {
            match s.push_leader_frame(&r.leader[n * 165..(n + 1) * 165]) {
                Err(Error::Backlog { .. }) => break,
                res => res.unwrap(),
            }
            n += 1;
            while s.pull_follower_frame(&mut f).unwrap() {
                out.push(f.positions);
            }
        }
        n
    };
    let mut got = Vec::new();
    let n = drive(&mut s, &mut got);
    assert!(!s.is_finished());
    s.finish().unwrap();
    assert!(s.is_finished());
    let steps = s.steps();
    assert_eq!(
        s.push_leader_frame(&r.leader[n * 165..(n + 1) * 165]),
        Err(Error::Ended { frames: n })
    );
    assert_eq!(s.force_history(&r.tokens), Err(Error::Ended { frames: n }));
    s.finish().unwrap();
    assert_eq!((s.steps(), s.frames_pushed()), (steps, n));
    while s.pull_follower_frame(&mut f).unwrap() {
        got.push(f.positions);
    }
    // 300 frames of music: R's K = (300 - 4) / 4 - 29 = 45 steps, 184 frames
    // (the stream ran all 45 steps; the drain decodes the last d tokens).
    eprintln!(
        "{n} leader frames pushed, {} frames after the drain",
        got.len()
    );
    assert_eq!((s.steps(), got.len()), (45, 184));
    s.reset(r.seed).unwrap();
    assert!(!s.is_finished());
    s.set_music_track(&r.music[..300 * 54]).unwrap();
    let mut again = Vec::new();
    assert_eq!(drive(&mut s, &mut again), n);
    s.finish().unwrap();
    while s.pull_follower_frame(&mut f).unwrap() {
        again.push(f.positions);
    }
    assert!(again == got, "a reset session drains differently");
}

/// Music pushed frame by frame exactly `music_lookahead` tokens ahead of
/// the leader (music frame f + 4 a_m in before leader frame f; in lockstep
/// for a_m = 0): every follower frame f is ready once leader frame
/// f + latency_frames is pushed, and some frame needs all of it (the
/// reported latency is exact). Before the live latency, the minimum budget
/// reported 0 frames and gave frames 3 late.
#[test]
fn live_music_frames_arrive_within_the_reported_latency() {
    use duolando_core::duolando::session::{FollowerFrame, Preset, Session};
    let file = tiny_model();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let r = roll("rollout_tiny_long");
    let m = &model.cfg;
    let n_music = 54;
    let mut cases: Vec<(String, SessionConfig)> = Preset::ALL
        .iter()
        .map(|&p| (p.name().to_string(), SessionConfig::preset(m, p)))
        .collect();
    cases.push((
        "a0 e0 d2 a_m 3".into(),
        SessionConfig {
            music_lookahead: 3,
            ..SessionConfig::with(m, 0, 0, 2, 22)
        },
    ));
    cases.push((
        "a1 e0 d0 a_m 0".into(),
        SessionConfig {
            music_lookahead: 0,
            ..SessionConfig::with(m, 1, 0, 0, 22)
        },
    ));
    for (name, cfg) in cases {
        let lead = 4 * cfg.music_lookahead as usize;
        let mut arena = vec![0u8; model.session_bytes(&cfg).unwrap()];
        let mut s = Session::new(&model, &mut arena, &cfg, r.seed).unwrap();
        let lat = s.latency_frames() as usize;
        assert_eq!(lat as u32, cfg.live_latency_frames(4));
        let (mut pushed, mut worst, mut n) = (0usize, 0usize, 0usize);
        let mut f = FollowerFrame::default();
        for x in 0..600 {
            while pushed <= (x + lead).min(599) {
                s.push_music_frame(&r.music[pushed * n_music..(pushed + 1) * n_music])
                    .unwrap();
                pushed += 1;
            }
            match s.push_leader_frame(&r.leader[x * 165..(x + 1) * 165]) {
                // The music ends with the clip: the last steps wait for it.
                Err(duolando_core::error::Error::Backlog { .. }) => break,
                res => res.unwrap(),
            }
            while s.pull_follower_frame(&mut f).unwrap() {
                let late = x - f.index as usize;
                assert!(
                    late <= lat,
                    "{name}: frame {} ready at leader frame {x}, {late} > latency {lat}",
                    f.index
                );
                worst = worst.max(late);
                n += 1;
            }
        }
        eprintln!("{name}: a_m {} latency {lat} frames (with a track {}), worst delay {worst} over {n} frames", cfg.music_lookahead, cfg.latency_frames(4));
        assert_eq!(worst, lat, "{name}: the reported latency is not tight");
        assert!(n >= 300, "{name}: {n} frames");
    }
}

/// `music_buffer_frames` is the number of music frames a session holds:
/// a fresh session configured with 440 takes 440 frames, not 444, and
/// the refusal names 440 of 440; once steps read music, pushes are taken
/// again, never more than 440 beyond those read.
#[test]
fn music_buffer_holds_the_configured_number() {
    use duolando_core::duolando::session::Session;
    use duolando_core::error::{Buffer, Error};
    let file = tiny_model();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let r = roll("rollout_tiny_long");
    let cfg = SessionConfig::minimum(&model.cfg);
    assert_eq!(cfg.music_buffer_frames, 440);
    let mut arena = vec![0u8; model.session_bytes(&cfg).unwrap()];
    let mut s = Session::new(&model, &mut arena, &cfg, r.seed).unwrap();
    let frame = |i: usize| &r.music[i * 54..(i + 1) * 54];
    let mut pushed = 0;
    while s.push_music_frame(frame(pushed)).is_ok() {
        pushed += 1;
    }
    assert_eq!(pushed, 440);
    assert_eq!(
        s.push_music_frame(frame(pushed)),
        Err(Error::Backlog {
            buffer: Buffer::Music,
            held: 440,
            capacity: 440
        })
    );
    // Steps read music: minimum budget, step k reads music frames < 4 (k + 31).
    for i in 0..20 {
        s.push_leader_frame(&r.leader[i * 165..(i + 1) * 165])
            .unwrap();
    }
    let k = s.steps();
    assert_eq!(k, 5);
    // Steps 0..k-1 ran; the music LAT has read what step k - 1's row needs,
    // music frames < 4 (k + 1 + a_m) (it reads for step k only once step
    // k's leader row exists).
    let read = 4 * (k + 1 + 29);
    let mut more = 0;
    while s.push_music_frame(frame(pushed)).is_ok() {
        pushed += 1;
        more += 1;
    }
    eprintln!(
        "music buffer 440: {pushed} frames taken, {read} read by the music LAT after {k} steps"
    );
    assert_eq!(pushed, read + 440, "{more} more frames after {k} steps");
}
