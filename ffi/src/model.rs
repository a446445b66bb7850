//! `duo_model`: an immutable, validated, bound model, shared by sessions.
//!
//! Ownership: the handle is reference counted. `duo_model_free` drops the
//! caller's reference; every session holds one more, so the weights stay
//! valid until the last session made from the model is freed too, whatever
//! the order. Bytes passed to `duo_model_open_bytes` are borrowed (no copy)
//! and must stay valid and unmodified until then.
//!
//! Thread rule: a `duo_model` is immutable; any number of threads may use
//! it at the same time (open sessions, read info). `duo_model_free` must
//! not race with other calls on the same handle.

use std::ffi::{c_char, CStr};
use std::sync::Arc;

use duolando_core::bailando::model::Model as SoloModel;
use duolando_core::family::{Family, FamilyConfig};
use duolando_core::format::DuoFile;
use duolando_core::Model;
use duolando_runtime::model_file::{explain, AlignedBytes, ModelFile, ModelFileError};

use crate::result::{guard, DuoResult, Failure};

/// Where the model bytes live. Each variant keeps its bytes at a fixed
/// address for the life of the value (heap, mmap, or caller memory).
enum Storage {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    /// Caller memory (`duo_model_open_bytes`): not owned.
    Borrowed,
    /// `duo_model_open_file` (mmap or aligned copy) or `duo_model_open_copy`.
    File(ModelFile),
}

