//! Byte-level mutations aimed at the parts of a file (prefix, header, data),
//! so a fuzzer or a property test spends its effort where the decoder looks.

use arbitrary::Arbitrary;

/// Where a mutation lands, given the file's [`Regions`].
#[derive(Arbitrary, Clone, Copy, Debug)]
pub enum Region {
    Prefix,
    Header,
    Data,
    Anywhere,
}

/// A position: a region and an offset folded into it.
#[derive(Arbitrary, Clone, Copy, Debug)]
pub struct Pos {
    pub region: Region,
    pub offset: u32,
}

/// Byte ranges of a file: `[0, prefix)` the fixed prefix, `[prefix,
/// header_end)` the header, `[header_end, len)` the data.
#[derive(Clone, Copy, Debug)]
pub struct Regions {
    pub prefix: usize,
    pub header_end: usize,
}

impl Pos {
    /// The byte index this position names in a file of `len` bytes (None
    /// for an empty file or region).
    pub fn resolve(self, r: Regions, len: usize) -> Option<usize> {
        let (lo, hi) = match self.region {
            Region::Prefix => (0, r.prefix.min(len)),
            Region::Header => (r.prefix.min(len), r.header_end.min(len)),
            Region::Data => (r.header_end.min(len), len),
            Region::Anywhere => (0, len),
        };
        let (lo, hi) = if hi > lo { (lo, hi) } else { (0, len) };
        (hi > lo).then(|| lo + self.offset as usize % (hi - lo))
    }
}

/// Integers that sit on the edges decoders get wrong.
pub const INTERESTING: [u64; 20] = [
    0,
    1,
    2,
    3,
    4,
    63,
    64,
    65,
    255,
    256,
    4096,
    (1 << 22) + 1,
    (1 << 24),
    (1 << 24) + 1,
    0x7fff_ffff,
    0x8000_0000,
    u32::MAX as u64,
    1 << 32,
    i64::MAX as u64,
    u64::MAX,
];

/// An integer: one of [`INTERESTING`], nudged, or raw.
#[derive(Arbitrary, Clone, Copy, Debug)]
pub enum Int {
    Edge(u8),
    EdgePlus(u8, i8),
    Raw(u64),
}

impl Int {
    pub fn value(self) -> u64 {
        match self {
            Int::Edge(i) => INTERESTING[i as usize % INTERESTING.len()],
            Int::EdgePlus(i, d) => {
                INTERESTING[i as usize % INTERESTING.len()].wrapping_add(d as i64 as u64)
            }
            Int::Raw(v) => v,
        }
    }
}

/// One byte-level edit.
#[derive(Arbitrary, Clone, Debug)]
pub enum ByteMutation {
    Flip {
        at: Pos,
        bit: u8,
    },
    Set {
        at: Pos,
        value: u8,
    },
    /// Little-endian u32 / u64 written over the bytes at `at` (clipped at the end).
    U32 {
        at: Pos,
        value: Int,
    },
    U64 {
        at: Pos,
        value: Int,
    },
    /// A LEB128 varint (postcard's integer encoding) replacing the varint at `at`.
    Varint {
        at: Pos,
        value: Int,
    },
    Truncate {
        at: Pos,
    },
    Insert {
        at: Pos,
        bytes: Vec<u8>,
    },
    Remove {
        at: Pos,
        len: u16,
    },
    Copy {
        from: Pos,
        to: Pos,
        len: u16,
    },
}

/// LEB128 encoding of `v` (what postcard writes for integers).
pub fn varint(mut v: u64, out: &mut Vec<u8>) {
    loop {
        let b = (v & 0x7f) as u8;
        v >>= 7;
        if v == 0 {
            out.push(b);
            return;
        }
        out.push(b | 0x80);
    }
}

/// Length of the varint starting at `buf[0]` (at most 10 bytes; the rest of
/// `buf` if it never ends).
pub fn varint_len(buf: &[u8]) -> usize {
    buf.iter()
        .take(10)
        .position(|b| b & 0x80 == 0)
        .map_or(buf.len().min(10), |i| i + 1)
}

fn write_le(bytes: &mut [u8], at: usize, v: &[u8]) {
    let n = v.len().min(bytes.len() - at);
    bytes[at..at + n].copy_from_slice(&v[..n]);
}

/// Caps on what one mutation may insert (keeps inputs small).
const MAX_INSERT: usize = 256;

impl ByteMutation {
    /// Applies the edit to `bytes` (regions as they were before any edit).
    pub fn apply(&self, bytes: &mut Vec<u8>, r: Regions) {
        let len = bytes.len();
        match *self {
            ByteMutation::Flip { at, bit } => {
                if let Some(i) = at.resolve(r, len) {
                    bytes[i] ^= 1 << (bit % 8);
                }
            }
            ByteMutation::Set { at, value } => {
                if let Some(i) = at.resolve(r, len) {
                    bytes[i] = value;
                }
            }
            ByteMutation::U32 { at, value } => {
                if let Some(i) = at.resolve(r, len) {
                    write_le(bytes, i, &(value.value() as u32).to_le_bytes());
                }
            }
            ByteMutation::U64 { at, value } => {
                if let Some(i) = at.resolve(r, len) {
                    write_le(bytes, i, &value.value().to_le_bytes());
                }
            }
            ByteMutation::Varint { at, value } => {
                if let Some(i) = at.resolve(r, len) {
                    let old = varint_len(&bytes[i..]);
                    let mut new = Vec::new();
                    varint(value.value(), &mut new);
                    bytes.splice(i..i + old, new);
                }
            }
            ByteMutation::Truncate { at } => {
                if let Some(i) = at.resolve(r, len) {
                    bytes.truncate(i);
                }
            }
            ByteMutation::Insert { at, bytes: ref ins } => {
                let i = at.resolve(r, len).unwrap_or(0);
                let ins = &ins[..ins.len().min(MAX_INSERT)];
                bytes.splice(i..i, ins.iter().copied());
            }
            ByteMutation::Remove { at, len: n } => {
                if let Some(i) = at.resolve(r, len) {
                    let end = (i + n as usize).min(len);
                    bytes.drain(i..end);
                }
            }
            ByteMutation::Copy { from, to, len: n } => {
                if let (Some(a), Some(b)) = (from.resolve(r, len), to.resolve(r, len)) {
                    let n = (n as usize).min(len - a).min(len - b);
                    bytes.copy_within(a..a + n, b);
                }
            }
        }
    }
}

/// Applies every edit in order.
pub fn apply_all(bytes: &mut Vec<u8>, r: Regions, muts: &[ByteMutation]) {
    for m in muts {
        m.apply(bytes, r);
    }
}
