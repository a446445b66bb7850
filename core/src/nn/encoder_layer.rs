//! torch's `nn.TransformerEncoderLayer` as its defaults build it
//! (`norm_first=False`, ReLU, LayerNorm eps 1e-5, fused `in_proj`):
//! the POST-LN layer
//!
//! ```text
//! x = norm1(x + out_proj(MHA(x; in_proj) [+ bias in the scores]))
//! x = norm2(x + linear2(relu(linear1(x))))
//! ```
//!
//! with every row attending to every row (no mask), optionally with an
//! additive score bias (L, L) shared by every head (torch's float
//! `src_mask`). Transflower's transformers are stacks of it (DESIGN.md §7).
//! Unlike [`crate::nn::block`] (pre-LN, GELU MLP x4, separate q/k/v) the
//! FFN width is free (`dim_feedforward`) and q, k, v come from one GEMM.

use crate::arena::{ArenaError, Carve};
use crate::kernels::simd;
use crate::kernels::{layernorm, linear, matmul, relu_inplace, RowData};
use crate::nn::bind::{BindError, Binder, TensorSource};
use crate::nn::kv_store::{KvBuf, KvType};
use crate::nn::names::{name, Emit, Role, SchemaError};
use crate::nn::weights::{LayerNormW, Linear};

/// One `TransformerEncoderLayer(d, nhead, dim_feedforward = f)`.
#[derive(Clone, Copy, Debug)]
pub struct EncoderLayerW<'a> {
    /// `self_attn.in_proj_weight` (3d, d) / `in_proj_bias` (3d): q | k | v.
    pub in_proj: Linear<'a>,
    /// `self_attn.out_proj` (d, d).
    pub out_proj: Linear<'a>,
    /// `linear1` (f, d), `linear2` (d, f).
    pub linear1: Linear<'a>,
    pub linear2: Linear<'a>,
    /// `norm1` (after attention), `norm2` (after the FFN).
    pub norm1: LayerNormW<'a>,
    pub norm2: LayerNormW<'a>,
}

/// Binds the layer under `prefix` (e.g. `...transformer_encoder.layers.0`).
pub fn bind_encoder_layer<'a, S: TensorSource<'a>>(
    b: &Binder<'_, S>,
    prefix: &str,
    d: u32,
    f: u32,
) -> Result<EncoderLayerW<'a>, BindError> {
    let p = |s: &str| name(format_args!("{prefix}.{s}"));
    let d3 = d.checked_mul(3).ok_or(BindError::Capacity)?;
    Ok(EncoderLayerW {
        in_proj: Linear {
            w: b.matrix(p("self_attn.in_proj_weight")?, &[d3, d])?,
            b: Some(b.get(p("self_attn.in_proj_bias")?, &[d3])?),
        },
        out_proj: b.linear(&p("self_attn.out_proj")?, d, d, true)?,
        linear1: b.linear(&p("linear1")?, f, d, true)?,
        linear2: b.linear(&p("linear2")?, d, f, true)?,
        norm1: b.ln(&p("norm1")?, d)?,
        norm2: b.ln(&p("norm2")?, d)?,
    })
}

/// Lists the layer's tensors (the order of torch's `state_dict`).
pub fn emit_encoder_layer<E: From<SchemaError>>(
    e: &mut Emit<'_, E>,
    prefix: &str,
    d: u32,
    f: u32,
) -> Result<(), E> {
    let p = |s: &str| name(format_args!("{prefix}.{s}"));
    e.t(p("self_attn.in_proj_weight")?, &[3 * d, d], Role::Linear)?;
    e.t(p("self_attn.in_proj_bias")?, &[3 * d], Role::Vector)?;
    e.wb(&p("self_attn.out_proj")?, &[d, d], d, Role::Linear)?;
    e.wb(&p("linear1")?, &[f, d], f, Role::Linear)?;
    e.wb(&p("linear2")?, &[d, f], d, Role::Linear)?;
    e.wb(&p("norm1")?, &[d], d, Role::Vector)?;
    e.wb(&p("norm2")?, &[d], d, Role::Vector)
}

