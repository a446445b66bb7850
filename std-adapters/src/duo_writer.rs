//! Writing `.duo` files (docs/FORMAT.md). The writer sorts tensors by name,
//! lays payloads out 64-byte aligned in that order, encodes the postcard
//! header, and checks the result with the core decoder before returning it,
//! so a file it returns is one the engine accepts.

use std::fmt;
use std::path::Path;

use duolando_core::duolando::config::ModelConfig;
use duolando_core::family::{Family, FamilyConfig};
use duolando_core::format::{align_up, ALIGN, MAGIC, PREFIX_LEN, VERSION, VERSION_DUOLANDO};
use duolando_core::tensor::DType;
use serde::Serialize;

use crate::model_file::{AlignedBytes, ModelFile, ModelFileError};

/// Storage type chosen for a tensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StoreAs {
    F32,
    /// Rounded to nearest from f32 (`half::f16::from_f32`).
    F16,
    /// `DType::Q8Block32` (see [`quantise_q8_block32`]); the last axis must
    /// be a multiple of 32.
    Q8Block32,
    /// `DType::Q8Block32x8` (see [`quantise_q8_block32x8`]): the Q8Block32
    /// rows interleaved in groups of 8; the last axis must be a multiple of 32.
    Q8Block32x8,
    /// `DType::Q4Block32` (see [`quantise_q4_block32`]); the last axis must
    /// be a multiple of 32.
    Q4Block32,
    /// `DType::Q4Block32x8` (see [`quantise_q4_block32x8`]).
    Q4Block32x8,
}

/// Quantises `values` (rows of the last axis, a multiple of 32) to
/// `Q8Block32` bytes: per block of 32, scale `d = f16(max|v| / 127)` (round
/// to nearest) and `q = clamp(round(v / d), -127, 127)` (0 when `d == 0`),
/// stored as the 2 scale bytes then the 32 values. The scale used for
/// rounding is the stored f16 one, so `d * q` is the nearest grid point.
pub fn quantise_q8_block32(values: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(values.len() / 32 * 34);
    for b in values.chunks_exact(32) {
        let amax = b.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let d = half::f16::from_f32(amax / 127.0);
        let df = d.to_f32();
        let inv = if df > 0.0 { 1.0 / df } else { 0.0 };
        out.extend_from_slice(&d.to_le_bytes());
        out.extend(
            b.iter()
                .map(|&v| (v * inv).round().clamp(-127.0, 127.0) as i8 as u8),
        );
    }
    out
}

/// [`quantise_q8_block32`] (the same blocks, scales and values) with the
/// rows of `row` values in groups of 8, each group in the interleaved
/// layout of `DType::Q8Block32x8` (docs/FORMAT.md §4); the last group padded
/// with zero rows (scale 0, values 0).
pub fn quantise_q8_block32x8(values: &[f32], row: usize) -> Vec<u8> {
    interleave_x8(&quantise_q8_block32(values), row, 34)
}

/// [`quantise_q4_block32`] in the row groups of `DType::Q4Block32x8`
/// (docs/FORMAT.md §4); the last group padded with zero bytes.
pub fn quantise_q4_block32x8(values: &[f32], row: usize) -> Vec<u8> {
    interleave_x8(&quantise_q4_block32(values), row, 18)
}

/// Blocked rows (`block_bytes` per block of 32: a 2-byte scale, then the
/// values) of `row` values each, regrouped by 8 rows: per block, each
/// 8-byte piece `c` of the values of rows 0..8 side by side (`vb * 8 * b +
/// 64c + 8n`, `vb = block_bytes - 2`), then the 8 rows' scales per block.
fn interleave_x8(plain: &[u8], row: usize, block_bytes: usize) -> Vec<u8> {
    let nb = row / 32;
    let (rb, vb) = (nb * block_bytes, block_bytes - 2);
    let rows = if rb == 0 { 0 } else { plain.len() / rb };
    let mut out = vec![0u8; rows.div_ceil(8) * 8 * rb];
    for (r, src) in plain.chunks_exact(rb.max(1)).enumerate().take(rows) {
        let (t, n) = (r / 8, r % 8);
        let group = &mut out[t * 8 * rb..(t + 1) * 8 * rb];
        for (b, blk) in src.chunks_exact(block_bytes).enumerate() {
            for c in 0..vb / 8 {
                let at = 8 * vb * b + 64 * c + 8 * n;
                group[at..at + 8].copy_from_slice(&blk[2 + 8 * c..2 + 8 * c + 8]);
            }
            let at = 8 * vb * nb + 16 * b + 2 * n;
            group[at..at + 2].copy_from_slice(&blk[..2]);
        }
    }
    out
}

