//! `duo_step_batch`: several dancers on one model stepped together
//! (`duolando_core::duolando::session::Session::step_many`): one leader frame per
//! session per call, and each weight matrix of the LATs, the GPT and the
//! heads read once for all of them. Every session ends exactly as after
//! its own `duo_session_push_leader` (bit for bit); only the time differs
//! (docs/PERFORMANCE.md: 16 sessions in 4.4-4.6x the time of one at full
//! size).
//!
//! A batch is scratch memory only (no session state, no model reference):
//! it is sized for a session configuration and a number of sessions, and
//! steps any sessions of one model whose configurations need no more than
//! that one. Sessions keep their own handles (`duo_session_new` /
//! `duo_session_new_in`) and every other call (music, pulls, reset) as
//! before.
//!
//! Thread rule: a batch is used by one thread at a time, and the sessions
//! of a call are not used by any other thread during it.

use duolando_core::duolando::config::ModelConfig;
use duolando_core::duolando::session::{Session, SessionConfig, StepBatch, StepDims, MAX_BATCH};
use duolando_core::Error;

use crate::frames::DuoLeaderFrame;
use crate::handle::{buffer_mut, caller_slot, drop_handle, handle_bytes};
use crate::model::DuoModel;
use crate::result::{guard, DuoResult, Failure};
use crate::session::{
    config_ref, leader_pos3d, model_ref, DuoSession, DuoSessionConfig, SessionInner,
};

/// `DUO_NO_SESSION`: the `failed_session` of a call that succeeded, or whose
/// failure concerns no single session.
pub const NO_SESSION: usize = usize::MAX;

/// What a `duo_step_batch *` points to.
pub struct StepBatchInner {
    /// Carved from the arena below (or the caller's memory); declared first, dropped first.
    batch: StepBatch<'static>,
    /// The step memory it holds (what a session's `dims` must fit in).
    dims: StepDims,
    /// Library-allocated arena (`duo_step_batch_new`); None in caller memory.
    _arena: Option<Box<[u8]>>,
    /// True when this struct lives in caller memory (`duo_step_batch_new_in`).
    in_caller_memory: bool,
}

/// Opaque `duo_step_batch`.
pub type DuoStepBatch = StepBatchInner;

/// Alignment slack and size of the handle placed at the start of caller memory.
const HANDLE_BYTES: usize = handle_bytes::<StepBatchInner>();

/// Arena bytes of a batch of `max_sessions` sessions of `config` on `model`.
///
/// # Safety
/// `model` NULL or live; `config` NULL or valid.
unsafe fn arena_bytes<'x>(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    max_sessions: usize,
) -> Result<(usize, SessionConfig, &'x ModelConfig), Failure> {
    let m = model_ref(model)?;
    let cfg = config_ref(m, config)?;
    if max_sessions == 0 || max_sessions > MAX_BATCH {
        return Err(Failure::invalid(format!("max_sessions is {max_sessions}; a batch steps 1 to {MAX_BATCH} sessions (DUO_MAX_BATCH)")));
    }
    let model_cfg = m.duolando("a step batch")?.config();
    let n = StepBatch::bytes(model_cfg, &cfg, max_sessions)?;
    Ok((n, cfg, model_cfg))
}

/// Bytes `duo_step_batch_new_in` needs for `max_sessions` sessions of
/// `config` (any address).
///
/// # Safety
/// Pointers NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn duo_step_batch_bytes(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    max_sessions: usize,
    out_bytes: *mut usize,
) -> DuoResult {
    guard("duo_step_batch_bytes", || {
        // SAFETY: the caller's contract.
        let (n, _, _) = unsafe { arena_bytes(model, config, max_sessions) }?;
        if out_bytes.is_null() {
            return Err(Failure::null("out_bytes"));
        }
        let total = n
            .checked_add(HANDLE_BYTES)
            .ok_or_else(|| Failure::invalid("batch size overflows size_t"))?;
        // SAFETY: checked non-NULL.
        unsafe { *out_bytes = total };
        Ok(DuoResult::Ok)
    })
}

/// A batch in library memory (allocated here, once) for up to
/// `max_sessions` sessions of `model` whose configurations need no more
/// than `config`.
///
/// # Safety
/// `model` NULL or live; `config` NULL or valid; `out_batch` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_step_batch_new(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    max_sessions: usize,
    out_batch: *mut *mut DuoStepBatch,
) -> DuoResult {
    guard("duo_step_batch_new", || {
        // SAFETY: the caller's contract.
        let (n, cfg, model_cfg) = unsafe { arena_bytes(model, config, max_sessions) }?;
        if out_batch.is_null() {
            return Err(Failure::null("out_batch"));
        }
        let mut arena = vec![0u8; n].into_boxed_slice();
        // SAFETY: the boxed bytes stay at one address until the
        // StepBatchInner drops them, after the batch.
        let bytes: &'static mut [u8] =
            unsafe { std::slice::from_raw_parts_mut(arena.as_mut_ptr(), arena.len()) };
        let batch = StepBatch::new(model_cfg, &cfg, max_sessions, bytes)?;
        let dims = StepDims::new(model_cfg, &cfg, max_sessions).map_err(Error::Arena)?;
        let inner = Box::new(StepBatchInner {
            batch,
            dims,
            _arena: Some(arena),
            in_caller_memory: false,
        });
        // SAFETY: checked non-NULL.
        unsafe { *out_batch = Box::into_raw(inner) };
        Ok(DuoResult::Ok)
    })
}

