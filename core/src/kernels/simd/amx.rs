//! Intel AMX-INT8 variant of the packed int8 GEMM ([`super::gemm_q8_packed`]),
//! 16 activation rows x one packed tile of 8 weight rows per tile multiply,
//! bit-identical to the AVX512-VNNI kernel ([`super::x86::gemm_q8_packed_vnni`]).
//!
//! Why it is bit-identical: the VNNI kernel forms, per weight row `n`, block
//! `b` and lane half `h` (values `8g + 4h .. 8g + 4h + 4` of the block's four
//! 8-byte groups `g`), the exact i32 sum `sum w x`, converts it to f32 and
//! adds `(s_n,b * xd_b) * sum` into lane `2n + h` with one FMA; the two
//! lanes of a row are added at the end. The tile multiply `tdpbssd` forms
//! the same i32 sums (signed x signed, no offset correction needed) if its
//! weight operand (`B`: K/4 rows of 16 four-byte columns) keeps, in row
//! `2g + h`, only the columns `2n + h` of the stored 8-byte group `g` (the
//! stored 64-byte line is exactly `[row 0 half 0, row 0 half 1, row 1
//! half 0, ...]`): [`AmxWeights::prepare`] lays that out once per packed tile.
//! With the activation block as the `A` row (32 bytes, natural order), the
//! 16 x 16 result tile is lane for lane the VNNI kernel's `dp`, and the f32
//! steps after it are the same instructions in the same order.
//!
//! Tile instructions fault unless the OS granted the process the tile
//! data state (Linux: `arch_prctl(ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA)`);
//! core cannot ask, so the std side does and then calls [`enable`]. Every
//! call loads its own tile configuration and releases the tiles before it
//! returns: no tile state outlives a call, and nothing else in the process
//! needs to know about it.
//!
//! The tile instructions are written as inline assembly (their intrinsics
//! are not stable Rust); the f32 steps use the AVX-512 intrinsics.

use core::arch::asm;
use core::arch::x86_64::*;
use core::sync::atomic::{AtomicBool, Ordering};

use super::{Isa, PackedQ8, PACK_BLOCKS, PACK_BLOCK_NIBBLES, PACK_BLOCK_SCALES, PACK_BLOCK_VALUES, Q8_BLOCK};

/// Activation rows per tile multiply (the rows of the `A` and `C` tiles).
pub const ROWS: usize = 16;
/// Bytes of one block's masked weight operand: 8 `B` rows of 64 bytes.
const B_BLOCK: usize = 512;

static ENABLED: AtomicBool = AtomicBool::new(false);

/// Lets [`gemm_q8_packed_amx`] run (`on`) or stops it.
///
/// # Safety
/// With `on`, the CPU must support amx-tile and amx-int8, and the OS must
/// have granted this process the AMX tile data state (on Linux,
/// `arch_prctl(ARCH_REQ_XCOMP_PERM, 18)` returned 0). The kernel runs only
/// while the selected ISA is [`Isa::Avx512Vnni`] (whose `set_isa` contract
/// covers the AVX-512 steps).
pub unsafe fn enable(on: bool) {
    ENABLED.store(on, Ordering::Relaxed);
}

/// Whether the AMX kernel runs: enabled and the selected ISA is AVX512-VNNI.
#[inline]
pub fn enabled() -> bool {
    ENABLED.load(Ordering::Relaxed) && super::isa() == Isa::Avx512Vnni
}

/// The `B` operands of one packed tile of 8 weight rows, per block 8 rows
/// of 64 bytes (row `2g + h`: the stored group-`g` line with only the
/// four-byte columns `2n + h` kept, the others zero; 4-bit tiles widened to
/// signed bytes first). At most [`PACK_BLOCKS`] blocks.
#[repr(C, align(64))]
pub struct AmxWeights {
    b: [u8; PACK_BLOCKS * B_BLOCK],
    nb: usize,
}

impl AmxWeights {
    pub fn new() -> Self {
        AmxWeights { b: [0; PACK_BLOCKS * B_BLOCK], nb: 0 }
    }

    /// Lays out `w`'s weight operands; false (and nothing usable) if the
    /// kernel does not run ([`enabled`]) or `w` has more than
    /// [`PACK_BLOCKS`] blocks.
    pub fn prepare(&mut self, w: PackedQ8<'_>) -> bool {
        self.nb = 0;
        if !enabled() {
            return false;
        }
        // SAFETY: `enabled` implies the Avx512Vnni ISA (avx512f/bw among its features).
        unsafe { self.prepare_raw(w) }
    }

