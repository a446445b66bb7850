//! `duo_session`: one follower dancer over a shared `duo_model`
//! (`duolando_core::duolando::session::Session`), in library memory
//! (`duo_session_new`) or in caller memory (`duo_session_bytes` +
//! `duo_session_new_in`: no allocation at all).
//!
//! Input policy at the C boundary (issue #6 item 3): a leader or music
//! frame holding NaN or infinity, or a magnitude above
//! [`MAX_POSITION_M`] / [`MAX_MUSIC_FEATURE`], is rejected with
//! `DUO_NON_FINITE_INPUT` and the session is left unchanged; the caller
//! keeps the 30 fps clock by pushing its last good frame instead (the Unity
//! and Unreal wrappers do). A refused push for lack of room answers
//! `DUO_BACKLOG`, also without changing the session.
//!
//! Thread rule: a session is used by one thread at a time (it may move
//! between threads); distinct sessions, even on one model, run in parallel.

use std::sync::Arc;

use duolando_core::bailando::exact::MusicPadding;
use duolando_core::bailando::session::{
    Preset as SoloPreset, Session as SoloSession, SessionConfig as SoloConfig,
};
use duolando_core::duolando::config::{N_JOINTS, POSE_DIM};
use duolando_core::duolando::session::{
    CacheSchedule, FollowerFrame, KvType, Preset, Sampling, Session, SessionConfig, StepDims,
};

use crate::batch::BoundBatch;
use crate::frames::{quat_of_raw, DuoFollowerFrame, DuoLeaderFrame, DuoVec3};
use crate::handle::{buffer, buffer_mut, caller_slot, drop_handle, handle_bytes};
use crate::model::{share, transflower_refusal, AnyModel, DuoModel, ModelInner};
use crate::result::{guard, DuoResult, Failure};
use duolando_core::transflower::session::Session as TfSession;

/// Largest accepted |coordinate| of a leader joint, metres
/// (`DUO_MAX_POSITION_M`).
pub const MAX_POSITION_M: f32 = duolando_core::input::MAX_POSITION_M;
/// Largest accepted |value| of a music feature (`DUO_MAX_MUSIC_FEATURE`).
pub const MAX_MUSIC_FEATURE: f32 = duolando_core::input::MAX_MUSIC_FEATURE;

/// `DUO_SAMPLING_GREEDY` / `DUO_SAMPLING_TOP_K` / `DUO_SAMPLING_SOFTMAX`.
pub const SAMPLING_GREEDY: u32 = 0;
pub const SAMPLING_TOP_K: u32 = 1;
pub const SAMPLING_SOFTMAX: u32 = 2;
/// `DUO_KV_F32` / `DUO_KV_F16`.
pub const KV_F32: u32 = 0;
pub const KV_F16: u32 = 1;

/// `duo_session_config`: mirrors `duolando_core::duolando::session::SessionConfig`
/// (counts in tokens of 4 frames unless named frames). 64 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DuoSessionConfig {
    pub lookahead: u32,
    pub enc_future: u32,
    pub dec_future: u32,
    pub shift: u32,
    pub music_lookahead: u32,
    pub lat_past: u32,
    pub pending_frames: u32,
    pub music_buffer_frames: u32,
    pub sampling: u32,
    pub top_k: u32,
    /// 0: one GPT cache re-prefilled at window jumps; 1: one cache per live
    /// window (flat cost per step, more memory); 2: two caches, the next
    /// window filled ahead a few rows per step (`SessionConfig::spread`).
    pub staggered: u32,
    /// K/V cache element type: `KV_F32` or `KV_F16`.
    pub kv: u32,
    pub rng_seed: u64,
    /// `DUO_SAMPLING_SOFTMAX`'s temperature in thousandths, 1..=100 000
    /// (ignored by the other rules).
    pub temperature_milli: u32,
    /// 0 (refused otherwise: room for a later field).
    pub reserved: u32,
}

const _: () = assert!(std::mem::size_of::<DuoSessionConfig>() == 64);

/// The C fields of a sampling rule: `(sampling, top_k, temperature_milli, rng_seed)`.
fn sampling_fields(s: Sampling) -> (u32, u32, u32, u64) {
    match s {
        Sampling::Greedy => (SAMPLING_GREEDY, 0, 0, 0),
        Sampling::TopK { k, rng_seed } => (SAMPLING_TOP_K, k, 0, rng_seed),
        Sampling::Softmax {
            k,
            temperature_milli,
            rng_seed,
        } => (SAMPLING_SOFTMAX, k, temperature_milli, rng_seed),
    }
}

impl DuoSessionConfig {
    fn from_core(c: &SessionConfig) -> Self {
        let (sampling, top_k, temperature_milli, rng_seed) = sampling_fields(c.sampling);
        DuoSessionConfig {
            lookahead: c.lookahead,
            enc_future: c.enc_future,
            dec_future: c.dec_future,
            shift: c.shift,
            music_lookahead: c.music_lookahead,
            lat_past: c.lat_past,
            pending_frames: c.pending_frames,
            music_buffer_frames: c.music_buffer_frames,
            sampling,
            top_k,
            staggered: match c.schedule {
                CacheSchedule::Reprefill => 0,
                CacheSchedule::Staggered => 1,
                CacheSchedule::Spread => 2,
            },
            kv: match c.kv {
                KvType::F32 => KV_F32,
                KvType::F16 => KV_F16,
            },
            rng_seed,
            temperature_milli,
            reserved: 0,
        }
    }

