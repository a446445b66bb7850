//! `duo_step_batch`: step memory several sessions of one model share. One
//! handle for the two families that have one:
//!
//! - Duolando (`duo_step_batch_new`, here): several dancers stepped
//!   together (`duolando_core::duolando::session::Session::step_many`):
//!   one leader frame per session per call, and each weight matrix of the
//!   LATs, the GPT and the heads read once for all of them. Every session
//!   ends exactly as after its own `duo_session_push_leader` (bit for
//!   bit); only the time differs (docs/PERFORMANCE.md: 16 sessions in
//!   4.4-4.6x the time of one at full size). Scratch memory only (no
//!   session state, no model reference), sized for a session configuration
//!   and a number of sessions; it steps any sessions of one model whose
//!   configurations need no more than that one.
//! - Transflower (`duo_transflower_step_batch_new`, `duo_step_batch_step`:
//!   [`crate::transflower_batch`]): the step scratch and the flow's reverse
//!   weights of one model, its sessions stepped one after another through it.
//!
//! Sessions keep their own handles and every other call (input, pulls,
//! reset) as before. A Duolando session may also be bound to a batch
//! (`duo_session_new_batched`, [`crate::batched_session`]): it holds no
//! step memory and borrows the batch's for each of its calls. This file:
//! the handle, its placement (library or caller memory), its references
//! (the handle's and one per bound session; the last frees it), the checks
//! every batch call makes in the header's one order, and the Duolando calls.
//!
//! Thread rule: a batch is used by one thread at a time, and the sessions
//! of a call are not used by any other thread during it. Its step memory is
//! behind a lock, so sessions bound to it may live on other threads (their
//! calls then wait for each other and for the batch's).

