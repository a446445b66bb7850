//! Run-time selection of the core's SIMD kernels (`duolando_core::kernels::simd`).
//! Core (no_std) can only use what the compile-time target features
//! guarantee; the std side detects the CPU once and switches the
//! process-wide kernel table. Nobody has to ask: the first model opened
//! through [`crate::model_file::ModelFile`] (every std entry point: the CLI,
//! the Rust API, the C library) selects the detected kernels
//! ([`ensure_init`]). [`init`] does the same explicitly (and again, after a
//! change of `DUOLANDO_ISA`).
//!
//! `DUOLANDO_ISA=scalar|avx2|avxvnni|avx512|avx512vnni|avx512amx|neon|neondot|neoni8mm` caps
//! the choice (an ISA this CPU lacks selects scalar), for comparisons.
//!
//! AMX-INT8 (Intel Sapphire Rapids and later) is not an ISA of its own
//! here: on top of AVX512-VNNI, [`init`] asks Linux for the tile
//! permission and, if granted, lets the packed int8 GEMM run whole tiles
//! of 16 activation rows on the tile unit (the same values bit for bit:
//! `duolando_core::kernels::simd::amx`). `DUOLANDO_ISA=avx512vnni` keeps
//! it off; unset or `avx512amx` allows it. The NEON i8mm extension is
//! handled the same way on top of NeonDot (`smmla` for the packed int8
//! GEMM: `duolando_core::kernels::simd::i8mm`): `DUOLANDO_ISA=neondot`
//! keeps it off; unset or `neoni8mm` allows it.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Once;

use duolando_core::kernels::simd::{self, Isa};

/// Set once [`init`] has run (explicitly or through [`ensure_init`]).
static SELECTED: AtomicBool = AtomicBool::new(false);

/// Every ISA this CPU supports that the core has kernels for, best first.
pub fn supported() -> Vec<Isa> {
    #[allow(unused_mut)]
    let mut v = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        use std::is_x86_feature_detected as has;
        let avx2 = has!("avx2") && has!("fma") && has!("f16c");
        let avx512 =
            avx2 && has!("avx512f") && has!("avx512bw") && has!("avx512dq") && has!("avx512vl");
        if avx512 && has!("avx512vnni") {
            v.push(Isa::Avx512Vnni);
        }
        if avx512 {
            v.push(Isa::Avx512);
        }
        if avx2 && has!("avxvnni") {
            v.push(Isa::AvxVnni);
        }
        if avx2 {
            v.push(Isa::Avx2);
        }
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    {
        if std::arch::is_aarch64_feature_detected!("dotprod") {
            v.push(Isa::NeonDot);
        }
        v.push(Isa::Neon);
    }
    v.push(Isa::Scalar);
    v
}

/// The best ISA this CPU supports that the core has kernels for (capped
/// by `DUOLANDO_ISA` when set).
pub fn detect() -> Isa {
    let all = supported();
    let cap = std::env::var("DUOLANDO_ISA").ok().and_then(|s| parse(&s));
    match cap {
        Some(c) => all.iter().copied().find(|&i| i == c).unwrap_or(Isa::Scalar),
        None => all[0],
    }
}

/// An ISA by its lower-case name (`avx512vnni`, ...).
pub fn parse(name: &str) -> Option<Isa> {
    Some(match name.to_ascii_lowercase().as_str() {
        "scalar" => Isa::Scalar,
        "avx2" => Isa::Avx2,
        "avxvnni" => Isa::AvxVnni,
        "avx512" => Isa::Avx512,
        "avx512vnni" | "avx512amx" => Isa::Avx512Vnni,
        "neon" => Isa::Neon,
        "neondot" | "neoni8mm" => Isa::NeonDot,
        _ => return None,
    })
}