/// Working memory of [`encoder_layer`] over at most `rows` rows of width
/// `d` with FFN width `f`.
pub struct EncoderLayerScratch<'s> {
    /// (rows, 3d): q | k | v per row.
    qkv: &'s mut [f32],
    /// (rows, d): attention output, then the FFN output.
    att: &'s mut [f32],
    /// (rows, d): the queries, head-major (head h: (rows, d / n_head)),
    /// then each head's attention output in the same place.
    q: &'s mut [f32],
    /// (rows, rows): one head's attention probabilities.
    probs: &'s mut [f32],
    /// (rows, d): out_proj output + residual, then FFN output + residual.
    sum: &'s mut [f32],
    /// (rows, f): FFN hidden rows.
    hid: &'s mut [f32],
    /// (keys): one query's scores.
    scores: &'s mut [f32],
    /// Rows one call computes at a time.
    rows: usize,
}

impl<'s> EncoderLayerScratch<'s> {
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        rows: usize,
        d: usize,
        f: usize,
    ) -> Result<Self, ArenaError> {
        Self::carve_keys(a, rows, rows, d, f)
    }

    /// Scratch for `rows` rows at a time (of a whole layer, or of
    /// [`encoder_layer_rows`]) against at most `keys` kept rows
    /// (`keys >= rows`).
    pub fn carve_keys<A: Carve<'s>>(
        a: &mut A,
        rows: usize,
        keys: usize,
        d: usize,
        f: usize,
    ) -> Result<Self, ArenaError> {
        let rd = rows.checked_mul(d).ok_or(ArenaError::Overflow)?;
        Ok(EncoderLayerScratch {
            qkv: a.f32(rd.checked_mul(3).ok_or(ArenaError::Overflow)?)?,
            att: a.f32(rd)?,
            q: a.f32(rd)?,
            probs: a.f32(rows.checked_mul(rows).ok_or(ArenaError::Overflow)?)?,
            sum: a.f32(rd)?,
            hid: a.f32(rows.checked_mul(f).ok_or(ArenaError::Overflow)?)?,
            scores: a.f32(keys.max(rows))?,
            rows,
        })
    }

    /// Rows this scratch was carved for.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// After [`encoder_layer`] over `n` rows of width `d`: each row's
    /// q | k | v (n, 3d) of that layer (what a cache of its keys and values
    /// keeps: [`encoder_layer_rows`]).
    pub fn qkv(&self, n: usize, d: usize) -> &[f32] {
        &self.qkv[..(3 * n * d).min(self.qkv.len())]
    }
}

/// One layer over `x` (n, d) in place, n = `x.len() / d`, with `n_head`
/// heads and an optional additive score bias `bias` (n, n): bias[i * n + j]
/// is added to query i's score of key j (every head).
///
/// Only the first `keep` rows are computed through to the output (keys and
/// values from all n rows): `x[..keep * d]` holds the layer's output, the
/// rest of `x` is left as it was. `keep = n` is the whole layer; a smaller
/// `keep` serves a last layer of which only the first rows are read (the
/// cross-modal net's conditioning rows). The caller sizes the scratch
/// (`n <= rows`) and checks `bias.len() == n * n`.
pub fn encoder_layer(
    w: &EncoderLayerW<'_>,
    x: &mut [f32],
    d: usize,
    n_head: usize,
    bias: Option<&[f32]>,
    keep: usize,
    s: &mut EncoderLayerScratch<'_>,
) {
    if d == 0 || n_head == 0 {
        return;
    }
    let n = x.len() / d;
    let keep = keep.min(n);
    let f = w.linear1.w.rows();
    let (nd, kd) = (n * d, keep * d);
    // (n, 3d) = x in_proj^T + in_proj_bias.
    let qkv = &mut s.qkv[..3 * nd];
    linear(x, &w.in_proj.w, w.in_proj.b, qkv);
    // (keep, d) attention output of the kept query rows.
    match bias {
        Some(_) => self_attention(
            qkv,
            n,
            d,
            n_head,
            bias,
            keep,
            &mut s.scores[..n],
            &mut s.att[..kd],
        ),
        None if f >= d && s.probs.len() >= keep * n => attention_gemm(n, d, n_head, keep, s),
        None => self_attention(
            qkv,
            n,
            d,
            n_head,
            None,
            keep,
            &mut s.scores[..n],
            &mut s.att[..kd],
        ),
    }
    after_attention(w, &mut x[..kd], d, f, s);
}

