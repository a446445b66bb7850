//! Weight matrices as rows: the one abstraction every weight-reading
//! kernel is generic over.
//!
//! A kernel (`linear`, `linear_xw`, the quantizer, embedding lookups) is
//! written once against [`RowMatrix`] and dispatched once per call through
//! [`Matrix`] (one arm per stored dtype). Per weight type:
//!
//! | impl | stored | `dot` accumulation | activations |
//! |---|---|---|---|
//! | [`F32Rows`] | f32 | f32 | f32 as given |
//! | [`F16Rows`] | IEEE binary16 | f32 (exact f16 -> f32) | f32 as given |
//! | [`Q8Rows`] | blocks of 32: f16 scale + 32 i8 | i32 per block, f32 across blocks | quantised per block of 32 (f32 scale `max|x|/127`, round to nearest) once per row chunk ([`RowMatrix::prepare`]) |
//! | [`X8Rows`] | the Q8 or Q4 blocks of 8 rows interleaved ([`simd::PackedQ8`]) | as Q8 (the packed kernel reads a row group in place; other kernels expand a row's blocks to Q8 blocks) | as Q8 |
//! | [`Q4Rows`] | blocks of 32: f16 scale + 16 bytes of nibbles | as Q8 (the nibbles of a tile's rows are expanded to Q8 blocks in registers/stack, then the same Q8 dots run) | as Q8 |
//!
//! Quantising the activations per block (Q8_0 x Q8_0, as ggml) keeps the
//! inner loop integer; the extra error is measured end to end
//! (tests/quantized.rs and docs/FORMAT.md §4).

use super::simd::{self, f16_to_f32, Tile, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN};

/// Activation columns prepared at once by an int8 row matrix (stack buffer
/// of `TM x ACT_CHUNK` i8 + `TM x ACT_CHUNK / 32` f32 scales: 4.5 KiB).
pub const ACT_CHUNK: usize = 1024;

/// Activations prepared for a weight type (see [`RowMatrix::prepare`]).
pub trait PreparedAct {
    fn new() -> Self;
}

impl PreparedAct for () {
    fn new() -> Self {}
}

/// Int8-quantised activations of up to `TM` rows: (ACT_CHUNK) values and
/// (ACT_CHUNK / 32) scales per row.
pub struct Q8Act {
    pub q: [[i8; ACT_CHUNK]; TM],
    pub d: [[f32; ACT_CHUNK / Q8_BLOCK]; TM],
}

impl PreparedAct for Q8Act {
    fn new() -> Self {
        Q8Act {
            q: [[0; ACT_CHUNK]; TM],
            d: [[0.0; ACT_CHUNK / Q8_BLOCK]; TM],
        }
    }
}

