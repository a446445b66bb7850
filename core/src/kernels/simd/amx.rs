//! Intel AMX-INT8 variant of the packed int8 GEMM ([`super::gemm_q8_packed`]):
//! 12 (or 8) activation rows x two packed tiles (16 weight rows) per tile multiply,
//! bit-identical to the AVX512-VNNI kernel ([`super::x86::gemm_q8_packed_vnni`]).
//!
//! Why it is bit-identical: the VNNI kernel forms, per weight row `n` and
//! block `b`, the exact i32 block sum `sum w x`, converts it to f32 and adds
//! `(s_n,b * xd_b) * sum` with one FMA into lane `2n` (even blocks) or `2n +
//! 1` (odd blocks) of its accumulator; the two lanes of a row are added at
//! the end. The tile multiply `tdpbssd` forms the same i32 sums (signed x
//! signed, no offset correction needed) with the activation block as the
//! `A` row (32 bytes, natural order) and a weight operand (`B`: 8 rows of
//! 16 four-byte columns, one column per weight row) whose row `2g + h` holds
//! the four-byte halves `h` of the 16 rows' stored 8-byte groups `g`
//! ([`TilePair::prepare`] lays that out once per packed tile). Per
//! activation row, two blocks' result rows are interleaved into the VNNI
//! lane order and the f32 steps after that are the VNNI kernel's, in the
//! same order.
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

use crate::kernels::parallel::Window;

use super::x86::gelu16;
use super::{Isa, PACK_BLOCKS, Q8_BLOCK};

/// Activation rows per tile multiply: groups of 12, and of [`ROWS_SMALL`]
/// where 12s leave 8-11 rows ([`groups`]). Measured (2026-12-03, the Xeon
/// with AMX, one tile pair hot, 96 rows, time per row against 8-row
/// groups): 10 rows 0.90 / 0.84x (768 / 3072 wide), 12 rows 0.80-0.88 /
/// 0.79-0.84x, 14 rows 1.05 / 1.00x, 16 rows 1.03 / 0.95x: the tile multiplies
/// cost little more for 12 rows than for 8, and the 24 accumulators of 12
/// rows still fit the registers (16 rows: 32, which spill).
pub const ROWS: usize = 12;
/// The smaller activation row group.
pub const ROWS_SMALL: usize = 8;

/// (groups of [`ROWS`], groups of [`ROWS_SMALL`]) the kernel takes of
/// `rows` activation rows: every multiple of 4 from 8 on is covered whole,
/// at most 3 rows (or 4-7 of fewer than 8) are left to the caller.
pub fn groups(rows: usize) -> (usize, usize) {
    let k = rows / 4;
    match k % 3 {
        0 => (k / 3, 0),
        2 => (k / 3, 1),
        _ if k >= 4 => (k / 3 - 1, 2),
        _ => (0, 0),
    }
}

/// Weight rows per tile multiply: two packed tiles (the `B` and `C` columns).
pub use super::tile_pair::COLS;
use super::tile_pair::{TilePair, B_BLOCK, PAIRS};

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

/// Row `m` of `out`, column `8t + n` = `bias[8t + n] + y` (`0 + y`
/// without a bias), then GELU of it where `gelu`
/// ([`super::bias_act`]), with `y` what [`super::gemm_q8_packed`] gives on
/// AVX512-VNNI for activation row `m` (`xq[m * stride..][..32 nb]`,
/// `xd[m * nb..][..nb]`) and weight row `n` of tile `t` prepared in `w`
/// ([`TilePair::prepare`]), bit for bit; for the first `out.cols()`
/// (at most [`COLS`]) columns of the first whole row groups of `out`'s
/// rows ([`amx_rows`]). The results go straight to `out` as each row group
/// finishes, between the tile multiplies of the next (not in one burst
/// after the call, whose stores to rows a window apart waited for their
/// cache lines). Returns the rows written: 0 when the kernel does not run
/// ([`enabled`]), the slices are short, `out` is wider than [`COLS`] or
/// the bias than... shorter than `out.cols()`, or `w` does not hold two
/// tiles of the same blocks. The lines of `ahead` (the weights the caller
/// reads next) are prefetched into L2 a few per block pair, spread over the
/// call, so their memory reads overlap the tile multiplies; no result
/// depends on it.
#[allow(clippy::too_many_arguments)]
pub fn gemm_q8_packed_amx(
    w: &TilePair,
    xq: &[i8],
    stride: usize,
    xd: &[f32],
    out: Window<'_>,
    bias: Option<&[f32]>,
    gelu: bool,
    ahead: &[u8],
) -> usize {
    if !enabled() {
        return 0;
    }
    // SAFETY: `enabled` (see `enable`'s contract).
    unsafe { gemm_q8_packed_amx_raw(w, xq, stride, xd, out, bias, gelu, ahead) }
}

