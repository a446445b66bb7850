//! Kernels against naive references (f64 loops written from the PyTorch
//! definitions). Tolerance: relative to the magnitude of the terms.
use crate::kernels::*;

/// Named tolerance: f32 kernels vs f64 references on O(1) data.
const CLOSE: f64 = 1e-5;

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
    fn vec(&mut self, n: usize) -> Vec<f32> {
        (0..n).map(|_| self.next()).collect()
    }
}

fn assert_close(got: &[f32], want: &[f64], tol: f64) {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(((*g as f64) - w).abs() <= tol * scale, "at {i}: {g} vs {w}");
    }
}

fn mat(d: &[f32], rows: usize, cols: usize) -> Matrix<'_> {
    Matrix::F32(F32Rows::new(d, rows, cols).unwrap())
}

#[test]
fn linear_matches_naive() {
    let mut r = Lcg(1);
    for &(n, i, o) in &[(1, 1, 1), (3, 17, 70), (33, 64, 130), (5, 9, 3)] {
        let (x, w, b) = (r.vec(n * i), r.vec(o * i), r.vec(o));
        let mut y = vec![0.0; n * o];
        linear(&x, &mat(&w, o, i), Some(&b), &mut y);
        let mut want = vec![0.0f64; n * o];
        for a in 0..n {
            for c in 0..o {
                want[a * o + c] = b[c] as f64
                    + (0..i)
                        .map(|k| x[a * i + k] as f64 * w[c * i + k] as f64)
                        .sum::<f64>();
            }
        }
        assert_close(&y, &want, CLOSE);
        // x W
        let mut z = vec![0.0; n * i];
        let xo = r.vec(n * o);
        linear_xw(&xo, &mat(&w, o, i), &mut z);
        let mut want = vec![0.0f64; n * i];
        for a in 0..n {
            for k in 0..i {
                want[a * i + k] = (0..o)
                    .map(|c| xo[a * o + c] as f64 * w[c * i + k] as f64)
                    .sum();
            }
        }
        assert_close(&z, &want, CLOSE);
    }
}

#[test]
fn layernorm_and_gelu() {
    let mut r = Lcg(2);
    let (x, w, b) = (r.vec(3 * 10), r.vec(10), r.vec(10));
    let mut y = vec![0.0; 30];
    layernorm(&x, &w, &b, &mut y);
    let mut want = vec![0.0f64; 30];
    for row in 0..3 {
        let xr: Vec<f64> = x[row * 10..row * 10 + 10]
            .iter()
            .map(|&v| v as f64)
            .collect();
        let m = xr.iter().sum::<f64>() / 10.0;
        let var = xr.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / 10.0;
        for i in 0..10 {
            want[row * 10 + i] = (xr[i] - m) / (var + 1e-5).sqrt() * w[i] as f64 + b[i] as f64;
        }
    }
    assert_close(&y, &want, CLOSE);
    // GELU(1) = 0.8413447 * 1, GELU(-1) = -0.1586553, exact-erf values.
    let mut g = [1.0f32, -1.0, 0.0, 3.0];
    gelu_inplace(&mut g);
    assert_close(
        &g,
        &[
            0.8413447460685429,
            -0.15865525393145707,
            0.0,
            2.995950070189245,
        ],
        1e-6,
    );
}

fn naive_conv(
    x: &[f32],
    t_in: usize,
    ci: usize,
    w: &[f32],
    b: &[f32],
    co: usize,
    g: ConvGeom,
    t_out: usize,
) -> Vec<f64> {
    let mut y = vec![0.0f64; t_out * co];
    for t in 0..t_out {
        for o in 0..co {
            let mut s = b[o] as f64;
            for c in 0..ci {
                for j in 0..g.kernel {
                    let p = (t * g.stride + j * g.dilation) as isize - g.pad as isize;
                    if p >= 0 && (p as usize) < t_in {
                        s += w[(o * ci + c) * g.kernel + j] as f64 * x[p as usize * ci + c] as f64;
                    }
                }
            }
            y[t * co + o] = s;
        }
    }
    y
}

