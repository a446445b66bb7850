//! Two packed tiles of 8 weight rows as one operand of 16 four-byte
//! columns ([`TilePair`]), laid out once per tile pair of a GEMM, and the
//! VNNI kernels over it ([`gemm_q8_pair`]: AVX-512 VNNI, and AVX-VNNI on
//! 32-byte vectors, two activation rows at a time): up to
//! [`PAIR_CALL_ROWS`] activation rows x 16 weight rows per call,
//! bit-identical to [`super::gemm_q8_packed`] on each tile. The AMX kernel
//! ([`super::amx`]) takes the same operand as its `B` tiles.
//!
//! On AVX-VNNI the pair kernel took the R step's GEMMs from 32-50% of the
//! `vpdpbusd ymm` peak to 59-63% (`bench --isa avxvnni --kernels`, Intel
//! Xeon capped to AVX-VNNI, 2026-12-06; docs/PERFORMANCE.md).
//!
//! Why the pair kernel is faster than the 8-row one
//! ([`super::x86::gemm_q8_packed_vnni`]): there a block's four 64-byte
//! groups hold 8 rows x 8 bytes, so an activation row needs two `vpdpbusd`
//! chains per block pair and a lane shuffle to bring each block's two
//! halves together before the f32 steps. Here register `k` of a block
//! holds bytes `4k .. 4k + 4` of all 16 rows (one row per i32 lane): an
//! activation row is 8 `vpdpbusd` against 4-byte broadcasts, and the i32
//! lane is already the row's block sum, so the f32 steps (one convert, one
//! scale product, one FMA) serve 16 rows instead of 8. Measured in a
//! scratch copy on an Intel Xeon with AVX-512 VNNI (2026-12-05, L1-resident
//! operands): 174-189 GMAC/s at 4-8 rows against 123-144 for the 8-row
//! kernel at 12; in `linear` (`duolando bench --kernels`), the R step's,
//! re-prefill's and batched sessions' GEMMs went from 24-29% of the VNNI
//! peak to 37-40% (docs/PERFORMANCE.md, 2026-12-05 night), and to 45-52%
//! with the activation rows laid out in call groups
//! ([`super::pair_group_index`], 2026-12-06: see [`pair_vnni`]).
//!
//! Why it is bit-identical: per weight row and block the i32 sum is exact
//! in both (the stored unsigned form plus the activation's correction, or
//! weights laid out unsigned, `w + 128`, with the same correction; 4-bit
//! tiles are widened to `q - 8`, whose sum equals the 8-row kernel's
//! `q`-sum plus its shifted correction). The f32 steps are the same
//! operations on the same values: `acc_h += f32(sum) * (s_b * xd_b)` into
//! the accumulator of the block's parity `h`, even and odd added at the end.

use core::arch::x86_64::*;

use super::{
    Isa, PackedQ8, PACK_BLOCKS, PACK_BLOCK_NIBBLES, PACK_BLOCK_SCALES, PACK_BLOCK_VALUES,
    PACK_ROWS, Q8_BLOCK,
};

/// Bytes of one block's operand: 8 rows of 64 bytes (16 columns x 4 bytes).
pub(super) const B_BLOCK: usize = 512;
/// Block pairs of the widest prepared tile.
pub(super) const PAIRS: usize = PACK_BLOCKS.div_ceil(2);
/// Weight rows of a prepared pair: the kernels' output columns.
pub const COLS: usize = 2 * PACK_ROWS;
/// Most activation rows per call of [`gemm_q8_pair`]: 16 accumulators, the
/// block's 8 weight registers and the temporaries fit the 32 registers.
pub const PAIR_CALL_ROWS: usize = 8;

/// Whether the tile pair kernels run: the selected ISA is AVX-512 VNNI
/// ([`gemm_q8_pair_raw`]) or AVX-VNNI ([`gemm_q8_pair_avxvnni_raw`], the
/// same operand on 32-byte vectors). Not AVX2: the same kernel with
/// `vpmaddubsw` and the sign trick (4 instructions per 32 products, the
/// operand stored signed) was no faster than the 8-row kernel there (42-50%
/// of the AVX2 peak against 43-54%, Intel Xeon capped to AVX2, 2026-12-06).
#[inline]
pub fn enabled() -> bool {
    matches!(super::isa(), Isa::Avx512Vnni | Isa::AvxVnni)
}

