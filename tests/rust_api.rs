//! The README's Rust API example, line for line, on the bundled demo model:
//! it runs the detected SIMD kernels although it never asks for them
//! (opening the model selects them: `duolando::simd::ensure_init`). Its own
//! test binary: the kernel choice is process-wide.

use duolando::model_file::ModelFile;
use duolando_core::duolando::{
    model::Model,
    session::{FollowerFrame, Session, SessionConfig},
};
use duolando_core::kernels::simd::{self, Isa};

fn asset(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../assets")
        .join(name)
}

#[test]
fn the_readme_example_runs_the_detected_kernels() -> Result<(), Box<dyn std::error::Error>> {
    assert_eq!(
        simd::isa(),
        Isa::Scalar,
        "no kernels are selected before a model is opened"
    );
    let leader =
        duolando::npy::read_f32_2d(&asset("demo_leader_pos3d.npy"), Some(165), "leader")?.data;
    let music = duolando::npy::read_f32_2d(&asset("demo_music.npy"), Some(54), "music")?.data;
    let seed_tokens = [0u32; 5];

    // --- the README's lines ---
    let file = ModelFile::open(asset("demo.duo"))?;
    let duo = file.duo()?;
    let model = Model::from_duo(&duo).map_err(|e| format!("{e:?}"))?;
    let cfg = SessionConfig::reference(&model.cfg);
    let mut arena = vec![0u8; model.session_bytes(&cfg).map_err(|e| format!("{e:?}"))?];
    let mut s =
        Session::new(&model, &mut arena, &cfg, seed_tokens).map_err(|e| format!("{e:?}"))?;
    s.set_music_track(&music).map_err(|e| format!("{e:?}"))?;
    let mut frame = FollowerFrame::default();
    let mut pulled = 0;
    for pose in leader.chunks(165).take(400) {
        s.push_leader_frame(pose).map_err(|e| format!("{e:?}"))?;
        while s
            .pull_follower_frame(&mut frame)
            .map_err(|e| format!("{e:?}"))?
        {
            pulled += 1;
        }
    }
    let before_finish = pulled;
    s.finish().map_err(|e| format!("{e:?}"))?;
    while s
        .pull_follower_frame(&mut frame)
        .map_err(|e| format!("{e:?}"))?
    {
        pulled += 1;
    }
    // --- end ---
    assert!(
        pulled > before_finish,
        "the drain gives the held-back frames"
    );

    assert!(pulled > 0, "frames came out");
    let want = duolando::simd::detect();
    assert_eq!(
        simd::isa(),
        want,
        "the example ran {:?}; this CPU's best (capped by DUOLANDO_ISA) is {want:?}",
        simd::isa()
    );
    Ok(())
}
