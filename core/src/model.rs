//! `Model<'a>`: every weight of the inference path, bound once as borrowed
//! views of the model bytes (mmap, `include_bytes!`, an engine asset) and
//! validated at bind time (names from [`crate::schema`], shapes, dtypes,
//! alignment). Immutable and `Sync`: many sessions share one model.
//!
//! Dtypes: weight matrices (Linear, Conv1d/ConvTranspose1d, token
//! embeddings, codebooks, heads) bind as [`Matrix`] of any stored type
//! (F32, F16, Q8Block32, Q4Block32 and their x8 groups; one generic kernel
//! path, `kernels::weights`); a ConvTranspose1d weight in either stored
//! order ([`ConvTWeight`]: PyTorch's, or the GEMM order of blocked files);
//! biases, LayerNorm parameters and `pos_emb` are added to activations
//! as they are and must be F32 (they are <1% of the bytes).
//!
//! Structure mirrors the original modules: [`LatW`] (`MusicTrans`),
//! [`BlockW`] (`MusicBlock` / `Block`), [`GptW`] (`GPT2nt`), [`VqW`]
//! (one part of `SepVQVAEXM`, or the translation `VQVAE`).

use heapless::Vec;

use crate::config::{LatConfig, ModelConfig, Part, VqConfig};
use crate::kernels::{ConvGeom, ConvTWeight, F16Rows, F32Rows, Matrix, Q4Rows, Q8Rows, X8Rows};
use crate::limits::{ConfigError, MAX_DEPTH, MAX_DOWN_T, MAX_GPT_LAYERS, MAX_LAT_LAYERS};
use crate::schema::{self, name, DecoderKind, SchemaError, TensorName};
use crate::tensor::{DType, TensorRef};

/// Where tensors come from: a parsed `.duo` file, or (tests) a map.
pub trait TensorSource<'a> {
    /// The tensor stored under the schema name, or None.
    fn tensor(&self, name: &str) -> Option<TensorRef<'a>>;
}

/// Why a model could not be bound. `name` is the schema name of the tensor.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BindError {
    Config(ConfigError),
    Name(SchemaError),
    Missing { name: TensorName },
    Shape { name: TensorName, expected: [u32; 4], expected_rank: u8, found: [u32; 4], found_rank: u8 },
    /// The stored dtype is not accepted for this tensor: vectors and tables
    /// added as f32 (biases, LayerNorm, `pos_emb`) must be F32; weight
    /// matrices may be F32, F16 or Q8Block32 (a Q8 matrix needs whole
    /// blocks per row).
    DType { name: TensorName, dtype: DType },
    /// Payload not 4-byte aligned in memory (the model buffer must be).
    Misaligned { name: TensorName },
    /// A layer count above its fixed capacity (caught by validate first).
    Capacity,
}

impl From<SchemaError> for BindError {
    fn from(e: SchemaError) -> Self {
        BindError::Name(e)
    }
}

/// `nn.Linear`: `w` (out, in), optional bias (out).
#[derive(Clone, Copy, Debug)]
pub struct Linear<'a> {
    pub w: Matrix<'a>,
    pub b: Option<&'a [f32]>,
}

/// `nn.LayerNorm` affine parameters (C).
#[derive(Clone, Copy, Debug)]
pub struct LayerNormW<'a> {
    pub w: &'a [f32],
    pub b: &'a [f32],
}

/// A pre-LN transformer block: `x += proj(attn(ln1 x)); x += mlp.2(gelu(mlp.0(ln2 x)))`.
#[derive(Clone, Copy, Debug)]
pub struct BlockW<'a> {
    pub ln1: LayerNormW<'a>,
    pub ln2: LayerNormW<'a>,
    pub query: Linear<'a>,
    pub key: Linear<'a>,
    pub value: Linear<'a>,
    pub proj: Linear<'a>,
    pub fc: Linear<'a>,
    pub fc_out: Linear<'a>,
}

/// A Look-Ahead Transformer (`MusicTrans`).
#[derive(Clone, Debug)]
pub struct LatW<'a> {
    pub cfg: LatConfig,
    pub cond_emb: Linear<'a>,
    pub blocks: Vec<BlockW<'a>, { MAX_LAT_LAYERS as usize }>,
    /// (C, C * downsample_rate).
    pub downsample: Linear<'a>,
}

