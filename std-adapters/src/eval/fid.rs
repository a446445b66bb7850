//! Fréchet distance (FID_k, FID_g, FID_cd) and diversity (Div_k, Div_g,
//! Div_cd) over per-clip feature vectors, as the Duolando evaluation
//! computes them:
//!
//! - both sets are first normalised with the REAL set's per-feature mean
//!   and population standard deviation plus 1e-10 (a feature that is
//!   constant in the real set is divided by 1e-10);
//! - FID = |mu_g - mu_r|^2 + tr S_g + tr S_r - 2 tr sqrtm(S_g S_r), with
//!   sample covariances (N - 1);
//! - Div = mean Euclidean distance over all unordered pairs of clips of one
//!   (normalised) set.
//!
//! `tr sqrtm(S_g S_r)` is the sum of the square roots of the eigenvalues of
//! `A^1/2 B A^1/2` (A, B symmetric positive semi-definite: the same
//! spectrum as A B), computed with two symmetric Jacobi eigen solves; tiny
//! negative eigenvalues from rounding count as zero, as the real part of
//! scipy's `sqrtm` does.

use super::EvalError;

/// Added to the real set's standard deviation before dividing (the authors' 1e-10).
pub const STD_EPS: f64 = 1e-10;

/// A set of feature vectors, one row per clip.
#[derive(Clone, Debug, PartialEq)]
pub struct Features {
    pub rows: Vec<Vec<f64>>,
}

impl Features {
    pub fn new(rows: Vec<Vec<f64>>) -> Self {
        Features { rows }
    }
    pub fn from_f32(rows: &[Vec<f32>]) -> Self {
        Features {
            rows: rows
                .iter()
                .map(|r| r.iter().map(|&v| v as f64).collect())
                .collect(),
        }
    }
    fn width(&self) -> usize {
        self.rows.first().map_or(0, |r| r.len())
    }
}

/// FID and diversities of a generated set against a real set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scores {
    pub fid: f64,
    pub div_gen: f64,
    pub div_real: f64,
}

fn check(set: &Features, name: &'static str, width: usize) -> Result<(), EvalError> {
    if set.rows.len() < 2 {
        return Err(EvalError::TooFewClips {
            what: "FID and Div",
            set: name,
            found: set.rows.len(),
            need: 2,
        });
    }
    for r in &set.rows {
        if r.len() != width {
            return Err(EvalError::Width {
                a: width,
                b: r.len(),
            });
        }
        if r.iter().any(|v| !v.is_finite()) {
            return Err(EvalError::NonFinite {
                what: "feature vectors",
            });
        }
    }
    Ok(())
}

/// Per-feature mean and population standard deviation.
fn mean_std(set: &Features) -> (Vec<f64>, Vec<f64>) {
    let d = set.width();
    let n = set.rows.len() as f64;
    let mut mean = vec![0.0; d];
    for r in &set.rows {
        for (m, v) in mean.iter_mut().zip(r) {
            *m += v;
        }
    }
    mean.iter_mut().for_each(|m| *m /= n);
    let mut var = vec![0.0; d];
    for r in &set.rows {
        for ((s, v), m) in var.iter_mut().zip(r).zip(&mean) {
            *s += (v - m) * (v - m);
        }
    }
    (mean, var.into_iter().map(|s| (s / n).sqrt()).collect())
}

/// Both sets checked as [`scores`] checks them, then each one's
/// per-feature mean and population standard deviation: `[real, gen]`.
fn checked_mean_std(real: &Features, gen: &Features) -> Result<[(Vec<f64>, Vec<f64>); 2], EvalError> {
    let d = real.width();
    check(real, "real", d)?;
    check(gen, "generated", d)?;
    Ok([mean_std(real), mean_std(gen)])
}

/// Both sets normalised by the real set's statistics (the authors' `normalize`).
pub fn normalize(real: &Features, gen: &Features) -> (Features, Features) {
    let (mean, std) = mean_std(real);
    let f = |set: &Features| Features {
        rows: set
            .rows
            .iter()
            .map(|r| {
                r.iter()
                    .zip(&mean)
                    .zip(&std)
                    .map(|((v, m), s)| (v - m) / (s + STD_EPS))
                    .collect()
            })
            .collect(),
    };
    (f(real), f(gen))
}

