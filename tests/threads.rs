//! GEMMs and attention split over threads
//! (`duolando::workers::set_threads`, issue #4 item 5) give the same bits
//! as one thread: the demo model (f16 and its
//! int8 re-store) in R mode over the demo clip and in S mode (a streaming
//! session over the same clip), at 1, 2 and 3 threads. The split really
//! happens (`workers::split_jobs` counts the GEMMs that ran on a pool).

use duolando::convert::storage_for;
use duolando::duo_writer::StoreAs;
use duolando::model_file::ModelFile;
use duolando::npy::read_f32_2d;
use duolando::workers;
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::{FollowerFrame, Session, SessionConfig};
use duolando_tests::{assets_dir, demo_model, restore_as, run_demo_clip, Rng};

/// Every follower frame of a streaming session over the first `frames`
/// frames of the demo clip (the music preloaded).
fn stream(file: &ModelFile, frames: usize) -> Vec<FollowerFrame> {
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let a = assets_dir();
    let leader = read_f32_2d(&a.join("demo_leader_pos3d.npy"), Some(165), "leader").unwrap();
    let music = read_f32_2d(&a.join("demo_music.npy"), None, "music").unwrap();
    let sc = SessionConfig::reference(&model.cfg);
    let mut arena = vec![0u8; model.session_bytes(&sc).unwrap()];
    let mut s = Session::new(&model, &mut arena, &sc, [1, 2, 3, 4, 5]).unwrap();
    s.set_music_track(&music.data).unwrap();
    let (mut out, mut f) = (Vec::new(), FollowerFrame::default());
    for row in leader.data.chunks_exact(165).take(frames) {
        s.push_leader_frame(row).unwrap();
        while s.pull_follower_frame(&mut f).unwrap() {
            out.push(f);
        }
    }
    out
}

/// The thread count is process-wide: the tests of this file take turns.
static POOL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn split_gemms_are_bit_identical_to_one_thread() {
    let _turn = POOL.lock().unwrap_or_else(|e| e.into_inner());
    duolando::simd::init();
    let f16 = demo_model();
    let int8 = restore_as(&f16, &|spec| storage_for(StoreAs::Q8Block32, spec));
    let mut one_thread = Vec::new();
    for (name, file) in [("f16", &f16), ("int8", &int8)] {
        workers::set_threads(1).unwrap();
        let (r1, s1) = (run_demo_clip(file), stream(file, 400));
        eprintln!("{name}: {} streamed frames, {} R steps", s1.len(), r1.steps);
        assert!(s1.len() > 40, "{name}: only {} streamed frames", s1.len());
        for n in [2, 3] {
            workers::set_threads(n).unwrap();
            assert_eq!(workers::threads(), n);
            let jobs = workers::split_jobs();
            let (rn, sn) = (run_demo_clip(file), stream(file, 400));
            let split = workers::split_jobs() - jobs;
            workers::set_threads(1).unwrap();
            eprintln!("{name}, {n} threads: {split} GEMMs split");
            assert!(
                split > 100,
                "{name}, {n} threads: only {split} GEMMs were split"
            );
            assert_eq!(rn.tokens, r1.tokens, "{name}, {n} threads: R tokens");
            assert_eq!(
                bits(&rn.pos),
                bits(&r1.pos),
                "{name}, {n} threads: R positions"
            );
            assert_eq!(
                bits(&rn.rot),
                bits(&r1.rot),
                "{name}, {n} threads: R rotations"
            );
            assert_eq!(
                sn.len(),
                s1.len(),
                "{name}, {n} threads: streamed frame count"
            );
            if let Some(i) = (0..s1.len()).find(|&i| s1[i] != sn[i]) {
                panic!("{name}, {n} threads: streamed frame {i} differs from one thread's");
            }
        }
        one_thread.push(s1);
    }
    // Two sessions stepped on two threads at once while a 2-thread pool is
    // installed: one thread's GEMMs take the pool, the other's run alone
    // whenever it is busy; both still match one thread.
    workers::set_threads(2).unwrap();
    let both: Vec<Vec<FollowerFrame>> = std::thread::scope(|sc| {
        let hs: Vec<_> = [&f16, &int8]
            .map(|f| sc.spawn(move || stream(f, 400)))
            .into_iter()
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    workers::set_threads(1).unwrap();
    assert!(
        both[0] == one_thread[0],
        "f16 session beside another thread differs"
    );
    assert!(
        both[1] == one_thread[1],
        "int8 session beside another thread differs"
    );
    assert_eq!(workers::threads(), 1);
}

/// `kernels::matmul` (attention as per-head GEMMs: Transflower's encoder
/// layers) split over 2 and 3 threads by output columns gives the bits of
/// one thread, on the scores' and the output's shapes of the paper config
/// (inner lengths 80 and 260) and on odd ones.
#[test]
fn split_matmul_is_bit_identical_to_one_thread() {
    let _turn = POOL.lock().unwrap_or_else(|e| e.into_inner());
    duolando::simd::init();
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    for &(m, k, n) in &[(260, 80, 260), (260, 260, 80), (37, 19, 131)] {
        let (a, b) = (rng.vec(m * k), rng.vec(k * n));
        workers::set_threads(1).unwrap();
        let mut c1 = vec![0f32; m * n];
        duolando_core::kernels::matmul(&a, &b, m, k, n, &mut c1);
        for t in [2, 3] {
            workers::set_threads(t).unwrap();
            let jobs = workers::split_jobs();
            let mut ct = vec![0f32; m * n];
            duolando_core::kernels::matmul(&a, &b, m, k, n, &mut ct);
            let split = workers::split_jobs() - jobs;
            workers::set_threads(1).unwrap();
            assert!(split >= 1, "({m},{k},{n}) on {t} threads: not split");
            assert_eq!(bits(&ct), bits(&c1), "({m},{k},{n}) on {t} threads");
        }
    }
}
