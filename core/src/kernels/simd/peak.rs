//! Register-only int8 multiply-accumulate peak probes, one per instruction
//! sequence the int8 GEMMs run (issue #40): the machine's ceiling that the
//! kernel bench (`duolando bench --kernels`, `cargo bench -p duolando
//! --bench kernels`) sets each GEMM shape's achieved GMAC/s against.
//!
//! Each probe runs `iters` iterations of a loop written in inline asm (so
//! the compiler can neither hoist nor fold the arithmetic) over several
//! independent accumulator chains held in registers (enough to cover the
//! instruction's latency times its issue rate on current cores), with no
//! memory access in the loop, and returns a checksum of the accumulators:
//! the sum of every i32 lane of every chain, each chain started at its
//! index. [`twin`] computes the same checksum from the operands in plain
//! integer arithmetic (the saturations and wrap-arounds of the
//! instructions included), and the tests check every probe this CPU can
//! run against it, so a probe cannot be optimised away or compute
//! something else than what it claims.
//!
//! Core has no clock: the caller times [`run`] (std side:
//! `duolando::kernel_bench`). The MACs a probe performs are
//! `iters * probe.macs_per_iter()` (one int8 x int8 product added into an
//! accumulator = one MAC, as GEMM figures count them).
//!
//! Probes:
//! - [`Probe::Avx512Vnni`]: `vpdpbusd zmm` (64 MACs), 12 chains;
//! - [`Probe::AvxVnni`]: `{vex} vpdpbusd ymm` (32 MACs), 8 chains (AVX-VNNI:
//!   Alder Lake / Zen 5 desktops without AVX-512; no [`Isa`] of its own yet);
//! - [`Probe::Avx512Bw`]: `vpmaddubsw` + `vpmaddwd` (by ones) + `vpaddd` on
//!   zmm (64 MACs per sequence), 8 chains: what the AVX-512 kernels without
//!   VNNI run per 64 bytes;
//! - [`Probe::Avx2`]: the same sequence on ymm (32 MACs), 6 chains: the AVX2
//!   kernels' sequence (their `vpsignb`, which makes one side unsigned, is
//!   not in the probe);
//! - [`Probe::Scalar`]: `imul` + `add` (x86_64) / `madd` (aarch64) on 32-bit
//!   registers, 1 MAC each, 4 chains;
//! - [`Probe::NeonDot`]: `sdot v.4s` (16 MACs), 8 chains;
//! - [`Probe::NeonI8mm`]: `smmla v.4s` (2x8 by 8x2: 32 MACs), 8 chains.

use super::Isa;

/// One int8 multiply-accumulate instruction sequence to probe.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Probe {
    Scalar,
    Avx2,
    Avx512Bw,
    Avx512Vnni,
    AvxVnni,
    NeonDot,
    NeonI8mm,
}

/// The operands every iteration multiplies: `a` (unsigned bytes for the
/// x86 sequences, read as signed by the NEON ones) and `b` (signed), 64
/// bytes each (a probe uses the first 1, 4, 16, 32 or 64).
#[derive(Clone, Copy, Debug)]
pub struct Operands {
    pub a: [u8; 64],
    pub b: [i8; 64],
}

impl Probe {
    /// Every probe, best x86 first, then NEON, then scalar.
    pub const ALL: [Probe; 7] = [
        Probe::Avx512Vnni,
        Probe::AvxVnni,
        Probe::Avx512Bw,
        Probe::Avx2,
        Probe::NeonI8mm,
        Probe::NeonDot,
        Probe::Scalar,
    ];