/// The follower GPT (`GPT2nt`).
#[derive(Clone, Debug)]
pub struct GptW<'a> {
    pub music: LatW<'a>,
    /// Leader LATs in part order up, down, lhand, rhand.
    pub leaders: [LatW<'a>; 4],
    /// `tok_emb_{up,down,lhand,rhand,transl}` (vocab, C).
    pub tok_emb: [Matrix<'a>; 5],
    /// `gpt_base.pos_emb` (n_streams * block_size, C).
    pub pos_emb: &'a [f32],
    pub base: Vec<BlockW<'a>, { MAX_GPT_LAYERS as usize }>,
    pub head: Vec<BlockW<'a>, { MAX_GPT_LAYERS as usize }>,
    /// Bias-free heads `head_{up,down,lhand,rhand,transl}` (vocab, C).
    pub heads: [Matrix<'a>; 5],
}

/// A `Conv1d` with its geometry.
#[derive(Clone, Copy, Debug)]
pub struct ConvW<'a> {
    /// (c_out, c_in * k).
    pub w: Matrix<'a>,
    pub b: &'a [f32],
    pub c_in: usize,
    pub c_out: usize,
    pub geom: ConvGeom,
}

/// A `ConvTranspose1d(k = 2s, stride s, pad s/2)`.
#[derive(Clone, Copy, Debug)]
pub struct ConvTW<'a> {
    /// PyTorch's (c_in, c_out, k) as stored: (c_in, c_out * k), or in GEMM
    /// order (c_out * k, c_in).
    pub w: ConvTWeight<'a>,
    pub b: &'a [f32],
    pub c_in: usize,
    pub c_out: usize,
    pub kernel: usize,
    pub stride: usize,
    pub pad: usize,
}

/// One `ResConv1DBlock`: `x + conv1x1(relu(conv_k3_dil(relu(x))))`.
#[derive(Clone, Copy, Debug)]
pub struct ResBlockW<'a> {
    pub conv_dil: ConvW<'a>,
    pub conv_1x1: ConvW<'a>,
}

/// `Resnet1D`: residual blocks in execution order.
pub type ResnetW<'a> = Vec<ResBlockW<'a>, { MAX_DEPTH as usize }>;

/// VQ-VAE encoder: `[conv(k2s, s) -> Resnet1D] x down_t -> conv(k3)`.
#[derive(Clone, Debug)]
pub struct EncoderW<'a> {
    pub stages: Vec<(ConvW<'a>, ResnetW<'a>), { MAX_DOWN_T as usize }>,
    pub out: ConvW<'a>,
}

/// VQ-VAE decoder: `conv(k3) -> [Resnet1D(reversed) -> convT] x down_t -> conv(k3)`.
#[derive(Clone, Debug)]
pub struct DecoderW<'a> {
    pub input: ConvW<'a>,
    pub stages: Vec<(ResnetW<'a>, ConvTW<'a>), { MAX_DOWN_T as usize }>,
    pub out: ConvW<'a>,
}

/// One VQ-VAE (a body part or the relative translation).
#[derive(Clone, Debug)]
pub struct VqW<'a> {
    pub cfg: VqConfig,
    pub encoder: EncoderW<'a>,
    /// `bottleneck.level_blocks.0.k` (l_bins, emb_width).
    pub codebook: Matrix<'a>,
    pub pos: DecoderW<'a>,
    /// Rotation decoder (None for the translation VQ-VAE).
    pub rot: Option<DecoderW<'a>>,
}

/// The whole inference path. Thread rule: immutable after [`Model::bind`];
/// `&Model` may be shared by any number of threads (`Model: Sync`).
#[derive(Clone, Debug)]
pub struct Model<'a> {
    pub cfg: ModelConfig,
    pub gpt: GptW<'a>,
    /// Part VQ-VAEs in order up, down, lhand, rhand.
    pub parts: [VqW<'a>; 4],
    pub transl: VqW<'a>,
}

struct Binder<'s, S> {
    src: &'s S,
}

