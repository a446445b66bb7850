//! Two packed tiles of 8 weight rows as one operand of 16 four-byte
//! columns ([`TilePair`]), laid out once per tile pair of a GEMM, and the
//! VNNI kernels over it ([`gemm_q8_pair`]: AVX-512 VNNI, and AVX-VNNI on
//! 32-byte vectors, two activation rows at a time; on AVX2 without VNNI a
//! layout of its own, [`TilePair::wide`], and `vpmaddwd`): up to
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
/// Blocks of the widest pair laid out wide (its i16 values fill the operand).
pub const WIDE_BLOCKS: usize = PACK_BLOCKS / 2;
/// Block pairs of the widest prepared tile.
pub(super) const PAIRS: usize = PACK_BLOCKS.div_ceil(2);
/// Weight rows of a prepared pair: the kernels' output columns.
pub const COLS: usize = 2 * PACK_ROWS;
/// Most activation rows per call of [`gemm_q8_pair`]: 16 accumulators, the
/// block's 8 weight registers and the temporaries fit the 32 registers.
pub const PAIR_CALL_ROWS: usize = 8;

/// Whether the tile pair kernels run: the selected ISA is AVX-512 VNNI
/// ([`gemm_q8_pair_raw`]), AVX-VNNI ([`gemm_q8_pair_avxvnni_raw`], the
/// same operand on 32-byte vectors) or AVX2 / AVX-512 without VNNI
/// ([`gemm_q8_pair_avx2_raw`] over the wide layout: [`wide_isa`]).
#[inline]
pub fn enabled() -> bool {
    matches!(super::isa(), Isa::Avx512Vnni | Isa::AvxVnni) || wide_isa()
}

/// Whether the selected ISA takes the wide layout ([`TilePair::wide`]):
/// AVX2, and AVX-512 without VNNI (its kernel on 32-byte vectors). The VNNI
/// operand with `vpmaddubsw` and the sign trick instead (4 instructions per
/// 32 products) was no faster than the 8-row kernel there (42-50% of the
/// AVX2 peak against 43-54%, Intel Xeon capped to AVX2, 2026-12-06).
#[inline]
pub fn wide_isa() -> bool {
    matches!(super::isa(), Isa::Avx2 | Isa::Avx512)
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
    /// Per tile: laid out wide (the AVX2 kernel's operand,
    /// [`prepare_b_wide`]: per block, 1024 bytes, and pair `j` of values,
    /// the tile's 8 rows' values `2j, 2j + 1` as i16 at byte `64 j + 32 t`;
    /// at most [`WIDE_BLOCKS`] blocks) instead of in 4-byte pieces.
    pub(super) wide: [bool; 2],
}

