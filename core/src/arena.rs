//! Fixed memory: a bump allocator over caller bytes, and a planner that
//! computes the same byte count without memory.
//!
//! Every buffer of an inference run is carved by ONE function written
//! against the [`Carve`] trait; run once with a [`Planner`] it yields the
//! exact size (`*_scratch_bytes`), run with an [`Arena`] it yields the
//! buffers. The two cannot drift apart.
//!
//! Layout rule: the arena first skips to a 64-byte boundary of the caller
//! buffer (at most [`ALIGN`]` - 1` bytes, counted by
//! [`Planner::total_for_any_base`]); every allocation is rounded up to a
//! multiple of 64 bytes, so every buffer starts on a cache line (what the
//! SIMD kernels of a later issue want).

/// Alignment of every buffer handed out (bytes).
pub const ALIGN: usize = 64;

/// The arena ran out of bytes or a size overflowed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArenaError {
    /// `needed` more bytes were requested when `available` were left.
    OutOfMemory { needed: usize, available: usize },
    /// An element count times its size overflowed `usize`.
    Overflow,
}

/// Something buffers can be carved from: an [`Arena`] (real memory) or a
/// [`Planner`] (counting only; hands out empty slices).
pub trait Carve<'a> {
    /// `n` f32 values, zeroed.
    fn f32(&mut self, n: usize) -> Result<&'a mut [f32], ArenaError>;
    /// `n` u32 values, zeroed.
    fn u32(&mut self, n: usize) -> Result<&'a mut [u32], ArenaError>;
    /// `n` u16 values (f16 bits), zeroed.
    fn u16(&mut self, n: usize) -> Result<&'a mut [u16], ArenaError>;
    /// `n` i8 values, zeroed (carved as `ceil(n / 4)` u32; a [`Planner`]'s is empty).
    fn i8(&mut self, n: usize) -> Result<&'a mut [i8], ArenaError> {
        let b: &'a mut [i8] = bytemuck::cast_slice_mut(self.u32(n.div_ceil(4))?);
        let len = b.len().min(n);
        Ok(&mut b[..len])
    }
    /// `n` i32 values, zeroed (carved as u32).
    fn i32(&mut self, n: usize) -> Result<&'a mut [i32], ArenaError> {
        Ok(bytemuck::cast_slice_mut(self.u32(n)?))
    }
}

/// Bytes an allocation of `n` elements of `size` bytes occupies.
fn rounded(n: usize, size: usize) -> Result<usize, ArenaError> {
    let b = n.checked_mul(size).ok_or(ArenaError::Overflow)?;
    b.checked_add(ALIGN - 1)
        .map(|v| v & !(ALIGN - 1))
        .ok_or(ArenaError::Overflow)
}

/// A bump allocator over `&'a mut [u8]`. Buffers live as long as the
/// caller's bytes; the arena never frees (reuse memory by carving phases
/// from [`Arena::into_rest`] one after the other).
pub struct Arena<'a> {
    rest: &'a mut [u8],
    used: usize,
}

impl<'a> Arena<'a> {
    /// Starts at the first 64-byte boundary of `buf`.
    pub fn new(buf: &'a mut [u8]) -> Self {
        let addr = buf.as_ptr() as usize;
        let pad = (ALIGN - addr % ALIGN) % ALIGN;
        let pad = pad.min(buf.len());
        let (_, rest) = buf.split_at_mut(pad);
        Arena { rest, used: pad }
    }

    /// Bytes consumed so far, alignment padding included.
    pub fn used(&self) -> usize {
        self.used
    }

    /// Bytes still available.
    pub fn available(&self) -> usize {
        self.rest.len()
    }

    fn bytes(&mut self, n: usize, size: usize) -> Result<&'a mut [u8], ArenaError> {
        let take = rounded(n, size)?;
        if take > self.rest.len() {
            return Err(ArenaError::OutOfMemory {
                needed: take,
                available: self.rest.len(),
            });
        }
        let rest = core::mem::take(&mut self.rest);
        let (head, tail) = rest.split_at_mut(take);
        self.rest = tail;
        self.used += take;
        let head = &mut head[..n * size];
        head.fill(0);
        Ok(head)
    }

    /// The unused remainder (starts 64-byte aligned), for a later phase.
    pub fn into_rest(self) -> &'a mut [u8] {
        self.rest
    }
}

