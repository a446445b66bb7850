//! Why a `.duo` buffer was rejected. Every variant carries the numbers
//! needed to explain itself (tensor index, offsets, expected vs found);
//! nothing is formatted until `Display` runs. The std side
//! (`duolando::model_file`) adds the file path and resolves indices to names.

use core::fmt;

use crate::limits::ConfigError;
use crate::nn::names::SchemaError;
use crate::tensor::MAX_RANK;

pub use super::weights::NonFiniteKind;

/// A tensor shape as stored in errors: `rank` dims, the rest unused (1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shape {
    pub rank: u8,
    pub dims: [u32; MAX_RANK],
}

impl Shape {
    /// The first `rank` dims (all of them if `rank` is out of range).
    pub fn dims(&self) -> &[u32] {
        let r = (self.rank as usize).min(MAX_RANK);
        &self.dims[..r]
    }
}

impl fmt::Display for Shape {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("[")?;
        for (i, d) in self.dims().iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{d}")?;
        }
        f.write_str("]")
    }
}

/// Which postcard field of the header failed to decode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeaderField {
    /// The family tag of a version-2 header.
    Family,
    Config,
    TensorCount,
    Name,
    Dtype,
    Rank,
    Dim,
    Offset,
    ByteLen,
}

impl fmt::Display for HeaderField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            HeaderField::Family => "model family tag",
            HeaderField::Config => "model config",
            HeaderField::TensorCount => "tensor count",
            HeaderField::Name => "tensor name",
            HeaderField::Dtype => "dtype code",
            HeaderField::Rank => "rank",
            HeaderField::Dim => "dimension",
            HeaderField::Offset => "data offset",
            HeaderField::ByteLen => "byte length",
        })
    }
}

/// A rejected `.duo` buffer, or a failed lookup. `index` is the position in
/// the tensor table; `schema_index` the position in `schema::for_each_tensor`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FormatError {
    /// The buffer is shorter than the 24-byte prefix.
    TooShort { len: usize },
    /// The buffer does not start on a 64-byte boundary in memory.
    MisalignedBuffer { addr_mod_64: usize },
    /// The first 8 bytes are not the `.duo` magic.
    BadMagic { found: [u8; 8] },
    /// A format version this decoder does not read.
    UnsupportedVersion { found: u32, supported: u32 },
    /// A version-2 header names a family this build does not read.
    UnknownFamily { tag: u32 },
    /// Flag bits that v1 does not define.
    UnknownFlags { flags: u32 },
    /// The header length is over [`super::MAX_HEADER_LEN`].
    HeaderTooLarge { header_len: u64, max: u64 },
    /// The header (or its padding) extends past the end of the buffer.
    HeaderPastEnd { header_end: u64, file_len: u64 },
    /// Postcard could not decode `field` at byte `offset` of the header.
    MalformedHeader { field: HeaderField, offset: usize },
    /// Bytes left in the header after the last tensor entry.
    TrailingHeaderBytes { count: usize },
    /// A non-zero byte in the padding between header and data section.
    NonZeroPadding { offset: u64 },
    /// More tensors than [`super::MAX_TENSORS`].
    TooManyTensors { count: u64, max: u32 },
    /// An empty tensor name.
    EmptyName { index: u32 },
    /// A tensor name over [`super::MAX_NAME_LEN`] bytes.
    NameTooLong { index: u32, len: usize, max: usize },
    /// Names must be strictly ascending (bytewise); this one is not.
    UnsortedTable { index: u32 },
    /// The same name twice (`index` repeats `previous`).
    DuplicateTensor { index: u32, previous: u32 },
    /// A dtype code the format does not define.
    UnknownDtype { index: u32, code: u8 },
    /// Rank 0 or over `MAX_RANK`.
    BadRank { index: u32, rank: u32 },
    /// A dimension of 0 or over [`super::MAX_DIM`].
    DimOutOfRange { index: u32, axis: u32, dim: u32 },
    /// The element count, byte size or end offset overflows, or the shape does
    /// not fit the dtype's block layout.
    SizeOverflow { index: u32 },
    /// Stored byte length differs from `dtype.bytes_for(shape)`.
    ByteLenMismatch {
        index: u32,
        expected: u64,
        found: u64,
    },
    /// A data offset that is not a multiple of 64.
    UnalignedOffset { index: u32, offset: u64 },
    /// A payload starting before the end of the previous one (table order).
    Overlap { index: u32, previous: u32 },
    /// A payload ending past the end of the data section (truncated file or
    /// an out-of-range offset).
    DataOutOfRange { index: u32, end: u64, data_len: u64 },
    /// A non-zero byte after the data section (the last payload's end
    /// rounded up to 64): trailing bytes are accepted only as zero padding.
    /// `offset` is the byte's file offset.
    TrailingData { offset: u64 },
    /// The config failed `ModelConfig::validate` (sizes over the caps, or
    /// inconsistent).
    InvalidConfig(ConfigError),
    /// A Transflower config failed `TransflowerConfig::validate` (sizes
    /// over the caps, inconsistent, or a corrupt modality name).
    InvalidTransflowerConfig(crate::transflower::config::ConfigError),
    /// A tensor the schema requires is absent.
    MissingTensor { schema_index: u32 },
    /// A tensor the schema does not know (table `index`).
    UnknownTensor { index: u32 },
    /// A tensor whose shape differs from the schema's for this config.
    ShapeMismatch {
        index: u32,
        expected: Shape,
        found: Shape,
    },
    /// A quantization scale that is NaN or infinite.
    NonFiniteScale { index: u32, block: u64 },
    /// An `F32` / `F16` weight that is NaN or infinite: element `element`
    /// (row-major) of tensor `index`.
    NonFiniteWeight {
        index: u32,
        element: u64,
        kind: NonFiniteKind,
    },
    /// A schema name outgrew its buffer (impossible for a validated config).
    Schema(SchemaError),
    /// `DuoFile::tensor(name)`: no tensor with that name.
    NotFound,
}