#[test]
fn conv1d_matches_naive() {
    let mut r = Lcg(3);
    let geoms = [
        ConvGeom {
            kernel: 4,
            stride: 2,
            pad: 1,
            dilation: 1,
        },
        ConvGeom {
            kernel: 3,
            stride: 1,
            pad: 1,
            dilation: 1,
        },
        ConvGeom {
            kernel: 3,
            stride: 1,
            pad: 9,
            dilation: 9,
        },
        ConvGeom {
            kernel: 1,
            stride: 1,
            pad: 0,
            dilation: 1,
        },
        ConvGeom {
            kernel: 3,
            stride: 1,
            pad: 0,
            dilation: 2,
        },
    ];
    for g in geoms {
        for &(t_in, ci, co) in &[(4usize, 3usize, 5usize), (70, 7, 6), (64, 16, 16)] {
            let t_out = match g.out_len(t_in) {
                Some(t) => t,
                None => continue,
            };
            let (x, w, b) = (r.vec(t_in * ci), r.vec(co * ci * g.kernel), r.vec(co));
            let mut y = vec![0.0; t_out * co];
            let mut col = vec![0.0; conv1d_col_len(ci, g.kernel)];
            conv1d(&x, ci, &mat(&w, co, ci * g.kernel), &b, g, &mut y, &mut col);
            assert_close(&y, &naive_conv(&x, t_in, ci, &w, &b, co, g, t_out), CLOSE);
        }
    }
}

#[test]
fn conv_transpose_matches_naive() {
    let mut r = Lcg(4);
    for &(s, t_in, ci, co) in &[
        (2usize, 1usize, 3usize, 4usize),
        (2, 40, 8, 5),
        (4, 9, 3, 3),
    ] {
        let (k, p) = (2 * s, s / 2);
        let t_out = (t_in - 1) * s + k - 2 * p;
        assert_eq!(t_out, t_in * s);
        let (x, w, b) = (r.vec(t_in * ci), r.vec(ci * co * k), r.vec(co));
        let wt = gemm_order(&w, ci, co * k);
        let mut ys = [vec![0.0; t_out * co], vec![0.0; t_out * co]];
        let mut z = vec![0.0; convt_z_len(co, k)];
        conv_transpose1d(
            &x,
            &ConvTWeight::Rows(mat(&w, ci, co * k)),
            &b,
            k,
            s,
            p,
            &mut ys[0],
            &mut z,
        );
        conv_transpose1d(
            &x,
            &ConvTWeight::Gemm(mat(&wt, co * k, ci)),
            &b,
            k,
            s,
            p,
            &mut ys[1],
            &mut z,
        );
        let mut want = vec![0.0f64; t_out * co];
        for t in 0..t_out {
            for o in 0..co {
                want[t * co + o] = b[o] as f64;
            }
        }
        for i in 0..t_in {
            for j in 0..k {
                let t = (i * s + j) as isize - p as isize;
                if t < 0 || t as usize >= t_out {
                    continue;
                }
                for o in 0..co {
                    for c in 0..ci {
                        want[t as usize * co + o] +=
                            x[i * ci + c] as f64 * w[(c * co + o) * k + j] as f64;
                    }
                }
            }
        }
        for y in &ys {
            assert_close(y, &want, CLOSE);
        }
    }
}

/// A ConvTranspose1d weight (c_in, c_out * k) in GEMM order (c_out * k,
/// c_in): row `o * k + j` = `W[:, o, j]`.
fn gemm_order(w: &[f32], c_in: usize, zk: usize) -> Vec<f32> {
    (0..zk * c_in)
        .map(|n| w[(n % c_in) * zk + n / c_in])
        .collect()
}