impl<'a> Carve<'a> for Arena<'a> {
    fn f32(&mut self, n: usize) -> Result<&'a mut [f32], ArenaError> {
        let b = self.bytes(n, 4)?;
        bytemuck::try_cast_slice_mut(b).map_err(|_| ArenaError::Overflow)
    }
    fn u32(&mut self, n: usize) -> Result<&'a mut [u32], ArenaError> {
        let b = self.bytes(n, 4)?;
        bytemuck::try_cast_slice_mut(b).map_err(|_| ArenaError::Overflow)
    }
    fn u16(&mut self, n: usize) -> Result<&'a mut [u16], ArenaError> {
        let b = self.bytes(n, 2)?;
        bytemuck::try_cast_slice_mut(b).map_err(|_| ArenaError::Overflow)
    }
}

/// Counts the bytes a carve function needs, with the same rounding as
/// [`Arena`], without memory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Planner {
    bytes: usize,
}

impl Planner {
    pub const fn new() -> Self {
        Planner { bytes: 0 }
    }
    /// Bytes counted so far (an aligned base assumed).
    pub fn bytes(&self) -> usize {
        self.bytes
    }
    /// Adds `n` bytes of a nested phase (already a multiple of [`ALIGN`]).
    pub fn add(&mut self, n: usize) -> Result<(), ArenaError> {
        self.bytes = self.bytes.checked_add(n).ok_or(ArenaError::Overflow)?;
        Ok(())
    }
    /// Bytes a caller buffer needs whatever its address: the count plus
    /// the worst-case skip to the first 64-byte boundary.
    pub fn total_for_any_base(&self) -> Option<usize> {
        self.bytes.checked_add(ALIGN - 1)
    }
}

impl<'a> Carve<'a> for Planner {
    fn f32(&mut self, n: usize) -> Result<&'a mut [f32], ArenaError> {
        self.add(rounded(n, 4)?)?;
        Ok(&mut [])
    }
    fn u32(&mut self, n: usize) -> Result<&'a mut [u32], ArenaError> {
        self.add(rounded(n, 4)?)?;
        Ok(&mut [])
    }
    fn u16(&mut self, n: usize) -> Result<&'a mut [u16], ArenaError> {
        self.add(rounded(n, 2)?)?;
        Ok(&mut [])
    }
}

/// Carves consecutive pieces of one f32 pool carved earlier, NOT zeroed:
/// for working memory that the phases of a step use in turn (a piece's
/// contents are whatever the previous phase left; its users write before
/// they read). Pieces are rounded like [`Arena`]'s, so a pool of
/// `Planner::bytes() / 4` floats fits the same carve function. Integer
/// pieces are the pool's floats viewed as integers (as unzeroed).
pub struct Split<'a> {
    rest: &'a mut [f32],
}

impl<'a> Split<'a> {
    pub fn new(pool: &'a mut [f32]) -> Self {
        Split { rest: pool }
    }

    /// Floats of a pool that holds what `plan` counted.
    pub fn floats_for(plan: &Planner) -> usize {
        plan.bytes() / 4
    }
}

impl<'a> Carve<'a> for Split<'a> {
    fn f32(&mut self, n: usize) -> Result<&'a mut [f32], ArenaError> {
        let take = rounded(n, 4)? / 4;
        if take > self.rest.len() {
            return Err(ArenaError::OutOfMemory {
                needed: take * 4,
                available: self.rest.len() * 4,
            });
        }
        let (head, tail) = core::mem::take(&mut self.rest).split_at_mut(take);
        self.rest = tail;
        Ok(&mut head[..n])
    }
    /// The pool's floats, viewed as u32 (an int8 panel's values and corrections).
    fn u32(&mut self, n: usize) -> Result<&'a mut [u32], ArenaError> {
        Ok(bytemuck::cast_slice_mut(self.f32(n)?))
    }
    fn u16(&mut self, n: usize) -> Result<&'a mut [u16], ArenaError> {
        let b: &'a mut [u16] = bytemuck::cast_slice_mut(self.f32(n.div_ceil(2))?);
        Ok(&mut b[..n])
    }
}
