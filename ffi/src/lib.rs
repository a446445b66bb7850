//! duolando-ffi: the C ABI over duolando-core (`include/duolando.h`,
//! documented in docs/C_API.md).
//!
//! Objects: [`model`] (`duo_model`, immutable, shared by threads and
//! sessions) and `session` (`duo_session`, one dancer, one thread at a
//! time); [`frames`] (blittable frame structs, coordinate conversions);
//! [`result`] (result codes, the thread-local last error, the panic
//! boundary). Every entry point catches panics: no unwinding crosses the C
//! boundary. Outputs are written only on success.

use std::ffi::c_char;
use std::panic::catch_unwind;

pub mod frames;
pub mod model;
pub mod result;
pub mod session;

pub use frames::{DuoFollowerFrame, DuoLeaderFrame, DuoQuat, DuoVec3};
pub use model::{DuoModel, DuoModelInfo};
pub use result::DuoResult;
pub use session::{DuoSession, DuoSessionConfig};

/// Major version, as in Cargo.toml (`DUOLANDO_VERSION_MAJOR` in the header).
pub const VERSION_MAJOR: u32 = 0;
/// Minor version (`DUOLANDO_VERSION_MINOR`).
pub const VERSION_MINOR: u32 = 1;
/// Patch version (`DUOLANDO_VERSION_PATCH`).
pub const VERSION_PATCH: u32 = 0;

static VERSION: &[u8] = concat!(env!("CARGO_PKG_VERSION"), "\0").as_bytes();

/// The library version as a static NUL-terminated string ("0.1.0").
/// Never NULL; the caller must not free it. Thread-safe.
#[no_mangle]
pub extern "C" fn duo_version() -> *const c_char {
    catch_unwind(|| VERSION.as_ptr().cast::<c_char>()).unwrap_or(c"?".as_ptr())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn version_matches_cargo_toml() {
        // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
        let s = unsafe { std::ffi::CStr::from_ptr(duo_version()) }.to_str().unwrap();
        assert_eq!(s, env!("CARGO_PKG_VERSION"));
        assert_eq!(s, format!("{VERSION_MAJOR}.{VERSION_MINOR}.{VERSION_PATCH}"));
        let header = include_str!("../../include/duolando.h");
        for (name, v) in [("MAJOR", VERSION_MAJOR), ("MINOR", VERSION_MINOR), ("PATCH", VERSION_PATCH)] {
            assert!(
                header.contains(&format!("#define DUOLANDO_VERSION_{name} {v}\n")),
                "include/duolando.h: DUOLANDO_VERSION_{name} must be {v}"
            );
        }
    }
}