    fn to_core(self) -> Result<SessionConfig, Failure> {
        let (sampling, kv) = self.to_core_fields()?;
        let schedule = match self.staggered {
            0 => CacheSchedule::Reprefill,
            1 => CacheSchedule::Staggered,
            2 => CacheSchedule::Spread,
            v => {
                return Err(Failure::invalid(format!(
                    "config.staggered is {v}, not 0, 1 or 2"
                )))
            }
        };
        Ok(SessionConfig {
            lookahead: self.lookahead,
            enc_future: self.enc_future,
            dec_future: self.dec_future,
            shift: self.shift,
            music_lookahead: self.music_lookahead,
            lat_past: self.lat_past,
            sampling,
            pending_frames: self.pending_frames,
            music_buffer_frames: self.music_buffer_frames,
            schedule,
            kv,
        })
    }
}

/// A session configuration of either family.
#[derive(Clone, Copy, Debug)]
pub(crate) enum AnyConfig {
    Duolando(SessionConfig),
    Bailando(SoloConfig),
}

impl DuoSessionConfig {
    fn from_solo(c: &SoloConfig) -> Self {
        let (sampling, top_k, temperature_milli, rng_seed) = sampling_fields(c.sampling);
        DuoSessionConfig {
            dec_future: c.dec_future,
            shift: c.shift,
            pending_frames: c.pending_frames,
            music_buffer_frames: c.music_buffer_rows,
            sampling,
            top_k,
            staggered: if c.schedule == CacheSchedule::Spread {
                2
            } else {
                0
            },
            kv: match c.kv {
                KvType::F32 => KV_F32,
                KvType::F16 => KV_F16,
            },
            rng_seed,
            temperature_milli,
            ..DuoSessionConfig::default()
        }
    }

    /// A solo model's configuration: the fields it has (dec_future, shift,
    /// pending_frames, music_buffer_frames = music rows, sampling, top_k,
    /// kv, rng_seed); the others must be 0 (refused by name).
    fn to_solo(self) -> Result<SoloConfig, Failure> {
        for (v, name) in [
            (self.lookahead, "lookahead"),
            (self.enc_future, "enc_future"),
            (self.music_lookahead, "music_lookahead"),
            (self.lat_past, "lat_past"),
            (if self.staggered == 1 { 1 } else { 0 }, "staggered"),
        ] {
            if v != 0 {
                return Err(Failure::invalid(format!(
                    "config.{name} is {v}: a Bailando model (a solo dancer) has no {name}; leave it 0 (start from duo_session_config_preset)"
                )));
            }
        }
        let d = self.to_core_fields()?;
        let schedule = match self.staggered {
            0 => CacheSchedule::Reprefill,
            2 => CacheSchedule::Spread,
            v => return Err(Failure::invalid(format!("config.staggered is {v}: a Bailando model takes 0 (one cache) or 2 (two caches, spread)"))),
        };
        Ok(SoloConfig {
            dec_future: self.dec_future,
            shift: self.shift,
            sampling: d.0,
            pending_frames: self.pending_frames,
            music_buffer_rows: self.music_buffer_frames,
            kv: d.1,
            schedule,
        })
    }

    fn to_core_fields(self) -> Result<(Sampling, KvType), Failure> {
        if self.reserved != 0 {
            return Err(Failure::invalid(format!(
                "config.reserved is {}: it must be 0 (start from duo_session_config_preset)",
                self.reserved
            )));
        }
        let sampling = match self.sampling {
            SAMPLING_GREEDY => Sampling::Greedy,
            SAMPLING_TOP_K => Sampling::TopK {
                k: self.top_k,
                rng_seed: self.rng_seed,
            },
            SAMPLING_SOFTMAX => Sampling::Softmax {
                k: self.top_k,
                temperature_milli: self.temperature_milli,
                rng_seed: self.rng_seed,
            },
            s => {
                return Err(Failure::invalid(format!(
                    "config.sampling {s} is not a duo_sampling value (0 greedy, 1 top-k, 2 softmax)"
                )))
            }
        };
        let kv = match self.kv {
            KV_F32 => KvType::F32,
            KV_F16 => KvType::F16,
            k => {
                return Err(Failure::invalid(format!(
                    "config.kv {k} is not a duo_kv value (0 f32, 1 f16)"
                )))
            }
        };
        Ok((sampling, kv))
    }

    fn from_any(c: &AnyConfig) -> Self {
        match c {
            AnyConfig::Duolando(c) => Self::from_core(c),
            AnyConfig::Bailando(c) => Self::from_solo(c),
        }
    }
}

