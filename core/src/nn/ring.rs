//! Fixed-capacity rings over an append-only sequence of rows, each row
//! stored once at slot `i % cap`, read one row at a time (the K/V rings the
//! attention reads as runs are [`super::kv_store::KvRing`]). Reads outside
//! the last `cap` rows are errors, never panics (the session's sizes make
//! them impossible; tests check).

use crate::arena::{ArenaError, Carve};
use crate::error::{Buffer, Error};

/// The last `cap` f32 rows of width `width` of an append-only sequence.
pub struct RowRing<'s> {
    /// (cap, width)
    data: &'s mut [f32],
    cap: usize,
    width: usize,
    /// Rows appended so far.
    len: usize,
}

impl<'s> RowRing<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, cap: usize, width: usize) -> Result<Self, ArenaError> {
        let n = cap.checked_mul(width).ok_or(ArenaError::Overflow)?;
        Ok(RowRing {
            data: a.f32(n)?,
            cap,
            width,
            len: 0,
        })
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

    /// Floats per row.
    pub fn width(&self) -> usize {
        self.width
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
        let s = self.len % self.cap;
        self.data[s * w..(s + 1) * w].copy_from_slice(row);
        self.len += 1;
        Ok(())
    }

    /// Row `i` (width). Errors if it is no longer (or not yet) held.
    pub fn row(&self, i: usize) -> Result<&[f32], Error> {
        let oldest = self.len.saturating_sub(self.cap);
        if i < oldest || i >= self.len {
            return Err(Error::Evicted {
                index: i,
                oldest,
                len: self.len,
            });
        }
        let s = i % self.cap;
        Ok(&self.data[s * self.width..(s + 1) * self.width])
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
        Ok(TokenRing {
            data: a.u32(cap.checked_mul(width).ok_or(ArenaError::Overflow)?)?,
            width,
            len: 0,
        })
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
        self.data.len().checked_div(self.width).unwrap_or(0)
    }
    pub fn push(&mut self, row: &[u32]) -> Result<(), Error> {
        let (cap, w) = (self.cap(), self.width);
        if cap == 0 || row.len() != w {
            return Err(Error::Length {
                buffer: Buffer::Tokens,
                len: row.len(),
                expected: w,
            });
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
            return Err(Error::Evicted {
                index: i,
                oldest,
                len: self.len,
            });
        }
        let s = i % cap;
        Ok(&self.data[s * w..(s + 1) * w])
    }
}
