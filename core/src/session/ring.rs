//! Fixed-capacity rings over an append-only sequence of rows.
//!
//! A mirrored [`RowRing`] stores every row twice (slots `i mod cap` and
//! `i mod cap + cap`), so any run of at most `cap` consecutive rows is ONE
//! contiguous slice: attention reads its keys straight from the ring, in
//! order, without a gather. A plain ring stores each row once and serves
//! single rows. Reads outside the last `cap` rows are errors,
//! never panics (the session's sizes make them impossible; tests check).

use crate::arena::{ArenaError, Carve};
use crate::error::{Buffer, Error};

/// The last `cap` rows of width `width` of an append-only sequence.
pub struct RowRing<'s> {
    /// (2 * cap, width) mirrored: row `i` lives at slots `i % cap` and
    /// `i % cap + cap`; (cap, width) plain.
    data: &'s mut [f32],
    cap: usize,
    mirrored: bool,
    width: usize,
    /// Rows appended so far.
    len: usize,
}

impl<'s> RowRing<'s> {
    /// A mirrored ring: [`RowRing::rows`] serves any run of <= `cap` rows.
    pub fn carve<A: Carve<'s>>(a: &mut A, cap: usize, width: usize) -> Result<Self, ArenaError> {
        Self::carve_as(a, cap, width, true)
    }

    /// A plain ring: half the memory, single-row reads only.
    pub fn carve_plain<A: Carve<'s>>(a: &mut A, cap: usize, width: usize) -> Result<Self, ArenaError> {
        Self::carve_as(a, cap, width, false)
    }

    fn carve_as<A: Carve<'s>>(a: &mut A, cap: usize, width: usize, mirrored: bool) -> Result<Self, ArenaError> {
        let copies = if mirrored { 2 } else { 1 };
        let n = cap.checked_mul(copies).and_then(|v| v.checked_mul(width)).ok_or(ArenaError::Overflow)?;
        Ok(RowRing { data: a.f32(n)?, cap, width, mirrored, len: 0 })
    }

    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Rows appended so far (also the index of the next row).
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn capacity(&self) -> usize {
        self.cap
    }

    /// Appends one row; the oldest falls out once `cap` are held.
    pub fn push(&mut self, row: &[f32]) -> Result<(), Error> {
        let w = self.width;
        if row.len() != w || self.cap == 0 {
            return Err(Error::Length { buffer: Buffer::Output, len: row.len(), expected: w });
        }
        let s = self.len % self.cap;
        self.data[s * w..(s + 1) * w].copy_from_slice(row);
        if self.mirrored {
            let t = s + self.cap;
            self.data[t * w..(t + 1) * w].copy_from_slice(row);
        }
        self.len += 1;
        Ok(())
    }

    /// Rows `[lo, hi)` as one slice ((hi - lo), width). Errors if any of
    /// them is no longer (or not yet) held, or if a plain ring is asked
    /// for more than one row.
    pub fn rows(&self, lo: usize, hi: usize) -> Result<&[f32], Error> {
        let oldest = self.len.saturating_sub(self.cap);
        if lo > hi || lo < oldest || hi > self.len || (!self.mirrored && hi - lo > 1) {
            return Err(Error::Evicted { index: lo, oldest, len: self.len });
        }
        if lo == hi {
            return Ok(&[]);
        }
        let s = lo % self.cap;
        Ok(&self.data[s * self.width..(s + hi - lo) * self.width])
    }

    /// Row `i` (width).
    pub fn row(&self, i: usize) -> Result<&[f32], Error> {
        self.rows(i, i + 1)
    }
}

/// The last `cap` rows of `width` u32 values (follower tokens: width 5).
pub struct TokenRing<'s> {
    /// (cap, width)
    data: &'s mut [u32],
    width: usize,
    len: usize,
}

impl<'s> TokenRing<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, cap: usize, width: usize) -> Result<Self, ArenaError> {
        Ok(TokenRing { data: a.u32(cap.checked_mul(width).ok_or(ArenaError::Overflow)?)?, width, len: 0 })
    }
    pub fn clear(&mut self) {
        self.len = 0;
    }
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    fn cap(&self) -> usize {
        if self.width == 0 {
            0
        } else {
            self.data.len() / self.width
        }
    }
    pub fn push(&mut self, row: &[u32]) -> Result<(), Error> {
        let (cap, w) = (self.cap(), self.width);
        if cap == 0 || row.len() != w {
            return Err(Error::Length { buffer: Buffer::Tokens, len: row.len(), expected: w });
        }
        let s = self.len % cap;
        self.data[s * w..(s + 1) * w].copy_from_slice(row);
        self.len += 1;
        Ok(())
    }
    pub fn row(&self, i: usize) -> Result<&[u32], Error> {
        let (cap, w) = (self.cap(), self.width);
        let oldest = self.len.saturating_sub(cap);
        if i < oldest || i >= self.len {
            return Err(Error::Evicted { index: i, oldest, len: self.len });
        }
        let s = i % cap;
        Ok(&self.data[s * w..(s + 1) * w])
    }
}
