//! Binding weights by name: [`TensorSource`] (a parsed `.duo` file, or a
//! map in tests), [`BindError`], and [`Binder`], whose methods bind the
//! shared building blocks (Linear, LayerNorm, block, convs, Resnet1D,
//! VQ-VAE). Each family's model binds its own modules from these.

use heapless::Vec;

use crate::kernels::{ConvGeom, ConvTWeight, F16Rows, F32Rows, Matrix, Q4Rows, Q8Rows, X8Rows};
use crate::limits::ConfigError;
use crate::nn::names::{self, name, DecoderKind, SchemaError, TensorName};
use crate::nn::vq_config::VqConfig;
use crate::nn::weights::{
    BlockW, ConvTW, ConvW, DecoderW, EncoderW, LayerNormW, Linear, ResBlockW, ResnetW, VqW,
};
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
    Missing {
        name: TensorName,
    },
    Shape {
        name: TensorName,
        expected: [u32; 4],
        expected_rank: u8,
        found: [u32; 4],
        found_rank: u8,
    },
    /// The stored dtype is not accepted for this tensor: vectors and tables
    /// added as f32 (biases, LayerNorm, `pos_emb`) must be F32; weight
    /// matrices may be F32, F16 or Q8Block32 (a Q8 matrix needs whole
    /// blocks per row).
    DType {
        name: TensorName,
        dtype: DType,
    },
    /// Payload not 4-byte aligned in memory (the model buffer must be).
    Misaligned {
        name: TensorName,
    },
    /// A layer count above its fixed capacity (caught by validate first).
    Capacity,
    /// The file holds a model of another family than the one asked for.
    Family {
        expected: crate::family::Family,
        found: crate::family::Family,
    },
}

impl From<SchemaError> for BindError {
    fn from(e: SchemaError) -> Self {
        BindError::Name(e)
    }
}

/// Binds tensors of a [`TensorSource`] by schema name, checking shape,
/// dtype and alignment: the building blocks every family's model binds.
pub struct Binder<'s, S> {
    pub src: &'s S,
}