    /// A short name of the instruction sequence.
    pub fn name(self) -> &'static str {
        match self {
            Probe::Scalar => "scalar imul+add",
            Probe::Avx2 => "avx2 vpmaddubsw+vpmaddwd+vpaddd ymm",
            Probe::Avx512Bw => "avx512bw vpmaddubsw+vpmaddwd+vpaddd zmm",
            Probe::Avx512Vnni => "avx512vnni vpdpbusd zmm",
            Probe::AvxVnni => "avxvnni vpdpbusd ymm",
            Probe::NeonDot => "neon sdot",
            Probe::NeonI8mm => "neon i8mm smmla",
        }
    }

    /// Independent accumulator chains (registers) the loop keeps.
    pub fn chains(self) -> usize {
        match self {
            Probe::Scalar => 4,
            Probe::Avx2 => 6,
            Probe::Avx512Bw | Probe::AvxVnni | Probe::NeonDot | Probe::NeonI8mm => 8,
            Probe::Avx512Vnni => 12,
        }
    }

    /// i32 lanes per accumulator.
    pub fn lanes(self) -> usize {
        match self {
            Probe::Scalar => 1,
            Probe::Avx2 | Probe::AvxVnni => 8,
            Probe::Avx512Bw | Probe::Avx512Vnni => 16,
            Probe::NeonDot | Probe::NeonI8mm => 4,
        }
    }

    /// int8 MACs per accumulator per iteration.
    pub fn macs_per_chain(self) -> u64 {
        match self {
            Probe::Scalar => 1,
            Probe::Avx2 | Probe::AvxVnni => 32,
            Probe::Avx512Bw | Probe::Avx512Vnni => 64,
            Probe::NeonDot => 16,
            Probe::NeonI8mm => 32,
        }
    }

    /// int8 MACs of one loop iteration (all chains).
    pub fn macs_per_iter(self) -> u64 {
        self.chains() as u64 * self.macs_per_chain()
    }

    /// The probe of the instructions `isa`'s int8 GEMM kernels run.
    pub fn for_isa(isa: Isa) -> Probe {
        match isa {
            Isa::Scalar | Isa::Neon => Probe::Scalar,
            Isa::Avx2 => Probe::Avx2,
            Isa::AvxVnni => Probe::AvxVnni,
            Isa::Avx512 => Probe::Avx512Bw,
            Isa::Avx512Vnni => Probe::Avx512Vnni,
            Isa::NeonDot => Probe::NeonDot,
        }
    }
}

/// What one iteration adds to lane `lane` of chain `chain`, as the
/// instructions compute it (i16 saturation of `vpmaddubsw` included).
fn increment(p: Probe, o: &Operands, chain: usize, lane: usize) -> i32 {
    let a = |i: usize| o.a[i] as i32;
    let sa = |i: usize| o.a[i] as i8 as i32;
    let b = |i: usize| o.b[i] as i32;
    match p {
        Probe::Scalar => a(chain) * b(0),
        Probe::Avx2 | Probe::Avx512Bw => {
            let pair = |i: usize| {
                (a(i) * b(i) + a(i + 1) * b(i + 1)).clamp(i16::MIN as i32, i16::MAX as i32)
            };
            pair(4 * lane) + pair(4 * lane + 2)
        }
        Probe::Avx512Vnni | Probe::AvxVnni => {
            (0..4).map(|i| a(4 * lane + i) * b(4 * lane + i)).sum()
        }
        Probe::NeonDot => (0..4).map(|i| sa(4 * lane + i) * b(4 * lane + i)).sum(),
        // Lane 2i + j: row i of a (bytes 8i..8i+8) dot row j of b.
        Probe::NeonI8mm => (0..8)
            .map(|k| sa(8 * (lane / 2) + k) * b(8 * (lane % 2) + k))
            .sum(),
    }
}

/// The checksum [`run`] returns, computed in plain integer arithmetic:
/// per chain `k` and lane, `k + iters * increment` (wrapping i32, as the
/// accumulators wrap), summed over chains and lanes as i64.
pub fn twin(p: Probe, iters: u64, o: &Operands) -> i64 {
    let n = iters as u32 as i32;
    let mut s = 0i64;
    for k in 0..p.chains() {
        for l in 0..p.lanes() {
            s += (k as i32).wrapping_add(n.wrapping_mul(increment(p, o, k, l))) as i64;
        }
    }
    s
}

