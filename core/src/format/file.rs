//! [`DuoFile`]: a validated, zero-copy view of a whole `.duo` buffer.

use super::prefix::Prefix;
use super::table::{decode_entry, Cursor, TensorEntry};
use super::{align_up, schema_check, FormatError, HeaderField, MAX_TENSORS, PREFIX_LEN};
use crate::bailando::config::BailandoConfig;
use crate::duolando::config::ModelConfig;
use crate::family::{Family, FamilyConfig, FamilyConfigError};
use crate::kernels::simd::{PACK_BLOCK_NIBBLES, PACK_BLOCK_SCALES, PACK_BLOCK_VALUES};
use crate::tensor::{block_row, DType, TensorRef};
use crate::transflower::config::TransflowerConfig;

/// A `.duo` buffer that passed every rule of docs/FORMAT.md.
///
/// Borrowed from the caller's bytes (mmap, `include_bytes!`, an engine
/// asset); `Copy`, no allocation. Thread rule: `Send + Sync` like the slice.
#[derive(Clone, Copy, Debug)]
pub struct DuoFile<'a> {
    prefix: Prefix,
    config: FamilyConfig,
    /// Header bytes holding the tensor entries (after the config and count).
    table: &'a [u8],
    count: u32,
    /// The data section: from `prefix.data_start` to the end of the buffer.
    data: &'a [u8],
    /// Skip index for [`DuoFile::find`]: `marks[m]` is the table byte offset
    /// of entry `m * stride` (entries are variable-length, so this is what
    /// makes a lookup O(log SKIP + stride) instead of O(count)).
    marks: [u32; SKIP],
    stride: u32,
}

/// Entries of the skip index (512 bytes; `MAX_TENSORS / SKIP` = 64 entries
/// at most between marks).
const SKIP: usize = 64;

