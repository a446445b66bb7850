//! `duolando bench --ort-json FILE` (issues #38, #39, #40): onnxruntime's R-step
//! figure of the family (the JSON of tools/<family>_ort_r_step.py) is read
//! and checked before anything runs (a missing, broken or other family's
//! file is a named error), printed with its CPU, and written to the JSON
//! output. `--dtypes` with no value skips the model benches, so these runs
//! take milliseconds.

use std::path::PathBuf;

mod common;
use common::bench;

fn tmp(name: &str, text: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("duo-bench-ort-{}-{name}", std::process::id()));
    std::fs::write(&p, text).unwrap();
    p
}

/// What tools/transflower_ort_r_step.py writes (its keys, made-up times).
fn transflower_json() -> serde_json::Value {
    serde_json::json!({
        "family": "transflower",
        "what": "Transflower R step (paper config ...), onnxruntime f32",
        "onnxruntime": "1.32.0",
        "torch": "2.15.0",
        "threads": 1,
        "cpu": "Test CPU 9000",
        "loadavg_1min_before": 0.25,
        "median_ms": 812.5,
        "p99_ms": 840.0,
        "runs": 30,
        "by_threads": [
            {"threads": 1, "median_ms": 812.5, "p99_ms": 840.0},
            {"threads": 2, "median_ms": 430.25, "p99_ms": 451.0}
        ],
        "max_abs_err_vs_torch": 3.1e-5
    })
}

fn refused(args: &[&str], wanted: &[&str]) {
    let o = bench(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success(),
        "accepted {args:?}:\n{}",
        String::from_utf8_lossy(&o.stdout)
    );
    for w in wanted {
        assert!(err.contains(w), "{args:?}: error lacks '{w}':\n{err}");
    }
    // Refused before anything ran: no bandwidth line, no model bench.
    assert!(
        !String::from_utf8_lossy(&o.stdout).contains("memcpy"),
        "ran before refusing"
    );
}

