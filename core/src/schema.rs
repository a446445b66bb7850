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
//! safetensors; [`crate::model`] binds weights with the same name builders
//! (`name`, [`TensorName`]) and its tests check it consumes this list.

use core::fmt::Write;

use crate::config::{LatConfig, ModelConfig, Part, VqConfig};

/// Capacity of a tensor name in bytes (the longest full-model name is ~85).
pub const TENSOR_NAME_CAP: usize = 128;

/// A tensor name, built without allocation.
pub type TensorName = heapless::String<TENSOR_NAME_CAP>;

/// One tensor the config requires.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TensorSpec {
    pub name: TensorName,
    pub rank: u8,
    /// PyTorch-order dims; entries past `rank` are 1.
    pub shape: [u32; 4],
    /// How the engine reads the tensor (decides which storage types suit it).
    pub role: Role,
}

/// How the engine reads a tensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Role {
    /// Biases and LayerNorm parameters (f32 only).
    Vector,
    /// `Linear.weight (out, in)` and the GPT heads: rows dotted with activations.
    Linear,
    /// `Conv1d.weight (out, in, k)` of a VQ decoder: each output channel's
    /// `in * k` values dotted with an im2col row.
    Conv,
    /// `Conv1d.weight` of a VQ encoder: read like [`Role::Conv`], kept apart
    /// because the leader's tokens (the nearest codebook row to the
    /// encoder's output) depend on it, so converters keep it more precise.
    EncoderConv,
    /// `ConvTranspose1d.weight (in, out, k)`: rows scaled and added (`x W`),
    /// or stored in GEMM order (`TensorSpec::gemm_dims`) and dotted with
    /// the input rows.
    ConvTranspose,
    /// Token embeddings: rows read whole.
    Embedding,
    /// VQ codebooks: rows read whole and compared by distance.
    Codebook,
    /// `pos_emb` (f32 only).
    PosEmb,
}

impl TensorSpec {
    pub fn dims(&self) -> &[u32] {
        &self.shape[..self.rank as usize]
    }
    /// The GEMM-order shape a file may store a `ConvTranspose1d` weight
    /// `(in, out, k)` in instead: `(out * k, in)`, row `o * k + j` holding
    /// `W[:, o, j]` (docs/FORMAT.md §6). None for every other role, or if
    /// `out * k` overflows.
    pub fn gemm_dims(&self) -> Option<[u32; 2]> {
        match (self.role, self.dims()) {
            (Role::ConvTranspose, &[c_in, c_out, k]) => Some([c_out.checked_mul(k)?, c_in]),
            _ => None,
        }
    }
    /// Whether a stored tensor of shape `dims` is this tensor: the schema's
    /// shape, or [`Self::gemm_dims`].
    pub fn accepts(&self, dims: &[u32]) -> bool {
        dims == self.dims() || self.gemm_dims().is_some_and(|g| dims == g)
    }
}

/// Why a name could not be built (only if a name outgrew
/// [`TENSOR_NAME_CAP`], impossible for a validated config).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SchemaError {
    NameTooLong,
}

/// Builds a name from format arguments: `name(format_args!("{p}.weight"))`.
pub fn name(args: core::fmt::Arguments<'_>) -> Result<TensorName, SchemaError> {
    let mut s = TensorName::new();
    s.write_fmt(args).map_err(|_| SchemaError::NameTooLong)?;
    Ok(s)
}

/// Prefix of a LAT in the GPT: `gpt.music_trans` or `gpt.leader_<part>_trans`.
pub fn lat_prefix(which: Option<Part>) -> Result<TensorName, SchemaError> {
    match which {
        None => name(format_args!("gpt.music_trans")),
        Some(p) => name(format_args!("gpt.leader_{}_trans", p.name())),
    }
}

/// Token embedding table of a stream (0..4 = up, down, lhand, rhand, 4 = transl).
pub fn tok_emb_name(stream: usize) -> Result<TensorName, SchemaError> {
    name(format_args!("gpt.tok_emb_{}.weight", STREAM_NAMES[stream.min(4)]))
}