impl<'a> DuoFile<'a> {
    /// Validates `bytes` completely (prefix, header, table, offsets, config,
    /// schema, then every f32 / f16 weight finite: one pass over the data,
    /// docs/FORMAT.md §5 rule 15). Never panics and never allocates,
    /// whatever `bytes` holds. `bytes` must start on a 64-byte boundary in
    /// memory.
    pub fn parse(bytes: &'a [u8]) -> Result<DuoFile<'a>, FormatError> {
        let file = Self::parse_without_weight_scan(bytes)?;
        file.check_weights()?;
        Ok(file)
    }

    /// Every rule of [`DuoFile::parse`] but the weight scan (rule 15): the
    /// header and table only, milliseconds for the full model. For bytes
    /// that passed `parse` and have not changed since (a `ModelFile`
    /// re-creating its view); on other bytes a NaN or infinite weight goes
    /// unnoticed (memory safety does not depend on it: only the numbers).
    pub fn parse_without_weight_scan(bytes: &'a [u8]) -> Result<DuoFile<'a>, FormatError> {
        let prefix = Prefix::parse(bytes)?;
        // Prefix::parse proved data_start <= bytes.len(), so these fit usize.
        let header_end = PREFIX_LEN + prefix.header_len as usize;
        let data_start = prefix.data_start as usize;
        let header = bytes.get(PREFIX_LEN..header_end).unwrap_or(&[]);
        let padding = bytes.get(header_end..data_start).unwrap_or(&[]);
        if let Some(i) = padding.iter().position(|&b| b != 0) {
            return Err(FormatError::NonZeroPadding {
                offset: (header_end + i) as u64,
            });
        }
        let data = bytes.get(data_start..).unwrap_or(&[]);
        let data_len = data.len() as u64;

        let mut cur = Cursor::new(header);
        let config = if prefix.version == super::VERSION_DUOLANDO {
            FamilyConfig::Duolando(cur.take::<ModelConfig>(HeaderField::Config)?)
        } else {
            let tag: u32 = cur.take(HeaderField::Family)?;
            match Family::from_tag(tag) {
                Some(Family::Duolando) => {
                    FamilyConfig::Duolando(cur.take::<ModelConfig>(HeaderField::Config)?)
                }
                Some(Family::Bailando) => {
                    FamilyConfig::Bailando(cur.take::<BailandoConfig>(HeaderField::Config)?)
                }
                Some(Family::Transflower) => {
                    FamilyConfig::Transflower(cur.take::<TransflowerConfig>(HeaderField::Config)?)
                }
                None => return Err(FormatError::UnknownFamily { tag }),
            }
        };
        config.validate().map_err(|e| match e {
            FamilyConfigError::Config(e) => FormatError::InvalidConfig(e),
            FamilyConfigError::Transflower(e) => FormatError::InvalidTransflowerConfig(e),
        })?;
        let count: u64 = cur.take(HeaderField::TensorCount)?;
        if count > MAX_TENSORS as u64 {
            return Err(FormatError::TooManyTensors {
                count,
                max: MAX_TENSORS,
            });
        }
        let count = count as u32;
        let table = cur.rest;
        let stride = count.div_ceil(SKIP as u32).max(1);
        let mut marks = [0u32; SKIP];

        let mut prev: Option<TensorEntry<'a>> = None;
        let mut prev_end: u64 = 0;
        for index in 0..count {
            if index % stride == 0 {
                // index < count <= stride * SKIP, so the mark exists; the
                // table is at most MAX_HEADER_LEN bytes, so the offset fits.
                marks[(index / stride) as usize] = (table.len() - cur.rest.len()) as u32;
            }
            let e = decode_entry(&mut cur, index)?;
            if let Some(p) = prev {
                match e.name.as_bytes().cmp(p.name.as_bytes()) {
                    core::cmp::Ordering::Equal => {
                        return Err(FormatError::DuplicateTensor {
                            index,
                            previous: index - 1,
                        })
                    }
                    core::cmp::Ordering::Less => return Err(FormatError::UnsortedTable { index }),
                    core::cmp::Ordering::Greater => {}
                }
            }
            if e.offset % super::ALIGN as u64 != 0 {
                return Err(FormatError::UnalignedOffset {
                    index,
                    offset: e.offset,
                });
            }
            if index > 0 && e.offset < prev_end {
                return Err(FormatError::Overlap {
                    index,
                    previous: index - 1,
                });
            }
            let end = e
                .offset
                .checked_add(e.nbytes)
                .ok_or(FormatError::SizeOverflow { index })?;
            if end > data_len {
                return Err(FormatError::DataOutOfRange {
                    index,
                    end,
                    data_len,
                });
            }
            match e.dtype {
                DType::Q8Block32 | DType::Q4Block32 => {
                    check_block_scales(payload(data, &e), e.dtype.block_bytes(), index)?
                }
                DType::Q8Block32x8 => check_group_scales(
                    payload(data, &e),
                    block_row(e.dims()) / 32,
                    PACK_BLOCK_VALUES,
                    index,
                )?,
                DType::Q4Block32x8 => check_group_scales(
                    payload(data, &e),
                    block_row(e.dims()) / 32,
                    PACK_BLOCK_NIBBLES,
                    index,
                )?,
                DType::F32 | DType::F16 => {}
            }
            prev_end = end;
            prev = Some(e);
        }
        if !cur.rest.is_empty() {
            return Err(FormatError::TrailingHeaderBytes {
                count: cur.rest.len(),
            });
        }
        // The data section ends at the last payload padded to 64 bytes; zero
        // bytes may follow (asset pipelines pad files), nothing else.
        let expected_len = align_up(prev_end).unwrap_or(u64::MAX);
        if data_len > expected_len {
            // expected_len < data_len, a usize.
            let tail = data.get(expected_len as usize..).unwrap_or(&[]);
            if let Some(i) = tail.iter().position(|&b| b != 0) {
                return Err(FormatError::TrailingData {
                    offset: prefix.data_start + expected_len + i as u64,
                });
            }
        }
        if data_len < expected_len {
            return Err(FormatError::DataOutOfRange {
                index: count.saturating_sub(1),
                end: expected_len,
                data_len,
            });
        }

        let file = DuoFile {
            prefix,
            config,
            table,
            count,
            data,
            marks,
            stride,
        };
        schema_check::check(&file)?;
        Ok(file)
    }

    /// The model's family and configuration (already validated).
    pub fn config(&self) -> &FamilyConfig {
        &self.config
    }

    /// The decoded fixed prefix and section boundaries.
    pub fn prefix(&self) -> Prefix {
        self.prefix
    }

    /// Number of tensors in the table.
    pub fn len(&self) -> usize {
        self.count as usize
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Every table entry, in table (= name, = data) order.
    pub fn tensors(&self) -> Tensors<'a> {
        Tensors {
            cur: Cursor::new(self.table),
            index: 0,
            count: self.count,
        }
    }

    /// The entry and payload of the tensor called `name` (a binary search
    /// over the skip index, then a scan of at most `stride` entries).
    pub fn tensor(&self, name: &str) -> Result<TensorRef<'a>, FormatError> {
        self.entry(name).map(|e| self.view(&e))
    }

    /// The table entry called `name`.
    pub fn entry(&self, name: &str) -> Result<TensorEntry<'a>, FormatError> {
        self.find(name).map(|(_, e)| e).ok_or(FormatError::NotFound)
    }

