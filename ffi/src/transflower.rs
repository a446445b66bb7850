//! Transflower sessions through the C ABI (`duo_transflower_*`): a
//! probabilistic solo dancer whose frames are the model's motion features
//! (scaled, C floats each), made from audio feature rows pushed with
//! `duo_session_push_music`, a motion seed and style labels given at
//! creation, and base samples drawn from the session's seeded RNG or
//! given by the caller (`duo_transflower_pull_frame_with_noise`).
//! `transflower::session` (core) does the work; docs/C_API.md "Transflower".

use std::ffi::{c_char, CStr};
use std::sync::Arc;

use duolando_core::nn::kv_store::KvType;
use duolando_core::transflower::config::FPS;
use duolando_core::transflower::session::{
    batched_session_bytes, lookahead_rows, session_bytes, Preset, Session, SessionConfig,
};

use crate::handle::{buffer, buffer_mut};
use crate::model::{AnyModel, DuoModel, ModelInner};
use crate::result::{guard, DuoResult, Failure};
use crate::session::{
    model_ref, place_session, session_mut, AnySession, DuoSession, SessionInner, HANDLE_BYTES,
};

/// `duo_transflower_info`: the sizes a host needs (48 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct DuoTransflowerInfo {
    /// C: floats per frame (the output modality's features).
    pub channels: u32,
    /// Rows of the motion seed (the output modality's window): the seed is
    /// seed_rows x channels floats.
    pub seed_rows: u32,
    /// Input modalities (motion, audio, labels).
    pub inputs: u32,
    /// Floats per audio row (the last input; duo_session_push_music).
    pub audio_features: u32,
    /// Rows of audio a step reads (the longest window).
    pub audio_window: u32,
    /// Style labels the session takes (discrete inputs).
    pub labels: u32,
    /// Values of the first style label (0 if none).
    pub label_values: u32,
    /// Floats of one base sample (channels x output_length).
    pub noise_floats: u32,
    /// Frames per second (20).
    pub fps: u32,
    /// Frame t is song row `output_time_offset + t`.
    pub output_time_offset: u32,
    /// Audio rows after a frame's own row that its step reads (19 in the
    /// published configs: 0.95 s); negative: none.
    pub lookahead_rows: i32,
    pub reserved: u32,
}

/// `duo_transflower_config` (32 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct DuoTransflowerConfig {
    /// Steps between recomputations of every row: 1 = the offline model.
    pub refresh: u32,
    /// A `duo_kv` value: the stale-rows mode's kept keys and values.
    pub kv: u32,
    /// Audio rows the session holds beyond its window.
    pub input_buffer_rows: u32,
    /// Frames made and not yet pulled (the session makes one per pull).
    pub pending_frames: u32,
    /// 1: recompute a share of the rows every step (no cost spike); 0:
    /// all of them every `refresh`-th step.
    pub rolling: u32,
    /// 1: a session for step batches only: its state alone, no step memory
    /// (`batched_session_bytes`); its frames are made by
    /// `duo_step_batch_step`, its pulls only take them. 0: its own step
    /// memory (it steps on its pulls, and in batches too). Was `reserved`
    /// (0) before step batches.
    pub batched: u32,
    /// The base samples' seed.
    pub rng_seed: u64,
}

// The header's sizes (include/duolando.h), checked at compile time here
// and by tests/c/header_c.c on the C side.
const _: () = assert!(std::mem::size_of::<DuoTransflowerInfo>() == 48);
const _: () = assert!(std::mem::size_of::<DuoTransflowerConfig>() == 32);

impl DuoTransflowerConfig {
    fn from_core(c: &SessionConfig, rng_seed: u64) -> Self {
        DuoTransflowerConfig {
            refresh: c.refresh,
            kv: matches!(c.kv, KvType::F16) as u32,
            input_buffer_rows: c.input_buffer_rows,
            pending_frames: c.pending_frames,
            rolling: c.rolling as u32,
            batched: 0,
            rng_seed,
        }
    }