/// The `B` operands of two packed tiles of 8 weight rows (tile `t`: the
/// operand columns `8t .. 8t + 8`), per block 8 rows of 64 bytes (row `2g +
/// h`, column `8t + n`: bytes `8g + 4h .. 8g + 4h + 4` of row `n`'s block;
/// 4-bit tiles widened to signed bytes first), and their scales as the
/// kernel multiplies them (per block parity `h` and pair `p`, lane `8t +
/// n`: tile `t`'s `s_n,2p+h`, the scale of the block whose sums column
/// `8t + n` of the C tile holds). At most [`PACK_BLOCKS`] blocks.
#[repr(C, align(64))]
pub struct TilePair {
    pub(super) b: [u8; PACK_BLOCKS * B_BLOCK],
    pub(super) s: [[[f32; 16]; PAIRS]; 2],
    pub(super) nb: [usize; 2],
    /// Per tile: its bytes stored unsigned (`w + 128`, what `vpdpbusd`
    /// multiplies) instead of signed (what the AMX kernel takes).
    pub(super) unsigned: [bool; 2],
}

impl TilePair {
    pub fn new() -> Self {
        TilePair {
            b: [0; PACK_BLOCKS * B_BLOCK],
            s: [[[0.0; 16]; PAIRS]; 2],
            nb: [0; 2],
            unsigned: [false; 2],
        }
    }

    /// Lays out `w` as tile `half` (0: weight rows 0-7 of the result, 1:
    /// rows 8-15) of the operands; false (and nothing usable) if no kernel
    /// takes them ([`enabled`]), `half > 1` or `w` has more than
    /// [`PACK_BLOCKS`] blocks. Both tiles must be laid out, with the same
    /// number of blocks, before a kernel ([`super::gemm_q8_packed_amx`],
    /// [`gemm_q8_pair`]) runs on them. Stored signed where the AMX kernel
    /// runs ([`super::amx::enabled`]: its operand), else unsigned (the pair
    /// kernel's: [`Self::unsigned`]).
    pub fn prepare(&mut self, half: usize, w: PackedQ8<'_>) -> bool {
        if half < 2 {
            self.nb[half] = 0;
        }
        if !enabled() {
            return false;
        }
        let unsigned = !super::amx::enabled();
        if super::isa() == Isa::AvxVnni {
            // SAFETY: the AvxVnni ISA's `set_isa` contract covers avx2 and f16c.
            return unsafe { self.prepare_raw_avx2(half, w, unsigned) };
        }
        // SAFETY: `enabled` and not AvxVnni: the Avx512Vnni ISA (avx512f/bw among its features).
        unsafe { self.prepare_raw(half, w, unsigned) }
    }

    /// [`Self::prepare`] of both tiles, `w0` as tile 0 and `w1` as tile 1,
    /// in one pass on AVX-512 (each 64-byte operand row written once, whole,
    /// from both tiles' lines: half the stores of two passes, and no second
    /// visit of rows that left L1): the same bytes and scales as the two
    /// calls (test `tile_pair_kernel_equals_the_8_row_kernel_bit_for_bit`). False where either
    /// call would be; on AVX-VNNI (no AVX-512) the two calls.
    pub fn prepare_both(&mut self, w0: PackedQ8<'_>, w1: PackedQ8<'_>) -> bool {
        if !enabled() || super::isa() == Isa::AvxVnni || w0.blocks() != w1.blocks() {
            return self.prepare(0, w0) && self.prepare(1, w1);
        }
        let unsigned = !super::amx::enabled();
        // SAFETY: `enabled` and not AvxVnni: the Avx512Vnni ISA (avx512f/bw, f16c among its features).
        unsafe { self.prepare_both_raw(w0, w1, unsigned) }
    }

    /// [`Self::prepare_both`] without the ISA checks, the bytes stored
    /// `unsigned` or signed as asked (both tiles need the same block count).
    ///
    /// # Safety
    /// The CPU must support avx512f, avx512bw and f16c.
    pub unsafe fn prepare_both_raw(
        &mut self,
        w0: PackedQ8<'_>,
        w1: PackedQ8<'_>,
        unsigned: bool,
    ) -> bool {
        let (Some(nb), Some(nb1)) = (self.checked_blocks(0, w0), self.checked_blocks(1, w1)) else {
            return false;
        };
        if nb != nb1 {
            return false;
        }
        // SAFETY: the caller's features; the extents were checked above.
        unsafe { prepare_b_both(w0, w1, nb, unsigned, &mut self.b, &mut self.s) };
        self.nb = [nb; 2];
        self.unsigned = [unsigned; 2];
        true
    }

    /// Whether both tiles are stored unsigned: the operand the pair
    /// kernels take (signed pairs are the AMX kernel's).
    pub fn unsigned(&self) -> bool {
        self.unsigned == [true; 2]
    }

