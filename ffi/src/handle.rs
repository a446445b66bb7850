//! Handles placed in caller memory (`duo_session_new_in`,
//! `duo_step_batch_new_in`) or boxed by the library, and their release:
//! the one place that does the alignment arithmetic. Also the header's
//! buffer rule ([`buffer`], [`buffer_mut`]): the one place that turns a
//! caller's pointer and length into a slice.

use crate::result::{DuoResult, Failure};

/// Bytes of caller memory a handle `T` takes at the worst alignment.
pub const fn handle_bytes<T>() -> usize {
    std::mem::size_of::<T>() + std::mem::align_of::<T>()
}

/// `len` elements at `ptr` under the header's rule: a NULL buffer with
/// length 0 is an empty buffer, exactly like a non-NULL one with length 0
/// (the call then answers as for any empty buffer); NULL with a length is
/// `DUO_NULL_PARAMETER` naming `what`.
///
/// # Safety
/// `ptr` NULL, or `len` readable, aligned `T` that stay valid for `'x`.
pub unsafe fn buffer<'x, T>(ptr: *const T, len: usize, what: &str) -> Result<&'x [T], Failure> {
    if ptr.is_null() {
        return if len == 0 {
            Ok(&[])
        } else {
            Err(Failure::null(what))
        };
    }
    // SAFETY: non-NULL with `len` readable elements (contract).
    Ok(unsafe { std::slice::from_raw_parts(ptr, len) })
}

/// [`buffer`] for caller memory the library writes.
///
/// # Safety
/// `ptr` NULL, or `len` writable bytes that stay valid for `'x` and that
/// nothing else uses meanwhile.
pub unsafe fn buffer_mut<'x>(
    ptr: *mut u8,
    len: usize,
    what: &str,
) -> Result<&'x mut [u8], Failure> {
    if ptr.is_null() {
        return if len == 0 {
            Ok(&mut [])
        } else {
            Err(Failure::null(what))
        };
    }
    // SAFETY: non-NULL with `len` writable bytes (contract).
    Ok(unsafe { std::slice::from_raw_parts_mut(ptr, len) })
}

/// Splits caller memory (`memory`, any alignment; empty is refused as too
/// small like any short buffer) into an aligned, uninitialised slot for a
/// `T` and the bytes after it (the arena). `need` is what the object needs
/// in all (its arena plus [`handle_bytes`]); `bytes_fn` names the function
/// that tells it.
pub fn caller_slot<T>(
    memory: &'static mut [u8],
    need: usize,
    bytes_fn: &str,
) -> Result<(*mut T, &'static mut [u8]), Failure> {
    let len = memory.len();
    if len < need {
        return Err(Failure::new(
            DuoResult::BufferTooSmall,
            format!("memory has {len} bytes, this configuration needs {need} ({bytes_fn})"),
        ));
    }
    let pad = memory.as_ptr().align_offset(std::mem::align_of::<T>());
    if pad == usize::MAX || pad.saturating_add(std::mem::size_of::<T>()) > len {
        return Err(Failure::new(
            DuoResult::BufferTooSmall,
            "memory cannot hold the handle",
        ));
    }
    let (head, arena) = memory.split_at_mut(pad + std::mem::size_of::<T>());
    Ok((head[pad..].as_mut_ptr().cast::<T>(), arena))
}

/// Drops a handle: in place when it lives in caller memory, else as the
/// `Box` it came from. NULL is ignored.
///
/// # Safety
/// `p` NULL, or a live handle from `Box::into_raw` (`in_caller_memory`
/// false) or written into a [`caller_slot`] (true); dropped once.
pub unsafe fn drop_handle<T>(p: *mut T, in_caller_memory: impl FnOnce(&T) -> bool) {
    if p.is_null() {
        return;
    }
    // SAFETY: a live handle (contract); the flag is read before dropping.
    unsafe {
        if in_caller_memory(&*p) {
            std::ptr::drop_in_place(p);
        } else {
            drop(Box::from_raw(p));
        }
    }
}