/// A `(rows, cols)` weight matrix read row by row. Callers guarantee
/// `r < rows()` and slice lengths as documented per method.
///
/// Dot products run over column chunks of at most [`RowMatrix::CHUNK`]
/// columns (a multiple of 32): the activation chunks of up to `TM` rows are
/// prepared once ([`RowMatrix::prepare`]: nothing for f32/f16, int8
/// quantisation for [`Q8Rows`]) and then dotted with many weight rows, a
/// `TM x TN` register tile at a time ([`RowMatrix::dot_tile`]).
pub trait RowMatrix {
    /// Prepared activations of one chunk.
    type Act: PreparedAct;
    /// Columns per chunk (`usize::MAX`: one chunk, nothing prepared).
    const CHUNK: usize;
    fn rows(&self) -> usize;
    fn cols(&self) -> usize;
    /// Prepares activation rows `x[m]` into row `m` of `act` (`x.len() <=
    /// TM`; each a chunk starting at a multiple of `CHUNK`, at most `CHUNK`
    /// long, all the same length).
    fn prepare(x: &[&[f32]], act: &mut Self::Act);
    /// `row(r)[c0 .. c0 + x.len()] . x`, with `act` from `prepare(&[x])`.
    fn dot_chunk(&self, r: usize, c0: usize, x: &[f32], act: &Self::Act) -> f32;
    /// `out[m][n] = row(o[n])[c0 .. c0 + len] . x[m]`, with `act` from
    /// `prepare(&x)` (the register-blocked GEMM step; ISA-dispatched).
    fn dot_tile(&self, o: [usize; TN], c0: usize, x: [&[f32]; TM], act: &Self::Act) -> Tile;
    /// `y += a * row(r)` (`y`: cols).
    fn axpy(&self, r: usize, a: f32, y: &mut [f32]);
    /// For `m < g`: `y_m += sum_r coef[m coef_stride + r - r0] * row(r)`
    /// over rows `r0..r1` in order, `y_m = y[m y_stride ..][..cols]`: per
    /// output row bit for bit [`Self::axpy`] row after row (dense rows:
    /// each row's lanes loaded once for the `g` outputs,
    /// [`DenseElem::axpy_rows_group`]).
    #[allow(clippy::too_many_arguments)]
    fn axpy_rows_group(
        &self,
        r0: usize,
        r1: usize,
        coef: &[f32],
        coef_stride: usize,
        y: &mut [f32],
        y_stride: usize,
        g: usize,
    ) {
        let n = self.cols();
        for m in 0..g {
            for r in r0..r1 {
                self.axpy(
                    r,
                    coef[m * coef_stride + r - r0],
                    &mut y[m * y_stride..m * y_stride + n],
                );
            }
        }
    }
    /// `out = row(r)` as f32 (`out`: cols; embedding and codebook rows).
    fn row_into(&self, r: usize, out: &mut [f32]);
    /// `row(r) . x` (`x`: cols), chunk by chunk.
    fn dot(&self, r: usize, x: &[f32]) -> f32 {
        let mut act = Self::Act::new();
        let mut sum = 0.0;
        for (i, xc) in x.chunks(Self::CHUNK.min(x.len().max(1))).enumerate() {
            Self::prepare(&[xc], &mut act);
            sum += self.dot_chunk(r, i * Self::CHUNK, xc, &act);
        }
        sum
    }
}

/// `a . b` over f32 (activations or f32 weights), ISA-dispatched.
#[inline]
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    simd::dot_f32(a, b)
}

/// The element of dense (unblocked) weight rows: f32, or f16 bit patterns
/// (`u16`). The dtype difference of the dense path lives here and only here.
pub trait DenseElem: Copy + 'static {
    fn to_f32(self) -> f32;
    /// `w . x` (ISA-dispatched).
    fn dot(w: &[Self], x: &[f32]) -> f32;
    /// The register-blocked tile `out[m][n] = w[n] . x[m]` (ISA-dispatched).
    fn tile(w: [&[Self]; TN], x: [&[f32]; TM]) -> Tile;
    /// `y += a * w` (ISA-dispatched where a variant exists).
    #[inline]
    fn axpy(a: f32, w: &[Self], y: &mut [f32]) {
        for (yi, &wi) in y.iter_mut().zip(w) {
            *yi += a * wi.to_f32();
        }
    }
    /// `out[j] = q . rows[j * stride ..][..q.len()]` (attention scores
    /// against stored key rows; ISA-dispatched, [`simd::dot_rows`]).
    fn dot_rows(q: &[f32], rows: &[Self], stride: usize, out: &mut [f32]);
    /// `y += sum_j coef[j] * rows[j * stride ..][..y.len()]` (attention's
    /// weighted values; ISA-dispatched, [`simd::axpy_rows_f32`]): [`Self::axpy`]
    /// row after row, bit for bit.
    fn axpy_rows(coef: &[f32], rows: &[Self], stride: usize, y: &mut [f32]);
    /// [`Self::dot_rows`] for `g` queries `q_stride` apart, their `n`
    /// scores `out_stride` apart ([`simd::dot_rows_group`]; bit for bit the
    /// per-query call; `side` prefetched into L2 meanwhile).
    #[allow(clippy::too_many_arguments)]
    fn dot_rows_group(
        q: &[f32],
        hd: usize,
        q_stride: usize,
        g: usize,
        rows: &[Self],
        stride: usize,
        n: usize,
        out: &mut [f32],
        out_stride: usize,
        side: &[u8],
    );
    /// [`Self::axpy_rows`] for `g` queries: coefficients `coef_stride`
    /// apart, outputs of `n` lanes `y_stride` apart
    /// ([`simd::axpy_rows_group_f32`]; bit for bit the per-query call).
    #[allow(clippy::too_many_arguments)]
    fn axpy_rows_group(
        coef: &[f32],
        coef_stride: usize,
        nk: usize,
        rows: &[Self],
        stride: usize,
        y: &mut [f32],
        y_stride: usize,
        n: usize,
        g: usize,
        side: &[u8],
    );
}