    /// [`Self::prepare`] without the [`enabled`] check, the bytes stored
    /// `unsigned` or signed as asked.
    ///
    /// # Safety
    /// The CPU must support avx512f, avx512bw and f16c.
    pub unsafe fn prepare_raw(&mut self, half: usize, w: PackedQ8<'_>, unsigned: bool) -> bool {
        let Some(nb) = self.checked_blocks(half, w) else {
            return false;
        };
        // SAFETY: the caller's features; the extents were checked above.
        unsafe { prepare_b(w, nb, half, unsigned, &mut self.b, &mut self.s) };
        self.nb[half] = nb;
        self.unsigned[half] = unsigned;
        true
    }

    /// [`Self::prepare_raw`] on 32-byte vectors: the same bytes and scales.
    ///
    /// # Safety
    /// The CPU must support avx2 and f16c.
    pub unsafe fn prepare_raw_avx2(
        &mut self,
        half: usize,
        w: PackedQ8<'_>,
        unsigned: bool,
    ) -> bool {
        let Some(nb) = self.checked_blocks(half, w) else {
            return false;
        };
        // SAFETY: the caller's features; the extents were checked above.
        unsafe { prepare_b_avx2(w, nb, half, unsigned, &mut self.b, &mut self.s) };
        self.nb[half] = nb;
        self.unsigned[half] = unsigned;
        true
    }

    /// Tile `half` emptied, and `w`'s block count where it fits the pair
    /// (`half` 0 or 1, at most [`PACK_BLOCKS`] blocks, its values and
    /// scales all there).
    fn checked_blocks(&mut self, half: usize, w: PackedQ8<'_>) -> Option<usize> {
        if half > 1 {
            return None;
        }
        self.nb[half] = 0;
        let nb = w.blocks();
        let per = if w.q4 {
            PACK_BLOCK_NIBBLES
        } else {
            PACK_BLOCK_VALUES
        };
        (nb <= PACK_BLOCKS && w.v.len() >= nb * per && w.s.len() >= nb * PACK_BLOCK_SCALES)
            .then_some(nb)
    }
}

impl Default for TilePair {
    fn default() -> Self {
        Self::new()
    }
}

/// Block `b`'s four 64-byte lines of a packed tile as the operand takes
/// them: signed bytes (4-bit tiles widened to `q - 8`), `+ 128` where
/// `unsigned`, each line's even dwords (`h = 0`) in its low 256 bits and its
/// odd ones in the high 256 bits.
///
/// # Safety
/// avx512f and avx512bw; `w.v` holds block `b`.
#[inline]
#[target_feature(enable = "avx512f,avx512bw")]
unsafe fn block_halves(w: PackedQ8<'_>, b: usize, unsigned: bool) -> [__m512i; 4] {
    let flip = _mm512_set1_epi8(if unsigned { -128 } else { 0 });
    let split = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 1, 3, 5, 7, 9, 11, 13, 15);
    // SAFETY: the caller's.
    unsafe { block_lines(w, b) }.map(|l| _mm512_xor_si512(_mm512_permutexvar_epi32(split, l), flip))
}

/// Block `b`'s four 64-byte lines of a packed tile as signed bytes (4-bit
/// tiles widened to `q - 8`).
///
/// # Safety
/// avx512f and avx512bw; `w.v` holds block `b`.
#[inline]
#[target_feature(enable = "avx512f,avx512bw")]
unsafe fn block_lines(w: PackedQ8<'_>, b: usize) -> [__m512i; 4] {
    if w.q4 {
        let (low, eight) = (_mm512_set1_epi8(0x0f), _mm512_set1_epi8(8));
        let vb = &w.v[PACK_BLOCK_NIBBLES * b..PACK_BLOCK_NIBBLES * (b + 1)];
        // SAFETY: vb holds 2 x 64 bytes.
        let h: [__m512i; 2] = core::array::from_fn(|k| unsafe {
            _mm512_loadu_si512(vb.as_ptr().add(64 * k) as *const _)
        });
        [
            _mm512_sub_epi8(_mm512_and_si512(h[0], low), eight),
            _mm512_sub_epi8(_mm512_and_si512(h[1], low), eight),
            _mm512_sub_epi8(_mm512_and_si512(_mm512_srli_epi16::<4>(h[0]), low), eight),
            _mm512_sub_epi8(_mm512_and_si512(_mm512_srli_epi16::<4>(h[1]), low), eight),
        ]
    } else {
        let vb = &w.v[PACK_BLOCK_VALUES * b..PACK_BLOCK_VALUES * (b + 1)];
        // SAFETY: vb holds 4 x 64 bytes.
        core::array::from_fn(|g| unsafe { _mm512_loadu_si512(vb.as_ptr().add(64 * g) as *const _) })
    }
}

