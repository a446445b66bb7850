//! Run-time selection of the core's SIMD kernels (`duolando_core::kernels::simd`).
//! Core (no_std) can only use what the compile-time target features
//! guarantee; the std side detects the CPU once and switches the
//! process-wide kernel table. Call [`init`] once at start-up (the CLI
//! commands that run the model do).

use duolando_core::kernels::simd::{self, Isa};

/// The best ISA this CPU supports that the core has kernels for.
pub fn detect() -> Isa {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") && std::is_x86_feature_detected!("f16c") {
        return Isa::Avx2;
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    return Isa::Neon;
    #[allow(unreachable_code)]
    Isa::Scalar
}

/// Selects the detected kernels ([`detect`]) for the whole process; returns them.
pub fn init() -> Isa {
    let isa = detect();
    // SAFETY: `detect` returned `isa` only after checking that this CPU
    // supports every feature its kernels are compiled for.
    unsafe { simd::set_isa(isa) };
    isa
}