/// The probe of the selected ISA ([`super::isa`]; [`Probe::for_isa`]):
/// `iters` iterations, the checksum.
pub fn run_selected(iters: u64, o: &Operands) -> i64 {
    let p = Probe::for_isa(super::isa());
    // SAFETY: `set_isa`'s contract: the CPU supports the selected ISA, and
    // each ISA's probe needs only that ISA's features. A probe this build
    // has no variant for returns None (not reached: `for_isa` maps foreign
    // ISAs, which `set_isa` falls back from, to those of this build or
    // scalar, which every 64-bit build has; elsewhere the twin stands in).
    unsafe { run(p, iters, o) }.unwrap_or_else(|| twin(p, iters, o))
}

/// Runs probe `p` for `iters` iterations and returns its checksum (equal
/// to [`twin`]); `None` where this build has no variant of it (another
/// architecture; the scalar probe exists on x86_64 and aarch64).
///
/// # Safety
/// The CPU must support the probe's instructions: [`Probe::Avx2`] avx2;
/// [`Probe::Avx512Bw`] avx512f + avx512bw; [`Probe::Avx512Vnni`] those and
/// avx512vnni; [`Probe::AvxVnni`] avx2 + avxvnni; [`Probe::NeonDot`]
/// dotprod; [`Probe::NeonI8mm`] i8mm. [`Probe::Scalar`] is always sound.
#[allow(unused_variables)]
pub unsafe fn run(p: Probe, iters: u64, o: &Operands) -> Option<i64> {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the caller vouched for the CPU (this fn's contract).
    unsafe {
        return match p {
            Probe::Scalar => Some(x86::scalar(iters, o)),
            Probe::Avx2 => Some(x86::avx2(iters, o)),
            Probe::Avx512Bw => Some(x86::avx512bw(iters, o)),
            Probe::Avx512Vnni => Some(x86::avx512vnni(iters, o)),
            Probe::AvxVnni => Some(x86::avxvnni(iters, o)),
            Probe::NeonDot | Probe::NeonI8mm => None,
        };
    }
    #[cfg(target_arch = "aarch64")]
    // SAFETY: the caller vouched for the CPU (this fn's contract).
    unsafe {
        return match p {
            Probe::Scalar => Some(arm::scalar(iters, o)),
            #[cfg(target_feature = "neon")]
            Probe::NeonDot => Some(arm::sdot(iters, o)),
            #[cfg(target_feature = "neon")]
            Probe::NeonI8mm => Some(arm::smmla(iters, o)),
            _ => None,
        };
    }
    #[allow(unreachable_code)]
    None
}

/// Sums the i32 lanes of `chains` as [`twin`] does.
#[allow(dead_code)]
fn lane_sum(lanes: &[i32]) -> i64 {
    lanes.iter().map(|&v| v as i64).sum()
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{lane_sum, Operands};
    use core::arch::asm;
    use core::arch::x86_64::*;

    /// # Safety
    /// Always sound (base x86_64 instructions).
    pub unsafe fn scalar(iters: u64, o: &Operands) -> i64 {
        let b = o.b[0] as i32;
        let (x0, x1, x2, x3) = (o.a[0] as i32, o.a[1] as i32, o.a[2] as i32, o.a[3] as i32);
        let mut c = [0i32, 1, 2, 3];
        if iters > 0 {
            // SAFETY: register-only base instructions; `n` counts down to 0.
            unsafe {
                asm!(
                    "2:",
                    "mov {t:e}, {x0:e}", "imul {t:e}, {b:e}", "add {c0:e}, {t:e}",
                    "mov {t:e}, {x1:e}", "imul {t:e}, {b:e}", "add {c1:e}, {t:e}",
                    "mov {t:e}, {x2:e}", "imul {t:e}, {b:e}", "add {c2:e}, {t:e}",
                    "mov {t:e}, {x3:e}", "imul {t:e}, {b:e}", "add {c3:e}, {t:e}",
                    "dec {n}",
                    "jnz 2b",
                    c0 = inout(reg) c[0], c1 = inout(reg) c[1], c2 = inout(reg) c[2], c3 = inout(reg) c[3],
                    x0 = in(reg) x0, x1 = in(reg) x1, x2 = in(reg) x2, x3 = in(reg) x3, b = in(reg) b,
                    t = out(reg) _, n = inout(reg) iters => _,
                    options(nomem, nostack),
                )
            };
        }
        lane_sum(&c)
    }

    /// The sum of every i32 lane of `v`.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn sum256(v: &[__m256i]) -> i64 {
        // SAFETY: __m256i and [i32; 8] are the same plain bytes.
        v.iter()
            .map(|&x| lane_sum(&unsafe { core::mem::transmute::<__m256i, [i32; 8]>(x) }))
            .sum()
    }

    #[inline]
    #[target_feature(enable = "avx512f")]
    fn sum512(v: &[__m512i]) -> i64 {
        // SAFETY: __m512i and [i32; 16] are the same plain bytes.
        v.iter()
            .map(|&x| lane_sum(&unsafe { core::mem::transmute::<__m512i, [i32; 16]>(x) }))
            .sum()
    }

    /// # Safety
    /// The CPU must support avx2.
    #[target_feature(enable = "avx2")]
    pub unsafe fn avx2(iters: u64, o: &Operands) -> i64 {
        // SAFETY: 32-byte reads of 64-byte arrays.
        let (x, y) = unsafe {
            (
                _mm256_loadu_si256(o.a.as_ptr().cast()),
                _mm256_loadu_si256(o.b.as_ptr().cast()),
            )
        };
        let one = _mm256_set1_epi16(1);
        let mut c: [__m256i; 6] = core::array::from_fn(|k| _mm256_set1_epi32(k as i32));
        if iters > 0 {
            // SAFETY: register-only AVX2 instructions (this fn's feature).
            unsafe {
                asm!(
                    "2:",
                    "vpmaddubsw {t0}, {x}, {y}", "vpmaddwd {t0}, {t0}, {one}", "vpaddd {c0}, {c0}, {t0}",
                    "vpmaddubsw {t1}, {x}, {y}", "vpmaddwd {t1}, {t1}, {one}", "vpaddd {c1}, {c1}, {t1}",
                    "vpmaddubsw {t2}, {x}, {y}", "vpmaddwd {t2}, {t2}, {one}", "vpaddd {c2}, {c2}, {t2}",
                    "vpmaddubsw {t0}, {x}, {y}", "vpmaddwd {t0}, {t0}, {one}", "vpaddd {c3}, {c3}, {t0}",
                    "vpmaddubsw {t1}, {x}, {y}", "vpmaddwd {t1}, {t1}, {one}", "vpaddd {c4}, {c4}, {t1}",
                    "vpmaddubsw {t2}, {x}, {y}", "vpmaddwd {t2}, {t2}, {one}", "vpaddd {c5}, {c5}, {t2}",
                    "dec {n}",
                    "jnz 2b",
                    c0 = inout(ymm_reg) c[0], c1 = inout(ymm_reg) c[1], c2 = inout(ymm_reg) c[2],
                    c3 = inout(ymm_reg) c[3], c4 = inout(ymm_reg) c[4], c5 = inout(ymm_reg) c[5],
                    t0 = out(ymm_reg) _, t1 = out(ymm_reg) _, t2 = out(ymm_reg) _,
                    x = in(ymm_reg) x, y = in(ymm_reg) y, one = in(ymm_reg) one,
                    n = inout(reg) iters => _,
                    options(nomem, nostack),
                )
            };
        }
        sum256(&c)
    }

    /// # Safety
    /// The CPU must support avx512f and avx512bw.
    #[target_feature(enable = "avx512f,avx512bw")]
    pub unsafe fn avx512bw(iters: u64, o: &Operands) -> i64 {
        // SAFETY: 64-byte reads of 64-byte arrays.
        let (x, y) = unsafe {
            (
                core::ptr::read_unaligned(o.a.as_ptr().cast::<__m512i>()),
                core::ptr::read_unaligned(o.b.as_ptr().cast::<__m512i>()),
            )
        };
        let one = _mm512_set1_epi16(1);
        let mut c: [__m512i; 8] = core::array::from_fn(|k| _mm512_set1_epi32(k as i32));
        if iters > 0 {
            // SAFETY: register-only AVX-512BW instructions (this fn's features).
            unsafe {
                asm!(
                    "2:",
                    "vpmaddubsw {t0}, {x}, {y}", "vpmaddwd {t0}, {t0}, {one}", "vpaddd {c0}, {c0}, {t0}",
                    "vpmaddubsw {t1}, {x}, {y}", "vpmaddwd {t1}, {t1}, {one}", "vpaddd {c1}, {c1}, {t1}",
                    "vpmaddubsw {t2}, {x}, {y}", "vpmaddwd {t2}, {t2}, {one}", "vpaddd {c2}, {c2}, {t2}",
                    "vpmaddubsw {t3}, {x}, {y}", "vpmaddwd {t3}, {t3}, {one}", "vpaddd {c3}, {c3}, {t3}",
                    "vpmaddubsw {t0}, {x}, {y}", "vpmaddwd {t0}, {t0}, {one}", "vpaddd {c4}, {c4}, {t0}",
                    "vpmaddubsw {t1}, {x}, {y}", "vpmaddwd {t1}, {t1}, {one}", "vpaddd {c5}, {c5}, {t1}",
                    "vpmaddubsw {t2}, {x}, {y}", "vpmaddwd {t2}, {t2}, {one}", "vpaddd {c6}, {c6}, {t2}",
                    "vpmaddubsw {t3}, {x}, {y}", "vpmaddwd {t3}, {t3}, {one}", "vpaddd {c7}, {c7}, {t3}",
                    "dec {n}",
                    "jnz 2b",
                    c0 = inout(zmm_reg) c[0], c1 = inout(zmm_reg) c[1], c2 = inout(zmm_reg) c[2], c3 = inout(zmm_reg) c[3],
                    c4 = inout(zmm_reg) c[4], c5 = inout(zmm_reg) c[5], c6 = inout(zmm_reg) c[6], c7 = inout(zmm_reg) c[7],
                    t0 = out(zmm_reg) _, t1 = out(zmm_reg) _, t2 = out(zmm_reg) _, t3 = out(zmm_reg) _,
                    x = in(zmm_reg) x, y = in(zmm_reg) y, one = in(zmm_reg) one,
                    n = inout(reg) iters => _,
                    options(nomem, nostack),
                )
            };
        }
        sum512(&c)
    }

    /// # Safety
    /// The CPU must support avx512f, avx512bw and avx512vnni.
    #[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
    pub unsafe fn avx512vnni(iters: u64, o: &Operands) -> i64 {
        // SAFETY: 64-byte reads of 64-byte arrays.
        let (x, y) = unsafe {
            (
                core::ptr::read_unaligned(o.a.as_ptr().cast::<__m512i>()),
                core::ptr::read_unaligned(o.b.as_ptr().cast::<__m512i>()),
            )
        };
        let mut c: [__m512i; 12] = core::array::from_fn(|k| _mm512_set1_epi32(k as i32));
        if iters > 0 {
            // SAFETY: register-only AVX512-VNNI instructions (this fn's features).
            unsafe {
                asm!(
                    "2:",
                    "vpdpbusd {c0}, {x}, {y}", "vpdpbusd {c1}, {x}, {y}", "vpdpbusd {c2}, {x}, {y}",
                    "vpdpbusd {c3}, {x}, {y}", "vpdpbusd {c4}, {x}, {y}", "vpdpbusd {c5}, {x}, {y}",
                    "vpdpbusd {c6}, {x}, {y}", "vpdpbusd {c7}, {x}, {y}", "vpdpbusd {c8}, {x}, {y}",
                    "vpdpbusd {c9}, {x}, {y}", "vpdpbusd {c10}, {x}, {y}", "vpdpbusd {c11}, {x}, {y}",
                    "dec {n}",
                    "jnz 2b",
                    c0 = inout(zmm_reg) c[0], c1 = inout(zmm_reg) c[1], c2 = inout(zmm_reg) c[2], c3 = inout(zmm_reg) c[3],
                    c4 = inout(zmm_reg) c[4], c5 = inout(zmm_reg) c[5], c6 = inout(zmm_reg) c[6], c7 = inout(zmm_reg) c[7],
                    c8 = inout(zmm_reg) c[8], c9 = inout(zmm_reg) c[9], c10 = inout(zmm_reg) c[10], c11 = inout(zmm_reg) c[11],
                    x = in(zmm_reg) x, y = in(zmm_reg) y,
                    n = inout(reg) iters => _,
                    options(nomem, nostack),
                )
            };
        }
        sum512(&c)
    }

    /// # Safety
    /// The CPU must support avx2 and avxvnni.
    #[target_feature(enable = "avx2,avxvnni")]
    pub unsafe fn avxvnni(iters: u64, o: &Operands) -> i64 {
        // SAFETY: 32-byte reads of 64-byte arrays.
        let (x, y) = unsafe {
            (
                _mm256_loadu_si256(o.a.as_ptr().cast()),
                _mm256_loadu_si256(o.b.as_ptr().cast()),
            )
        };
        let mut c: [__m256i; 8] = core::array::from_fn(|k| _mm256_set1_epi32(k as i32));
        if iters > 0 {
            // SAFETY: register-only AVX-VNNI instructions (VEX-encoded,
            // this fn's features; ymm_reg allocates ymm0-15 here).
            unsafe {
                asm!(
                    "2:",
                    "{{vex}} vpdpbusd {c0}, {x}, {y}", "{{vex}} vpdpbusd {c1}, {x}, {y}",
                    "{{vex}} vpdpbusd {c2}, {x}, {y}", "{{vex}} vpdpbusd {c3}, {x}, {y}",
                    "{{vex}} vpdpbusd {c4}, {x}, {y}", "{{vex}} vpdpbusd {c5}, {x}, {y}",
                    "{{vex}} vpdpbusd {c6}, {x}, {y}", "{{vex}} vpdpbusd {c7}, {x}, {y}",
                    "dec {n}",
                    "jnz 2b",
                    c0 = inout(ymm_reg) c[0], c1 = inout(ymm_reg) c[1], c2 = inout(ymm_reg) c[2], c3 = inout(ymm_reg) c[3],
                    c4 = inout(ymm_reg) c[4], c5 = inout(ymm_reg) c[5], c6 = inout(ymm_reg) c[6], c7 = inout(ymm_reg) c[7],
                    x = in(ymm_reg) x, y = in(ymm_reg) y,
                    n = inout(reg) iters => _,
                    options(nomem, nostack),
                )
            };
        }
        sum256(&c)
    }
}