/// [`prepare_b`] of both tiles at once: line `g` of each tile split into
/// its even and odd dwords as there, then operand row `2g` = (tile 0's
/// even | tile 1's even) and row `2g + 1` = (tile 0's odd | tile 1's odd),
/// each one 64-byte store; the scales as [`prepare_scales`] per tile.
///
/// # Safety
/// avx512f, avx512bw and f16c; `w0.v`, `w1.v` hold `nb` blocks, their `s`
/// the blocks' scales, `out` `nb * B_BLOCK` bytes, `nb <= PACK_BLOCKS`.
#[target_feature(enable = "avx512f,avx512bw,f16c")]
unsafe fn prepare_b_both(
    w0: PackedQ8<'_>,
    w1: PackedQ8<'_>,
    nb: usize,
    unsigned: bool,
    out: &mut [u8],
    scales: &mut [[[f32; 16]; PAIRS]; 2],
) {
    for (b, ob) in out.chunks_exact_mut(B_BLOCK).take(nb).enumerate() {
        // SAFETY: both tiles hold block b < nb.
        let (h0, h1) = unsafe { (block_halves(w0, b, unsigned), block_halves(w1, b, unsigned)) };
        for (g, (&v0, &v1)) in h0.iter().zip(&h1).enumerate() {
            // (v0 low 256 | v1 low 256) and (v0 high 256 | v1 high 256).
            let even = _mm512_inserti64x4::<1>(v0, _mm512_castsi512_si256(v1));
            let odd = _mm512_shuffle_i64x2::<0xEE>(v0, v1);
            // SAFETY: ob holds 8 x 64 bytes; 128g + 64 + 64 <= 512.
            unsafe {
                _mm512_storeu_si512(ob.as_mut_ptr().add(128 * g) as *mut _, even);
                _mm512_storeu_si512(ob.as_mut_ptr().add(128 * g + 64) as *mut _, odd);
            }
        }
    }
    // SAFETY: the caller's features include f16c; the extents are the caller's.
    unsafe {
        prepare_scales(w0, nb, 0, scales);
        prepare_scales(w1, nb, 1, scales);
    }
}

/// [`TilePair::prepare`]'s layout of tile `half` (bytes `w + 128` where `unsigned`).
///
/// # Safety
/// avx512f, avx512bw and f16c; `w.v` holds `nb` blocks, `w.s` their scales,
/// `out` `nb * B_BLOCK` bytes, `nb <= PACK_BLOCKS`.
#[target_feature(enable = "avx512f,avx512bw,f16c")]
unsafe fn prepare_b(
    w: PackedQ8<'_>,
    nb: usize,
    half: usize,
    unsigned: bool,
    out: &mut [u8],
    scales: &mut [[[f32; 16]; PAIRS]; 2],
) {
    for (b, ob) in out.chunks_exact_mut(B_BLOCK).take(nb).enumerate() {
        // SAFETY: w holds block b < nb.
        let halves = unsafe { block_halves(w, b, unsigned) };
        for (g, &v) in halves.iter().enumerate() {
            // SAFETY: ob holds 8 x 64 bytes; 128g + 64 + 32 half + 32 <= 512.
            unsafe {
                _mm256_storeu_si256(
                    ob.as_mut_ptr().add(128 * g + 32 * half) as *mut _,
                    _mm512_castsi512_si256(v),
                );
                _mm256_storeu_si256(
                    ob.as_mut_ptr().add(128 * g + 64 + 32 * half) as *mut _,
                    _mm512_extracti64x4_epi64::<1>(v),
                );
            }
        }
    }
    // SAFETY: the caller's features include f16c; the extents are the caller's.
    unsafe { prepare_scales(w, nb, half, scales) };
}

/// The scales of tile `half` as the kernels multiply them (see [`TilePair`]).
///
/// # Safety
/// avx and f16c; `w.s` holds the scales of `nb <= PACK_BLOCKS` blocks.
#[target_feature(enable = "avx,f16c")]
unsafe fn prepare_scales(
    w: PackedQ8<'_>,
    nb: usize,
    half: usize,
    scales: &mut [[[f32; 16]; PAIRS]; 2],
) {
    let scale = |b: usize| -> [f32; 8] {
        let mut f = [0f32; 8];
        if b < nb {
            // SAFETY: block b's 8 f16 scales (16 bytes) lie in w.s; f holds 8 floats.
            unsafe {
                _mm256_storeu_ps(
                    f.as_mut_ptr(),
                    _mm256_cvtph_ps(_mm_loadu_si128(
                        w.s[PACK_BLOCK_SCALES * b..].as_ptr() as *const __m128i
                    )),
                )
            };
        }
        f
    };
    for p in 0..nb.div_ceil(2) {
        for (h, sh) in scales.iter_mut().enumerate() {
            sh[p][PACK_ROWS * half..PACK_ROWS * (half + 1)].copy_from_slice(&scale(2 * p + h));
        }
    }
}

