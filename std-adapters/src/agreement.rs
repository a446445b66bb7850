//! Agreement figures between two runs of the model (S vs R, or one dtype
//! vs another): the definitions of docs/STREAMING.md §7, shared by
//! `duolando compare` and the tests.

use serde::Serialize;

/// Stream names in token-column order.
pub const STREAMS: [&str; 5] = ["up", "down", "lhand", "rhand", "transl"];

/// Fraction of equal tokens, overall and per stream, over `n` rows.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct TokenAgreement {
    pub all: f64,
    pub per_stream: [f64; 5],
    pub rows: usize,
}

/// `a`, `b`: (rows, 5); compares the first `n` rows of each.
pub fn token_agreement(a: &[u32], b: &[u32], n: usize) -> TokenAgreement {
    let (all, per) = agreement_of(a, b, n, 5);
    let mut per_stream = [0.0; 5];
    per_stream.copy_from_slice(&per);
    TokenAgreement {
        all,
        per_stream,
        rows: n,
    }
}

/// Any number of streams: `a`, `b` (rows, `w`), the first `n` rows of
/// each: (overall fraction of equal tokens, per stream).
pub fn agreement_of(a: &[u32], b: &[u32], n: usize, w: usize) -> (f64, Vec<f64>) {
    let mut per = vec![0usize; w];
    for r in 0..n {
        for (j, p) in per.iter_mut().enumerate() {
            *p += usize::from(a[r * w + j] == b[r * w + j]);
        }
    }
    let d = n.max(1) as f64;
    (
        per.iter().sum::<usize>() as f64 / (w.max(1) as f64 * d),
        per.iter().map(|&c| c as f64 / d).collect(),
    )
}

/// [`free_run`] for `w` streams per row: rows 1..=n (row 0, the seed, is
/// shared), n = min(rows) - 1: (overall, per stream, n).
pub fn free_run_of(a: &[u32], b: &[u32], w: usize) -> (f64, Vec<f64>, usize) {
    let n = (a.len() / w).min(b.len() / w).saturating_sub(1);
    let (all, per) = agreement_of(&a[w.min(a.len())..], &b[w.min(b.len())..], n, w);
    (all, per, n)
}

/// One-step agreement: `pred` (n, 5) choices made under the history of the
/// reference run whose tokens are `reference` (>= n+1 rows): pred row k vs
/// reference row k+1.
pub fn one_step(pred: &[u32], reference: &[u32]) -> TokenAgreement {
    let n = (pred.len() / 5).min((reference.len() / 5).saturating_sub(1));
    token_agreement(pred, &reference[5..], n)
}

/// Free-running agreement: token rows 1..=n of two histories (row 0, the
/// seed, is shared), n = min(rows) - 1.
pub fn free_run(a: &[u32], b: &[u32]) -> TokenAgreement {
    let n = (a.len() / 5).min(b.len() / 5).saturating_sub(1);
    token_agreement(&a[5.min(a.len())..], &b[5.min(b.len())..], n)
}

/// Per-joint Euclidean distance (mm) between two (frames, 165) position
/// arrays over the frames both have: (mean, max, frames).
pub fn joint_error_mm(a: &[f32], b: &[f32]) -> (f64, f64, usize) {
    joint_error_mm_of(a, b, 55)
}

/// [`joint_error_mm`] for poses of `joints` joints ((frames, 3 * joints)).
pub fn joint_error_mm_of(a: &[f32], b: &[f32], joints: usize) -> (f64, f64, usize) {
    let row = 3 * joints.max(1);
    let n = (a.len() / row).min(b.len() / row);
    let (mut sum, mut max) = (0.0f64, 0.0f64);
    for i in 0..n * joints {
        let d: f64 = (0..3)
            .map(|c| (a[i * 3 + c] as f64 - b[i * 3 + c] as f64).powi(2))
            .sum::<f64>()
            .sqrt()
            * 1000.0;
        sum += d;
        max = max.max(d);
    }
    (sum / (n * joints).max(1) as f64, max, n)
}