#[cfg(target_arch = "aarch64")]
mod arm {
    use super::{lane_sum, Operands};
    use core::arch::asm;

    /// # Safety
    /// Always sound (base aarch64 instructions).
    pub unsafe fn scalar(iters: u64, o: &Operands) -> i64 {
        let b = o.b[0] as i32;
        let (x0, x1, x2, x3) = (o.a[0] as i32, o.a[1] as i32, o.a[2] as i32, o.a[3] as i32);
        let mut c = [0i32, 1, 2, 3];
        if iters > 0 {
            // SAFETY: register-only base instructions; `n` counts down to 0.
            unsafe {
                asm!(
                    "2:",
                    "madd {c0:w}, {x0:w}, {b:w}, {c0:w}",
                    "madd {c1:w}, {x1:w}, {b:w}, {c1:w}",
                    "madd {c2:w}, {x2:w}, {b:w}, {c2:w}",
                    "madd {c3:w}, {x3:w}, {b:w}, {c3:w}",
                    "subs {n}, {n}, #1",
                    "b.ne 2b",
                    c0 = inout(reg) c[0], c1 = inout(reg) c[1], c2 = inout(reg) c[2], c3 = inout(reg) c[3],
                    x0 = in(reg) x0, x1 = in(reg) x1, x2 = in(reg) x2, x3 = in(reg) x3, b = in(reg) b,
                    n = inout(reg) iters => _,
                    options(nomem, nostack),
                )
            };
        }
        lane_sum(&c)
    }