/// [`prepare_b`] on 32-byte vectors (for CPUs without AVX-512): the same
/// bytes and scales.
///
/// # Safety
/// avx2 and f16c; as [`prepare_b`] otherwise.
#[target_feature(enable = "avx2,f16c")]
unsafe fn prepare_b_avx2(
    w: PackedQ8<'_>,
    nb: usize,
    half: usize,
    unsigned: bool,
    out: &mut [u8],
    scales: &mut [[[f32; 16]; PAIRS]; 2],
) {
    let low = _mm256_set1_epi8(0x0f);
    let flip = _mm256_set1_epi8(if unsigned { -128 } else { 0 });
    let eight = _mm256_set1_epi8(8);
    // A stored line's 32-byte half holds 4 rows' (h = 0, h = 1) dword pairs:
    // the even dwords (h = 0) to its low 128 bits, the odd ones to its high.
    let split = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
    for (b, ob) in out.chunks_exact_mut(B_BLOCK).take(nb).enumerate() {
        // lines[g][i]: bytes 32i .. 32i + 32 of line g (rows 4i .. 4i + 4).
        let lines: [[__m256i; 2]; 4] = if w.q4 {
            let vb = &w.v[PACK_BLOCK_NIBBLES * b..PACK_BLOCK_NIBBLES * (b + 1)];
            // SAFETY: vb holds 4 x 32 bytes.
            let h: [__m256i; 4] = core::array::from_fn(|k| unsafe {
                _mm256_loadu_si256(vb.as_ptr().add(32 * k) as *const _)
            });
            let lo = |v: __m256i| _mm256_sub_epi8(_mm256_and_si256(v, low), eight);
            let hi = |v: __m256i| {
                _mm256_sub_epi8(_mm256_and_si256(_mm256_srli_epi16::<4>(v), low), eight)
            };
            [
                [lo(h[0]), lo(h[1])],
                [lo(h[2]), lo(h[3])],
                [hi(h[0]), hi(h[1])],
                [hi(h[2]), hi(h[3])],
            ]
        } else {
            let vb = &w.v[PACK_BLOCK_VALUES * b..PACK_BLOCK_VALUES * (b + 1)];
            // SAFETY: vb holds 8 x 32 bytes.
            core::array::from_fn(|g| {
                core::array::from_fn(|i| unsafe {
                    _mm256_loadu_si256(vb.as_ptr().add(64 * g + 32 * i) as *const _)
                })
            })
        };
        for (g, [l0, l1]) in lines.iter().enumerate() {
            let (a, c) = (
                _mm256_permutevar8x32_epi32(*l0, split),
                _mm256_permutevar8x32_epi32(*l1, split),
            );
            // h = 0 of rows 0-7, then h = 1.
            let even = _mm256_xor_si256(_mm256_permute2x128_si256::<0x20>(a, c), flip);
            let odd = _mm256_xor_si256(_mm256_permute2x128_si256::<0x31>(a, c), flip);
            // SAFETY: ob holds 8 x 64 bytes; 128g + 64 + 32 half + 32 <= 512.
            unsafe {
                _mm256_storeu_si256(ob.as_mut_ptr().add(128 * g + 32 * half) as *mut _, even);
                _mm256_storeu_si256(ob.as_mut_ptr().add(128 * g + 64 + 32 * half) as *mut _, odd);
            }
        }
    }
    // SAFETY: the caller's features include f16c; the extents are the caller's.
    unsafe { prepare_scales(w, nb, half, scales) };
}

/// `M` activation rows of a quantised panel against the prepared pair `w`,
/// the rows laid out as one call group ([`super::pair_group_index`]: per
/// block, the `M` rows' 32 values one after another, likewise their block
/// scales and their two corrections each), `n_in` values per row (what
/// [`super::gemm_q8_packed`] takes per row, interleaved by block). Row `m`,
/// column `8t + n` of the result is what [`super::gemm_q8_packed`] gives for
/// row `n` of tile `t`, bit for bit, over the blocks that both tiles and
/// the rows hold. Prefetches `ahead` into L2, spread over the block pairs.
/// None where the kernel does not run ([`enabled`]), `M` is 0 or over
/// [`PAIR_CALL_ROWS`], the operands are shorter than `M` rows, or the two
/// tiles were laid out with different block counts or signed (for AMX:
/// [`TilePair::unsigned`]): the caller then takes the 8-row kernel per
/// tile.
#[inline]
pub fn gemm_q8_pair<const M: usize>(
    w: &TilePair,
    xq: &[i8],
    xd: &[f32],
    xc: &[i32],
    n_in: usize,
    ahead: &[u8],
) -> Option<[[f32; COLS]; M]> {
    match super::isa() {
        // SAFETY: the Avx512Vnni ISA's `set_isa` contract covers the kernel's features.
        Isa::Avx512Vnni => unsafe { gemm_q8_pair_raw(w, xq, xd, xc, n_in, ahead) },
        // SAFETY: the AvxVnni ISA's `set_isa` contract covers the kernel's features.
        Isa::AvxVnni => unsafe { gemm_q8_pair_avxvnni_raw(w, xq, xd, xc, n_in, ahead) },
        _ => None,
    }
}