/// Output head of a follower stream (0..4 = up, down, lhand, rhand, transl).
pub fn head_name(stream: usize) -> Result<TensorName, SchemaError> {
    name(format_args!("gpt.gpt_head.head_{}.weight", STREAM_NAMES[stream.min(4)]))
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

/// Which decoder of a VQ-VAE: positions (`decoders`) or rotations (`decoders_rot`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecoderKind {
    Position,
    Rotation,
}

impl DecoderKind {
    pub const fn module(self) -> &'static str {
        match self {
            DecoderKind::Position => "decoders",
            DecoderKind::Rotation => "decoders_rot",
        }
    }
}

/// Module prefix of strided encoder stage `i`: `<vq>.encoders.0.level_blocks.0.model.<i>`
/// (its conv is `.0`, its Resnet1D `.1`); stage `down_t` is the final conv.
pub fn encoder_stage(vq: &str, i: u32) -> Result<TensorName, SchemaError> {
    name(format_args!("{vq}.encoders.0.level_blocks.0.model.{i}"))
}

/// Module prefix of decoder stage `i` (0 = input conv, 1..=down_t = Resnet1D `.0` + ConvTranspose `.1`).
pub fn decoder_stage(vq: &str, kind: DecoderKind, i: u32) -> Result<TensorName, SchemaError> {
    name(format_args!("{vq}.{}.0.level_blocks.0.model.{i}", kind.module()))
}

/// Output conv of a decoder: `<vq>.<decoders|decoders_rot>.0.out`.
pub fn decoder_out(vq: &str, kind: DecoderKind) -> Result<TensorName, SchemaError> {
    name(format_args!("{vq}.{}.0.out", kind.module()))
}

/// Codebook of a VQ-VAE: `<vq>.bottleneck.level_blocks.0.k` (l_bins, emb_width).
pub fn codebook_name(vq: &str) -> Result<TensorName, SchemaError> {
    name(format_args!("{vq}.bottleneck.level_blocks.0.k"))
}

/// Output channels of a decoder kind for a VQ config.
pub fn decoder_channels(vq: &VqConfig, kind: DecoderKind) -> u32 {
    match kind {
        DecoderKind::Position => vq.in_channels,
        DecoderKind::Rotation => vq.rot_channels,
    }
}

/// Dilation of residual block `d` of a Resnet1D (`growth^d`; decoders
/// use the reversed order, `vqvae_reverse_decoder_dilation: True`).
pub fn dilation(vq: &VqConfig, d: u32, reversed: bool) -> u32 {
    let e = if reversed { vq.depth - 1 - d.min(vq.depth - 1) } else { d };
    vq.dilation_growth_rate.saturating_pow(e)
}

struct Emit<'f, E> {
    f: &'f mut dyn FnMut(&TensorSpec) -> Result<(), E>,
}