    /// The table index and entry called `name`.
    pub fn find(&self, name: &str) -> Option<(u32, TensorEntry<'a>)> {
        if self.count == 0 {
            return None;
        }
        // The last mark whose entry name is <= `name` (names are sorted).
        let n_marks = self.count.div_ceil(self.stride) as usize;
        let (mut lo, mut hi) = (0usize, n_marks);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            match self.from_mark(mid).next() {
                Some(e) if e.name <= name => lo = mid,
                _ => hi = mid,
            }
        }
        let first = lo as u32 * self.stride;
        for (i, e) in self.from_mark(lo).take(self.stride as usize).enumerate() {
            match e.name.cmp(name) {
                core::cmp::Ordering::Equal => return Some((first + i as u32, e)),
                core::cmp::Ordering::Greater => return None,
                core::cmp::Ordering::Less => {}
            }
        }
        None
    }

    /// The entries from mark `m` on.
    fn from_mark(&self, m: usize) -> Tensors<'a> {
        let off = self.marks[m] as usize;
        Tensors {
            cur: Cursor::new(self.table.get(off..).unwrap_or(&[])),
            index: m as u32 * self.stride,
            count: self.count,
        }
    }

    /// The payload view of a validated entry of this file.
    pub fn view(&self, e: &TensorEntry<'a>) -> TensorRef<'a> {
        TensorRef {
            dtype: e.dtype,
            rank: e.rank,
            shape: e.shape,
            data: payload(self.data, e),
        }
    }

    /// Rule 15: every `F32` / `F16` element finite (the first one that is
    /// not, by table index and row-major element index). One vectorised
    /// pass over those payloads (docs/FORMAT.md §4 "Non-finite values").
    pub fn check_weights(&self) -> Result<(), FormatError> {
        for (index, e) in self.tensors().enumerate() {
            if let Some((element, kind)) =
                super::weights::first_non_finite(e.dtype, payload(self.data, &e))
            {
                return Err(FormatError::NonFiniteWeight {
                    index: index as u32,
                    element,
                    kind,
                });
            }
        }
        Ok(())
    }

    /// The first f32/f16 weight that is NaN or infinite, as (table index,
    /// element index): [`DuoFile::check_weights`] as an option (always
    /// None for a file from `parse`, which runs it).
    pub fn first_non_finite(&self) -> Option<(u32, u64)> {
        match self.check_weights() {
            Err(FormatError::NonFiniteWeight { index, element, .. }) => Some((index, element)),
            _ => None,
        }
    }
}

/// The payload of an entry whose range was validated against `data`
/// (an empty slice if it somehow was not: never a panic).
fn payload<'a>(data: &'a [u8], e: &TensorEntry<'_>) -> &'a [u8] {
    let start = usize::try_from(e.offset).ok();
    let end = start.and_then(|s| {
        usize::try_from(e.nbytes)
            .ok()
            .and_then(|n| s.checked_add(n))
    });
    match (start, end) {
        (Some(s), Some(t)) => data.get(s..t).unwrap_or(&[]),
        _ => &[],
    }
}

/// Blocked payloads (Q8Block32: 34-byte blocks, Q4Block32: 18-byte ones)
/// start each block with an f16 scale, which must be finite.
fn check_block_scales(bytes: &[u8], block_bytes: usize, index: u32) -> Result<(), FormatError> {
    for (block, chunk) in bytes.chunks_exact(block_bytes.max(2)).enumerate() {
        let scale = half::f16::from_le_bytes([chunk[0], chunk[1]]);
        if !scale.is_finite() {
            return Err(FormatError::NonFiniteScale {
                index,
                block: block as u64,
            });
        }
    }
    Ok(())
}

/// `Q8Block32x8` / `Q4Block32x8` payloads: row groups of `nb` blocks, each
/// `nb * per_block` value bytes (256 / 128) then `nb * 8` f16 scales, which
/// must be finite (the padding rows' too). Blocks are numbered group-major,
/// then block, then row (`(t * nb + b) * 8 + n`).
fn check_group_scales(
    bytes: &[u8],
    nb: usize,
    per_block: usize,
    index: u32,
) -> Result<(), FormatError> {
    let (values, group) = (nb * per_block, nb * (per_block + PACK_BLOCK_SCALES));
    if group == 0 {
        return Ok(());
    }
    for (t, g) in bytes.chunks_exact(group).enumerate() {
        for (k, c) in g[values..].chunks_exact(2).enumerate() {
            if !half::f16::from_le_bytes([c[0], c[1]]).is_finite() {
                return Err(FormatError::NonFiniteScale {
                    index,
                    block: (t * nb * 8 + k) as u64,
                });
            }
        }
    }
    Ok(())
}

/// Iterator over the table entries of a [`DuoFile`].
pub struct Tensors<'a> {
    cur: Cursor<'a>,
    index: u32,
    count: u32,
}

impl<'a> Iterator for Tensors<'a> {
    type Item = TensorEntry<'a>;
    fn next(&mut self) -> Option<TensorEntry<'a>> {
        if self.index >= self.count {
            return None;
        }
        let e = decode_entry(&mut self.cur, self.index).ok()?;
        self.index += 1;
        Some(e)
    }
    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = (self.count - self.index) as usize;
        (n, Some(n))
    }
}
