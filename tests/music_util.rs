//! Shared helpers of the music tests: fixture loading, per-group error
//! figures and the named tolerances of issue #7.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use duolando::music::{BEAT_COL, CHROMA_COLS, DELTA_COLS, FEATURE_DIM, MFCC_COLS, ONSET_COL};

/// MFCC and delta: absolute error (issue: 1e-2; measured max 1.2e-4).
pub const MFCC_ABS: f32 = 1e-3;
/// Chroma: absolute error on interior frames (issue: 1e-2; measured max 3.3e-6).
pub const CHROMA_ABS: f32 = 1e-4;
/// Onset strength: absolute error relative to the golden envelope's peak (measured max 1.8e-4).
pub const ONSET_REL_PEAK: f32 = 1e-3;
/// Beats on signals that are not click tracks: matches within this many frames...
pub const BEAT_SLACK: usize = 1;
/// ... with at least this F-measure.
pub const BEAT_F_MIN: f64 = 0.9;

pub fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join("music")
}

/// One manifest line.
#[derive(Debug, Clone)]
pub struct Golden {
    pub name: String,
    pub tempo: f64,
    pub tuning: f64,
    pub frames: usize,
    pub samples: usize,
}

pub fn manifest() -> Vec<Golden> {
    let text = std::fs::read_to_string(dir().join("manifest.txt")).expect("manifest.txt");
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            Golden {
                name: f[0].to_string(),
                tempo: f[1].parse().unwrap(),
                tuning: f[2].parse().unwrap(),
                frames: f[3].parse().unwrap(),
                samples: f[4].parse().unwrap(),
            }
        })
        .collect()
}

pub fn read_npy_f32(path: &Path) -> (Vec<u64>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape = npy.shape().to_vec();
    (shape, npy.into_vec::<f32>().unwrap())
}

/// The int16 input of a synthetic golden as f32 (value / 32768).
pub fn read_pcm16(name: &str) -> Vec<f32> {
    let path = dir().join(format!("{name}.pcm16.npy"));
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
    npy.into_vec::<i16>()
        .unwrap()
        .into_iter()
        .map(|v| v as f32 / 32768.0)
        .collect()
}

/// Golden (T, 54) features.
pub fn read_features(name: &str) -> Vec<f32> {
    let (shape, data) = read_npy_f32(&dir().join(format!("{name}.features.npy")));
    assert_eq!(shape.len(), 2);
    assert_eq!(shape[1] as usize, FEATURE_DIM);
    data
}

/// Max abs difference over the given columns and frame range.
pub fn max_abs(
    a: &[f32],
    b: &[f32],
    cols: std::ops::Range<usize>,
    frames: std::ops::Range<usize>,
) -> f32 {
    let mut m = 0.0f32;
    for t in frames {
        for c in cols.clone() {
            m = m.max((a[t * FEATURE_DIM + c] - b[t * FEATURE_DIM + c]).abs());
        }
    }
    m
}

pub fn beat_frames(f: &[f32]) -> Vec<usize> {
    f.chunks_exact(FEATURE_DIM)
        .enumerate()
        .filter(|(_, r)| r[BEAT_COL] > 0.5)
        .map(|(t, _)| t)
        .collect()
}

/// F-measure of `got` against `want` with a matching window of `slack` frames (greedy one-to-one).
pub fn beat_f(want: &[usize], got: &[usize], slack: usize) -> f64 {
    if want.is_empty() && got.is_empty() {
        return 1.0;
    }
    let mut used = vec![false; got.len()];
    let mut hits = 0usize;
    for &w in want {
        if let Some(j) = (0..got.len()).find(|&j| !used[j] && got[j].abs_diff(w) <= slack) {
            used[j] = true;
            hits += 1;
        }
    }
    if hits == 0 {
        return 0.0;
    }
    let p = hits as f64 / got.len() as f64;
    let r = hits as f64 / want.len() as f64;
    2.0 * p * r / (p + r)
}

/// Per-group errors of `got` against `want` (both (T, 54)).
#[derive(Debug, Clone, Copy)]
pub struct GroupErrors {
    pub mfcc: f32,
    pub delta: f32,
    pub chroma_interior: f32,
    pub chroma_all: f32,
    pub onset_rel: f32,
    pub beat_f: f64,
    pub beats_exact: bool,
}

/// Interior frames for chroma: away from the ends by the lowest CQT filter's half length (~0.8 s).
pub const CHROMA_EDGE: usize = 24;

pub fn group_errors(want: &[f32], got: &[f32]) -> GroupErrors {
    let t = want.len() / FEATURE_DIM;
    let interior = if t > 2 * CHROMA_EDGE {
        CHROMA_EDGE..t - CHROMA_EDGE
    } else {
        0..0
    };
    let peak = (0..t)
        .map(|i| want[i * FEATURE_DIM + ONSET_COL])
        .fold(0.0f32, f32::max);
    let onset = max_abs(want, got, ONSET_COL..ONSET_COL + 1, 0..t);
    let (wb, gb) = (beat_frames(want), beat_frames(got));
    GroupErrors {
        mfcc: max_abs(want, got, MFCC_COLS, 0..t),
        delta: max_abs(want, got, DELTA_COLS, 0..t),
        chroma_interior: max_abs(want, got, CHROMA_COLS, interior),
        chroma_all: max_abs(want, got, CHROMA_COLS, 0..t),
        onset_rel: if peak > 0.0 { onset / peak } else { onset },
        beat_f: beat_f(&wb, &gb, BEAT_SLACK),
        beats_exact: wb == gb,
    }
}
