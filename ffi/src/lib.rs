//! duolando-ffi: the C ABI over duolando-core (`include/duolando.h`,
//! documented in docs/C_API.md).
//!
//! Objects: [`model`] (`duo_model`, immutable, shared by threads and
//! sessions) and `session` (`duo_session`, one dancer, one thread at a
//! time); [`batch`] (`duo_step_batch`, sessions of one model stepped
//! together; Transflower's: [`transflower_batch`]); [`frames`] (blittable frame structs, coordinate conversions);
//! [`result`] (result codes, the thread-local last error, the panic
//! boundary). Every entry point catches panics: no unwinding crosses the C
//! boundary. Outputs are written only on success.

use std::ffi::c_char;
use std::panic::catch_unwind;

pub mod batch;
pub mod batched_session;
pub mod frames;
mod handle;
pub mod model;
pub mod result;
pub mod session;
pub mod transflower;
pub mod transflower_batch;

pub use batch::DuoStepBatch;
pub use frames::{DuoFollowerFrame, DuoLeaderFrame, DuoQuat, DuoVec3};
pub use model::{DuoModel, DuoModelInfo};
pub use result::DuoResult;
pub use session::{DuoSession, DuoSessionConfig};

/// Major version, as in Cargo.toml (`DUOLANDO_VERSION_MAJOR` in the header).
pub const VERSION_MAJOR: u32 = 0;
/// Minor version (`DUOLANDO_VERSION_MINOR`).
pub const VERSION_MINOR: u32 = 2;
/// Patch version (`DUOLANDO_VERSION_PATCH`).
pub const VERSION_PATCH: u32 = 0;

static VERSION: &[u8] = concat!(env!("CARGO_PKG_VERSION"), "\0").as_bytes();

/// The library version as a static NUL-terminated string ("0.2.0").
/// Never NULL; the caller must not free it. Thread-safe.
#[no_mangle]
pub extern "C" fn duo_version() -> *const c_char {
    catch_unwind(|| VERSION.as_ptr().cast::<c_char>()).unwrap_or(c"?".as_ptr())
}

/// Most threads [`duo_set_threads`] accepts.
pub const MAX_THREADS: u32 = 64;

/// Splits the large matrix products of every later call (all models and
/// sessions of this process) over `threads` threads: the calling thread
/// plus `threads - 1` pooled workers, started on first use of that count.
/// 0 or 1: everything on the calling thread (the default). Outputs do not
/// depend on the thread count (bit-identical). One split product runs at a
/// time: a session stepped on another thread meanwhile computes on its own
/// thread. `DUO_INVALID_ARGUMENT` above `DUOLANDO_MAX_THREADS` (64);
/// `DUO_IO` when the operating system refuses a thread. Thread-safe.
#[no_mangle]
pub extern "C" fn duo_set_threads(threads: u32) -> DuoResult {
    result::guard("duo_set_threads", || {
        if threads > MAX_THREADS {
            return Err(result::Failure::new(
                DuoResult::InvalidArgument,
                format!("{threads} threads: at most {MAX_THREADS}"),
            ));
        }
        duolando_runtime::workers::set_threads(threads as usize).map_err(|e| {
            result::Failure::new(
                DuoResult::Io,
                format!("could not start {threads} threads: {e}"),
            )
        })?;
        Ok(DuoResult::Ok)
    })
}

/// The thread count set by [`duo_set_threads`] (1 when unset). Thread-safe.
#[no_mangle]
pub extern "C" fn duo_get_threads() -> u32 {
    catch_unwind(|| duolando_runtime::workers::threads() as u32).unwrap_or(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_threads_accepts_0_to_64_and_reports_above() {
        assert_eq!(duo_set_threads(2), DuoResult::Ok);
        assert_eq!(duo_get_threads(), 2);
        assert_eq!(duo_set_threads(0), DuoResult::Ok);
        assert_eq!(duo_get_threads(), 1);
        assert_eq!(duo_set_threads(MAX_THREADS + 1), DuoResult::InvalidArgument);
        assert_eq!(duo_get_threads(), 1);
        let mut buf = [0u8; 128];
        // SAFETY: buf is a live local of the given length.
        let n = unsafe { result::duo_last_error_message(buf.as_mut_ptr().cast(), buf.len()) };
        let msg = std::str::from_utf8(&buf[..n.min(127)]).unwrap();
        assert_eq!(msg, "duo_set_threads: 65 threads: at most 64");
    }

    #[test]
    fn version_matches_cargo_toml() {
        // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
        let s = unsafe { std::ffi::CStr::from_ptr(duo_version()) }
            .to_str()
            .unwrap();
        assert_eq!(s, env!("CARGO_PKG_VERSION"));
        assert_eq!(
            s,
            format!("{VERSION_MAJOR}.{VERSION_MINOR}.{VERSION_PATCH}")
        );
        let header = include_str!("../../include/duolando.h");
        for (name, v) in [
            ("MAJOR", VERSION_MAJOR),
            ("MINOR", VERSION_MINOR),
            ("PATCH", VERSION_PATCH),
        ] {
            assert!(
                header.contains(&format!("#define DUOLANDO_VERSION_{name} {v}\n")),
                "include/duolando.h: DUOLANDO_VERSION_{name} must be {v}"
            );
        }
    }
}