    #[cfg(target_feature = "neon")]
    macro_rules! neon_probe {
        ($name:ident, $feat:literal, $ins:literal) => {
            /// # Safety
            /// The CPU must support the instruction's extension (this fn's features).
            #[target_feature(enable = $feat)]
            pub unsafe fn $name(iters: u64, o: &Operands) -> i64 {
                use core::arch::aarch64::*;
                // SAFETY: 16-byte reads of 64-byte arrays.
                let (x, y) = unsafe { (vld1q_s8(o.a.as_ptr().cast()), vld1q_s8(o.b.as_ptr())) };
                let mut c: [int32x4_t; 8] = core::array::from_fn(|k| vdupq_n_s32(k as i32));
                if iters > 0 {
                    // SAFETY: register-only instructions of the extension.
                    unsafe {
                        asm!(
                            "2:",
                            concat!($ins, " {c0:v}.4s, {x:v}.16b, {y:v}.16b"),
                            concat!($ins, " {c1:v}.4s, {x:v}.16b, {y:v}.16b"),
                            concat!($ins, " {c2:v}.4s, {x:v}.16b, {y:v}.16b"),
                            concat!($ins, " {c3:v}.4s, {x:v}.16b, {y:v}.16b"),
                            concat!($ins, " {c4:v}.4s, {x:v}.16b, {y:v}.16b"),
                            concat!($ins, " {c5:v}.4s, {x:v}.16b, {y:v}.16b"),
                            concat!($ins, " {c6:v}.4s, {x:v}.16b, {y:v}.16b"),
                            concat!($ins, " {c7:v}.4s, {x:v}.16b, {y:v}.16b"),
                            "subs {n}, {n}, #1",
                            "b.ne 2b",
                            c0 = inout(vreg) c[0], c1 = inout(vreg) c[1], c2 = inout(vreg) c[2], c3 = inout(vreg) c[3],
                            c4 = inout(vreg) c[4], c5 = inout(vreg) c[5], c6 = inout(vreg) c[6], c7 = inout(vreg) c[7],
                            x = in(vreg) x, y = in(vreg) y,
                            n = inout(reg) iters => _,
                            options(nomem, nostack),
                        )
                    };
                }
                // SAFETY: int32x4_t and [i32; 4] are the same plain bytes.
                c.iter().map(|&v| lane_sum(&unsafe { core::mem::transmute::<int32x4_t, [i32; 4]>(v) })).sum()
            }
        };
    }
    #[cfg(target_feature = "neon")]
    neon_probe!(sdot, "neon,dotprod", "sdot");
    #[cfg(target_feature = "neon")]
    neon_probe!(smmla, "neon,i8mm", "smmla");
}

