//! `Session::step_many`: sessions stepped together (LATs, GPT and heads
//! batched, each weight matrix read once for all) end bit for bit where
//! their own `push_leader_frame` calls would take them; refusals name the
//! session and change none. Every test runs the kernels this CPU selects
//! (`duolando::simd::init`: on an AMX machine the batch's GEMMs of 16 and
//! more rows take the tile kernel while one session's take AVX512-VNNI, so
//! the bit-identity covers that switch too).

use duolando::duo_writer::StoreAs;
use duolando::model_file::ModelFile;
use duolando::npy::read_f32_2d;
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::{
    CacheSchedule, FollowerFrame, KvType, Sampling, Session, SessionConfig, Setting, StepBatch,
    StepReport,
};
use duolando_core::error::{Buffer, Error};
use duolando_tests::fixture;

fn convert(model: &str, store_as: StoreAs) -> ModelFile {
    duolando_tests::convert_fixture(model, store_as)
}

struct Clip {
    leader: Vec<f32>,
    music: Vec<f32>,
}

fn clip(rollout: &str) -> Clip {
    let d = fixture(rollout);
    Clip {
        leader: read_f32_2d(&d.join("leader_pos3d.npy"), Some(165), "leader")
            .unwrap()
            .data,
        music: read_f32_2d(&d.join("music.npy"), None, "music")
            .unwrap()
            .data,
    }
}

/// Session `i`'s leader: the clip started `5 i` frames later (cyclic) and
/// moved by `0.1 i` m, so that every session of a batch sees other frames.
fn leader_of(c: &Clip, i: usize) -> Vec<f32> {
    let n = c.leader.len() / 165;
    let mut out = Vec::with_capacity(c.leader.len());
    for t in 0..n {
        let f = (t + 5 * i) % n;
        out.extend(
            c.leader[f * 165..(f + 1) * 165]
                .iter()
                .enumerate()
                .map(|(j, v)| if j % 3 == 0 { v + 0.1 * i as f32 } else { *v }),
        );
    }
    out
}

/// Everything observable after each leader frame: the step reports and the
/// pulled frames.
#[derive(Debug, PartialEq)]
struct Trace {
    steps: Vec<Option<StepReport>>,
    frames: Vec<FollowerFrame>,
}

/// Where two traces first differ (a short message; the traces are long).
fn first_difference(a: &Trace, b: &Trace) -> Option<String> {
    if let Some(t) =
        (0..a.steps.len().max(b.steps.len())).find(|&t| a.steps.get(t) != b.steps.get(t))
    {
        return Some(format!(
            "after leader frame {t}: step {:?} alone, {:?} batched",
            a.steps.get(t),
            b.steps.get(t)
        ));
    }
    if let Some(f) =
        (0..a.frames.len().max(b.frames.len())).find(|&f| a.frames.get(f) != b.frames.get(f))
    {
        let root = |t: &Trace| t.frames.get(f).map(|x| x.root);
        return Some(format!(
            "follower frame {f}: root {:?} alone, {:?} batched ({} / {} frames)",
            root(a),
            root(b),
            a.frames.len(),
            b.frames.len()
        ));
    }
    None
}

fn configs(model: &Model<'_>) -> Vec<(&'static str, SessionConfig)> {
    let cfg = &model.cfg;
    let reference = SessionConfig::reference(cfg);
    let mut live = SessionConfig::with(cfg, 4, 3, 3, reference.shift);
    live.music_lookahead = 0;
    live.sampling = Sampling::TopK { k: 3, rng_seed: 7 };
    let mut f16kv = SessionConfig::minimum(cfg);
    f16kv.kv = KvType::F16;
    vec![
        ("reference", reference),
        ("minimum+f16kv", f16kv),
        ("live+topk", live),
        (
            "staggered+f16kv",
            SessionConfig {
                schedule: CacheSchedule::Staggered,
                kv: KvType::F16,
                ..reference
            },
        ),
        (
            "spread",
            SessionConfig {
                schedule: CacheSchedule::Spread,
                ..reference
            },
        ),
    ]
}