    /// The core configuration, and whether the session is for batches only.
    fn to_core(self) -> Result<(SessionConfig, bool), Failure> {
        let kv = match self.kv {
            0 => KvType::F32,
            1 => KvType::F16,
            v => {
                return Err(Failure::invalid(format!(
                    "kv is {v}; DUO_KV_F32 (0) or DUO_KV_F16 (1)"
                )))
            }
        };
        let rolling = match self.rolling {
            0 => false,
            1 => true,
            v => return Err(Failure::invalid(format!("rolling is {v}; 0 or 1"))),
        };
        let batched = match self.batched {
            0 => false,
            1 => true,
            v => return Err(Failure::invalid(format!("batched is {v}; 0 or 1"))),
        };
        let c = SessionConfig {
            refresh: self.refresh,
            kv,
            rolling,
            input_buffer_rows: self.input_buffer_rows,
            pending_frames: self.pending_frames,
        };
        c.check().map_err(|(setting, value, max)| {
            Failure::from(duolando_core::Error::Setting {
                setting,
                value,
                max,
            })
        })?;
        Ok((c, batched))
    }
}

pub(crate) fn transflower<'x>(
    m: &'x ModelInner,
    what: &str,
) -> Result<&'x duolando_core::transflower::model::Model<'static>, Failure> {
    match m.any() {
        AnyModel::Transflower(t) => Ok(t),
        _ => Err(Failure::invalid(format!(
            "{what} needs a Transflower model; this is a {} model",
            m.family().name()
        ))),
    }
}

fn session_of<'x>(
    s: &'x mut SessionInner,
    what: &str,
) -> Result<&'x mut Session<'static>, Failure> {
    match &mut s.session {
        AnySession::Transflower(t) => Ok(t),
        _ => Err(Failure::invalid(format!(
            "{what} needs a session of a Transflower model; this one's model is a {} model",
            s.model.family().name()
        ))),
    }
}

/// Rows `x` for sliding input `index` (duo_transflower_push_input, and
/// duo_session_push_music for the audio, the last input): none (`count`
/// names the C count), an index past the inputs, the motion or a label,
/// ragged rows, a bad value (named with its index) or a full feed are
/// refused, the session unchanged.
pub(crate) fn push_rows(
    s: &mut Session<'static>,
    index: usize,
    x: &[f32],
    count: &str,
) -> Result<(), Failure> {
    if x.is_empty() {
        return Err(Failure::invalid(format!(
            "{count} is 0: push one or more whole rows"
        )));
    }
    let n_in = s.config_model().inputs().len();
    if index >= n_in {
        return Err(Failure::invalid(format!(
            "index {index}: the model has {n_in} inputs"
        )));
    }
    s.push(index, x).map_err(|e| match e {
        duolando_core::Error::State => Failure::invalid(format!("input {index} is the motion (fed back) or a style label: only sliding feature inputs are pushed")),
        duolando_core::Error::NonFinite { .. } | duolando_core::Error::OutOfRange { .. } => {
            crate::session::rejected_value(e, x, "rows", duolando_core::input::MAX_MUSIC_FEATURE)
        }
        e => fail(e, s),
    })
}

/// A core refusal of a Transflower session, described with the model's
/// names (inputs, frames) rather than the duet's.
pub(crate) fn fail(e: duolando_core::Error, s: &Session<'_>) -> Failure {
    Failure::new(
        crate::result::code_of(&e),
        duolando_runtime::engine_errors::describe_transflower(&e, s.config_model()),
    )
}

/// Sizes of a Transflower model.
///
/// # Safety
/// `model` NULL or live; `out_info` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_get_info(
    model: *const DuoModel,
    out_info: *mut DuoTransflowerInfo,
) -> DuoResult {
    guard("duo_transflower_get_info", || {
        let m = model_ref(model)?;
        let t = transflower(m, "duo_transflower_get_info")?;
        if out_info.is_null() {
            return Err(Failure::null("out_info"));
        }
        let cfg = &t.cfg;
        let ins = cfg.inputs();
        let last = &ins[ins.len() - 1];
        let first_label = ins.iter().find(|i| i.is_discrete());
        let info = DuoTransflowerInfo {
            channels: cfg.channels() as u32,
            seed_rows: cfg.output_input().length,
            inputs: ins.len() as u32,
            audio_features: if last.is_discrete() { 0 } else { last.dim },
            audio_window: cfg.max_window() as u32,
            labels: ins.iter().filter(|i| i.is_discrete()).count() as u32,
            label_values: first_label.map_or(0, |i| i.tokens),
            noise_floats: (cfg.channels() * cfg.output_length as usize) as u32,
            fps: FPS,
            output_time_offset: cfg.output_time_offset,
            lookahead_rows: lookahead_rows(cfg).clamp(i32::MIN as i64, i32::MAX as i64) as i32,
            reserved: 0,
        };
        // SAFETY: checked non-NULL.
        unsafe { *out_info = info };
        Ok(DuoResult::Ok)
    })
}

