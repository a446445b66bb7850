//! `duolando eval`: the papers' motion metrics (FID_k, FID_g, Div_k,
//! Div_g, FID_cd, Div_cd, BAS, BED, foot-skating ratio) of a folder of
//! generated motions against a folder of real ones (or their saved
//! features), as the authors' evaluation code computes them
//! (docs/EVAL.md).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use serde_json::{json, Map, Value};

use crate::eval::fid::{self, Features};
use crate::eval::{footskate, sets};

/// Flags of `duolando eval`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Folder of generated motions: <name>_00.npy (T, 165) (the follower) and, for the duet metrics, <name>_01.npy (its leader); .bvh also read.
    #[arg(long)]
    pub gen: PathBuf,
    /// Folder of real motions (same layout): the reference of FID and Div.
    #[arg(long, conflicts_with = "real_stats")]
    pub real: Option<PathBuf>,
    /// Real-set features saved earlier with --save-real, instead of --real.
    #[arg(long)]
    pub real_stats: Option<PathBuf>,
    /// Write the real set's per-clip features (JSON) here, for later --real-stats.
    #[arg(long, requires = "real")]
    pub save_real: Option<PathBuf>,
    /// Folder of (T, 54) music features <Genre>_<CC>_<TT>.npy (beat in column 53) for BAS.
    #[arg(long)]
    pub music: Option<PathBuf>,
    /// Write every figure as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