/// Session `i`'s config: `base` with its own sampler seed.
fn config_of(base: &SessionConfig, i: usize) -> SessionConfig {
    let mut sc = *base;
    if let Sampling::TopK { k, rng_seed } = sc.sampling {
        sc.sampling = Sampling::TopK {
            k,
            rng_seed: rng_seed + 1000 * i as u64,
        };
    }
    sc
}

fn seed_of(i: usize) -> [u32; 5] {
    [
        i as u32 % 7,
        (2 * i as u32 + 1) % 7,
        3,
        (i as u32 + 4) % 7,
        (5 * i as u32) % 7,
    ]
}

/// Runs `n` sessions of `model` over the clip, alone or together
/// (`batched`), and returns each session's trace.
fn run(model: &Model<'_>, base: &SessionConfig, c: &Clip, n: usize, batched: bool) -> Vec<Trace> {
    run_in(model, base, c, n, batched, n)
}

/// [`run`] with a `StepBatch` of capacity `cap` (>= n) for the batched run.
fn run_in(
    model: &Model<'_>,
    base: &SessionConfig,
    c: &Clip,
    n: usize,
    batched: bool,
    cap: usize,
) -> Vec<Trace> {
    let n_music = model.cfg.gpt.music.n_in as usize;
    let leaders: Vec<Vec<f32>> = (0..n).map(|i| leader_of(c, i)).collect();
    let cfgs: Vec<SessionConfig> = (0..n).map(|i| config_of(base, i)).collect();
    let mut batch_arena = vec![0u8; StepBatch::bytes(&model.cfg, base, cap).unwrap()];
    let mut batch = StepBatch::new(&model.cfg, base, cap, &mut batch_arena).unwrap();
    // In the batched run, the odd sessions have no step memory of their own
    // (`Session::new_batched`): both kinds in one batch.
    let own = |i: usize| !batched || i % 2 == 0;
    let mut arenas: Vec<Vec<u8>> = cfgs
        .iter()
        .enumerate()
        .map(|(i, sc)| {
            vec![
                0u8;
                if own(i) {
                    model.session_bytes(sc)
                } else {
                    model.batched_session_bytes(sc)
                }
                .unwrap()
            ]
        })
        .collect();
    let mut sessions: Vec<Session<'_>> = Vec::new();
    for (i, (a, sc)) in arenas.iter_mut().zip(&cfgs).enumerate() {
        sessions.push(
            if own(i) {
                Session::new(model, a, sc, seed_of(i))
            } else {
                Session::new_batched(model, a, sc, seed_of(i), &mut batch)
            }
            .unwrap(),
        );
    }
    let live = base.music_lookahead == 0;
    if !live {
        for s in sessions.iter_mut() {
            s.with_batch(&mut batch, |s| s.set_music_track(&c.music))
                .unwrap()
                .unwrap();
        }
    }
    let mut traces: Vec<Trace> = (0..n)
        .map(|_| Trace {
            steps: Vec::new(),
            frames: Vec::new(),
        })
        .collect();
    let frames = c.leader.len() / 165;
    let mut f = FollowerFrame::default();
    for t in 0..frames {
        if live {
            for s in sessions.iter_mut() {
                let m = &c.music[t * n_music..(t + 1) * n_music];
                if s.has_step_memory() {
                    s.push_music_frame(m).unwrap();
                } else {
                    s.with_batch(&mut batch, |s| s.push_music_frame(m))
                        .unwrap()
                        .unwrap();
                }
            }
        }
        let rows: Vec<&[f32]> = leaders.iter().map(|l| &l[t * 165..(t + 1) * 165]).collect();
        let r = if batched {
            let mut refs: Vec<&mut Session<'_>> = sessions.iter_mut().collect();
            Session::step_many(&mut refs, &rows, &mut batch)
        } else {
            sessions
                .iter_mut()
                .zip(&rows)
                .enumerate()
                .try_for_each(|(i, (s, x))| s.push_leader_frame(x).map_err(|e| (i, e)))
        };
        match r {
            // A preloaded track ends: its last tokens have no music look-ahead.
            Err((_, Error::Backlog { .. })) if !live => break,
            r => r.unwrap(),
        }
        for (s, tr) in sessions.iter_mut().zip(traces.iter_mut()) {
            tr.steps.push(s.last_step());
            while s.pull_follower_frame(&mut f).unwrap() {
                tr.frames.push(f);
            }
        }
    }
    traces
}

