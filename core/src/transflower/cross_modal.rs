//! The cross-modal transformer (`net_output_<out>`, `nlayers` post-LN
//! layers, every latent row attending to every row, [+ `pe`]): its first
//! `cond_len` output rows (the oldest motion positions in the paper
//! config) condition the flow. Only those rows are computed through the
//! last layer (all rows are its keys and values).

use crate::transflower::model::Model;
use crate::transflower::probe::{Net, Probe};
use crate::transflower::transformer::{forward_recorded, stages, TransformerScratch};

/// `cond` (cond_len, dhid) from `latent` (sum L_i, dhid).
pub fn condition(
    model: &Model<'_>,
    latent: &[f32],
    s: &mut TransformerScratch<'_>,
    cond: &mut [f32],
    probe: &mut dyn FnMut(Probe, &[f32]),
) {
    condition_recorded(model, latent, s, cond, probe, &mut |_, _| {});
}

/// [`condition`] that also hands layer `l`'s q | k | v rows (sum L, 3 dhid)
/// to `layer_qkv(l, qkv)`.
pub fn condition_recorded(
    model: &Model<'_>,
    latent: &[f32],
    s: &mut TransformerScratch<'_>,
    cond: &mut [f32],
    probe: &mut dyn FnMut(Probe, &[f32]),
    layer_qkv: &mut dyn FnMut(usize, &[f32]),
) {
    let keep = model.cfg.cond_len as usize;
    forward_recorded(
        &model.cross_modal,
        latent,
        keep,
        s,
        cond,
        &mut stages(probe, Net::CrossModal),
        layer_qkv,
    );
    probe(Probe::Cond, &cond[..keep * model.cfg.dhid as usize]);
}