/// The named preset ("exact", "reference", "realtime").
///
/// # Safety
/// `model` NULL or live; `name` NULL or NUL-terminated; `out_config` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_config_preset(
    model: *const DuoModel,
    name: *const c_char,
    out_config: *mut DuoTransflowerConfig,
) -> DuoResult {
    guard("duo_transflower_config_preset", || {
        let m = model_ref(model)?;
        transflower(m, "duo_transflower_config_preset")?;
        if name.is_null() {
            return Err(Failure::null("name"));
        }
        if out_config.is_null() {
            return Err(Failure::null("out_config"));
        }
        // SAFETY: NULL checked; NUL-terminated (contract).
        let n = unsafe { CStr::from_ptr(name) }.to_string_lossy();
        let p = Preset::from_name(&n).ok_or_else(|| {
            Failure::invalid(format!(
                "no preset named '{n}' for a Transflower model (presets: {})",
                Preset::ALL.map(Preset::name).join(", ")
            ))
        })?;
        // SAFETY: checked non-NULL.
        unsafe { *out_config = DuoTransflowerConfig::from_core(&SessionConfig::preset(p), 0) };
        Ok(DuoResult::Ok)
    })
}

/// Bytes `duo_transflower_session_new_in` needs for `config` (any
/// address): the session's arena and its handle.
///
/// # Safety
/// Pointers NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_session_bytes(
    model: *const DuoModel,
    config: *const DuoTransflowerConfig,
    out_bytes: *mut usize,
) -> DuoResult {
    guard("duo_transflower_session_bytes", || {
        let m = model_ref(model)?;
        let t = transflower(m, "duo_transflower_session_bytes")?;
        // SAFETY: NULL or a valid struct (contract).
        let c = unsafe { config.as_ref() }
            .ok_or_else(|| Failure::null("config"))?
            .to_core()?;
        if out_bytes.is_null() {
            return Err(Failure::null("out_bytes"));
        }
        let n = arena_bytes(&t.cfg, c)?
            .checked_add(HANDLE_BYTES)
            .ok_or_else(|| Failure::invalid("session size overflows size_t"))?;
        // SAFETY: checked non-NULL.
        unsafe { *out_bytes = n };
        Ok(DuoResult::Ok)
    })
}

/// A Transflower session: `seed_motion` (seed_rows x channels floats, the
/// scaled motion features of the dance so far), `labels` (one per style
/// input, `n_labels` of them; NULL with 0 when there is none).
///
/// # Safety
/// `model` NULL or live; `config` NULL or valid; `seed_motion` NULL or
/// `n_floats` readable floats; `labels` NULL or `n_labels` readable u32;
/// `out_session` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_session_new(
    model: *const DuoModel,
    config: *const DuoTransflowerConfig,
    seed_motion: *const f32,
    n_floats: usize,
    labels: *const u32,
    n_labels: usize,
    out_session: *mut *mut DuoSession,
) -> DuoResult {
    guard("duo_transflower_session_new", || {
        // SAFETY: the caller's pointers as documented above (contract).
        unsafe {
            make_session(
                "duo_transflower_session_new",
                model,
                config,
                (seed_motion, n_floats),
                (labels, n_labels),
                None,
                out_session,
            )
        }
    })
}

/// Arena bytes of a session (`batched`: its state alone).
fn arena_bytes(
    model: &duolando_core::transflower::config::TransflowerConfig,
    (c, batched): (SessionConfig, bool),
) -> Result<usize, duolando_core::Error> {
    if batched {
        batched_session_bytes(model, &c)
    } else {
        session_bytes(model, &c)
    }
}