/// A batch placed entirely in caller memory (`memory`, `len` >=
/// `duo_step_batch_bytes`; any alignment). No allocation.
///
/// # Safety
/// As `duo_step_batch_new`; `memory` NULL or `len` writable bytes that
/// stay valid, unmoved and otherwise untouched until `duo_step_batch_free`.
#[no_mangle]
pub unsafe extern "C" fn duo_step_batch_new_in(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    max_sessions: usize,
    memory: *mut u8,
    len: usize,
    out_batch: *mut *mut DuoStepBatch,
) -> DuoResult {
    guard("duo_step_batch_new_in", || {
        // SAFETY: the caller's contract.
        let (n, cfg, model_cfg) = unsafe { arena_bytes(model, config, max_sessions) }?;
        if out_batch.is_null() {
            return Err(Failure::null("out_batch"));
        }
        // SAFETY: NULL or `len` writable bytes kept for the batch (contract).
        let memory = unsafe { buffer_mut(memory, len, "memory") }?;
        let (slot, arena) = caller_slot::<StepBatchInner>(
            memory,
            n.saturating_add(HANDLE_BYTES),
            "duo_step_batch_bytes",
        )?;
        let batch = StepBatch::new(model_cfg, &cfg, max_sessions, arena)?;
        let dims = StepDims::new(model_cfg, &cfg, max_sessions).map_err(Error::Arena)?;
        // SAFETY: `slot` is aligned, in bounds, and holds no value yet.
        unsafe {
            slot.write(StepBatchInner {
                batch,
                dims,
                _arena: None,
                in_caller_memory: true,
            });
            *out_batch = slot;
        }
        Ok(DuoResult::Ok)
    })
}

/// Frees a batch. NULL is ignored. The sessions it stepped are untouched.
/// For `duo_step_batch_new_in`, the caller's memory may be released
/// afterwards.
///
/// # Safety
/// `batch` NULL or a live handle, freed once, not used afterwards.
#[no_mangle]
pub unsafe extern "C" fn duo_step_batch_free(batch: *mut DuoStepBatch) {
    let _ = guard("duo_step_batch_free", || {
        // SAFETY: NULL or a live handle, freed once (contract).
        unsafe { drop_handle(batch, |b| b.in_caller_memory) };
        Ok(DuoResult::Ok)
    });
}

/// Pushes `frames[i]` into `sessions[i]` for every `i < n` and runs the
/// steps that become possible, the sessions' weight-heavy work together.
/// Each session ends as after its own `duo_session_push_leader`.
///
/// Refusals, in this order, the first one found answering (no session
/// changes; `*failed_session` = the session concerned, else
/// `DUO_NO_SESSION`):
/// 1. the call: `batch` NULL (`DUO_NULL_PARAMETER`); `n == 0` does nothing
///    (`DUO_OK`, whatever `sessions` and `frames` are); `n` above the
///    batch's `max_sessions` (`DUO_INVALID_ARGUMENT`); `sessions` or
///    `frames` NULL (`DUO_NULL_PARAMETER`) — all with `DUO_NO_SESSION`;
/// 2. the sessions, by index: the first that is NULL (`DUO_NULL_PARAMETER`),
///    given twice, of another model than `sessions[0]`, or needing more
///    step memory than the batch holds (`DUO_INVALID_ARGUMENT`);
/// 3. the frames, by index: the first with a non-finite or out-of-range
///    value (`DUO_NON_FINITE_INPUT`);
/// 4. the sessions, by index: the first that would refuse its frame for
///    backlog (`DUO_BACKLOG`).
///
/// `failed_session` (NULL or writable) is written on every return: the index
/// of the session a failure concerns, else `DUO_NO_SESSION`.
///
/// # Safety
/// `batch` NULL or live; `sessions` NULL or `n` readable pointers, each
/// NULL or a live session not used by another thread during the call;
/// `frames` NULL or `n` readable frames; `failed_session` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_step_batch_push_leader(
    batch: *mut DuoStepBatch,
    sessions: *const *mut DuoSession,
    frames: *const DuoLeaderFrame,
    n: usize,
    failed_session: *mut usize,
) -> DuoResult {
    let mut failed = NO_SESSION;
    // SAFETY: the caller's contract (see push_leader_many).
    let r = guard("duo_step_batch_push_leader", || unsafe {
        push_leader_many(batch, sessions, frames, n, &mut failed)
    });
    if !failed_session.is_null() {
        // SAFETY: non-NULL and writable (contract).
        unsafe { *failed_session = failed };
    }
    r
}