/// The segmented convolutions (several streams' columns in one GEMM per
/// tile) give each segment bit for bit what a call over that segment alone
/// gives: f32, f16 and int8 weights, segments of every length around the
/// tile size (tiles crossing segment ends), empty segments, inputs longer
/// than the outputs need, and per-segment offsets.
#[test]
fn segmented_convs_equal_one_call_per_segment() {
    use super::simd::{f16_bits, q8_bytes};
    let mut r = Lcg(11);
    let (ci, co) = (32usize, 40usize);
    let lists: [&[(usize, usize, usize)]; 5] = [
        &[(5, 3, 1)],
        &[(3, 2, 1), (0, 0, 0), (7, 5, 2), (1, 1, 0)],
        &[(40, 33, 1), (31, 30, 3), (2, 2, 0)],
        &[(33, 32, 0), (33, 32, 0), (1, 1, 1), (64, 40, 2)],
        &[(12, 12, 0), (12, 12, 0), (12, 12, 0)],
    ];
    let geoms = [
        ConvGeom {
            kernel: 3,
            stride: 1,
            pad: 0,
            dilation: 3,
        },
        ConvGeom {
            kernel: 4,
            stride: 2,
            pad: 0,
            dilation: 1,
        },
        ConvGeom {
            kernel: 1,
            stride: 1,
            pad: 0,
            dilation: 1,
        },
    ];
    for g in geoms {
        let ck = ci * g.kernel;
        let (w, b) = (r.vec(co * ck), r.vec(co));
        let (h, q) = (f16_bits(&w), q8_bytes(&w));
        let mats = [
            mat(&w, co, ck),
            Matrix::F16(F16Rows::new(&h, co, ck).unwrap()),
            Matrix::Q8(Q8Rows::new(&q, co, ck).unwrap()),
        ];
        for m in &mats {
            for list in lists {
                // (t_in, t_out, pad); a pointwise conv reads input row t for output row t.
                let segs: Vec<ConvSeg> = list
                    .iter()
                    .map(|&(ti, to, p)| {
                        if g.kernel == 1 {
                            ConvSeg {
                                t_in: ti,
                                t_out: to.min(ti),
                                pad: 0,
                            }
                        } else {
                            ConvSeg {
                                t_in: ti,
                                t_out: to,
                                pad: p,
                            }
                        }
                    })
                    .collect();
                let t_in: usize = segs.iter().map(|s| s.t_in).sum();
                let t_out: usize = segs.iter().map(|s| s.t_out).sum();
                let x = r.vec(t_in * ci);
                let mut col = vec![0.0; conv1d_col_len(ci, g.kernel)];
                let mut y = vec![f32::NAN; t_out * co];
                conv1d_segs(&x, ci, m, &b, g, &segs, &mut y, &mut col);
                let (mut x0, mut y0) = (0, 0);
                for s in &segs {
                    let mut alone = vec![f32::NAN; s.t_out * co];
                    conv1d(
                        &x[x0 * ci..(x0 + s.t_in) * ci],
                        ci,
                        m,
                        &b,
                        ConvGeom { pad: s.pad, ..g },
                        &mut alone,
                        &mut col,
                    );
                    assert!(
                        alone
                            .iter()
                            .zip(&y[y0 * co..(y0 + s.t_out) * co])
                            .all(|(a, b)| a.to_bits() == b.to_bits()),
                        "conv1d {g:?} {segs:?}: segment {s:?}"
                    );
                    x0 += s.t_in;
                    y0 += s.t_out;
                }
            }
        }
    }
    // Transposed: w (c_in, c_out * k), or (c_out * k, c_in) in GEMM order.
    let (k, st) = (4usize, 2usize);
    let (w, b) = (r.vec(ci * co * k), r.vec(co));
    let wt = gemm_order(&w, ci, co * k);
    let (h, q, qt) = (f16_bits(&w), q8_bytes(&w), q8_bytes(&wt));
    let mats = [
        ConvTWeight::Rows(mat(&w, ci, co * k)),
        ConvTWeight::Rows(Matrix::F16(F16Rows::new(&h, ci, co * k).unwrap())),
        ConvTWeight::Rows(Matrix::Q8(Q8Rows::new(&q, ci, co * k).unwrap())),
        ConvTWeight::Gemm(mat(&wt, co * k, ci)),
        ConvTWeight::Gemm(Matrix::Q8(Q8Rows::new(&qt, co * k, ci).unwrap())),
    ];
    for m in &mats {
        for list in lists {
            let segs: Vec<ConvSeg> = list
                .iter()
                .map(|&(ti, _, p)| ConvSeg {
                    t_in: ti,
                    t_out: (ti * st).saturating_sub(p),
                    pad: p,
                })
                .collect();
            let t_in: usize = segs.iter().map(|s| s.t_in).sum();
            let t_out: usize = segs.iter().map(|s| s.t_out).sum();
            let x = r.vec(t_in * ci);
            let mut z = vec![0.0; convt_z_len(co, k)];
            let mut y = vec![f32::NAN; t_out * co];
            conv_transpose1d_segs(&x, m, &b, k, st, &segs, &mut y, &mut z);
            let (mut x0, mut y0) = (0, 0);
            for s in &segs {
                let mut alone = vec![f32::NAN; s.t_out * co];
                conv_transpose1d(
                    &x[x0 * ci..(x0 + s.t_in) * ci],
                    m,
                    &b,
                    k,
                    st,
                    s.pad,
                    &mut alone,
                    &mut z,
                );
                assert!(
                    alone
                        .iter()
                        .zip(&y[y0 * co..(y0 + s.t_out) * co])
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "conv_transpose1d {segs:?}: segment {s:?}"
                );
                x0 += s.t_in;
                y0 += s.t_out;
            }
        }
    }
}