impl fmt::Display for FormatError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use FormatError::*;
        match *self {
            TooShort { len } => write!(f, "buffer of {len} bytes is shorter than the 24-byte .duo prefix"),
            MisalignedBuffer { addr_mod_64 } => write!(
                f,
                "model buffer is not 64-byte aligned in memory (address % 64 = {addr_mod_64}); copy it to an aligned buffer"
            ),
            BadMagic { found } => {
                // Bytes in file order, as a hex dump shows them.
                let hex = |f: &mut fmt::Formatter<'_>, bytes: &[u8]| -> fmt::Result {
                    f.write_str("0x")?;
                    bytes.iter().try_for_each(|b| write!(f, "{b:02x}"))
                };
                f.write_str("not a .duo file: its first 8 bytes (the magic) are ")?;
                hex(f, &found)?;
                f.write_str(", a .duo file starts with ")?;
                hex(f, &super::MAGIC)
            }
            UnsupportedVersion { found, supported } => {
                write!(f, ".duo format version {found} is not supported (this decoder reads versions 1 to {supported})")
            }
            UnknownFamily { tag } => write!(
                f,
                "model family {tag} is not one this build reads (0 Duolando, 1 Bailando, 2 Transflower); a newer duolando may read it"
            ),
            UnknownFlags { flags } => write!(f, "unknown flag bits {flags:#010x} (versions 1 and 2 define none)"),
            HeaderTooLarge { header_len, max } => write!(f, "header length {header_len} exceeds the cap of {max} bytes"),
            HeaderPastEnd { header_end, file_len } => {
                write!(f, "header ends at byte {header_end} but the file has only {file_len} bytes")
            }
            MalformedHeader { field, offset } => write!(f, "malformed header: cannot decode the {field} at header byte {offset}"),
            TrailingHeaderBytes { count } => write!(f, "{count} unexpected bytes after the last tensor entry in the header"),
            NonZeroPadding { offset } => write!(f, "non-zero padding byte at file offset {offset}"),
            TooManyTensors { count, max } => write!(f, "{count} tensors exceeds the cap of {max}"),
            EmptyName { index } => write!(f, "tensor #{index}: empty name"),
            NameTooLong { index, len, max } => write!(f, "tensor #{index}: name of {len} bytes exceeds the cap of {max}"),
            UnsortedTable { index } => write!(f, "tensor #{index}: names are not in ascending byte order"),
            DuplicateTensor { index, previous } => write!(f, "tensor #{index}: duplicate of tensor #{previous}"),
            UnknownDtype { index, code } => write!(f, "tensor #{index}: unknown dtype code {code}"),
            BadRank { index, rank } => write!(f, "tensor #{index}: rank {rank} outside 1..={MAX_RANK}"),
            DimOutOfRange { index, axis, dim } => {
                write!(f, "tensor #{index}: dimension {axis} is {dim}, outside 1..={}", super::MAX_DIM)
            }
            SizeOverflow { index } => write!(f, "tensor #{index}: element count or byte size overflows"),
            ByteLenMismatch { index, expected, found } => {
                write!(f, "tensor #{index}: byte length {found}, expected {expected} for its dtype and shape")
            }
            UnalignedOffset { index, offset } => write!(f, "tensor #{index}: data offset {offset} is not a multiple of 64"),
            Overlap { index, previous } => write!(f, "tensor #{index}: data overlaps tensor #{previous} (or precedes it)"),
            DataOutOfRange { index, end, data_len } => write!(
                f,
                "tensor #{index}: data ends at {end} but the data section has only {data_len} bytes (truncated file?)"
            ),
            TrailingData { offset } => write!(
                f,
                "non-zero byte at file offset {offset} after the data section (trailing bytes are accepted only as zero padding)"
            ),
            InvalidConfig(e) => write!(f, "invalid model config: {e:?}"),
            InvalidTransflowerConfig(e) => write!(f, "invalid Transflower model config: {e:?}"),
            MissingTensor { schema_index } => write!(f, "schema tensor #{schema_index} is missing"),
            UnknownTensor { index } => write!(f, "tensor #{index} is not part of the model schema"),
            ShapeMismatch { index, expected, found } => {
                write!(f, "tensor #{index}: shape {found}, the config requires {expected}")
            }
            NonFiniteScale { index, block } => write!(f, "tensor #{index}: quantization scale of block {block} is NaN or infinite"),
            NonFiniteWeight { index, element, kind } => write!(f, "tensor #{index}: weight element {element} is {kind}"),
            Schema(e) => write!(f, "schema error: {e:?}"),
            NotFound => write!(f, "no tensor with that name"),
        }
    }
}