impl DenseElem for f32 {
    #[inline]
    fn to_f32(self) -> f32 {
        self
    }
    #[inline]
    fn dot(w: &[f32], x: &[f32]) -> f32 {
        simd::dot_f32(w, x)
    }
    #[inline]
    fn tile(w: [&[f32]; TN], x: [&[f32]; TM]) -> Tile {
        simd::tile_f32(w, x)
    }
    #[inline]
    fn axpy(a: f32, w: &[f32], y: &mut [f32]) {
        simd::axpy_f32(a, w, y)
    }
    #[inline]
    fn dot_rows(q: &[f32], rows: &[f32], stride: usize, out: &mut [f32]) {
        simd::dot_rows(q, rows, stride, out)
    }
    #[inline]
    fn axpy_rows(coef: &[f32], rows: &[f32], stride: usize, y: &mut [f32]) {
        simd::axpy_rows_f32(coef, rows, stride, y)
    }
    #[inline]
    fn dot_rows_group(
        q: &[f32],
        hd: usize,
        q_stride: usize,
        g: usize,
        rows: &[f32],
        stride: usize,
        n: usize,
        out: &mut [f32],
        out_stride: usize,
        side: &[u8],
    ) {
        simd::dot_rows_group(q, hd, q_stride, g, rows, stride, n, out, out_stride, side)
    }
    #[inline]
    fn axpy_rows_group(
        coef: &[f32],
        coef_stride: usize,
        nk: usize,
        rows: &[f32],
        stride: usize,
        y: &mut [f32],
        y_stride: usize,
        n: usize,
        g: usize,
        side: &[u8],
    ) {
        simd::axpy_rows_group_f32(coef, coef_stride, nk, rows, stride, y, y_stride, n, g, side)
    }
}

/// IEEE binary16 bit patterns.
impl DenseElem for u16 {
    #[inline]
    fn to_f32(self) -> f32 {
        f16_to_f32(self)
    }
    #[inline]
    fn dot(w: &[u16], x: &[f32]) -> f32 {
        simd::dot_f16(w, x)
    }
    #[inline]
    fn tile(w: [&[u16]; TN], x: [&[f32]; TM]) -> Tile {
        simd::tile_f16(w, x)
    }
    #[inline]
    fn axpy(a: f32, w: &[u16], y: &mut [f32]) {
        simd::axpy_f16(a, w, y)
    }
    #[inline]
    fn dot_rows(q: &[f32], rows: &[u16], stride: usize, out: &mut [f32]) {
        simd::dot_rows_f16(q, rows, stride, out)
    }
    #[inline]
    fn axpy_rows(coef: &[f32], rows: &[u16], stride: usize, y: &mut [f32]) {
        simd::axpy_rows_f16(coef, rows, stride, y)
    }
    #[inline]
    fn dot_rows_group(
        q: &[f32],
        hd: usize,
        q_stride: usize,
        g: usize,
        rows: &[u16],
        stride: usize,
        n: usize,
        out: &mut [f32],
        out_stride: usize,
        side: &[u8],
    ) {
        simd::dot_rows_group_f16(q, hd, q_stride, g, rows, stride, n, out, out_stride, side)
    }
    #[inline]
    fn axpy_rows_group(
        coef: &[f32],
        coef_stride: usize,
        nk: usize,
        rows: &[u16],
        stride: usize,
        y: &mut [f32],
        y_stride: usize,
        n: usize,
        g: usize,
        side: &[u8],
    ) {
        simd::axpy_rows_group_f16(coef, coef_stride, nk, rows, stride, y, y_stride, n, g, side)
    }
}

/// Row-major dense weights borrowed from the model bytes.
#[derive(Clone, Copy, Debug)]
pub struct DenseRows<'a, E> {
    data: &'a [E], // (rows, cols)
    rows: usize,
    cols: usize,
}

/// Row-major f32 weights.
pub type F32Rows<'a> = DenseRows<'a, f32>;
/// Row-major IEEE binary16 weights (bit patterns).
pub type F16Rows<'a> = DenseRows<'a, u16>;