fn naive_attention(
    q: &[f32],
    k: &[f32],
    v: &[f32],
    c: usize,
    nh: usize,
    allowed: &dyn Fn(usize, usize) -> bool,
) -> Vec<f64> {
    let hd = c / nh;
    let (nq, nk) = (q.len() / c, k.len() / c);
    let mut out = vec![0.0f64; nq * c];
    for i in 0..nq {
        for h in 0..nh {
            let s: Vec<f64> = (0..nk)
                .map(|j| {
                    if allowed(i, j) {
                        (0..hd)
                            .map(|d| q[i * c + h * hd + d] as f64 * k[j * c + h * hd + d] as f64)
                            .sum::<f64>()
                            / (hd as f64).sqrt()
                    } else {
                        f64::NEG_INFINITY
                    }
                })
                .collect();
            let m = s.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            let e: Vec<f64> = s.iter().map(|v| (v - m).exp()).collect();
            let z: f64 = e.iter().sum();
            for d in 0..hd {
                out[i * c + h * hd + d] = (0..nk)
                    .map(|j| e[j] / z * v[j * c + h * hd + d] as f64)
                    .sum();
            }
        }
    }
    out
}

#[test]
fn attention_band_and_tiled_causal() {
    let mut r = Lcg(5);
    let (c, nh) = (12, 3);
    // Band over 20 rows, radius 4.
    let n = 20;
    let (q, k, v) = (r.vec(n * c), r.vec(n * c), r.vec(n * c));
    let mut out = vec![0.0; n * c];
    let mut scores = vec![0.0; n];
    let band = BandMask {
        radius: 4,
        q_pos0: 0,
        k_pos0: 0,
    };
    attention(&q, &k[..], &v[..], c, nh, &band, &mut scores, &mut out);
    assert_close(
        &out,
        &naive_attention(&q, &k[..], &v[..], c, nh, &|i, j| i.abs_diff(j) <= 4),
        CLOSE,
    );
    // Tiled causal: 10 streams of t = 3.
    let t = 3;
    let n = 10 * t;
    let (q, k, v) = (r.vec(n * c), r.vec(n * c), r.vec(n * c));
    let mut out = vec![0.0; n * c];
    let mut scores = vec![0.0; n];
    let m = TiledCausalMask {
        t_q: t,
        t_k: t,
        q_pos0: 0,
    };
    attention(&q, &k[..], &v[..], c, nh, &m, &mut scores, &mut out);
    let want = naive_attention(&q, &k[..], &v[..], c, nh, &|i, j| j % t <= i % t);
    assert_close(&out, &want, CLOSE);
    // Only the last position of stream 7 as a query (the logits shortcut).
    let qi = 7 * t + t - 1;
    let mut one = vec![0.0; c];
    let last = TiledCausalMask {
        t_q: 1,
        t_k: t,
        q_pos0: t - 1,
    };
    attention(
        &q[qi * c..(qi + 1) * c],
        &k[..],
        &v[..],
        c,
        nh,
        &last,
        &mut scores,
        &mut one,
    );
    assert_close(&one, &want[qi * c..(qi + 1) * c], CLOSE);
}