    /// [`Self::prepare`] without the [`enabled`] check.
    ///
    /// # Safety
    /// The CPU must support avx512f and avx512bw.
    pub unsafe fn prepare_raw(&mut self, w: PackedQ8<'_>) -> bool {
        self.nb = 0;
        let nb = w.blocks();
        let per = if w.q4 { PACK_BLOCK_NIBBLES } else { PACK_BLOCK_VALUES };
        if nb > PACK_BLOCKS || w.v.len() < nb * per {
            return false;
        }
        // SAFETY: the caller's features; the extents were checked above.
        unsafe { prepare_b(w, nb, &mut self.b) };
        self.nb = nb;
        true
    }
}

impl Default for AmxWeights {
    fn default() -> Self {
        Self::new()
    }
}

/// [`AmxWeights::prepare`]'s layout.
///
/// # Safety
/// avx512f and avx512bw; `w.v` holds `nb` blocks, `out` `nb * B_BLOCK` bytes.
#[target_feature(enable = "avx512f,avx512bw")]
unsafe fn prepare_b(w: PackedQ8<'_>, nb: usize, out: &mut [u8]) {
    let low = _mm512_set1_epi8(0x0f);
    let eight = _mm512_set1_epi8(8);
    for (b, ob) in out.chunks_exact_mut(B_BLOCK).take(nb).enumerate() {
        let lines: [__m512i; 4] = if w.q4 {
            let vb = &w.v[PACK_BLOCK_NIBBLES * b..PACK_BLOCK_NIBBLES * (b + 1)];
            // SAFETY: vb holds 2 x 64 bytes.
            let h: [__m512i; 2] = core::array::from_fn(|k| unsafe { _mm512_loadu_si512(vb.as_ptr().add(64 * k) as *const _) });
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
        };
        for (g, line) in lines.iter().enumerate() {
            // SAFETY: ob holds 8 x 64 bytes; 128g + 64 + 64 <= 512.
            unsafe {
                _mm512_storeu_si512(ob.as_mut_ptr().add(128 * g) as *mut _, _mm512_maskz_mov_epi32(0x5555, *line));
                _mm512_storeu_si512(ob.as_mut_ptr().add(128 * g + 64) as *mut _, _mm512_maskz_mov_epi32(0xaaaa, *line));
            }
        }
    }
}

/// `out[m][n]` for the `out.len() / 16 * 16` activation rows `m` (row `m`:
/// `xq[m * stride..][..32 nb]`, `xd[m * nb..][..nb]`) and the 8 weight rows
/// of `w` (prepared from `s` by [`AmxWeights::prepare`]; `s` supplies the
/// scales): what [`super::gemm_q8_packed`] gives on AVX512-VNNI, bit for
/// bit. Returns the rows written: 0 when the kernel does not run
/// ([`enabled`]), the slices are short or `w` holds no prepared tile of
/// `s`'s blocks.
pub fn gemm_q8_packed_amx(w: &AmxWeights, s: PackedQ8<'_>, xq: &[i8], stride: usize, xd: &[f32], out: &mut [[f32; 8]]) -> usize {
    if !enabled() {
        return 0;
    }
    // SAFETY: `enabled` (see `enable`'s contract).
    unsafe { gemm_q8_packed_amx_raw(w, s, xq, stride, xd, out) }
}

/// [`gemm_q8_packed_amx`] without the [`enabled`] check.
///
/// # Safety
/// The CPU must support amx-tile, amx-int8, avx512f/bw/dq/vl, avx2, fma and
/// f16c, and the OS must have granted this process the tile data state
/// ([`request_linux_permission`]).
pub unsafe fn gemm_q8_packed_amx_raw(w: &AmxWeights, s: PackedQ8<'_>, xq: &[i8], stride: usize, xd: &[f32], out: &mut [[f32; 8]]) -> usize {
    let nb = w.nb;
    let rows = out.len() / ROWS * ROWS;
    let need_q = if rows == 0 { 0 } else { (rows - 1) * stride + nb * Q8_BLOCK };
    if rows == 0 || nb == 0 || s.blocks() != nb || s.s.len() < nb * PACK_BLOCK_SCALES || stride < nb * Q8_BLOCK || xq.len() < need_q || xd.len() < rows * nb {
        return 0;
    }
    // SAFETY: the caller's features and permission; the operand extents
    // were checked above: 16 rows of every tile of xq reach `need_q`, the
    // weight operands are `nb * B_BLOCK` bytes of `w.b`.
    unsafe { tiles_q8(&w.b[..nb * B_BLOCK], s.s, nb, xq, stride, xd, &mut out[..rows]) };
    rows
}

