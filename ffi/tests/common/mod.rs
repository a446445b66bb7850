//! Helpers shared by the ffi test crates (each says `mod common;`): the
//! committed fixtures, the thread's last error message, a model opened
//! through the C entry point.
#![allow(dead_code)] // each test crate uses its own subset

pub mod golden;

use std::ffi::{c_char, CStr, CString};
use std::path::{Path, PathBuf};
use std::ptr;

use duolando::model::{duo_model_open_file, DuoModel};
use duolando::result::{duo_last_error_message, DuoResult};

/// `tests/fixtures/<name>` of the workspace.
pub fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/fixtures")
        .join(name)
}

/// The calling thread's last error message (`duo_last_error_message`).
pub fn last_error() -> String {
    let mut buf = vec![0 as c_char; 512];
    // SAFETY: a writable buffer of the given length; the result is NUL-terminated.
    unsafe { duo_last_error_message(buf.as_mut_ptr(), buf.len()) };
    // SAFETY: as above.
    unsafe { CStr::from_ptr(buf.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

/// `duo_model_open_file(path)`, which must succeed (else the test fails
/// with the library's message). The caller frees the handle.
pub fn open_model(path: &Path) -> *mut DuoModel {
    let p = CString::new(path.to_str().unwrap()).unwrap();
    let mut m = ptr::null_mut();
    // SAFETY: a NUL-terminated path and a live out-pointer.
    assert_eq!(
        unsafe { duo_model_open_file(p.as_ptr(), &mut m) },
        DuoResult::Ok,
        "{}: {}",
        path.display(),
        last_error()
    );
    m
}