/// The rest of the layer over the rows `x` (m, d) whose attention output
/// is in `s.att[..m d]`: `x = norm1(x + out_proj(att))`, then
/// `x = norm2(x + linear2(relu(linear1(x))))`.
fn after_attention(
    w: &EncoderLayerW<'_>,
    x: &mut [f32],
    d: usize,
    f: usize,
    s: &mut EncoderLayerScratch<'_>,
) {
    let kd = x.len();
    let m = kd / d;
    let sum = &mut s.sum[..kd];
    linear(&s.att[..kd], &w.out_proj.w, w.out_proj.b, sum);
    add(sum, x);
    layernorm(sum, w.norm1.w, w.norm1.b, x);
    let hid = &mut s.hid[..m * f];
    linear(x, &w.linear1.w, w.linear1.b, hid);
    relu_inplace(hid);
    let ff = &mut s.att[..kd];
    linear(hid, &w.linear2.w, w.linear2.b, ff);
    add(ff, x);
    layernorm(ff, w.norm2.w, w.norm2.b, x);
}

/// Where a layer's keys and values of `n` rows are kept between calls of
/// [`encoder_layer_rows`]: `k`, `v` (n, d) each in a [`KvBuf`]'s storage
/// (f32, or f16 rounded once when stored), a row per slot.
pub struct LayerKv<'s> {
    pub k: KvBuf<'s>,
    pub v: KvBuf<'s>,
}

impl<'s> LayerKv<'s> {
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        kv: KvType,
        n: usize,
        d: usize,
    ) -> Result<Self, ArenaError> {
        let nd = n.checked_mul(d).ok_or(ArenaError::Overflow)?;
        Ok(LayerKv {
            k: KvBuf::carve(a, kv, nd)?,
            v: KvBuf::carve(a, kv, nd)?,
        })
    }

    /// Stores the keys and values of `qkv` (n, 3d), row `j` into slot `j`
    /// (what [`EncoderLayerScratch::qkv`] holds after a whole layer).
    pub fn store_all(&mut self, qkv: &[f32], d: usize) {
        for (j, row) in qkv.chunks_exact(3 * d).enumerate() {
            // In range: the caller carved n >= the rows of `qkv`.
            let _ = self.k.store(j * d, &row[d..2 * d]);
            let _ = self.v.store(j * d, &row[2 * d..]);
        }
    }
}

/// The score bias of [`encoder_layer_rows`]: `bias` (L, L) by window
/// position, `pos[j]` the current position of the row in slot `j`.
#[derive(Clone, Copy, Debug)]
pub struct SlotBias<'x> {
    pub bias: &'x [f32],
    pub pos: &'x [u32],
}

/// One layer over only some rows of a sequence whose other rows' keys and
/// values are kept in `kv` from earlier calls: `x` (m, d) holds the rows
/// to compute (in place), `slots[r]` the slot of row r. Their keys and
/// values are stored into their slots first (replacing what was there);
/// then each row attends to every slot of `kv` (n rows, no mask; with
/// `bias`, query r's score of slot j gets `bias[pos[slots[r]] L + pos[j]]`),
/// and the rest of the layer is [`encoder_layer`]'s. With every slot's keys
/// and values from the same layer inputs, a row's numbers are those of
/// the whole layer up to the order of the softmax sums; with keys and values
/// kept from earlier inputs (stale rows), it is an approximation
/// (Transflower's stale-rows S mode). Scratch: `m` and `n` rows.
#[allow(clippy::too_many_arguments)]
pub fn encoder_layer_rows(
    w: &EncoderLayerW<'_>,
    x: &mut [f32],
    d: usize,
    n_head: usize,
    kv: &mut LayerKv<'_>,
    slots: &[u32],
    bias: Option<SlotBias<'_>>,
    s: &mut EncoderLayerScratch<'_>,
) {
    if d == 0 || n_head == 0 || !d.is_multiple_of(n_head) {
        return;
    }
    let m = store_rows_kv(w, x, d, kv, slots, s);
    let n = kv.k.len() / d;
    let f = w.linear1.w.rows();
    let qkv = &s.qkv[..3 * m * d];
    let hd = d / n_head;
    let scale = 1.0 / libm::sqrtf(hd as f32);
    let scores = &mut s.scores[..n];
    let (Ok(kd), Ok(vd)) = (kv.k.view(0, n * d), kv.v.view(0, n * d)) else {
        return;
    };
    for r in 0..m {
        for h in 0..n_head {
            let q = &qkv[r * 3 * d + h * hd..][..hd];
            match kd {
                RowData::F32(k) => simd::dot_rows(q, &k[h * hd..], d, scores),
                RowData::F16(k) => simd::dot_rows_f16(q, &k[h * hd..], d, scores),
            }
            let max = match bias {
                None => simd::scale_max(scores, scale, f32::NEG_INFINITY),
                Some(b) => {
                    let l = b.pos.len();
                    let qp = b.pos[slots[r] as usize] as usize;
                    let row = &b.bias[qp * l..(qp + 1) * l];
                    let mut max = f32::NEG_INFINITY;
                    for (sc, &pj) in scores.iter_mut().zip(b.pos) {
                        *sc = *sc * scale + row[pj as usize];
                        max = max.max(*sc);
                    }
                    max
                }
            };
            let sum = simd::exp_shifted_sum(scores, max);
            let inv = if sum > 0.0 { 1.0 / sum } else { 0.0 };
            for sc in scores.iter_mut() {
                *sc *= inv;
            }
            let o = &mut s.att[r * d + h * hd..][..hd];
            o.fill(0.0);
            match vd {
                RowData::F32(v) => simd::axpy_rows_f32(scores, &v[h * hd..], d, o),
                RowData::F16(v) => simd::axpy_rows_f16(scores, &v[h * hd..], d, o),
            }
        }
    }
    after_attention(w, &mut x[..m * d], d, f, s);
}

