//! A session steps, and `Session::step_many` steps a batch, on a thread
//! with a 1 MiB stack (docs/C_API.md names that figure for callers'
//! threads), under the kernels this CPU selects and under the scalar ones.
//! The int8 GEMM keeps its activation panel on the stack, sized for the
//! full model whatever the model (fixed arrays), so the tiny int8 fixture
//! takes the same frames as the full size. A stack overflow aborts the test
//! binary. Its own binary: it switches the process-wide kernels.

use duolando::model_file::ModelFile;
use duolando::npy::read_f32_2d;
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::{FollowerFrame, Session, SessionConfig, StepBatch};
use duolando_tests::fixture;

/// The stack of the stepping thread: 1 MiB, or `STACK_KIB` KiB (to find the
/// least that works; 2026-12-02, release: > 576 and <= 640 KiB, the same
/// before and after the int8 panel grew to 96 KiB; > 576 and <= 608 KiB with
/// the AMX tile-pair kernel and the 192 KiB panel, and again on 2026-12-03 with 12-row AMX
/// groups; the test profile: <= 768 KiB).
fn stack() -> usize {
    std::env::var("STACK_KIB")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1024)
        * 1024
}

#[test]
fn sessions_and_batches_step_in_a_1_mib_stack() {
    let file = ModelFile::open(fixture("tiny2/model.duo")).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let d = fixture("rollout_tiny2_frames");
    let leader = read_f32_2d(&d.join("leader_pos3d.npy"), Some(165), "leader")
        .unwrap()
        .data;
    let music = read_f32_2d(&d.join("music.npy"), None, "music")
        .unwrap()
        .data;
    let sc = SessionConfig::reference(&model.cfg);
    for scalar in [false, true] {
        duolando::simd::init();
        if scalar {
            duolando_core::kernels::simd::force_scalar();
        }
        let (model, leader, music, sc) = (&model, &leader, &music, &sc);
        let pulled = std::thread::scope(|scope| {
            std::thread::Builder::new()
                .stack_size(stack())
                .spawn_scoped(scope, move || {
                    let n = 4;
                    let mut arenas: Vec<Vec<u8>> = (0..n)
                        .map(|_| vec![0u8; model.session_bytes(sc).unwrap()])
                        .collect();
                    let mut sessions: Vec<Session<'_>> = arenas
                        .iter_mut()
                        .enumerate()
                        .map(|(i, a)| Session::new(model, a, sc, [i as u32, 1, 2, 3, 4]).unwrap())
                        .collect();
                    for s in sessions.iter_mut() {
                        s.set_music_track(music).unwrap();
                    }
                    let mut batch_arena =
                        vec![0u8; StepBatch::bytes(&model.cfg, sc, n - 1).unwrap()];
                    let mut batch =
                        StepBatch::new(&model.cfg, sc, n - 1, &mut batch_arena).unwrap();
                    let mut f = FollowerFrame::default();
                    let mut pulled = 0;
                    for t in 0..leader.len() / 165 {
                        let x = &leader[t * 165..(t + 1) * 165];
                        let (one, rest) = sessions.split_at_mut(1);
                        // Session 0 alone, the other three as one batch.
                        if one[0].push_leader_frame(x).is_err() {
                            break;
                        }
                        let mut refs: Vec<&mut Session<'_>> = rest.iter_mut().collect();
                        if Session::step_many(&mut refs, &[x, x, x], &mut batch).is_err() {
                            break;
                        }
                        for s in sessions.iter_mut() {
                            while s.pull_follower_frame(&mut f).unwrap() {
                                pulled += 1;
                            }
                        }
                    }
                    pulled
                })
                .unwrap()
                .join()
                .unwrap()
        });
        assert!(
            pulled > 4 * 20,
            "scalar={scalar}: only {pulled} frames pulled"
        );
    }
}