/// The coordinated attention of a whole window as per-head GEMMs
/// (`attention_staircase`) against the f64 reference and the key-by-key
/// kernel: 1, 3 and 10 streams (fewer and more than a GEMM call's 6 rows),
/// windows of 1-29 positions, heads of 8, 20, 64 and 96 lanes (96: two
/// column chunks of the output GEMM); shapes that are not a whole window
/// or a short `work` are refused (false, `out` untouched); room for
/// several heads at a time gives the same bits. The same bits on
/// every SIMD ISA: tests/attention_isas.rs.
#[test]
fn staircase_attention_matches_the_reference() {
    let mut r = Lcg(19);
    for (c, nh) in [(32, 4), (40, 2), (128, 2), (96, 1)] {
        for (streams, t) in [(10, 29), (10, 3), (3, 7), (1, 5), (10, 1), (7, 13)] {
            let n = streams * t;
            let (q, k, v) = (r.vec(n * c), r.vec(n * c), r.vec(n * c));
            let want = naive_attention(&q, &k, &v, c, nh, &|i, j| j % t <= i % t);
            let mut work = vec![0.0f32; gemm_attention_work(n, n, c / nh).unwrap()];
            let mut out = vec![f32::NAN; n * c];
            assert!(attention_staircase(
                &q, &k, &v, c, nh, t, &mut work, &mut out
            ));
            assert_close(&out, &want, CLOSE);
            // Room for 3 heads at a time (a last wave of fewer): the same bits.
            let mut wide = vec![0.0f32; 3 * work.len() + 5];
            let mut again = vec![f32::NAN; n * c];
            assert!(attention_staircase(
                &q, &k, &v, c, nh, t, &mut wide, &mut again
            ));
            assert!(again
                .iter()
                .zip(&out)
                .all(|(a, b)| a.to_bits() == b.to_bits()));
            let mut keywise = vec![0.0f32; n * c];
            let mut scores = vec![0.0f32; n];
            let m = TiledCausalMask {
                t_q: t,
                t_k: t,
                q_pos0: 0,
            };
            assert_eq!(m.gemm(), Some(GemmMask::Staircase(t)));
            attention(&q, &k[..], &v[..], c, nh, &m, &mut scores, &mut keywise);
            assert_close(
                &out,
                &keywise.iter().map(|&x| x as f64).collect::<Vec<_>>(),
                CLOSE,
            );
            // Refusals: a short work buffer, rows that are not a whole window.
            let mut untouched = vec![7.0f32; n * c];
            let short = gemm_attention_work(n, n, c / nh).unwrap() - 1;
            assert!(!attention_staircase(
                &q,
                &k,
                &v,
                c,
                nh,
                t,
                &mut work[..short],
                &mut untouched
            ));
            if t > 1 {
                assert!(!attention_staircase(
                    &q[..(n - 1) * c],
                    &k,
                    &v,
                    c,
                    nh,
                    t,
                    &mut work,
                    &mut untouched
                ));
            }
            assert!(!attention_staircase(
                &q,
                &k,
                &v,
                c,
                0,
                t,
                &mut work,
                &mut untouched
            ));
            assert!(untouched.iter().all(|&x| x == 7.0));
        }
    }
    // Masks that are not a whole window from position 0 take the key-by-key kernel.
    let off = |t_q, t_k, q_pos0| TiledCausalMask { t_q, t_k, q_pos0 }.gemm();
    assert_eq!(off(1, 4, 3), None);
    assert_eq!(off(4, 4, 1), None);
    let band = |radius, q_pos0, k_pos0| {
        BandMask {
            radius,
            q_pos0,
            k_pos0,
        }
        .gemm()
    };
    assert_eq!(band(2, 0, 0), Some(GemmMask::Band(2)));
    assert_eq!(band(2, 1, 0), None);
    assert_eq!(band(2, 0, 3), None);
}

/// A LAT's band as per-head GEMMs (`attention_band`) against the f64
/// reference and the key-by-key kernel, radii 0-40 over 1-70 rows, heads
/// of 8, 20 and 96 lanes; the first `nq` queries alone (a LAT's last
/// block) give the bits of the same rows of all of them; a short `work`
/// or more queries than keys are refused.
#[test]
fn band_attention_matches_the_reference() {
    let mut r = Lcg(23);
    for (c, nh) in [(32, 4), (40, 2), (96, 1)] {
        for (n, radius) in [
            (1, 0),
            (7, 0),
            (20, 4),
            (70, 9),
            (58, 29),
            (40, 40),
            (13, 100),
        ] {
            let (q, k, v) = (r.vec(n * c), r.vec(n * c), r.vec(n * c));
            let want = naive_attention(&q, &k, &v, c, nh, &|i, j| i.abs_diff(j) <= radius);
            let mut work = vec![0.0f32; gemm_attention_work(n, n, c / nh).unwrap()];
            let mut out = vec![f32::NAN; n * c];
            assert!(attention_band(
                &q, &k, &v, c, nh, radius, &mut work, &mut out
            ));
            assert_close(&out, &want, CLOSE);
            let mut keywise = vec![0.0f32; n * c];
            let mut scores = vec![0.0f32; n];
            let m = BandMask {
                radius,
                q_pos0: 0,
                k_pos0: 0,
            };
            attention(&q, &k[..], &v[..], c, nh, &m, &mut scores, &mut keywise);
            assert_close(
                &out,
                &keywise.iter().map(|&x| x as f64).collect::<Vec<_>>(),
                CLOSE,
            );
            // The first nq queries alone: the same bits as in the whole.
            for nq in [1, n / 2, n.saturating_sub(1)]
                .into_iter()
                .filter(|&m| m >= 1)
            {
                let mut w = vec![0.0f32; gemm_attention_work(nq, n, c / nh).unwrap()];
                let mut part = vec![f32::NAN; nq * c];
                assert!(attention_band(
                    &q[..nq * c],
                    &k,
                    &v,
                    c,
                    nh,
                    radius,
                    &mut w,
                    &mut part
                ));
                assert!(
                    part.iter()
                        .zip(&out)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "first {nq} of {n} rows, radius {radius}"
                );
                let short = w.len() - 1;
                assert!(!attention_band(
                    &q[..nq * c],
                    &k,
                    &v,
                    c,
                    nh,
                    radius,
                    &mut w[..short],
                    &mut part
                ));
            }
            if n > 1 {
                let mut untouched = vec![7.0f32; n * c];
                assert!(!attention_band(
                    &q,
                    &k[..(n - 1) * c],
                    &v,
                    c,
                    nh,
                    radius,
                    &mut work,
                    &mut untouched
                ));
                assert!(untouched.iter().all(|&x| x == 7.0));
            }
        }
    }
}