/// The activation rows [`gemm_q8_packed_amx`] computes of `rows` rows of
/// `nb` blocks with these operand extents (the first rows, in whole groups:
/// [`groups`]; 0 if it would refuse them).
pub fn amx_rows(nb: usize, xq_len: usize, stride: usize, xd_len: usize, rows: usize) -> usize {
    let (a, b) = groups(rows);
    let rows = a * ROWS + b * ROWS_SMALL;
    let need_q = if rows == 0 {
        0
    } else {
        (rows - 1) * stride + nb * Q8_BLOCK
    };
    if rows == 0
        || nb == 0
        || nb > PACK_BLOCKS
        || stride < nb * Q8_BLOCK
        || xq_len < need_q
        || xd_len < rows * nb
    {
        return 0;
    }
    rows
}

/// [`gemm_q8_packed_amx`] without the [`enabled`] check.
///
/// # Safety
/// The CPU must support amx-tile, amx-int8, avx512f/bw/dq/vl, avx2, fma and
/// f16c, and the OS must have granted this process the tile data state
/// ([`request_linux_permission`]).
#[allow(clippy::too_many_arguments)]
pub unsafe fn gemm_q8_packed_amx_raw(
    w: &TilePair,
    xq: &[i8],
    stride: usize,
    xd: &[f32],
    out: Window<'_>,
    bias: Option<&[f32]>,
    gelu: bool,
    ahead: &[u8],
) -> usize {
    let nb = w.nb[0];
    let rows = amx_rows(nb, xq.len(), stride, xd.len(), out.rows());
    if rows == 0
        || w.nb[1] != nb
        || w.unsigned != [false; 2]
        || out.cols() > COLS
        || bias.is_some_and(|b| b.len() < out.cols())
    {
        return 0;
    }
    let e = Tail { bias, gelu };
    // SAFETY: the caller's features and permission; the operand extents
    // were checked by `amx_rows`: every row of every group lies within
    // `need_q` of xq, the weight operands are `nb * B_BLOCK` bytes of `w.b`.
    let big = groups(rows).0 * ROWS;
    let (o_big, o_small) = out.split_rows(big);
    // SAFETY: as above; the small groups' rows start `big` rows further in
    // `xq` and `xd` (inside the checked extents). `ahead` goes to the first call.
    unsafe {
        tiles_q8::<ROWS>(
            &w.b[..nb * B_BLOCK],
            &w.s,
            nb,
            xq,
            stride,
            xd,
            o_big,
            e,
            ahead,
        );
        tiles_q8::<ROWS_SMALL>(
            &w.b[..nb * B_BLOCK],
            &w.s,
            nb,
            &xq[big * stride..],
            stride,
            &xd[big * nb..],
            o_small.split_rows(rows - big).0,
            e,
            if big > 0 { &[] } else { ahead },
        );
    }
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

/// The epilogue [`gemm_q8_packed_amx`] applies to its results.
#[derive(Clone, Copy)]
struct Tail<'b> {
    bias: Option<&'b [f32]>,
    gelu: bool,
}

/// The first `n` (at most 16) lanes.
#[inline]
fn lanes(n: usize) -> __mmask16 {
    ((1u32 << n.min(16)) - 1) as __mmask16
}

#[repr(C, align(64))]
struct TileConfig([u8; 64]);