#[cfg(test)]
mod tests {
    use super::*;

    fn operands(seed: u64, x86_signs_ok: bool) -> Operands {
        let mut s = seed | 1;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let mut o = Operands {
            a: [0; 64],
            b: [0; 64],
        };
        for i in 0..64 {
            // x86_signs_ok: a in 0..=127 (no i16 saturation in vpmaddubsw,
            // as the engine's sign trick guarantees); else any byte.
            o.a[i] = if x86_signs_ok {
                (next() % 128) as u8
            } else {
                next() as u8
            };
            o.b[i] = next() as i8;
        }
        o
    }

    /// The probes this CPU runs (the test binary's own detection).
    fn runnable() -> Vec<Probe> {
        #[allow(unused_mut)]
        let mut v = vec![Probe::Scalar];
        #[cfg(target_arch = "x86_64")]
        {
            use std::is_x86_feature_detected as has;
            if has!("avx2") {
                v.push(Probe::Avx2);
            }
            if has!("avx512f") && has!("avx512bw") {
                v.push(Probe::Avx512Bw);
                if has!("avx512vnni") {
                    v.push(Probe::Avx512Vnni);
                }
            }
            if has!("avx2") && has!("avxvnni") {
                v.push(Probe::AvxVnni);
            }
        }
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        {
            if std::arch::is_aarch64_feature_detected!("dotprod") {
                v.push(Probe::NeonDot);
            }
            if std::arch::is_aarch64_feature_detected!("i8mm") {
                v.push(Probe::NeonI8mm);
            }
        }
        v
    }