/// A band that claims every query sees the same keys (it does not): the
/// group's check of the members' key runs must take each query alone.
struct FalsePeriod(BandMask);
impl Mask for FalsePeriod {
    fn allowed(&self, qi: usize, kj: usize) -> bool {
        self.0.allowed(qi, kj)
    }
    fn period(&self) -> Option<usize> {
        Some(1)
    }
}

/// Queries scored in groups ([`Mask::period`]) give, bit for bit, what
/// each query attended alone gives: the tiled causal mask of 1-10 streams
/// (S-mode rows of one position, R-mode windows, offsets `q_pos0`), f32
/// rows and f16 rows split in two runs, heads of 8, 64 and 96 lanes (past
/// the register block), score buffers of 1-5 rows; a false period is caught
/// by the run check (equal to the band alone and to the naive reference).
#[test]
fn grouped_queries_equal_each_query_alone() {
    let mut r = Lcg(71);
    for (c, nh) in [(32, 4), (128, 2), (96, 1)] {
        for (streams, t_q, t_k, q_pos0) in [
            (10, 1, 4, 3),
            (10, 4, 4, 0),
            (5, 7, 9, 2),
            (3, 2, 5, 1),
            (1, 6, 6, 0),
        ] {
            let (nq, nk) = (streams * t_q, streams * t_k);
            let (q, k, v) = (r.vec(nq * c), r.vec(nk * c), r.vec(nk * c));
            let f16 = |x: &[f32]| -> Vec<u16> {
                x.iter()
                    .map(|&a| half::f16::from_f32(a).to_bits())
                    .collect()
            };
            let (k16, v16) = (f16(&k), f16(&v));
            let split = (nk / 3) * c;
            let m = TiledCausalMask { t_q, t_k, q_pos0 };
            for rows in [1, 2, 5] {
                let mut scores = vec![0.0; rows * nk];
                let (mut grouped, mut alone) = (vec![f32::NAN; nq * c], vec![f32::NAN; nq * c]);
                attention(&q, &k[..], &v[..], c, nh, &m, &mut scores, &mut grouped);
                attention(
                    &q,
                    &k[..],
                    &v[..],
                    c,
                    nh,
                    &Ungrouped(m),
                    &mut scores,
                    &mut alone,
                );
                assert!(
                    grouped
                        .iter()
                        .zip(&alone)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "f32 c={c} {streams}x{t_q} q_pos0={q_pos0} rows={rows}"
                );
                fn kv16(d: &[u16], split: usize) -> KvRows<'_> {
                    KvRows::two(RowData::F16(&d[..split]), RowData::F16(&d[split..]))
                }
                let (mut grouped16, mut alone16) = (vec![f32::NAN; nq * c], vec![f32::NAN; nq * c]);
                attention(
                    &q,
                    kv16(&k16, split),
                    kv16(&v16, split),
                    c,
                    nh,
                    &m,
                    &mut scores,
                    &mut grouped16,
                );
                attention(
                    &q,
                    kv16(&k16, split),
                    kv16(&v16, split),
                    c,
                    nh,
                    &Ungrouped(m),
                    &mut scores,
                    &mut alone16,
                );
                assert!(
                    grouped16
                        .iter()
                        .zip(&alone16)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "f16 c={c} {streams}x{t_q} q_pos0={q_pos0} rows={rows}"
                );
            }
            let want = naive_attention(&q, &k, &v, c, nh, &|i, j| j % t_k <= q_pos0 + i % t_q);
            let mut scores = vec![0.0; nk];
            let mut out = vec![0.0; nq * c];
            attention(&q, &k[..], &v[..], c, nh, &m, &mut scores, &mut out);
            assert_close(&out, &want, CLOSE);
        }
        let n = 24;
        let (q, k, v) = (r.vec(n * c), r.vec(n * c), r.vec(n * c));
        let band = BandMask {
            radius: 3,
            q_pos0: 0,
            k_pos0: 0,
        };
        let mut scores = vec![0.0; 4 * n];
        let (mut fooled, mut plain) = (vec![0.0; n * c], vec![0.0; n * c]);
        attention(
            &q,
            &k[..],
            &v[..],
            c,
            nh,
            &FalsePeriod(band),
            &mut scores,
            &mut fooled,
        );
        attention(&q, &k[..], &v[..], c, nh, &band, &mut scores, &mut plain);
        assert!(
            fooled
                .iter()
                .zip(&plain)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "false period c={c}"
        );
        assert_close(
            &fooled,
            &naive_attention(&q, &k, &v, c, nh, &|i, j| i.abs_diff(j) <= 3),
            CLOSE,
        );
    }
}