/// Holds the process-wide kernel choice for one test (the tests of this
/// file run one at a time): the detected kernels ([`duolando::simd::init`]).
fn detected_kernels() -> std::sync::MutexGuard<'static, ()> {
    static KERNELS: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let guard = KERNELS.lock().unwrap_or_else(|e| e.into_inner());
    duolando::simd::init();
    guard
}

/// Under the detected kernels and again under the scalar ones.
#[test]
fn batched_sessions_match_their_own_runs_bit_for_bit() {
    let _kernels = detected_kernels();
    let cases = [
        ("tiny", StoreAs::F32, "rollout_tiny_long"),
        ("tiny2", StoreAs::Q8Block32, "rollout_tiny2_frames"),
        ("tiny2", StoreAs::Q4Block32x8, "rollout_tiny2_frames"),
        ("tiny", StoreAs::F16, "rollout_tiny_long"),
    ];
    for scalar in [false, true] {
        if scalar {
            duolando_core::kernels::simd::force_scalar();
        }
        each_case(&cases);
    }
}

fn each_case(cases: &[(&str, StoreAs, &str)]) {
    for &(name, store, rollout) in cases {
        let file = convert(name, store);
        let duo = file.duo().unwrap();
        let model = Model::from_duo(&duo).unwrap();
        let c = clip(rollout);
        for (label, sc) in configs(&model) {
            let n = 5;
            let alone = run(&model, &sc, &c, n, false);
            let together = run(&model, &sc, &c, n, true);
            for i in 0..n {
                assert!(
                    alone[i].frames.len() > 20,
                    "{name} {store:?} {label}: session {i} pulled only {} frames",
                    alone[i].frames.len()
                );
                assert!(alone[i].steps.iter().flatten().count() > 5);
                if let Some(d) = first_difference(&alone[i], &together[i]) {
                    panic!("{name} {store:?} {label}: session {i} differs when stepped in a batch of {n}: {d}");
                }
            }
            // The sessions really differ from each other (else the test could not see a mix-up).
            assert_ne!(alone[0].frames, alone[1].frames, "{name} {label}");
        }
    }
}

/// A re-prefill runs in chunks of `REPREFILL_CHUNK` window rows in a
/// session's own step, and in one call through a `StepBatch` of capacity
/// 32 (32 window rows >= a whole window): the numbers are the same bit for
/// bit, and the chunked run really did re-prefill more than a chunk.
#[test]
fn chunked_reprefill_matches_one_call_bit_for_bit() {
    let _kernels = detected_kernels();
    use duolando_core::duolando::session::REPREFILL_CHUNK;
    for (name, store, rollout) in [
        ("tiny", StoreAs::F32, "rollout_tiny_long"),
        ("tiny", StoreAs::Q8Block32, "rollout_tiny_long"),
    ] {
        let file = convert(name, store);
        let duo = file.duo().unwrap();
        let model = Model::from_duo(&duo).unwrap();
        let m = model.cfg.gpt.block_size as usize - 1;
        let c = clip(rollout);
        for (label, sc) in configs(&model) {
            assert!(
                sc.shift as usize > REPREFILL_CHUNK || sc.schedule != CacheSchedule::Reprefill,
                "{label}: shift {} does not need chunks",
                sc.shift
            );
            assert!(32 >= m, "capacity 32 holds a window of {m} rows");
            let chunked = run(&model, &sc, &c, 1, false);
            let one_call = run_in(&model, &sc, &c, 1, true, 32);
            assert!(
                chunked[0].steps.iter().flatten().count() > sc.shift as usize + 2,
                "{label}: too few steps to re-prefill"
            );
            if let Some(d) = first_difference(&chunked[0], &one_call[0]) {
                panic!("{name} {store:?} {label}: chunked re-prefill differs from one call: {d}");
            }
        }
    }
}

