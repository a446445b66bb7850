//! Where the streaming session keeps keys and values: the GPT's K/V cache
//! ([`crate::nn::gpt_cache`]) and the LATs' K/V rings ([`KvRing`]) store each
//! row ONCE, in the session's [`KvType`], and hand the attention a
//! [`KvRows`] view of them in place (no mirrored copy, no widened copy).

use crate::arena::{ArenaError, Carve};
use crate::error::{Buffer, Error};
use crate::kernels::{KvRows, RowData};

/// Element type of the session's K/V storage (the GPT cache and the LAT
/// rings).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KvType {
    F32,
    /// f16 storage (half the bytes): each key/value is rounded to the
    /// nearest binary16 when stored and read back exactly (the attention
    /// kernels widen it lane by lane).
    F16,
}

/// A flat run of K/V elements in `KvType` storage.
pub enum KvBuf<'s> {
    F32(&'s mut [f32]),
    F16(&'s mut [u16]),
}

/// `x` in binary16, rounded to nearest; a finite value beyond binary16's
/// range is kept as the largest finite one of its sign, not infinity (an
/// infinite key makes the softmax NaN): post-LN layers (Transflower) store
/// keys of unnormalised rows. `d`: as long as `x`.
fn narrow_saturating(x: &[f32], d: &mut [u16]) {
    crate::kernels::simd::narrow_f16(x, d);
    for (h, &v) in d.iter_mut().zip(x) {
        if *h & 0x7fff == 0x7c00 && v.is_finite() {
            *h = (*h & 0x8000) | 0x7bff;
        }
    }
}

impl KvType {
    /// Rounds `x` in place to what a row stored in this type reads back
    /// as ([`KvBuf::store`]; f32: unchanged), so that rows kept apart for
    /// a moment (a LAT push's newest keys, [`KvRows::then`]) give the
    /// attention the values their ring will hold.
    pub fn round_as_stored(self, x: &mut [f32]) {
        if self == KvType::F32 {
            return;
        }
        let mut h = [0u16; 64];
        for chunk in x.chunks_mut(64) {
            let h = &mut h[..chunk.len()];
            narrow_saturating(chunk, h);
            crate::kernels::simd::widen_f16(h, chunk);
        }
    }
}

fn out_of_range(at: usize, len: usize) -> Error {
    Error::Length {
        buffer: Buffer::Output,
        len: at,
        expected: len,
    }
}

impl<'s> KvBuf<'s> {
    /// `n` zeroed elements.
    pub fn carve<A: Carve<'s>>(a: &mut A, kv: KvType, n: usize) -> Result<Self, ArenaError> {
        Ok(match kv {
            KvType::F32 => KvBuf::F32(a.f32(n)?),
            KvType::F16 => KvBuf::F16(a.u16(n)?),
        })
    }

    pub fn len(&self) -> usize {
        match self {
            KvBuf::F32(d) => d.len(),
            KvBuf::F16(d) => d.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Stores `x` at elements `at .. at + x.len()` (f16: rounded to nearest,
    /// finite values beyond its range saturated to +-65504).
    pub fn store(&mut self, at: usize, x: &[f32]) -> Result<(), Error> {
        let end = at
            .checked_add(x.len())
            .filter(|&e| e <= self.len())
            .ok_or(out_of_range(at, self.len()))?;
        match self {
            KvBuf::F32(d) => d[at..end].copy_from_slice(x),
            KvBuf::F16(d) => narrow_saturating(x, &mut d[at..end]),
        }
        Ok(())
    }

    /// Copies `n` elements of `src` from `from` to `at` (the same storage
    /// type: the values move unchanged).
    pub fn copy_from(&mut self, at: usize, src: &KvBuf<'_>, from: usize, n: usize) -> Result<(), Error> {
        let (end, src_end) = (at.checked_add(n), from.checked_add(n));
        let end = end.filter(|&e| e <= self.len()).ok_or(out_of_range(at, self.len()))?;
        let src_end = src_end
            .filter(|&e| e <= src.len())
            .ok_or(out_of_range(from, src.len()))?;
        match (self, src) {
            (KvBuf::F32(d), KvBuf::F32(s)) => d[at..end].copy_from_slice(&s[from..src_end]),
            (KvBuf::F16(d), KvBuf::F16(s)) => d[at..end].copy_from_slice(&s[from..src_end]),
            _ => return Err(Error::State),
        }
        Ok(())
    }

    /// Elements `a..b` for the attention.
    pub fn view(&self, a: usize, b: usize) -> Result<RowData<'_>, Error> {
        if a > b || b > self.len() {
            return Err(out_of_range(b, self.len()));
        }
        Ok(match self {
            KvBuf::F32(d) => RowData::F32(&d[a..b]),
            KvBuf::F16(d) => RowData::F16(&d[a..b]),
        })
    }
}

/// The last `cap` key (or value) rows of one attention layer of an
/// append-only sequence, each stored once at slot `i % cap`: any run of at
/// most `cap` consecutive rows is at most two contiguous runs (before and
/// after the wrap), which [`KvRows`] hands to the attention in order.
/// Reads outside the last `cap` rows are errors, never panics.
pub struct KvRing<'s> {
    /// (cap, width) in `KvType` storage.
    data: KvBuf<'s>,
    cap: usize,
    width: usize,
    /// Rows appended so far.
    len: usize,
}

impl<'s> KvRing<'s> {
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        kv: KvType,
        cap: usize,
        width: usize,
    ) -> Result<Self, ArenaError> {
        let n = cap.checked_mul(width).ok_or(ArenaError::Overflow)?;
        Ok(KvRing {
            data: KvBuf::carve(a, kv, n)?,
            cap,
            width,
            len: 0,
        })
    }

    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Rows appended so far.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn capacity(&self) -> usize {
        self.cap
    }

    /// The element type the rows are stored in.
    pub fn kv_type(&self) -> KvType {
        match self.data {
            KvBuf::F32(_) => KvType::F32,
            KvBuf::F16(_) => KvType::F16,
        }
    }

    /// Appends one row; the oldest falls out once `cap` are held.
    pub fn push(&mut self, row: &[f32]) -> Result<(), Error> {
        let w = self.width;
        if row.len() != w || self.cap == 0 {
            return Err(Error::Length {
                buffer: Buffer::Output,
                len: row.len(),
                expected: w,
            });
        }
        self.data.store((self.len % self.cap) * w, row)?;
        self.len += 1;
        Ok(())
    }

    /// Rows `[lo, hi)` in order. Errors if any of them is no longer (or
    /// not yet) held.
    pub fn rows(&self, lo: usize, hi: usize) -> Result<KvRows<'_>, Error> {
        let oldest = self.len.saturating_sub(self.cap);
        if lo > hi || lo < oldest || hi > self.len {
            return Err(Error::Evicted {
                index: lo,
                oldest,
                len: self.len,
            });
        }
        let w = self.width;
        if lo == hi {
            return Ok(KvRows::one(self.data.view(0, 0)?));
        }
        let (s, n) = (lo % self.cap, hi - lo);
        if s + n <= self.cap {
            Ok(KvRows::one(self.data.view(s * w, (s + n) * w)?))
        } else {
            Ok(KvRows::two(
                self.data.view(s * w, self.cap * w)?,
                self.data.view(0, (s + n - self.cap) * w)?,
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f16 storage: values within range are rounded to nearest; finite
    /// values beyond +-65504 are saturated (an infinite key would make the
    /// softmax NaN); infinities and NaN stay what they are.
    #[test]
    fn f16_store_saturates_finite_overflow() {
        let mut buf = [0u16; 6];
        let mut kv = KvBuf::F16(&mut buf);
        kv.store(0, &[1.0, -2.5, 1.0e6, -7.0e4, f32::INFINITY, 65504.0])
            .unwrap();
        let KvBuf::F16(d) = kv else { unreachable!() };
        let back: [f32; 6] = core::array::from_fn(|i| crate::kernels::simd::f16_to_f32(d[i]));
        assert_eq!(back, [1.0, -2.5, 65504.0, -65504.0, f32::INFINITY, 65504.0]);
    }
}