/// The blocks [`gemm_q8_pair`] runs over, or None where it refuses (see there).
fn call_blocks<const M: usize>(
    w: &TilePair,
    xq: &[i8],
    xd: &[f32],
    xc: &[i32],
    n_in: usize,
) -> Option<usize> {
    let rb = n_in / Q8_BLOCK;
    if M == 0
        || M > PAIR_CALL_ROWS
        || w.nb[0] != w.nb[1]
        || !w.unsigned()
        || xq.len() < M * n_in
        || xd.len() < M * rb
        || xc.len() < 2 * M * rb
    {
        return None;
    }
    Some(w.nb[0].min(PACK_BLOCKS).min(rb))
}

/// [`gemm_q8_pair`] on AVX-VNNI (32-byte vectors) without the ISA check:
/// the same values as [`gemm_q8_pair_raw`], bit for bit.
///
/// # Safety
/// The CPU must support avx2, avxvnni, fma and f16c.
pub unsafe fn gemm_q8_pair_avxvnni_raw<const M: usize>(
    w: &TilePair,
    xq: &[i8],
    xd: &[f32],
    xc: &[i32],
    n_in: usize,
    ahead: &[u8],
) -> Option<[[f32; COLS]; M]> {
    let nb = call_blocks::<M>(w, xq, xd, xc, n_in)?;
    // SAFETY: the caller's features; the extents were checked above.
    Some(unsafe { ymm_rows::<M, 2>(w, nb, xq, xd, xc, ahead) })
}

/// The call group's `M` rows, `R` at a time (what the 16 registers hold),
/// on [`pair_avxvnni`]; the group's prefetch spread over the passes.
///
/// # Safety
/// As [`pair_avxvnni`] for every pass.
#[inline(always)]
unsafe fn ymm_rows<const M: usize, const R: usize>(
    w: &TilePair,
    nb: usize,
    xq: &[i8],
    xd: &[f32],
    xc: &[i32],
    ahead: &[u8],
) -> [[f32; COLS]; M] {
    let mut out = [[0.0f32; COLS]; M];
    let passes = M.div_ceil(R);
    let (q, d, c) = (xq.as_ptr(), xd.as_ptr(), xc.as_ptr());
    let mut m = 0;
    while m < M {
        let (a0, a1) = super::part_bytes(ahead.len(), m / R, passes);
        let share = &ahead[a0..a1];
        // SAFETY: the caller's; rows m .. m + r of the group (m + r <= M).
        unsafe {
            if m + R <= M {
                out[m..m + R].copy_from_slice(&pair_avxvnni::<R>(w, nb, M, m, q, d, c, share));
            } else {
                let [t] = pair_avxvnni::<1>(w, nb, M, m, q, d, c, share);
                out[m] = t;
            }
        }
        m += R;
    }
    out
}

