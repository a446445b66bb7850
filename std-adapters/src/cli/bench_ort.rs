//! `duolando bench --ort-json FILE` (every family): onnxruntime's
//! time for the family's R step, measured right before by
//! `tools/<family>_ort_r_step.py` (its JSON), read once before anything
//! runs and printed beside the engine's R step with the ratio
//! onnxruntime / ours per weight type and thread count.
//!
//! The JSON (every script): `median_ms`, `p99_ms` and `threads` of the
//! headline run, `onnxruntime` (version), `cpu`; optional `family`
//! (`duolando`, `bailando`, `transflower`; older Bailando files name it only in
//! `what`), `by_threads` (`[{threads, median_ms, p99_ms}]`: more thread
//! counts), `max_abs_err_vs_torch`.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context};
use serde_json::Value;

use super::LABEL;

/// The R-step medians of one family's bench, per weight type and thread
/// count (`ours`: what [`OrtBaseline::print_ratios`] and
/// [`OrtBaseline::json`] read), and each line's ratio notes.
#[derive(Default)]
pub struct RStepMedians {
    f32_ms: std::collections::BTreeMap<usize, f64>,
    pub ours: Vec<(String, usize, f64)>,
}

impl RStepMedians {
    /// Records weight type `d` on `t` threads at `ms` (median) and returns
    /// its line's note: `"; f32/int8 1.30x"` (where f32 ran before on `t`
    /// threads) then onnxruntime's [`OrtBaseline::ratio_note`].
    pub fn record(&mut self, d: &str, t: usize, ms: f64, ort: Option<&OrtBaseline>) -> String {
        if d == "f32" {
            self.f32_ms.insert(t, ms);
        }
        self.ours.push((d.to_string(), t, ms));
        let mut note = self.f32_ms.get(&t).map(|f| format!("; f32/{d} {:.2}x", f / ms)).unwrap_or_default();
        if let Some(o) = ort {
            note.push_str(&o.ratio_note(t, ms));
        }
        note
    }
}

/// onnxruntime's R-step figures of one family.
#[derive(Debug)]
pub struct OrtBaseline {
    path: PathBuf,
    family: &'static str,
    version: String,
    cpu: String,
    /// (threads, median ms, p99 ms), the headline first, one per thread count.
    by_threads: Vec<(usize, f64, f64)>,
    max_abs_err: Option<f64>,
    load: Option<f64>,
}

/// Which script writes a family's JSON.
fn script(family: &str) -> String {
    format!("tools/{family}_ort_r_step.py")
}

fn positive_ms(v: &Value, key: &str) -> Option<f64> {
    v[key].as_f64().filter(|x| x.is_finite() && *x > 0.0)
}

impl OrtBaseline {
    /// Reads and checks `path` for `family` (`duolando`, `bailando`, `transflower`).
    pub fn read(path: &Path, family: &'static str) -> anyhow::Result<OrtBaseline> {
        let how = script(family);
        let bytes = std::fs::read(path).with_context(|| format!("--ort-json {}: cannot read it (make it with {how})", path.display()))?;
        let v: Value = serde_json::from_slice(&bytes).with_context(|| format!("--ort-json {}: not JSON (the file {how} writes)", path.display()))?;
        let bad = |what: String| anyhow!("--ort-json {}: {what} (not the JSON of {how})", path.display());
        if !v.is_object() {
            return Err(bad("not a JSON object".into()));
        }
        let named = match v["family"].as_str() {
            Some(f) => f.to_ascii_lowercase(),
            // Older Bailando files: "what": "Bailando R step (...)".
            None => v["what"].as_str().and_then(|w| w.split_whitespace().next()).unwrap_or("").to_ascii_lowercase(),
        };
        if named != family {
            return Err(bad(format!("onnxruntime figures of {}, this is --family {family}", if named.is_empty() { "no named family" } else { &named })));
        }
        let threads = v["threads"].as_u64().filter(|&t| t >= 1).ok_or_else(|| bad("no `threads` (a count >= 1)".into()))? as usize;
        let median = positive_ms(&v, "median_ms").ok_or_else(|| bad("no `median_ms` (a time > 0)".into()))?;
        let p99 = positive_ms(&v, "p99_ms").ok_or_else(|| bad("no `p99_ms` (a time > 0)".into()))?;
        let mut by_threads = vec![(threads, median, p99)];
        if let Some(list) = v.get("by_threads") {
            let list = list.as_array().ok_or_else(|| bad("`by_threads` is not a list".into()))?;
            for (i, e) in list.iter().enumerate() {
                let t = e["threads"].as_u64().filter(|&t| t >= 1).ok_or_else(|| bad(format!("by_threads[{i}]: no `threads`")))? as usize;
                let m = positive_ms(e, "median_ms").ok_or_else(|| bad(format!("by_threads[{i}]: no `median_ms`")))?;
                let p = positive_ms(e, "p99_ms").ok_or_else(|| bad(format!("by_threads[{i}]: no `p99_ms`")))?;
                match by_threads.iter().find(|(bt, _, _)| *bt == t) {
                    // The headline repeated in the list: it must agree.
                    Some(&(_, bm, _)) if bm != m => return Err(bad(format!("by_threads[{i}]: {t} thread(s) twice, {bm} and {m} ms"))),
                    Some(_) => {}
                    None => by_threads.push((t, m, p)),
                }
            }
        }
        Ok(OrtBaseline {
            path: path.to_path_buf(),
            family,
            version: v["onnxruntime"].as_str().unwrap_or("?").to_string(),
            cpu: v["cpu"].as_str().unwrap_or("unknown CPU").to_string(),
            by_threads,
            max_abs_err: v["max_abs_err_vs_torch"].as_f64(),
            load: v["loadavg_1min_before"].as_f64(),
        })
    }

