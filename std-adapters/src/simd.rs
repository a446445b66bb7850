//! Run-time selection of the core's SIMD kernels (`duolando_core::kernels::simd`).
//! Core (no_std) can only use what the compile-time target features
//! guarantee; the std side detects the CPU once and switches the
//! process-wide kernel table. Call [`init`] once at start-up (the CLI
//! commands that run the model do).
//!
//! `DUOLANDO_ISA=scalar|avx2|avx512|avx512vnni|neon|neondot` caps the
//! choice (an ISA this CPU lacks selects scalar), for comparisons.

use duolando_core::kernels::simd::{self, Isa};

/// Every ISA this CPU supports that the core has kernels for, best first.
pub fn supported() -> Vec<Isa> {
    #[allow(unused_mut)]
    let mut v = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        use std::is_x86_feature_detected as has;
        let avx2 = has!("avx2") && has!("fma") && has!("f16c");
        let avx512 = avx2 && has!("avx512f") && has!("avx512bw") && has!("avx512dq") && has!("avx512vl");
        if avx512 && has!("avx512vnni") {
            v.push(Isa::Avx512Vnni);
        }
        if avx512 {
            v.push(Isa::Avx512);
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
        "avx512" => Isa::Avx512,
        "avx512vnni" => Isa::Avx512Vnni,
        "neon" => Isa::Neon,
        "neondot" => Isa::NeonDot,
        _ => return None,
    })
}

/// Selects the detected kernels ([`detect`]) for the whole process; returns them.
pub fn init() -> Isa {
    let isa = detect();
    // SAFETY: `detect` returned `isa` only from `supported`, which checked
    // that this CPU supports every feature its kernels are compiled for.
    #[allow(unsafe_code)]
    unsafe { simd::set_isa(isa) };
    isa
}