use std::ptr::NonNull;
use std::sync::atomic::{fence, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use duolando_core::duolando::session::{Session, SessionConfig, StepBatch, StepDims, MAX_BATCH};
use duolando_core::family::Family;
use duolando_core::transflower::session::StepBatch as TfStepBatch;
use duolando_core::Error;

use crate::frames::DuoLeaderFrame;
use crate::handle::{buffer_mut, caller_slot, drop_handle, handle_bytes};
use crate::model::{DuoModel, ModelInner};
use crate::result::{guard, DuoResult, Failure};
use crate::session::{
    config_ref, leader_pos3d, model_ref, AnySession, DuoSession, DuoSessionConfig, SessionInner,
};

/// `DUO_NO_SESSION`: the `failed_session` of a call that succeeded, or whose
/// failure concerns no single session.
pub const NO_SESSION: usize = usize::MAX;

/// The step memory of one family.
pub(crate) enum Kind {
    Duolando {
        /// Locked by each call that steps in it (a batch call, or a call
        /// of a session bound to the batch).
        batch: Mutex<StepBatch<'static>>,
        /// The step memory it holds (what a session's `dims` must fit in).
        dims: StepDims,
    },
    Transflower {
        batch: Mutex<TfStepBatch<'static>>,
        /// The model the batch's reverse weights come from: kept alive (its
        /// address is what a session's model is compared with).
        model: Arc<ModelInner>,
    },
}

impl Kind {
    fn family(&self) -> Family {
        match self {
            Kind::Duolando { .. } => Family::Duolando,
            Kind::Transflower { .. } => Family::Transflower,
        }
    }

    /// Most sessions one call steps.
    fn capacity(&self) -> usize {
        match self {
            Kind::Duolando { dims, .. } => dims.n,
            Kind::Transflower { .. } => MAX_BATCH,
        }
    }
}

/// The step memory behind `m`, for this call (a panic that poisoned the
/// lock left no state in it: a batch holds scratch only).
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// What a `duo_step_batch *` points to.
pub struct StepBatchInner {
    /// Carved from the arena below (or the caller's memory); declared first, dropped first.
    pub(crate) kind: Kind,
    /// Library-allocated arena (`_new`); None in caller memory.
    _arena: Option<Box<[u8]>>,
    /// True when this struct lives in caller memory (`_new_in`).
    in_caller_memory: bool,
    /// References: the handle's (until `duo_step_batch_free`) and one per
    /// session bound to the batch; the last one released frees it.
    refs: AtomicUsize,
}

/// Opaque `duo_step_batch`.
pub type DuoStepBatch = StepBatchInner;

/// Drops one reference to the batch at `p`; the last one frees it (in
/// place in caller memory, else the box).
///
/// # Safety
/// `p` NULL or a live batch, each reference released once.
unsafe fn release(p: *mut StepBatchInner) {
    // SAFETY: NULL or live (contract).
    let Some(b) = (unsafe { p.as_ref() }) else {
        return;
    };
    if b.refs.fetch_sub(1, Ordering::Release) != 1 {
        return;
    }
    // Every other reference's use happens before the free.
    fence(Ordering::Acquire);
    // SAFETY: the last reference: nothing else uses the batch.
    unsafe { drop_handle(p, |b| b.in_caller_memory) };
}

/// A session's reference to the Duolando batch whose step memory it
/// borrows (`duo_session_new_batched`): keeps the batch alive until the
/// session is freed.
pub(crate) struct BoundBatch(NonNull<StepBatchInner>);

// SAFETY: the batch is only read through this reference, its step memory
// behind a lock, and its count of references is atomic.
unsafe impl Send for BoundBatch {}
// SAFETY: as above.
unsafe impl Sync for BoundBatch {}

impl BoundBatch {
    /// A new reference to the batch at `p`, with the step memory it holds,
    /// or a refusal where it is NULL or not a Duolando batch.
    ///
    /// # Safety
    /// `p` NULL or a live batch.
    pub(crate) unsafe fn new(
        p: *mut StepBatchInner,
        what: &str,
    ) -> Result<(Self, StepDims), Failure> {
        let ptr = NonNull::new(p).ok_or_else(|| Failure::null("batch"))?;
        // SAFETY: live (contract).
        let b = unsafe { ptr.as_ref() };
        let Kind::Duolando { dims, .. } = &b.kind else {
            return Err(Failure::invalid(format!(
                "{what}: this batch is a {} model's; a session borrows the step memory of a Duolando batch (duo_step_batch_new)",
                b.kind.family().name()
            )));
        };
        b.refs.fetch_add(1, Ordering::Relaxed);
        Ok((BoundBatch(ptr), *dims))
    }

    /// The batch's step memory, locked for the caller's call.
    pub(crate) fn lock(&self) -> MutexGuard<'_, StepBatch<'static>> {
        // SAFETY: the batch lives while this reference does.
        match &unsafe { self.0.as_ref() }.kind {
            Kind::Duolando { batch, .. } => lock(batch),
            Kind::Transflower { .. } => unreachable!("BoundBatch::new takes Duolando batches only"),
        }
    }
}

impl Drop for BoundBatch {
    fn drop(&mut self) {
        // SAFETY: this reference, counted by `new`, released once.
        unsafe { release(self.0.as_ptr()) };
    }
}

/// Alignment slack and size of the handle placed at the start of caller memory.
pub(crate) const HANDLE_BYTES: usize = handle_bytes::<StepBatchInner>();

/// `n` arena bytes plus the handle's (what `_bytes` reports).
pub(crate) fn with_handle(n: usize) -> Result<usize, Failure> {
    n.checked_add(HANDLE_BYTES)
        .ok_or_else(|| Failure::invalid("batch size overflows size_t"))
}

/// Every constructor's end: `out_batch` checked, an `n`-byte arena
/// allocated here (`memory` None) or taken from caller memory (`memory` =
/// pointer and length, handle first; `bytes_fn` names the size function),
/// `make` carving the batch from it, the handle written to `*out_batch`.
///
/// # Safety
/// `out_batch` NULL or writable; `memory` None, or NULL or `len` writable
/// bytes that stay valid, unmoved and otherwise untouched until
/// `duo_step_batch_free`.
pub(crate) unsafe fn place(
    n: usize,
    memory: Option<(*mut u8, usize)>,
    bytes_fn: &str,
    out_batch: *mut *mut DuoStepBatch,
    make: impl FnOnce(&'static mut [u8]) -> Result<Kind, Failure>,
) -> Result<DuoResult, Failure> {
    if out_batch.is_null() {
        return Err(Failure::null("out_batch"));
    }
    let handle = match memory {
        None => {
            let mut arena = vec![0u8; n].into_boxed_slice();
            // SAFETY: the boxed bytes stay at one address until the
            // StepBatchInner drops them, after the batch.
            let bytes: &'static mut [u8] =
                unsafe { std::slice::from_raw_parts_mut(arena.as_mut_ptr(), arena.len()) };
            let kind = make(bytes)?;
            Box::into_raw(Box::new(StepBatchInner {
                kind,
                _arena: Some(arena),
                in_caller_memory: false,
                refs: AtomicUsize::new(1),
            }))
        }
        Some((ptr, len)) => {
            // SAFETY: NULL or `len` writable bytes kept for the batch (contract).
            let memory = unsafe { buffer_mut(ptr, len, "memory") }?;
            let (slot, arena) =
                caller_slot::<StepBatchInner>(memory, n.saturating_add(HANDLE_BYTES), bytes_fn)?;
            let kind = make(arena)?;
            // SAFETY: `slot` is aligned, in bounds, and holds no value yet.
            unsafe {
                slot.write(StepBatchInner {
                    kind,
                    _arena: None,
                    in_caller_memory: true,
                    refs: AtomicUsize::new(1),
                })
            };
            slot
        }
    };
    // SAFETY: checked non-NULL.
    unsafe { *out_batch = handle };
    Ok(DuoResult::Ok)
}

/// Arena bytes of a Duolando batch of `max_sessions` sessions of `config`.
///
/// # Safety
/// `model` NULL or live; `config` NULL or valid.
unsafe fn arena_bytes<'x>(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    max_sessions: usize,
) -> Result<(usize, SessionConfig, &'x ModelInner), Failure> {
    let m = model_ref(model)?;
    let cfg = config_ref(m, config)?;
    if max_sessions == 0 || max_sessions > MAX_BATCH {
        return Err(Failure::invalid(format!("max_sessions is {max_sessions}; a batch steps 1 to {MAX_BATCH} sessions (DUO_MAX_BATCH)")));
    }
    let n = StepBatch::bytes(m.duolando("a step batch")?.config(), &cfg, max_sessions)?;
    Ok((n, cfg, m))
}

/// Both Duolando constructors (`memory` as [`place`]).
///
/// # Safety
/// As `duo_step_batch_new_in` (`memory` None: as `duo_step_batch_new`).
unsafe fn make_duolando(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    max_sessions: usize,
    memory: Option<(*mut u8, usize)>,
    out_batch: *mut *mut DuoStepBatch,
) -> Result<DuoResult, Failure> {
    // SAFETY: the caller's contract.
    let (n, cfg, m) = unsafe { arena_bytes(model, config, max_sessions) }?;
    let model_cfg = m.duolando("a step batch")?.config();
    // SAFETY: the caller's contract.
    unsafe {
        place(n, memory, "duo_step_batch_bytes", out_batch, |arena| {
            Ok(Kind::Duolando {
                batch: Mutex::new(StepBatch::new(model_cfg, &cfg, max_sessions, arena)?),
                dims: StepDims::new(model_cfg, &cfg, max_sessions).map_err(Error::Arena)?,
            })
        })
    }
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
        let total = with_handle(n)?;
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
        unsafe { make_duolando(model, config, max_sessions, None, out_batch) }
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
        unsafe { make_duolando(model, config, max_sessions, Some((memory, len)), out_batch) }
    })
}