/// C tiles 0, 3 (even block pairs) and 6, 7 (odd pairs): `r` x 64 bytes;
/// A tiles 1 and 5: `r` x 32 bytes; B tiles 2 and 4: 8 x 64 bytes.
const fn config(r: u8) -> TileConfig {
    let mut c = [0u8; 64];
    c[0] = 1; // palette 1
    let tiles: [(usize, u8, u16); 8] = [
        (0, r, 64),
        (1, r, 32),
        (2, 8, 64),
        (3, r, 64),
        (4, 8, 64),
        (5, r, 32),
        (6, r, 64),
        (7, r, 64),
    ];
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
static CONFIG: TileConfig = config(ROWS as u8);
static CONFIG_SMALL: TileConfig = config(ROWS_SMALL as u8);

/// The C tiles of one block pair (up to [`ROWS`] rows x 16 i32 each) as stored.
#[repr(C, align(64))]
struct CPair([[i32; 16 * ROWS]; 2]);

/// The C tiles of block pair `p` = blocks `2p` and `2p + 1` (the second
/// only if `two`): `tmm0`/`tmm3` for even `p` (`EVEN`), `tmm6`/`tmm7` for odd.
///
/// # Safety
/// Tiles configured ([`CONFIG`] or [`CONFIG_SMALL`]); `a` has as many rows of 32 (64 if `two`) bytes
/// at `stride`, `b` 8 (16 if `two`) rows of 64 bytes.
#[inline(always)]
unsafe fn multiply<const EVEN: bool>(a: *const i8, stride: usize, b: *const u8, two: bool) {
    // SAFETY: the caller's; the second block's operands are 32 bytes
    // further in `a` and `B_BLOCK` bytes further in `b`.
    unsafe {
        let (a1, b1) = (a.add(32), b.add(B_BLOCK));
        match (EVEN, two) {
            (true, true) => {
                asm!("tilezero tmm0", "tileloadd tmm1, [{a} + {sa}]", "tileloadd tmm2, [{b} + {sb}]", "tdpbssd tmm0, tmm1, tmm2",
                "tilezero tmm3", "tileloadd tmm5, [{a1} + {sa}]", "tileloadd tmm4, [{b1} + {sb}]", "tdpbssd tmm3, tmm5, tmm4",
                a = in(reg) a, a1 = in(reg) a1, sa = in(reg) stride, b = in(reg) b, b1 = in(reg) b1, sb = in(reg) 64usize, options(nostack, readonly))
            }
            (true, false) => {
                asm!("tilezero tmm0", "tileloadd tmm1, [{a} + {sa}]", "tileloadd tmm2, [{b} + {sb}]", "tdpbssd tmm0, tmm1, tmm2",
                a = in(reg) a, sa = in(reg) stride, b = in(reg) b, sb = in(reg) 64usize, options(nostack, readonly))
            }
            (false, true) => {
                asm!("tilezero tmm6", "tileloadd tmm1, [{a} + {sa}]", "tileloadd tmm2, [{b} + {sb}]", "tdpbssd tmm6, tmm1, tmm2",
                "tilezero tmm7", "tileloadd tmm5, [{a1} + {sa}]", "tileloadd tmm4, [{b1} + {sb}]", "tdpbssd tmm7, tmm5, tmm4",
                a = in(reg) a, a1 = in(reg) a1, sa = in(reg) stride, b = in(reg) b, b1 = in(reg) b1, sb = in(reg) 64usize, options(nostack, readonly))
            }
            (false, false) => {
                asm!("tilezero tmm6", "tileloadd tmm1, [{a} + {sa}]", "tileloadd tmm2, [{b} + {sb}]", "tdpbssd tmm6, tmm1, tmm2",
                a = in(reg) a, sa = in(reg) stride, b = in(reg) b, sb = in(reg) 64usize, options(nostack, readonly))
            }
        }
    }
}

/// Stores the C tiles of a block pair ([`multiply`]'s `EVEN`; the second
/// only if `two`).
///
/// # Safety
/// Tiles configured and multiplied.
#[inline(always)]
unsafe fn store<const EVEN: bool>(c: &mut CPair, two: bool) {
    let (c0, c1) = (c.0[0].as_mut_ptr(), c.0[1].as_mut_ptr());
    // SAFETY: the caller's; 8 rows x 64 bytes fill each half of `c`.
    unsafe {
        match (EVEN, two) {
            (true, true) => {
                asm!("tilestored [{c0} + {s}], tmm0", "tilestored [{c1} + {s}], tmm3", c0 = in(reg) c0, c1 = in(reg) c1, s = in(reg) 64usize, options(nostack))
            }
            (true, false) => {
                asm!("tilestored [{c0} + {s}], tmm0", c0 = in(reg) c0, s = in(reg) 64usize, options(nostack))
            }
            (false, true) => {
                asm!("tilestored [{c0} + {s}], tmm6", "tilestored [{c1} + {s}], tmm7", c0 = in(reg) c0, c1 = in(reg) c1, s = in(reg) 64usize, options(nostack))
            }
            (false, false) => {
                asm!("tilestored [{c0} + {s}], tmm6", c0 = in(reg) c0, s = in(reg) 64usize, options(nostack))
            }
        }
    }
}

/// The kernel of [`gemm_q8_packed_amx`] for groups of `R` rows ([`ROWS`] or
/// [`ROWS_SMALL`]; extents checked there). Per `R`-row
/// tile and block pair `p`: multiply pair `p + 1` while pair `p`'s results
/// are stored and scaled into the accumulators (two sets of C tiles and two
/// stored copies alternate), and the next share of `ahead`'s lines is
/// prefetched.
///
/// # Safety
/// As [`gemm_q8_packed_amx`]'s SAFETY note: AMX usable, the Avx512Vnni
/// features, and the extents it checked.
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx2,fma,f16c")]
#[allow(clippy::too_many_arguments)]
unsafe fn tiles_q8<const R: usize>(
    wb: &[u8],
    sc: &[[[f32; 16]; PAIRS]; 2],
    nb: usize,
    xq: &[i8],
    stride: usize,
    xd: &[f32],
    mut out: Window<'_>,
    e: Tail<'_>,
    ahead: &[u8],
) {
    // Row m of a pair's C tile h: lane 8t + n = weight row 8t + n's sums of block 2p + h, which
    // the VNNI kernel keeps in lane 2n (h = 0) or 2n + 1 (h = 1) of tile t's accumulator: the same
    // FMAs lane for lane in acc[h], whose lanes the VNNI kernel adds at the end, even + odd.
    let np = nb.div_ceil(2);
    // `ahead`'s lines, spread evenly over the (row group, block pair) steps.
    if out.rows() < R {
        return;
    }
    let (lines, steps) = (ahead.len().div_ceil(64), out.rows() / R * np);
    // The window's columns (at most COLS) and their bias, as lanes.
    let cols = lanes(out.cols());
    // SAFETY: the masked lanes < out.cols() <= bias.len() (checked by the caller).
    let bias = e.bias.map_or(_mm512_setzero_ps(), |b| unsafe {
        _mm512_maskz_loadu_ps(cols, b.as_ptr())
    });
    let mut c = [CPair([[0; 16 * ROWS]; 2]), CPair([[0; 16 * ROWS]; 2])];
    let cfg = if R == ROWS { &CONFIG } else { &CONFIG_SMALL };
    // SAFETY: both are valid palette-1 configurations (R is one of their row counts).
    unsafe { asm!("ldtilecfg [{0}]", in(reg) cfg.0.as_ptr(), options(nostack, readonly)) };
    for t in 0..out.rows() / R {
        let a = &xq[t * R * stride..];
        let d = &xd[t * R * nb..(t + 1) * R * nb];
        let mut acc = [[_mm512_setzero_ps(); R]; 2];
        let two = |p: usize| 2 * p + 1 < nb;
        // SAFETY: pair 0's blocks (< nb) of 8 rows of `a` and of `wb` (extents checked by the caller).
        unsafe { multiply::<true>(a.as_ptr(), stride, wb.as_ptr(), two(0)) };
        for p in 0..np {
            // SAFETY: tiles configured; pair p + 1's blocks (< nb) of 8 rows of
            // `a` and of `wb`, as for pair 0; pair p's results are in the C
            // tiles of its parity (multiplied in the previous step).
            unsafe {
                if p + 1 < np {
                    let (ap, bp) = (
                        a[64 * (p + 1)..].as_ptr(),
                        wb[2 * B_BLOCK * (p + 1)..].as_ptr(),
                    );
                    if p % 2 == 0 {
                        multiply::<false>(ap, stride, bp, two(p + 1))
                    } else {
                        multiply::<true>(ap, stride, bp, two(p + 1))
                    }
                }
                if p % 2 == 0 {
                    store::<true>(&mut c[0], two(p))
                } else {
                    store::<false>(&mut c[1], two(p))
                }
            }
            let step = t * np + p;
            for l in step * lines / steps..(step + 1) * lines / steps {
                // SAFETY: a prefetch is a hint with no architectural effect; line l < lines lies in `ahead`.
                unsafe { _mm_prefetch::<_MM_HINT_T1>(ahead.as_ptr().add(64 * l) as *const i8) };
            }
            let cp = &c[p % 2].0;
            // The blocks of the pair: 2p, and 2p + 1 if there is one.
            let parities = if two(p) { 2 } else { 1 };
            for (h, cph) in cp.iter().enumerate().take(parities) {
                // SAFETY: the pair's scales of this parity: 16 floats.
                let sv = unsafe { _mm512_loadu_ps(sc[h][p].as_ptr()) };
                for m in 0..R {
                    // SAFETY: row m of the stored tile: 16 i32 at 16m (aligned).
                    let sums = unsafe { _mm512_load_si512(cph[16 * m..].as_ptr() as *const _) };
                    let xdv = _mm512_set1_ps(d[m * nb + 2 * p + h]);
                    acc[h][m] = _mm512_fmadd_ps(
                        _mm512_cvtepi32_ps(sums),
                        _mm512_mul_ps(sv, xdv),
                        acc[h][m],
                    );
                }
            }
        }
        for (m, (even, odd)) in acc[0].iter().zip(&acc[1]).enumerate() {
            // Each weight row's even and odd block sums, added as the VNNI kernel adds its lane pairs;
            // then the epilogue's operations (`bias_act`): b + y, then GELU.
            let y = _mm512_add_ps(bias, _mm512_add_ps(*even, *odd));
            let o = out.row(t * R + m);
            // SAFETY: the masked lanes < out.cols() = o.len().
            unsafe {
                _mm512_mask_storeu_ps(o.as_mut_ptr(), cols, if e.gelu { gelu16(y) } else { y })
            };
        }
    }
    // SAFETY: tiles configured above; releasing returns them to the init state.
    unsafe { asm!("tilerelease", options(nostack, nomem)) };
}