impl<'a, S: TensorSource<'a>> Binder<'_, S> {
    /// The tensor `n`, checked to have exactly the shape `dims`.
    fn tensor(&self, n: &TensorName, dims: &[u32]) -> Result<TensorRef<'a>, BindError> {
        let t = self.src.tensor(n).ok_or_else(|| BindError::Missing { name: n.clone() })?;
        let mut expected = [1u32; 4];
        expected[..dims.len()].copy_from_slice(dims);
        let numel = dims.iter().map(|&d| d as usize).product::<usize>();
        if t.rank as usize != dims.len() || t.dims() != dims || t.dtype.bytes_for(numel, crate::tensor::block_row(dims)) != Some(t.data.len()) {
            return Err(BindError::Shape {
                name: n.clone(),
                expected,
                expected_rank: dims.len() as u8,
                found: t.shape,
                found_rank: t.rank,
            });
        }
        Ok(t)
    }
    /// An f32 vector/table (biases, LayerNorm, `pos_emb`): f32 only.
    fn get(&self, n: TensorName, dims: &[u32]) -> Result<&'a [f32], BindError> {
        let t = self.tensor(&n, dims)?;
        if t.dtype != DType::F32 {
            return Err(BindError::DType { name: n, dtype: t.dtype });
        }
        t.as_f32().ok_or(BindError::Misaligned { name: n })
    }
    /// A weight matrix viewed as (dims[0], product of the rest): any dtype
    /// with a [`crate::kernels::RowMatrix`] impl (F32, F16, Q8Block32, Q8Block32x8, Q4Block32, Q4Block32x8).
    fn matrix(&self, n: TensorName, dims: &[u32]) -> Result<Matrix<'a>, BindError> {
        let t = self.tensor(&n, dims)?;
        let rows = dims[0] as usize;
        let cols = dims[1..].iter().map(|&d| d as usize).product::<usize>();
        let m = match t.dtype {
            DType::F32 => F32Rows::new(t.as_f32().ok_or(BindError::Misaligned { name: n.clone() })?, rows, cols).map(Matrix::F32),
            DType::F16 => {
                let bits: &'a [u16] = bytemuck::try_cast_slice(t.data).map_err(|_| BindError::Misaligned { name: n.clone() })?;
                F16Rows::new(bits, rows, cols).map(Matrix::F16)
            }
            DType::Q8Block32 => Q8Rows::new(t.data, rows, cols).map(Matrix::Q8),
            DType::Q8Block32x8 => X8Rows::new(t.data, rows, cols).map(Matrix::X8),
            DType::Q4Block32x8 => X8Rows::new_q4(t.data, rows, cols).map(Matrix::X8),
            DType::Q4Block32 => Q4Rows::new(t.data, rows, cols).map(Matrix::Q4),
        };
        m.ok_or(BindError::DType { name: n, dtype: t.dtype })
    }
    /// A `ConvTranspose1d` weight `(c_in, c_out, k)`: PyTorch order (rank
    /// 3), or GEMM order `(c_out * k, c_in)` (rank 2; docs/FORMAT.md §6).
    fn conv_t(&self, n: TensorName, c_in: u32, c_out: u32, k: u32) -> Result<ConvTWeight<'a>, BindError> {
        let gemm = self.src.tensor(&n).is_some_and(|t| t.rank == 2);
        match c_out.checked_mul(k) {
            Some(zk) if gemm => Ok(ConvTWeight::Gemm(self.matrix(n, &[zk, c_in])?)),
            _ => Ok(ConvTWeight::Rows(self.matrix(n, &[c_in, c_out, k])?)),
        }
    }
    fn linear(&self, prefix: &str, out: u32, inp: u32, bias: bool) -> Result<Linear<'a>, BindError> {
        let w = self.matrix(name(format_args!("{prefix}.weight"))?, &[out, inp])?;
        let b = if bias { Some(self.get(name(format_args!("{prefix}.bias"))?, &[out])?) } else { None };
        Ok(Linear { w, b })
    }
    fn ln(&self, prefix: &str, c: u32) -> Result<LayerNormW<'a>, BindError> {
        Ok(LayerNormW {
            w: self.get(name(format_args!("{prefix}.weight"))?, &[c])?,
            b: self.get(name(format_args!("{prefix}.bias"))?, &[c])?,
        })
    }
    fn block(&self, prefix: &str, c: u32) -> Result<BlockW<'a>, BindError> {
        let l = |p: &str| -> Result<TensorName, BindError> { Ok(name(format_args!("{prefix}.{p}"))?) };
        Ok(BlockW {
            ln1: self.ln(&l("ln1")?, c)?,
            ln2: self.ln(&l("ln2")?, c)?,
            query: self.linear(&l("attn.query")?, c, c, true)?,
            key: self.linear(&l("attn.key")?, c, c, true)?,
            value: self.linear(&l("attn.value")?, c, c, true)?,
            proj: self.linear(&l("attn.proj")?, c, c, true)?,
            fc: self.linear(&l("mlp.0")?, 4 * c, c, true)?,
            fc_out: self.linear(&l("mlp.2")?, c, 4 * c, true)?,
        })
    }
    fn lat(&self, which: Option<Part>, lat: &LatConfig, c: u32) -> Result<LatW<'a>, BindError> {
        let p = schema::lat_prefix(which)?;
        let mut blocks = Vec::new();
        for i in 0..lat.n_layer {
            let b = self.block(&name(format_args!("{p}.blocks.{i}"))?, c)?;
            blocks.push(b).map_err(|_| BindError::Capacity)?;
        }
        Ok(LatW {
            cfg: *lat,
            cond_emb: self.linear(&name(format_args!("{p}.cond_emb"))?, c, lat.n_in, true)?,
            blocks,
            downsample: self.linear(&name(format_args!("{p}.downsample"))?, c, c * lat.downsample_rate, true)?,
        })
    }
    fn conv(&self, prefix: &str, c_out: u32, c_in: u32, k: u32, geom: ConvGeom) -> Result<ConvW<'a>, BindError> {
        Ok(ConvW {
            w: self.matrix(name(format_args!("{prefix}.weight"))?, &[c_out, c_in, k])?,
            b: self.get(name(format_args!("{prefix}.bias"))?, &[c_out])?,
            c_in: c_in as usize,
            c_out: c_out as usize,
            geom,
        })
    }
    fn resnet(&self, stage: &str, vq: &VqConfig, reversed: bool) -> Result<ResnetW<'a>, BindError> {
        let (w, inner) = (vq.width, vq.res_inner().unwrap_or(0));
        let mut blocks = Vec::new();
        for d in 0..vq.depth {
            let dil = schema::dilation(vq, d, reversed) as usize;
            let blk = name(format_args!("{stage}.model.{d}.model"))?;
            let g3 = ConvGeom { kernel: 3, stride: 1, pad: dil, dilation: dil };
            let g1 = ConvGeom { kernel: 1, stride: 1, pad: 0, dilation: 1 };
            let rb = ResBlockW {
                conv_dil: self.conv(&name(format_args!("{blk}.1"))?, inner, w, 3, g3)?,
                conv_1x1: self.conv(&name(format_args!("{blk}.3"))?, w, inner, 1, g1)?,
            };
            blocks.push(rb).map_err(|_| BindError::Capacity)?;
        }
        Ok(blocks)
    }
    fn decoder(&self, vq_name: &str, vq: &VqConfig, kind: DecoderKind) -> Result<DecoderW<'a>, BindError> {
        let (w, s) = (vq.width, vq.stride_t);
        let g3 = ConvGeom { kernel: 3, stride: 1, pad: 1, dilation: 1 };
        let input = self.conv(&schema::decoder_stage(vq_name, kind, 0)?, w, vq.emb_width, 3, g3)?;
        let mut stages = Vec::new();
        for i in 0..vq.down_t {
            let stage = schema::decoder_stage(vq_name, kind, i + 1)?;
            let res = self.resnet(&name(format_args!("{stage}.0"))?, vq, true)?;
            let out = if i + 1 == vq.down_t { vq.emb_width } else { w };
            let k = 2 * s;
            let ct = ConvTW {
                w: self.conv_t(name(format_args!("{stage}.1.weight"))?, w, out, k)?,
                b: self.get(name(format_args!("{stage}.1.bias"))?, &[out])?,
                c_in: w as usize,
                c_out: out as usize,
                kernel: k as usize,
                stride: s as usize,
                pad: (s / 2) as usize,
            };
            stages.push((res, ct)).map_err(|_| BindError::Capacity)?;
        }
        let c_out = schema::decoder_channels(vq, kind);
        let out = self.conv(&schema::decoder_out(vq_name, kind)?, c_out, vq.emb_width, 3, g3)?;
        Ok(DecoderW { input, stages, out })
    }
    fn vq(&self, which: Option<Part>, vq: &VqConfig) -> Result<VqW<'a>, BindError> {
        let p = schema::vq_prefix(which)?;
        let (w, s) = (vq.width, vq.stride_t);
        let mut stages = Vec::new();
        for i in 0..vq.down_t {
            let stage = schema::encoder_stage(&p, i)?;
            let c_in = if i == 0 { vq.in_channels } else { w };
            let g = ConvGeom { kernel: 2 * s as usize, stride: s as usize, pad: (s / 2) as usize, dilation: 1 };
            let conv = self.conv(&name(format_args!("{stage}.0"))?, w, c_in, 2 * s, g)?;
            let res = self.resnet(&name(format_args!("{stage}.1"))?, vq, false)?;
            stages.push((conv, res)).map_err(|_| BindError::Capacity)?;
        }
        let g3 = ConvGeom { kernel: 3, stride: 1, pad: 1, dilation: 1 };
        let out = self.conv(&schema::encoder_stage(&p, vq.down_t)?, vq.emb_width, w, 3, g3)?;
        let codebook = self.matrix(schema::codebook_name(&p)?, &[vq.l_bins, vq.emb_width])?;
        let pos = self.decoder(&p, vq, DecoderKind::Position)?;
        let rot = if vq.rot_channels > 0 { Some(self.decoder(&p, vq, DecoderKind::Rotation)?) } else { None };
        Ok(VqW { cfg: *vq, encoder: EncoderW { stages, out }, codebook, pos, rot })
    }
    fn gpt(&self, cfg: &ModelConfig) -> Result<GptW<'a>, BindError> {
        let g = &cfg.gpt;
        let c = g.n_embd;
        let music = self.lat(None, &g.music, c)?;
        let leaders = [
            self.lat(Some(Part::Up), &g.leader, c)?,
            self.lat(Some(Part::Down), &g.leader, c)?,
            self.lat(Some(Part::LHand), &g.leader, c)?,
            self.lat(Some(Part::RHand), &g.leader, c)?,
        ];
        let mut tok = [None; 5];
        for (s, t) in tok.iter_mut().enumerate() {
            *t = Some(self.matrix(schema::tok_emb_name(s)?, &[g.vocab[s], c])?);
        }
        let pos_emb = self.get(name(format_args!("gpt.gpt_base.pos_emb"))?, &[1, g.block_size * g.n_streams, c])?;
        let mut base = Vec::new();
        for i in 0..g.n_layer_base {
            let b = self.block(&name(format_args!("gpt.gpt_base.blocks.{i}"))?, c)?;
            base.push(b).map_err(|_| BindError::Capacity)?;
        }
        let mut head = Vec::new();
        for i in 0..g.n_layer_head {
            let b = self.block(&name(format_args!("gpt.gpt_head.blocks.{i}"))?, c)?;
            head.push(b).map_err(|_| BindError::Capacity)?;
        }
        // Quirk: head_lhand has vocab_up rows, head_rhand vocab_down rows.
        let head_rows = [g.vocab[0], g.vocab[1], g.vocab[0], g.vocab[1], g.vocab[4]];
        let mut heads = [None; 5];
        for (s, h) in heads.iter_mut().enumerate() {
            *h = Some(self.matrix(schema::head_name(s)?, &[head_rows[s], c])?);
        }
        let unwrap5 = |a: [Option<Matrix<'a>>; 5]| -> Result<[Matrix<'a>; 5], BindError> {
            let mut out = [a[0].ok_or(BindError::Capacity)?; 5];
            for (o, m) in out.iter_mut().zip(a) {
                *o = m.ok_or(BindError::Capacity)?;
            }
            Ok(out)
        };
        Ok(GptW { music, leaders, tok_emb: unwrap5(tok)?, pos_emb, base, head, heads: unwrap5(heads)? })
    }
}

