//! Which weight tensors a [`TransflowerConfig`] needs, their names and
//! shapes: exactly the authors' `TransflowerModel.state_dict()` names (a
//! Lightning checkpoint's `state_dict`), without the buffers inference
//! never reads (`is_initialized` of the norm layers, the flow's `bounds`).
//!
//! ```text
//! net_input_<mod>.            BasicTransformerModel per input (2 layers)
//!   [encoder.weight]            (tokens, dim)       discrete inputs
//!   encoder1.{weight,bias}      (D, dim)
//!   [pos_emb]                   (L, L)              rel_pos_emb_inputs, L > 1
//!   transformer_encoder.layers.<i>.  (nn::encoder_layer, width D, FFN D)
//!   decoder.{weight,bias}       (D, D)
//! net_output_<out>.           the cross-modal transformer (nlayers)
//!   encoder1 (D, D), [pos_encoder.pe (sum L, 1, D)], layers, decoder (D, D)
//! net_output_glow_<out>.flows.channels.<k>.   flow step j: k = 3j, 3j+1, 3j+2
//!   norm:      gamma, beta, running_mean, running_var | mean, inv_std  (1, C, 1, 1)
//!   1x1 conv:  l, u, p (C, C), log_s, sign_s (C)
//!   coupling:  [input_encoder (D, C - cc)], nn.rescale.weight_{g,v} (cc, 1, 1),
//!              nn.transformer.{encoder1 (Df, in), [pos_encoder.pe (rows, 1, Df)],
//!              layers (width Df, FFN Df), decoder (2 cc, Df)}
//! ```

use crate::nn::encoder_layer::emit_encoder_layer;
use crate::nn::names::{name, Emit, Role, SchemaError, TensorName, TensorSpec};
use crate::transflower::config::{NormLayer, TransflowerConfig, INPUT_LAYERS};

/// `net_input_<mod>` of input `i`.
pub fn input_prefix(cfg: &TransflowerConfig, i: usize) -> Result<TensorName, SchemaError> {
    name(format_args!(
        "net_input_{}",
        cfg.inputs[i.min(cfg.inputs.len() - 1)].name.as_str()
    ))
}

/// `net_output_<out>`: the cross-modal transformer.
pub fn cross_modal_prefix(cfg: &TransflowerConfig) -> Result<TensorName, SchemaError> {
    name(format_args!(
        "net_output_{}",
        cfg.output_input().name.as_str()
    ))
}

/// `net_output_glow_<out>.flows.channels.<k>`: flow module `k`.
pub fn flow_module(cfg: &TransflowerConfig, k: u32) -> Result<TensorName, SchemaError> {
    name(format_args!(
        "net_output_glow_{}.flows.channels.{k}",
        cfg.output_input().name.as_str()
    ))
}

/// Module indices of flow step `j`: (norm if any, 1x1 conv, coupling).
pub fn step_modules(cfg: &TransflowerConfig, j: u32) -> (Option<u32>, u32, u32) {
    let per = cfg.modules_per_step();
    let base = per * j;
    if per == 3 {
        (Some(base), base + 1, base + 2)
    } else {
        (None, base, base + 1)
    }
}

/// Lists a `BasicTransformerModel` under `p` (input width `din`, output
/// `dout`, width `d`, `layers` layers, `pe` rows if any, `bias` rows of a
/// `pos_emb` if any).
#[allow(clippy::too_many_arguments)]
fn transformer<E: From<SchemaError>>(
    e: &mut Emit<'_, E>,
    p: &str,
    din: u32,
    d: u32,
    dout: u32,
    layers: u32,
    pe: Option<u32>,
    bias: Option<u32>,
) -> Result<(), E> {
    e.wb(
        &name(format_args!("{p}.encoder1"))?,
        &[d, din],
        d,
        Role::Linear,
    )?;
    if let Some(rows) = pe {
        e.t(
            name(format_args!("{p}.pos_encoder.pe"))?,
            &[rows, 1, d],
            Role::PosEmb,
        )?;
    }
    if let Some(l) = bias {
        e.t(name(format_args!("{p}.pos_emb"))?, &[l, l], Role::PosEmb)?;
    }
    for i in 0..layers {
        emit_encoder_layer(
            e,
            &name(format_args!("{p}.transformer_encoder.layers.{i}"))?,
            d,
            d,
        )?;
    }
    e.wb(
        &name(format_args!("{p}.decoder"))?,
        &[dout, d],
        dout,
        Role::Linear,
    )
}