    /// onnxruntime's median on `threads` threads, if measured.
    pub fn median_ms(&self, threads: usize) -> Option<f64> {
        self.by_threads.iter().find(|(t, _, _)| *t == threads).map(|(_, m, _)| *m)
    }

    /// `"; onnxruntime/this 2.41x"` for a step of `ours_ms` on `threads`
    /// threads (empty where onnxruntime has no figure for that count).
    pub fn ratio_note(&self, threads: usize, ours_ms: f64) -> String {
        self.median_ms(threads).map(|m| format!("; onnxruntime/this {:.2}x", m / ours_ms)).unwrap_or_default()
    }

    /// One line per thread count: onnxruntime's figure, where it was
    /// measured, and (when it is not this CPU) a warning.
    pub fn print(&self, step: &str) {
        let here = crate::kernel_bench::cpu_name();
        let elsewhere = if self.cpu == here { String::new() } else { format!(" [measured on another CPU than this one ({here}): the ratios compare machines]") };
        let err = self.max_abs_err.map(|e| format!(", max |onnxruntime - torch| {e:.1e}")).unwrap_or_default();
        let load = self.load.map(|l| format!(", load {l:.2}")).unwrap_or_default();
        for (t, m, p) in &self.by_threads {
            say!(
                "{step} onnxruntime {} f32 t{t} ({}{load}): median {m:8.1} ms  p99 {p:8.1} ms  p99/median {:.2}  ({}{err}){elsewhere}",
                self.version,
                self.cpu,
                p / m,
                self.path.display()
            );
        }
    }

    /// One line of every ratio onnxruntime / ours, labelled with the ISA
    /// that ran ours and the CPU: `ours` = (weight type, threads, median ms).
    pub fn print_ratios(&self, step: &str, ours: &[(String, usize, f64)]) {
        let parts: Vec<String> = ours
            .iter()
            .filter_map(|(d, t, ms)| self.median_ms(*t).map(|m| format!("{d} t{t} {:.2}x", m / ms)))
            .collect();
        if parts.is_empty() {
            say!("{step}: onnxruntime/ours not computed (onnxruntime timed on {:?} thread(s) only)", self.by_threads.iter().map(|b| b.0).collect::<Vec<_>>());
            return;
        }
        say!(
            "{step} onnxruntime {} f32 / ours ({} | {}): {}",
            self.version,
            crate::simd::name(crate::simd::active()),
            crate::kernel_bench::cpu_name(),
            parts.join(", ")
        );
    }

    /// JSON entries: `ort_r_step_ms_t<N>`, `ort_r_step_p99_ms_t<N>`,
    /// `ort_version`, `ort_cpu`, `ort_max_abs_err_vs_torch`, and
    /// `ort_r_over_r_step_<dtype>_t<N>` for each of `ours`.
    pub fn json(&self, j: &mut serde_json::Map<String, Value>, ours: &[(String, usize, f64)]) {
        for (t, m, p) in &self.by_threads {
            j.insert(format!("ort_r_step_ms_t{t}"), (*m).into());
            j.insert(format!("ort_r_step_p99_ms_t{t}"), (*p).into());
        }
        j.insert("ort_version".into(), self.version.clone().into());
        j.insert("ort_cpu".into(), self.cpu.clone().into());
        j.insert("ort_family".into(), self.family.into());
        if let Some(e) = self.max_abs_err {
            j.insert("ort_max_abs_err_vs_torch".into(), e.into());
        }
        for (d, t, ms) in ours {
            if let Some(m) = self.median_ms(*t) {
                j.insert(format!("ort_r_over_r_step_{d}_t{t}"), (m / ms).into());
            }
        }
    }
}

/// `--ort-json` read for the family asked.
pub fn from_args(path: Option<&Path>, family: &str) -> anyhow::Result<Option<OrtBaseline>> {
    let Some(path) = path else { return Ok(None) };
    let family: &'static str = match family {
        "duolando" => "duolando",
        "bailando" => "bailando",
        "transflower" => "transflower",
        other => bail!("unknown family '{other}' (duolando, bailando, transflower)"),
    };
    OrtBaseline::read(path, family).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn r_step_notes_give_f32_and_onnxruntime_ratios() {
        let o = OrtBaseline {
            path: PathBuf::from("ort.json"),
            family: "duolando",
            version: "1.32.0".into(),
            cpu: "Test CPU".into(),
            by_threads: vec![(1, 300.0, 310.0)],
            max_abs_err: None,
            load: None,
        };
        let mut m = RStepMedians::default();
        // f32 first (its own ratio 1), then int8 at 150 ms: f32/int8 2x, onnxruntime/int8 2x.
        assert_eq!(m.record("f32", 1, 300.0, Some(&o)), "; f32/f32 1.00x; onnxruntime/this 1.00x");
        assert_eq!(m.record("int8", 1, 150.0, Some(&o)), "; f32/int8 2.00x; onnxruntime/this 2.00x");
        // Two threads: no f32 and no onnxruntime figure there, no note.
        assert_eq!(m.record("int8", 2, 100.0, Some(&o)), "");
        assert_eq!(m.record("int8", 1, 75.0, None), "; f32/int8 4.00x");
        assert_eq!(m.ours.len(), 4);
        assert_eq!(m.ours[1], ("int8".to_string(), 1, 150.0));
    }
}
