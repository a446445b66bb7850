//! What the CLI says when something is wrong (issue #36 §5): usage errors
//! exit 2 and runtime errors 1, as docs/CLI.md says; an OS error is printed
//! once; a file that is not safetensors says why with numbers; a file that
//! is not a model prints its magic as 0x-prefixed hex.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("duo-messages-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run(args: &[&str]) -> (Option<i32>, String) {
    let o: Output = Command::new(env!("CARGO_BIN_EXE_duolando"))
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// `duolando convert` of the tiny fixture with `config` and `gpt` in place
/// of its own, writing into `dir`.
fn convert(config: &Path, gpt: &Path, dir: &Path) -> (Option<i32>, String) {
    let t = fixtures().join("tiny");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let args = [
        "convert".to_string(),
        "--config".into(),
        s(config),
        "--gpt".into(),
        s(gpt),
        "--vqvae".into(),
        s(&t.join("vqvae.safetensors")),
        "--transl".into(),
        s(&t.join("transl.safetensors")),
        "-o".into(),
        s(&dir.join("m.duo")),
    ];
    run(&args.iter().map(String::as_str).collect::<Vec<_>>())
}

#[test]
fn usage_errors_exit_2_and_errors_exit_1() {
    let (code, e) = run(&["generate", "--model"]);
    assert_eq!(code, Some(2), "{e}");
    let (code, e) = run(&["no-such-command"]);
    assert_eq!(code, Some(2), "{e}");
    let (code, e) = run(&["inspect", "/nonexistent/model.duo"]);
    assert_eq!(code, Some(1), "{e}");
}

#[test]
fn an_os_error_is_printed_once() {
    let dir = tmp("os");
    let yaml = dir.join("missing.yaml");
    let t = fixtures().join("tiny");
    let (code, e) = convert(&yaml, &t.join("gpt.safetensors"), &dir);
    assert_eq!(code, Some(1), "{e}");
    assert!(e.contains("missing.yaml"), "{e}");
    assert_eq!(e.matches("os error 2").count(), 1, "the OS error once: {e}");
}

#[test]
fn a_file_that_is_not_safetensors_says_why() {
    let dir = tmp("st");
    let t = fixtures().join("tiny");
    let fake = dir.join("gpt.safetensors");
    // A PyTorch zip checkpoint begins "PK\x03\x04...": read as a header
    // length, that is an absurd number.
    let mut bytes = b"PK\x03\x04\x14\x00\x00\x00".to_vec();
    bytes.extend_from_slice(&[0u8; 100]);
    std::fs::write(&fake, &bytes).unwrap();
    let (code, e) = convert(&t.join("follower_gpt.yaml"), &fake, &dir);
    assert_eq!(code, Some(1), "{e}");
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap());
    assert!(
        e.contains(&format!("header of {n} bytes")) && e.contains("108 bytes"),
        "{e}"
    );
    assert!(
        e.contains("pt_to_safetensors.py"),
        "says how to make one: {e}"
    );
}

#[test]
fn not_a_model_prints_its_magic_in_hex() {
    let dir = tmp("magic");
    let f = dir.join("notes.duo");
    std::fs::write(&f, b"hello, world, this is not a model at all").unwrap();
    let (code, e) = run(&["inspect", f.to_str().unwrap()]);
    assert_eq!(code, Some(1), "{e}");
    assert!(
        e.contains("not a .duo file") && e.contains("0x68656c6c6f2c2077"),
        "{e}"
    );
}

#[test]
fn synth_puts_beats_on_the_grid_it_is_given_and_refuses_a_bad_one() {
    let d = tmp("synth-grid");
    let out = d.join("s");
    let (code, e) = run(&[
        "synth",
        "--minutes",
        "0.5",
        "--seed",
        "2",
        "--beat-grid-frames",
        "4",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{e}");
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("takes.json")).unwrap()).unwrap();
    let grid = index["beat_grid_s"].as_f64().unwrap();
    assert!((grid - 4.0 / 30.0).abs() < 1e-6, "{grid}");
    let takes = index["takes"].as_array().unwrap();
    assert!(!takes.is_empty());
    for t in takes {
        for b in t["beats_s"].as_array().unwrap() {
            let k = b.as_f64().unwrap() / grid;
            assert!(
                (k - k.round()).abs() < 1e-3,
                "{}: beat {b} off the grid",
                t["name"]
            );
        }
    }
    let (code, e) = run(&[
        "synth",
        "--beat-grid-frames",
        "0",
        "--out",
        d.join("bad").to_str().unwrap(),
    ]);
    assert_eq!(code, Some(1), "{e}");
    assert!(e.contains("--beat-grid-frames must be 1 to 48"), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}