/// The body of [`duo_step_batch_push_leader`]; `failed` = the session a
/// failure concerns.
///
/// # Safety
/// As [`duo_step_batch_push_leader`].
unsafe fn push_leader_many(
    batch: *mut DuoStepBatch,
    sessions: *const *mut DuoSession,
    frames: *const DuoLeaderFrame,
    n: usize,
    failed: &mut usize,
) -> Result<DuoResult, Failure> {
    // SAFETY: NULL or a live handle used by one thread at a time (contract).
    let b = unsafe { batch.as_mut() }.ok_or_else(|| Failure::null("batch"))?;
    if n == 0 {
        return Ok(DuoResult::Ok);
    }
    if n > b.batch.capacity() {
        return Err(Failure::invalid(format!(
            "{n} sessions given to a batch made for at most {}",
            b.batch.capacity()
        )));
    }
    if sessions.is_null() {
        return Err(Failure::null("sessions"));
    }
    if frames.is_null() {
        return Err(Failure::null("frames"));
    }
    // SAFETY: `n` readable pointers and `n` readable frames (contract).
    let (ptrs, frames) = unsafe {
        (
            std::slice::from_raw_parts(sessions, n),
            std::slice::from_raw_parts(frames, n),
        )
    };
    // 2. The sessions themselves.
    let mut first: Option<&SessionInner> = None;
    for (i, &p) in ptrs.iter().enumerate() {
        *failed = i;
        // SAFETY: NULL or a live session (contract); read only here.
        let s = unsafe { p.as_ref() }.ok_or_else(|| Failure::null(&format!("sessions[{i}]")))?;
        if let Some(j) = ptrs[..i].iter().position(|&q| std::ptr::eq(q, p)) {
            return Err(Failure::invalid(format!(
                "sessions[{i}] is sessions[{j}] again; a session takes one frame per call"
            )));
        }
        let s0 = *first.get_or_insert(s);
        if !std::sync::Arc::ptr_eq(&s.model, &s0.model) {
            return Err(Failure::invalid(format!(
                "sessions[{i}] is a session of another model than sessions[0]"
            )));
        }
        let dims = match &s.session {
            crate::session::AnySession::Duolando { dims, .. } => dims,
            crate::session::AnySession::Bailando(_) => {
                return Err(crate::session::solo_refusal(&format!("sessions[{i}] in duo_step_batch_push_leader (solo sessions are stepped by their own pulls)")))
            }
            crate::session::AnySession::Transflower(_) => {
                return Err(crate::model::transflower_refusal(&format!("sessions[{i}] in duo_step_batch_push_leader")))
            }
        };
        if !b.dims.holds(dims) {
            return Err(Failure::invalid(format!(
                "sessions[{i}] needs more step memory than this batch holds: its configuration needs more than the batch's (duo_step_batch_new)"
            )));
        }
    }
    // 3. The frames' values. Nothing allocates: the frames are read in
    // place, the lists live on the stack (n <= capacity <= MAX_BATCH).
    let mut rows: heapless::Vec<&[f32], MAX_BATCH> = heapless::Vec::new();
    for (i, f) in frames.iter().enumerate() {
        *failed = i;
        rows.push(leader_pos3d(f)?)
            .map_err(|_| Failure::invalid("more frames than DUO_MAX_BATCH"))?;
    }
    *failed = NO_SESSION;
    let mut refs: heapless::Vec<&mut Session<'static>, MAX_BATCH> = heapless::Vec::new();
    for &p in ptrs {
        // SAFETY: every pointer is a live session (contract), and they are
        // pairwise distinct (checked above): one `&mut` each.
        let session = match unsafe { &mut (*p).session } {
            crate::session::AnySession::Duolando { session, .. } => session,
            crate::session::AnySession::Bailando(_) => {
                return Err(crate::session::solo_refusal("duo_step_batch_push_leader"))
            }
            crate::session::AnySession::Transflower(_) => {
                return Err(crate::model::transflower_refusal(
                    "duo_step_batch_push_leader",
                ))
            }
        };
        refs.push(session)
            .map_err(|_| Failure::invalid("more sessions than DUO_MAX_BATCH"))?;
    }
    // 4. Backlog: `step_many` checks every session (model, step memory,
    // frame, backlog: the first three passed above) before it changes any.
    Session::step_many(&mut refs, &rows, &mut b.batch).map_err(|(i, e)| {
        *failed = i;
        match e {
            // Caught above; kept should core's checks ever be wider.
            Error::State => Failure::invalid(format!(
                "sessions[{i}] cannot be stepped with sessions[0] in this batch: another model, or a configuration that needs more than the batch was made for"
            )),
            e => Failure::from(e),
        }
    })?;
    Ok(DuoResult::Ok)
}