/// The session of either family behind a `duo_session`.
pub(crate) enum AnySession {
    Duolando {
        session: Session<'static>,
        /// The step memory the session needs (`StepDims::new(.., 1)`): what
        /// a `duo_step_batch` must hold to step it.
        dims: StepDims,
        /// The batch whose step memory the session borrows for each call
        /// (`duo_session_new_batched`: it has none of its own); None: its
        /// own. Dropped after the session.
        bound: Option<BoundBatch>,
    },
    Bailando(SoloSession<'static>),
    Transflower(TfSession<'static>),
}

/// What a `duo_session *` points to.
pub struct SessionInner {
    /// Borrows `model` and the arena; declared first, dropped first.
    pub(crate) session: AnySession,
    /// The counted model reference that keeps the weights alive.
    pub(crate) model: Arc<ModelInner>,
    /// Library-allocated arena (`duo_session_new`); None in caller memory.
    _arena: Option<Box<[u8]>>,
    /// True when this struct lives in caller memory (`duo_session_new_in`).
    in_caller_memory: bool,
}

impl SessionInner {
    /// A session in library memory: `session` borrows `arena` and `model`'s
    /// weights, both kept here (and dropped after it).
    pub(crate) fn owned(
        session: AnySession,
        model: Arc<ModelInner>,
        arena: Box<[u8]>,
    ) -> Box<SessionInner> {
        Box::new(SessionInner {
            session,
            model,
            _arena: Some(arena),
            in_caller_memory: false,
        })
    }

    /// A session in caller memory (its arena too), written into a
    /// [`caller_slot`] and dropped in place.
    pub(crate) fn in_caller(session: AnySession, model: Arc<ModelInner>) -> SessionInner {
        SessionInner {
            session,
            model,
            _arena: None,
            in_caller_memory: true,
        }
    }

    /// Runs `f` on the Duolando session with step memory ([`with_step_memory`]),
    /// or refuses a session of another family for `what`.
    pub(crate) fn duolando<R>(
        &mut self,
        what: &str,
        f: impl FnOnce(&mut Session<'static>) -> Result<R, duolando_core::Error>,
    ) -> Result<R, Failure> {
        match &mut self.session {
            AnySession::Duolando { session, bound, .. } => Ok(with_step_memory(session, bound, f)?),
            AnySession::Bailando(_) => Err(solo_refusal(what)),
            AnySession::Transflower(_) => Err(transflower_refusal(what)),
        }
    }
}

/// Runs `f` on a Duolando session with step memory: its own, or the
/// memory of the batch it is bound to, locked for the call.
pub(crate) fn with_step_memory<R>(
    session: &mut Session<'static>,
    bound: &Option<BoundBatch>,
    f: impl FnOnce(&mut Session<'static>) -> Result<R, duolando_core::Error>,
) -> Result<R, duolando_core::Error> {
    match bound {
        None => f(session),
        Some(b) => session.with_batch(&mut b.lock(), f)?,
    }
}

/// `what` is for Duolando sessions; this one dances solo to music.
pub(crate) fn solo_refusal(what: &str) -> Failure {
    Failure::invalid(format!(
        "{what}: this session's model is a Bailando model (a solo dancer): it takes music only (duo_session_push_music) and gives positions (duo_session_pull_positions)"
    ))
}

/// Opaque `duo_session`.
pub type DuoSession = SessionInner;

pub(crate) fn model_ref<'x>(model: *const DuoModel) -> Result<&'x ModelInner, Failure> {
    // SAFETY: NULL or a live handle (the documented contract).
    unsafe { model.as_ref() }.ok_or_else(|| Failure::null("model"))
}

pub(crate) fn config_ref(
    model: &ModelInner,
    config: *const DuoSessionConfig,
) -> Result<SessionConfig, Failure> {
    let m = model.duolando("a step batch")?;
    // SAFETY: NULL or a valid struct (contract).
    let c = unsafe { config.as_ref() }.ok_or_else(|| Failure::null("config"))?;
    let core = c.to_core()?;
    // Validate now for a message naming the setting (also done by core).
    m.session_bytes(&core)?;
    Ok(core)
}

/// The configuration for a session of `model`'s family, checked.
pub(crate) fn any_config_ref(
    model: &ModelInner,
    config: *const DuoSessionConfig,
) -> Result<AnyConfig, Failure> {
    // SAFETY: NULL or a valid struct (contract).
    let c = unsafe { config.as_ref() }.ok_or_else(|| Failure::null("config"))?;
    match model.any() {
        AnyModel::Duolando(m) => {
            let core = c.to_core()?;
            m.session_bytes(&core)?;
            Ok(AnyConfig::Duolando(core))
        }
        AnyModel::Bailando(m) => {
            let core = c.to_solo()?;
            m.session_bytes(&core)?;
            Ok(AnyConfig::Bailando(core))
        }
        AnyModel::Transflower(_) => Err(transflower_refusal("duo_session_config")),
    }
}

/// Arena bytes of a session of `cfg` on `model`.
fn any_session_bytes(model: &ModelInner, cfg: &AnyConfig) -> Result<usize, Failure> {
    Ok(match (model.any(), cfg) {
        (AnyModel::Duolando(m), AnyConfig::Duolando(c)) => m.session_bytes(c)?,
        (AnyModel::Bailando(m), AnyConfig::Bailando(c)) => m.session_bytes(c)?,
        _ => return Err(Failure::invalid("configuration of another family")),
    })
}

/// Seed tokens for `model`'s family: 5 (Duolando) or 2 (Bailando: up, down).
#[derive(Clone, Copy)]
pub(crate) enum AnySeed {
    Duolando([u32; 5]),
    Bailando([u32; 2]),
}

fn any_seed_ref(model: &ModelInner, seed: *const u32) -> Result<AnySeed, Failure> {
    if seed.is_null() {
        return Err(Failure::null("seed_tokens"));
    }
    Ok(match model.any() {
        AnyModel::Duolando(_) => AnySeed::Duolando(seed_ref(seed)?),
        // SAFETY: the contract: 2 readable u32 for a Bailando model.
        AnyModel::Bailando(_) => {
            AnySeed::Bailando(unsafe { std::ptr::read_unaligned(seed.cast::<[u32; 2]>()) })
        }
        AnyModel::Transflower(_) => return Err(transflower_refusal("seed_tokens")),
    })
}

pub(crate) fn seed_ref(seed: *const u32) -> Result<[u32; 5], Failure> {
    if seed.is_null() {
        return Err(Failure::null("seed_tokens"));
    }
    // SAFETY: the contract: 5 readable u32.
    Ok(unsafe { std::ptr::read_unaligned(seed.cast::<[u32; 5]>()) })
}

pub(crate) fn session_mut<'x>(session: *mut DuoSession) -> Result<&'x mut SessionInner, Failure> {
    // SAFETY: NULL or a live handle used by one thread at a time (contract).
    unsafe { session.as_mut() }.ok_or_else(|| Failure::null("session"))
}

/// Writes the default configuration for `which` into `out`.
///
/// # Safety
/// `model` NULL or a live handle; `out` NULL or writable (the contract of
/// the two public entry points below).
unsafe fn config_default(
    model: *const DuoModel,
    out: *mut DuoSessionConfig,
    reference: bool,
) -> Result<DuoResult, Failure> {
    let m = model_ref(model)?;
    if out.is_null() {
        return Err(Failure::null("out_config"));
    }
    let c = match m.any() {
        AnyModel::Duolando(model) => {
            let cfg = model.config();
            AnyConfig::Duolando(if reference {
                SessionConfig::reference(cfg)
            } else {
                SessionConfig::minimum(cfg)
            })
        }
        AnyModel::Bailando(model) => AnyConfig::Bailando(SoloConfig::preset(
            &model.cfg,
            if reference {
                SoloPreset::Reference
            } else {
                SoloPreset::Minimum
            },
        )),
        AnyModel::Transflower(_) => {
            return Err(transflower_refusal(if reference {
                "duo_session_config_reference"
            } else {
                "duo_session_config_minimum"
            }))
        }
    };
    // SAFETY: checked non-NULL.
    unsafe { *out = DuoSessionConfig::from_any(&c) };
    Ok(DuoResult::Ok)
}

/// The reference preset: full look-ahead and conv context (about 9.7 s of
/// latency for the full model), the presets' window shift (15 at full size).
///
/// # Safety
/// `model` NULL or live; `out_config` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_session_config_reference(
    model: *const DuoModel,
    out_config: *mut DuoSessionConfig,
) -> DuoResult {
    // SAFETY: the caller's contract above is `config_default`'s.
    guard("duo_session_config_reference", || unsafe {
        config_default(model, out_config, true)
    })
}

/// The lowest-latency configuration (no leader look-ahead, no encoder or
/// decoder future: latency 0 frames; music look-ahead kept).
///
/// # Safety
/// `model` NULL or live; `out_config` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_session_config_minimum(
    model: *const DuoModel,
    out_config: *mut DuoSessionConfig,
) -> DuoResult {
    // SAFETY: the caller's contract above is `config_default`'s.
    guard("duo_session_config_minimum", || unsafe {
        config_default(model, out_config, false)
    })
}

/// The named preset `name` (NUL-terminated: "reference", "interactive",
/// "live-music", "minimum": `duolando_core::duolando::session::Preset::ALL`, the
/// list the CLI takes) into `out_config`.
///
/// # Safety
/// `model` NULL or live; `name` NULL or a NUL-terminated string;
/// `out_config` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_session_config_preset(
    model: *const DuoModel,
    name: *const std::ffi::c_char,
    out_config: *mut DuoSessionConfig,
) -> DuoResult {
    guard("duo_session_config_preset", || {
        let m = model_ref(model)?;
        if name.is_null() {
            return Err(Failure::null("name"));
        }
        if out_config.is_null() {
            return Err(Failure::null("out_config"));
        }
        // SAFETY: NULL checked; NUL-terminated (contract).
        let n = unsafe { std::ffi::CStr::from_ptr(name) }.to_string_lossy();
        let c = match m.any() {
            AnyModel::Duolando(model) => {
                let names: Vec<&str> = Preset::ALL.iter().map(|p| p.name()).collect();
                let p = Preset::from_name(&n).ok_or_else(|| {
                    Failure::invalid(format!(
                        "no preset named '{n}' for a Duolando model (presets: {})",
                        names.join(", ")
                    ))
                })?;
                AnyConfig::Duolando(SessionConfig::preset(model.config(), p))
            }
            AnyModel::Bailando(model) => {
                let names: Vec<&str> = SoloPreset::ALL.iter().map(|p| p.name()).collect();
                let p = SoloPreset::from_name(&n).ok_or_else(|| {
                    Failure::invalid(format!(
                        "no preset named '{n}' for a Bailando model (presets: {})",
                        names.join(", ")
                    ))
                })?;
                AnyConfig::Bailando(SoloConfig::preset(&model.cfg, p))
            }
            AnyModel::Transflower(_) => {
                return Err(transflower_refusal(
                    "duo_session_config_preset (Transflower: duo_transflower_config_preset)",
                ))
            }
        };
        // SAFETY: checked non-NULL.
        unsafe { *out_config = DuoSessionConfig::from_any(&c) };
        Ok(DuoResult::Ok)
    })
}

/// Alignment slack and size of the handle placed at the start of caller memory.
pub(crate) const HANDLE_BYTES: usize = handle_bytes::<SessionInner>();

/// Every session constructor's end: an `n`-byte arena allocated here
/// (`memory` None) or taken from caller memory (`memory` = pointer and
/// length, the handle first; `bytes_fn` names the size function), `make`
/// building the session over it with the model reference the handle
/// keeps, and the handle written to `*out_session` (checked non-NULL by the
/// caller, in its order of refusals).
///
/// # Safety
/// `model` a live handle; `memory` None, or NULL or `len` writable bytes
/// that stay valid, unmoved and otherwise untouched until
/// `duo_session_free`; `out_session` writable.
pub(crate) unsafe fn place_session(
    n: usize,
    memory: Option<(*mut u8, usize)>,
    bytes_fn: &str,
    model: *const DuoModel,
    out_session: *mut *mut DuoSession,
    make: impl FnOnce(&Arc<ModelInner>, &'static mut [u8]) -> Result<AnySession, Failure>,
) -> Result<DuoResult, Failure> {
    let handle = match memory {
        None => {
            let mut arena = vec![0u8; n].into_boxed_slice();
            // SAFETY: the boxed bytes stay at one address until the
            // SessionInner drops them, after the session.
            let bytes: &'static mut [u8] =
                unsafe { std::slice::from_raw_parts_mut(arena.as_mut_ptr(), arena.len()) };
            // SAFETY: `model` is a live handle (contract).
            let arc = unsafe { share(model) };
            let session = make(&arc, bytes)?;
            Box::into_raw(SessionInner::owned(session, arc, arena))
        }
        Some((ptr, len)) => {
            // SAFETY: NULL or `len` writable bytes kept for the session (contract).
            let memory = unsafe { buffer_mut(ptr, len, "memory") }?;
            let (slot, arena) =
                caller_slot::<SessionInner>(memory, n.saturating_add(HANDLE_BYTES), bytes_fn)?;
            // SAFETY: `model` is a live handle (contract).
            let arc = unsafe { share(model) };
            let session = make(&arc, arena)?;
            // SAFETY: `slot` is aligned, in bounds, and holds no value yet.
            unsafe { slot.write(SessionInner::in_caller(session, arc)) };
            slot
        }
    };
    // SAFETY: writable (contract).
    unsafe { *out_session = handle };
    Ok(DuoResult::Ok)
}

/// Bytes `duo_session_new_in` needs for `config` (any address).
///
/// # Safety
/// Pointers NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn duo_session_bytes(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    out_bytes: *mut usize,
) -> DuoResult {
    guard("duo_session_bytes", || {
        let m = model_ref(model)?;
        let cfg = any_config_ref(m, config)?;
        if out_bytes.is_null() {
            return Err(Failure::null("out_bytes"));
        }
        let n = any_session_bytes(m, &cfg)?;
        let total = n
            .checked_add(HANDLE_BYTES)
            .ok_or_else(|| Failure::invalid("session size overflows size_t"))?;
        // SAFETY: checked non-NULL.
        unsafe { *out_bytes = total };
        Ok(DuoResult::Ok)
    })
}

/// Builds the core session over `arena` (which must outlive it: the
/// caller of this function guarantees it); a Duolando session bound to a
/// batch where `bound` is given (its state alone in `arena`).
pub(crate) fn start(
    model: &Arc<ModelInner>,
    arena: &'static mut [u8],
    cfg: &AnyConfig,
    seed: AnySeed,
    bound: Option<BoundBatch>,
) -> Result<AnySession, Failure> {
    // SAFETY: the model lives in the Arc, which the SessionInner keeps
    // (and drops after the session).
    let m: &'static ModelInner = unsafe { &*Arc::as_ptr(model) };
    Ok(match (m.any(), cfg, seed) {
        (AnyModel::Duolando(model), AnyConfig::Duolando(c), AnySeed::Duolando(seed)) => {
            let dims = StepDims::new(model.config(), c, 1).map_err(duolando_core::Error::Arena)?;
            let session = match &bound {
                None => Session::new(model, arena, c, seed)?,
                Some(b) => Session::new_batched(model, arena, c, seed, &mut b.lock())?,
            };
            AnySession::Duolando {
                session,
                dims,
                bound,
            }
        }
        (AnyModel::Bailando(model), AnyConfig::Bailando(c), AnySeed::Bailando(seed))
            if bound.is_none() =>
        {
            AnySession::Bailando(SoloSession::new(model, arena, c, seed)?)
        }
        _ => return Err(Failure::invalid("configuration or seed of another family")),
    })
}

/// A session in library memory (allocated here, once).
///
/// # Safety
/// `model` NULL or live; `config` NULL or valid; `seed_tokens` NULL or 5
/// readable u32; `out_session` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_session_new(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    seed_tokens: *const u32,
    out_session: *mut *mut DuoSession,
) -> DuoResult {
    guard("duo_session_new", || {
        let m = model_ref(model)?;
        let cfg = any_config_ref(m, config)?;
        let seed = any_seed_ref(m, seed_tokens)?;
        if out_session.is_null() {
            return Err(Failure::null("out_session"));
        }
        let n = any_session_bytes(m, &cfg)?;
        // SAFETY: the caller's contract; `out_session` checked non-NULL.
        unsafe {
            place_session(
                n,
                None,
                "duo_session_bytes",
                model,
                out_session,
                |arc, arena| start(arc, arena, &cfg, seed, None),
            )
        }
    })
}