/// Frees a batch of either family. NULL is ignored. The sessions it
/// stepped are untouched. Sessions bound to it keep it alive: it goes
/// with the last of them. For a batch in caller memory, the memory may be
/// released once it and its bound sessions are freed.
///
/// # Safety
/// `batch` NULL or a live handle, freed once, not used afterwards.
#[no_mangle]
pub unsafe extern "C" fn duo_step_batch_free(batch: *mut DuoStepBatch) {
    let _ = guard("duo_step_batch_free", || {
        // SAFETY: NULL or a live handle, its own reference released once (contract).
        unsafe { release(batch) };
        Ok(DuoResult::Ok)
    });
}

/// Runs a batch call's body with `failed` (`DUO_NO_SESSION` unless the
/// body names a session) and writes it to `failed_session` (NULL or
/// writable) on every return.
pub(crate) fn with_failed(
    what: &str,
    failed_session: *mut usize,
    body: impl FnOnce(&mut usize) -> Result<DuoResult, Failure>,
) -> DuoResult {
    let mut failed = NO_SESSION;
    let r = guard(what, || body(&mut failed));
    if !failed_session.is_null() {
        // SAFETY: non-NULL and writable (the callers' contract).
        unsafe { *failed_session = failed };
    }
    r
}

/// Step 1 of the header's order, the part every batch call shares: `batch`
/// NULL, or of another family than `family` (the call's); `n == 0` (None:
/// nothing to do); `n` above what the batch steps; `sessions` NULL.
///
/// # Safety
/// `batch` NULL or live, used by this thread alone; `sessions` NULL or `n`
/// readable pointers.
pub(crate) unsafe fn the_call<'x>(
    batch: *mut DuoStepBatch,
    family: Family,
    what: &str,
    sessions: *const *mut DuoSession,
    n: usize,
) -> Result<Option<(&'x Kind, &'x [*mut DuoSession])>, Failure> {
    // SAFETY: NULL or a live handle (contract); shared with the sessions
    // bound to it, its step memory behind a lock.
    let b = &unsafe { batch.as_ref() }
        .ok_or_else(|| Failure::null("batch"))?
        .kind;
    if b.family() != family {
        let made_by = match b.family() {
            Family::Transflower => "duo_transflower_step_batch_new; step its sessions with duo_step_batch_step",
            _ => "duo_step_batch_new; push its sessions' leader frames with duo_step_batch_push_leader",
        };
        return Err(Failure::invalid(format!(
            "{what} steps {} sessions; this batch is a {} model's (made by {made_by})",
            family.name(),
            b.family().name()
        )));
    }
    if n == 0 {
        return Ok(None);
    }
    if n > b.capacity() {
        return Err(Failure::invalid(format!(
            "{n} sessions given to a batch made for at most {}",
            b.capacity()
        )));
    }
    if sessions.is_null() {
        return Err(Failure::null("sessions"));
    }
    // SAFETY: `n` readable pointers (contract).
    Ok(Some((b, unsafe {
        std::slice::from_raw_parts(sessions, n)
    })))
}