/// A bound model of any family.
pub enum AnyModel {
    /// A follower dancing with a leader to music.
    Duolando(Model<'static>),
    /// A solo dancer to music.
    Bailando(SoloModel<'static>),
    /// A probabilistic solo dancer (motion features from audio features).
    Transflower(duolando_core::transflower::model::Model<'static>),
}

/// What a `duo_model *` points to (an `Arc<ModelInner>` turned into a raw
/// pointer by [`Arc::into_raw`]).
pub struct ModelInner {
    /// Bound weights viewing `storage` (or the caller's bytes). Declared
    /// first: dropped before the storage it borrows from.
    model: AnyModel,
    storage: Storage,
}

// SAFETY: `Model<'static>` is Sync (immutable views); `Storage::File` is
// Send + Sync; `Borrowed` holds nothing. The caller's borrowed bytes are
// only read.
unsafe impl Send for ModelInner {}
// SAFETY: as for `Send` above: nothing in it is mutated after construction.
unsafe impl Sync for ModelInner {}

impl ModelInner {
    pub fn any(&self) -> &AnyModel {
        &self.model
    }
    /// The Duolando model, or a refusal naming this model's family for an
    /// entry point only Duolando models take (`what`).
    pub fn duolando(&self, what: &str) -> Result<&Model<'static>, Failure> {
        match &self.model {
            AnyModel::Duolando(m) => Ok(m),
            AnyModel::Bailando(_) => Err(Failure::invalid(format!(
                "{what} needs a Duolando model (a follower dancing with a leader); this is a Bailando model (a solo dancer to music): docs/C_API.md \"Solo models\""
            ))),
            AnyModel::Transflower(_) => Err(transflower_refusal(what)),
        }
    }
    pub fn family(&self) -> Family {
        match &self.model {
            AnyModel::Duolando(_) => Family::Duolando,
            AnyModel::Bailando(_) => Family::Bailando,
            AnyModel::Transflower(_) => Family::Transflower,
        }
    }
    pub fn is_mapped(&self) -> bool {
        matches!(&self.storage, Storage::File(f) if f.is_mapped())
    }
}

/// `what` is for Duolando / Bailando; Transflower has its own entry points.
pub(crate) fn transflower_refusal(what: &str) -> Failure {
    Failure::invalid(format!(
        "{what}: this is a Transflower model (motion features from audio features): its sessions are made and used with the duo_transflower_* functions (duo_session_push_music, duo_session_free too): docs/C_API.md \"Transflower\""
    ))
}

/// Opaque `duo_model` (never constructed; a pointer to [`ModelInner`]).
pub type DuoModel = ModelInner;

/// Binds a parsed file whose bytes outlive the returned model (the caller
/// guarantees it; see the Storage variants). The first model of the
/// process selects the SIMD kernels this CPU supports
/// (`duolando::simd::init`, as the CLI does; bit-identical across thread
/// counts, not across ISAs); a build without this would run the scalar
/// kernels its compile-time target allows.
fn bind(duo: &DuoFile<'static>, origin: &str) -> Result<AnyModel, Failure> {
    static KERNELS: std::sync::Once = std::sync::Once::new();
    KERNELS.call_once(|| {
        duolando_runtime::simd::init();
    });
    let bad = |e: duolando_core::nn::bind::BindError| {
        Failure::new(
            DuoResult::BadModel,
            format!(
                "{origin}: invalid .duo model: {}",
                duolando_runtime::engine_errors::describe(&duolando_core::Error::from(e))
            ),
        )
    };
    match duo.config() {
        FamilyConfig::Duolando(_) => Model::from_duo(duo).map(AnyModel::Duolando).map_err(bad),
        FamilyConfig::Bailando(_) => SoloModel::from_duo(duo)
            .map(AnyModel::Bailando)
            .map_err(bad),
        FamilyConfig::Transflower(_) => duolando_core::transflower::model::Model::from_duo(duo)
            .map(AnyModel::Transflower)
            .map_err(|e| {
                Failure::new(
                    DuoResult::BadModel,
                    format!(
                        "{origin}: invalid .duo model: {}",
                        duolando_runtime::engine_errors::describe_transflower_model(&e)
                    ),
                )
            }),
    }
}

fn publish(inner: ModelInner, out: *mut *mut DuoModel) -> Result<DuoResult, Failure> {
    let ptr = Arc::into_raw(Arc::new(inner)) as *mut DuoModel;
    // SAFETY: `out` was checked non-NULL by the caller of publish.
    unsafe { *out = ptr };
    Ok(DuoResult::Ok)
}

/// Extends the lifetime of bytes whose owner keeps them alive and fixed for
/// as long as the model lives (caller memory, mmap, heap buffer).
///
/// # Safety
/// The bytes must stay valid, unmoved and unmodified while any `Model`
/// bound from them exists.
unsafe fn forever(bytes: &[u8]) -> &'static [u8] {
    // SAFETY: per the function contract.
    unsafe { std::slice::from_raw_parts(bytes.as_ptr(), bytes.len()) }
}

fn from_model_file(
    mf: ModelFile,
    origin: &str,
    out: *mut *mut DuoModel,
) -> Result<DuoResult, Failure> {
    // SAFETY: the bytes live in `mf` (mmap or heap: fixed addresses), which
    // is moved into the same ModelInner as the model and dropped after it.
    let bytes = unsafe { forever(mf.bytes()) };
    // `mf` passed the full `DuoFile::parse` (weights included) when it was
    // made; its bytes are immutable since: the table alone is read again.
    let duo = DuoFile::parse_without_weight_scan(bytes).map_err(|e| {
        Failure::new(
            DuoResult::BadModel,
            format!("{origin}: invalid .duo model: {}", explain(bytes, &e)),
        )
    })?;
    let model = bind(&duo, origin)?;
    publish(
        ModelInner {
            model,
            storage: Storage::File(mf),
        },
        out,
    )
}

fn file_failure(e: ModelFileError) -> Failure {
    let code = match &e {
        ModelFileError::Io { .. } => DuoResult::Io,
        ModelFileError::Format { .. } => DuoResult::BadModel,
    };
    Failure::new(code, e.to_string())
}

/// Opens a model from caller memory without copying.
///
/// # Safety
/// `bytes` must be NULL or point to `len` readable bytes that stay valid
/// and unmodified until the model and all its sessions are freed; `out`
/// must be NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_model_open_bytes(
    bytes: *const u8,
    len: usize,
    out_model: *mut *mut DuoModel,
) -> DuoResult {
    guard("duo_model_open_bytes", || {
        if out_model.is_null() {
            return Err(Failure::null("out_model"));
        }
        // SAFETY: caller contract.
        let b = unsafe { crate::handle::buffer(bytes, len, "bytes") }?;
        // An empty buffer, NULL or not, at any address, is one answer:
        // too short (parse would check the address of an empty slice).
        #[repr(C, align(64))]
        struct Empty([u8; 0]);
        static EMPTY: Empty = Empty([]);
        let b = if b.is_empty() { &EMPTY.0[..] } else { b };
        let addr = b.as_ptr() as usize;
        if !b.is_empty() && addr & 63 != 0 {
            return Err(Failure::invalid(format!(
                "model bytes at address {addr:#x} are not 64-byte aligned (address % 64 = {}); \
                 allocate them 64-byte aligned, or use duo_model_open_copy (copies) or duo_model_open_file (mmap)",
                addr % 64
            )));
        }
        // SAFETY: the caller keeps the bytes valid until the model and its
        // sessions are freed (the documented rule).
        let bytes = unsafe { forever(b) };
        let duo = DuoFile::parse(bytes).map_err(|e| {
            Failure::new(
                DuoResult::BadModel,
                format!("<memory>: invalid .duo model: {}", explain(bytes, &e)),
            )
        })?;
        let model = bind(&duo, "<memory>")?;
        publish(
            ModelInner {
                model,
                storage: Storage::Borrowed,
            },
            out_model,
        )
    })
}