/// A session placed entirely in caller memory (`memory`, `len` >=
/// `duo_session_bytes`; any alignment). No allocation.
///
/// # Safety
/// As `duo_session_new`; `memory` NULL or `len` writable bytes that stay
/// valid, unmoved and otherwise untouched until `duo_session_free`.
#[no_mangle]
pub unsafe extern "C" fn duo_session_new_in(
    model: *const DuoModel,
    config: *const DuoSessionConfig,
    seed_tokens: *const u32,
    memory: *mut u8,
    len: usize,
    out_session: *mut *mut DuoSession,
) -> DuoResult {
    guard("duo_session_new_in", || {
        let m = model_ref(model)?;
        let cfg = any_config_ref(m, config)?;
        let seed = any_seed_ref(m, seed_tokens)?;
        if out_session.is_null() {
            return Err(Failure::null("out_session"));
        }
        let n = any_session_bytes(m, &cfg)?;
        // SAFETY: the caller's contract; `out_session` checked non-NULL.
        unsafe {
            place_session(
                n,
                Some((memory, len)),
                "duo_session_bytes",
                model,
                out_session,
                |arc, arena| start(arc, arena, &cfg, seed, None),
            )
        }
    })
}

/// Frees a session (and its model reference). NULL is ignored. For
/// `duo_session_new_in`, the caller's memory may be released afterwards.
///
/// # Safety
/// `session` NULL or a live handle, freed once, not used afterwards.
#[no_mangle]
pub unsafe extern "C" fn duo_session_free(session: *mut DuoSession) {
    let _ = guard("duo_session_free", || {
        // SAFETY: NULL or a live handle, freed once (contract).
        unsafe { drop_handle(session, |s| s.in_caller_memory) };
        Ok(DuoResult::Ok)
    });
}

