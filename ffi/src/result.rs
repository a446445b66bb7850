//! Result codes, the thread-local last error message, and the panic
//! boundary every entry point runs inside.
//!
//! Convention (rustls-ffi): every fallible function returns a
//! [`DuoResult`]; on anything but `DUO_OK` (and `DUO_NOT_READY`, which is
//! not a failure) it also stores a one-line message for the calling thread,
//! readable with [`duo_last_error_message`]. Outputs are written only on
//! `DUO_OK`.

use std::cell::RefCell;
use std::ffi::c_char;
use std::panic::{catch_unwind, AssertUnwindSafe};

use duolando_core::arena::ArenaError;
use duolando_core::Error;

/// `duo_result` in the header. Numbers are stable; new codes may be added
/// at the end (treat any unknown code as a failure).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DuoResult {
    /// Success.
    Ok = 0,
    /// A required pointer argument was NULL.
    NullParameter = 1,
    /// An argument has a wrong value or size (wrong float count, unknown
    /// enum value, seed token out of vocabulary, misaligned model bytes,
    /// an invalid session configuration).
    InvalidArgument = 2,
    /// The model bytes or file are not a valid `.duo` model (the message
    /// names the reason: magic, version, truncated, tensor, shape, ...).
    BadModel = 3,
    /// A caller buffer is too small (session memory).
    BufferTooSmall = 4,
    /// No follower frame is ready yet (not a failure: push more input).
    NotReady = 5,
    /// An input frame holds NaN, infinity, or a value beyond the accepted
    /// magnitude; it was rejected and the session is unchanged.
    NonFiniteInput = 6,
    /// The session refused the push: ready follower frames must be pulled
    /// first (or the music buffer is full). The session is unchanged.
    Backlog = 7,
    /// An operating-system call failed: the model file could not be opened
    /// or read, or a worker thread could not be started.
    Io = 8,
    /// A panic was caught inside the library (a bug: please report it).
    /// The object the call was made on must not be used again except to
    /// free it.
    Panic = 9,
    /// An internal invariant failed (a bug: please report it).
    Internal = 10,
    /// The session was told the leader has ended (`duo_session_finish`): it
    /// takes no more leader frames until `duo_session_reset`. Unchanged.
    Ended = 11,
}

impl DuoResult {
    /// The `DUO_*` name, for messages and tests.
    pub fn name(self) -> &'static str {
        match self {
            DuoResult::Ok => "DUO_OK",
            DuoResult::NullParameter => "DUO_NULL_PARAMETER",
            DuoResult::InvalidArgument => "DUO_INVALID_ARGUMENT",
            DuoResult::BadModel => "DUO_BAD_MODEL",
            DuoResult::BufferTooSmall => "DUO_BUFFER_TOO_SMALL",
            DuoResult::NotReady => "DUO_NOT_READY",
            DuoResult::NonFiniteInput => "DUO_NON_FINITE_INPUT",
            DuoResult::Backlog => "DUO_BACKLOG",
            DuoResult::Io => "DUO_IO",
            DuoResult::Panic => "DUO_PANIC",
            DuoResult::Internal => "DUO_INTERNAL",
            DuoResult::Ended => "DUO_ENDED",
        }
    }
}

/// A failure on its way out: the code and the message to store.
#[derive(Debug)]
pub struct Failure {
    pub code: DuoResult,
    pub message: String,
}

impl Failure {
    pub fn new(code: DuoResult, message: impl Into<String>) -> Self {
        Failure {
            code,
            message: message.into(),
        }
    }
    pub fn null(what: &str) -> Self {
        Failure::new(DuoResult::NullParameter, format!("{what} is NULL"))
    }
    pub fn invalid(message: impl Into<String>) -> Self {
        Failure::new(DuoResult::InvalidArgument, message)
    }
}