/// Opens a model from caller memory by copying it into a 64-byte aligned
/// library buffer; the caller may free `bytes` as soon as this returns.
///
/// # Safety
/// `bytes` must be NULL or point to `len` readable bytes; `out_model` must
/// be NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_model_open_copy(
    bytes: *const u8,
    len: usize,
    out_model: *mut *mut DuoModel,
) -> DuoResult {
    guard("duo_model_open_copy", || {
        if out_model.is_null() {
            return Err(Failure::null("out_model"));
        }
        // SAFETY: caller contract.
        let b = unsafe { crate::handle::buffer(bytes, len, "bytes") }?;
        let mf = ModelFile::from_aligned(AlignedBytes::copy_from(b), "<memory>")
            .map_err(file_failure)?;
        from_model_file(mf, "<memory>", out_model)
    })
}

/// Opens a model file (memory-mapped read-only; copied if the map is not
/// 64-byte aligned). The file must not be modified while the model lives.
///
/// # Safety
/// `path` must be NULL or a NUL-terminated string (UTF-8); `out_model`
/// must be NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_model_open_file(
    path: *const c_char,
    out_model: *mut *mut DuoModel,
) -> DuoResult {
    guard("duo_model_open_file", || {
        if out_model.is_null() {
            return Err(Failure::null("out_model"));
        }
        if path.is_null() {
            return Err(Failure::null("path"));
        }
        // SAFETY: caller contract: NUL-terminated.
        let p = unsafe { CStr::from_ptr(path) }
            .to_str()
            .map_err(|_| Failure::invalid("path is not valid UTF-8"))?;
        let mf = ModelFile::open(p).map_err(file_failure)?;
        from_model_file(mf, p, out_model)
    })
}

/// Releases the caller's reference. NULL is ignored.
///
/// # Safety
/// `model` must be NULL or a handle from `duo_model_open_*` not yet freed.
#[no_mangle]
pub unsafe extern "C" fn duo_model_free(model: *mut DuoModel) {
    let _ = guard("duo_model_free", || {
        if !model.is_null() {
            // SAFETY: a pointer from Arc::into_raw, released once (contract).
            drop(unsafe { Arc::from_raw(model as *const ModelInner) });
        }
        Ok(DuoResult::Ok)
    });
}

/// A new counted reference to the model behind a handle.
///
/// # Safety
/// `model` must be a live handle from `duo_model_open_*`.
pub unsafe fn share(model: *const DuoModel) -> Arc<ModelInner> {
    // SAFETY: the handle owns one count, alive for this call (contract);
    // we add one and return it.
    unsafe {
        Arc::increment_strong_count(model);
        Arc::from_raw(model)
    }
}