/// `*out_frames` = frames between a leader frame and the follower frame
/// of the same index: with a music track, `Session::latency_frames`;
/// without one (music pushed `music_lookahead` tokens ahead) the live
/// latency, which is longer when lookahead + enc_future is 0.
///
/// # Safety
/// Pointers NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn duo_session_latency_frames(
    session: *const DuoSession,
    out_frames: *mut u32,
) -> DuoResult {
    guard("duo_session_latency_frames", || {
        // SAFETY: NULL or live (contract).
        let s = unsafe { session.as_ref() }.ok_or_else(|| Failure::null("session"))?;
        if out_frames.is_null() {
            return Err(Failure::null("out_frames"));
        }
        // SAFETY: checked non-NULL.
        let frames = match &s.session {
            AnySession::Duolando { session, .. } => session.latency_frames(),
            AnySession::Bailando(session) => session.latency_frames(),
            AnySession::Transflower(_) => return Err(transflower_refusal("duo_session_latency_frames (Transflower: duo_transflower_get_info's lookahead_rows)")),
        };
        // SAFETY: checked non-NULL.
        unsafe { *out_frames = frames };
        Ok(DuoResult::Ok)
    })
}

/// Index and value of the first value that is non-finite or above `limit`.
fn first_bad(x: &[f32], limit: f32) -> Option<(usize, f32)> {
    x.iter()
        .position(|v| !v.is_finite() || v.abs() > limit)
        .map(|i| (i, x[i]))
}

