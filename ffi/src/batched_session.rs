//! Duolando sessions bound to a `duo_step_batch`
//! (`duolando_core::duolando::session::Session::new_batched`): a session
//! that holds its state alone (about 16.0 MB at full size with f16 K/V,
//! 1.5 MB less than `duo_session_bytes`) and borrows its batch's step
//! memory for every call that runs the model: its creation (the seed's
//! frames), `duo_session_push_leader`, `_push_music`, `_set_music_track`,
//! `_finish`, `_pull_follower` / `_pull_positions` (a finished session
//! steps in its pulls) and `_reset`; `duo_step_batch_push_leader` steps it
//! with the batch it is given, as any session. Its frames are those of a
//! session of `duo_session_new`, bit for bit.
//!
//! The batch's step memory is behind a lock: sessions bound to one batch
//! may live on different threads, whose calls then run one at a time. A
//! bound session holds a reference on its batch (`duo_step_batch_free`
//! drops the caller's; the batch goes with the last session), as every
//! session holds one on its model.

use duolando_core::duolando::session::StepDims;

use crate::batch::{BoundBatch, DuoStepBatch};
use crate::model::DuoModel;
use crate::result::{guard, DuoResult, Failure};
use crate::session::{
    config_ref, model_ref, place_session, seed_ref, start, AnyConfig, AnySeed, DuoSession,
    DuoSessionConfig, HANDLE_BYTES,
};

/// What every constructor checks and builds, in the header's order: the
/// model (a Duolando one), the configuration, the seed tokens, the batch
/// (a Duolando batch holding the session's step memory), `out_session`;
/// then the arena (`memory` None: allocated here; else the caller's, the
/// handle first) and the session, bound to the batch.
///
/// # Safety
/// As `duo_session_new_batched_in` (`memory` None: `_new_batched`).
unsafe fn make(
    what: &str,
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    seed_tokens: *const u32,
    batch: *mut DuoStepBatch,
    memory: Option<(*mut u8, usize)>,
    out_session: *mut *mut DuoSession,
) -> Result<DuoResult, Failure> {
    let m = model_ref(model)?;
    let dm = m.duolando(what)?;
    let cfg = config_ref(m, config)?;
    let seed = seed_ref(seed_tokens)?;
    // SAFETY: NULL or a live batch (contract).
    let (bound, held) = unsafe { BoundBatch::new(batch, what) }?;
    let need = StepDims::new(dm.config(), &cfg, 1).map_err(duolando_core::Error::Arena)?;
    if !held.holds(&need) {
        return Err(Failure::invalid(format!(
            "{what}: this configuration needs more step memory than the batch holds (make the batch with this configuration or a larger one: duo_step_batch_new)"
        )));
    }
    if out_session.is_null() {
        return Err(Failure::null("out_session"));
    }
    let n = dm.batched_session_bytes(&cfg)?;
    let (cfg, seed) = (AnyConfig::Duolando(cfg), AnySeed::Duolando(seed));
    let bytes_fn = "duo_session_batched_bytes";
    // SAFETY: the caller's contract; `out_session` checked non-NULL.
    unsafe {
        place_session(n, memory, bytes_fn, model, out_session, |arc, arena| {
            start(arc, arena, &cfg, seed, Some(bound))
        })
    }
}

/// Bytes `duo_session_new_batched_in` needs for `config` (any address):
/// the session's state alone.
///
/// # Safety
/// Pointers NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn duo_session_batched_bytes(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    out_bytes: *mut usize,
) -> DuoResult {
    guard("duo_session_batched_bytes", || {
        let m = model_ref(model)?;
        let dm = m.duolando("duo_session_batched_bytes")?;
        let cfg = config_ref(m, config)?;
        if out_bytes.is_null() {
            return Err(Failure::null("out_bytes"));
        }
        let total = dm
            .batched_session_bytes(&cfg)?
            .checked_add(HANDLE_BYTES)
            .ok_or_else(|| Failure::invalid("session size overflows size_t"))?;
        // SAFETY: checked non-NULL.
        unsafe { *out_bytes = total };
        Ok(DuoResult::Ok)
    })
}

/// A session bound to `batch`, in library memory (allocated here, once).
///
/// # Safety
/// As `duo_session_new`; `batch` NULL or live.
#[no_mangle]
pub unsafe extern "C" fn duo_session_new_batched(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    seed_tokens: *const u32,
    batch: *mut DuoStepBatch,
    out_session: *mut *mut DuoSession,
) -> DuoResult {
    let what = "duo_session_new_batched";
    guard(what, || {
        // SAFETY: the caller's contract.
        unsafe { make(what, model, config, seed_tokens, batch, None, out_session) }
    })
}

/// A session bound to `batch`, entirely in caller memory (`memory`, `len`
/// >= `duo_session_batched_bytes`; any alignment). No allocation.
///
/// # Safety
/// As `duo_session_new_batched`; `memory` NULL or `len` writable bytes
/// that stay valid, unmoved and otherwise untouched until
/// `duo_session_free`.
#[no_mangle]
pub unsafe extern "C" fn duo_session_new_batched_in(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    seed_tokens: *const u32,
    batch: *mut DuoStepBatch,
    memory: *mut u8,
    len: usize,
    out_session: *mut *mut DuoSession,
) -> DuoResult {
    let what = "duo_session_new_batched_in";
    guard(what, || {
        // SAFETY: the caller's contract.
        unsafe {
            make(
                what,
                model,
                config,
                seed_tokens,
                batch,
                Some((memory, len)),
                out_session,
            )
        }
    })
}