/// `bench [--family F] --dtypes --ort-json <v> --json OUT`: must succeed;
/// returns the onnxruntime lines (those starting with `<Family> R step
/// onnxruntime 1.32.0 f32`) and the JSON written.
fn run_ort(family: &str, v: &serde_json::Value) -> (Vec<String>, serde_json::Value) {
    let input = tmp(&format!("{family}-in.json"), &v.to_string());
    let json = std::env::temp_dir().join(format!(
        "duo-bench-ort-{}-{family}-out.json",
        std::process::id()
    ));
    let o = bench(&[
        "--family",
        family,
        "--dtypes",
        "--ort-json",
        input.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let title = format!("{}{}", family[..1].to_uppercase(), &family[1..]);
    let prefix = format!("{title} R step onnxruntime 1.32.0 f32");
    let lines: Vec<String> = out
        .lines()
        .filter(|l| l.starts_with(&prefix))
        .map(str::to_owned)
        .collect();
    assert_eq!(lines.len(), 2, "{out}");
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let _ = std::fs::remove_file(&json);
    let _ = std::fs::remove_file(&input);
    assert_eq!(j["ort_family"], family);
    (lines, j)
}

#[test]
fn a_good_transflower_json_is_printed_and_written() {
    let (lines, j) = run_ort("transflower", &transflower_json());
    assert!(
        lines[0].contains(" t1 (Test CPU 9000, load 0.25)")
            && lines[0].contains("median    812.5 ms")
            && lines[0].contains("p99    840.0 ms"),
        "{}",
        lines[0]
    );
    assert!(
        lines[1].contains(" t2 ") && lines[1].contains("median    430.2 ms"),
        "{}",
        lines[1]
    );
    // Not this machine's CPU: said so.
    assert!(lines[0].contains("measured on another CPU"), "{}", lines[0]);
    assert_eq!(j["ort_r_step_ms_t1"], 812.5);
    assert_eq!(j["ort_r_step_p99_ms_t1"], 840.0);
    assert_eq!(j["ort_r_step_ms_t2"], 430.25);
    assert_eq!(j["ort_version"], "1.32.0");
    assert_eq!(j["ort_cpu"], "Test CPU 9000");
    assert_eq!(j["ort_max_abs_err_vs_torch"], 3.1e-5);
}

#[test]
fn a_duolando_json_is_read_for_duolando() {
    // The keys tools/duolando_ort_r_step.py writes (made-up times).
    let v = serde_json::json!({
        "family": "duolando",
        "what": "Duolando R step (follower GPT, 29-token window, LATs included, the 5 heads' last logits), published size, onnxruntime f32",
        "onnxruntime": "1.32.0", "torch": "2.15.0", "threads": 1, "cpu": "Test CPU 9000",
        "loadavg_1min_before": 0.5, "params": 300000000,
        "median_ms": 377.0, "p99_ms": 390.5, "runs": 20,
        "by_threads": [
            {"threads": 1, "median_ms": 377.0, "p99_ms": 390.5, "min_ms": 370.0, "runs": 20},
            {"threads": 2, "median_ms": 201.5, "p99_ms": 210.0, "min_ms": 199.0, "runs": 20}
        ],
        "max_abs_err_vs_torch": 2.0e-6, "logit_scale": 1.5
    });
    let (lines, j) = run_ort("duolando", &v);
    assert!(lines[0].contains(" t1 ") && lines[0].contains("median    377.0 ms"), "{}", lines[0]);
    assert!(lines[1].contains(" t2 ") && lines[1].contains("median    201.5 ms"), "{}", lines[1]);
    assert_eq!(j["ort_r_step_ms_t2"], 201.5);
    // A Duolando file is not a Bailando one.
    let input = tmp("duolando2.json", &v.to_string());
    refused(
        &["--family", "bailando", "--ort-json", input.to_str().unwrap()],
        &["onnxruntime figures of duolando, this is --family bailando"],
    );
    let _ = std::fs::remove_file(&input);
}

#[test]
fn an_older_bailando_json_is_read_for_bailando() {
    // tools/bailando_ort_r_step.py before `family`: named only in `what`, one thread.
    let v = serde_json::json!({
        "what": "Bailando R step (actor GPT over a 28-token window), onnxruntime f32",
        "onnxruntime": "1.32.0", "threads": 1, "cpu": "Test CPU 9000",
        "median_ms": 160.1, "p99_ms": 170.0, "runs": 20
    });
    let input = tmp("bailando.json", &v.to_string());
    let o = bench(&[
        "--family",
        "bailando",
        "--dtypes",
        "--ort-json",
        input.to_str().unwrap(),
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        out.lines().any(|l| l
            .starts_with("Bailando R step onnxruntime 1.32.0 f32 t1 (Test CPU 9000)")
            && l.contains("median    160.1 ms")),
        "{out}"
    );
    // ... and refused for Transflower.
    refused(
        &[
            "--family",
            "transflower",
            "--dtypes",
            "--ort-json",
            input.to_str().unwrap(),
        ],
        &[
            "--ort-json",
            "onnxruntime figures of bailando, this is --family transflower",
            "tools/transflower_ort_r_step.py",
        ],
    );
    let _ = std::fs::remove_file(&input);
}

#[test]
fn a_missing_or_wrong_json_is_a_named_error() {
    let dir = std::env::temp_dir();
    let missing = dir.join(format!("duo-bench-ort-{}-absent.json", std::process::id()));
    let m = missing.to_str().unwrap();
    refused(
        &["--family", "transflower", "--ort-json", m],
        &[
            "--ort-json",
            "cannot read it",
            "tools/transflower_ort_r_step.py",
        ],
    );

    let broken = tmp("broken.json", "{\"median_ms\": 1.0,");
    refused(
        &[
            "--family",
            "transflower",
            "--ort-json",
            broken.to_str().unwrap(),
        ],
        &["not JSON", "tools/transflower_ort_r_step.py"],
    );

    let mut v = transflower_json();
    v.as_object_mut().unwrap().remove("median_ms");
    let no_median = tmp("no-median.json", &v.to_string());
    refused(
        &[
            "--family",
            "transflower",
            "--ort-json",
            no_median.to_str().unwrap(),
        ],
        &["no `median_ms`"],
    );

    let mut v = transflower_json();
    v["by_threads"][1]["p99_ms"] = serde_json::json!("slow");
    let bad_list = tmp("bad-list.json", &v.to_string());
    refused(
        &[
            "--family",
            "transflower",
            "--ort-json",
            bad_list.to_str().unwrap(),
        ],
        &["by_threads[1]: no `p99_ms`"],
    );

    let good = tmp("good2.json", &transflower_json().to_string());
    refused(
        &["--family", "bailando", "--ort-json", good.to_str().unwrap()],
        &["onnxruntime figures of transflower, this is --family bailando"],
    );
    refused(
        &["--ort-json", good.to_str().unwrap()],
        &["onnxruntime figures of transflower, this is --family duolando"],
    );
    for p in [broken, no_median, bad_list, good] {
        let _ = std::fs::remove_file(p);
    }
}
