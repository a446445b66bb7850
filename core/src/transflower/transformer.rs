//! The authors' `BasicTransformerModel` (models/transformer.py) forward,
//! used by the input encoders, the cross-modal transformer and every
//! coupling: `encoder1` -> [+ `pe`] -> post-LN encoder layers (every row
//! sees every row; [+ `pos_emb` in the scores]) -> `decoder`. A discrete
//! input's embedding lookup happens before (the caller passes the row).

use crate::arena::{ArenaError, Carve};
use crate::kernels::linear;
use crate::nn::encoder_layer::{
    encoder_layer, encoder_layer_rows, store_rows_kv, EncoderLayerScratch, LayerKv, SlotBias,
};
use crate::transflower::model::TransformerW;
use crate::transflower::probe::{Probe, Stage};

/// Working memory of [`forward`] over at most `rows` rows of width at most `d`.
pub struct TransformerScratch<'s> {
    /// (rows, d): the hidden rows.
    x: &'s mut [f32],
    layer: EncoderLayerScratch<'s>,
}

impl<'s> TransformerScratch<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, rows: usize, d: usize) -> Result<Self, ArenaError> {
        Self::carve_keys(a, rows, rows, d)
    }

    /// Scratch for `rows` rows at a time against at most `keys` kept rows
    /// ([`forward_rows`], [`forward_chunked`]; [`forward`] over at most
    /// `rows` rows).
    pub fn carve_keys<A: Carve<'s>>(
        a: &mut A,
        rows: usize,
        keys: usize,
        d: usize,
    ) -> Result<Self, ArenaError> {
        Ok(TransformerScratch {
            x: a.f32(rows.checked_mul(d).ok_or(ArenaError::Overflow)?)?,
            layer: EncoderLayerScratch::carve_keys(a, rows, keys, d, d)?,
        })
    }

    /// Rows one call computes at a time.
    pub fn rows(&self) -> usize {
        self.layer.rows()
    }
}

/// `out` (keep, dout) = the transformer over `input` (L, din), of whose
/// output only the first `keep` rows are computed (the last layer's other
/// rows are never read: the cross-modal net's conditioning rows, a
/// coupling's frame rows). `probe(stage, rows)` sees every stage output
/// (`Stage::Layer` of the last layer and `Stage::Decoder`: `keep` rows).
/// Callers size the scratch and check `input.len() == L * din` with
/// L matching `pe` / `pos_emb` rows (the config fixes both).
pub fn forward<const N: usize>(
    w: &TransformerW<'_, N>,
    input: &[f32],
    keep: usize,
    s: &mut TransformerScratch<'_>,
    out: &mut [f32],
    probe: &mut dyn FnMut(Stage, &[f32]),
) {
    forward_recorded(w, input, keep, s, out, probe, &mut |_, _| {});
}

/// [`forward`] that also hands each layer's q | k | v of every row (L, 3d)
/// to `layer_qkv(layer, qkv)` (a stale-rows session keeps the keys and
/// values: `transflower::session`). Same numbers.
pub fn forward_recorded<const N: usize>(
    w: &TransformerW<'_, N>,
    input: &[f32],
    keep: usize,
    s: &mut TransformerScratch<'_>,
    out: &mut [f32],
    probe: &mut dyn FnMut(Stage, &[f32]),
    layer_qkv: &mut dyn FnMut(usize, &[f32]),
) {
    let d = w.d;
    let rows = input.len() / w.din.max(1);
    // (L, d) = encoder1(input).
    let x = &mut s.x[..rows * d];
    linear(input, &w.encoder1.w, w.encoder1.b, x);
    probe(Stage::Encoder1, x);
    if let Some(pe) = w.pe {
        // `pe` (L, 1, d): its rows are the config's L.
        for (v, p) in x.iter_mut().zip(pe) {
            *v += p;
        }
        probe(Stage::PosEncoder, x);
    }
    let n = w.layers.len();
    for (i, layer) in w.layers.iter().enumerate() {
        let k = if i + 1 == n { keep } else { rows };
        encoder_layer(layer, x, d, w.n_head, w.bias, k, &mut s.layer);
        layer_qkv(i, s.layer.qkv(rows, d));
        probe(Stage::Layer(i as u32), &x[..k * d]);
    }
    let keep = if n == 0 { rows } else { keep.min(rows) };
    let y = &mut out[..keep * w.dout];
    linear(&x[..keep * d], &w.decoder.w, w.decoder.b, y);
    probe(Stage::Decoder, y);
}

/// Adapts a [`Probe`] callback to one net's [`Stage`]s.
pub fn stages<'p>(
    probe: &'p mut dyn FnMut(Probe, &[f32]),
    net: crate::transflower::probe::Net,
) -> impl FnMut(Stage, &[f32]) + 'p {
    move |stage, v| probe(Probe::Net { net, stage }, v)
}

