//! A ring of settled columns (a unit's input, a stack's output).

use super::*;

/// The last `cap` columns (`ch` floats each) of an append-only sequence.
pub(super) struct ColRing<'s> {
    /// (cap, ch): column `i` at slot `i % cap`.
    data: &'s mut [f32],
    pub(super) cap: usize,
    pub(super) ch: usize,
    /// Columns appended so far.
    pub(super) n: usize,
}

/// A ring read outside the columns it holds (the plan makes this
/// impossible; reported as an error, never a panic).
pub(super) fn evicted(index: usize, oldest: usize, len: usize) -> Error {
    Error::Evicted { index, oldest, len }
}

impl<'s> ColRing<'s> {
    pub(super) fn carve<A: Carve<'s>>(
        a: &mut A,
        cap: usize,
        ch: usize,
    ) -> Result<Self, ArenaError> {
        Ok(ColRing {
            data: a.f32(cap.checked_mul(ch).ok_or(ArenaError::Overflow)?)?,
            cap,
            ch,
            n: 0,
        })
    }

    /// Appends one column of at most `ch` floats (the oldest falls out).
    pub(super) fn push(&mut self, col: &[f32]) -> Result<(), Error> {
        if col.len() > self.ch {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: col.len(),
                expected: self.ch,
            });
        }
        if self.cap > 0 {
            let s = (self.n % self.cap) * self.ch;
            let len = self.data.len();
            let slot = self.data.get_mut(s..s + col.len()).ok_or(Error::Length {
                buffer: Buffer::Features,
                len,
                expected: s + col.len(),
            })?;
            slot.copy_from_slice(col);
        }
        self.n += 1;
        Ok(())
    }

    /// Column `i` (ch floats).
    pub(super) fn col(&self, i: usize) -> Result<&[f32], Error> {
        let oldest = self.n.saturating_sub(self.cap);
        if i < oldest || i >= self.n {
            return Err(evicted(i, oldest, self.n));
        }
        let s = (i % self.cap) * self.ch;
        self.data
            .get(s..s + self.ch)
            .ok_or(evicted(i, oldest, self.n))
    }
}