impl<'a, S: TensorSource<'a>> Binder<'_, S> {
    /// The tensor `n`, checked to have exactly the shape `dims`.
    pub fn tensor(&self, n: &TensorName, dims: &[u32]) -> Result<TensorRef<'a>, BindError> {
        let t = self
            .src
            .tensor(n)
            .ok_or_else(|| BindError::Missing { name: n.clone() })?;
        let mut expected = [1u32; 4];
        expected[..dims.len()].copy_from_slice(dims);
        let numel = dims.iter().map(|&d| d as usize).product::<usize>();
        if t.rank as usize != dims.len()
            || t.dims() != dims
            || t.dtype.bytes_for(numel, crate::tensor::block_row(dims)) != Some(t.data.len())
        {
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
    pub fn get(&self, n: TensorName, dims: &[u32]) -> Result<&'a [f32], BindError> {
        let t = self.tensor(&n, dims)?;
        if t.dtype != DType::F32 {
            return Err(BindError::DType {
                name: n,
                dtype: t.dtype,
            });
        }
        t.as_f32().ok_or(BindError::Misaligned { name: n })
    }
    /// A weight matrix viewed as (`dims[0]`, product of the rest): any dtype
    /// with a [`crate::kernels::RowMatrix`] impl (F32, F16, Q8Block32, Q8Block32x8, Q4Block32, Q4Block32x8).
    pub fn matrix(&self, n: TensorName, dims: &[u32]) -> Result<Matrix<'a>, BindError> {
        let t = self.tensor(&n, dims)?;
        let rows = dims[0] as usize;
        let cols = dims[1..].iter().map(|&d| d as usize).product::<usize>();
        let m = match t.dtype {
            DType::F32 => F32Rows::new(
                t.as_f32()
                    .ok_or(BindError::Misaligned { name: n.clone() })?,
                rows,
                cols,
            )
            .map(Matrix::F32),
            DType::F16 => {
                let bits: &'a [u16] = bytemuck::try_cast_slice(t.data)
                    .map_err(|_| BindError::Misaligned { name: n.clone() })?;
                F16Rows::new(bits, rows, cols).map(Matrix::F16)
            }
            DType::Q8Block32 => Q8Rows::new(t.data, rows, cols).map(Matrix::Q8),
            DType::Q8Block32x8 => X8Rows::new(t.data, rows, cols).map(Matrix::X8),
            DType::Q4Block32x8 => X8Rows::new_q4(t.data, rows, cols).map(Matrix::X8),
            DType::Q4Block32 => Q4Rows::new(t.data, rows, cols).map(Matrix::Q4),
        };
        m.ok_or(BindError::DType {
            name: n,
            dtype: t.dtype,
        })
    }
    /// A `ConvTranspose1d` weight `(c_in, c_out, k)`: PyTorch order (rank
    /// 3), or GEMM order `(c_out * k, c_in)` (rank 2; docs/FORMAT.md §6).
    pub fn conv_t(
        &self,
        n: TensorName,
        c_in: u32,
        c_out: u32,
        k: u32,
    ) -> Result<ConvTWeight<'a>, BindError> {
        let gemm = self.src.tensor(&n).is_some_and(|t| t.rank == 2);
        match c_out.checked_mul(k) {
            Some(zk) if gemm => Ok(ConvTWeight::Gemm(self.matrix(n, &[zk, c_in])?)),
            _ => Ok(ConvTWeight::Rows(self.matrix(n, &[c_in, c_out, k])?)),
        }
    }
    pub fn linear(
        &self,
        prefix: &str,
        out: u32,
        inp: u32,
        bias: bool,
    ) -> Result<Linear<'a>, BindError> {
        let w = self.matrix(name(format_args!("{prefix}.weight"))?, &[out, inp])?;
        let b = if bias {
            Some(self.get(name(format_args!("{prefix}.bias"))?, &[out])?)
        } else {
            None
        };
        Ok(Linear { w, b })
    }
    pub fn ln(&self, prefix: &str, c: u32) -> Result<LayerNormW<'a>, BindError> {
        Ok(LayerNormW {
            w: self.get(name(format_args!("{prefix}.weight"))?, &[c])?,
            b: self.get(name(format_args!("{prefix}.bias"))?, &[c])?,
        })
    }
    pub fn block(&self, prefix: &str, c: u32) -> Result<BlockW<'a>, BindError> {
        let l =
            |p: &str| -> Result<TensorName, BindError> { Ok(name(format_args!("{prefix}.{p}"))?) };
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
    pub fn conv(
        &self,
        prefix: &str,
        c_out: u32,
        c_in: u32,
        k: u32,
        geom: ConvGeom,
    ) -> Result<ConvW<'a>, BindError> {
        Ok(ConvW {
            w: self.matrix(name(format_args!("{prefix}.weight"))?, &[c_out, c_in, k])?,
            b: self.get(name(format_args!("{prefix}.bias"))?, &[c_out])?,
            c_in: c_in as usize,
            c_out: c_out as usize,
            geom,
        })
    }
    pub fn resnet(
        &self,
        stage: &str,
        vq: &VqConfig,
        reversed: bool,
    ) -> Result<ResnetW<'a>, BindError> {
        let (w, inner) = (vq.width, vq.res_inner().unwrap_or(0));
        let mut blocks = Vec::new();
        for d in 0..vq.depth {
            let dil = names::dilation(vq, d, reversed) as usize;
            let blk = name(format_args!("{stage}.model.{d}.model"))?;
            let g3 = ConvGeom {
                kernel: 3,
                stride: 1,
                pad: dil,
                dilation: dil,
            };
            let g1 = ConvGeom {
                kernel: 1,
                stride: 1,
                pad: 0,
                dilation: 1,
            };
            let rb = ResBlockW {
                conv_dil: self.conv(&name(format_args!("{blk}.1"))?, inner, w, 3, g3)?,
                conv_1x1: self.conv(&name(format_args!("{blk}.3"))?, w, inner, 1, g1)?,
            };
            blocks.push(rb).map_err(|_| BindError::Capacity)?;
        }
        Ok(blocks)
    }
    pub fn decoder(
        &self,
        vq_name: &str,
        vq: &VqConfig,
        kind: DecoderKind,
    ) -> Result<DecoderW<'a>, BindError> {
        let (w, s) = (vq.width, vq.stride_t);
        let g3 = ConvGeom {
            kernel: 3,
            stride: 1,
            pad: 1,
            dilation: 1,
        };
        let input = self.conv(
            &names::decoder_stage(vq_name, kind, 0)?,
            w,
            vq.emb_width,
            3,
            g3,
        )?;
        let mut stages = Vec::new();
        for i in 0..vq.down_t {
            let stage = names::decoder_stage(vq_name, kind, i + 1)?;
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
        let c_out = names::decoder_channels(vq, kind);
        let out = self.conv(
            &names::decoder_out(vq_name, kind)?,
            c_out,
            vq.emb_width,
            3,
            g3,
        )?;
        Ok(DecoderW { input, stages, out })
    }
    pub fn vq(&self, p: &str, vq: &VqConfig) -> Result<VqW<'a>, BindError> {
        let (w, s) = (vq.width, vq.stride_t);
        let mut stages = Vec::new();
        for i in 0..vq.down_t {
            let stage = names::encoder_stage(p, i)?;
            let c_in = if i == 0 { vq.in_channels } else { w };
            let g = ConvGeom {
                kernel: 2 * s as usize,
                stride: s as usize,
                pad: (s / 2) as usize,
                dilation: 1,
            };
            let conv = self.conv(&name(format_args!("{stage}.0"))?, w, c_in, 2 * s, g)?;
            let res = self.resnet(&name(format_args!("{stage}.1"))?, vq, false)?;
            stages.push((conv, res)).map_err(|_| BindError::Capacity)?;
        }
        let g3 = ConvGeom {
            kernel: 3,
            stride: 1,
            pad: 1,
            dilation: 1,
        };
        let out = self.conv(&names::encoder_stage(p, vq.down_t)?, vq.emb_width, w, 3, g3)?;
        let codebook = self.matrix(names::codebook_name(p)?, &[vq.l_bins, vq.emb_width])?;
        let pos = self.decoder(p, vq, DecoderKind::Position)?;
        let rot = if vq.rot_channels > 0 {
            Some(self.decoder(p, vq, DecoderKind::Rotation)?)
        } else {
            None
        };
        Ok(VqW {
            cfg: *vq,
            encoder: EncoderW { stages, out },
            codebook,
            pos,
            rot,
        })
    }
}

impl<'a> TensorSource<'a> for crate::format::DuoFile<'a> {
    fn tensor(&self, name: &str) -> Option<TensorRef<'a>> {
        crate::format::DuoFile::tensor(self, name).ok()
    }
}
