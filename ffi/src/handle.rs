//! Handles placed in caller memory (`duo_session_new_in`,
//! `duo_step_batch_new_in`) or boxed by the library, and their release:
//! the one place that does the alignment arithmetic.

use crate::result::{DuoResult, Failure};

/// Bytes of caller memory a handle `T` takes at the worst alignment.
pub const fn handle_bytes<T>() -> usize {
    std::mem::size_of::<T>() + std::mem::align_of::<T>()
}

/// Splits caller memory (`memory`, `len` bytes, any alignment) into an
/// aligned, uninitialised slot for a `T` and the bytes after it (the
/// arena). `need` is what the object needs in all (its arena plus
/// [`handle_bytes`]); `bytes_fn` names the function that tells it.
///
/// # Safety
/// `memory` is non-NULL and points to `len` writable bytes that stay valid,
/// unmoved and otherwise untouched while the slot and arena are in use.
pub unsafe fn caller_slot<T>(memory: *mut u8, len: usize, need: usize, bytes_fn: &str) -> Result<(*mut T, &'static mut [u8]), Failure> {
    if len < need {
        return Err(Failure::new(DuoResult::BufferTooSmall, format!("memory has {len} bytes, this configuration needs {need} ({bytes_fn})")));
    }
    let pad = memory.align_offset(std::mem::align_of::<T>());
    if pad == usize::MAX || pad + std::mem::size_of::<T>() > len {
        return Err(Failure::new(DuoResult::BufferTooSmall, "memory cannot hold the handle"));
    }
    // SAFETY: [pad, pad + size) lies in the caller's `len` bytes (checked)
    // and is aligned for T; the arena is the rest, disjoint (the contract).
    unsafe {
        let start = pad + std::mem::size_of::<T>();
        Ok((memory.add(pad).cast::<T>(), std::slice::from_raw_parts_mut(memory.add(start), len - start)))
    }
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