/// A core refusal, with the offending value in the message when core
/// refused a value of `x` (non-finite or above `limit`).
pub(crate) fn rejected_value(
    e: duolando_core::Error,
    x: &[f32],
    what: &str,
    limit: f32,
) -> Failure {
    match e {
        duolando_core::Error::NonFinite { index, .. }
        | duolando_core::Error::OutOfRange { index, .. }
            if index < x.len() =>
        {
            reject(what, index, x[index], limit, "")
        }
        e => e.into(),
    }
}

fn reject(what: &str, i: usize, v: f32, limit: f32, unit: &str) -> Failure {
    let msg = if v.is_finite() {
        format!("{what} value {v:e} at flat index {i} exceeds {limit:e}{unit}; frame rejected, session unchanged")
    } else {
        format!("{what} contains {v} at flat index {i}; frame rejected, session unchanged")
    };
    Failure::new(DuoResult::NonFiniteInput, msg)
}

/// The 165 floats of a leader frame (in place), refused
/// (`DUO_NON_FINITE_INPUT`) if a coordinate is non-finite or above
/// [`MAX_POSITION_M`].
pub(crate) fn leader_pos3d(f: &DuoLeaderFrame) -> Result<&[f32; POSE_DIM], Failure> {
    let pos = f.pos3d();
    if let Some((i, v)) = first_bad(pos, MAX_POSITION_M) {
        return Err(reject("leader frame", i, v, MAX_POSITION_M, " m"));
    }
    Ok(pos)
}

/// Pushes one leader frame (SMPL-X, metres).
///
/// # Safety
/// `session` NULL or live (one thread at a time); `frame` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn duo_session_push_leader(
    session: *mut DuoSession,
    frame: *const DuoLeaderFrame,
) -> DuoResult {
    guard("duo_session_push_leader", || {
        let s = session_mut(session)?;
        // SAFETY: NULL or valid (contract).
        let f = unsafe { frame.as_ref() }.ok_or_else(|| Failure::null("frame"))?;
        // The family first, then the frame's values (as before bound sessions).
        let what = "duo_session_push_leader";
        let (session, bound) = match &mut s.session {
            AnySession::Duolando { session, bound, .. } => (session, bound),
            AnySession::Bailando(_) => return Err(solo_refusal(what)),
            AnySession::Transflower(_) => return Err(transflower_refusal(what)),
        };
        let pos = leader_pos3d(f)?;
        with_step_memory(session, bound, |s| s.push_leader_frame(pos))?;
        Ok(DuoResult::Ok)
    })
}

/// The leader has ended (`Session::finish`): the session decodes what the
/// look-ahead allows, as the offline model does at the end of a clip; pull
/// the remaining frames as usual (as many in all as the offline model
/// outputs). Afterwards `duo_session_push_leader` answers `DUO_ENDED`
/// until `duo_session_reset`; calling it again does nothing.
///
/// # Safety
/// `session` NULL or live (one thread at a time).
#[no_mangle]
pub unsafe extern "C" fn duo_session_finish(session: *mut DuoSession) -> DuoResult {
    guard("duo_session_finish", || {
        let s = session_mut(session)?;
        match &mut s.session {
            AnySession::Duolando { session, bound, .. } => {
                with_step_memory(session, bound, |s| s.finish())?
            }
            // The music-only path's end padding (copies of the last row to a
            // whole number of tokens, at least one); again: nothing to do.
            AnySession::Bailando(session) => match session.finish(MusicPadding::Demo) {
                Ok(()) | Err(duolando_core::Error::State) if session.music_rows() > 0 => {}
                Ok(()) => {}
                Err(duolando_core::Error::State) => {
                    return Err(Failure::invalid(
                        "duo_session_finish before any music row: a solo dance needs music",
                    ))
                }
                Err(e) => return Err(e.into()),
            },
            AnySession::Transflower(_) => return Err(transflower_refusal("duo_session_finish (a Transflower session has nothing to drain: each frame is final when its step runs)")),
        }
        Ok(DuoResult::Ok)
    })
}