/// Mean and sample covariance (N - 1) of a set.
fn mean_cov(set: &Features) -> (Vec<f64>, Vec<f64>) {
    let d = set.width();
    let n = set.rows.len();
    let (mean, _) = mean_std(set);
    let mut cov = vec![0.0; d * d];
    for r in &set.rows {
        for i in 0..d {
            let a = r[i] - mean[i];
            for j in i..d {
                cov[i * d + j] += a * (r[j] - mean[j]);
            }
        }
    }
    for i in 0..d {
        for j in i..d {
            let v = cov[i * d + j] / (n - 1) as f64;
            cov[i * d + j] = v;
            cov[j * d + i] = v;
        }
    }
    (mean, cov)
}

/// Eigenvalues and eigenvectors (columns of `v`) of a symmetric d x d
/// matrix, by cyclic Jacobi rotations.
pub fn jacobi_eigen(a: &[f64], d: usize) -> (Vec<f64>, Vec<f64>) {
    let mut a = a.to_vec();
    let mut v = vec![0.0; d * d];
    for i in 0..d {
        v[i * d + i] = 1.0;
    }
    let total: f64 = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    for _sweep in 0..100 {
        let off: f64 = (0..d)
            .flat_map(|i| (0..d).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i * d + j] * a[i * d + j])
            .sum::<f64>()
            .sqrt();
        if off <= 1e-15 * total || off == 0.0 {
            break;
        }
        for p in 0..d {
            for q in p + 1..d {
                let apq = a[p * d + q];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[q * d + q] - a[p * d + p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..d {
                    let akp = a[k * d + p];
                    let akq = a[k * d + q];
                    a[k * d + p] = c * akp - s * akq;
                    a[k * d + q] = s * akp + c * akq;
                }
                for k in 0..d {
                    let apk = a[p * d + k];
                    let aqk = a[q * d + k];
                    a[p * d + k] = c * apk - s * aqk;
                    a[q * d + k] = s * apk + c * aqk;
                }
                for k in 0..d {
                    let vkp = v[k * d + p];
                    let vkq = v[k * d + q];
                    v[k * d + p] = c * vkp - s * vkq;
                    v[k * d + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    ((0..d).map(|i| a[i * d + i]).collect(), v)
}

/// `tr sqrtm(A B)` for symmetric positive semi-definite A and B.
pub fn trace_sqrt_product(a: &[f64], b: &[f64], d: usize) -> f64 {
    let (w, v) = jacobi_eigen(a, d);
    // A^1/2 = V diag(sqrt(max(w, 0))) V^T
    let mut half = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..d {
            let mut s = 0.0;
            for k in 0..d {
                s += v[i * d + k] * w[k].max(0.0).sqrt() * v[j * d + k];
            }
            half[i * d + j] = s;
        }
    }
    let mul = |x: &[f64], y: &[f64]| {
        let mut out = vec![0.0; d * d];
        for i in 0..d {
            for k in 0..d {
                let xik = x[i * d + k];
                if xik == 0.0 {
                    continue;
                }
                for j in 0..d {
                    out[i * d + j] += xik * y[k * d + j];
                }
            }
        }
        out
    };
    let mut m = mul(&mul(&half, b), &half);
    for i in 0..d {
        for j in i + 1..d {
            let s = 0.5 * (m[i * d + j] + m[j * d + i]);
            m[i * d + j] = s;
            m[j * d + i] = s;
        }
    }
    let (lam, _) = jacobi_eigen(&m, d);
    lam.iter().map(|l| l.max(0.0).sqrt()).sum()
}

/// Fréchet distance between two already-normalised sets.
pub fn frechet(gen: &Features, real: &Features) -> f64 {
    let d = real.width();
    let (mg, sg) = mean_cov(gen);
    let (mr, sr) = mean_cov(real);
    let diff: f64 = mg.iter().zip(&mr).map(|(a, b)| (a - b) * (a - b)).sum();
    let tr = |s: &[f64]| (0..d).map(|i| s[i * d + i]).sum::<f64>();
    diff + tr(&sg) + tr(&sr) - 2.0 * trace_sqrt_product(&sg, &sr, d)
}

/// Mean pairwise Euclidean distance of one set (the authors' `calculate_avg_distance`).
pub fn diversity(set: &Features) -> f64 {
    let n = set.rows.len();
    let mut total = 0.0;
    for i in 0..n {
        for j in i + 1..n {
            total += set.rows[i]
                .iter()
                .zip(&set.rows[j])
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt();
        }
    }
    total / ((n * n - n) as f64 / 2.0)
}

/// A feature that does not vary over the real set but does over (or
/// differs in) the generated one: the authors' normalisation divides it by
/// [`STD_EPS`], so its generated values reach ~1e7-1e10 and the FID is
/// that feature's alone (the Bailando demo's FID_g of 3e14:
/// docs/DEMO_MODEL.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Flat {
    /// Column of the feature vector.
    pub index: usize,
    /// Its value in every real clip.
    pub real: f64,
    /// Its mean and population standard deviation over the generated clips.
    pub gen_mean: f64,
    pub gen_std: f64,
}

/// The features whose real standard deviation is 0 while some generated
/// clip holds another value (see [`Flat`]), in column order. Both sets as
/// [`scores`] checks them.
pub fn flat_in_real(real: &Features, gen: &Features) -> Result<Vec<Flat>, EvalError> {
    let [(rm, rs), (gm, gs)] = checked_mean_std(real, gen)?;
    Ok((0..real.width())
        .filter(|&i| rs[i] == 0.0 && gen.rows.iter().any(|r| r[i] != rm[i]))
        .map(|i| Flat {
            index: i,
            real: rm[i],
            gen_mean: gm[i],
            gen_std: gs[i],
        })
        .collect())
}

/// Both sets without the columns `drop` (sorted or not; out of range ignored).
pub fn without(set: &Features, drop: &[usize]) -> Features {
    Features {
        rows: set
            .rows
            .iter()
            .map(|r| {
                r.iter()
                    .enumerate()
                    .filter(|(i, _)| !drop.contains(i))
                    .map(|(_, v)| *v)
                    .collect()
            })
            .collect(),
    }
}

/// The FID's mean term split by feature: for each column, the generated
/// mean's distance from the real mean in units of the real set's standard
/// deviation (plus [`STD_EPS`]), signed (`(mu_g - mu_r) / (sd_r + eps)`).
/// The squares sum to the term `|mu_g - mu_r|^2` of [`frechet`] on the
/// normalised sets; the rest of the FID is the covariances'. Both sets as
/// [`scores`] checks them.
pub fn mean_shifts(real: &Features, gen: &Features) -> Result<Vec<f64>, EvalError> {
    let [(rm, rs), (gm, _)] = checked_mean_std(real, gen)?;
    Ok((0..real.width()).map(|i| (gm[i] - rm[i]) / (rs[i] + STD_EPS)).collect())
}

/// FID and both diversities, with the real set's normalisation.
pub fn scores(real: &Features, gen: &Features) -> Result<Scores, EvalError> {
    let d = real.width();
    check(real, "real", d)?;
    check(gen, "generated", d)?;
    let (r, g) = normalize(real, gen);
    Ok(Scores {
        fid: frechet(&g, &r),
        div_gen: diversity(&g),
        div_real: diversity(&r),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A generated set that is the real one shifted by a constant per
    /// feature has the real covariance, so its FID is the mean term alone:
    /// the squared shifts sum to it, and each is the shift over the real
    /// population standard deviation, signed.
    #[test]
    fn mean_shifts_split_the_mean_term() {
        let real = Features::new(vec![
            vec![1.0, 10.0, -3.0],
            vec![2.0, 14.0, -1.0],
            vec![4.0, 11.0, -2.5],
            vec![3.0, 9.0, 0.5],
        ]);
        let shift = [0.5, -6.0, 0.0];
        let gen = Features::new(
            real.rows
                .iter()
                .map(|r| r.iter().zip(shift).map(|(v, s)| v + s).collect())
                .collect(),
        );
        let m = mean_shifts(&real, &gen).unwrap();
        let (_, sd) = mean_std(&real);
        for i in 0..3 {
            assert!((m[i] - shift[i] / (sd[i] + STD_EPS)).abs() < 1e-12, "feature {i}: {}", m[i]);
        }
        assert!(m[0] > 0.0 && m[1] < 0.0 && m[2] == 0.0);
        let fid = scores(&real, &gen).unwrap().fid;
        let term: f64 = m.iter().map(|v| v * v).sum();
        assert!((fid - term).abs() < 1e-6 * term, "FID {fid} mean term {term}");
        assert!(mean_shifts(&real, &Features::new(vec![vec![1.0, 2.0]; 2])).is_err());
    }

    #[test]
    fn jacobi_diagonalises() {
        let a = [4.0, 1.0, 2.0, 1.0, 3.0, 0.5, 2.0, 0.5, 5.0];
        let (w, v) = jacobi_eigen(&a, 3);
        for k in 0..3 {
            for i in 0..3 {
                let av: f64 = (0..3).map(|j| a[i * 3 + j] * v[j * 3 + k]).sum();
                assert!((av - w[k] * v[i * 3 + k]).abs() < 1e-12);
            }
        }
        assert!((w.iter().sum::<f64>() - 12.0).abs() < 1e-12);
    }

    #[test]
    fn identical_sets_have_zero_fid() {
        let rows: Vec<Vec<f64>> = (0..9)
            .map(|i| vec![i as f64, (i * i) as f64 * 0.1, (i % 3) as f64])
            .collect();
        let f = Features::new(rows);
        let s = scores(&f, &f).unwrap();
        assert!(s.fid.abs() < 1e-9, "{}", s.fid);
        assert_eq!(s.div_gen, s.div_real);
    }

    /// A feature constant in the real set that moves in the generated set
    /// owns the FID (divided by 1e-10, as the authors normalise); it is
    /// found by name, and the FID without it is the FID of the other
    /// columns. A feature constant in both sets is not reported.
    #[test]
    fn a_feature_flat_in_the_real_set_is_found_and_can_be_left_out() {
        let real = Features::new(
            (0..8)
                .map(|i| vec![i as f64, 0.0, (i % 3) as f64, 0.5])
                .collect(),
        );
        let gen = Features::new(
            (0..6)
                .map(|i| vec![i as f64 + 0.5, 0.001 * (i % 2) as f64, (i % 2) as f64, 0.5])
                .collect(),
        );
        let flats = flat_in_real(&real, &gen).unwrap();
        assert_eq!(flats.len(), 1, "{flats:?}");
        assert_eq!((flats[0].index, flats[0].real), (1, 0.0));
        assert!((flats[0].gen_mean - 0.0005).abs() < 1e-12);
        let all = scores(&real, &gen).unwrap();
        let kept = scores(&without(&real, &[1]), &without(&gen, &[1])).unwrap();
        assert!(all.fid > 1e10, "the flat feature owns the FID: {}", all.fid);
        assert!(kept.fid > 0.0 && kept.fid < 100.0, "{}", kept.fid);
        // Nothing flat: nothing reported.
        assert!(flat_in_real(&real, &real).unwrap().is_empty());
    }

    #[test]
    fn too_few_clips_and_width_mismatch_are_named() {
        let one = Features::new(vec![vec![1.0, 2.0]]);
        let two = Features::new(vec![vec![1.0, 2.0], vec![3.0, 4.0]]);
        assert!(matches!(
            scores(&two, &one),
            Err(EvalError::TooFewClips {
                set: "generated",
                ..
            })
        ));
        let wide = Features::new(vec![vec![1.0, 2.0, 3.0], vec![3.0, 4.0, 5.0]]);
        assert_eq!(scores(&two, &wide), Err(EvalError::Width { a: 2, b: 3 }));
    }
}