impl<'a, E: DenseElem> DenseRows<'a, E> {
    /// None unless `data.len() == rows * cols`.
    pub fn new(data: &'a [E], rows: usize, cols: usize) -> Option<Self> {
        if rows.checked_mul(cols)? != data.len() {
            return None;
        }
        Some(DenseRows { data, rows, cols })
    }
    pub fn row(&self, r: usize) -> &'a [E] {
        &self.data[r * self.cols..(r + 1) * self.cols]
    }
}

impl<E: DenseElem> RowMatrix for DenseRows<'_, E> {
    type Act = ();
    const CHUNK: usize = usize::MAX;
    fn rows(&self) -> usize {
        self.rows
    }
    fn cols(&self) -> usize {
        self.cols
    }
    #[inline]
    fn prepare(_: &[&[f32]], _: &mut ()) {}
    #[inline]
    fn dot_chunk(&self, r: usize, c0: usize, x: &[f32], _: &()) -> f32 {
        E::dot(&self.row(r)[c0..], x)
    }
    #[inline]
    fn dot_tile(&self, o: [usize; TN], c0: usize, x: [&[f32]; TM], _: &()) -> Tile {
        E::tile(o.map(|r| &self.row(r)[c0..]), x)
    }
    #[inline]
    fn axpy(&self, r: usize, a: f32, y: &mut [f32]) {
        E::axpy(a, self.row(r), y)
    }
    fn axpy_rows_group(
        &self,
        r0: usize,
        r1: usize,
        coef: &[f32],
        coef_stride: usize,
        y: &mut [f32],
        y_stride: usize,
        g: usize,
    ) {
        let c = self.cols;
        E::axpy_rows_group(
            coef,
            coef_stride,
            r1.saturating_sub(r0),
            &self.data[r0 * c..r1 * c],
            c,
            y,
            y_stride,
            c,
            g,
            &[],
        )
    }
    fn row_into(&self, r: usize, out: &mut [f32]) {
        for (o, &w) in out.iter_mut().zip(self.row(r)) {
            *o = w.to_f32();
        }
    }
}

/// The int8 tile over `nb` blocks of stored Q8Block32 rows `w` and the
/// prepared activations `act` (shared by [`Q8Rows`] and [`Q4Rows`]).
#[inline]
fn tile_q8_act(w: [&[u8]; TN], nb: usize, act: &Q8Act) -> Tile {
    let xq = act.q.each_ref().map(|q| &q[..nb * Q8_BLOCK]);
    let xd = act.d.each_ref().map(|d| &d[..nb]);
    simd::tile_q8(w, xq, xd)
}

/// `y += s * q` over one block's quantised values (`s`: activation x scale).
#[inline]
fn q8_block_axpy(s: f32, q: &[u8], y: &mut [f32]) {
    for (yi, &qi) in y.iter_mut().zip(q) {
        *yi += s * (qi as i8 as f32);
    }
}

/// `out = d * q` over one block's quantised values.
#[inline]
fn q8_block_into(d: f32, q: &[u8], out: &mut [f32]) {
    for (o, &qi) in out.iter_mut().zip(q) {
        *o = d * (qi as i8 as f32);
    }
}

/// Row-major `DType::Q8Block32` weights: each row is `cols / 32` blocks of
/// [f16 scale, 32 x i8]; value = scale * q.
#[derive(Clone, Copy, Debug)]
pub struct Q8Rows<'a> {
    data: &'a [u8],
    rows: usize,
    cols: usize,
}

