//! The affine coupling, reversed (models/flowplusplus/coupling.py
//! `Coupling`, transformer_nn.py `TransformerNN`):
//!
//! ```text
//! x_change = x[0 .. cc]   (the FIRST ceil(C/2) channels)    x_id = x[cc .. C]
//! seq = concat_cols(x_id^T, cond)              (H, C - cc + D)       cond_concat_dims
//!     | concat_rows(input_encoder(x_id^T), cond) (H + cond_len, D)   otherwise
//! y = transformer(seq)[0 .. H]                 (H, 2 cc): s = y[:, :cc]^T, t = y[:, cc:]^T
//! a = rescale(tanh(s)) = (v * (g / |v|)) * tanh(s)      (weight norm of a (cc,1,1) weight)
//! scale = sigmoid(a + 2) + (1 - sigmoid(2))
//! x_change = x_change / scale - t
//! ```

use crate::arena::{ArenaError, Carve};
use crate::kernels::linear;
use crate::transflower::config::TransflowerConfig;
use crate::transflower::model::CouplingW;
use crate::transflower::probe::{Net, Probe};
use crate::transflower::transformer::{forward, stages, TransformerScratch};

/// The coupling's offset (`self.offset`).
pub const OFFSET: f32 = 2.0;

/// Working memory of [`reverse`].
pub struct CouplingScratch<'s> {
    /// (H, C - cc): x_id transposed (the `input_encoder`'s input).
    xt: &'s mut [f32],
    /// (coupling rows, coupling input width): the transformer's sequence.
    seq: &'s mut [f32],
    /// (H, 2 cc): the transformer's kept rows.
    y: &'s mut [f32],
    /// (cc, H) each: the rescaled `s` and `t`.
    a: &'s mut [f32],
    t: &'s mut [f32],
}

impl<'s> CouplingScratch<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, cfg: &TransflowerConfig) -> Result<Self, ArenaError> {
        let h = cfg.output_length as usize;
        let c = cfg.channels();
        let cc = cfg.change_channels();
        let seq = cfg
            .coupling_rows()
            .checked_mul(cfg.coupling_in())
            .ok_or(ArenaError::Overflow)?;
        Ok(CouplingScratch {
            xt: a.f32(h * (c - cc))?,
            seq: a.f32(seq)?,
            y: a.f32(h * 2 * cc)?,
            a: a.f32(cc * h)?,
            t: a.f32(cc * h)?,
        })
    }
}

/// `1 - sigmoid(2)` as the authors' Python float, rounded to f32 by torch.
fn sigmoid_offset() -> f32 {
    (1.0 - 1.0 / (1.0 + libm::exp(-(OFFSET as f64)))) as f32
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + libm::expf(-x))
}

/// Reverses coupling module `k` on `x` (C, H) in place given `cond`
/// (cond_len, D).
#[allow(clippy::too_many_arguments)]
pub fn reverse(
    cfg: &TransflowerConfig,
    w: &CouplingW<'_>,
    k: u32,
    x: &mut [f32],
    cond: &[f32],
    net: &mut TransformerScratch<'_>,
    s: &mut CouplingScratch<'_>,
    probe: &mut dyn FnMut(Probe, &[f32]),
) {
    let h = cfg.output_length as usize;
    let c = cfg.channels();
    let cc = cfg.change_channels();
    let ci = c - cc;
    let d = cfg.dhid as usize;
    let (xc, xid) = x.split_at_mut(cc * h);
    let rows = cfg.coupling_rows();
    let width = cfg.coupling_in();
    let seq = &mut s.seq[..rows * width];
    match &w.input_encoder {
        None => {
            // Row h: [x_id[:, h] (ci), cond[h] (D)].
            for t in 0..h {
                let r = &mut seq[t * width..(t + 1) * width];
                for i in 0..ci {
                    r[i] = xid[i * h + t];
                }
                r[ci..].copy_from_slice(&cond[t * d..(t + 1) * d]);
            }
        }
        Some(enc) => {
            // Rows 0..H: input_encoder(x_id^T) (H, D); rows H..: cond.
            let xt = &mut s.xt[..h * ci];
            for t in 0..h {
                for i in 0..ci {
                    xt[t * ci + i] = xid[i * h + t];
                }
            }
            let (top, bottom) = seq.split_at_mut(h * d);
            linear(xt, &enc.w, enc.b, top);
            probe(Probe::InputEncoder(k), top);
            bottom.copy_from_slice(&cond[..bottom.len()]);
        }
    }
    let y = &mut s.y[..h * 2 * cc];
    forward(&w.net, seq, h, net, y, &mut stages(probe, Net::Coupling(k)));
    let (a, tt) = (&mut s.a[..cc * h], &mut s.t[..cc * h]);
    for ch in 0..cc {
        // weight_norm: weight = v * (g / ||v||), the norm over one element.
        let wn = w.weight_v[ch] * (w.weight_g[ch] / w.weight_v[ch].abs());
        for t in 0..h {
            a[ch * h + t] = wn * libm::tanhf(y[t * 2 * cc + ch]);
            tt[ch * h + t] = y[t * 2 * cc + cc + ch];
        }
    }
    probe(Probe::CouplingS(k), a);
    probe(Probe::CouplingT(k), tt);
    let off = sigmoid_offset();
    for ((v, &av), &tv) in xc.iter_mut().zip(a.iter()).zip(tt.iter()) {
        let scale = sigmoid(av + OFFSET) + off;
        *v = *v / scale - tv;
    }
}