#[test]
fn a_refused_frame_names_its_session_and_changes_none() {
    let _kernels = detected_kernels();
    let file = ModelFile::open(fixture("tiny/model.duo")).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let c = clip("rollout_tiny_long");
    let sc = SessionConfig::reference(&model.cfg);
    let file2 = ModelFile::open(fixture("tiny/model.duo")).unwrap();
    let duo2 = file2.duo().unwrap();
    let other = Model::from_duo(&duo2).unwrap();
    let mut arenas: Vec<Vec<u8>> = (0..3)
        .map(|_| vec![0u8; model.session_bytes(&sc).unwrap()])
        .collect();
    let mut sessions: Vec<Session<'_>> = arenas
        .iter_mut()
        .map(|a| Session::new(&model, a, &sc, [0; 5]).unwrap())
        .collect();
    for s in sessions.iter_mut() {
        s.set_music_track(&c.music).unwrap();
    }
    let mut batch_arena = vec![0u8; StepBatch::bytes(&model.cfg, &sc, 3).unwrap()];
    let mut batch = StepBatch::new(&model.cfg, &sc, 3, &mut batch_arena).unwrap();
    let good = &c.leader[..165];
    let mut bad = good.to_vec();
    bad[7] = f32::NAN;
    {
        let mut refs: Vec<&mut Session<'_>> = sessions.iter_mut().collect();
        assert_eq!(
            Session::step_many(&mut refs, &[good, good, &bad], &mut batch),
            Err((
                2,
                Error::NonFinite {
                    buffer: Buffer::LeaderPos3d,
                    index: 7
                }
            ))
        );
        assert_eq!(
            Session::step_many(&mut refs, &[good, &good[..160], good], &mut batch),
            Err((
                1,
                Error::Length {
                    buffer: Buffer::LeaderPos3d,
                    len: 160,
                    expected: 165
                }
            ))
        );
        assert!(matches!(
            Session::step_many(&mut refs, &[good, good], &mut batch),
            Err((0, Error::Length { .. }))
        ));
    }
    assert!(
        sessions.iter().all(|s| s.frames_pushed() == 0),
        "a refused batch must change no session"
    );
    // More sessions than the batch holds.
    let mut arenas4: Vec<Vec<u8>> = (0..4)
        .map(|_| vec![0u8; model.session_bytes(&sc).unwrap()])
        .collect();
    let mut four: Vec<Session<'_>> = arenas4
        .iter_mut()
        .map(|a| Session::new(&model, a, &sc, [0; 5]).unwrap())
        .collect();
    let mut refs: Vec<&mut Session<'_>> = four.iter_mut().collect();
    assert_eq!(
        Session::step_many(&mut refs, &[good; 4], &mut batch),
        Err((
            0,
            Error::Setting {
                setting: Setting::Batch,
                value: 4,
                max: 3
            }
        ))
    );
    assert!(four.iter().all(|s| s.frames_pushed() == 0));
    // A session of another model (same config) does not join.
    {
        let (mut aa, mut oa) = (
            vec![0u8; model.session_bytes(&sc).unwrap()],
            vec![0u8; other.session_bytes(&sc).unwrap()],
        );
        let mut a = Session::new(&model, &mut aa, &sc, [0; 5]).unwrap();
        let mut o = Session::new(&other, &mut oa, &sc, [0; 5]).unwrap();
        let mut refs: Vec<&mut Session<'_>> = vec![&mut a, &mut o];
        assert_eq!(
            Session::step_many(&mut refs, &[good, good], &mut batch),
            Err((1, Error::State))
        );
        assert_eq!((a.frames_pushed(), o.frames_pushed()), (0, 0));
    }
    // A batch made for a smaller look-ahead cannot hold a session that needs more keys.
    assert!(matches!(
        StepBatch::bytes(&model.cfg, &sc, 0),
        Err(Error::Setting {
            setting: Setting::Batch,
            ..
        })
    ));
    assert!(matches!(
        StepBatch::bytes(&model.cfg, &sc, 65),
        Err(Error::Setting {
            setting: Setting::Batch,
            ..
        })
    ));
    // Accepted after all: the same frames one by one and together agree (smoke check).
    let mut refs: Vec<&mut Session<'_>> = sessions.iter_mut().collect();
    Session::step_many(&mut refs, &[good, good, good], &mut batch).unwrap();
    assert!(sessions.iter().all(|s| s.frames_pushed() == 1));
}