/// Both constructors: the checks in the header's order, the arena
/// (allocated, or `memory` = (pointer, len) of caller memory: handle
/// first), the session, `*out_session`.
///
/// # Safety
/// As duo_transflower_session_new_in (`memory` None: as _new).
unsafe fn make_session(
    what: &str,
    model: *const DuoModel,
    config: *const DuoTransflowerConfig,
    (seed_motion, n_floats): (*const f32, usize),
    (labels, n_labels): (*const u32, usize),
    memory: Option<(*mut u8, usize)>,
    out_session: *mut *mut DuoSession,
) -> Result<DuoResult, Failure> {
    let m = model_ref(model)?;
    let t = transflower(m, what)?;
    // SAFETY: NULL or a valid struct (contract).
    let cc = *unsafe { config.as_ref() }.ok_or_else(|| Failure::null("config"))?;
    let (c, batched) = cc.to_core()?;
    // SAFETY: NULL or `n_floats` readable floats (contract).
    let seed: &[f32] = unsafe { buffer(seed_motion, n_floats, "seed_motion") }?;
    // SAFETY: NULL or `n_labels` readable u32 (contract).
    let lab: &[u32] = unsafe { buffer(labels, n_labels, "labels") }?;
    if out_session.is_null() {
        return Err(Failure::null("out_session"));
    }
    let n = arena_bytes(&t.cfg, (c, batched))?;
    let make = |arc: &Arc<ModelInner>, arena: &'static mut [u8]| {
        // SAFETY: the model lives in the Arc, which the SessionInner keeps
        // (and drops after the session).
        let tm: &'static duolando_core::transflower::model::Model<'static> =
            match unsafe { &*Arc::as_ptr(arc) }.any() {
                AnyModel::Transflower(t) => t,
                _ => return Err(Failure::invalid("not a Transflower model")),
            };
        let new = if batched {
            Session::new_batched
        } else {
            Session::new
        };
        Ok(AnySession::Transflower(new(
            tm,
            &c,
            seed,
            lab,
            cc.rng_seed,
            arena,
        )?))
    };
    let bytes_fn = "duo_transflower_session_bytes";
    // SAFETY: the caller's contract; `out_session` checked non-NULL.
    unsafe { place_session(n, memory, bytes_fn, model, out_session, make) }
}

/// As duo_transflower_session_new, placed entirely in caller memory
/// (`memory`, `len` >= duo_transflower_session_bytes; any alignment): no
/// allocation.
///
/// # Safety
/// As duo_transflower_session_new; `memory` NULL or `len` writable bytes
/// that stay valid, unmoved and otherwise untouched until
/// `duo_session_free`.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn duo_transflower_session_new_in(
    model: *const DuoModel,
    config: *const DuoTransflowerConfig,
    seed_motion: *const f32,
    n_floats: usize,
    labels: *const u32,
    n_labels: usize,
    memory: *mut u8,
    len: usize,
    out_session: *mut *mut DuoSession,
) -> DuoResult {
    guard("duo_transflower_session_new_in", || {
        // SAFETY: the caller's pointers as documented above (contract).
        unsafe {
            make_session(
                "duo_transflower_session_new_in",
                model,
                config,
                (seed_motion, n_floats),
                (labels, n_labels),
                Some((memory, len)),
                out_session,
            )
        }
    })
}

/// Rows for input `index` other than the audio (models with several
/// sliding inputs; the audio also takes duo_session_push_music).
///
/// # Safety
/// `session` NULL or live; `rows` NULL or `n_floats` readable floats.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_push_input(
    session: *mut DuoSession,
    index: u32,
    rows: *const f32,
    n_floats: usize,
) -> DuoResult {
    guard("duo_transflower_push_input", || {
        let s = session_of(session_mut(session)?, "duo_transflower_push_input")?;
        // SAFETY: NULL or `n_floats` readable floats (contract).
        let x: &[f32] = unsafe { buffer(rows, n_floats, "rows") }?;
        push_rows(s, index as usize, x, "n_floats")?;
        Ok(DuoResult::Ok)
    })
}