impl<'a> Q8Rows<'a> {
    /// None unless `cols % 32 == 0` and `data.len() == rows * cols / 32 * 34`.
    pub fn new(data: &'a [u8], rows: usize, cols: usize) -> Option<Self> {
        if cols % Q8_BLOCK != 0
            || rows
                .checked_mul(cols / Q8_BLOCK)?
                .checked_mul(Q8_BLOCK_BYTES)?
                != data.len()
        {
            return None;
        }
        Some(Q8Rows { data, rows, cols })
    }
    /// The stored bytes of row `r` (`cols / 32` blocks of [f16 scale, 32 x i8]).
    pub fn row(&self, r: usize) -> &'a [u8] {
        let rb = self.cols / Q8_BLOCK * Q8_BLOCK_BYTES;
        &self.data[r * rb..(r + 1) * rb]
    }
    /// Stored bytes of rows `r0..r1` (clamped to the matrix; contiguous).
    pub fn rows_bytes(&self, r0: usize, r1: usize) -> &'a [u8] {
        let rb = self.cols / Q8_BLOCK * Q8_BLOCK_BYTES;
        let (r0, r1) = (r0.min(self.rows), r1.min(self.rows));
        &self.data[r0 * rb..r1.max(r0) * rb]
    }
    /// `f(column block start, scale, 32 quantised values)` for each block of row `r`.
    fn for_blocks(&self, r: usize, mut f: impl FnMut(usize, f32, &[u8])) {
        for (b, blk) in self.row(r).chunks_exact(Q8_BLOCK_BYTES).enumerate() {
            f(
                b * Q8_BLOCK,
                f16_to_f32(u16::from_le_bytes([blk[0], blk[1]])),
                &blk[2..],
            );
        }
    }
}

impl RowMatrix for Q8Rows<'_> {
    type Act = Q8Act;
    const CHUNK: usize = ACT_CHUNK;
    fn rows(&self) -> usize {
        self.rows
    }
    fn cols(&self) -> usize {
        self.cols
    }
    #[inline]
    fn prepare(x: &[&[f32]], act: &mut Q8Act) {
        for ((xm, q), d) in x.iter().zip(&mut act.q).zip(&mut act.d) {
            simd::quantise_q8(xm, q, d);
        }
    }
    #[inline]
    fn dot_chunk(&self, r: usize, c0: usize, x: &[f32], act: &Q8Act) -> f32 {
        let b0 = c0 / Q8_BLOCK * Q8_BLOCK_BYTES;
        let nb = x.len() / Q8_BLOCK;
        let w = &self.row(r)[b0..b0 + nb * Q8_BLOCK_BYTES];
        simd::dot_q8(w, &act.q[0][..nb * Q8_BLOCK], &act.d[0][..nb])
    }
    #[inline]
    fn dot_tile(&self, o: [usize; TN], c0: usize, x: [&[f32]; TM], act: &Q8Act) -> Tile {
        let b0 = c0 / Q8_BLOCK * Q8_BLOCK_BYTES;
        let nb = x[0].len() / Q8_BLOCK;
        tile_q8_act(
            o.map(|r| &self.row(r)[b0..b0 + nb * Q8_BLOCK_BYTES]),
            nb,
            act,
        )
    }
    fn axpy(&self, r: usize, a: f32, y: &mut [f32]) {
        self.for_blocks(r, |c, d, q| {
            q8_block_axpy(a * d, q, &mut y[c..c + Q8_BLOCK])
        });
    }
    fn row_into(&self, r: usize, out: &mut [f32]) {
        self.for_blocks(r, |c, d, q| q8_block_into(d, q, &mut out[c..c + Q8_BLOCK]));
    }
}

/// Rows per interleaved group of `DType::Q8Block32x8`.
pub const Q8X8_ROWS: usize = simd::PACK_ROWS;

/// Bytes of one stored `DType::Q8Block32x8` row group of `nb` blocks (8
/// rows: `nb * 256` value bytes, then `nb * 16` scale bytes).
const fn q8x8_group_bytes(nb: usize) -> usize {
    nb * Q8X8_ROWS * Q8_BLOCK_BYTES
}

/// Bytes of one stored `DType::Q4Block32x8` row group of `nb` blocks (8
/// rows: `nb * 128` value bytes, then `nb * 16` scale bytes).
const fn q4x8_group_bytes(nb: usize) -> usize {
    nb * Q8X8_ROWS * Q4_BLOCK_BYTES
}

/// `DType::Q8Block32x8` / `DType::Q4Block32x8` weights: the rows of a
/// Q8Block32 / Q4Block32 matrix (same blocks, scales and values) in groups
/// of 8, each group stored as a [`simd::PackedQ8`] tile; the last group is
/// padded with rows whose results are dropped. The int8 GEMM reads a
/// group's tile in place (no packing per call); the other kernels expand
/// one row's blocks to Q8 blocks ([`X8Rows::expand`], exact) and run the
/// Q8 code.
#[derive(Clone, Copy, Debug)]
pub struct X8Rows<'a> {
    data: &'a [u8],
    rows: usize,
    cols: usize,
    q4: bool,
}