/// Selects the detected kernels ([`detect`]) for the whole process, and the
/// AMX tiles where [`amx_usable`] (unless `DUOLANDO_ISA` names another ISA
/// than `avx512amx`); returns the ISA.
pub fn init() -> Isa {
    let isa = detect();
    // SAFETY: `detect` returned `isa` only from `supported`, which checked
    // that this CPU supports every feature its kernels are compiled for.
    #[allow(unsafe_code)]
    unsafe {
        simd::set_isa(isa)
    };
    #[cfg(target_arch = "x86_64")]
    {
        let wanted =
            std::env::var("DUOLANDO_ISA").map_or(true, |s| s.eq_ignore_ascii_case("avx512amx"));
        let amx = isa == Isa::Avx512Vnni && wanted && amx_usable();
        // SAFETY: `amx_usable` checked the CPU's amx-tile and amx-int8 bits
        // and got the tile permission from the OS; the ISA is Avx512Vnni.
        #[allow(unsafe_code)]
        unsafe {
            simd::amx::enable(amx)
        };
    }
    #[cfg(target_arch = "aarch64")]
    {
        let wanted =
            std::env::var("DUOLANDO_ISA").map_or(true, |s| s.eq_ignore_ascii_case("neoni8mm"));
        // SAFETY: `i8mm_usable` checked the CPU's i8mm bit; the ISA is NeonDot.
        #[allow(unsafe_code)]
        unsafe {
            simd::i8mm::enable(isa == Isa::NeonDot && wanted && i8mm_usable())
        };
    }
    // Only now: a concurrent `ensure_init` that sees the flag must find the
    // selection complete (stored first, a model opened on another thread ran
    // its first GEMMs on the kernels in place before).
    SELECTED.store(true, Ordering::Release);
    isa
}

/// Whether this CPU runs the int8 MAC peak probe `p`
/// (`duolando_core::kernels::simd::peak`).
pub fn probe_supported(p: simd::peak::Probe) -> bool {
    use simd::peak::Probe;
    #[cfg(target_arch = "x86_64")]
    {
        use std::is_x86_feature_detected as has;
        match p {
            Probe::Scalar => true,
            Probe::Avx2 => has!("avx2"),
            Probe::Avx512Bw => has!("avx512f") && has!("avx512bw"),
            Probe::Avx512Vnni => has!("avx512f") && has!("avx512bw") && has!("avx512vnni"),
            Probe::AvxVnni => has!("avx2") && has!("avxvnni"),
            Probe::NeonDot | Probe::NeonI8mm => false,
        }
    }
    #[cfg(target_arch = "aarch64")]
    {
        use std::arch::is_aarch64_feature_detected as has;
        match p {
            Probe::Scalar => true,
            Probe::NeonDot => cfg!(target_feature = "neon") && has!("dotprod"),
            Probe::NeonI8mm => cfg!(target_feature = "neon") && has!("i8mm"),
            _ => false,
        }
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    {
        let _ = p;
        false
    }
}

/// Runs the peak probe `p` for `iters` iterations (its checksum; see
/// `simd::peak::run`); `None` where this CPU or build cannot run it.
pub fn run_probe(p: simd::peak::Probe, iters: u64, o: &simd::peak::Operands) -> Option<i64> {
    if !probe_supported(p) {
        return None;
    }
    // SAFETY: `probe_supported` checked this CPU's features for `p`.
    #[allow(unsafe_code)]
    unsafe {
        simd::peak::run(p, iters, o)
    }
}

/// Selects the ISA named `name` (as [`parse`] reads it; `avx512amx`: AVX512-VNNI
/// with the AMX tiles, which must be usable) for the whole process, whatever
/// `DUOLANDO_ISA` says; AMX stays off for every other name. Refuses, by
/// name, an ISA this CPU lacks (`duolando bench --isa`).
pub fn select(name: &str) -> Result<Isa, String> {
    let isa = parse(name).ok_or_else(|| {
        format!("unknown ISA '{name}' (scalar, avx2, avxvnni, avx512, avx512vnni, avx512amx, neon, neondot, neoni8mm)")
    })?;
    let all = supported();
    let amx = name.eq_ignore_ascii_case("avx512amx");
    let i8mm = name.eq_ignore_ascii_case("neoni8mm");
    if !all.contains(&isa) || (amx && !amx_usable()) || (i8mm && !i8mm_usable()) {
        let names: Vec<&str> = all.iter().map(|&i| name_plain(i)).collect();
        return Err(format!(
            "ISA '{name}': this CPU does not have it (it has: {}{}{})",
            names.join(", "),
            if amx_usable() { ", avx512amx" } else { "" },
            if i8mm_usable() { ", neoni8mm" } else { "" }
        ));
    }
    SELECTED.store(true, Ordering::Release);
    // SAFETY: `supported` listed `isa`: this CPU has every feature its
    // kernels are compiled for.
    #[allow(unsafe_code)]
    unsafe {
        simd::set_isa(isa)
    };
    #[cfg(target_arch = "x86_64")]
    // SAFETY: AMX only where `amx_usable` checked the CPU bits and got the
    // tile permission, and the ISA is Avx512Vnni (parse maps avx512amx to it).
    #[allow(unsafe_code)]
    unsafe {
        simd::amx::enable(amx)
    };
    // SAFETY: i8mm only where `i8mm_usable` checked the CPU bit, and the ISA
    // is NeonDot (parse maps neoni8mm to it).
    #[allow(unsafe_code)]
    unsafe {
        simd::i8mm::enable(i8mm)
    };
    Ok(isa)
}

/// The lower-case name of an ISA, AMX aside.
fn name_plain(isa: Isa) -> &'static str {
    match isa {
        Isa::Scalar => "scalar",
        Isa::Avx2 => "avx2",
        Isa::AvxVnni => "avxvnni",
        Isa::Avx512 => "avx512",
        Isa::Avx512Vnni => "avx512vnni",
        Isa::Neon => "neon",
        Isa::NeonDot => "neondot",
    }
}