/// Whether the CPU reports AMX-TILE and AMX-INT8 (CPUID leaf 7, sub-leaf 0,
/// EDX bits 24 and 25). The OS must still grant the tile state before use.
pub fn cpu_has_amx_int8() -> bool {
    // SAFETY: every x86_64 CPU has CPUID; one without leaf 7 answers with
    // another leaf's bits (the OS then refuses the permission). The
    // instruction has no other effect.
    #[allow(unused_unsafe)]
    let edx = unsafe { __cpuid_count(7, 0) }.edx;
    edx & (3 << 24) == 3 << 24
}

/// Asks Linux for this process's AMX tile data permission
/// (`arch_prctl(ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA)`); true if granted
/// (also when it was granted before). Without AMX in the CPU or the kernel
/// the call fails and nothing changes.
#[cfg(target_os = "linux")]
pub fn request_linux_permission() -> bool {
    const ARCH_REQ_XCOMP_PERM: u64 = 0x1023;
    const XFEATURE_XTILEDATA: u64 = 18;
    const SYS_ARCH_PRCTL: u64 = 158;
    let ret: i64;
    // SAFETY: arch_prctl with this code only changes the process's
    // permitted extended-state set (or returns an error); it reads and
    // writes no memory of ours. `syscall` clobbers rcx and r11.
    unsafe {
        asm!("syscall", inlateout("rax") SYS_ARCH_PRCTL as i64 => ret, in("rdi") ARCH_REQ_XCOMP_PERM, in("rsi") XFEATURE_XTILEDATA,
            lateout("rcx") _, lateout("r11") _, options(nostack));
    }
    ret == 0
}

#[repr(C, align(64))]
struct TileConfig([u8; 64]);

/// Tile 0 and 3: C (16 x 64 bytes), tile 1: A (16 x 32 bytes), tiles 2 and
/// 4: B (8 x 64 bytes).
const fn config() -> TileConfig {
    let mut c = [0u8; 64];
    c[0] = 1; // palette 1
    let tiles: [(usize, u8, u16); 5] = [(0, 16, 64), (1, 16, 32), (2, 8, 64), (3, 16, 64), (4, 8, 64)];
    let mut i = 0;
    while i < tiles.len() {
        let (t, rows, colsb) = tiles[i];
        c[16 + 2 * t] = colsb as u8;
        c[17 + 2 * t] = (colsb >> 8) as u8;
        c[48 + t] = rows;
        i += 1;
    }
    TileConfig(c)
}
static CONFIG: TileConfig = config();

/// C tile (16 rows x 16 i32) as stored.
#[repr(C, align(64))]
struct CTile([i32; 256]);

/// `C(even) = A . B` into tile 0 (`EVEN`) or tile 3 (else).
///
/// # Safety
/// Tiles configured ([`CONFIG`]); `a` has 16 rows of 32 bytes at `stride`,
/// `b` 8 rows of 64 bytes.
#[inline(always)]
unsafe fn multiply<const EVEN: bool>(a: *const i8, stride: usize, b: *const u8) {
    // SAFETY: the caller's.
    unsafe {
        if EVEN {
            asm!("tilezero tmm0", "tileloadd tmm1, [{a} + {sa}]", "tileloadd tmm2, [{b} + {sb}]", "tdpbssd tmm0, tmm1, tmm2",
                a = in(reg) a, sa = in(reg) stride, b = in(reg) b, sb = in(reg) 64usize, options(nostack, readonly));
        } else {
            asm!("tilezero tmm3", "tileloadd tmm1, [{a} + {sa}]", "tileloadd tmm4, [{b} + {sb}]", "tdpbssd tmm3, tmm1, tmm4",
                a = in(reg) a, sa = in(reg) stride, b = in(reg) b, sb = in(reg) 64usize, options(nostack, readonly));
        }
    }
}

