//! The Transflower feature scaler in a plain file: the authors standardise
//! every feature with an sklearn `StandardScaler` (pickled as
//! `<feature>_scaler.pkl`); `tools/transflower_scalers.py` writes its
//! effective affine map as JSON, and generation undoes it as
//! `inverse_transform` does: `x = z * scale + mean` (here in f64).
//!
//! The file (docs/TRANSFLOWER.md "The scaler file"):
//! `{"format": "duolando-transflower-scaler", "version": 1, "width": C,
//! "mean": [C numbers], "scale": [C numbers], ...}`; other keys (`source`,
//! `with_mean`, `with_std`, `var`, `n_samples_seen`) are informative.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Deserialize;

/// The `format` value of a scaler file.
pub const FORMAT: &str = "duolando-transflower-scaler";
/// The version this reader knows.
pub const VERSION: u32 = 1;

#[derive(Deserialize)]
struct File {
    format: String,
    version: u32,
    width: usize,
    mean: Vec<f64>,
    scale: Vec<f64>,
}

/// A feature scaler: per column `mean` and `scale` (both of width C).
#[derive(Clone, Debug, PartialEq)]
pub struct Scaler {
    pub mean: Vec<f64>,  // (C,)
    pub scale: Vec<f64>, // (C,)
}

impl Scaler {
    /// Reads a scaler file; every refusal names the file and the problem.
    pub fn read(path: &Path) -> Result<Scaler> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the scaler {}", path.display()))?;
        Scaler::parse(&text).with_context(|| format!("scaler {}", path.display()))
    }

    /// Parses and checks the JSON text: format and version, `mean` and
    /// `scale` of `width` finite values, every scale > 0.
    pub fn parse(text: &str) -> Result<Scaler> {
        let f: File = serde_json::from_str(text).context("not a scaler file (expected JSON with format, version, width, mean, scale: tools/transflower_scalers.py writes it)")?;
        if f.format != FORMAT {
            bail!("format {:?}, expected {FORMAT:?}", f.format);
        }
        if f.version != VERSION {
            bail!("version {}, this reader knows version {VERSION}", f.version);
        }
        for (name, v) in [("mean", &f.mean), ("scale", &f.scale)] {
            if v.len() != f.width {
                bail!("`{name}` has {} values, `width` says {}", v.len(), f.width);
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                bail!("`{name}`[{i}] = {} is not finite", v[i]);
            }
        }
        if let Some(i) = f.scale.iter().position(|&s| s <= 0.0) {
            bail!(
                "`scale`[{i}] = {} is not > 0 (sklearn stores 1 for a constant column, never 0)",
                f.scale[i]
            );
        }
        if f.width == 0 {
            bail!("width 0");
        }
        Ok(Scaler {
            mean: f.mean,
            scale: f.scale,
        })
    }

    /// Columns per row.
    pub fn width(&self) -> usize {
        self.mean.len()
    }

    /// `rows` (T, C) scaled features -> (T, C) features, `z * scale + mean`
    /// in f64. The caller guarantees `rows.len() % C == 0`.
    pub fn unscale(&self, rows: &[f32]) -> Vec<f64> {
        let c = self.width();
        rows.iter()
            .enumerate()
            .map(|(k, &z)| z as f64 * self.scale[k % c] + self.mean[k % c])
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(width: usize, mean: &str, scale: &str) -> String {
        format!(
            r#"{{"format": "{FORMAT}", "version": 1, "width": {width}, "mean": {mean}, "scale": {scale}, "source": "x.pkl"}}"#
        )
    }

    #[test]
    fn reads_and_inverts() {
        let s = Scaler::parse(&doc(2, "[1.5, -2]", "[2, 0.5]")).unwrap();
        assert_eq!(
            s.unscale(&[1.0, 2.0, -1.0, 0.0]),
            vec![3.5, -1.0, -0.5, -2.0]
        );
    }

    #[test]
    fn refusals_name_the_problem() {
        let e = |t: &str| format!("{:#}", Scaler::parse(t).unwrap_err());
        assert!(e(&doc(2, "[1]", "[1, 1]")).contains("`mean` has 1 values, `width` says 2"));
        assert!(e(&doc(2, "[1, 1]", "[1, 0]")).contains("`scale`[1] = 0 is not > 0"));
        assert!(e(&doc(1, "[1]", "[-1]")).contains("is not > 0"));
        assert!(
            e(&doc(1, "[NaN]", "[1]")).contains("not a scaler file"),
            "JSON has no NaN: {}",
            e(&doc(1, "[NaN]", "[1]"))
        );
        assert!(
            e(&doc(1, "[1e999]", "[1]")).contains("not a scaler file")
                || e(&doc(1, "[1e999]", "[1]")).contains("not finite")
        );
        assert!(
            e(r#"{"format": "other", "version": 1, "width": 1, "mean": [0], "scale": [1]}"#)
                .contains("format \"other\"")
        );
        assert!(
            e(&doc(1, "[0]", "[1]").replace("\"version\": 1", "\"version\": 2"))
                .contains("version 2")
        );
        assert!(e("not json").contains("not a scaler file"));
        assert!(e(&doc(0, "[]", "[]")).contains("width 0"));
    }

    /// The file tools/transflower_scalers.py wrote from a pickled sklearn
    /// StandardScaler fit on random data (one constant column: scale 1).
    #[test]
    fn reads_the_tools_self_test_output() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../tests/fixtures/transflower_motion/scaler_selftest.json");
        let s = Scaler::read(&p).unwrap();
        assert_eq!(s.width(), 7);
        assert_eq!(s.scale[2], 1.0);
        assert_eq!(s.mean[2], 0.25);
    }
}