/// Pushes one music feature frame (`n_features` = duo_model_info.music_features).
///
/// # Safety
/// `session` NULL or live; `features` NULL or `n_features` readable floats.
#[no_mangle]
pub unsafe extern "C" fn duo_session_push_music(
    session: *mut DuoSession,
    features: *const f32,
    n_features: usize,
) -> DuoResult {
    guard("duo_session_push_music", || {
        let s = session_mut(session)?;
        // SAFETY: NULL or `n_features` readable floats (contract).
        let x = unsafe { buffer(features, n_features, "features") }?;
        // Core checks state, then the length, then the values: a frame of
        // the wrong length is refused as such whatever it holds.
        match &mut s.session {
            AnySession::Duolando { session, bound, .. } => {
                with_step_memory(session, bound, |s| s.push_music_frame(x))
            }
            AnySession::Bailando(session) => session.push_music(x),
            AnySession::Transflower(session) => {
                let audio = session.config_model().inputs().len() - 1;
                crate::transflower::push_rows(session, audio, x, "n_features")?;
                return Ok(DuoResult::Ok);
            }
        }
        .map_err(|e| rejected_value(e, x, "music frame", MAX_MUSIC_FEATURE))?;
        Ok(DuoResult::Ok)
    })
}

/// Gives the session a whole music track (frames x music_features floats),
/// borrowed, instead of pushing music frame by frame.
///
/// # Safety
/// `session` NULL or live; `track` NULL or `n_floats` readable floats that
/// stay valid and unmodified until the session is reset or freed.
#[no_mangle]
pub unsafe extern "C" fn duo_session_set_music_track(
    session: *mut DuoSession,
    track: *const f32,
    n_floats: usize,
) -> DuoResult {
    guard("duo_session_set_music_track", || {
        let s = session_mut(session)?;
        // SAFETY: NULL or `n_floats` readable floats valid until reset/free,
        // which drop the borrow (contract).
        let x: &'static [f32] = unsafe { buffer(track, n_floats, "track") }?;
        match &mut s.session {
            AnySession::Duolando { session, bound, .. } => {
                with_step_memory(session, bound, |s| s.set_music_track(x))
            }
            // A solo session copies the rows into its music buffer.
            AnySession::Bailando(session) if x.is_empty() => {
                let _ = session;
                Ok(())
            }
            AnySession::Bailando(session) => {
                if session.music_rows() > 0 {
                    return Err(Failure::invalid(
                        "music already given: a track goes before any music row",
                    ));
                }
                session.push_music(x)
            }
            AnySession::Transflower(_) => {
                return Err(transflower_refusal(
                    "duo_session_set_music_track (push the audio rows with duo_session_push_music)",
                ))
            }
        }
        .map_err(|e| rejected_value(e, x, "music track", MAX_MUSIC_FEATURE))?;
        Ok(DuoResult::Ok)
    })
}

/// Converts a core frame to the C struct (rotations projected to the
/// nearest rotation, as quaternions).
pub fn to_c_frame(f: &FollowerFrame, out: &mut DuoFollowerFrame) {
    out.index = f.index;
    for j in 0..N_JOINTS {
        out.positions[j] = DuoVec3 {
            x: f.positions[3 * j],
            y: f.positions[3 * j + 1],
            z: f.positions[3 * j + 2],
        };
        out.rotations[j] = quat_of_raw(&f.rotations[9 * j..9 * j + 9]);
    }
    out.root = DuoVec3 {
        x: f.root[0],
        y: f.root[1],
        z: f.root[2],
    };
}

/// Pulls the next follower frame: DUO_OK (written) or DUO_NOT_READY
/// (untouched).
///
/// # Safety
/// `session` NULL or live; `out_frame` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_session_pull_follower(
    session: *mut DuoSession,
    out_frame: *mut DuoFollowerFrame,
) -> DuoResult {
    guard("duo_session_pull_follower", || {
        let s = session_mut(session)?;
        if out_frame.is_null() {
            return Err(Failure::null("out_frame"));
        }
        let mut f = FollowerFrame::default();
        if !s.duolando("duo_session_pull_follower", |s| {
            s.pull_follower_frame(&mut f)
        })? {
            return Ok(DuoResult::NotReady);
        }
        let mut c = DuoFollowerFrame::default();
        to_c_frame(&f, &mut c);
        // SAFETY: checked non-NULL.
        unsafe { *out_frame = c };
        Ok(DuoResult::Ok)
    })
}