/// The result code for a core error (the message comes from
/// `duolando::engine_errors::describe`).
pub fn code_of(e: &Error) -> DuoResult {
    match e {
        Error::NonFinite { .. } | Error::OutOfRange { .. } => DuoResult::NonFiniteInput,
        Error::Backlog { .. } => DuoResult::Backlog,
        Error::Ended { .. } => DuoResult::Ended,
        Error::Evicted { .. } => DuoResult::Internal,
        Error::Setting { .. } | Error::State => DuoResult::InvalidArgument,
        Error::Arena(ArenaError::OutOfMemory { .. }) => DuoResult::BufferTooSmall,
        Error::Arena(ArenaError::Overflow) => DuoResult::InvalidArgument,
        Error::Bind(_) => DuoResult::BadModel,
        Error::Length { .. }
        | Error::Ragged { .. }
        | Error::TooShort { .. }
        | Error::Token { .. }
        | Error::Context { .. } => DuoResult::InvalidArgument,
        #[allow(unreachable_patterns)]
        _ => DuoResult::InvalidArgument,
    }
}

impl From<Error> for Failure {
    fn from(e: Error) -> Self {
        Failure::new(code_of(&e), duolando_runtime::engine_errors::describe(&e))
    }
}

thread_local! {
    static LAST_ERROR: RefCell<String> = const { RefCell::new(String::new()) };
}

/// Stores `message` as this thread's last error.
pub fn set_last_error(message: &str) {
    // `try_with`: during thread teardown the slot may be gone; drop it then.
    let _ = LAST_ERROR.try_with(|slot| {
        if let Ok(mut s) = slot.try_borrow_mut() {
            s.clear();
            s.push_str(message);
        }
    });
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "non-string panic payload".to_string()
    }
}

/// The panic boundary: runs `f`, stores the message of a failure, maps a
/// panic to `DUO_PANIC`. `what` names the entry point in messages.
pub fn guard<F>(what: &str, f: F) -> DuoResult
where
    F: FnOnce() -> Result<DuoResult, Failure>,
{
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(code)) => code,
        Ok(Err(fail)) => {
            set_last_error(&format!("{what}: {}", fail.message));
            fail.code
        }
        Err(payload) => {
            // Formatting may itself panic (out of memory is an abort, not a
            // panic); keep the boundary airtight.
            let _ = catch_unwind(AssertUnwindSafe(|| {
                set_last_error(&format!(
                    "{what}: panic inside duolando: {}",
                    panic_message(&*payload)
                ))
            }));
            DuoResult::Panic
        }
    }
}

/// Copies this thread's last error message into `buf` (`len` bytes) as a
/// NUL-terminated string, truncated to `len - 1` bytes at a UTF-8 boundary
/// (nothing is written when `buf` is NULL or `len` is 0). Returns the full
/// message length in bytes, without the NUL (snprintf convention: a return
/// value >= `len` means the copy was truncated; call with `NULL, 0` to size
/// a buffer). Returns 0 when this thread has no message. The message is
/// that of the most recent call on this thread that failed; successful
/// calls leave it as it was.
///
/// # Safety
/// `buf` must be NULL or point to `len` writable bytes.
#[no_mangle]
pub unsafe extern "C" fn duo_last_error_message(buf: *mut c_char, len: usize) -> usize {
    catch_unwind(AssertUnwindSafe(|| {
        LAST_ERROR
            .try_with(|slot| {
                let Ok(msg) = slot.try_borrow() else { return 0 };
                if !buf.is_null() && len > 0 {
                    let mut n = msg.len().min(len - 1);
                    while n > 0 && !msg.is_char_boundary(n) {
                        n -= 1;
                    }
                    // SAFETY: the caller promises `len` writable bytes at
                    // `buf`; n + 1 <= len.
                    unsafe {
                        std::ptr::copy_nonoverlapping(msg.as_ptr(), buf.cast::<u8>(), n);
                        *buf.add(n) = 0;
                    }
                }
                msg.len()
            })
            .unwrap_or(0)
    }))
    .unwrap_or(0)
}