/// The transformer over only the rows `input` (m, din) of a sequence whose
/// other rows' keys and values are kept in `kv` (one [`LayerKv`] per layer,
/// a row per slot; [`forward_recorded`] fills them): row r is at slot
/// `slots[r]` and window position `pos[slots[r]]` (`pe` is added at that
/// position, `pos_emb` biases the scores by positions). `out` (keep, dout)
/// = the decoder of the first `keep` rows. The stale-rows S mode
/// (`transflower::session`): rows not passed keep the keys and values of
/// the inputs they had when last computed. `m` <= the scratch's rows.
#[allow(clippy::too_many_arguments)]
pub fn forward_rows<const N: usize>(
    w: &TransformerW<'_, N>,
    input: &[f32],
    slots: &[u32],
    pos: &[u32],
    keep: usize,
    kv: &mut [LayerKv<'_>],
    s: &mut TransformerScratch<'_>,
    out: &mut [f32],
) {
    let m = slots.len();
    let TransformerScratch { x, layer } = s;
    kept_rows(
        w,
        input,
        slots,
        pos,
        keep,
        kv,
        &mut x[..m * w.d],
        layer,
        out,
    );
}

/// The transformer over every row of `input` (L, din) in a scratch of
/// fewer rows, keeping every layer's keys and values in `kv` (row j in
/// slot j, at window position `pos[j]`; [`forward_recorded`]'s numbers up
/// to the attention's summation order, and to `kv`'s storage: f16 keys and
/// values are read back rounded). `x` (L, d): the hidden rows; `ids`
/// (>= L): 0, 1, 2, ...; `out` (keep, dout) = the decoder of the first
/// `keep` rows. The first step of a rolling stale-rows session
/// (`transflower::session`): its arena holds a chunk's scratch, not a
/// whole step's.
#[allow(clippy::too_many_arguments)]
pub fn forward_chunked<const N: usize>(
    w: &TransformerW<'_, N>,
    input: &[f32],
    ids: &[u32],
    pos: &[u32],
    keep: usize,
    kv: &mut [LayerKv<'_>],
    x: &mut [f32],
    s: &mut TransformerScratch<'_>,
    out: &mut [f32],
) {
    let rows = (input.len() / w.din.max(1)).min(ids.len());
    kept_rows(w, input, &ids[..rows], pos, keep, kv, x, &mut s.layer, out);
}

/// [`forward_rows`] and [`forward_chunked`]: the rows `input` (m, din) at
/// `slots` through every layer against the kept keys and values, `x`
/// (m, d) their hidden rows, in chunks of the scratch's rows. Per layer,
/// the rows a single [`encoder_layer_rows`] call computes store their own
/// keys and values before attending; any other row's (rows past `keep` in
/// the last layer, every row when the layer takes several chunks) are
/// stored first ([`store_rows_kv`]), so every query sees this layer's keys
/// and values of all `m` rows. A row's output needs only its own input
/// and the stored keys and values: chunks change no number.
#[allow(clippy::too_many_arguments)]
fn kept_rows<const N: usize>(
    w: &TransformerW<'_, N>,
    input: &[f32],
    slots: &[u32],
    pos: &[u32],
    keep: usize,
    kv: &mut [LayerKv<'_>],
    x: &mut [f32],
    s: &mut EncoderLayerScratch<'_>,
    out: &mut [f32],
) {
    let d = w.d;
    let m = slots.len();
    let chunk = s.rows().max(1);
    let x = &mut x[..m * d];
    linear(&input[..m * w.din], &w.encoder1.w, w.encoder1.b, x);
    if let Some(pe) = w.pe {
        for (row, &slot) in x.chunks_exact_mut(d.max(1)).zip(slots) {
            let p = pos[slot as usize] as usize;
            for (v, e) in row.iter_mut().zip(&pe[p * d..(p + 1) * d]) {
                *v += e;
            }
        }
    }
    let bias = w.bias.map(|bias| SlotBias { bias, pos });
    let n = w.layers.len();
    for (i, (layer, lkv)) in w.layers.iter().zip(kv.iter_mut()).enumerate() {
        // Rows computed through this layer (the last: only those decoded).
        let k = if i + 1 == n { keep.min(m) } else { m };
        let stored_first = if k <= chunk { k } else { 0 };
        for a in (stored_first..m).step_by(chunk) {
            let b = (a + chunk).min(m);
            store_rows_kv(layer, &x[a * d..b * d], d, lkv, &slots[a..b], s);
        }
        for a in (0..k).step_by(chunk) {
            let b = (a + chunk).min(k);
            encoder_layer_rows(
                layer,
                &mut x[a * d..b * d],
                d,
                w.n_head,
                lkv,
                &slots[a..b],
                bias,
                s,
            );
        }
    }
    let keep = if n == 0 { m } else { keep.min(m) };
    linear(
        &x[..keep * d],
        &w.decoder.w,
        w.decoder.b,
        &mut out[..keep * w.dout],
    );
}
