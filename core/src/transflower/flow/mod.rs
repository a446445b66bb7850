//! The flow (`FlowPlusPlus` with one scale `[[S, 0]]`), sampled in
//! reverse: from a base sample z (C, H) through the S steps from the
//! last to the first, each step's modules in reverse order
//! (coupling, 1x1 conv, norm). The conditioning rows enter every coupling.
//!
//! - [`norm`]: BatchNorm / ActNorm
//! - [`inv_conv`]: the invertible 1x1 convolution in LU form
//! - [`coupling`]: the affine coupling with a transformer net
//!
//! Layout inside: x (C, H) channel-major, as the authors' (1, C, H, 1).

pub mod coupling;
pub mod inv_conv;
pub mod norm;

use crate::arena::{ArenaError, Carve};
use crate::transflower::config::TransflowerConfig;
use crate::transflower::model::Model;
use crate::transflower::probe::Probe;
use crate::transflower::schema::step_modules;
use crate::transflower::transformer::TransformerScratch;
use coupling::CouplingScratch;

/// Working memory of [`reverse`] (besides the shared transformer scratch).
pub struct FlowScratch<'s> {
    pub coupling: CouplingScratch<'s>,
    /// (C, H): the 1x1 conv's output before it is copied back.
    tmp: &'s mut [f32],
}

impl<'s> FlowScratch<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, cfg: &TransflowerConfig) -> Result<Self, ArenaError> {
        Ok(FlowScratch {
            coupling: CouplingScratch::carve(a, cfg)?,
            tmp: a.f32(cfg.channels() * cfg.output_length as usize)?,
        })
    }
}

/// `x` (C, H): the base sample in, the flow's sample out. `inv_w`
/// (S, C, C): every step's reverse 1x1 weight ([`inv_conv::inverse_weight`]).
/// `cond` (cond_len, D).
pub fn reverse(
    model: &Model<'_>,
    inv_w: &[f32],
    x: &mut [f32],
    cond: &[f32],
    net: &mut TransformerScratch<'_>,
    s: &mut FlowScratch<'_>,
    probe: &mut dyn FnMut(Probe, &[f32]),
) {
    let cfg = &model.cfg;
    let h = cfg.output_length as usize;
    let c = cfg.channels();
    for (j, step) in model.flow.iter().enumerate().rev() {
        let (norm_k, conv_k, coupling_k) = step_modules(cfg, j as u32);
        coupling::reverse(
            cfg,
            &step.coupling,
            coupling_k,
            x,
            cond,
            net,
            &mut s.coupling,
            probe,
        );
        probe(Probe::FlowModule(coupling_k), x);
        inv_conv::apply(&inv_w[j * c * c..(j + 1) * c * c], x, h, s.tmp);
        probe(Probe::FlowModule(conv_k), x);
        if let Some(k) = norm_k {
            norm::reverse(&step.norm, x, h);
            probe(Probe::FlowModule(k), x);
        }
    }
}
