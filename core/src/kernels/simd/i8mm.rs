//! The NEON i8mm switch: on [`Isa::NeonDot`], the packed int8 GEMM
//! ([`super::gemm_q8_packed`]) runs [`super::neon::gemm_q8_packed_i8mm`]
//! (`smmla`, bit-identical to the `sdot` kernel) where the runtime found the
//! i8mm extension and enabled it, as [`super::amx`] does for AMX on
//! AVX512-VNNI. Every other kernel stays [`Isa::NeonDot`]'s.

use core::sync::atomic::{AtomicBool, Ordering};

use super::Isa;

static ENABLED: AtomicBool = AtomicBool::new(false);

/// Lets the i8mm packed kernel run (`on`) or stops it.
///
/// # Safety
/// With `on`, the CPU must support the i8mm extension (and dotprod, which
/// the [`Isa::NeonDot`] selection already vouches for). The kernel runs only
/// while the selected ISA is [`Isa::NeonDot`].
pub unsafe fn enable(on: bool) {
    ENABLED.store(on, Ordering::Relaxed);
}

/// Whether the i8mm kernel runs: enabled and the selected ISA is NeonDot.
#[inline]
pub fn enabled() -> bool {
    ENABLED.load(Ordering::Relaxed) && super::isa() == Isa::NeonDot
}