/// Rows `m0 .. m0 + R` of a call group of `rows` rows ([`pair_vnni`]'s
/// layout) against the prepared pair, on 32-byte vectors: per block and
/// row, the even and odd 4-byte pieces in one `vpdpbusd` chain per 8
/// columns from the row's two corrections (an exact i32 sum: the same as
/// [`pair_vnni`]'s two chains added), then the same f32 steps in the same
/// order.
///
/// # Safety
/// avx2, avxvnni, fma, f16c; `nb <= PACK_BLOCKS`, both tiles of `w`
/// prepared unsigned with at least `nb` blocks, `m0 + R <= rows`, and `xq`,
/// `xd`, `xc` hold `nb` blocks of `rows` rows as
/// [`super::pair_group_index`] lays them out.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2,avxvnni,fma,f16c")]
unsafe fn pair_avxvnni<const R: usize>(
    w: &TilePair,
    nb: usize,
    rows: usize,
    m0: usize,
    xq: *const i8,
    xd: *const f32,
    xc: *const i32,
    ahead: &[u8],
) -> [[f32; COLS]; R] {
    // Block b's operand, values, scales and corrections (moved on per block).
    // SAFETY (pointer offsets): row m0's entries of block 0 (m0 < rows).
    let (mut ob, mut xs, mut ds, mut cs) = unsafe {
        (
            w.b.as_ptr(),
            xq.add(Q8_BLOCK * m0),
            xd.add(m0),
            xc.add(2 * m0),
        )
    };
    // acc[m][h][t]: row m's sums of the blocks of parity h, tile t (lane = weight row).
    let mut acc = [[[_mm256_setzero_ps(); 2]; 2]; R];
    macro_rules! block {
        ($h:literal, $p:expr) => {{
            // SAFETY: w.s[h] holds PAIRS >= pairs rows of 16 floats (p < pairs).
            let sv: [__m256; 2] =
                core::array::from_fn(|t| unsafe { _mm256_loadu_ps(w.s[$h][$p].as_ptr().add(8 * t)) });
            // d[m][t]: row m's block sum against tile t, from its two corrections.
            let mut d: [[__m256i; 2]; R] = core::array::from_fn(|m| {
                // SAFETY: row m's two corrections of this block (the group's extents).
                let c = unsafe { (*cs.add(2 * m)).wrapping_add(*cs.add(2 * m + 1)) };
                [_mm256_set1_epi32(c); 2]
            });
            for k in 0..8 {
                // Register k, lane j of tile t: bytes 4k .. 4k + 4 of weight row 8t + j (w + 128).
                // SAFETY: the block's B_BLOCK operand bytes; 64k + 32t + 32 <= B_BLOCK.
                let wv: [__m256i; 2] =
                    core::array::from_fn(|t| unsafe { _mm256_loadu_si256(ob.add(64 * k + 32 * t) as *const _) });
                for (m, dm) in d.iter_mut().enumerate() {
                    // Register k holds piece k / 2 of parity k % 2: bytes 8(k/2) + 4(k%2) of the row's block.
                    // SAFETY: row m's 32 values of this block; 4k + 4 <= Q8_BLOCK.
                    let x = unsafe { (xs.add(Q8_BLOCK * m + 4 * k) as *const i32).read_unaligned() };
                    let xb = _mm256_set1_epi32(x);
                    for t in 0..2 {
                        dm[t] = _mm256_dpbusd_avx_epi32(dm[t], wv[t], xb);
                    }
                }
            }
            for (m, am) in acc.iter_mut().enumerate() {
                // SAFETY: row m's scale of this block.
                let xdb = _mm256_set1_ps(unsafe { *ds.add(m) });
                for t in 0..2 {
                    am[$h][t] = _mm256_fmadd_ps(
                        _mm256_cvtepi32_ps(d[m][t]),
                        _mm256_mul_ps(sv[t], xdb),
                        am[$h][t],
                    );
                }
            }
            // SAFETY: one block on: at most one past the last of the nb blocks.
            unsafe {
                ob = ob.add(B_BLOCK);
                xs = xs.add(Q8_BLOCK * rows);
                ds = ds.add(rows);
                cs = cs.add(2 * rows);
            }
        }};
    }
    let pairs = nb.div_ceil(2);
    for p in 0..nb / 2 {
        super::prefetch_part(ahead, p, pairs);
        block!(0, p);
        block!(1, p);
    }
    if nb % 2 == 1 {
        super::prefetch_part(ahead, nb / 2, pairs);
        block!(0, nb / 2);
    }
    let _ = (ob, xs, ds, cs);
    let mut out = [[0.0f32; COLS]; R];
    for (o, a) in out.iter_mut().zip(acc) {
        for t in 0..2 {
            // SAFETY: o holds 16 floats; 8t + 8 <= 16.
            unsafe { _mm256_storeu_ps(o.as_mut_ptr().add(8 * t), _mm256_add_ps(a[0][t], a[1][t])) };
        }
    }
    out
}

/// [`gemm_q8_pair`] without the [`enabled`] check.
///
/// # Safety
/// The CPU must support avx512f/bw/dq/vl/vnni, avx2, fma and f16c.
pub unsafe fn gemm_q8_pair_raw<const M: usize>(
    w: &TilePair,
    xq: &[i8],
    xd: &[f32],
    xc: &[i32],
    n_in: usize,
    ahead: &[u8],
) -> Option<[[f32; COLS]; M]> {
    let nb = call_blocks::<M>(w, xq, xd, xc, n_in)?;
    // SAFETY: the caller's features; the group holds `nb <= rb` blocks of
    // its `M` rows (above), both tiles were prepared unsigned with
    // `w.nb[0] >= nb` blocks.
    Some(unsafe { pair_vnni(w, nb, xq.as_ptr(), xd.as_ptr(), xc.as_ptr(), ahead) })
}