/// Step 2 of the header's order: each session by index, NULL, given
/// twice, then `fits` (its family, model, step memory); `failed` follows
/// the index.
///
/// # Safety
/// Every pointer NULL or a live session not used by another thread.
pub(crate) unsafe fn check_sessions(
    ptrs: &[*mut DuoSession],
    failed: &mut usize,
    mut fits: impl FnMut(usize, &SessionInner) -> Result<(), Failure>,
) -> Result<(), Failure> {
    for (i, &p) in ptrs.iter().enumerate() {
        *failed = i;
        // SAFETY: NULL or a live session (contract); read only here.
        let s = unsafe { p.as_ref() }.ok_or_else(|| Failure::null(&format!("sessions[{i}]")))?;
        if let Some(j) = ptrs[..i].iter().position(|&q| std::ptr::eq(q, p)) {
            return Err(Failure::invalid(format!(
                "sessions[{i}] is sessions[{j}] again; a session takes one step per call"
            )));
        }
        fits(i, s)?;
    }
    *failed = NO_SESSION;
    Ok(())
}

/// Sessions[i] of another family than the batch's.
pub(crate) fn family_refusal(i: usize, s: &SessionInner, batch: Family) -> Failure {
    Failure::invalid(format!(
        "sessions[{i}] is a session of a {} model; this batch steps {} sessions",
        s.model.family().name(),
        batch.name()
    ))
}