/// `linear_xw` (passes of 8 weight rows, output rows 4 at a time over a
/// dense row's lanes loaded once) gives, bit for bit, one `axpy` per
/// (weight row, input row) in weight-row order, as it did before: f32 and
/// f16 rows, 0-9 input rows (whole groups and rests), weight rows across
/// pass ends, output widths with 64-lane blocks, 8-lane bodies and tails.
#[test]
fn linear_xw_equals_one_axpy_per_row_and_input() {
    use crate::kernels::weights::RowMatrix;
    let mut r = Lcg(83);
    for rows in [1, 3, 8, 9, 17] {
        for cols in [1, 7, 8, 64, 65, 130] {
            let w = r.vec(rows * cols);
            let w16: Vec<u16> = w
                .iter()
                .map(|&v| half::f16::from_f32(v).to_bits())
                .collect();
            let f32m = F32Rows::new(&w, rows, cols).unwrap();
            let f16m = F16Rows::new(&w16, rows, cols).unwrap();
            for n in 0..=9 {
                let x = r.vec(n * rows);
                let check = |m: &Matrix<'_>, one: &dyn Fn(usize, f32, &mut [f32]), name: &str| {
                    let mut z = vec![f32::NAN; n * cols];
                    linear_xw(&x, m, &mut z);
                    let mut want = vec![0.0f32; n * cols];
                    for k in 0..rows {
                        for i in 0..n {
                            one(k, x[i * rows + k], &mut want[i * cols..(i + 1) * cols]);
                        }
                    }
                    assert!(
                        z.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()),
                        "{name} rows={rows} cols={cols} n={n}"
                    );
                };
                check(&Matrix::F32(f32m), &|k, a, y| f32m.axpy(k, a, y), "f32");
                check(&Matrix::F16(f16m), &|k, a, y| f16m.axpy(k, a, y), "f16");
            }
        }
    }
}

/// The runs of keys `0..nk` query `qi` may see, by scanning `allowed`.
fn scanned_runs<M: Mask>(m: &M, qi: usize, nk: usize) -> Vec<(usize, usize)> {
    let mut runs = Vec::new();
    let mut kj = 0;
    while kj < nk {
        if m.allowed(qi, kj) {
            let a = kj;
            while kj < nk && m.allowed(qi, kj) {
                kj += 1;
            }
            runs.push((a, kj));
        } else {
            kj += 1;
        }
    }
    runs
}