/// Stores C tile 0 (`EVEN`) or 3.
///
/// # Safety
/// Tiles configured; `c` is a whole [`CTile`].
#[inline(always)]
unsafe fn store<const EVEN: bool>(c: &mut CTile) {
    // SAFETY: the caller's; 16 rows x 64 bytes fill `c`.
    unsafe {
        if EVEN {
            asm!("tilestored [{c} + {sc}], tmm0", c = in(reg) c.0.as_mut_ptr(), sc = in(reg) 64usize, options(nostack));
        } else {
            asm!("tilestored [{c} + {sc}], tmm3", c = in(reg) c.0.as_mut_ptr(), sc = in(reg) 64usize, options(nostack));
        }
    }
}

/// The kernel of [`gemm_q8_packed_amx`] (extents checked there). Per 16-row
/// tile and block `b`: multiply block `b + 1` while block `b`'s result is
/// stored and block `b - 1`'s is scaled into the accumulators (two C tiles
/// and two stored copies alternate).
///
/// # Safety
/// As [`gemm_q8_packed_amx`]'s SAFETY note: AMX usable, the Avx512Vnni
/// features, and the extents it checked.
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx2,fma,f16c")]
unsafe fn tiles_q8(wb: &[u8], s: &[u8], nb: usize, xq: &[i8], stride: usize, xd: &[f32], out: &mut [[f32; 8]]) {
    let dup = _mm512_setr_epi32(0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7);
    let mut c = [CTile([0; 256]), CTile([0; 256])];
    // SAFETY: CONFIG is a valid palette-1 configuration.
    unsafe { asm!("ldtilecfg [{0}]", in(reg) CONFIG.0.as_ptr(), options(nostack, readonly)) };
    for (t, ot) in out.chunks_exact_mut(ROWS).enumerate() {
        let a = &xq[t * ROWS * stride..];
        let d = &xd[t * ROWS * nb..(t + 1) * ROWS * nb];
        let mut acc = [_mm512_setzero_ps(); ROWS];
        // SAFETY: block 0 of 16 rows of `a` and of `wb` (extents checked by the caller).
        unsafe { multiply::<true>(a.as_ptr(), stride, wb.as_ptr()) };
        for b in 0..=nb {
            if b < nb {
                if b + 1 < nb {
                    let (ap, bp) = (a[32 * (b + 1)..].as_ptr(), wb[B_BLOCK * (b + 1)..].as_ptr());
                    // SAFETY: block b + 1 < nb, as for block 0.
                    unsafe {
                        if b % 2 == 0 {
                            multiply::<false>(ap, stride, bp)
                        } else {
                            multiply::<true>(ap, stride, bp)
                        }
                    }
                }
                // SAFETY: tiles configured; block b's result is in tile 0 (b even) or 3.
                unsafe {
                    if b % 2 == 0 {
                        store::<true>(&mut c[0])
                    } else {
                        store::<false>(&mut c[1])
                    }
                }
            }
            if b == 0 {
                continue;
            }
            let p = b - 1;
            let cp = &c[p % 2].0;
            // SAFETY: s holds nb x 8 f16 (16 bytes per block).
            let sv = _mm512_permutexvar_ps(dup, _mm512_castps256_ps512(_mm256_cvtph_ps(unsafe { _mm_loadu_si128(s[PACK_BLOCK_SCALES * p..].as_ptr() as *const __m128i) })));
            for (m, am) in acc.iter_mut().enumerate() {
                // SAFETY: row m of the stored tile: 16 i32 at 16m (aligned).
                let dp = unsafe { _mm512_load_si512(cp[16 * m..].as_ptr() as *const _) };
                *am = _mm512_fmadd_ps(_mm512_cvtepi32_ps(dp), _mm512_mul_ps(sv, _mm512_set1_ps(d[m * nb + p])), *am);
            }
        }
        for (o, a) in ot.iter_mut().zip(acc) {
            // Lane pairs (2n, 2n + 1) are row n, as in the VNNI kernel.
            let pairs = _mm512_add_ps(a, _mm512_permute_ps::<0b10_11_00_01>(a));
            let mut v = [0f32; 16];
            // SAFETY: v holds 16 floats.
            unsafe { _mm512_storeu_ps(v.as_mut_ptr(), pairs) };
            for (n, on) in o.iter_mut().enumerate() {
                *on = v[2 * n];
            }
        }
    }
    // SAFETY: tiles configured above; releasing returns them to the init state.
    unsafe { asm!("tilerelease", options(nostack, nomem)) };
}
