//! `duolando bench --isa a,b,...` (issue #40): the bench once per ISA in
//! one invocation, every line and JSON key labelled with its ISA (and the
//! CPU model), and an ISA this CPU lacks refused by name before anything
//! runs; `--kernels`: the int8 MAC peak per ISA and each GEMM shape's
//! fraction of it. `--dtypes` with no value skips the (full-size) model
//! benches, so these runs take seconds.

mod common;
use common::bench;

use duolando_core::kernels::simd::Isa;

fn name(isa: Isa) -> &'static str {
    match isa {
        Isa::Scalar => "scalar",
        Isa::Avx2 => "avx2",
        Isa::AvxVnni => "avxvnni",
        Isa::Avx512 => "avx512",
        Isa::Avx512Vnni => "avx512vnni",
        Isa::Neon => "neon",
        Isa::NeonDot => "neondot",
    }
}

#[test]
fn kernels_run_once_per_isa_labelled_with_isa_and_cpu() {
    let supported = duolando::simd::supported();
    // The best ISA and scalar (the two ends; both on every CPU).
    let isas: Vec<&str> = if supported[0] == Isa::Scalar {
        vec!["scalar"]
    } else {
        vec![name(supported[0]), "scalar"]
    };
    let json = std::env::temp_dir().join(format!("duo-bench-isa-{}.json", std::process::id()));
    let o = bench(&[
        "--kernels",
        "--dtypes",
        "--runs",
        "1",
        "--isa",
        &isas.join(","),
        "--json",
        json.to_str().unwrap(),
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let cpu = duolando::kernel_bench::cpu_name();
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let _ = std::fs::remove_file(&json);
    assert_eq!(j["cpu"], cpu.as_str());
    assert_eq!(j["isas"], serde_json::json!(isas));
    let shapes = duolando::kernel_bench::SHAPES;
    for isa in &isas {
        let label = format!("[{isa} | {cpu}] ");
        let lines: Vec<&str> = out.lines().filter(|l| l.starts_with(&label)).collect();
        // The peak line, then one line per shape.
        assert_eq!(lines.len(), 1 + shapes.len(), "{isa}:\n{out}");
        assert!(lines[0].contains("int8 MAC peak"), "{}", lines[0]);
        let peak = j[format!("peak_gmacs_{isa}")]
            .as_f64()
            .unwrap_or_else(|| panic!("peak_gmacs_{isa} in {j}"));
        assert!(peak > 0.1, "{isa}: peak {peak}");
        // Each run's `isa` is the name `--isa` took.
        assert_eq!(j[format!("isa_{isa}")], *isa, "{j}");
        for s in shapes {
            let g = j[format!("gemm_{}_gmacs_{isa}", s.key)].as_f64().unwrap();
            let f = j[format!("gemm_{}_of_peak_{isa}", s.key)].as_f64().unwrap();
            let pk = j[format!("gemm_{}_peak_gmacs_{isa}", s.key)]
                .as_f64()
                .unwrap();
            assert!(
                g > 0.0 && pk > 0.1 && (f - g / pk).abs() < 1e-9 * f.max(1.0),
                "{isa} {}: {g} GMAC/s, {f} of {pk}",
                s.key
            );
            assert!(
                lines.iter().any(|l| l.contains(s.what)),
                "{isa}: no {} line",
                s.what
            );
        }
    }
    // No unlabelled figures but the probes' header (ISA-independent).
    for l in out
        .lines()
        .filter(|l| !isas.iter().any(|i| l.starts_with(&format!("[{i} | "))))
    {
        assert!(
            l.starts_with(&format!("int8 MAC peaks on {cpu}")),
            "unlabelled line: {l}"
        );
    }
}

#[test]
fn an_isa_this_cpu_lacks_is_refused_by_name_before_anything_runs() {
    let supported = duolando::simd::supported();
    let missing: Vec<&str> = ["neondot", "neon", "avx512vnni", "avx512", "avxvnni", "avx2"]
        .into_iter()
        .filter(|n| !supported.contains(&duolando::simd::parse(n).unwrap()))
        .chain((!duolando::simd::amx_usable()).then_some("avx512amx"))
        .chain((!duolando::simd::i8mm_usable()).then_some("neoni8mm"))
        .collect();
    assert!(
        !missing.is_empty(),
        "no ISA family is missing on any CPU: x86 lacks NEON, aarch64 AVX"
    );
    for m in missing {
        let o = bench(&[
            "--kernels",
            "--dtypes",
            "--runs",
            "1",
            "--isa",
            &format!("scalar,{m}"),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{m} accepted");
        assert!(
            err.contains(&format!("ISA '{m}': this CPU does not have it")),
            "{m}: {err}"
        );
        assert!(
            o.stdout.is_empty(),
            "{m}: ran before refusing: {}",
            String::from_utf8_lossy(&o.stdout)
        );
    }
    let o = bench(&["--dtypes", "--isa", "avx9"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown ISA 'avx9'"));
}

#[test]
fn zero_runs_steps_threads_or_sessions_are_refused_by_name_not_a_panic() {
    // `--s-steps 0` used to reach the timing summary with no samples and
    // panic (exit 101) after building the model.
    for (flag, value) in [
        ("--runs", "0"),
        ("--s-steps", "0"),
        ("--threads", "1,0"),
        ("--batch", "0"),
    ] {
        let o = bench(&["--dtypes", flag, value]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(
            err.contains(flag) && err.contains("0"),
            "{flag} {value}: {err}"
        );
        assert!(o.stdout.is_empty(), "{flag} {value}: ran before refusing");
    }
}

#[test]
fn a_shift_outside_the_window_or_for_transflower_is_refused_before_anything_runs() {
    for (args, want) in [
        (&["--dtypes", "--shift", "0"][..], "--shift"),
        (&["--dtypes", "--shift", "30"][..], "window shift is 1..=29"),
        (
            &["--dtypes", "--family", "bailando", "--shift", "29"][..],
            "bailando model's window shift is 1..=28",
        ),
        (
            &["--dtypes", "--family", "transflower", "--shift", "15"][..],
            "not for --family transflower",
        ),
    ] {
        let o = bench(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} accepted");
        assert!(err.contains(want), "{args:?}: {err}");
        assert!(o.stdout.is_empty(), "{args:?}: ran before refusing");
    }
}