/// `duo_model_info`: sizes an engine needs.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DuoModelInfo {
    /// Joints per pose (55).
    pub joints: u32,
    /// Floats per music feature frame (`n_music`, 54).
    pub music_features: u32,
    /// Motion (and music) frames per second (30).
    pub fps: u32,
    /// Motion frames per token (4).
    pub frames_per_token: u32,
    /// GPT window length in tokens (`block_size`, 30).
    pub block_size: u32,
    /// Largest leader/music look-ahead the model was trained with, tokens (`look_forward`, 29).
    pub look_forward: u32,
    /// 1 when the weights are memory-mapped from a file, else 0.
    pub mapped: u32,
    /// The model family (`DUO_FAMILY_*`: 0 Duolando, 1 Bailando; the
    /// field was a reserved 0 before families).
    pub family: u32,
}

/// Fills `*out_info`.
///
/// # Safety
/// `model` must be NULL or a live handle; `out_info` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn duo_model_get_info(
    model: *const DuoModel,
    out_info: *mut DuoModelInfo,
) -> DuoResult {
    guard("duo_model_get_info", || {
        // SAFETY: caller contract.
        let m = unsafe { model.as_ref() }.ok_or_else(|| Failure::null("model"))?;
        if out_info.is_null() {
            return Err(Failure::null("out_info"));
        }
        let info = match m.any() {
            AnyModel::Duolando(model) => {
                let cfg = model.config();
                DuoModelInfo {
                    joints: duolando_core::duolando::config::N_JOINTS as u32,
                    music_features: cfg.gpt.music.n_in,
                    fps: 30,
                    frames_per_token: cfg.parts[0].hop().unwrap_or(0),
                    block_size: cfg.gpt.block_size,
                    look_forward: cfg.gpt.look_forward,
                    mapped: m.is_mapped() as u32,
                    family: Family::Duolando as u32,
                }
            }
            AnyModel::Bailando(model) => {
                let cfg = &model.cfg;
                DuoModelInfo {
                    joints: duolando_core::bailando::config::N_JOINTS as u32,
                    music_features: cfg.gpt.n_music,
                    fps: duolando_core::bailando::config::FPS,
                    frames_per_token: cfg.hop() as u32,
                    block_size: cfg.gpt.block_size,
                    look_forward: 0,
                    mapped: m.is_mapped() as u32,
                    family: Family::Bailando as u32,
                }
            }
            AnyModel::Transflower(model) => {
                let cfg = &model.cfg;
                let last = &cfg.inputs()[cfg.inputs().len() - 1];
                DuoModelInfo {
                    joints: 0,
                    music_features: if last.is_discrete() { 0 } else { last.dim },
                    fps: duolando_core::transflower::config::FPS,
                    frames_per_token: 1,
                    block_size: cfg.max_window() as u32,
                    look_forward: duolando_core::transflower::session::lookahead_rows(cfg).max(0)
                        as u32,
                    mapped: m.is_mapped() as u32,
                    family: Family::Transflower as u32,
                }
            }
        };
        // SAFETY: checked non-NULL.
        unsafe { *out_info = info };
        Ok(DuoResult::Ok)
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::ptr;

    pub fn fixture_path() -> String {
        format!(
            "{}/../tests/fixtures/tiny/model.duo",
            env!("CARGO_MANIFEST_DIR")
        )
    }

    pub fn open_fixture() -> *mut DuoModel {
        // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
        let p = std::ffi::CString::new(fixture_path()).unwrap();
        let mut m = ptr::null_mut();
        assert_eq!(
            unsafe { duo_model_open_file(p.as_ptr(), &mut m) },
            DuoResult::Ok
        );
        assert!(!m.is_null());
        m
    }

    fn last() -> String {
        // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
        let mut buf = vec![0 as c_char; 1024];
        unsafe { crate::result::duo_last_error_message(buf.as_mut_ptr(), buf.len()) };
        unsafe { CStr::from_ptr(buf.as_ptr()) }
            .to_str()
            .unwrap()
            .to_string()
    }

    #[test]
    fn open_all_ways() {
        // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
        let m = open_fixture();
        let mut info = DuoModelInfo::default();
        assert_eq!(unsafe { duo_model_get_info(m, &mut info) }, DuoResult::Ok);
        assert_eq!(
            (info.joints, info.fps, info.frames_per_token, info.mapped),
            (55, 30, 4, 1)
        );
        unsafe { duo_model_free(m) };

        let bytes = std::fs::read(fixture_path()).unwrap();
        let mut c = ptr::null_mut();
        assert_eq!(
            unsafe { duo_model_open_copy(bytes.as_ptr(), bytes.len(), &mut c) },
            DuoResult::Ok
        );
        let mut info2 = DuoModelInfo::default();
        assert_eq!(unsafe { duo_model_get_info(c, &mut info2) }, DuoResult::Ok);
        assert_eq!(info2, DuoModelInfo { mapped: 0, ..info });
        unsafe { duo_model_free(c) };

        let aligned = AlignedBytes::copy_from(&bytes);
        let mut b = ptr::null_mut();
        assert_eq!(
            unsafe { duo_model_open_bytes(aligned.as_bytes().as_ptr(), aligned.len(), &mut b) },
            DuoResult::Ok
        );
        unsafe { duo_model_free(b) };
    }

    #[test]
    fn rejections() {
        // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
        let bytes = std::fs::read(fixture_path()).unwrap();
        let aligned = AlignedBytes::copy_from(&bytes);
        let mut dummy = 0u8;
        let sentinel = (&mut dummy as *mut u8).cast::<DuoModel>();
        let mut m = sentinel;
        // Misaligned caller bytes: refused, output untouched.
        let mis = AlignedBytes::copy_from(&[&[0u8][..], &bytes].concat());
        let r = unsafe { duo_model_open_bytes(mis.as_bytes()[1..].as_ptr(), bytes.len(), &mut m) };
        assert_eq!(r, DuoResult::InvalidArgument);
        assert!(last().contains("not 64-byte aligned"), "{}", last());
        assert_eq!(m, sentinel);
        // Truncated.
        let r =
            unsafe { duo_model_open_bytes(aligned.as_bytes().as_ptr(), bytes.len() / 2, &mut m) };
        assert_eq!(r, DuoResult::BadModel);
        assert_eq!(m, sentinel);
        let r = unsafe { duo_model_open_copy(bytes.as_ptr(), 100, &mut m) };
        assert_eq!(r, DuoResult::BadModel);
        assert!(
            last().starts_with("duo_model_open_copy: <memory>: invalid .duo model"),
            "{}",
            last()
        );
        // Empty and NULL.
        assert_eq!(
            unsafe { duo_model_open_bytes(ptr::null(), 0, &mut m) },
            DuoResult::BadModel
        );
        assert_eq!(
            unsafe { duo_model_open_bytes(ptr::null(), 10, &mut m) },
            DuoResult::NullParameter
        );
        assert_eq!(
            unsafe { duo_model_open_bytes(aligned.as_bytes().as_ptr(), 10, ptr::null_mut()) },
            DuoResult::NullParameter
        );
        assert_eq!(
            unsafe { duo_model_open_file(ptr::null(), &mut m) },
            DuoResult::NullParameter
        );
        let missing = c"/nonexistent/model.duo";
        assert_eq!(
            unsafe { duo_model_open_file(missing.as_ptr(), &mut m) },
            DuoResult::Io
        );
        assert!(last().contains("/nonexistent/model.duo"), "{}", last());
        assert_eq!(m, sentinel);
        assert_eq!(
            unsafe { duo_model_get_info(ptr::null(), &mut DuoModelInfo::default()) },
            DuoResult::NullParameter
        );
        unsafe { duo_model_free(ptr::null_mut()) };
    }
}
