//! Opening `.duo` files: a 64-byte aligned buffer (mmap, or an aligned copy)
//! plus a validated [`DuoFile`] view, with errors that name the file, the
//! tensor and the expected vs found values. Opening a model also selects the
//! fastest kernels this CPU supports, once per process
//! ([`crate::simd::ensure_init`]).

use std::fmt;
use std::path::{Path, PathBuf};

use duolando_core::format::{DuoFile, FormatError};

/// 64 bytes with 64-byte alignment: the unit of [`AlignedBytes`].
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(64))]
struct Line([u8; 64]);

/// An owned byte buffer whose first byte is 64-byte aligned in memory (what
/// `DuoFile::parse` requires; a plain `Vec<u8>` gives no such promise).
#[derive(Clone)]
pub struct AlignedBytes {
    lines: Vec<Line>,
    len: usize,
}

impl AlignedBytes {
    /// An aligned copy of `bytes`.
    pub fn copy_from(bytes: &[u8]) -> AlignedBytes {
        let mut lines = vec![Line([0; 64]); bytes.len().div_ceil(64)];
        bytemuck::cast_slice_mut::<Line, u8>(&mut lines)[..bytes.len()].copy_from_slice(bytes);
        AlignedBytes {
            lines,
            len: bytes.len(),
        }
    }
    pub fn as_bytes(&self) -> &[u8] {
        &bytemuck::cast_slice::<Line, u8>(&self.lines)[..self.len]
    }
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

enum Storage {
    Mapped(memmap2::Mmap),
    Owned(AlignedBytes),
}

/// A validated `.duo` model held in memory: mapped read-only when possible,
/// otherwise an aligned copy. Thread rule: `Send + Sync`; share it by
/// reference between sessions.
pub struct ModelFile {
    storage: Storage,
    /// Where the bytes came from (a path, or "<memory>"), for messages.
    origin: String,
}

impl ModelFile {
    /// Maps `path` read-only and validates it. Page-aligned maps satisfy the
    /// 64-byte rule; should a platform ever map at a lesser alignment, the
    /// bytes are copied to an aligned buffer instead.
    ///
    /// The file must not be modified while mapped (the usual mmap contract).
    pub fn open(path: impl AsRef<Path>) -> Result<ModelFile, ModelFileError> {
        let path = path.as_ref();
        let origin = path.display().to_string();
        let io = |source| ModelFileError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::open(path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        let storage = if len == 0 {
            // Mapping an empty file fails on some platforms; nothing to map.
            Storage::Owned(AlignedBytes::copy_from(&[]))
        } else {
            // SAFETY: read-only map; the file is not modified by us, and the
            // documented contract forbids others from modifying it meanwhile.
            #[allow(unsafe_code)]
            let map = unsafe { memmap2::Mmap::map(&file) }.map_err(io)?;
            if (map.as_ptr() as usize) & 63 == 0 {
                Storage::Mapped(map)
            } else {
                Storage::Owned(AlignedBytes::copy_from(&map))
            }
        };
        let mf = ModelFile { storage, origin };
        mf.validate()?;
        crate::simd::ensure_init();
        Ok(mf)
    }

    /// Validates an in-memory `.duo` (copied to an aligned buffer).
    pub fn from_bytes(bytes: Vec<u8>) -> Result<ModelFile, ModelFileError> {
        Self::from_aligned(AlignedBytes::copy_from(&bytes), "<memory>")
    }

    /// Validates an already aligned buffer; `origin` names it in messages.
    pub fn from_aligned(bytes: AlignedBytes, origin: &str) -> Result<ModelFile, ModelFileError> {
        let mf = ModelFile {
            storage: Storage::Owned(bytes),
            origin: origin.to_string(),
        };
        mf.validate()?;
        crate::simd::ensure_init();
        Ok(mf)
    }

    /// The whole file, 64-byte aligned in memory.
    pub fn bytes(&self) -> &[u8] {
        match &self.storage {
            Storage::Mapped(m) => m,
            Storage::Owned(a) => a.as_bytes(),
        }
    }

    /// True when the bytes are memory-mapped (not copied).
    pub fn is_mapped(&self) -> bool {
        matches!(self.storage, Storage::Mapped(_))
    }

    /// Every rule of `DuoFile::parse`, the weight scan included (once, when
    /// the `ModelFile` is made).
    fn validate(&self) -> Result<(), ModelFileError> {
        let bytes = self.bytes();
        DuoFile::parse(bytes)
            .map(|_| ())
            .map_err(|error| self.format_error(bytes, error))
    }

    /// The validated view. Re-runs `DuoFile::parse_without_weight_scan`
    /// (cheap: header and table only, milliseconds for the full model):
    /// the full `parse`, weights included, succeeded when the `ModelFile`
    /// was made, and the bytes are immutable since.
    pub fn duo(&self) -> Result<DuoFile<'_>, ModelFileError> {
        let bytes = self.bytes();
        DuoFile::parse_without_weight_scan(bytes).map_err(|error| self.format_error(bytes, error))
    }

