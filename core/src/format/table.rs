//! The tensor table inside the postcard header, decoded one entry at a
//! time from the borrowed header bytes (no allocation; names are `&'a str`).
//!
//! Entry encoding (postcard, in order): name (`varint len` + UTF-8 bytes),
//! dtype code (`u8`), shape (`varint rank` + `rank` x varint `u32`),
//! offset (varint `u64`, relative to the data section), byte length
//! (varint `u64`).

use super::{FormatError, HeaderField, Shape, MAX_DIM, MAX_NAME_LEN};
use crate::tensor::{DType, MAX_RANK};

/// One validated table entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TensorEntry<'a> {
    pub name: &'a str,
    pub dtype: DType,
    pub rank: u8,
    /// Dimensions, row-major (PyTorch order); entries past `rank` are 1.
    pub shape: [u32; MAX_RANK],
    /// Offset of the payload from the start of the data section.
    pub offset: u64,
    /// Payload bytes (`dtype.bytes_for(numel, block_row(shape))`).
    pub nbytes: u64,
}

impl TensorEntry<'_> {
    pub fn dims(&self) -> &[u32] {
        &self.shape[..(self.rank as usize).min(MAX_RANK)]
    }
    pub fn shape(&self) -> Shape {
        Shape {
            rank: self.rank,
            dims: self.shape,
        }
    }
}

/// A cursor over the header bytes that remembers how far it has read.
pub(crate) struct Cursor<'a> {
    pub(crate) rest: &'a [u8],
    pub(crate) header_len: usize,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(header: &'a [u8]) -> Self {
        Cursor {
            rest: header,
            header_len: header.len(),
        }
    }
    pub(crate) fn offset(&self) -> usize {
        self.header_len - self.rest.len()
    }
    /// Decodes one postcard value; on failure names the field and offset.
    pub(crate) fn take<T: serde::Deserialize<'a>>(
        &mut self,
        field: HeaderField,
    ) -> Result<T, FormatError> {
        let offset = self.offset();
        match postcard::take_from_bytes::<T>(self.rest) {
            Ok((v, rest)) => {
                self.rest = rest;
                Ok(v)
            }
            Err(_) => Err(FormatError::MalformedHeader { field, offset }),
        }
    }
}

/// Decodes and checks entry `index` in isolation: name length, dtype code,
/// rank, dims, element count and byte length. Ordering, offsets and the
/// schema are checked by the caller, which sees the neighbours.
pub(crate) fn decode_entry<'a>(
    cur: &mut Cursor<'a>,
    index: u32,
) -> Result<TensorEntry<'a>, FormatError> {
    let name: &'a str = cur.take(HeaderField::Name)?;
    if name.is_empty() {
        return Err(FormatError::EmptyName { index });
    }
    if name.len() > MAX_NAME_LEN {
        return Err(FormatError::NameTooLong {
            index,
            len: name.len(),
            max: MAX_NAME_LEN,
        });
    }
    let code: u8 = cur.take(HeaderField::Dtype)?;
    let dtype = DType::from_code(code).ok_or(FormatError::UnknownDtype { index, code })?;
    let rank: u32 = cur.take(HeaderField::Rank)?;
    if rank == 0 || rank as usize > MAX_RANK {
        return Err(FormatError::BadRank { index, rank });
    }
    let mut shape = [1u32; MAX_RANK];
    let mut numel: u64 = 1;
    for axis in 0..rank {
        let dim: u32 = cur.take(HeaderField::Dim)?;
        if dim == 0 || dim > MAX_DIM {
            return Err(FormatError::DimOutOfRange { index, axis, dim });
        }
        shape[axis as usize] = dim;
        numel = numel
            .checked_mul(dim as u64)
            .ok_or(FormatError::SizeOverflow { index })?;
    }
    let offset: u64 = cur.take(HeaderField::Offset)?;
    let nbytes: u64 = cur.take(HeaderField::ByteLen)?;
    let numel = usize::try_from(numel).map_err(|_| FormatError::SizeOverflow { index })?;
    let row = crate::tensor::block_row(&shape[..rank as usize]);
    let expected = dtype
        .bytes_for(numel, row)
        .ok_or(FormatError::SizeOverflow { index })? as u64;
    if expected != nbytes {
        return Err(FormatError::ByteLenMismatch {
            index,
            expected,
            found: nbytes,
        });
    }
    Ok(TensorEntry {
        name,
        dtype,
        rank: rank as u8,
        shape,
        offset,
        nbytes,
    })
}

/// The name of entry `index` of a possibly invalid `.duo` buffer, decoded
/// leniently (for error messages: `DuoFile::parse` reports indices, the
/// std side turns them into names). None if it cannot be decoded.
pub fn entry_name(bytes: &[u8], index: u32) -> Option<&str> {
    let mut len = [0u8; 8];
    len.copy_from_slice(bytes.get(16..24)?);
    let header_len = usize::try_from(u64::from_le_bytes(len)).ok()?;
    let header = bytes.get(super::PREFIX_LEN..super::PREFIX_LEN.checked_add(header_len)?)?;
    let mut cur = Cursor::new(header);
    cur.take::<crate::duolando::config::ModelConfig>(HeaderField::Config)
        .ok()?;
    let count: u64 = cur.take(HeaderField::TensorCount).ok()?;
    if index as u64 >= count {
        return None;
    }
    for i in 0..=index {
        let name: &str = cur.take(HeaderField::Name).ok()?;
        if i == index {
            return Some(name);
        }
        cur.take::<u8>(HeaderField::Dtype).ok()?;
        let rank: u32 = cur.take(HeaderField::Rank).ok()?;
        if rank as usize > MAX_RANK {
            return None;
        }
        for _ in 0..rank {
            cur.take::<u32>(HeaderField::Dim).ok()?;
        }
        cur.take::<u64>(HeaderField::Offset).ok()?;
        cur.take::<u64>(HeaderField::ByteLen).ok()?;
    }
    None
}
