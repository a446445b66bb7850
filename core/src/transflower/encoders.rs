//! The input encoders: one `BasicTransformerModel` per input modality
//! (`net_input_<mod>`, 2 layers), each over its own window; their outputs
//! are stacked in `input_modalities` order (motion rows first in the
//! published configs) into the latent sequence the cross-modal
//! transformer reads.

use crate::transflower::model::{Model, TransformerW};
use crate::transflower::probe::{Net, Probe, Stage};
use crate::transflower::transformer::{forward_recorded, stages, TransformerScratch};

/// One input's window at a step.
#[derive(Clone, Copy, Debug)]
pub enum Window<'x> {
    /// A continuous input's rows (L_i, d_i).
    Rows(&'x [f32]),
    /// A discrete input's label (`single`: one row for the whole sequence).
    Label(u32),
}

/// What input net `net` reads for window `win`: a continuous window's rows
/// (L_i, d_i), or a label's embedding row (1, dim) looked up into `emb`
/// (the net's `encoder`, an Embedding; a label for a continuous input is
/// refused by the caller: empty here).
pub fn input_rows<'x, const N: usize>(
    net: &TransformerW<'_, N>,
    win: Window<'x>,
    emb: &'x mut [f32],
) -> &'x [f32] {
    match (win, net.embedding.as_ref()) {
        (Window::Rows(rows), _) => rows,
        (Window::Label(label), Some(table)) => {
            let e = &mut emb[..net.din];
            table.row_into(label as usize, e);
            e
        }
        (Window::Label(_), None) => &[],
    }
}

/// `latent` (sum L_i, dhid) = every input transformer over its window,
/// stacked. `emb`: (max discrete dim) scratch for an embedding row.
/// Callers check the windows (lengths, labels in range).
pub fn encode_inputs(
    model: &Model<'_>,
    windows: &[Window<'_>],
    s: &mut TransformerScratch<'_>,
    emb: &mut [f32],
    latent: &mut [f32],
    probe: &mut dyn FnMut(Probe, &[f32]),
) {
    encode_inputs_recorded(model, windows, s, emb, latent, probe, &mut |_, _, _| {});
}

/// [`encode_inputs`] that also hands input `i`'s layer `l` q | k | v rows
/// (L_i, 3 dhid) to `layer_qkv(i, l, qkv)`.
#[allow(clippy::too_many_arguments)]
pub fn encode_inputs_recorded(
    model: &Model<'_>,
    windows: &[Window<'_>],
    s: &mut TransformerScratch<'_>,
    emb: &mut [f32],
    latent: &mut [f32],
    probe: &mut dyn FnMut(Probe, &[f32]),
    layer_qkv: &mut dyn FnMut(usize, usize, &[f32]),
) {
    let d = model.cfg.dhid as usize;
    let mut row = 0usize;
    for (i, (net, win)) in model.inputs.iter().zip(windows).enumerate() {
        let l = model.cfg.inputs[i].length as usize;
        let input = input_rows(net, *win, emb);
        if let Window::Label(_) = win {
            probe(
                Probe::Net {
                    net: Net::Input(i as u8),
                    stage: Stage::Encoder,
                },
                input,
            );
        }
        let out = &mut latent[row * d..(row + l) * d];
        forward_recorded(
            net,
            input,
            l,
            s,
            out,
            &mut stages(probe, Net::Input(i as u8)),
            &mut |layer, qkv| layer_qkv(i, layer, qkv),
        );
        row += l;
    }
}
