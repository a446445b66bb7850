//! Tensor names and specs of the shared building blocks: the name builder
//! ([`name`], [`TensorName`], no allocation), [`TensorSpec`] and its
//! [`Role`], the VQ-VAE module names of the authors' `encdec.py` lineage
//! (Duolando's VQ-VAE grew from Bailando's), and [`Emit`], which lists a
//! block's or a VQ-VAE's tensors. Each family's `schema` lists its whole
//! model with these.

use core::fmt::Write;

use crate::nn::vq_config::VqConfig;

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

/// Which decoder of a VQ-VAE: positions (`decoders`) or rotations (`decoders_rot`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecoderKind {
    Position,
    Rotation,
    /// `decoders_root`: Bailando's root-velocity decoder of the down part
    /// ([`ROOT_CHANNELS`] per frame).
    Root,
}

/// Output channels of a root-velocity decoder (xyz).
pub const ROOT_CHANNELS: u32 = 3;

impl DecoderKind {
    pub const fn module(self) -> &'static str {
        match self {
            DecoderKind::Position => "decoders",
            DecoderKind::Rotation => "decoders_rot",
            DecoderKind::Root => "decoders_root",
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
    name(format_args!(
        "{vq}.{}.0.level_blocks.0.model.{i}",
        kind.module()
    ))
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
        DecoderKind::Root => ROOT_CHANNELS,
    }
}

/// Dilation of residual block `d` of a Resnet1D (`growth^d`; decoders
/// use the reversed order, `vqvae_reverse_decoder_dilation: True`).
pub fn dilation(vq: &VqConfig, d: u32, reversed: bool) -> u32 {
    let e = if reversed {
        vq.depth - 1 - d.min(vq.depth - 1)
    } else {
        d
    };
    vq.dilation_growth_rate.saturating_pow(e)
}

/// Emits [`TensorSpec`]s of the shared building blocks to a callback;
/// each family's schema lists its modules with these.
pub struct Emit<'f, E> {
    pub f: &'f mut dyn FnMut(&TensorSpec) -> Result<(), E>,
}

impl<E: From<SchemaError>> Emit<'_, E> {
    pub fn t(&mut self, name: TensorName, dims: &[u32], role: Role) -> Result<(), E> {
        let mut shape = [1u32; 4];
        shape[..dims.len()].copy_from_slice(dims);
        (self.f)(&TensorSpec {
            name,
            rank: dims.len() as u8,
            shape,
            role,
        })
    }
    /// `<prefix>.weight` (`w`, read as `role`) and `<prefix>.bias` (`bias`).
    pub fn wb(&mut self, prefix: &str, w: &[u32], bias: u32, role: Role) -> Result<(), E> {
        self.t(name(format_args!("{prefix}.weight"))?, w, role)?;
        self.t(name(format_args!("{prefix}.bias"))?, &[bias], Role::Vector)
    }
    /// A pre-LN transformer block (`MusicBlock` or `Block`) of width `c`.
    pub fn block(&mut self, prefix: &str, c: u32) -> Result<(), E> {
        self.wb(&name(format_args!("{prefix}.ln1"))?, &[c], c, Role::Vector)?;
        self.wb(&name(format_args!("{prefix}.ln2"))?, &[c], c, Role::Vector)?;
        for p in ["key", "query", "value", "proj"] {
            self.wb(
                &name(format_args!("{prefix}.attn.{p}"))?,
                &[c, c],
                c,
                Role::Linear,
            )?;
        }
        self.wb(
            &name(format_args!("{prefix}.mlp.0"))?,
            &[4 * c, c],
            4 * c,
            Role::Linear,
        )?;
        self.wb(
            &name(format_args!("{prefix}.mlp.2"))?,
            &[c, 4 * c],
            c,
            Role::Linear,
        )
    }
    /// A Resnet1D whose convs are read as `conv` (encoder or decoder).
    pub fn resnet(&mut self, stage: &str, vq: &VqConfig, conv: Role) -> Result<(), E> {
        let (w, inner) = (vq.width, vq.res_inner().unwrap_or(0));
        for d in 0..vq.depth {
            let blk = name(format_args!("{stage}.model.{d}.model"))?;
            self.wb(&name(format_args!("{blk}.1"))?, &[inner, w, 3], inner, conv)?;
            self.wb(&name(format_args!("{blk}.3"))?, &[w, inner, 1], w, conv)?;
        }
        Ok(())
    }
    pub fn vq(&mut self, vq_name: &str, vq: &VqConfig) -> Result<(), E> {
        let (w, k) = (vq.width, 2 * vq.stride_t);
        for i in 0..vq.down_t {
            let stage = encoder_stage(vq_name, i)?;
            let c_in = if i == 0 { vq.in_channels } else { w };
            self.wb(
                &name(format_args!("{stage}.0"))?,
                &[w, c_in, k],
                w,
                Role::EncoderConv,
            )?;
            self.resnet(&name(format_args!("{stage}.1"))?, vq, Role::EncoderConv)?;
        }
        self.wb(
            &encoder_stage(vq_name, vq.down_t)?,
            &[vq.emb_width, w, 3],
            vq.emb_width,
            Role::EncoderConv,
        )?;
        self.t(
            codebook_name(vq_name)?,
            &[vq.l_bins, vq.emb_width],
            Role::Codebook,
        )?;
        for kind in [DecoderKind::Position, DecoderKind::Rotation] {
            if decoder_channels(vq, kind) > 0 {
                self.decoder(vq_name, vq, kind)?;
            }
        }
        Ok(())
    }
    /// Decoder `kind` of the VQ-VAE `vq_name`.
    pub fn decoder(&mut self, vq_name: &str, vq: &VqConfig, kind: DecoderKind) -> Result<(), E> {
        let (w, k) = (vq.width, 2 * vq.stride_t);
        let c_out = decoder_channels(vq, kind);
        self.wb(
            &decoder_stage(vq_name, kind, 0)?,
            &[w, vq.emb_width, 3],
            w,
            Role::Conv,
        )?;
        for i in 0..vq.down_t {
            let stage = decoder_stage(vq_name, kind, i + 1)?;
            self.resnet(&name(format_args!("{stage}.0"))?, vq, Role::Conv)?;
            let out = if i + 1 == vq.down_t { vq.emb_width } else { w };
            self.wb(
                &name(format_args!("{stage}.1"))?,
                &[w, out, k],
                out,
                Role::ConvTranspose,
            )?;
        }
        self.wb(
            &decoder_out(vq_name, kind)?,
            &[c_out, vq.emb_width, 3],
            c_out,
            Role::Conv,
        )
    }
}