/// The static name of a result code (`"DUO_OK"`, ...; `"DUO_UNKNOWN"` for a
/// number that is not a code). Never NULL; do not free. Thread-safe.
#[no_mangle]
pub extern "C" fn duo_result_name(result: i32) -> *const c_char {
    catch_unwind(|| {
        let s: &'static std::ffi::CStr = match result {
            0 => c"DUO_OK",
            1 => c"DUO_NULL_PARAMETER",
            2 => c"DUO_INVALID_ARGUMENT",
            3 => c"DUO_BAD_MODEL",
            4 => c"DUO_BUFFER_TOO_SMALL",
            5 => c"DUO_NOT_READY",
            6 => c"DUO_NON_FINITE_INPUT",
            7 => c"DUO_BACKLOG",
            8 => c"DUO_IO",
            9 => c"DUO_PANIC",
            10 => c"DUO_INTERNAL",
            11 => c"DUO_ENDED",
            _ => c"DUO_UNKNOWN",
        };
        s.as_ptr()
    })
    .unwrap_or(c"DUO_UNKNOWN".as_ptr())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn last() -> String {
        // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
        let n = unsafe { duo_last_error_message(std::ptr::null_mut(), 0) };
        let mut buf = vec![0 as c_char; n + 1];
        let m = unsafe { duo_last_error_message(buf.as_mut_ptr(), buf.len()) };
        assert_eq!(m, n);
        unsafe { std::ffi::CStr::from_ptr(buf.as_ptr()) }
            .to_str()
            .unwrap()
            .to_string()
    }

    #[test]
    fn guard_maps_failures_and_panics() {
        assert_eq!(guard("f", || Ok(DuoResult::Ok)), DuoResult::Ok);
        assert_eq!(
            guard("f", || Err(Failure::null("out"))),
            DuoResult::NullParameter
        );
        assert_eq!(last(), "f: out is NULL");
        assert_eq!(
            guard("g", || -> Result<DuoResult, Failure> { panic!("boom") }),
            DuoResult::Panic
        );
        assert_eq!(last(), "g: panic inside duolando: boom");
        // Success leaves the message.
        assert_eq!(guard("h", || Ok(DuoResult::Ok)), DuoResult::Ok);
        assert_eq!(last(), "g: panic inside duolando: boom");
    }

    #[test]
    fn message_truncates_snprintf_style() {
        // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
        set_last_error("héllo");
        let mut buf = [0x55 as c_char; 3];
        // "h" + 2-byte "é": 2 bytes fit, but that would split "é": keep "h".
        let n = unsafe { duo_last_error_message(buf.as_mut_ptr(), 3) };
        assert_eq!(n, "héllo".len());
        assert_eq!(buf[0] as u8, b'h');
        assert_eq!(buf[1], 0);
        let n0 = unsafe { duo_last_error_message(buf.as_mut_ptr(), 0) };
        assert_eq!(n0, n);
        assert_eq!(buf[0] as u8, b'h');
        // Messages are per thread.
        std::thread::spawn(|| {
            assert_eq!(
                unsafe { duo_last_error_message(std::ptr::null_mut(), 0) },
                0
            )
        })
        .join()
        .unwrap();
    }

    #[test]
    fn result_names() {
        // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
        for (i, code) in [
            DuoResult::Ok,
            DuoResult::NullParameter,
            DuoResult::InvalidArgument,
            DuoResult::BadModel,
            DuoResult::BufferTooSmall,
            DuoResult::NotReady,
            DuoResult::NonFiniteInput,
            DuoResult::Backlog,
            DuoResult::Io,
            DuoResult::Panic,
            DuoResult::Internal,
            DuoResult::Ended,
        ]
        .into_iter()
        .enumerate()
        {
            assert_eq!(code as i32, i as i32);
            let s = unsafe { std::ffi::CStr::from_ptr(duo_result_name(i as i32)) };
            assert_eq!(s.to_str().unwrap(), code.name());
        }
        let s = unsafe { std::ffi::CStr::from_ptr(duo_result_name(-1)) };
        assert_eq!(s.to_str().unwrap(), "DUO_UNKNOWN");
    }
}
