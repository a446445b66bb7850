//! Every CLI command that runs a model runs the fastest kernels this CPU
//! supports without being asked (issue #36 §1): opening a model selects
//! them (`duolando::simd::ensure_init`). Each command prints the kernels
//! it ran (`kernels: ...` on stderr; `dance` also in summary.json), and
//! `DUOLANDO_ISA` still caps the choice.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("duo-kernels-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn p(path: &Path) -> String {
    path.to_str().unwrap().to_string()
}

/// Runs the binary with `DUOLANDO_ISA` set to `isa` (or removed).
fn run(args: &[String], isa: Option<&str>) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_duolando"));
    c.args(args);
    match isa {
        Some(v) => c.env("DUOLANDO_ISA", v),
        None => c.env_remove("DUOLANDO_ISA"),
    };
    c.output().unwrap()
}

/// The `kernels:` line the command printed.
fn kernels(o: &Output) -> String {
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{e}");
    let lines: Vec<&str> = e
        .lines()
        .filter_map(|l| l.strip_prefix("kernels: "))
        .collect();
    assert_eq!(lines.len(), 1, "one kernels line expected:\n{e}");
    lines[0].trim().to_string()
}

/// What the detected kernels are called here (`Avx512Vnni+AMX`, `Avx2`, ...).
fn detected() -> String {
    // The best supported, uncapped: the commands run without DUOLANDO_ISA.
    let isa = duolando::simd::supported()[0];
    let amx = isa == duolando_core::kernels::simd::Isa::Avx512Vnni && duolando::simd::amx_usable();
    format!("{isa:?}{}", if amx { "+AMX" } else { "" })
}

/// Each command on the tiny model, writing under `out`.
fn commands(out: &Path) -> Vec<(&'static str, Vec<String>)> {
    let fx = fixtures();
    let model = fx.join("tiny/model.duo");
    let roll = fx.join("rollout_tiny_long");
    let io = |mode: &str| {
        vec![
            "--leader".into(),
            p(&roll.join("leader_pos3d.npy")),
            "--music".into(),
            p(&roll.join("music.npy")),
            "--out".into(),
            p(&out.join(mode)),
        ]
    };
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<String>>();
    let mut dance = s(&["dance", "--model"]);
    dance.push(p(&model));
    dance.extend(io("dance"));
    let mut generate = s(&["generate", "--model"]);
    generate.push(p(&model));
    generate.extend(io("generate"));
    generate.extend(s(&["--seed-tokens", "1,2,3,4,5", "--mode", "exact"]));
    let mut streaming = s(&["generate", "--model"]);
    streaming.push(p(&model));
    streaming.extend(io("streaming"));
    streaming.extend(s(&["--seed-tokens", "1,2,3,4,5", "--mode", "streaming"]));
    let mut compare = s(&["compare", "--model"]);
    compare.push(p(&model));
    compare.extend(io("compare")[..4].iter().cloned());
    compare.extend(s(&["--seed-tokens", "1,2,3,4,5"]));
    let mut live = s(&["live", "--model"]);
    live.push(p(&model));
    live.extend(io("live")[..4].iter().cloned());
    live.extend(s(&[
        "--seed-tokens",
        "1,2,3,4,5",
        "--no-pace",
        "--port",
        "0",
        "--linger",
        "0",
    ]));
    let mut inspect = s(&["inspect"]);
    inspect.push(p(&model));
    vec![
        ("dance", dance),
        ("generate exact", generate),
        ("generate streaming", streaming),
        ("compare", compare),
        ("live", live),
        ("inspect", inspect),
    ]
}

#[test]
fn every_command_runs_the_detected_kernels_unasked() {
    let want = detected();
    let out = tmp("all");
    for (name, args) in commands(&out) {
        let got = kernels(&run(&args, None));
        assert_eq!(
            got, want,
            "`duolando {name}` ran {got}, this CPU's best is {want}"
        );
    }
    // dance also records them in summary.json.
    let s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("dance/summary.json")).unwrap()).unwrap();
    assert_eq!(s["kernels"], want.as_str());
}

#[test]
fn duolando_isa_still_caps_the_kernels() {
    let inspect = commands(&tmp("capped")).pop().unwrap().1;
    assert_eq!(kernels(&run(&inspect, Some("scalar"))), "Scalar");
}
