//! The metric code against the authors' own (tests/fixtures/metrics/goldens.json,
//! written by tools/metrics_goldens.py): per-clip features, beats and
//! scores of the recipe set, and FID / Div on small feature matrices.

use serde_json::Value;

use super::testset::{checksum, Recipe};
use super::*;

/// Relative tolerance of f32 features (kinetic, cross-distance): the
/// authors round float64 (kinetic) or accumulate float32 (cross distance).
pub const FEATURE_REL_TOL: f64 = 2e-6;
/// Relative tolerance of FID and Div on the feature matrices (the authors
/// normalise in float32).
pub const FID_REL_TOL: f64 = 1e-5;
/// Relative tolerance of one clip's BAS / BED (float64 both sides).
pub const SCORE_REL_TOL: f64 = 1e-12;

pub(crate) fn goldens() -> Value {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/fixtures/metrics/goldens.json");
    serde_json::from_slice(&std::fs::read(&path).expect("goldens.json"))
        .expect("goldens.json parses")
}

pub(crate) fn recipe(g: &Value) -> Recipe {
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

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-30)
}

/// Largest relative difference of `got` vs `want`, with differences below
/// `floor` (absolute) ignored.
fn worst(got: &[f32], want: &[f64], floor: f64) -> f64 {
    assert_eq!(got.len(), want.len());
    got.iter()
        .zip(want)
        .map(|(&g, &w)| {
            if (g as f64 - w).abs() <= floor {
                0.0
            } else {
                rel(g as f64, w)
            }
        })
        .fold(0.0, f64::max)
}

#[test]
fn recipe_motions_are_bit_identical_to_the_scripts() {
    let g = goldens();
    let r = recipe(&g);
    let sums = g["checksums"].as_object().unwrap();
    for (set, sub) in [(0u64, "real"), (1, "gen")] {
        for k in 0..3u64 {
            let nm = Recipe::name(set, k);
            let f = r.motion(set, k, 0);
            let l = r.motion(set, k, 1);
            let m = r.music(set, k, f.len() / 165);
            assert_eq!(
                checksum(&f),
                sums[&format!("{sub}/{nm}_00.npy")].as_u64().unwrap(),
                "{nm} follower"
            );
            assert_eq!(
                checksum(&l),
                sums[&format!("{sub}/{nm}_01.npy")].as_u64().unwrap(),
                "{nm} leader"
            );
            assert_eq!(
                checksum(&m),
                sums[&format!("music/{nm}.npy")].as_u64().unwrap(),
                "{nm} music"
            );
        }
    }
}

#[test]
fn per_clip_figures_match_the_authors_code() {
    let g = goldens();
    let r = recipe(&g);
    let (mut wk, mut wcd, mut wba, mut wbe) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for c in g["clips"].as_array().unwrap() {
        let set = if c["set"] == "real" { 0 } else { 1 };
        let k = c["k"].as_u64().unwrap();
        let f = r.motion(set, k, 0);
        let l = r.motion(set, k, 1);
        let m = r.music(set, k, f.len() / 165);
        let name = c["name"].as_str().unwrap();

        let kin = kinetic::features(&f).unwrap();
        wk = wk.max(worst(&kin, &floats(&c["kinetic"]), 1e-9));
        let geo = manual::features(&f).unwrap();
        let want: Vec<f32> = floats(&c["geometric"]).iter().map(|&v| v as f32).collect();
        assert_eq!(geo, want, "{name}: geometric features must be equal");
        let cdf = cd::features(&f, &l).unwrap();
        wcd = wcd.max(worst(&cdf, &floats(&c["cd"]), 0.0));

        let beats: Vec<u64> = bas::motion_beats(&f)
            .unwrap()
            .into_iter()
            .map(|b| b as u64)
            .collect();
        let want: Vec<u64> = c["motion_beats"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert_eq!(beats, want, "{name}: motion beats");
        let lb: Vec<u64> = bas::motion_beats(&l)
            .unwrap()
            .into_iter()
            .map(|b| b as u64)
            .collect();
        let want: Vec<u64> = c["leader_beats"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        assert_eq!(lb, want, "{name}: leader beats");
        wba = wba.max(rel(
            bas::clip_score(&f, &m, 54).unwrap(),
            c["ba"].as_f64().unwrap(),
        ));
        wbe = wbe.max(rel(
            bed::duet_score(&f, &l).unwrap(),
            c["be"].as_f64().unwrap(),
        ));

        let fs = footskate::clip_counts(&f).unwrap();
        assert_eq!(
            [fs.0 as u64, fs.1 as u64],
            [c["fs"][0].as_u64().unwrap(), c["fs"][1].as_u64().unwrap()],
            "{name}: foot skating"
        );
    }
    eprintln!("max rel diff vs authors: kinetic {wk:.2e}, cross-distance {wcd:.2e}, BA {wba:.2e}, BE {wbe:.2e}");
    assert!(
        wk <= FEATURE_REL_TOL,
        "kinetic features: max relative difference {wk:e}"
    );
    assert!(
        wcd <= FEATURE_REL_TOL,
        "cross-distance features: max relative difference {wcd:e}"
    );
    assert!(wba <= SCORE_REL_TOL, "BA: max relative difference {wba:e}");
    assert!(wbe <= SCORE_REL_TOL, "BE: max relative difference {wbe:e}");
}

#[test]
fn fid_and_div_match_the_authors_code() {
    let g = goldens();
    for (i, case) in g["fid_cases"].as_array().unwrap().iter().enumerate() {
        let rows =
            |v: &Value| fid::Features::new(v.as_array().unwrap().iter().map(floats).collect());
        let s = fid::scores(&rows(&case["real"]), &rows(&case["gen"])).unwrap();
        let (f, dg, dr) = (
            case["fid"].as_f64().unwrap(),
            case["div_gen"].as_f64().unwrap(),
            case["div_real"].as_f64().unwrap(),
        );
        eprintln!(
            "case {i}: FID {} vs {f} (rel {:.2e}), Div {:.2e} {:.2e}",
            s.fid,
            rel(s.fid, f),
            rel(s.div_gen, dg),
            rel(s.div_real, dr)
        );
        assert!(
            rel(s.fid, f) <= FID_REL_TOL,
            "case {i}: FID {} vs {f}",
            s.fid
        );
        assert!(
            rel(s.div_gen, dg) <= FID_REL_TOL,
            "case {i}: Div {} vs {dg}",
            s.div_gen
        );
        assert!(
            rel(s.div_real, dr) <= FID_REL_TOL,
            "case {i}: real Div {} vs {dr}",
            s.div_real
        );
    }
}