impl<'a> Model<'a> {
    /// Validates `cfg` and binds every tensor the schema lists from `src`.
    pub fn bind<S: TensorSource<'a>>(cfg: &ModelConfig, src: &S) -> Result<Model<'a>, BindError> {
        cfg.validate().map_err(BindError::Config)?;
        let b = Binder { src };
        let gpt = b.gpt(cfg)?;
        let parts = [
            b.vq(Some(Part::Up), &cfg.parts[0])?,
            b.vq(Some(Part::Down), &cfg.parts[1])?,
            b.vq(Some(Part::LHand), &cfg.parts[2])?,
            b.vq(Some(Part::RHand), &cfg.parts[3])?,
        ];
        let transl = b.vq(None, &cfg.transl)?;
        Ok(Model { cfg: *cfg, gpt, parts, transl })
    }

    pub fn config(&self) -> &ModelConfig {
        &self.cfg
    }
}

const _: () = {
    const fn assert_sync<T: Sync>() {}
    assert_sync::<Model<'static>>();
};

impl<'a> TensorSource<'a> for crate::format::DuoFile<'a> {
    fn tensor(&self, name: &str) -> Option<TensorRef<'a>> {
        crate::format::DuoFile::tensor(self, name).ok()
    }
}

impl<'a> Model<'a> {
    /// Binds every weight of a parsed `.duo` file (its config was validated
    /// by the decoder and is validated again here).
    pub fn from_duo(file: &crate::format::DuoFile<'a>) -> Result<Model<'a>, BindError> {
        Model::bind(file.config(), file)
    }
}

impl<'a> Model<'a> {
    /// The VQ-VAE of a body part or of the translation.
    pub fn vq(&self, which: crate::limits::VqWhich) -> &VqW<'a> {
        match which {
            crate::limits::VqWhich::Part(p) => &self.parts[p as usize],
            crate::limits::VqWhich::Transl => &self.transl,
        }
    }
}