/// [`gemm_q8_pair`] on the first `nb` blocks of a call group of `M` rows
/// (both tiles stored unsigned).
///
/// Every operand is walked with one pointer that moves on per block, the
/// rows and the 4-byte pieces at fixed offsets from it: every memory
/// operand is `[register + constant]`. With row-major rows (an index
/// register per row) each `vpdpbusd` with a broadcast operand took two
/// micro-ops and the kernel ran at 48-53% of the VNNI peak in L1; this way
/// 63-67% (Intel Xeon, AVX-512 VNNI, 2026-12-06, 768 and 3072 values per
/// row, 8 rows).
///
/// # Safety
/// avx512f/bw/dq/vl/vnni, avx2, fma, f16c; `nb <= PACK_BLOCKS`, both tiles
/// of `w` prepared with at least `nb` blocks, and `xq`, `xd`, `xc` hold
/// `nb` blocks of `M` rows as [`super::pair_group_index`] lays them out
/// (`32 M nb` values, `M nb` scales, `2 M nb` corrections).
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx512vnni,avx2,fma,f16c")]
unsafe fn pair_vnni<const M: usize>(
    w: &TilePair,
    nb: usize,
    xq: *const i8,
    xd: *const f32,
    xc: *const i32,
    ahead: &[u8],
) -> [[f32; COLS]; M] {
    // Block b's operand, values, scales and corrections (moved on per block).
    let (mut ob, mut xs, mut ds, mut cs) = (w.b.as_ptr(), xq, xd, xc);
    // acc[m][h]: row m's sums of the blocks of parity h, lane = weight row.
    let mut acc = [[_mm512_setzero_ps(); 2]; M];
    // The next block of parity $h (a literal: the accumulators stay in
    // registers) into the accumulators, its pair's scales `$sv`.
    macro_rules! block {
        ($h:literal, $sv:expr) => {{
            // Register k, lane j: bytes 4k .. 4k + 4 of weight row j, stored unsigned (w + 128).
            let wv: [__m512i; 8] = core::array::from_fn(|k| {
                // SAFETY: the block's B_BLOCK operand bytes (fewer than nb blocks walked); 64k + 64 <= B_BLOCK.
                unsafe { _mm512_loadu_si512(ob.add(64 * k) as *const _) }
            });
            let sv: __m512 = $sv;
            for (m, am) in acc.iter_mut().enumerate() {
                // SAFETY: row m < M's corrections and scale of this block (the group's extents).
                let (c0, c1, xdb) = unsafe { (*cs.add(2 * m), *cs.add(2 * m + 1), *ds.add(m)) };
                // Two chains of 4: the even and odd 4-byte pieces of the block,
                // each starting from one of the block's two corrections
                // (broadcasts from memory: no shuffle-port work).
                let mut d0 = _mm512_set1_epi32(c0);
                let mut d1 = _mm512_set1_epi32(c1);
                for g in 0..4 {
                    // SAFETY: row m's 32 values of this block; 8g + 8 <= Q8_BLOCK.
                    let (x0, x1) = unsafe {
                        let xm = xs.add(Q8_BLOCK * m + 8 * g);
                        ((xm as *const i32).read_unaligned(), (xm.add(4) as *const i32).read_unaligned())
                    };
                    d0 = _mm512_dpbusd_epi32(d0, wv[2 * g], _mm512_set1_epi32(x0));
                    d1 = _mm512_dpbusd_epi32(d1, wv[2 * g + 1], _mm512_set1_epi32(x1));
                }
                let sum = _mm512_cvtepi32_ps(_mm512_add_epi32(d0, d1));
                am[$h] = _mm512_fmadd_ps(sum, _mm512_mul_ps(sv, _mm512_set1_ps(xdb)), am[$h]);
            }
            // SAFETY: one block on: at most one past the last of the nb blocks.
            unsafe {
                ob = ob.add(B_BLOCK);
                xs = xs.add(Q8_BLOCK * M);
                ds = ds.add(M);
                cs = cs.add(2 * M);
            }
        }};
    }
    let pairs = nb.div_ceil(2);
    // SAFETY: w.s[h] holds PAIRS >= pairs rows of 16 floats (p < pairs below).
    let scales = |h: usize, p: usize| unsafe { _mm512_loadu_ps(w.s[h][p].as_ptr()) };
    for p in 0..nb / 2 {
        super::prefetch_part(ahead, p, pairs);
        block!(0, scales(0, p));
        block!(1, scales(1, p));
    }
    if nb % 2 == 1 {
        super::prefetch_part(ahead, nb / 2, pairs);
        block!(0, scales(0, nb / 2));
    }
    // The pointers end one block past the last (not read again).
    let _ = (ob, xs, ds, cs);
    let mut out = [[0.0f32; COLS]; M];
    for (o, a) in out.iter_mut().zip(acc) {
        // SAFETY: o holds 16 floats.
        unsafe { _mm512_storeu_ps(o.as_mut_ptr(), _mm512_add_ps(a[0], a[1])) };
    }
    out
}
