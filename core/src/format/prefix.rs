//! The fixed 24-byte little-endian prefix and the layout it implies.

use super::{
    align_up, FormatError, ALIGN, MAGIC, MAX_HEADER_LEN, PREFIX_LEN, VERSION, VERSION_DUOLANDO,
};

/// The decoded prefix plus the derived section boundaries (all checked).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Prefix {
    pub version: u32,
    pub flags: u32,
    /// Bytes of the postcard header, starting at byte 24.
    pub header_len: u64,
    /// First byte of the data section: `align_up(24 + header_len, 64)`.
    pub data_start: u64,
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    let mut w = [0u8; 4];
    for (i, dst) in w.iter_mut().enumerate() {
        *dst = b.get(at + i).copied().unwrap_or(0);
    }
    u32::from_le_bytes(w)
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut w = [0u8; 8];
    for (i, dst) in w.iter_mut().enumerate() {
        *dst = b.get(at + i).copied().unwrap_or(0);
    }
    u64::from_le_bytes(w)
}

impl Prefix {
    /// Checks buffer alignment, magic, version, flags and the header length
    /// against the cap and the buffer length (header and padding included).
    pub fn parse(bytes: &[u8]) -> Result<Prefix, FormatError> {
        let addr_mod_64 = bytes.as_ptr() as usize % ALIGN;
        if addr_mod_64 != 0 {
            return Err(FormatError::MisalignedBuffer { addr_mod_64 });
        }
        if bytes.len() < PREFIX_LEN {
            return Err(FormatError::TooShort { len: bytes.len() });
        }
        let mut found = [0u8; 8];
        found.copy_from_slice(&bytes[..8]);
        if found != MAGIC {
            return Err(FormatError::BadMagic { found });
        }
        let version = u32_at(bytes, 8);
        if !(VERSION_DUOLANDO..=VERSION).contains(&version) {
            return Err(FormatError::UnsupportedVersion {
                found: version,
                supported: VERSION,
            });
        }
        let flags = u32_at(bytes, 12);
        if flags != 0 {
            return Err(FormatError::UnknownFlags { flags });
        }
        let header_len = u64_at(bytes, 16);
        if header_len > MAX_HEADER_LEN {
            return Err(FormatError::HeaderTooLarge {
                header_len,
                max: MAX_HEADER_LEN,
            });
        }
        // header_len <= 2^22, so neither sum can overflow; checked anyway.
        let header_end = (PREFIX_LEN as u64).checked_add(header_len);
        let data_start = header_end.and_then(align_up);
        let file_len = bytes.len() as u64;
        match (header_end, data_start) {
            (Some(_), Some(ds)) if ds <= file_len => Ok(Prefix {
                version,
                flags,
                header_len,
                data_start: ds,
            }),
            _ => Err(FormatError::HeaderPastEnd {
                header_end: header_end.unwrap_or(u64::MAX),
                file_len,
            }),
        }
    }
}
