//! The `.duo` model file, versions 1 and 2 (byte layout and every rule: docs/FORMAT.md).
//!
//! ```text
//! offset 0   magic        8 bytes  89 44 55 4F 0D 0A 1A 0A  ("\x89DUO\r\n\x1a\n")
//!        8   version      u32 LE   1 (Duolando) or 2 (any family)
//!       12   flags        u32 LE   0 (no flag defined in v1; any set bit is rejected)
//!       16   header_len   u64 LE   bytes of the postcard header that follows
//!       24   header       postcard: v1 ModelConfig / v2 FamilyConfig, then the tensor table
//!            padding      zero bytes up to the next multiple of 64
//!  data_start data        tensor payloads, each 64-byte aligned, in table order
//!            padding      zero bytes up to the next multiple of 64, then any
//!                         number of zero bytes (asset-pipeline padding)
//! ```
//!
//! [`DuoFile::parse`] validates everything up front, without allocating and
//! without panicking on any input; afterwards every [`TensorRef`] it hands
//! out is in range, correctly sized, aligned, and shaped as the schema
//! (`crate::duolando::schema`) requires for the file's config, and every float it
//! holds (f32 / f16 weights, quantisation scales) is finite.
//!
//! [`TensorRef`]: crate::tensor::TensorRef

mod error;
mod file;
mod prefix;
mod schema_check;
mod table;
mod weights;

pub use error::{FormatError, HeaderField, NonFiniteKind, Shape};
pub use file::{DuoFile, Tensors};
pub use prefix::Prefix;
pub use schema_check::schema_tensor;
pub use table::{entry_name, TensorEntry};

/// First 8 bytes of every `.duo` file. The high first byte and the CR LF /
/// ^Z / LF tail catch 7-bit and newline-translating transfers (as PNG does).
pub const MAGIC: [u8; 8] = *b"\x89DUO\r\n\x1a\n";
/// The newest format version this decoder reads: version 2 (any family;
/// the header starts with the family tag). Version 1 files (the header
/// starts with a Duolando config) are read as Duolando models, and the
/// writer still writes Duolando models as version 1 (docs/FORMAT.md §1).
pub const VERSION: u32 = 2;
/// The version of Duolando-only headers (before families).
pub const VERSION_DUOLANDO: u32 = 1;
/// Bytes of the fixed prefix: magic, version, flags, header length.
pub const PREFIX_LEN: usize = 24;
/// Alignment of the data section, of every tensor payload, and of the model
/// buffer in memory.
pub const ALIGN: usize = 64;

/// Largest accepted postcard header (4 MiB; the full model needs ~60 KiB).
pub const MAX_HEADER_LEN: u64 = 1 << 22;
/// Most tensors in one file (the full model has ~900).
pub const MAX_TENSORS: u32 = 4096;
/// Longest tensor name in bytes.
pub const MAX_NAME_LEN: usize = 160;
/// Largest single dimension (2^24). Products of dims are checked separately.
pub const MAX_DIM: u32 = 1 << 24;

/// `n` rounded up to a multiple of [`ALIGN`]; None on overflow.
pub const fn align_up(n: u64) -> Option<u64> {
    match n.checked_add(ALIGN as u64 - 1) {
        Some(v) => Some(v & !(ALIGN as u64 - 1)),
        None => None,
    }
}
