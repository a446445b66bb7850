//! The single source of truth for which weight tensors a [`ModelConfig`]
//! needs, their names and their shapes.
//!
//! Names are the ORIGINAL PyTorch `state_dict` names (no DataParallel
//! `module.` prefix) with a component prefix: `gpt.` (GPT2nt), `motion.`
//! (SepVQVAEXM), `transl.` (the translation VQVAE). Shapes are PyTorch
//! order: `Linear.weight (out, in)`, `Conv1d.weight (out, in, k)`,
//! `ConvTranspose1d.weight (in, out, k)`, `Embedding.weight (rows, dim)`.
//!
//! Only what the inference path reads is listed: no `attn.mask` buffers,
//! no LAT `pos_emb` (unused by the original forward), no
//! `gpt_base.cond_*emb*` (constructed but never called), no
//! `vqvae_down.decoders_root` (training-only root-velocity head).
//!
//! Users: the `.duo` decoder checks every stored shape against
//! [`for_each_tensor`]; the converter pulls exactly these names from the
//! safetensors; [`crate::duolando::model`] binds weights with the same name builders
//! (`name`, [`TensorName`]) and its tests check it consumes this list.

use crate::duolando::config::{LatConfig, ModelConfig, Part};
use crate::nn::names::{name, Emit, Role, SchemaError, TensorName, TensorSpec};

/// Prefix of a LAT in the GPT: `gpt.music_trans` or `gpt.leader_<part>_trans`.
pub fn lat_prefix(which: Option<Part>) -> Result<TensorName, SchemaError> {
    match which {
        None => name(format_args!("gpt.music_trans")),
        Some(p) => name(format_args!("gpt.leader_{}_trans", p.name())),
    }
}

/// Token embedding table of a stream (0..4 = up, down, lhand, rhand, 4 = transl).
pub fn tok_emb_name(stream: usize) -> Result<TensorName, SchemaError> {
    name(format_args!(
        "gpt.tok_emb_{}.weight",
        STREAM_NAMES[stream.min(4)]
    ))
}

/// Output head of a follower stream (0..4 = up, down, lhand, rhand, transl).
pub fn head_name(stream: usize) -> Result<TensorName, SchemaError> {
    name(format_args!(
        "gpt.gpt_head.head_{}.weight",
        STREAM_NAMES[stream.min(4)]
    ))
}

/// Stream names in token order.
pub const STREAM_NAMES: [&str; 5] = ["up", "down", "lhand", "rhand", "transl"];

/// Prefix of a VQ-VAE: `motion.vqvae_<part>` or `transl`.
pub fn vq_prefix(which: Option<Part>) -> Result<TensorName, SchemaError> {
    match which {
        Some(p) => name(format_args!("motion.vqvae_{}", p.name())),
        None => name(format_args!("transl")),
    }
}

/// Calls `f` once per tensor the config needs, in a fixed order (GPT,
/// then the four part VQ-VAEs, then the translation VQ-VAE). The config
/// should have passed [`ModelConfig::validate`] (sizes are not re-checked
/// here; unvalidated configs may produce absurd shapes, never a panic).
pub fn for_each_tensor<E: From<SchemaError>>(
    cfg: &ModelConfig,
    f: &mut dyn FnMut(&TensorSpec) -> Result<(), E>,
) -> Result<(), E> {
    let mut e = Emit { f };
    let g = &cfg.gpt;
    let c = g.n_embd;
    lat(&mut e, &lat_prefix(None)?, &g.music, c)?;
    for p in Part::ALL {
        lat(&mut e, &lat_prefix(Some(p))?, &g.leader, c)?;
    }
    for s in 0..5 {
        e.t(tok_emb_name(s)?, &[g.vocab[s], c], Role::Embedding)?;
    }
    e.t(
        name(format_args!("gpt.gpt_base.pos_emb"))?,
        &[1, g.block_size.saturating_mul(g.n_streams), c],
        Role::PosEmb,
    )?;
    for i in 0..g.n_layer_base {
        e.block(&name(format_args!("gpt.gpt_base.blocks.{i}"))?, c)?;
    }
    for i in 0..g.n_layer_head {
        e.block(&name(format_args!("gpt.gpt_head.blocks.{i}"))?, c)?;
    }
    // Quirk of the original: head_lhand has vocab_up rows, head_rhand vocab_down rows.
    let head_rows = [g.vocab[0], g.vocab[1], g.vocab[0], g.vocab[1], g.vocab[4]];
    for (s, rows) in head_rows.iter().enumerate() {
        e.t(head_name(s)?, &[*rows, c], Role::Linear)?;
    }
    for (i, p) in Part::ALL.iter().enumerate() {
        e.vq(&vq_prefix(Some(*p))?, &cfg.parts[i])?;
    }
    e.vq(&vq_prefix(None)?, &cfg.transl)
}

/// Number of tensors the config needs.
pub fn tensor_count(cfg: &ModelConfig) -> usize {
    let mut n = 0usize;
    let _ = for_each_tensor::<SchemaError>(cfg, &mut |_| {
        n += 1;
        Ok(())
    });
    n
}

fn lat<E: From<SchemaError>>(
    e: &mut Emit<'_, E>,
    prefix: &str,
    lat: &LatConfig,
    c: u32,
) -> Result<(), E> {
    e.wb(
        &name(format_args!("{prefix}.cond_emb"))?,
        &[c, lat.n_in],
        c,
        Role::Linear,
    )?;
    for i in 0..lat.n_layer {
        e.block(&name(format_args!("{prefix}.blocks.{i}"))?, c)?;
    }
    e.wb(
        &name(format_args!("{prefix}.downsample"))?,
        &[c, c * lat.downsample_rate],
        c,
        Role::Linear,
    )
}