/// A mask's closed-form `key_runs` equals scanning `allowed` for queries
/// `0..nq` and `0..=nk_max` keys: the count, and the runs that fit in a
/// buffer of 64 and of 2 (the first two).
pub(crate) fn assert_key_runs_scan<M: Mask>(what: &str, m: &M, nq: usize, nk_max: usize) {
    for nk in 0..=nk_max {
        for qi in 0..nq {
            let want = scanned_runs(m, qi, nk);
            for cap in [64usize, 2] {
                let mut got = vec![(usize::MAX, usize::MAX); cap];
                let n = m
                    .key_runs(qi, nk, &mut got)
                    .unwrap_or_else(|| panic!("{what}: no closed form"));
                assert_eq!(n, want.len(), "{what} qi={qi} nk={nk}: count");
                let k = n.min(cap);
                assert_eq!(got[..k], want[..k], "{what} qi={qi} nk={nk} cap={cap}");
            }
        }
    }
}

#[test]
fn mask_key_runs_equal_the_scan() {
    for radius in [0usize, 1, 3, 7, 116] {
        for (q0, k0) in [(0usize, 0usize), (5, 0), (0, 5), (20, 3), (3, 40)] {
            assert_key_runs_scan(
                &format!("band r={radius} q0={q0} k0={k0}"),
                &BandMask {
                    radius,
                    q_pos0: q0,
                    k_pos0: k0,
                },
                12,
                60,
            );
        }
    }
    for (t_q, t_k) in [(1usize, 1usize), (1, 4), (3, 8), (5, 5), (29, 29), (4, 3)] {
        for q0 in [0usize, 1, 3, 7, 28, 40] {
            let m = TiledCausalMask {
                t_q,
                t_k,
                q_pos0: q0,
            };
            assert_key_runs_scan(
                &format!("tiled t_q={t_q} t_k={t_k} q0={q0}"),
                &m,
                2 * t_q + 1,
                3 * t_k + 2,
            );
            assert_key_runs_scan(
                &format!("ungrouped tiled t_q={t_q} t_k={t_k} q0={q0}"),
                &Ungrouped(m),
                t_q,
                2 * t_k + 1,
            );
        }
    }
    // The R window: 10 streams of 29, 290 keys.
    assert_key_runs_scan(
        "R window",
        &TiledCausalMask {
            t_q: 29,
            t_k: 29,
            q_pos0: 0,
        },
        290,
        290,
    );
    assert_key_runs_scan(
        "LAT band",
        &crate::duolando::session::lat_stream::Visible,
        3,
        40,
    );
}

/// A `Cols` window covers exactly its rows and columns: rows read and
/// written through it land at `i0 + m`, columns `a..b`; `split_rows`
/// hands out the rows in order; windows past the output or outside the
/// view's columns panic instead of reaching memory.
#[test]
fn cols_window_covers_its_block() {
    use crate::kernels::parallel::Cols;
    let (rows, stride) = (5usize, 7usize);
    let mut y = std::vec![0.0f32; rows * stride];
    {
        let mut cols = Cols::whole(&mut y, stride);
        let w = cols.window(1, 3, 2, 6);
        assert_eq!((w.rows(), w.cols()), (3, 4));
        let (mut top, mut rest) = w.split_rows(1);
        assert_eq!((top.rows(), rest.rows()), (1, 2));
        top.row(0).fill(1.0);
        rest.row(0).fill(2.0);
        rest.row(1).fill(3.0);
        let (all, none) = rest.split_rows(9);
        assert_eq!((all.rows(), none.rows()), (2, 0));
        assert_eq!(cols.window(5, 0, 0, 7).rows(), 0);
    }
    for i in 0..rows {
        for j in 0..stride {
            let want = if (2..6).contains(&j) && (1..4).contains(&i) {
                i as f32
            } else {
                0.0
            };
            assert_eq!(y[i * stride + j], want, "[{i}][{j}]");
        }
    }
    let outside = |i0: usize, n: usize, a: usize, b: usize| {
        std::panic::catch_unwind(move || {
            let mut y = std::vec![0.0f32; rows * stride];
            Cols::whole(&mut y, stride).window(i0, n, a, b).rows()
        })
        .is_err()
    };
    assert!(outside(3, 3, 0, 7), "rows past the output");
    assert!(outside(0, 1, 3, 8), "columns past the row");
    assert!(outside(0, 1, 5, 4), "an inverted range");
    assert!(outside(usize::MAX, 2, 0, 1), "an overflowing row index");
    assert!(!outside(4, 1, 0, 7), "the last row");
    let panics = std::panic::catch_unwind(|| {
        let mut y = std::vec![0.0f32; rows * stride];
        Cols::whole(&mut y, stride).window(0, 2, 0, 3).row(2).len()
    });
    assert!(panics.is_err(), "a row past the window");
}