impl TilePair {
    pub fn new() -> Self {
        TilePair {
            b: [0; PACK_BLOCKS * B_BLOCK],
            s: [[[0.0; 16]; PAIRS]; 2],
            nb: [0; 2],
            unsigned: [false; 2],
            wide: [false; 2],
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
        if wide_isa() {
            // SAFETY: the Avx2 and Avx512 ISAs' `set_isa` contract covers avx2 and f16c.
            return unsafe { self.prepare_raw_wide(half, w) };
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
        if !enabled() || super::isa() == Isa::AvxVnni || wide_isa() || w0.blocks() != w1.blocks() {
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
        self.wide = [false; 2];
        true
    }

    /// Whether both tiles are stored unsigned: the operand the pair
    /// kernels take (signed pairs are the AMX kernel's).
    pub fn unsigned(&self) -> bool {
        self.unsigned == [true; 2]
    }

    /// Whether both tiles are laid out wide: the operand the AVX2 pair
    /// kernel takes ([`gemm_q8_pair_avx2_raw`]).
    pub fn wide(&self) -> bool {
        self.wide == [true; 2]
    }

    /// Whether the pair kernel of the selected ISA takes this operand as
    /// laid out ([`gemm_q8_pair`]; false for the AMX kernel's signed pairs).
    pub fn ready(&self) -> bool {
        if wide_isa() {
            self.wide()
        } else {
            self.unsigned()
        }
    }

    /// Tile `half` laid out wide ([`Self::wide`]) without the ISA check.
    ///
    /// # Safety
    /// The CPU must support avx2 and f16c.
    pub unsafe fn prepare_raw_wide(&mut self, half: usize, w: PackedQ8<'_>) -> bool {
        let Some(nb) = self.checked_blocks(half, w).filter(|&nb| nb <= WIDE_BLOCKS) else {
            return false;
        };
        // SAFETY: the caller's features; the extents were checked above.
        unsafe { prepare_b_wide(w, nb, half, &mut self.b, &mut self.s) };
        self.nb[half] = nb;
        self.unsigned[half] = false;
        self.wide[half] = true;
        true
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
        self.wide[half] = false;
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
        self.wide[half] = false;
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

/// Block `b`'s four 64-byte lines of a packed tile as signed bytes (4-bit
/// tiles widened to `q - 8`), on 32-byte vectors: `[g][i]` = bytes `32 i ..
/// 32 i + 32` of line `g` (rows `4 i .. 4 i + 4`, 8 bytes each).
///
/// # Safety
/// avx2; `w.v` holds block `b`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn block_lines_avx2(w: PackedQ8<'_>, b: usize) -> [[__m256i; 2]; 4] {
    if w.q4 {
        let (low, eight) = (_mm256_set1_epi8(0x0f), _mm256_set1_epi8(8));
        let vb = &w.v[PACK_BLOCK_NIBBLES * b..PACK_BLOCK_NIBBLES * (b + 1)];
        // SAFETY: vb holds 4 x 32 bytes.
        let h: [__m256i; 4] = core::array::from_fn(|k| unsafe {
            _mm256_loadu_si256(vb.as_ptr().add(32 * k) as *const _)
        });
        let lo = |v: __m256i| _mm256_sub_epi8(_mm256_and_si256(v, low), eight);
        let hi =
            |v: __m256i| _mm256_sub_epi8(_mm256_and_si256(_mm256_srli_epi16::<4>(v), low), eight);
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
    }
}

/// [`TilePair::prepare_raw_wide`]'s layout of tile `half`: per block (1024
/// bytes), line `g` (8 rows x 8 bytes) transposed at 2-byte grain into the
/// four pairs `j = 4 g .. 4 g + 4` (row `n`'s bytes `2j, 2j + 1` at `2n`),
/// each widened to 16 i16 (`vpmovsxbw`, exact) and stored at byte `64 j +
/// 32 half`; the scales as [`prepare_scales`].
///
/// # Safety
/// avx2 and f16c; `w.v` holds `nb` blocks, `w.s` their scales, `out` `nb *
/// 2 B_BLOCK` bytes, `nb <= WIDE_BLOCKS`.
#[target_feature(enable = "avx2,f16c")]
unsafe fn prepare_b_wide(
    w: PackedQ8<'_>,
    nb: usize,
    half: usize,
    out: &mut [u8],
    scales: &mut [[[f32; 16]; PAIRS]; 2],
) {
    for (b, ob) in out.chunks_exact_mut(2 * B_BLOCK).take(nb).enumerate() {
        // SAFETY: w holds block b < nb (the caller's); the caller's features.
        let lines = unsafe { block_lines_avx2(w, b) };
        for (g, [l0, l1]) in lines.iter().enumerate() {
            // 16-bit words: row r's pair p of this line is word 4r + p.
            let (r01, r23) = (
                _mm256_castsi256_si128(*l0),
                _mm256_extracti128_si256::<1>(*l0),
            );
            let (r45, r67) = (
                _mm256_castsi256_si128(*l1),
                _mm256_extracti128_si256::<1>(*l1),
            );
            // [r0p0 r2p0 r0p1 r2p1 ..], [r1p0 r3p0 ..], likewise rows 4-7.
            let (t0, t1) = (_mm_unpacklo_epi16(r01, r23), _mm_unpackhi_epi16(r01, r23));
            let (t2, t3) = (_mm_unpacklo_epi16(r45, r67), _mm_unpackhi_epi16(r45, r67));
            // [r0p0 r1p0 r2p0 r3p0 r0p1 r1p1 r2p1 r3p1], then p2, p3; likewise rows 4-7.
            let (u0, u1) = (_mm_unpacklo_epi16(t0, t1), _mm_unpackhi_epi16(t0, t1));
            let (u2, u3) = (_mm_unpacklo_epi16(t2, t3), _mm_unpackhi_epi16(t2, t3));
            let pairs = [
                _mm_unpacklo_epi64(u0, u2),
                _mm_unpackhi_epi64(u0, u2),
                _mm_unpacklo_epi64(u1, u3),
                _mm_unpackhi_epi64(u1, u3),
            ];
            for (p, v) in pairs.into_iter().enumerate() {
                // SAFETY: ob holds 2 B_BLOCK = 1024 bytes; 64 (4g + p) + 32 half + 32 <= 1024.
                unsafe {
                    _mm256_storeu_si256(
                        ob.as_mut_ptr().add(64 * (4 * g + p) + 32 * half) as *mut _,
                        _mm256_cvtepi8_epi16(v),
                    )
                };
            }
        }
    }
    // SAFETY: the caller's features include f16c; the extents are the caller's.
    unsafe { prepare_scales(w, nb, half, scales) };
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
    let flip = _mm256_set1_epi8(if unsigned { -128 } else { 0 });
    // A stored line's 32-byte half holds 4 rows' (h = 0, h = 1) dword pairs:
    // the even dwords (h = 0) to its low 128 bits, the odd ones to its high.
    let split = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
    for (b, ob) in out.chunks_exact_mut(B_BLOCK).take(nb).enumerate() {
        // SAFETY: w holds block b < nb (the caller's); the caller's features.
        let lines = unsafe { block_lines_avx2(w, b) };
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
        // SAFETY: the Avx2 and Avx512 ISAs' `set_isa` contract covers avx2, fma and f16c.
        Isa::Avx2 | Isa::Avx512 => unsafe { gemm_q8_pair_avx2_raw(w, xq, xd, n_in, ahead) },
        _ => None,
    }
}

/// The blocks [`gemm_q8_pair`] runs over, or None where it refuses (see
/// there): for the VNNI kernels (`wide` false) both tiles stored unsigned,
/// for the AVX2 kernel both laid out wide (it reads no corrections: pass
/// `&[]`).
fn call_blocks<const M: usize>(
    w: &TilePair,
    xq: &[i8],
    xd: &[f32],
    xc: &[i32],
    n_in: usize,
    wide: bool,
) -> Option<usize> {
    let rb = n_in / Q8_BLOCK;
    if M == 0
        || M > PAIR_CALL_ROWS
        || w.nb[0] != w.nb[1]
        || (if wide { !w.wide() } else { !w.unsigned() })
        || xq.len() < M * n_in
        || xd.len() < M * rb
        || (!wide && xc.len() < 2 * M * rb)
    {
        return None;
    }
    Some(w.nb[0].min(PACK_BLOCKS).min(rb))
}

/// `$block!(h, p)` for blocks `0..$nb` in order (block `2p + h`: parity
/// `h` as a literal, so that a kernel's accumulators stay in registers), the
/// prefetch of `$ahead` spread over the block pairs.
macro_rules! each_block {
    ($nb:expr, $ahead:expr, $block:ident) => {{
        let pairs = $nb.div_ceil(2);
        for p in 0..$nb / 2 {
            super::prefetch_part($ahead, p, pairs);
            $block!(0, p);
            $block!(1, p);
        }
        if $nb % 2 == 1 {
            super::prefetch_part($ahead, $nb / 2, pairs);
            $block!(0, $nb / 2);
        }
    }};
}

/// [`gemm_q8_pair`] on AVX2 (and AVX-512 without VNNI) without the ISA
/// check, over the wide layout ([`TilePair::wide`]): the same values as the
/// 8-row kernels per tile, bit for bit. The rows go in passes of at most 4
/// ([`super::even_passes`]: 5 = 3 + 2), each on [`pair_avx2`].
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
pub unsafe fn gemm_q8_pair_avx2_raw<const M: usize>(
    w: &TilePair,
    xq: &[i8],
    xd: &[f32],
    n_in: usize,
    ahead: &[u8],
) -> Option<[[f32; COLS]; M]> {
    let nb = call_blocks::<M>(w, xq, xd, &[], n_in, true)?;
    let mut out = [[0.0f32; COLS]; M];
    let passes = M.div_ceil(4).max(1);
    let (q, d) = (xq.as_ptr(), xd.as_ptr());
    let mut k = 0;
    super::even_passes(M, 4, &mut |m0, r| {
        let (a0, a1) = super::part_bytes(ahead.len(), k, passes);
        k += 1;
        let share = &ahead[a0..a1];
        macro_rules! pass {
            ($r:literal) => {
                // SAFETY: the caller's features; rows m0 .. m0 + r of the
                // group (even_passes stays inside M), whose extents and the
                // pair's were checked by call_blocks.
                out[m0..m0 + $r]
                    .copy_from_slice(&unsafe { pair_avx2::<$r>(w, nb, M, m0, q, d, share) })
            };
        }
        match r {
            1 => pass!(1),
            2 => pass!(2),
            3 => pass!(3),
            _ => pass!(4),
        }
    });
    Some(out)
}

/// Rows `m0 .. m0 + R` (`R <= 4`) of a call group of `rows` rows
/// ([`pair_vnni`]'s layout, corrections unused) against the pair laid out
/// wide: per block, each row's 32 values widened to i16 once; per pair `j`
/// of values, each tile's 16 i16 (lane `n` = weight row `n`'s values `2j,
/// 2j + 1`) multiplied by the row's pair broadcast (`vpmaddwd`) and added
/// into the row's sums: lane `n` ends as row `n`'s exact block sum, with no
/// sign trick and no horizontal adds. Then the f32 steps of every other
/// pair kernel, in the same order.
///
/// Why: the 8-row AVX2 kernel's sign trick takes a third multiply-pipe
/// instruction per 32 products (on the AMD EPYC, Zen 4, a register-only
/// loop of it ran at 73.5 GMAC/s, one of `vpmaddwd` + `vpaddd` at 94). In
/// `linear` there (`bench --isa avx2 --kernels`, 2026-12-08): the R step's
/// fc and q/k/v/proj GEMMs 59-61 GMAC/s against 49-53 (50-52% of the AVX2
/// peak against 42-45%). With the weights stored as i8 and widened in the
/// kernel instead it was no faster than the 8-row kernel; stored as i16
/// they fill the operand at [`WIDE_BLOCKS`] blocks, so rows of 3072 values
/// (fc_out) keep the 8-row kernel.
///
/// # Safety
/// avx2, fma, f16c; `nb <= PACK_BLOCKS`, both tiles of `w` laid out wide
/// with at least `nb` blocks, `m0 + R <= rows`, and `xq`, `xd` hold `nb`
/// blocks of `rows` rows as [`super::pair_group_index`] lays them out.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx2,fma,f16c")]
unsafe fn pair_avx2<const R: usize>(
    w: &TilePair,
    nb: usize,
    rows: usize,
    m0: usize,
    xq: *const i8,
    xd: *const f32,
    ahead: &[u8],
) -> [[f32; COLS]; R] {
    // Block b's operand, values and scales (moved on per block).
    // SAFETY (pointer offsets): row m0's entries of block 0 (m0 < rows).
    let (mut ob, mut xs, mut ds) = unsafe { (w.b.as_ptr(), xq.add(Q8_BLOCK * m0), xd.add(m0)) };
    // acc[m][h][t]: row m's sums of the blocks of parity h, tile t (lane = weight row).
    let mut acc = [[[_mm256_setzero_ps(); 2]; 2]; R];
    // xw[m]: row m's 32 values of the block, widened.
    let mut xw = [[0i16; Q8_BLOCK]; R];
    macro_rules! block {
        ($h:literal, $p:expr) => {{
            for (m, xm) in xw.iter_mut().enumerate() {
                // SAFETY: row m's 32 values of this block (the group's extents); xm holds 32 i16.
                unsafe {
                    let x = xs.add(Q8_BLOCK * m) as *const __m128i;
                    let xp = xm.as_mut_ptr() as *mut __m256i;
                    _mm256_storeu_si256(xp, _mm256_cvtepi8_epi16(_mm_loadu_si128(x)));
                    _mm256_storeu_si256(xp.add(1), _mm256_cvtepi8_epi16(_mm_loadu_si128(x.add(1))));
                }
            }
            // d[m][t]: row m's block sums against tile t.
            let mut d = [[_mm256_setzero_si256(); 2]; R];
            for j in 0..Q8_BLOCK / 2 {
                // Tile t's pair j: 16 i16 (lane n = weight row n's values 2j, 2j + 1).
                // SAFETY: the block's 2 B_BLOCK operand bytes (i16); 64j + 32t + 32 <= 2 B_BLOCK.
                let wv: [__m256i; 2] = core::array::from_fn(|t| unsafe {
                    _mm256_loadu_si256(ob.add(64 * j + 32 * t) as *const _)
                });
                for (m, dm) in d.iter_mut().enumerate() {
                    // SAFETY: values 2j, 2j + 1 of xw[m] (2j + 2 <= 32).
                    let x = unsafe { (xw[m].as_ptr().add(2 * j) as *const i32).read_unaligned() };
                    let xb = _mm256_set1_epi32(x);
                    for t in 0..2 {
                        dm[t] = _mm256_add_epi32(dm[t], _mm256_madd_epi16(wv[t], xb));
                    }
                }
            }
            // SAFETY: w.s[h] holds PAIRS >= pairs rows of 16 floats (p < pairs).
            let sv: [__m256; 2] = core::array::from_fn(|t| unsafe {
                _mm256_loadu_ps(w.s[$h][$p].as_ptr().add(8 * t))
            });
            // SAFETY: rows m < R's scales of this block (the group's extents).
            unsafe { ymm_block_sums::<R, $h>(&mut acc, &sv, &d, ds) };
            // SAFETY: one block on: at most one past the last of the nb blocks.
            unsafe {
                ob = ob.add(2 * B_BLOCK);
                xs = xs.add(Q8_BLOCK * rows);
                ds = ds.add(rows);
            }
        }};
    }
    each_block!(nb, ahead, block);
    let _ = (ob, xs, ds);
    // SAFETY: the caller's features (avx).
    unsafe { ymm_pair_out(acc) }
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
    let nb = call_blocks::<M>(w, xq, xd, xc, n_in, false)?;
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
            // SAFETY: rows m < R's scales of this block (the group's extents).
            unsafe { ymm_block_sums::<R, $h>(&mut acc, &sv, &d, ds) };
            // SAFETY: one block on: at most one past the last of the nb blocks.
            unsafe {
                ob = ob.add(B_BLOCK);
                xs = xs.add(Q8_BLOCK * rows);
                ds = ds.add(rows);
                cs = cs.add(2 * rows);
            }
        }};
    }
    each_block!(nb, ahead, block);
    let _ = (ob, xs, ds, cs);
    // SAFETY: the caller's features (avx).
    unsafe { ymm_pair_out(acc) }
}

/// The f32 steps of one block for the 32-byte pair kernels: per row `m`
/// and tile `t`, `acc[m][H][t] += f32(d[m][t]) * (sv[t] * xd_m)`, `xd_m` =
/// `*ds.add(m)` (the row's block scale).
///
/// # Safety
/// avx and fma (inlined into callers that have them); `ds` holds `R` scales.
#[inline(always)]
unsafe fn ymm_block_sums<const R: usize, const H: usize>(
    acc: &mut [[[__m256; 2]; 2]; R],
    sv: &[__m256; 2],
    d: &[[__m256i; 2]; R],
    ds: *const f32,
) {
    for (m, am) in acc.iter_mut().enumerate() {
        // SAFETY: row m's scale of this block (the caller's extents); the caller's features.
        unsafe {
            let xdb = _mm256_set1_ps(*ds.add(m));
            for t in 0..2 {
                am[H][t] = _mm256_fmadd_ps(
                    _mm256_cvtepi32_ps(d[m][t]),
                    _mm256_mul_ps(sv[t], xdb),
                    am[H][t],
                );
            }
        }
    }
}

/// The 32-byte pair kernels' result: per row, each tile's even and odd
/// block sums added (`acc[m][0][t] + acc[m][1][t]` into columns `8t ..`).
///
/// # Safety
/// avx (inlined into callers that have it).
#[inline(always)]
unsafe fn ymm_pair_out<const R: usize>(acc: [[[__m256; 2]; 2]; R]) -> [[f32; COLS]; R] {
    let mut out = [[0.0f32; COLS]; R];
    for (o, a) in out.iter_mut().zip(acc) {
        for t in 0..2 {
            // SAFETY: o holds 16 floats (8t + 8 <= 16); the caller's features.
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
    let nb = call_blocks::<M>(w, xq, xd, xc, n_in, false)?;
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
