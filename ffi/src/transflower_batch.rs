//! Transflower sessions stepped through a `duo_step_batch`
//! (`duolando_core::transflower::session::StepBatch`): the step scratch and
//! the flow's reverse 1x1 weights of one model, held once, the sessions
//! stepped one after another through it, each with its own seeded RNG;
//! every frame is the one the session makes stepped alone, bit for bit.
//! A session made with `batched` = 1 (`duo_transflower_config`) holds its
//! state alone (`duo_transflower_session_bytes` gives the smaller size) and
//! is stepped only here; one with its own step memory may be stepped both
//! ways. The batch keeps its model alive (a counted reference, as a
//! session does). Handle, placement, release and the checks shared with
//! Duolando batches: [`crate::batch`].

use std::sync::Arc;

use duolando_core::family::Family;
use duolando_core::transflower::session::StepBatch;
use duolando_core::Error;

use crate::batch::{
    check_sessions, family_refusal, place, sessions_mut, the_call, with_failed, with_handle,
    DuoStepBatch, Kind,
};
use crate::model::{share, AnyModel, DuoModel};
use crate::result::{guard, DuoResult, Failure};
use crate::session::{model_ref, AnySession, DuoSession};
use crate::transflower::{fail, transflower};

/// Both constructors: the model (a Transflower one), the batch's arena
/// (`memory` as [`place`]), its reverse weights computed once.
///
/// # Safety
/// As duo_transflower_step_batch_new_in (`memory` None: as _new).
unsafe fn make(
    what: &str,
    model: *const DuoModel,
    memory: Option<(*mut u8, usize)>,
    out_batch: *mut *mut DuoStepBatch,
) -> Result<DuoResult, Failure> {
    let t = transflower(model_ref(model)?, what)?;
    let n = StepBatch::bytes(&t.cfg)?;
    // SAFETY: `model` is a live handle (contract).
    let arc = unsafe { share(model) };
    // SAFETY: the caller's contract.
    unsafe {
        place(
            n,
            memory,
            "duo_transflower_step_batch_bytes",
            out_batch,
            |arena| {
                let AnyModel::Transflower(tm) = arc.any() else {
                    return Err(Failure::invalid("not a Transflower model"));
                };
                let batch = StepBatch::new(tm, arena)?;
                Ok(Kind::Transflower {
                    batch: std::sync::Mutex::new(batch),
                    model: arc,
                })
            },
        )
    }
}

/// Bytes `duo_transflower_step_batch_new_in` needs (any address): the
/// model's step scratch and reverse weights, and the handle.
///
/// # Safety
/// `model` NULL or live; `out_bytes` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_step_batch_bytes(
    model: *const DuoModel,
    out_bytes: *mut usize,
) -> DuoResult {
    guard("duo_transflower_step_batch_bytes", || {
        let t = transflower(model_ref(model)?, "duo_transflower_step_batch_bytes")?;
        if out_bytes.is_null() {
            return Err(Failure::null("out_bytes"));
        }
        let n = with_handle(StepBatch::bytes(&t.cfg)?)?;
        // SAFETY: checked non-NULL.
        unsafe { *out_bytes = n };
        Ok(DuoResult::Ok)
    })
}

/// A batch for the sessions of a Transflower model, in library memory
/// (allocated here, once).
///
/// # Safety
/// `model` NULL or live; `out_batch` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_step_batch_new(
    model: *const DuoModel,
    out_batch: *mut *mut DuoStepBatch,
) -> DuoResult {
    guard("duo_transflower_step_batch_new", || {
        // SAFETY: the caller's contract.
        unsafe { make("duo_transflower_step_batch_new", model, None, out_batch) }
    })
}