fn mean(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// The name of column `i` of FID_`tag`'s features, where they have names
/// (the kinetic features of FID_k, the geometric ones of FID_g; the
/// cross-distance features of FID_cd are unnamed).
fn feature_name(tag: &str, i: usize) -> Option<String> {
    match tag {
        "k" => crate::eval::kinetic::feature_name(i),
        "g" => crate::eval::manual::feature_name(i),
        _ => None,
    }
}

/// FID_`tag`'s features that are constant over the real set but not over
/// the generated one ([`fid::flat_in_real`]): the authors' normalisation
/// divides them by 1e-10, so they own the FID and the Div. Names them
/// (`fid_<tag>_flat_in_real`) and adds the figures without them
/// (`fid_<tag>_without_flat`, `div_<tag>_without_flat`: ours, not the
/// papers'), with a warning.
fn flat_features(tag: &str, r: &Features, g: &Features, out: &mut Map<String, Value>, warnings: &mut Vec<String>) -> Result<()> {
    let flats = fid::flat_in_real(r, g).with_context(|| format!("FID_{tag}"))?;
    if flats.is_empty() {
        return Ok(());
    }
    let name = |i: usize| feature_name(tag, i);
    let drop: Vec<usize> = flats.iter().map(|f| f.index).collect();
    let kept = fid::scores(&fid::without(r, &drop), &fid::without(g, &drop)).with_context(|| format!("FID_{tag} without its flat features"))?;
    out.insert(
        format!("fid_{tag}_flat_in_real"),
        json!(flats
            .iter()
            .map(|f| json!({"feature": f.index, "name": name(f.index), "real": f.real, "gen_mean": f.gen_mean, "gen_std": f.gen_std}))
            .collect::<Vec<_>>()),
    );
    out.insert(format!("fid_{tag}_without_flat"), json!(kept.fid));
    out.insert(format!("div_{tag}_without_flat"), json!(kept.div_gen));
    out.insert(format!("div_{tag}_real_without_flat"), json!(kept.div_real));
    let listed: Vec<String> = flats
        .iter()
        .map(|f| match name(f.index) {
            Some(n) => format!("{} ({n}: {} in every real clip, generated mean {:.3e})", f.index, f.real, f.gen_mean),
            None => format!("{} ({} in every real clip, generated mean {:.3e})", f.index, f.real, f.gen_mean),
        })
        .collect();
    warnings.push(format!(
        "FID_{tag}/Div_{tag}: feature(s) {} are constant over the real set and vary over the generated one; \
         the papers' normalisation divides them by 1e-10, so they own fid_{tag} and div_{tag} (the authors' code gives the same). \
         Without them (ours, not the papers'): fid_{tag}_without_flat {:.3}, div_{tag}_without_flat {:.3} (real {:.3})",
        listed.join("; "),
        kept.fid,
        kept.div_gen,
        kept.div_real
    ));
    Ok(())
}

/// Features listed by [`mean_shift_report`].
const LARGEST_SHIFTS: usize = 6;

/// Where FID_`tag`'s mean term comes from ([`fid::mean_shifts`]): the term
/// itself (`fid_<tag>_mean_term`; the rest of the FID is the
/// covariances') and the features whose generated mean lies furthest from
/// the real one, in real standard deviations, signed, largest first
/// (`fid_<tag>_largest_shifts`, named where the features have names).
fn mean_shift_report(tag: &str, r: &Features, g: &Features, out: &mut Map<String, Value>) -> Result<()> {
    let shifts = fid::mean_shifts(r, g).with_context(|| format!("FID_{tag}"))?;
    let name = |i: usize| feature_name(tag, i);
    let mut order: Vec<usize> = (0..shifts.len()).collect();
    order.sort_by(|&a, &b| shifts[b].abs().total_cmp(&shifts[a].abs()).then(a.cmp(&b)));
    out.insert(format!("fid_{tag}_mean_term"), json!(shifts.iter().map(|v| v * v).sum::<f64>()));
    out.insert(
        format!("fid_{tag}_largest_shifts"),
        json!(order
            .iter()
            .take(LARGEST_SHIFTS)
            .map(|&i| json!({"feature": i, "name": name(i), "shift_sd": shifts[i]}))
            .collect::<Vec<_>>()),
    );
    Ok(())
}

/// Runs `duolando eval`.
pub fn run(args: Args) -> Result<()> {
    let real = match (&args.real, &args.real_stats) {
        (Some(dir), _) => {
            let (r, _) = sets::compute(dir, None, false).context("real set")?;
            if let Some(path) = &args.save_real {
                sets::save(&r, path)?;
                eprintln!("saved the real set's features ({} clips) to {}", r.clips.len(), path.display());
            }
            Some(r)
        }
        (None, Some(path)) => Some(sets::load_stats(path)?),
        (None, None) => None,
    };
    let (gen, extra) = sets::compute(&args.gen, args.music.as_deref(), true)?;
    let mut out = Map::new();
    let mut notes = Vec::new();
    let mut warnings = Vec::new();
    out.insert("clips_gen".into(), json!(gen.clips.len()));
    out.insert("duets_gen".into(), json!(gen.duets.len()));
    if let Some(real) = &real {
        out.insert("clips_real".into(), json!(real.clips.len()));
        out.insert("duets_real".into(), json!(real.duets.len()));
        for (tag, r, g) in [("k", &real.kinetic, &gen.kinetic), ("g", &real.geometric, &gen.geometric)] {
            let (r, g) = (Features::from_f32(r), Features::from_f32(g));
            let s = fid::scores(&r, &g).with_context(|| format!("FID_{tag}"))?;
            out.insert(format!("fid_{tag}"), json!(s.fid));
            out.insert(format!("div_{tag}"), json!(s.div_gen));
            out.insert(format!("div_{tag}_real"), json!(s.div_real));
            mean_shift_report(tag, &r, &g, &mut out)?;
            flat_features(tag, &r, &g, &mut out, &mut warnings)?;
        }
        if real.cd.len() >= 2 && gen.cd.len() >= 2 {
            let (r, g) = (Features::from_f32(&real.cd), Features::from_f32(&gen.cd));
            let s = fid::scores(&r, &g).context("FID_cd")?;
            out.insert("fid_cd".into(), json!(s.fid));
            out.insert("div_cd".into(), json!(s.div_gen));
            out.insert("div_cd_real".into(), json!(s.div_real));
            mean_shift_report("cd", &r, &g, &mut out)?;
            flat_features("cd", &r, &g, &mut out, &mut warnings)?;
        } else {
            notes.push(format!(
                "FID_cd/Div_cd need two duets (<name>_01 leaders) in each set: real {}, generated {}",
                real.duets.len(),
                gen.duets.len()
            ));
        }
    } else {
        notes.push(
            "FID and Div need --real DIR or --real-stats FILE (the demo models' held-out dances: \
             assets/demo_real_stats.json, assets/bailando_demo_real_stats.json)"
                .to_string(),
        );
    }
    match (&extra.bas_error, mean(&extra.bas)) {
        (Some(e), _) => notes.push(format!("BAS: {e}")),
        (None, Some(v)) => {
            out.insert("bas".into(), json!(v));
        }
        (None, None) => notes.push("BAS needs --music DIR".into()),
    }
    match (&extra.bed_error, mean(&extra.bed)) {
        (Some(e), _) => notes.push(format!("BED: {e}")),
        (None, Some(v)) => {
            out.insert("bed".into(), json!(v));
        }
        (None, None) => notes.push("BED needs <name>_01 leader files next to the _00 clips".into()),
    }
    if extra.fs_all.is_empty() {
        notes.push("foot skating is counted on .npy files only".into());
    } else {
        out.insert("fsr".into(), json!(footskate::ratio(&extra.fs_all)));
        out.insert("fsr_00".into(), json!(footskate::ratio(&extra.fs_00)));
    }
    for (k, v) in &out {
        match v {
            Value::Number(n) if n.is_f64() => println!("{k:<12} {:.6}", n.as_f64().unwrap_or(f64::NAN)),
            _ => println!("{k:<12} {v}"),
        }
    }
    for n in &notes {
        eprintln!("not computed: {n}");
    }
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    if let Some(path) = &args.json {
        let mut doc = out.clone();
        doc.insert("not_computed".into(), json!(notes));
        doc.insert("warnings".into(), json!(warnings));
        std::fs::write(path, serde_json::to_string_pretty(&Value::Object(doc))?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if out.len() <= 2 && notes.len() > 2 {
        bail!("no metric could be computed");
    }
    Ok(())
}