impl<'a> X8Rows<'a> {
    /// `Q8Block32x8`: None unless `cols % 32 == 0` and `data.len() ==
    /// ceil(rows / 8) * 8 * cols / 32 * 34`.
    pub fn new(data: &'a [u8], rows: usize, cols: usize) -> Option<Self> {
        Self::with(data, rows, cols, false)
    }
    /// `Q4Block32x8`: None unless `cols % 32 == 0` and `data.len() ==
    /// ceil(rows / 8) * 8 * cols / 32 * 18`.
    pub fn new_q4(data: &'a [u8], rows: usize, cols: usize) -> Option<Self> {
        Self::with(data, rows, cols, true)
    }
    fn with(data: &'a [u8], rows: usize, cols: usize, q4: bool) -> Option<Self> {
        let groups = rows.div_ceil(Q8X8_ROWS);
        let m = X8Rows {
            data,
            rows,
            cols,
            q4,
        };
        if cols % Q8_BLOCK != 0 || groups.checked_mul(m.group_bytes())? != data.len() {
            return None;
        }
        Some(m)
    }
    fn group_bytes(&self) -> usize {
        let nb = self.cols / Q8_BLOCK;
        if self.q4 {
            q4x8_group_bytes(nb)
        } else {
            q8x8_group_bytes(nb)
        }
    }
    /// The packed tile of rows `8t .. 8t + 8` (`t < ceil(rows / 8)`).
    pub fn group(&self, t: usize) -> simd::PackedQ8<'a> {
        let gb = self.group_bytes();
        let nb = self.cols / Q8_BLOCK;
        let g = &self.data[t * gb..(t + 1) * gb];
        let tile = if self.q4 {
            simd::PackedQ8::from_q4_group(g, nb)
        } else {
            simd::PackedQ8::from_group(g, nb)
        };
        tile.unwrap_or_else(|| unreachable!("group length checked by new"))
    }
    /// Stored bytes of the groups holding rows `r0..r1` (clamped; contiguous).
    pub fn rows_bytes(&self, r0: usize, r1: usize) -> &'a [u8] {
        let gb = self.group_bytes();
        let (r0, r1) = (r0.min(self.rows), r1.min(self.rows));
        &self.data[r0 / Q8X8_ROWS * gb..r1.max(r0).div_ceil(Q8X8_ROWS) * gb]
    }
    /// Blocks `b0 .. b0 + nb` of row `r` in the Q8Block32 layout (`dst`:
    /// at least `nb * 34` bytes; exact: the same scale and values).
    pub fn expand(&self, r: usize, b0: usize, nb: usize, dst: &mut [u8]) {
        let g = self.group(r / Q8X8_ROWS);
        let n = r % Q8X8_ROWS;
        for (k, d) in dst.chunks_exact_mut(Q8_BLOCK_BYTES).take(nb).enumerate() {
            g.q8_block_of_row(b0 + k, n, d);
        }
    }
}

impl ExpandsToQ8 for X8Rows<'_> {
    fn dims(&self) -> (usize, usize) {
        (self.rows, self.cols)
    }
    #[inline]
    fn expand_blocks(&self, r: usize, b0: usize, nb: usize, dst: &mut [u8]) {
        self.expand(r, b0, nb, dst)
    }
}

/// Bytes of one stored `DType::Q4Block32` block: f16 scale + 16 bytes.
pub const Q4_BLOCK_BYTES: usize = 18;

/// Expands stored Q4Block32 blocks (`src`: nb * 18 bytes) into the
/// Q8Block32 layout (`dst`: nb * 34 bytes): same f16 scale, value
/// `nibble - 8` as i8. Exact: `d * (nibble - 8)` is the same number in
/// both layouts, so every Q8 kernel computes the Q4 product.
#[inline]
pub fn expand_q4(src: &[u8], dst: &mut [u8]) {
    for (s, d) in src
        .chunks_exact(Q4_BLOCK_BYTES)
        .zip(dst.chunks_exact_mut(Q8_BLOCK_BYTES))
    {
        d[0] = s[0];
        d[1] = s[1];
        let (lo, hi) = d[2..].split_at_mut(16);
        for ((&b, l), h) in s[2..].iter().zip(lo.iter_mut()).zip(hi.iter_mut()) {
            *l = ((b & 0x0f) as i8 - 8) as u8;
            *h = ((b >> 4) as i8 - 8) as u8;
        }
    }
}