/// Quantises `values` (rows of the last axis, a multiple of 32) to
/// `Q4Block32` bytes: per block of 32, scale `d = f16(max|v| / 7)` (round to
/// nearest) and `q = clamp(round(v / d), -8, 7)` (0 when `d == 0`), stored
/// as the 2 scale bytes then 16 bytes, byte `j` = `(q_j + 8) | (q_{j+16} +
/// 8) << 4`. As for Q8, the stored f16 scale is the one used for rounding.
pub fn quantise_q4_block32(values: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(values.len() / 32 * 18);
    for b in values.chunks_exact(32) {
        let amax = b.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let d = half::f16::from_f32(amax / 7.0);
        let df = d.to_f32();
        let inv = if df > 0.0 { 1.0 / df } else { 0.0 };
        let q = |v: f32| ((v * inv).round().clamp(-8.0, 7.0) as i32 + 8) as u8;
        out.extend_from_slice(&d.to_le_bytes());
        out.extend((0..16).map(|j| q(b[j]) | (q(b[j + 16]) << 4)));
    }
    out
}

/// One tensor to write: a `.duo` name, a row-major shape, f32 values.
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor {
    pub name: String,
    pub shape: Vec<u32>,
    pub values: Vec<f32>,
    pub store_as: StoreAs,
}

/// One tensor-table entry exactly as encoded (see `format::TensorEntry`).
/// Public so tests can build deliberately broken tables with [`assemble`].
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct HeaderEntry {
    pub name: String,
    pub dtype: u8,
    pub shape: Vec<u32>,
    pub offset: u64,
    pub nbytes: u64,
}

/// The postcard header: the config, then the tensor table (varint count +
/// entries). Field order is the byte order.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Header {
    pub config: ModelConfig,
    pub tensors: Vec<HeaderEntry>,
}

/// A version-2 header (docs/FORMAT.md §2): the family's config (its tag,
/// then the config), then the tensor table.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HeaderV2 {
    pub config: FamilyConfig,
    pub tensors: Vec<HeaderEntry>,
}

/// Why a set of tensors could not be written.
#[derive(Debug)]
pub enum WriteError {
    /// `values.len()` differs from the product of `shape`.
    ValueCount {
        name: String,
        shape: Vec<u32>,
        expected: u64,
        found: usize,
    },
    /// `StoreAs::Q8Block32` / `Q4Block32` on a tensor whose last axis is not a multiple of 32.
    BlockShape { name: String, shape: Vec<u32> },
    /// Two tensors with the same name.
    Duplicate { name: String },
    /// The header could not be encoded.
    Encode(postcard::Error),
    /// The written bytes did not pass the decoder (a config/schema mismatch:
    /// the detail names the tensor and the expected vs found shape).
    Rejected(ModelFileError),
    Io {
        path: String,
        source: std::io::Error,
    },
}

impl fmt::Display for WriteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WriteError::ValueCount {
                name,
                shape,
                expected,
                found,
            } => {
                write!(
                    f,
                    "tensor '{name}': shape {shape:?} needs {expected} values, got {found}"
                )
            }
            WriteError::BlockShape { name, shape } => {
                write!(f, "tensor '{name}': shape {shape:?} cannot be stored in blocks of 32 (Q8Block32/Q4Block32: last axis not a multiple of 32)")
            }
            WriteError::Duplicate { name } => write!(f, "tensor '{name}' given twice"),
            WriteError::Encode(e) => write!(f, "cannot encode the .duo header: {e}"),
            WriteError::Rejected(e) => write!(f, "the written model does not validate: {e}"),
            WriteError::Io { path, source } => write!(f, "{path}: {source}"),
        }
    }
}

impl std::error::Error for WriteError {}

/// Prefix + header + zero padding + `data` (which must already hold the
/// payloads at the offsets the entries name, padded to 64). No checks: this
/// is the raw layout step, public for tests that need malformed files.
pub fn assemble(header: &Header, data: &[u8]) -> Result<Vec<u8>, WriteError> {
    let header_bytes = postcard::to_stdvec(header).map_err(WriteError::Encode)?;
    assemble_raw(&header_bytes, data)
}

/// [`assemble`] of a version-2 header (any family).
pub fn assemble_v2(header: &HeaderV2, data: &[u8]) -> Result<Vec<u8>, WriteError> {
    let header_bytes = postcard::to_stdvec(header).map_err(WriteError::Encode)?;
    assemble_raw_version(VERSION, &header_bytes, data)
}

/// [`assemble`] with already-encoded version-1 header bytes.
pub fn assemble_raw(header_bytes: &[u8], data: &[u8]) -> Result<Vec<u8>, WriteError> {
    assemble_raw_version(VERSION_DUOLANDO, header_bytes, data)
}

/// Prefix of `version` + `header_bytes` + zero padding + `data`.
pub fn assemble_raw_version(
    version: u32,
    header_bytes: &[u8],
    data: &[u8],
) -> Result<Vec<u8>, WriteError> {
    let header_end = (PREFIX_LEN + header_bytes.len()) as u64;
    let data_start = align_up(header_end).unwrap_or(header_end) as usize;
    let mut out = Vec::with_capacity(data_start + data.len());
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&(header_bytes.len() as u64).to_le_bytes());
    out.extend_from_slice(header_bytes);
    out.resize(data_start, 0);
    out.extend_from_slice(data);
    Ok(out)
}

