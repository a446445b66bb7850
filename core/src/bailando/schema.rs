//! Which weight tensors a [`BailandoConfig`] needs, their names and
//! shapes. Names are the authors' `state_dict` names (no DataParallel
//! `module.` prefix) behind a component prefix: `gpt.` (`CrossCondGPT2AC`
//! without its training-only `critic_net`) and `motion.` (`SepVQVAER`).
//! Not listed: the `attn.mask` buffers (recomputed), `critic_net.*`.

use crate::bailando::config::{BailandoConfig, N_STREAMS};
use crate::nn::names::{name, DecoderKind, Emit, Role, SchemaError, TensorName, TensorSpec};

/// Stream names of the two token streams.
pub const PART_NAMES: [&str; 2] = ["up", "down"];

/// Prefix of a part's VQ-VAE: `motion.vqvae_up` / `motion.vqvae_down`.
pub fn vq_prefix(part: usize) -> Result<TensorName, SchemaError> {
    name(format_args!("motion.vqvae_{}", PART_NAMES[part.min(1)]))
}

/// Token embedding of a stream: `gpt.gpt_base.tok_emb_<up|down>.weight`.
pub fn tok_emb_name(part: usize) -> Result<TensorName, SchemaError> {
    name(format_args!(
        "gpt.gpt_base.tok_emb_{}.weight",
        PART_NAMES[part.min(1)]
    ))
}

/// Output head of a stream: `gpt.gpt_head.head_<up|down>.weight`.
pub fn head_name(part: usize) -> Result<TensorName, SchemaError> {
    name(format_args!(
        "gpt.gpt_head.head_{}.weight",
        PART_NAMES[part.min(1)]
    ))
}

/// Calls `f` once per tensor the config needs, in a fixed order (GPT
/// base, GPT head, up VQ-VAE, down VQ-VAE with its root decoder).
pub fn for_each_tensor<E: From<SchemaError>>(
    cfg: &BailandoConfig,
    f: &mut dyn FnMut(&TensorSpec) -> Result<(), E>,
) -> Result<(), E> {
    let mut e = Emit { f };
    let g = &cfg.gpt;
    let c = g.n_embd;
    for p in 0..2 {
        e.t(tok_emb_name(p)?, &[g.vocab[p], c], Role::Embedding)?;
    }
    e.t(
        name(format_args!("gpt.gpt_base.pos_emb"))?,
        &[1, g.block_size.saturating_mul(N_STREAMS as u32), c],
        Role::PosEmb,
    )?;
    e.wb("gpt.gpt_base.cond_emb", &[c, g.n_music], c, Role::Linear)?;
    for i in 0..g.n_layer_base {
        e.block(&name(format_args!("gpt.gpt_base.blocks.{i}"))?, c)?;
    }
    for i in 0..g.n_layer_head {
        e.block(&name(format_args!("gpt.gpt_head.blocks.{i}"))?, c)?;
    }
    e.wb("gpt.gpt_head.ln_f", &[c], c, Role::Vector)?;
    for p in 0..2 {
        e.t(head_name(p)?, &[g.vocab[p], c], Role::Linear)?;
    }
    for p in 0..2 {
        e.vq(&vq_prefix(p)?, &cfg.parts[p])?;
    }
    e.decoder(&vq_prefix(1)?, &cfg.parts[1], DecoderKind::Root)
}

/// Number of tensors the config needs.
pub fn tensor_count(cfg: &BailandoConfig) -> usize {
    let mut n = 0usize;
    let _ = for_each_tensor::<SchemaError>(cfg, &mut |_| {
        n += 1;
        Ok(())
    });
    n
}