/// The sessions, checked by [`check_sessions`], as `&mut` to the family's
/// core session (`get`; None: another family, not expected after the
/// checks). Nothing allocates: the list lives on the stack.
///
/// # Safety
/// Every pointer a live session, pairwise distinct, not used by another
/// thread during the call.
pub(crate) unsafe fn sessions_mut<'x, T: 'x>(
    ptrs: &[*mut DuoSession],
    get: impl Fn(&'x mut AnySession) -> Option<&'x mut T>,
) -> Result<heapless::Vec<&'x mut T, MAX_BATCH>, Failure> {
    let mut refs = heapless::Vec::new();
    for &p in ptrs {
        // SAFETY: a live session (contract), distinct from the others: one
        // `&mut` each.
        let s = get(unsafe { &mut (*p).session })
            .ok_or_else(|| Failure::invalid("a session changed family"))?;
        refs.push(s)
            .map_err(|_| Failure::invalid("more sessions than DUO_MAX_BATCH"))?;
    }
    Ok(refs)
}

/// Pushes `frames[i]` into `sessions[i]` for every `i < n` and runs the
/// steps that become possible, the sessions' weight-heavy work together.
/// Each session ends as after its own `duo_session_push_leader`.
///
/// Refusals in the header's order, the first one found answering (no
/// session changes; `*failed_session` = the session concerned, else
/// `DUO_NO_SESSION`): 1. the call ([`the_call`]; then `frames` NULL);
/// 2. the sessions ([`check_sessions`]: another family, another model
/// than `sessions[0]`, more step memory than the batch holds); 3. the
/// frames, by index (`DUO_NON_FINITE_INPUT`); 4. the sessions, by index,
/// that would refuse their frame for backlog (`DUO_BACKLOG`).
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
    // SAFETY: the caller's contract (see push_leader_many).
    with_failed(
        "duo_step_batch_push_leader",
        failed_session,
        |failed| unsafe { push_leader_many(batch, sessions, frames, n, failed) },
    )
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
    let what = "duo_step_batch_push_leader";
    // SAFETY: the caller's contract.
    let Some((kind, ptrs)) = (unsafe { the_call(batch, Family::Duolando, what, sessions, n) })?
    else {
        return Ok(DuoResult::Ok);
    };
    let Kind::Duolando { batch, dims } = kind else {
        return Err(Failure::invalid("not a Duolando batch"));
    };
    if frames.is_null() {
        return Err(Failure::null("frames"));
    }
    // SAFETY: `n` readable frames (contract).
    let frames = unsafe { std::slice::from_raw_parts(frames, n) };
    // 2. The sessions themselves.
    let mut first: Option<*const ModelInner> = None;
    // SAFETY: the caller's contract.
    unsafe {
        check_sessions(ptrs, failed, |i, s| {
            let AnySession::Duolando { dims: need, .. } = &s.session else {
                return Err(family_refusal(i, s, Family::Duolando));
            };
            if *first.get_or_insert(Arc::as_ptr(&s.model)) != Arc::as_ptr(&s.model) {
                return Err(Failure::invalid(format!(
                    "sessions[{i}] is a session of another model than sessions[0]"
                )));
            }
            if !dims.holds(need) {
                return Err(Failure::invalid(format!(
                    "sessions[{i}] needs more step memory than this batch holds: its configuration needs more than the batch's (duo_step_batch_new)"
                )));
            }
            Ok(())
        })
    }?;
    // 3. The frames' values, read in place (n <= capacity <= MAX_BATCH).
    let mut rows: heapless::Vec<&[f32], MAX_BATCH> = heapless::Vec::new();
    for (i, f) in frames.iter().enumerate() {
        *failed = i;
        rows.push(leader_pos3d(f)?)
            .map_err(|_| Failure::invalid("more frames than DUO_MAX_BATCH"))?;
    }
    *failed = NO_SESSION;
    // SAFETY: checked live and pairwise distinct above (contract).
    let mut refs = unsafe {
        sessions_mut(ptrs, |s| match s {
            AnySession::Duolando { session, .. } => Some(session),
            _ => None,
        })
    }?;
    // 4. Backlog: `step_many` checks every session (model, step memory,
    // frame, backlog: the first three passed above) before it changes any.
    Session::step_many(&mut refs, &rows, &mut lock(batch)).map_err(|(i, e)| {
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