/// Selects the detected kernels ([`init`]) unless a selection was already
/// made in this process; returns the ISA running now. Called by every
/// constructor of [`crate::model_file::ModelFile`], so that no std caller
/// runs the scalar kernels by forgetting a call. A selection made earlier
/// (an explicit [`init`], or a test that pinned an ISA and then called
/// [`init`]) is kept.
pub fn ensure_init() -> Isa {
    static ONCE: Once = Once::new();
    if !SELECTED.load(Ordering::Acquire) {
        ONCE.call_once(|| {
            init();
        });
    }
    simd::isa()
}

/// Pins the scalar kernels for the whole process (`duolando bench
/// --scalar`); models opened afterwards keep them ([`ensure_init`] sees a
/// selection made).
pub fn force_scalar() {
    SELECTED.store(true, Ordering::Release);
    simd::force_scalar();
}

/// The kernels running now in words, as the CLI prints them: `Avx512Vnni`,
/// `Avx512Vnni+AMX`, `Avx2`, `NeonDot+I8MM`, `Neon`, `Scalar`, ...
pub fn describe() -> String {
    format!(
        "{:?}{}{}",
        simd::isa(),
        if amx_active() { "+AMX" } else { "" },
        if i8mm_active() { "+I8MM" } else { "" }
    )
}

/// The ISA whose kernels run now (scalar until [`init`] or [`ensure_init`]).
pub fn active() -> Isa {
    simd::isa()
}

/// The lower-case name of an ISA, as [`parse`] reads it; `avx512amx` where
/// the AMX tile kernel is on, `neoni8mm` where the i8mm kernel is.
pub fn name(isa: Isa) -> &'static str {
    match isa {
        Isa::Scalar => "scalar",
        Isa::Avx2 => "avx2",
        Isa::AvxVnni => "avxvnni",
        Isa::Avx512 => "avx512",
        Isa::Avx512Vnni if amx_active() => "avx512amx",
        Isa::Avx512Vnni => "avx512vnni",
        Isa::Neon => "neon",
        Isa::NeonDot if i8mm_active() => "neoni8mm",
        Isa::NeonDot => "neondot",
    }
}

/// Whether the NEON i8mm packed kernel runs now (after [`init`]).
pub fn i8mm_active() -> bool {
    simd::i8mm::enabled()
}

/// Whether this CPU has NEON dotprod and i8mm (aarch64 only).
pub fn i8mm_usable() -> bool {
    #[cfg(target_arch = "aarch64")]
    {
        std::arch::is_aarch64_feature_detected!("dotprod")
            && std::arch::is_aarch64_feature_detected!("i8mm")
    }
    #[cfg(not(target_arch = "aarch64"))]
    false
}

/// Whether the AMX tile kernel runs now (after [`init`]).
pub fn amx_active() -> bool {
    #[cfg(target_arch = "x86_64")]
    return simd::amx::enabled();
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Whether this CPU has AMX-TILE and AMX-INT8 and the OS granted this
/// process the tile data state (asked for here; Linux x86_64 only).
pub fn amx_usable() -> bool {
    #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
    {
        simd::amx::cpu_has_amx_int8() && simd::amx::request_linux_permission()
    }
    #[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
    false
}