/// Calls `f` once per tensor the config needs: the input transformers in
/// order, the cross-modal transformer, the flow modules in index order.
pub fn for_each_tensor<E: From<SchemaError>>(
    cfg: &TransflowerConfig,
    f: &mut dyn FnMut(&TensorSpec) -> Result<(), E>,
) -> Result<(), E> {
    let mut e = Emit { f };
    let d = cfg.dhid;
    for (i, inp) in cfg.inputs().iter().enumerate() {
        let p = input_prefix(cfg, i)?;
        if inp.is_discrete() {
            e.t(
                name(format_args!("{p}.encoder.weight"))?,
                &[inp.tokens, inp.dim],
                Role::Embedding,
            )?;
        }
        let bias = cfg.input_has_bias(i).then_some(inp.length);
        transformer(&mut e, &p, inp.dim, d, d, INPUT_LAYERS, None, bias)?;
    }
    let pe = cfg.pos_emb_output.then_some(cfg.latent_rows() as u32);
    transformer(
        &mut e,
        &cross_modal_prefix(cfg)?,
        d,
        d,
        d,
        cfg.nlayers,
        pe,
        None,
    )?;
    let c = cfg.channels() as u32;
    let cc = cfg.change_channels() as u32;
    let ci = c - cc;
    let f = &cfg.flow;
    for j in 0..f.steps {
        let (norm, conv, coupling) = step_modules(cfg, j);
        if let Some(k) = norm {
            let m = flow_module(cfg, k)?;
            let names: &[&str] = match f.norm {
                NormLayer::BatchNorm => &["gamma", "beta", "running_mean", "running_var"],
                NormLayer::ActNorm => &["mean", "inv_std"],
                NormLayer::None => &[],
            };
            for n in names {
                e.t(name(format_args!("{m}.{n}"))?, &[1, c, 1, 1], Role::Vector)?;
            }
        }
        let m = flow_module(cfg, conv)?;
        for n in ["l", "u", "p"] {
            e.t(name(format_args!("{m}.{n}"))?, &[c, c], Role::Vector)?;
        }
        for n in ["log_s", "sign_s"] {
            e.t(name(format_args!("{m}.{n}"))?, &[c], Role::Vector)?;
        }
        let m = flow_module(cfg, coupling)?;
        if !f.concat_dims {
            e.wb(
                &name(format_args!("{m}.input_encoder"))?,
                &[d, ci],
                d,
                Role::Linear,
            )?;
        }
        for n in ["weight_g", "weight_v"] {
            e.t(
                name(format_args!("{m}.nn.rescale.{n}"))?,
                &[cc, 1, 1],
                Role::Vector,
            )?;
        }
        let pe = f.pos_emb.then_some(cfg.coupling_rows() as u32);
        transformer(
            &mut e,
            &name(format_args!("{m}.nn.transformer"))?,
            cfg.coupling_in() as u32,
            f.dhid,
            2 * cc,
            f.layers,
            pe,
            None,
        )?;
    }
    Ok(())
}

/// Number of tensors the config needs.
pub fn tensor_count(cfg: &TransflowerConfig) -> usize {
    let mut n = 0usize;
    let _ = for_each_tensor::<SchemaError>(cfg, &mut |_| {
        n += 1;
        Ok(())
    });
    n
}