/// Row-major `DType::Q4Block32` weights: each row is `cols / 32` blocks of
/// [f16 scale, 16 bytes of nibbles]; value = scale * (nibble - 8). Half the
/// bytes of [`Q8Rows`]; dots expand the nibbles of the rows at hand into Q8
/// blocks ([`expand_q4`]) and reuse the Q8 kernels (one int8 code path).
#[derive(Clone, Copy, Debug)]
pub struct Q4Rows<'a> {
    data: &'a [u8],
    rows: usize,
    cols: usize,
}

/// Blocks of one activation chunk ([`ACT_CHUNK`] columns).
const CHUNK_BLOCKS: usize = ACT_CHUNK / Q8_BLOCK;

impl<'a> Q4Rows<'a> {
    /// None unless `cols % 32 == 0` and `data.len() == rows * cols / 32 * 18`.
    pub fn new(data: &'a [u8], rows: usize, cols: usize) -> Option<Self> {
        if cols % Q8_BLOCK != 0
            || rows
                .checked_mul(cols / Q8_BLOCK)?
                .checked_mul(Q4_BLOCK_BYTES)?
                != data.len()
        {
            return None;
        }
        Some(Q4Rows { data, rows, cols })
    }
    /// The stored bytes of row `r`.
    pub fn row(&self, r: usize) -> &'a [u8] {
        let rb = self.cols / Q8_BLOCK * Q4_BLOCK_BYTES;
        &self.data[r * rb..(r + 1) * rb]
    }
    /// Stored bytes of rows `r0..r1` (clamped to the matrix; contiguous).
    pub fn rows_bytes(&self, r0: usize, r1: usize) -> &'a [u8] {
        let rb = self.cols / Q8_BLOCK * Q4_BLOCK_BYTES;
        let (r0, r1) = (r0.min(self.rows), r1.min(self.rows));
        &self.data[r0 * rb..r1.max(r0) * rb]
    }
}

impl ExpandsToQ8 for Q4Rows<'_> {
    fn dims(&self) -> (usize, usize) {
        (self.rows, self.cols)
    }
    #[inline]
    fn expand_blocks(&self, r: usize, b0: usize, nb: usize, dst: &mut [u8]) {
        expand_q4(
            &self.row(r)[b0 * Q4_BLOCK_BYTES..(b0 + nb) * Q4_BLOCK_BYTES],
            dst,
        );
    }
}

/// An int8 layout read through its exact expansion into Q8Block32 blocks
/// ([`Q4Rows`]: nibbles to i8; [`X8Rows`]: a row out of its group): the
/// row reads expand the blocks at hand into a stack buffer and run the Q8
/// code, so every such layout computes what its Q8 expansion computes.
pub trait ExpandsToQ8 {
    /// `(rows, cols)`.
    fn dims(&self) -> (usize, usize);
    /// Blocks `b0 .. b0 + nb` of row `r` as Q8Block32 blocks (`dst`: at
    /// least `nb * 34` bytes).
    fn expand_blocks(&self, r: usize, b0: usize, nb: usize, dst: &mut [u8]);
}

/// `f(column block start, scale, 32 quantised values)` for each block of
/// row `r` of an expanded layout (as [`Q8Rows`] hands them over).
fn expanded_blocks<W: ExpandsToQ8>(w: &W, r: usize, mut f: impl FnMut(usize, f32, &[u8])) {
    let mut q8 = [0u8; Q8_BLOCK_BYTES];
    for b in 0..w.dims().1 / Q8_BLOCK {
        w.expand_blocks(r, b, 1, &mut q8);
        f(
            b * Q8_BLOCK,
            f16_to_f32(u16::from_le_bytes([q8[0], q8[1]])),
            &q8[2..],
        );
    }
}

