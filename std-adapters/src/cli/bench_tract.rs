//! The baseline a user would otherwise run: tract (tract-onnx 0.21, the
//! ONNX runtime the golden tests use) on the full-size R step exported by
//! `tools/reference/export_full_r_step.py`, timed in the same run as our
//! own steps (`duolando bench --tract-onnx FILE`, cargo feature `tract`).

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::anyhow;

/// Where the export script writes by default.
pub const DEFAULT_ONNX: &str = "/tmp/duolando_full/full_r_step.onnx";

/// How to make the file, for the bench's messages.
pub const HOW: &str = "python3 -m tools.reference.export_full_r_step from the repository root, with torch installed (pip install -r tools/requirements.txt; ~0.8 GB written, a few minutes), then `cargo run --release -p duolando --features tract -- bench`";

/// The ONNX file to use: the given one, else the default if it exists.
pub fn onnx_path(given: Option<&Path>) -> Option<PathBuf> {
    match given {
        Some(p) => Some(p.to_path_buf()),
        None => Some(PathBuf::from(DEFAULT_ONNX)).filter(|p| p.exists()),
    }
}

/// Timed runs of the R step in tract (one thread), after `warmup` runs,
/// and the largest relative difference of its logits from torch's
/// (`max |a - b| / max(1, max |b|)`, from the inputs and logits the export
/// wrote next to the file).
#[cfg(feature = "tract")]
pub fn r_steps(path: &Path, warmup: usize, runs: usize) -> anyhow::Result<(Vec<Duration>, f32)> {
    use crate::npy::{read_f32_2d, read_i64_2d};
    use anyhow::Context;
    use std::time::Instant;
    use tract_onnx::prelude::*;
    let io = path.with_file_name("full_r_step_io");
    let t0 = Instant::now();
    let typed = tract_onnx::onnx()
        .model_for_path(path)
        .and_then(|m| m.into_typed())
        .and_then(|m| m.into_decluttered())
        .map_err(|e| anyhow!("tract cannot load {}: {e:?}", path.display()))?;
    let (model, optimized) = match typed.clone().into_optimized() {
        Ok(m) => (m, true),
        Err(_) => (typed, false),
    };
    let plan = model
        .into_runnable()
        .map_err(|e| anyhow!("tract cannot plan {}: {e:?}", path.display()))?;
    eprintln!(
        "tract: {} loaded and planned in {:.1} s ({})",
        path.display(),
        t0.elapsed().as_secs_f64(),
        if optimized {
            "optimized"
        } else {
            "decluttered: the optimizer refused it"
        }
    );
    let mut inputs: TVec<TValue> = TVec::new();
    for name in [
        "f_up", "f_down", "f_lhand", "f_rhand", "f_transl", "music", "l_up", "l_down", "l_lhand",
        "l_rhand",
    ] {
        let f = io.join(format!("{name}.npy"));
        let t = if name == "music" {
            let a = read_f32_2d(&f, Some(54), name)
                .with_context(|| format!("{} (written by the export script)", f.display()))?;
            Tensor::from_shape(&[1, a.rows, 54], &a.data)?
        } else {
            let a = read_i64_2d(&f, None, name)
                .with_context(|| format!("{} (written by the export script)", f.display()))?;
            Tensor::from_shape(&[1, a.data.len()], &a.data)?
        };
        inputs.push(t.into());
    }
    inputs.push(Tensor::from_shape(&[1], &[1.0f32])?.into());
    let want = read_f32_2d(&io.join("logits.npy"), None, "logits")?;
    let mut times = Vec::new();
    let mut err = 0.0f32;
    for i in 0..warmup + runs {
        let t = Instant::now();
        let out = plan
            .run(inputs.clone())
            .map_err(|e| anyhow!("tract run failed: {e:?}"))?;
        let dt = t.elapsed();
        if i >= warmup {
            times.push(dt);
        }
        if i == 0 {
            let got = out[0]
                .as_slice::<f32>()
                .map_err(|e| anyhow!("tract output: {e:?}"))?;
            if got.len() != want.data.len() {
                return Err(anyhow!(
                    "tract gave {} logits, torch {}",
                    got.len(),
                    want.data.len()
                ));
            }
            let scale = want.data.iter().fold(1.0f32, |m, v| m.max(v.abs()));
            err = got
                .iter()
                .zip(&want.data)
                .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()))
                / scale;
        }
    }
    Ok((times, err))
}

#[cfg(not(feature = "tract"))]
pub fn r_steps(path: &Path, _: usize, _: usize) -> anyhow::Result<(Vec<Duration>, f32)> {
    Err(anyhow!(
        "{} is present, but this binary was built without the `tract` feature: {HOW}",
        path.display()
    ))
}