/// The first half of [`encoder_layer_rows`]: the q | k | v of the rows
/// `x` (m, d) into the scratch's `qkv` (m, 3d), their keys and values into
/// their slots of `kv` (m = the rows of `x` that have a slot). A whole
/// sequence too long for the scratch goes through a layer in two passes
/// (`transflower::transformer::forward_chunked`): this over every chunk,
/// then [`encoder_layer_rows`] over every chunk (which stores the same
/// keys and values again: `linear` computes each row on its own).
pub fn store_rows_kv(
    w: &EncoderLayerW<'_>,
    x: &[f32],
    d: usize,
    kv: &mut LayerKv<'_>,
    slots: &[u32],
    s: &mut EncoderLayerScratch<'_>,
) -> usize {
    let m = (x.len() / d.max(1)).min(slots.len());
    let qkv = &mut s.qkv[..3 * m * d];
    linear(&x[..m * d], &w.in_proj.w, w.in_proj.b, qkv);
    for (r, &slot) in slots[..m].iter().enumerate() {
        let row = &qkv[r * 3 * d..(r + 1) * 3 * d];
        // A slot outside the cache leaves it unchanged (callers pass slots < n).
        let at = slot as usize * d;
        let _ = kv.k.store(at, &row[d..2 * d]);
        let _ = kv.v.store(at, &row[2 * d..]);
    }
    m
}

fn add(y: &mut [f32], x: &[f32]) {
    for (a, b) in y.iter_mut().zip(x) {
        *a += b;
    }
}

