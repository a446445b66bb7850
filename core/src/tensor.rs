//! Borrowed, validated views of the weight tensors inside a `.duo` file.
//!
//! A `TensorRef` never owns memory: `data` points into the model bytes
//! (mmap, `include_bytes!`, an engine asset). The format decoder guarantees,
//! before a `TensorRef` is handed out, that `data.len()` equals
//! `dtype.bytes_for(numel)`, that `data` starts at a 64-byte aligned offset
//! of the file, and that the shape matches the schema for the config.

/// Element type of a stored tensor. Discriminants are the on-disk codes
/// (docs/FORMAT.md); codes not listed are rejected by the decoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum DType {
    /// IEEE-754 binary32, little-endian.
    F32 = 0,
    /// IEEE-754 binary16, little-endian.
    F16 = 1,
    /// int8 weights in blocks of 32 along each row ([`block_row`] values:
    /// every axis but the first), one f16 scale per
    /// block stored before the block's 32 values (34 bytes per block; Q8_0-like).
    /// The v1 decoder validates it (layout, finite scales; docs/FORMAT.md §4);
    /// `Model::bind` accepts it for weight matrices (`kernels::Q8Rows`).
    Q8Block32 = 2,
    /// 4-bit weights in blocks of 32 along each row ([`block_row`]): an f16 scale `d`,
    /// then 16 bytes of nibbles, byte `j` holding element `j` (low nibble)
    /// and element `j + 16` (high nibble); value = `d * (nibble - 8)`
    /// (18 bytes per block; Q4_0-like). Validated like Q8Block32;
    /// `Model::bind` accepts it for weight matrices (`kernels::Q4Rows`).
    Q4Block32 = 3,
    /// The blocks, scales and values of `Q8Block32` with the rows in
    /// groups of 8, each group interleaved for the int8 GEMM
    /// (`kernels::simd::PackedQ8`: per block, the 8 rows' values by 8-byte
    /// group, then the 8 rows' f16 scales at the group's end); the last
    /// group padded to 8 rows (`ceil(rows / 8) * 8 * row / 32 * 34` bytes).
    /// Validated like Q8Block32 (every scale, padding rows' included);
    /// `Model::bind` accepts it for weight matrices (`kernels::X8Rows`).
    Q8Block32x8 = 4,
    /// The blocks, scales and nibbles of `Q4Block32` with the rows in
    /// groups of 8, interleaved like `Q8Block32x8` (`kernels::simd::PackedQ8`:
    /// per block, each row's two 8-byte halves of nibbles side by side, then
    /// the 8 rows' f16 scales at the group's end); the last group padded
    /// to 8 rows (`ceil(rows / 8) * 8 * row / 32 * 18` bytes). Validated
    /// like Q4Block32; `Model::bind` accepts it for weight matrices.
    Q4Block32x8 = 5,
}

impl DType {
    pub fn from_code(code: u8) -> Option<DType> {
        match code {
            0 => Some(DType::F32),
            1 => Some(DType::F16),
            2 => Some(DType::Q8Block32),
            3 => Some(DType::Q4Block32),
            4 => Some(DType::Q8Block32x8),
            5 => Some(DType::Q4Block32x8),
            _ => None,
        }
    }
    /// Bytes of one block of 32 values of a blocked type (0 for dense ones).
    pub const fn block_bytes(self) -> usize {
        match self {
            DType::Q8Block32 | DType::Q8Block32x8 => 34,
            DType::Q4Block32 | DType::Q4Block32x8 => 18,
            DType::F32 | DType::F16 => 0,
        }
    }
    /// Bytes needed for `numel` elements in rows of `row` elements
    /// ([`block_row`] of the shape); None on overflow or when `row` does
    /// not divide into whole blocks.
    pub fn bytes_for(self, numel: usize, row: usize) -> Option<usize> {
        match self {
            DType::F32 => numel.checked_mul(4),
            DType::F16 => numel.checked_mul(2),
            DType::Q8Block32 | DType::Q4Block32 => {
                if row == 0 || row % 32 != 0 || numel % row != 0 {
                    return None;
                }
                (numel / 32).checked_mul(self.block_bytes())
            }
            DType::Q8Block32x8 | DType::Q4Block32x8 => {
                if row == 0 || row % 32 != 0 || numel % row != 0 {
                    return None;
                }
                (numel / row)
                    .div_ceil(8)
                    .checked_mul(8 * (row / 32) * self.block_bytes())
            }
        }
    }
}

/// Values per row of a blocked (`Q8Block32`, `Q4Block32`) tensor: the
/// product of every axis after the first (a Linear `(out, in)`: `in`; a
/// Conv1d `(out, in, k)`: the `in * k` values of one output channel, which
/// the kernels dot as one row); the only axis for rank 1; 0 on overflow.
/// Blocks of 32 never straddle two rows.
pub fn block_row(dims: &[u32]) -> usize {
    match dims {
        [] => 0,
        [only] => *only as usize,
        [_, rest @ ..] => rest
            .iter()
            .try_fold(1usize, |p, &d| p.checked_mul(d as usize))
            .unwrap_or(0),
    }
}

/// Maximum tensor rank stored in a `.duo` file.
pub const MAX_RANK: usize = 4;

/// A view of one weight tensor. Shape is row-major, PyTorch order
/// (e.g. `Linear.weight` is `(out, in)`, `Conv1d.weight` is `(out, in, k)`).
#[derive(Clone, Copy, Debug)]
pub struct TensorRef<'a> {
    pub dtype: DType,
    pub rank: u8,
    /// Dimensions; entries past `rank` are 1.
    pub shape: [u32; MAX_RANK],
    /// Raw little-endian payload, 64-byte aligned within the file.
    pub data: &'a [u8],
}

impl<'a> TensorRef<'a> {
    pub fn dims(&self) -> &[u32] {
        &self.shape[..self.rank as usize]
    }
    pub fn numel(&self) -> usize {
        self.dims().iter().map(|&d| d as usize).product()
    }
    /// The payload as f32 when the dtype is F32 and `data` is 4-byte aligned
    /// in memory (true for any model buffer that is itself 64-byte aligned).
    pub fn as_f32(&self) -> Option<&'a [f32]> {
        if self.dtype != DType::F32 {
            return None;
        }
        bytemuck::try_cast_slice(self.data).ok()
    }
}