/// Pulls the next frame (channels floats): runs its step if the audio is
/// there. `noise`: the step's base sample (noise_floats), or NULL for the
/// session's seeded RNG.
fn pull(
    s: &mut Session<'static>,
    noise: Option<&[f32]>,
    out: &mut [f32],
) -> Result<Option<u64>, Failure> {
    let c = s.config_model().channels();
    if out.len() != c {
        return Err(Failure::invalid(format!(
            "n_floats is {}; a frame of this model has {c} floats (duo_transflower_info.channels)",
            out.len()
        )));
    }
    if s.pending() == 0 {
        if s.batched() {
            // Its frames are made by duo_step_batch_step only.
            return Ok(None);
        }
        let made = match noise {
            Some(z) => s.step_with(z),
            None => s.step(),
        }
        .map_err(|e| fail(e, s))?;
        if !made {
            return Ok(None);
        }
    }
    let index = (s.steps() - s.pending()) as u64;
    s.pull(out);
    Ok(Some(index))
}

fn finish_pull(r: Option<u64>, out_index: *mut u64) -> DuoResult {
    match r {
        None => DuoResult::NotReady,
        Some(i) => {
            if !out_index.is_null() {
                // SAFETY: non-NULL and writable (contract).
                unsafe { *out_index = i };
            }
            DuoResult::Ok
        }
    }
}

/// The next frame with the session's seeded base samples: DUO_OK (`out`
/// and `*out_index` written; out_index may be NULL) or DUO_NOT_READY (its
/// audio is not there yet: nothing written). The costly call.
///
/// # Safety
/// `session` NULL or live; `out` NULL or `n_floats` writable floats;
/// `out_index` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_pull_frame(
    session: *mut DuoSession,
    out: *mut f32,
    n_floats: usize,
    out_index: *mut u64,
) -> DuoResult {
    guard("duo_transflower_pull_frame", || {
        let s = session_of(session_mut(session)?, "duo_transflower_pull_frame")?;
        // SAFETY: NULL or `n_floats` writable floats (contract).
        let dst = unsafe { out_floats(out, n_floats) }?;
        Ok(finish_pull(pull(s, None, dst)?, out_index))
    })
}

/// As duo_transflower_pull_frame with the caller's base sample `noise`
/// (noise_floats = channels x output_length, channel-major) for the step
/// it runs (unused when a frame was already made).
///
/// # Safety
/// As duo_transflower_pull_frame; `noise` NULL or `n_noise` readable floats.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_pull_frame_with_noise(
    session: *mut DuoSession,
    noise: *const f32,
    n_noise: usize,
    out: *mut f32,
    n_floats: usize,
    out_index: *mut u64,
) -> DuoResult {
    guard("duo_transflower_pull_frame_with_noise", || {
        let s = session_of(
            session_mut(session)?,
            "duo_transflower_pull_frame_with_noise",
        )?;
        // SAFETY: NULL or `n_noise` readable floats (contract).
        let z: &[f32] = unsafe { buffer(noise, n_noise, "noise") }?;
        // SAFETY: NULL or `n_floats` writable floats (contract).
        let dst = unsafe { out_floats(out, n_floats) }?;
        Ok(finish_pull(pull(s, Some(z), dst)?, out_index))
    })
}

/// `n` writable floats at `out` (the buffer rule: NULL with 0 is empty).
///
/// # Safety
/// `out` NULL or `n` writable floats.
unsafe fn out_floats<'x>(out: *mut f32, n: usize) -> Result<&'x mut [f32], Failure> {
    // SAFETY: per the function contract.
    let bytes = unsafe { buffer_mut(out.cast::<u8>(), n.saturating_mul(4), "out") }?;
    if n == 0 {
        return Ok(&mut []);
    }
    // SAFETY: `bytes` is `n * 4` writable bytes at `out`, given as floats.
    Ok(unsafe { std::slice::from_raw_parts_mut(bytes.as_mut_ptr().cast::<f32>(), n) })
}

/// Back to the start: the seed motion, no audio, no frames, the RNG
/// reseeded with `rng_seed`.
///
/// # Safety
/// `session` NULL or live.
#[no_mangle]
pub unsafe extern "C" fn duo_transflower_session_reset(
    session: *mut DuoSession,
    rng_seed: u64,
) -> DuoResult {
    guard("duo_transflower_session_reset", || {
        let s = session_of(session_mut(session)?, "duo_transflower_session_reset")?;
        s.reset(Some(rng_seed));
        Ok(DuoResult::Ok)
    })
}