impl<E: From<SchemaError>> Emit<'_, E> {
    fn t(&mut self, name: TensorName, dims: &[u32], role: Role) -> Result<(), E> {
        let mut shape = [1u32; 4];
        shape[..dims.len()].copy_from_slice(dims);
        (self.f)(&TensorSpec { name, rank: dims.len() as u8, shape, role })
    }
    /// `<prefix>.weight` (`w`, read as `role`) and `<prefix>.bias` (`bias`).
    fn wb(&mut self, prefix: &str, w: &[u32], bias: u32, role: Role) -> Result<(), E> {
        self.t(name(format_args!("{prefix}.weight"))?, w, role)?;
        self.t(name(format_args!("{prefix}.bias"))?, &[bias], Role::Vector)
    }
    /// A pre-LN transformer block (`MusicBlock` or `Block`) of width `c`.
    fn block(&mut self, prefix: &str, c: u32) -> Result<(), E> {
        self.wb(&name(format_args!("{prefix}.ln1"))?, &[c], c, Role::Vector)?;
        self.wb(&name(format_args!("{prefix}.ln2"))?, &[c], c, Role::Vector)?;
        for p in ["key", "query", "value", "proj"] {
            self.wb(&name(format_args!("{prefix}.attn.{p}"))?, &[c, c], c, Role::Linear)?;
        }
        self.wb(&name(format_args!("{prefix}.mlp.0"))?, &[4 * c, c], 4 * c, Role::Linear)?;
        self.wb(&name(format_args!("{prefix}.mlp.2"))?, &[c, 4 * c], c, Role::Linear)
    }
    fn lat(&mut self, prefix: &str, lat: &LatConfig, c: u32) -> Result<(), E> {
        self.wb(&name(format_args!("{prefix}.cond_emb"))?, &[c, lat.n_in], c, Role::Linear)?;
        for i in 0..lat.n_layer {
            self.block(&name(format_args!("{prefix}.blocks.{i}"))?, c)?;
        }
        self.wb(&name(format_args!("{prefix}.downsample"))?, &[c, c * lat.downsample_rate], c, Role::Linear)
    }
    /// A Resnet1D whose convs are read as `conv` (encoder or decoder).
    fn resnet(&mut self, stage: &str, vq: &VqConfig, conv: Role) -> Result<(), E> {
        let (w, inner) = (vq.width, vq.res_inner().unwrap_or(0));
        for d in 0..vq.depth {
            let blk = name(format_args!("{stage}.model.{d}.model"))?;
            self.wb(&name(format_args!("{blk}.1"))?, &[inner, w, 3], inner, conv)?;
            self.wb(&name(format_args!("{blk}.3"))?, &[w, inner, 1], w, conv)?;
        }
        Ok(())
    }
    fn vq(&mut self, vq_name: &str, vq: &VqConfig) -> Result<(), E> {
        let (w, k) = (vq.width, 2 * vq.stride_t);
        for i in 0..vq.down_t {
            let stage = encoder_stage(vq_name, i)?;
            let c_in = if i == 0 { vq.in_channels } else { w };
            self.wb(&name(format_args!("{stage}.0"))?, &[w, c_in, k], w, Role::EncoderConv)?;
            self.resnet(&name(format_args!("{stage}.1"))?, vq, Role::EncoderConv)?;
        }
        self.wb(&encoder_stage(vq_name, vq.down_t)?, &[vq.emb_width, w, 3], vq.emb_width, Role::EncoderConv)?;
        self.t(codebook_name(vq_name)?, &[vq.l_bins, vq.emb_width], Role::Codebook)?;
        for kind in [DecoderKind::Position, DecoderKind::Rotation] {
            let c_out = decoder_channels(vq, kind);
            if c_out == 0 {
                continue;
            }
            self.wb(&decoder_stage(vq_name, kind, 0)?, &[w, vq.emb_width, 3], w, Role::Conv)?;
            for i in 0..vq.down_t {
                let stage = decoder_stage(vq_name, kind, i + 1)?;
                self.resnet(&name(format_args!("{stage}.0"))?, vq, Role::Conv)?;
                let out = if i + 1 == vq.down_t { vq.emb_width } else { w };
                self.wb(&name(format_args!("{stage}.1"))?, &[w, out, k], out, Role::ConvTranspose)?;
            }
            self.wb(&decoder_out(vq_name, kind)?, &[c_out, vq.emb_width, 3], c_out, Role::Conv)?;
        }
        Ok(())
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
    e.lat(&lat_prefix(None)?, &g.music, c)?;
    for p in Part::ALL {
        e.lat(&lat_prefix(Some(p))?, &g.leader, c)?;
    }
    for s in 0..5 {
        e.t(tok_emb_name(s)?, &[g.vocab[s], c], Role::Embedding)?;
    }
    e.t(name(format_args!("gpt.gpt_base.pos_emb"))?, &[1, g.block_size.saturating_mul(g.n_streams), c], Role::PosEmb)?;
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