/// Pulls the next frame's joint positions, for a session of any family:
/// `n_floats` = joints x 3 (duo_model_info.joints), world positions in
/// metres; `*out_index` (NULL or writable) gets the frame index. DUO_OK
/// or DUO_NOT_READY (nothing written). `out` follows the buffer rule (NULL
/// with 0 is an empty buffer: a wrong count).
///
/// # Safety
/// `session` NULL or live; `out` NULL or `n_floats` writable floats;
/// `out_index` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_session_pull_positions(
    session: *mut DuoSession,
    out: *mut f32,
    n_floats: usize,
    out_index: *mut u64,
) -> DuoResult {
    guard("duo_session_pull_positions", || {
        let s = session_mut(session)?;
        let joints = match &s.session {
            AnySession::Duolando { .. } => N_JOINTS,
            AnySession::Bailando(_) => duolando_core::bailando::config::N_JOINTS,
            AnySession::Transflower(_) => return Err(transflower_refusal("duo_session_pull_positions (its frames are motion features: duo_transflower_pull_frame)")),
        };
        // SAFETY: NULL or `n_floats` writable floats (contract); the buffer
        // rule: NULL with 0 is an empty buffer (a wrong count below).
        let dst = unsafe { buffer_mut(out.cast::<u8>(), n_floats.saturating_mul(4), "out") }?;
        if n_floats != joints * 3 {
            return Err(Failure::invalid(format!(
                "n_floats is {n_floats}; a frame of this model has {joints} joints x 3 = {} floats",
                joints * 3
            )));
        }
        // SAFETY: `dst` is `n_floats * 4` writable bytes at `out`, which the
        // caller gives as floats (aligned for f32 by the contract).
        let dst =
            unsafe { std::slice::from_raw_parts_mut(dst.as_mut_ptr().cast::<f32>(), n_floats) };
        let index = match &mut s.session {
            AnySession::Duolando { session, bound, .. } => {
                let mut f = FollowerFrame::default();
                if !with_step_memory(session, bound, |s| s.pull_follower_frame(&mut f))? {
                    return Ok(DuoResult::NotReady);
                }
                dst.copy_from_slice(&f.positions);
                f.index
            }
            AnySession::Bailando(session) => {
                let mut f = [0f32; duolando_core::bailando::config::POSE_DIM];
                match session.pull(&mut f)? {
                    Some(i) => {
                        dst.copy_from_slice(&f);
                        i
                    }
                    None => return Ok(DuoResult::NotReady),
                }
            }
            AnySession::Transflower(_) => {
                return Err(transflower_refusal("duo_session_pull_positions"))
            }
        };
        if !out_index.is_null() {
            // SAFETY: non-NULL and writable (contract).
            unsafe { *out_index = index };
        }
        Ok(DuoResult::Ok)
    })
}

/// Back to the start with new seed tokens (the music track is dropped).
///
/// # Safety
/// `session` NULL or live; `seed_tokens` NULL or 5 readable u32.
#[no_mangle]
pub unsafe extern "C" fn duo_session_reset(
    session: *mut DuoSession,
    seed_tokens: *const u32,
) -> DuoResult {
    guard("duo_session_reset", || {
        let s = session_mut(session)?;
        if let AnySession::Transflower(_) = s.session {
            return Err(transflower_refusal(
                "duo_session_reset (Transflower: duo_transflower_session_reset)",
            ));
        }
        let seed = any_seed_ref(&s.model, seed_tokens)?;
        match (&mut s.session, seed) {
            (AnySession::Duolando { session, bound, .. }, AnySeed::Duolando(seed)) => {
                with_step_memory(session, bound, |s| s.reset(seed))?
            }
            (AnySession::Bailando(session), AnySeed::Bailando(seed)) => session.reset(seed)?,
            _ => return Err(Failure::invalid("seed of another family")),
        }
        Ok(DuoResult::Ok)
    })
}

/// Seed tokens from follower and leader start frames (`n_frames` each,
/// 165 floats a frame, a multiple of frames_per_token is used).
///
/// # Safety
/// `model` NULL or live; `follower_pos3d`/`leader_pos3d` NULL or
/// `n_frames * 165` readable floats; `out_tokens` NULL or 5 writable u32.
#[no_mangle]
pub unsafe extern "C" fn duo_model_seed_tokens(
    model: *const DuoModel,
    follower_pos3d: *const f32,
    leader_pos3d: *const f32,
    n_frames: usize,
    out_tokens: *mut u32,
) -> DuoResult {
    guard("duo_model_seed_tokens", || {
        let m = model_ref(model)?.duolando("duo_model_seed_tokens (a Bailando session takes its 2 seed tokens, up and down, directly)")?;
        if out_tokens.is_null() {
            return Err(Failure::null("out_tokens"));
        }
        let n = n_frames
            .checked_mul(POSE_DIM)
            .ok_or_else(|| Failure::invalid("n_frames too large"))?;
        // SAFETY: each NULL or `n_frames * 165` readable floats (contract).
        let (f, l) = unsafe {
            (
                buffer(follower_pos3d, n, "follower_pos3d")?,
                buffer(leader_pos3d, n, "leader_pos3d")?,
            )
        };
        for (what, x) in [("follower frames", f), ("leader frames", l)] {
            if let Some((i, v)) = first_bad(x, MAX_POSITION_M) {
                return Err(reject(what, i, v, MAX_POSITION_M, " m"));
            }
        }
        let cfg = m.config();
        let bytes = match duolando_core::duolando::exact::seed_scratch_bytes(cfg, n_frames) {
            Some(b) => b,
            // Too few frames (0 included): core says so before any scratch is used.
            None if n_frames < cfg.hop() => 0,
            None => return Err(Failure::invalid("n_frames too large")),
        };
        let mut scratch = vec![0u8; bytes];
        let t = duolando_core::duolando::exact::seed_tokens(m, f, l, &mut scratch)?;
        // SAFETY: checked non-NULL; 5 writable u32 (contract).
        unsafe { std::ptr::write_unaligned(out_tokens.cast::<[u32; 5]>(), t) };
        Ok(DuoResult::Ok)
    })
}