impl<W: ExpandsToQ8> RowMatrix for W {
    type Act = Q8Act;
    const CHUNK: usize = ACT_CHUNK;
    fn rows(&self) -> usize {
        self.dims().0
    }
    fn cols(&self) -> usize {
        self.dims().1
    }
    #[inline]
    fn prepare(x: &[&[f32]], act: &mut Q8Act) {
        Q8Rows::prepare(x, act)
    }
    #[inline]
    fn dot_chunk(&self, r: usize, c0: usize, x: &[f32], act: &Q8Act) -> f32 {
        let nb = x.len() / Q8_BLOCK;
        let mut buf = [0u8; CHUNK_BLOCKS * Q8_BLOCK_BYTES];
        self.expand_blocks(r, c0 / Q8_BLOCK, nb, &mut buf);
        simd::dot_q8(
            &buf[..nb * Q8_BLOCK_BYTES],
            &act.q[0][..nb * Q8_BLOCK],
            &act.d[0][..nb],
        )
    }
    #[inline]
    fn dot_tile(&self, o: [usize; TN], c0: usize, x: [&[f32]; TM], act: &Q8Act) -> Tile {
        let nb = x[0].len() / Q8_BLOCK;
        let mut bufs = [[0u8; CHUNK_BLOCKS * Q8_BLOCK_BYTES]; TN];
        for (buf, &r) in bufs.iter_mut().zip(&o) {
            self.expand_blocks(r, c0 / Q8_BLOCK, nb, buf);
        }
        tile_q8_act(bufs.each_ref().map(|b| &b[..nb * Q8_BLOCK_BYTES]), nb, act)
    }
    fn axpy(&self, r: usize, a: f32, y: &mut [f32]) {
        expanded_blocks(self, r, |c, d, q| {
            q8_block_axpy(a * d, q, &mut y[c..c + Q8_BLOCK])
        });
    }
    fn row_into(&self, r: usize, out: &mut [f32]) {
        expanded_blocks(self, r, |c, d, q| {
            q8_block_into(d, q, &mut out[c..c + Q8_BLOCK])
        });
    }
}

/// A weight matrix of any stored dtype; kernels match once per call (with
/// [`with_rows!`](crate::with_rows)) and run their generic body.
#[derive(Clone, Copy, Debug)]
pub enum Matrix<'a> {
    F32(F32Rows<'a>),
    F16(F16Rows<'a>),
    Q8(Q8Rows<'a>),
    X8(X8Rows<'a>),
    Q4(Q4Rows<'a>),
}

/// `with_rows!(matrix, m => expr)`: evaluates `expr` with `m` bound to the
/// concrete [`RowMatrix`] of each arm (the single dispatch point).
#[macro_export]
macro_rules! with_rows {
    ($mat:expr, $m:ident => $body:expr) => {
        match $mat {
            $crate::kernels::Matrix::F32($m) => $body,
            $crate::kernels::Matrix::F16($m) => $body,
            $crate::kernels::Matrix::Q8($m) => $body,
            $crate::kernels::Matrix::X8($m) => $body,
            $crate::kernels::Matrix::Q4($m) => $body,
        }
    };
}

impl Matrix<'_> {
    pub fn rows(&self) -> usize {
        crate::with_rows!(self, m => m.rows())
    }
    pub fn cols(&self) -> usize {
        crate::with_rows!(self, m => m.cols())
    }
    /// `out = row(r)`; callers guarantee `r < rows()` and `out.len() == cols()`.
    pub fn row_into(&self, r: usize, out: &mut [f32]) {
        crate::with_rows!(self, m => m.row_into(r, out))
    }
    /// `row(r) . x`.
    pub fn dot(&self, r: usize, x: &[f32]) -> f32 {
        crate::with_rows!(self, m => m.dot(r, x))
    }
    /// Bytes of weight data (what one full pass over the matrix reads).
    pub fn weight_bytes(&self) -> usize {
        match self {
            Matrix::F32(m) => m.rows * m.cols * 4,
            Matrix::F16(m) => m.rows * m.cols * 2,
            Matrix::Q8(m) => m.rows * m.cols / Q8_BLOCK * Q8_BLOCK_BYTES,
            Matrix::X8(m) => m.data.len(),
            Matrix::Q4(m) => m.rows * m.cols / Q8_BLOCK * Q4_BLOCK_BYTES,
        }
    }
}