/// Encodes `tensors` (any order) under a Duolando `config` into `.duo`
/// bytes (format version 1, as Duolando models have always been written)
/// and validates them with `DuoFile::parse` (schema and shapes included).
pub fn write_duo(config: &ModelConfig, tensors: &[Tensor]) -> Result<Vec<u8>, WriteError> {
    write_model(&FamilyConfig::Duolando(*config), tensors)
}

/// [`write_duo`] for any family: Duolando models as version 1 (bytes
/// unchanged since before families), every other family as version 2.
pub fn write_model(config: &FamilyConfig, tensors: &[Tensor]) -> Result<Vec<u8>, WriteError> {
    write_model_version(
        config,
        tensors,
        if config.family() == Family::Duolando {
            VERSION_DUOLANDO
        } else {
            VERSION
        },
    )
}

/// [`write_model`] in a given format version (2 for any family, 1 only for
/// Duolando); tests write Duolando models as version 2 with it.
pub fn write_model_version(
    config: &FamilyConfig,
    tensors: &[Tensor],
    version: u32,
) -> Result<Vec<u8>, WriteError> {
    let mut order: Vec<&Tensor> = tensors.iter().collect();
    order.sort_by(|a, b| a.name.as_bytes().cmp(b.name.as_bytes()));
    for pair in order.windows(2) {
        if pair[0].name == pair[1].name {
            return Err(WriteError::Duplicate {
                name: pair[0].name.clone(),
            });
        }
    }
    let mut entries = Vec::with_capacity(order.len());
    let mut data: Vec<u8> = Vec::new();
    for t in &order {
        let expected = t.shape.iter().map(|&d| d as u64).product::<u64>();
        if expected != t.values.len() as u64 {
            return Err(WriteError::ValueCount {
                name: t.name.clone(),
                shape: t.shape.clone(),
                expected,
                found: t.values.len(),
            });
        }
        let offset = data.len() as u64;
        let dtype = match t.store_as {
            StoreAs::F32 => {
                data.extend(t.values.iter().flat_map(|v| v.to_le_bytes()));
                DType::F32
            }
            StoreAs::F16 => {
                data.extend(
                    t.values
                        .iter()
                        .flat_map(|&v| half::f16::from_f32(v).to_le_bytes()),
                );
                DType::F16
            }
            StoreAs::Q8Block32
            | StoreAs::Q8Block32x8
            | StoreAs::Q4Block32
            | StoreAs::Q4Block32x8 => {
                let row = duolando_core::tensor::block_row(&t.shape);
                if row == 0 || row % 32 != 0 {
                    return Err(WriteError::BlockShape {
                        name: t.name.clone(),
                        shape: t.shape.clone(),
                    });
                }
                match t.store_as {
                    StoreAs::Q8Block32 => {
                        data.extend(quantise_q8_block32(&t.values));
                        DType::Q8Block32
                    }
                    StoreAs::Q8Block32x8 => {
                        data.extend(quantise_q8_block32x8(&t.values, row));
                        DType::Q8Block32x8
                    }
                    StoreAs::Q4Block32x8 => {
                        data.extend(quantise_q4_block32x8(&t.values, row));
                        DType::Q4Block32x8
                    }
                    _ => {
                        data.extend(quantise_q4_block32(&t.values));
                        DType::Q4Block32
                    }
                }
            }
        };
        let nbytes = data.len() as u64 - offset;
        data.resize(data.len().next_multiple_of(ALIGN), 0);
        entries.push(HeaderEntry {
            name: t.name.clone(),
            dtype: dtype as u8,
            shape: t.shape.clone(),
            offset,
            nbytes,
        });
    }
    let bytes = match (version, config) {
        (VERSION_DUOLANDO, FamilyConfig::Duolando(c)) => assemble(
            &Header {
                config: *c,
                tensors: entries,
            },
            &data,
        )?,
        _ => assemble_v2(
            &HeaderV2 {
                config: *config,
                tensors: entries,
            },
            &data,
        )?,
    };
    ModelFile::from_aligned(AlignedBytes::copy_from(&bytes), "<written model>")
        .map_err(WriteError::Rejected)?;
    Ok(bytes)
}

/// [`write_duo`], then writes the bytes to `path` (via a temporary file in
/// the same directory, renamed into place, so a failed write leaves no
/// half-written model behind).
pub fn write_duo_to_path(
    config: &ModelConfig,
    tensors: &[Tensor],
    path: &Path,
) -> Result<(), WriteError> {
    write_model_to_path(&FamilyConfig::Duolando(*config), tensors, path)
}

/// [`write_model`], then writes the bytes to `path` as [`write_duo_to_path`] does.
pub fn write_model_to_path(
    config: &FamilyConfig,
    tensors: &[Tensor],
    path: &Path,
) -> Result<(), WriteError> {
    let bytes = write_model(config, tensors)?;
    let io = |source| WriteError::Io {
        path: path.display().to_string(),
        source,
    };
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".partial");
    std::fs::write(&tmp, &bytes).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}
