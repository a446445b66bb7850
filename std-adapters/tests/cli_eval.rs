//! `duolando eval` end to end on the recipe motion set (rebuilt bit for bit
//! by `duolando::eval::testset`, checked against the checksums of
//! tests/fixtures/metrics/goldens.json): every figure equals the authors'
//! Python (tools/metrics_goldens.py) within the named tolerances below.

use std::path::{Path, PathBuf};
use std::process::Command;

use duolando::eval::testset::Recipe;
use serde_json::Value;

/// FID_k / FID_g / FID_cd: the authors normalise in float32 and take the
/// real part of scipy's `sqrtm` of a rank-deficient product (24 generated
/// clips, 72 / 32 / 100 features); we use a symmetric eigen solve in f64.
/// Observed: at most 1.4e-7.
const FID_REL_TOL: f64 = 1e-6;
/// Div_*: float32 normalisation and a float32 running sum in the authors' code.
/// Observed: at most 4.2e-7.
const DIV_REL_TOL: f64 = 2e-6;
/// BAS / BED: float64 both sides, beats equal.
const BEAT_REL_TOL: f64 = 1e-12;

fn goldens() -> Value {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/metrics/goldens.json");
    serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap()
}

fn recipe(g: &Value) -> Recipe {
    let r = &g["recipe"];
    Recipe {
        seed: r["seed"].as_u64().unwrap(),
        n_real: r["n_real"].as_u64().unwrap() as usize,
        n_gen: r["n_gen"].as_u64().unwrap() as usize,
        base_pose_mm: r["base_pose_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_i64().unwrap())
            .collect(),
    }
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("duo-eval-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn duolando(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_duolando"))
        .args(args)
        .output()
        .unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Writes the set and checks that it is the one the goldens were made on.
fn build(dir: &Path) -> Value {
    let g = goldens();
    let sums = recipe(&g).write(dir).unwrap();
    let want = g["checksums"].as_object().unwrap();
    assert_eq!(sums.len(), want.len());
    for (file, sum) in sums {
        assert_eq!(
            sum,
            want[&file].as_u64().unwrap(),
            "{file}: the recipe set differs from the script's"
        );
    }
    g
}

fn run_json(args: &[&str], json: &Path) -> Value {
    let out = duolando(args);
    assert!(
        out.status.success(),
        "eval failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&std::fs::read(json).unwrap()).unwrap()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-30)
}

fn compare(got: &Value, want: &Value) {
    let mut report = Vec::new();
    for (key, tol) in [
        ("fid_k", FID_REL_TOL),
        ("fid_g", FID_REL_TOL),
        ("fid_cd", FID_REL_TOL),
        ("div_k", DIV_REL_TOL),
        ("div_g", DIV_REL_TOL),
        ("div_cd", DIV_REL_TOL),
        ("div_k_real", DIV_REL_TOL),
        ("div_g_real", DIV_REL_TOL),
        ("div_cd_real", DIV_REL_TOL),
        ("bas", BEAT_REL_TOL),
        ("bed", BEAT_REL_TOL),
        ("fsr", 0.0),
        ("fsr_00", 0.0),
    ] {
        let (g, w) = (
            got[key].as_f64().unwrap_or_else(|| panic!("{key} missing")),
            want[key].as_f64().unwrap(),
        );
        let r = rel(g, w);
        report.push(format!("{key} {g:.9} vs {w:.9} rel {r:.1e}"));
        assert!(
            r <= tol,
            "{key}: {g} vs authors' {w} (relative {r:e} > {tol:e})\n{}",
            report.join("\n")
        );
    }
    eprintln!("{}", report.join("\n"));
}

#[test]
fn eval_matches_the_authors_figures_and_saved_stats_give_the_same() {
    let dir = tmp("full");
    let g = build(&dir);
    let want = &g["figures"];
    let (gen, real, music) = (dir.join("gen"), dir.join("real"), dir.join("music"));
    let (json, stats) = (dir.join("figures.json"), dir.join("real_stats.json"));
    let got = run_json(
        &[
            "eval",
            "--gen",
            s(&gen),
            "--real",
            s(&real),
            "--music",
            s(&music),
            "--save-real",
            s(&stats),
            "--json",
            s(&json),
        ],
        &json,
    );
    assert_eq!(got["clips_gen"], 24);
    assert_eq!(got["clips_real"], 80);
    compare(&got, want);
    // The saved real-set features reproduce every figure.
    let json2 = dir.join("figures2.json");
    let again = run_json(
        &[
            "eval",
            "--gen",
            s(&gen),
            "--real-stats",
            s(&stats),
            "--music",
            s(&music),
            "--json",
            s(&json2),
        ],
        &json2,
    );
    for key in [
        "fid_k",
        "fid_g",
        "fid_cd",
        "div_k",
        "div_g",
        "div_cd",
        "div_k_real",
        "bas",
        "bed",
        "fsr",
    ] {
        assert_eq!(again[key], got[key], "{key} from --real-stats");
    }
    // Each FID's mean term is part of it (the covariance part is >= 0), and
    // its largest per-feature shifts come largest first, their squares
    // within the term; the kinetic ones are named.
    for tag in ["k", "g", "cd"] {
        let fid = got[format!("fid_{tag}")].as_f64().unwrap();
        let term = got[format!("fid_{tag}_mean_term")].as_f64().unwrap();
        assert!(term >= 0.0 && term <= fid * (1.0 + 1e-9) + 1e-9, "{tag}: mean term {term}, FID {fid}");
        let top = got[format!("fid_{tag}_largest_shifts")].as_array().unwrap();
        assert_eq!(top.len(), 6, "{tag}");
        let sd: Vec<f64> = top.iter().map(|e| e["shift_sd"].as_f64().unwrap()).collect();
        assert!(sd.windows(2).all(|w| w[0].abs() >= w[1].abs()), "{tag}: {sd:?}");
        assert!(sd.iter().map(|v| v * v).sum::<f64>() <= term * (1.0 + 1e-12), "{tag}");
        if tag == "k" {
            assert!(top.iter().all(|e| e["name"].as_str().is_some_and(|n| n.contains("kinetic") || n.contains("expenditure"))));
        }
        assert_eq!(again[format!("fid_{tag}_mean_term")], got[format!("fid_{tag}_mean_term")], "{tag} from --real-stats");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn without_real_or_music_the_missing_metrics_are_named() {
    let dir = tmp("partial");
    build(&dir);
    let json = dir.join("figures.json");
    let out = duolando(&["eval", "--gen", s(&dir.join("gen")), "--json", s(&json)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("not computed: FID and Div need --real"),
        "{err}"
    );
    assert!(err.contains("not computed: BAS needs --music"), "{err}");
    let got: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert!(got.get("fid_k").is_none());
    assert!(got["bed"].as_f64().is_some());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_inputs_fail_with_named_errors() {
    let dir = tmp("bad");
    // Missing folder.
    let out = duolando(&["eval", "--gen", s(&dir.join("nope"))]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot read the motion folder"));
    // Empty folder.
    let out = duolando(&["eval", "--gen", s(&dir)]);
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("no <name>_00.npy"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // A two-frame clip: too short for the kinetic features.
    duolando::npy::write_f32(&dir.join("A_01_01_00.npy"), &[0.0; 330], &[2, 165]).unwrap();
    let out = duolando(&["eval", "--gen", s(&dir)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        err.contains("kinetic features needs at least 3 frames, the clip has 2"),
        "{err}"
    );
    // Wrong width.
    std::fs::remove_file(dir.join("A_01_01_00.npy")).unwrap();
    duolando::npy::write_f32(&dir.join("A_01_01_00.npy"), &[0.0; 40], &[4, 10]).unwrap();
    let out = duolando(&["eval", "--gen", s(&dir)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("165 columns"), "{err}");
    // A statistics file that is not one.
    std::fs::write(dir.join("stats.json"), "{}").unwrap();
    let out = duolando(&[
        "eval",
        "--gen",
        s(&dir),
        "--real-stats",
        s(&dir.join("stats.json")),
    ]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a real-set statistics file"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// BVH clips are read through `duolando dance`'s leader loader: the
/// features of a BVH duet set are those of the same takes as npy, up to the
/// BVH text's round-off (centimetres, 6 decimals of degrees).
#[test]
fn bvh_clips_give_the_features_of_their_npy() {
    use duolando::export::{bvh, Motion};
    /// Largest relative difference of a kinetic feature (npy vs BVH); observed 1.5e-5.
    const KINETIC_REL: f64 = 1e-3;
    /// Largest difference of a geometric feature (a fraction of 179 frames:
    /// one test flipping on one frame); observed 0.
    const GEOMETRIC_ABS: f64 = 0.006;
    let dir = tmp("bvh");
    let (npy_dir, bvh_dir) = (dir.join("npy"), dir.join("bvh"));
    std::fs::create_dir_all(&npy_dir).unwrap();
    std::fs::create_dir_all(&bvh_dir).unwrap();
    for seed in [3u64, 4, 5] {
        let take = duolando::synth::demo_take(seed, 6.0);
        for (role, track) in [("00", &take.follower), ("01", &take.leader)] {
            let name = format!("Take_{seed:02}_00_{role}");
            duolando::npy::write_f32(
                &npy_dir.join(format!("{name}.npy")),
                &track.positions,
                &[take.frames, 165],
            )
            .unwrap();
            bvh::write(
                &bvh_dir.join(format!("{name}.bvh")),
                &Motion::from_track(track),
                30.0,
                bvh::Units::Centimetres,
            )
            .unwrap();
        }
    }
    let stats = |real: &Path, out: &str| -> Value {
        let file = dir.join(out);
        let json = dir.join(format!("{out}.figures.json"));
        run_json(
            &[
                "eval",
                "--gen",
                s(&npy_dir),
                "--real",
                s(real),
                "--save-real",
                s(&file),
                "--json",
                s(&json),
            ],
            &json,
        );
        serde_json::from_slice(&std::fs::read(&file).unwrap()).unwrap()
    };
    let (a, b) = (stats(&npy_dir, "npy.json"), stats(&bvh_dir, "bvh.json"));
    assert_eq!(a["clips"], b["clips"]);
    assert_eq!(a["duets"], b["duets"]);
    let rows = |v: &Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .flat_map(|r| r.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
            .collect()
    };
    let (ka, kb) = (rows(&a["kinetic"]), rows(&b["kinetic"]));
    let kin = ka
        .iter()
        .zip(&kb)
        .map(|(x, y)| (x - y).abs() / x.abs().max(1e-3))
        .fold(0.0, f64::max);
    let (ga, gb) = (rows(&a["geometric"]), rows(&b["geometric"]));
    let geo = ga
        .iter()
        .zip(&gb)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    eprintln!("npy vs BVH: kinetic max rel {kin:.2e}, geometric max abs {geo:.3}");
    assert!(kin <= KINETIC_REL, "kinetic features npy vs BVH: {kin}");
    assert!(geo <= GEOMETRIC_ABS, "geometric features npy vs BVH: {geo}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A geometric feature that never fires in the real set (a rigid spine:
/// the chest never moves along belly->chest) but does in the generated one
/// (the chest jitters 1 cm along the spine) is divided by 1e-10 by the
/// papers' normalisation and owns FID_g: `eval` keeps that figure, names the
/// feature (`fid_g_flat_in_real`, a warning) and adds FID_g / Div_g
/// without it; the kinetic features flat in the real set are named too.
/// (Found on the Bailando demo: FID_g 3.3e14, 78.4 without.)
#[test]
fn a_geometric_feature_flat_in_the_real_set_is_named_and_left_out_of_a_second_figure() {
    let dir = tmp("flat");
    build(&dir);
    let base = duolando::npy::read_f32_2d(
        &dir.join("real").join(
            std::fs::read_dir(dir.join("real"))
                .unwrap()
                .map(|e| e.unwrap().file_name())
                .find(|n| n.to_string_lossy().ends_with("_00.npy"))
                .unwrap(),
        ),
        Some(165),
        "pose",
    )
    .unwrap();
    let pose = &base.data[..165];
    let frames = 60;
    for (sub, jitter) in [("real2", 0.0f32), ("gen2", 0.01)] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        for k in 0..6 {
            let mut m = Vec::with_capacity(frames * 165);
            let speed = 0.002 * (k + 1) as f32;
            for t in 0..frames {
                let mut p = pose.to_vec();
                for j in 0..55 {
                    p[3 * j] += speed * t as f32;
                }
                if t % 2 == 1 {
                    // The chest (joint 9) along the belly (3) -> chest direction.
                    let d: Vec<f32> = (0..3).map(|c| pose[27 + c] - pose[9 + c]).collect();
                    let n = d.iter().map(|v| v * v).sum::<f32>().sqrt();
                    for c in 0..3 {
                        p[27 + c] += jitter * d[c] / n;
                    }
                }
                m.extend(p);
            }
            duolando::npy::write_f32(
                &dir.join(sub).join(format!("C{k}_00.npy")),
                &m,
                &[frames, 165],
            )
            .unwrap();
        }
    }
    let json = dir.join("flat.json");
    let out = duolando(&[
        "eval",
        "--gen",
        s(&dir.join("gen2")),
        "--real",
        s(&dir.join("real2")),
        "--json",
        s(&json),
    ]);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{err}");
    let v: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let flats = v["fid_g_flat_in_real"]
        .as_array()
        .expect("flat geometric features reported");
    let ids: Vec<u64> = flats
        .iter()
        .map(|f| f["feature"].as_u64().unwrap())
        .collect();
    assert!(ids.contains(&4) && ids.contains(&5), "{ids:?}");
    assert!(
        flats[0]["name"]
            .as_str()
            .is_some_and(|n| n.contains("chest")),
        "{flats:?}"
    );
    assert!(
        v["fid_g"].as_f64().unwrap() > 1e10,
        "the papers' figure is kept: {}",
        v["fid_g"]
    );
    // The chest's jitter also moves it vertically, which no real clip
    // does: a kinetic feature flat in the real set, named as well.
    let kinetic = v["fid_k_flat_in_real"]
        .as_array()
        .expect("flat kinetic features reported");
    assert!(
        kinetic.iter().all(|f| f["name"]
            .as_str()
            .is_some_and(|n| n.contains("kinetic"))),
        "{kinetic:?}"
    );
    let kept = v["fid_g_without_flat"].as_f64().unwrap();
    assert!(kept.is_finite() && kept < 1e6, "{kept}");
    assert!(
        err.contains("warning: FID_g/Div_g") && err.contains("fid_g_without_flat"),
        "{err}"
    );
    assert!(v["warnings"].as_array().is_some_and(|w| !w.is_empty()));
    // The same set against itself: nothing flat, no warning.
    let out = duolando(&[
        "eval",
        "--gen",
        s(&dir.join("real2")),
        "--real",
        s(&dir.join("real2")),
    ]);
    assert!(out.status.success());
    assert!(!String::from_utf8_lossy(&out.stderr).contains("warning"));
}

/// The demo models' bundled reference statistics (assets/) load with
/// --real-stats and score a set: the recipe's generated clips against each,
/// every FID and Div finite (20 Duolando duets; 26 Bailando solo dancers).
#[test]
fn the_bundled_reference_statistics_score_a_set() {
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
    let dir = tmp("bundled");
    build(&dir);
    for (file, clips, duets) in [
        ("demo_real_stats.json", 20, 20),
        ("bailando_demo_real_stats.json", 26, 0),
    ] {
        let stats = assets.join(file);
        let doc: Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        assert_eq!(doc["clips"].as_array().unwrap().len(), clips, "{file}");
        assert_eq!(doc["duets"].as_array().unwrap().len(), duets, "{file}");
        let json = dir.join(format!("{file}.out.json"));
        let v = run_json(
            &[
                "eval",
                "--gen",
                s(&dir.join("gen")),
                "--real-stats",
                s(&stats),
                "--json",
                s(&json),
            ],
            &json,
        );
        assert_eq!(v["clips_real"].as_u64(), Some(clips as u64), "{file}");
        for k in [
            "fid_k",
            "fid_g",
            "div_k",
            "div_g",
            "div_k_real",
            "div_g_real",
        ] {
            assert!(
                v[k].as_f64().is_some_and(f64::is_finite),
                "{file}: {k} = {}",
                v[k]
            );
        }
        assert_eq!(v["fid_cd"].is_number(), duets >= 2, "{file}");
    }
}