    #[test]
    fn every_probe_this_cpu_runs_equals_its_scalar_twin() {
        let probes = runnable();
        eprintln!("probes run: {probes:?}");
        for p in probes {
            for (seed, small) in [(1u64, true), (2, false), (3, false), (4, true)] {
                let o = operands(seed, small);
                // 0 iterations: the chains' start values; many: wrap-arounds.
                for iters in [0u64, 1, 2, 7, 1000, 1 << 20] {
                    // SAFETY: `runnable` listed only probes this CPU supports.
                    let got = unsafe { run(p, iters, &o) }.expect("a variant on this architecture");
                    assert_eq!(got, twin(p, iters, &o), "{p:?} iters {iters} seed {seed}");
                }
            }
        }
    }

    /// The twin itself: hand-computed checksums, so a wrong twin (and a
    /// probe agreeing with it) fails here.
    #[test]
    fn twins_count_what_the_instructions_compute() {
        let mut o = Operands {
            a: [0; 64],
            b: [0; 64],
        };
        o.a[0] = 255;
        o.a[1] = 255;
        o.b[0] = -128;
        o.b[1] = -128;
        // Scalar: chain 0 gets 255 * -128 per iteration, chain 1 255 * -128,
        // chains 2, 3 nothing; starts 0 + 1 + 2 + 3.
        assert_eq!(twin(Probe::Scalar, 3, &o), 6 + 2 * 3 * 255 * -128);
        // AVX2: the pair 255 * -128 * 2 saturates to -32768 in lane 0 of
        // each of 6 chains; the other 7 lanes add 0; starts 8 * (0 + .. + 5).
        assert_eq!(twin(Probe::Avx2, 2, &o), 8 * 15 + 6 * 2 * -32768);
        // VNNI: exact, -65280 per iteration in lane 0 of 12 chains.
        assert_eq!(twin(Probe::Avx512Vnni, 2, &o), 16 * 66 + 12 * 2 * -65280);
        // NEON sdot reads a as signed: 255 -> -1, so +256 per iteration.
        assert_eq!(twin(Probe::NeonDot, 1, &o), 4 * 28 + 8 * 256);
        // smmla lane 0 (row 0 of a, row 0 of b) gets +256; lane 1 (row 0 of
        // a, row 1 of b: bytes 8..16 of b, zero) nothing.
        assert_eq!(twin(Probe::NeonI8mm, 1, &o), 4 * 28 + 8 * 256);
        // The accumulators wrap as the instructions' do.
        assert_eq!(
            twin(Probe::Avx512Vnni, 1 << 16, &o),
            16 * 66 + 12 * ((1i32 << 16).wrapping_mul(-65280) as i64)
        );
        assert_eq!(Probe::Avx512Vnni.macs_per_iter(), 12 * 64);
        assert_eq!(Probe::Avx2.macs_per_iter(), 6 * 32);
    }
}
