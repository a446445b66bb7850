//! The papers' motion metrics, computed as the authors' evaluation code
//! computes them (Duolando `utils/metrics.py`, `utils/metrics_duet.py`,
//! `utils/metric_footskating_dur.py`, and the Bailando feature extractors
//! they import), quirks included. docs/EVAL.md lists every metric, its
//! quirks, the golden test, and what is not implemented.
//!
//! Motion everywhere: (T, 165) SMPL-X joint positions, metres, y up, 30 fps,
//! row-major f32 (as the dataset's `pos3d` files).

pub mod bas;
pub mod bed;
pub mod cd;
pub mod fid;
pub mod footskate;
pub mod kinetic;
pub mod manual;
pub mod sets;
pub mod testset;

#[cfg(test)]
mod goldens;

/// Floats per motion row: 55 joints x (x, y, z).
pub const POSE_DIM: usize = 165;
/// SMPL-X joints per frame.
pub const JOINTS: usize = 55;

/// Why a metric cannot be computed. Every case the authors' code would
/// crash on or answer NaN for gets its own variant here.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum EvalError {
    #[error("motion has {values} values, not a whole number of {POSE_DIM}-float rows (55 SMPL-X joints x 3)")]
    Ragged { values: usize },
    #[error("{what} needs at least {need} frames, the clip has {frames}")]
    TooShort {
        what: &'static str,
        frames: usize,
        need: usize,
    },
    #[error("{what} needs at least {need} clips in the {set} set, found {found}")]
    TooFewClips {
        what: &'static str,
        set: &'static str,
        found: usize,
        need: usize,
    },
    #[error("feature sets differ in width: {a} vs {b}")]
    Width { a: usize, b: usize },
    #[error("{what}: no beats in the reference beat list (the authors' code divides by zero)")]
    NoReferenceBeats { what: &'static str },
    #[error("{what}: no motion beats (no local minimum of the smoothed velocity; the authors' code fails on an empty min)")]
    NoMotionBeats { what: &'static str },
    #[error("music features have {cols} columns; the beat is column 53 of the 54-d features")]
    MusicColumns { cols: usize },
    #[error("non-finite value in {what}")]
    NonFinite { what: &'static str },
}

/// Checks that `pos` holds whole (T, 165) rows and returns T.
pub fn frames(pos: &[f32]) -> Result<usize, EvalError> {
    if pos.len() % POSE_DIM != 0 {
        return Err(EvalError::Ragged { values: pos.len() });
    }
    Ok(pos.len() / POSE_DIM)
}

/// A 3-vector in f64.
pub(crate) type V3 = [f64; 3];

pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
pub(crate) fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}
pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The 24-joint SMPL skeleton the solo features read, made from SMPL-X as
/// the authors' `calc_and_save_feats` makes it: joints 0..21 kept, joint 22
/// (left hand) = mean of the five left finger bases (25, 28, 31, 34, 37),
/// joint 23 = mean of the right ones (40, 43, 46, 49, 52), summed left to
/// right in f32 as numpy does on the float32 file; then every joint minus
/// the FIRST frame's pelvis (in f64).
pub fn smpl24_rooted(pos: &[f32]) -> Result<Vec<[V3; 24]>, EvalError> {
    let t_len = frames(pos)?;
    let mut out = Vec::with_capacity(t_len);
    let mut root = [0.0f64; 3];
    for t in 0..t_len {
        let row = &pos[t * POSE_DIM..(t + 1) * POSE_DIM];
        let mut f = [[0.0f64; 3]; 24];
        for (j, fj) in f.iter_mut().enumerate().take(22) {
            for c in 0..3 {
                fj[c] = row[j * 3 + c] as f64;
            }
        }
        for (slot, first) in [(22usize, 25usize), (23, 40)] {
            for c in 0..3 {
                let mut s = row[first * 3 + c];
                for k in 1..5 {
                    s += row[(first + 3 * k) * 3 + c];
                }
                f[slot][c] = (s / 5.0f32) as f64;
            }
        }
        if t == 0 {
            root = f[0];
        }
        for fj in f.iter_mut() {
            *fj = sub(*fj, root);
        }
        out.push(f);
    }
    Ok(out)
}