    fn format_error(&self, bytes: &[u8], error: FormatError) -> ModelFileError {
        ModelFileError::Format {
            origin: self.origin.clone(),
            detail: explain(bytes, &error),
            error,
        }
    }
}

/// Why a model file could not be used.
#[derive(Debug)]
pub enum ModelFileError {
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// `detail` spells out `error` with tensor names and shapes resolved.
    Format {
        origin: String,
        error: FormatError,
        detail: String,
    },
}

impl fmt::Display for ModelFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ModelFileError::Io { path, source } => write!(f, "{}: {source}", path.display()),
            ModelFileError::Format { origin, detail, .. } => {
                write!(f, "{origin}: invalid .duo model: {detail}")
            }
        }
    }
}

impl std::error::Error for ModelFileError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ModelFileError::Io { source, .. } => Some(source),
            ModelFileError::Format { .. } => None,
        }
    }
}

/// Spells out a [`FormatError`] with tensor names and shapes resolved from
/// the (possibly invalid) bytes.
pub fn explain(bytes: &[u8], error: &FormatError) -> String {
    use duolando_core::format::{entry_name, schema_tensor};
    let tensor = |index: u32| match entry_name(bytes, index) {
        Some(name) => format!("tensor #{index} `{name}`"),
        None => format!("tensor #{index}"),
    };
    match *error {
        FormatError::MissingTensor { schema_index } => {
            let cfg = header_config(bytes);
            match cfg.as_ref().and_then(|c| schema_tensor(c, schema_index)) {
                Some(spec) => format!(
                    "missing tensor `{}` (shape {:?})",
                    spec.name.as_str(),
                    spec.dims()
                ),
                None => error.to_string(),
            }
        }
        FormatError::ShapeMismatch {
            index,
            expected,
            found,
        } => {
            format!(
                "{}: shape {found}, the config requires {expected}",
                tensor(index)
            )
        }
        FormatError::EmptyName { index }
        | FormatError::NameTooLong { index, .. }
        | FormatError::UnsortedTable { index }
        | FormatError::DuplicateTensor { index, .. }
        | FormatError::UnknownDtype { index, .. }
        | FormatError::BadRank { index, .. }
        | FormatError::DimOutOfRange { index, .. }
        | FormatError::SizeOverflow { index }
        | FormatError::ByteLenMismatch { index, .. }
        | FormatError::UnalignedOffset { index, .. }
        | FormatError::Overlap { index, .. }
        | FormatError::DataOutOfRange { index, .. }
        | FormatError::UnknownTensor { index }
        | FormatError::NonFiniteScale { index, .. }
        | FormatError::NonFiniteWeight { index, .. } => {
            // The core message starts with "tensor #i"; name it.
            let msg = error.to_string();
            let head = format!("tensor #{index}");
            match msg.strip_prefix(&head) {
                Some(rest) => format!("{}{rest}", tensor(index)),
                None => format!("{msg} ({})", tensor(index)),
            }
        }
        _ => error.to_string(),
    }
}

/// The config of a `.duo` header, if it decodes (for messages).
fn header_config(bytes: &[u8]) -> Option<duolando_core::family::FamilyConfig> {
    use duolando_core::family::FamilyConfig;
    let version = u32::from_le_bytes(bytes.get(8..12)?.try_into().ok()?);
    let len = u64::from_le_bytes(bytes.get(16..24)?.try_into().ok()?);
    let header = bytes.get(24..24usize.checked_add(usize::try_from(len).ok()?)?)?;
    if version == duolando_core::format::VERSION_DUOLANDO {
        postcard::take_from_bytes(header)
            .ok()
            .map(|(c, _)| FamilyConfig::Duolando(c))
    } else {
        postcard::take_from_bytes(header).ok().map(|(c, _)| c)
    }
}
