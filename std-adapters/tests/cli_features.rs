//! `duolando features`: `--for bailando` writes the (T, 438) features of a
//! decoded file, identical to the library's; the default stays Duolando's
//! (T, 54); OUT goes positionally or with `-o`; bad `--for` values and two
//! outputs are usage errors (exit 2).

use std::path::{Path, PathBuf};
use std::process::Command;

use duolando::music::{bailando, Extractor, FeatureSet, FEATURE_DIM, SAMPLE_RATE};

fn flac() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/music/stereo_44k.flac")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("duo-features-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run(args: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_duolando"))
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn library(set: FeatureSet) -> duolando::music::Features {
    let y = duolando::audio::load_mono(flac(), set.sample_rate()).unwrap();
    Extractor::for_set(set).features(&y).unwrap()
}

#[test]
fn for_bailando_writes_the_438_features_of_the_file() {
    let d = tmp("bailando");
    let out = d.join("music.npy");
    let (code, err) = run(&[
        "features",
        "--for",
        "bailando",
        flac().to_str().unwrap(),
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("(16, 438) bailando features at 7.5 fps"),
        "{err}"
    );
    let a = duolando::npy::read_f32_2d(&out, Some(bailando::FEATURE_DIM), "music").unwrap();
    let want = library(FeatureSet::Bailando);
    assert_eq!((a.rows, a.cols), (want.frames, 438));
    // 2 s at 3840 Hz: 7680 samples, 1 + 7680 / 512 frames
    assert_eq!(a.rows, 16);
    assert_eq!(a.data, want.data, "CLI and library features differ");
    std::fs::remove_dir_all(d).ok();
}

#[test]
fn default_is_duolando_and_o_still_works() {
    let d = tmp("duolando");
    let out = d.join("music.npy");
    let (code, err) = run(&[
        "features",
        flac().to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let a = duolando::npy::read_f32_2d(&out, Some(FEATURE_DIM), "music").unwrap();
    assert_eq!(a.rows, 1 + 2 * SAMPLE_RATE as usize / 512);
    assert_eq!(a.data, library(FeatureSet::Duolando).data);
    std::fs::remove_dir_all(d).ok();
}

#[test]
fn usage_errors_exit_2() {
    let d = tmp("usage");
    let out = d.join("m.npy");
    let (o, f) = (out.to_str().unwrap(), flac());
    let f = f.to_str().unwrap();
    let (code, err) = run(&["features", "--for", "edge", f, o]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("possible values: duolando, bailando, transflower"),
        "{err}"
    );
    let (code, err) = run(&["features", f, o, "-o", o]);
    assert_eq!(code, Some(2), "{err}");
    let (code, err) = run(&["features", f]);
    assert_eq!(code, Some(2), "{err}");
    let (code, _) = run(&["features", "--help"]);
    assert_eq!(code, Some(0));
    assert!(!out.exists());
    std::fs::remove_dir_all(d).ok();
}