/// Sessions of different budgets (encoder/decoder lags, hence different
/// tail cones in the streaming convolutions) and out of phase (one starts
/// two leader frames later, so its tokens complete at other calls) share
/// one batch: the batched encoders/decoders compute each stack's own
/// columns, and every session ends bit for bit where it ends alone.
#[test]
fn mixed_budgets_and_phases_in_one_batch_match_their_own_runs() {
    let _kernels = detected_kernels();
    for (name, store, rollout) in [
        ("tiny", StoreAs::F32, "rollout_tiny_long"),
        ("tiny2", StoreAs::Q8Block32, "rollout_tiny2_frames"),
    ] {
        let file = convert(name, store);
        let duo = file.duo().unwrap();
        let model = Model::from_duo(&duo).unwrap();
        let c = clip(rollout);
        let r = SessionConfig::reference(&model.cfg);
        let cfgs = [
            r,
            SessionConfig::with(&model.cfg, r.lookahead, r.enc_future / 2, 1, r.shift),
            SessionConfig::minimum(&model.cfg),
            r,
        ];
        let delay = [0usize, 0, 0, 2];
        let n = cfgs.len();
        let leaders: Vec<Vec<f32>> = (0..n).map(|i| leader_of(&c, i)).collect();
        // Stop well before the track ends (its last tokens lack music look-ahead).
        let frames = c.leader.len() / 165 * 3 / 4;
        let run = |batched: bool| -> Vec<Trace> {
            let mut arenas: Vec<Vec<u8>> = cfgs
                .iter()
                .map(|sc| vec![0u8; model.session_bytes(sc).unwrap()])
                .collect();
            let mut sessions: Vec<Session<'_>> = arenas
                .iter_mut()
                .zip(&cfgs)
                .enumerate()
                .map(|(i, (a, sc))| Session::new(&model, a, sc, seed_of(i)).unwrap())
                .collect();
            for s in sessions.iter_mut() {
                s.set_music_track(&c.music).unwrap();
            }
            let mut batch_arena = vec![0u8; StepBatch::bytes(&model.cfg, &r, n).unwrap()];
            let mut batch = StepBatch::new(&model.cfg, &r, n, &mut batch_arena).unwrap();
            let mut traces: Vec<Trace> = (0..n)
                .map(|_| Trace {
                    steps: Vec::new(),
                    frames: Vec::new(),
                })
                .collect();
            let mut f = FollowerFrame::default();
            for t in 0..frames + 2 {
                let active: Vec<usize> = (0..n)
                    .filter(|&i| t >= delay[i] && t - delay[i] < frames)
                    .collect();
                let rows: Vec<&[f32]> = active
                    .iter()
                    .map(|&i| &leaders[i][(t - delay[i]) * 165..(t - delay[i] + 1) * 165])
                    .collect();
                if batched {
                    let mut refs: Vec<&mut Session<'_>> = sessions
                        .iter_mut()
                        .enumerate()
                        .filter(|(i, _)| active.contains(i))
                        .map(|(_, s)| s)
                        .collect();
                    Session::step_many(&mut refs, &rows, &mut batch).unwrap();
                } else {
                    for (&i, x) in active.iter().zip(&rows) {
                        sessions[i]
                            .push_leader_frame(x)
                            .unwrap_or_else(|e| panic!("session {i} at frame {t}: {e:?}"));
                    }
                }
                for &i in &active {
                    traces[i].steps.push(sessions[i].last_step());
                    while sessions[i].pull_follower_frame(&mut f).unwrap() {
                        traces[i].frames.push(f);
                    }
                }
            }
            traces
        };
        let (alone, together) = (run(false), run(true));
        for i in 0..n {
            assert!(
                alone[i].frames.len() > 20,
                "{name}: session {i} pulled only {} frames",
                alone[i].frames.len()
            );
            if let Some(d) = first_difference(&alone[i], &together[i]) {
                panic!("{name} {store:?}: session {i} ({:?}, {} frames late) differs in the mixed batch: {d}", cfgs[i], delay[i]);
            }
        }
        assert_ne!(
            cfgs[1].enc_future, cfgs[0].enc_future,
            "{name}: the budgets must differ"
        );
    }
}