/// [`self_attention`] without a bias as GEMMs: per head, the scores
/// (keep, n) = q_h k_h^T and the output (keep, hd) = p_h v_h through
/// [`matmul`] (the right operand row-major, one running sum per value,
/// threads), the softmax between as [`self_attention`] does it. Keys go
/// transposed into `hid` (hd, n per head), values head-major into `sum`
/// (n, hd per head), queries into `q` (keep, hd per head), where each
/// head's output then lands; `att` (keep, d) gets them back row-major.
/// `qkv` is left as it was ([`EncoderLayerScratch::qkv`]).
///
/// Until 2026-12-06 both products ran as `linear` dot-product tiles over
/// head-major keys and transposed values: with a head's 80 values as the
/// inner length, the tiles' end-of-row reductions cost as much as the
/// products (28% of Transflower's R step, docs/TRANSFLOWER.md).
fn attention_gemm(n: usize, d: usize, n_head: usize, keep: usize, s: &mut EncoderLayerScratch<'_>) {
    let hd = d / n_head;
    let scale = 1.0 / libm::sqrtf(hd as f32);
    let qkv = &s.qkv[..3 * n * d];
    let (q, v, kt) = (
        &mut s.q[..keep * d],
        &mut s.sum[..n * d],
        &mut s.hid[..n * d],
    );
    for (j, row) in qkv.chunks_exact(3 * d).take(n).enumerate() {
        for h in 0..n_head {
            let (qh, vh) = (&row[h * hd..][..hd], &row[2 * d + h * hd..][..hd]);
            if j < keep {
                q[(h * keep + j) * hd..][..hd].copy_from_slice(qh);
            }
            v[(h * n + j) * hd..][..hd].copy_from_slice(vh);
        }
    }
    // The keys transposed 16 rows at a time: each (head, lane) row of `kt`
    // gets 16 consecutive values per pass (one cache line), not one value
    // per row of `qkv` (a line written 16 times, evicted in between: the
    // whole `kt` is larger than L2 at full size).
    for j0 in (0..n).step_by(16) {
        let rows = &qkv[j0 * 3 * d..(j0 + 16).min(n) * 3 * d];
        for h in 0..n_head {
            for t in 0..hd {
                let dst = &mut kt[(h * hd + t) * n + j0..][..rows.len() / (3 * d)];
                for (x, row) in dst.iter_mut().zip(rows.chunks_exact(3 * d)) {
                    *x = row[d + h * hd + t];
                }
            }
        }
    }
    let probs = &mut s.probs[..keep * n];
    for h in 0..n_head {
        let (kth, vh) = (
            &kt[h * hd * n..(h + 1) * hd * n],
            &v[h * n * hd..(h + 1) * n * hd],
        );
        let qh = &mut q[h * keep * hd..(h + 1) * keep * hd];
        matmul(qh, kth, keep, hd, n, probs);
        for p in probs.chunks_exact_mut(n) {
            let max = simd::scale_max(p, scale, f32::NEG_INFINITY);
            let sum = simd::exp_shifted_sum(p, max);
            let inv = if sum > 0.0 { 1.0 / sum } else { 0.0 };
            for v in p.iter_mut() {
                *v *= inv;
            }
        }
        matmul(probs, vh, keep, n, hd, qh);
    }
    for i in 0..keep {
        for h in 0..n_head {
            s.att[i * d + h * hd..][..hd].copy_from_slice(&q[(h * keep + i) * hd..][..hd]);
        }
    }
}

/// Multi-head attention of query rows `0..keep` over all `n` rows, no mask:
/// `qkv` (n, 3d) holds each row's q | k | v; `out` (keep, d). Scores are
/// `q_i . k_j / sqrt(d / n_head) (+ bias[i, j])`, softmax over j, then the
/// probability-weighted value rows (`simd::dot_rows`, `exp_shifted_sum`,
/// `axpy_rows_f32`: the attention kernel's operations). `scores`: (n).
#[allow(clippy::too_many_arguments)]
fn self_attention(
    qkv: &[f32],
    n: usize,
    d: usize,
    n_head: usize,
    bias: Option<&[f32]>,
    keep: usize,
    scores: &mut [f32],
    out: &mut [f32],
) {
    let hd = d / n_head;
    let scale = 1.0 / libm::sqrtf(hd as f32);
    let stride = 3 * d;
    for i in 0..keep {
        for h in 0..n_head {
            let q = &qkv[i * stride + h * hd..][..hd];
            // Key j, head h: qkv[j * 3d + d + h * hd ..][..hd].
            simd::dot_rows(q, &qkv[d + h * hd..], stride, scores);
            let max = match bias {
                None => simd::scale_max(scores, scale, f32::NEG_INFINITY),
                Some(b) => {
                    let mut max = f32::NEG_INFINITY;
                    for (sc, &bj) in scores.iter_mut().zip(&b[i * n..(i + 1) * n]) {
                        *sc = *sc * scale + bj;
                        max = max.max(*sc);
                    }
                    max
                }
            };
            let sum = simd::exp_shifted_sum(scores, max);
            let inv = if sum > 0.0 { 1.0 / sum } else { 0.0 };
            for sc in scores.iter_mut() {
                *sc *= inv;
            }
            let o = &mut out[i * d + h * hd..][..hd];
            o.fill(0.0);
            // Value j, head h: qkv[j * 3d + 2d + h * hd ..][..hd].
            simd::axpy_rows_f32(scores, &qkv[2 * d + h * hd..], stride, o);
        }
    }
}