/// As duo_transflower_step_batch_new, placed entirely in caller memory
/// (`memory`, `len` >= duo_transflower_step_batch_bytes; any alignment):
/// no allocation.
///
/// # Safety
/// As duo_transflower_step_batch_new; `memory` NULL or `len` writable
/// bytes that stay valid, unmoved and otherwise untouched until
/// `duo_step_batch_free`.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_step_batch_new_in(
    model: *const DuoModel,
    memory: *mut u8,
    len: usize,
    out_batch: *mut *mut DuoStepBatch,
) -> DuoResult {
    guard("duo_transflower_step_batch_new_in", || {
        // SAFETY: the caller's contract.
        unsafe {
            make(
                "duo_transflower_step_batch_new_in",
                model,
                Some((memory, len)),
                out_batch,
            )
        }
    })
}

/// Steps every session of `sessions[0..n]` whose input is in once (one
/// frame each, kept for its pulls), one after another through the
/// batch's memory, each with its own seeded RNG; a session without its
/// input is skipped. `*out_stepped` (NULL or writable) = how many stepped.
///
/// Refusals in the header's order, the first one found answering (no
/// session changes; `*failed_session` = the session concerned, else
/// `DUO_NO_SESSION`): 1. the call ([`the_call`]); 2. the sessions
/// ([`check_sessions`]: another family, another model than the batch's);
/// 4. the sessions, by index, whose pending frames are full (`DUO_BACKLOG`).
///
/// # Safety
/// `batch` NULL or live; `sessions` NULL or `n` readable pointers, each
/// NULL or a live session not used by another thread during the call;
/// `out_stepped` and `failed_session` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_step_batch_step(
    batch: *mut DuoStepBatch,
    sessions: *const *mut DuoSession,
    n: usize,
    out_stepped: *mut usize,
    failed_session: *mut usize,
) -> DuoResult {
    // SAFETY: the caller's contract (see step_many).
    with_failed("duo_step_batch_step", failed_session, |failed| unsafe {
        let stepped = step_many(batch, sessions, n, failed)?;
        if !out_stepped.is_null() {
            // SAFETY: non-NULL and writable (contract).
            *out_stepped = stepped;
        }
        Ok(DuoResult::Ok)
    })
}

/// The body of [`duo_step_batch_step`]: the sessions stepped.
///
/// # Safety
/// As [`duo_step_batch_step`].
unsafe fn step_many(
    batch: *mut DuoStepBatch,
    sessions: *const *mut DuoSession,
    n: usize,
    failed: &mut usize,
) -> Result<usize, Failure> {
    let what = "duo_step_batch_step";
    // SAFETY: the caller's contract.
    let Some((kind, ptrs)) = (unsafe { the_call(batch, Family::Transflower, what, sessions, n) })?
    else {
        return Ok(0);
    };
    let Kind::Transflower { batch, model } = kind else {
        return Err(Failure::invalid("not a Transflower batch"));
    };
    // SAFETY: the caller's contract.
    unsafe {
        check_sessions(ptrs, failed, |i, s| {
            if !matches!(s.session, AnySession::Transflower(_)) {
                return Err(family_refusal(i, s, Family::Transflower));
            }
            if !Arc::ptr_eq(&s.model, model) {
                return Err(Failure::invalid(format!(
                    "sessions[{i}] is a session of another model than the batch's"
                )));
            }
            Ok(())
        })
    }?;
    // SAFETY: checked live and pairwise distinct above (contract).
    let mut refs = unsafe {
        sessions_mut(ptrs, |s| match s {
            AnySession::Transflower(t) => Some(t),
            _ => None,
        })
    }?;
    // 4. Backlog, by index, before any session changes.
    for (i, s) in refs.iter().enumerate() {
        let capacity = s.config().pending_frames as usize;
        if s.pending() >= capacity {
            *failed = i;
            let e = Error::Backlog {
                buffer: duolando_core::error::Buffer::Output,
                held: s.pending(),
                capacity,
            };
            let f = fail(e, s);
            return Err(Failure::new(
                f.code,
                format!("sessions[{i}]: {}", f.message),
            ));
        }
    }
    // Model and backlog checked: core steps the ready ones.
    crate::batch::lock(batch)
        .step(&mut refs)
        .map_err(|e| match e {
            Error::State => Failure::invalid("a session of another model than the batch's"),
            e => Failure::from(e),
        })
}
