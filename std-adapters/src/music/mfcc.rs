//! `power_to_db`, the orthonormal DCT-II that turns log-mel frames into
//! MFCCs, and librosa's `delta(width=3)` (Savitzky-Golay, `mode='interp'`).

/// Number of MFCC coefficients in the Duolando feature.
pub const N_MFCC: usize = 20;

/// librosa `power_to_db(S, ref, amin=1e-10, top_db=80)` in place over a whole
/// matrix: `10 log10(max(amin, S)) - 10 log10(max(amin, ref))`, then floored
/// at `max - top_db` (the max taken over the whole matrix).
pub fn power_to_db_in_place(s: &mut [f32], reference: f32) {
    power_to_db_with_top(s, reference, |top| top);
}

/// As [`power_to_db_in_place`], with the floor at `top(max) - top_db`:
/// `top` maps the matrix's max dB to the level the floor hangs from
/// (offline: that max; streaming: a running max).
pub fn power_to_db_with_top(s: &mut [f32], reference: f32, top: impl FnOnce(f32) -> f32) {
    let amin = 1e-10f32;
    let ref_db = 10.0 * amin.max(reference).log10();
    let mut max = f32::NEG_INFINITY;
    for v in s.iter_mut() {
        *v = 10.0 * amin.max(*v).log10() - ref_db;
        max = max.max(*v);
    }
    let floor = top(max) - 80.0;
    for v in s.iter_mut() {
        *v = v.max(floor);
    }
}

/// Orthonormal DCT-II restricted to the first `n_out` coefficients of an
/// `n_in`-point input (scipy `fftpack.dct(type=2, norm='ortho')`).
pub struct Dct {
    n_in: usize,
    /// (n_out, n_in) row-major basis.
    basis: Vec<f32>,
}

impl Dct {
    pub fn new(n_in: usize, n_out: usize) -> Self {
        let mut basis = Vec::with_capacity(n_in * n_out);
        for k in 0..n_out {
            let scale = if k == 0 {
                (1.0 / n_in as f64).sqrt()
            } else {
                (2.0 / n_in as f64).sqrt()
            };
            for n in 0..n_in {
                let c = (std::f64::consts::PI * k as f64 * (2 * n + 1) as f64 / (2 * n_in) as f64)
                    .cos();
                basis.push((scale * c) as f32);
            }
        }
        Self { n_in, basis }
    }

    /// `out` (n_out,) from `x` (n_in,), accumulated in f64.
    pub fn apply(&self, x: &[f32], out: &mut [f32]) {
        for (o, row) in out.iter_mut().zip(self.basis.chunks_exact(self.n_in)) {
            *o = row
                .iter()
                .zip(x)
                .map(|(&b, &v)| b as f64 * v as f64)
                .sum::<f64>() as f32;
        }
    }
}

/// librosa `delta(width=3, order=1, mode='interp')` along time, for a
/// (T, dim) row-major matrix with T >= 3: central difference inside, the
/// slope of the line fitted to the first/last three frames at the edges.
pub fn delta3(x: &[f32], dim: usize, out: &mut [f32]) {
    let t = x.len() / dim;
    debug_assert!(t >= 3);
    for i in 0..t {
        let (a, b) = match i {
            0 => (0, 2),
            _ if i == t - 1 => (t - 3, t - 1),
            _ => (i - 1, i + 1),
        };
        for d in 0..dim {
            out[i * dim + d] = 0.5 * (x[b * dim + d] - x[a * dim + d]);
        }
    }
}
