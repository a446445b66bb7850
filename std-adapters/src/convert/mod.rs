//! The converter from the ORIGINAL training artifacts to `.duo`
//! (`duolando convert`; rules in docs/FORMAT.md §6).
//!
//! Inputs: the follower-GPT YAML (original key structure, any sizes) and
//! three safetensors files holding the original `state_dict`s (GPT2nt,
//! SepVQVAEXM, translation VQVAE; made from the `.pt` checkpoints by
//! `tools/pt_to_safetensors.py`). The schema (`duolando_core::duolando::schema`)
//! drives everything: each required `.duo` tensor is pulled from its
//! component's file by its original name, shape-checked and upcast to f32;
//! leftovers must be known-unused (`skipped`), else the conversion fails.
//!
//! - `yaml`: duplicate-key tolerant YAML (as PyYAML reads the originals).
//! - `config`: YAML -> `ModelConfig`.
//! - `source`: safetensors, `module.` prefix, dtype upcast.
//! - `skipped`: tensors that are not stored, and the mask checks.
//! - `error`: `ConvertError`.
//!
//! The other families: `bailando` (YAML + GPT + VQ-VAE safetensors) and
//! `transflower` (the authors' `hparams.yaml` + one state dict).

pub mod bailando;
pub mod config;
pub mod error;
pub mod skipped;
pub mod source;
pub mod transflower;
pub mod yaml;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use duolando_core::duolando::config::ModelConfig;
use duolando_core::duolando::schema::for_each_tensor;
use duolando_core::nn::names::{Role, SchemaError, TensorSpec};
use duolando_core::tensor::block_row;

pub use config::{is_bailando, load_config, parse_bailando_config, parse_config};
pub use error::ConvertError;
use skipped::{check_mask, classify, Component, Skip};
use source::Source;

use crate::duo_writer::{write_duo, StoreAs, Tensor};

/// The three source checkpoints, as bytes with the paths they came from.
pub struct Sources<'a> {
    pub gpt: (&'a Path, &'a [u8]),
    pub vqvae: (&'a Path, &'a [u8]),
    pub transl: (&'a Path, &'a [u8]),
}

/// What a conversion did (printed by the CLI).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Report {
    /// Tensors written to the `.duo`.
    pub written: usize,
    /// Source tensors skipped as unused (masks included).
    pub skipped: usize,
    /// Attention masks whose values were checked.
    pub masks_checked: usize,
    /// Bytes of the `.duo`.
    pub bytes: usize,
}

impl From<SchemaError> for ConvertError {
    fn from(e: SchemaError) -> ConvertError {
        ConvertError::ConfigKey {
            path: PathBuf::from("<schema>"),
            key: String::from("(tensor name)"),
            problem: format!("{e:?}"),
        }
    }
}

/// How a tensor is stored when the model is converted for weight type
/// `requested` (docs/FORMAT.md §6, "Weight types"), by its schema role:
/// - vectors (biases, LayerNorm) and `pos_emb` stay F32: the engine adds
///   them to activations as they are (<1% of the bytes);
/// - `F16`: every other tensor F16;
/// - `Q8Block32`: the tensors whose rows are dotted with activations or read
///   whole as embeddings (Linear weights, GPT heads, token embeddings, and
///   the VQ decoders' Conv1d weights, a row = one output channel's `in * k`
///   values, and their ConvTranspose1d weights in GEMM order
///   ([`to_stored_order`]: a row = the `in` values feeding one output
///   channel at one kernel tap), when a row is a multiple of 32 values; the
///   rest F16: the VQ encoders and codebooks (they pick the leader's
///   tokens, the input of everything: int8 encoders flipped 1.3% of the
///   tiny_long fixture's leader tokens, 4-bit ones 16%) and rows of other
///   lengths;
///   Of these, the matrices of the int8 GEMM (Linear weights, heads, decoder
///   convs and conv-transposes) are stored as `Q8Block32x8` (the same
///   values, rows interleaved in groups of 8 for the GEMM), the embeddings
///   as `Q8Block32`; requesting `Q8Block32x8` means the same;
/// - `Q4Block32`: the same tensors as `Q8Block32` in 4 bits (the GEMM
///   matrices as `Q4Block32x8`, the embeddings as `Q4Block32`), the rest as
///   there.
pub fn storage_for(requested: StoreAs, spec: &TensorSpec) -> StoreAs {
    if requested == StoreAs::F32 || matches!(spec.role, Role::Vector | Role::PosEmb) {
        return StoreAs::F32;
    }
    // A ConvTranspose1d weight is blocked along `in`, in GEMM order.
    let row = spec
        .gemm_dims()
        .map_or_else(|| block_row(spec.dims()), |[_, c_in]| c_in as usize);
    let blockable = matches!(
        spec.role,
        Role::Linear | Role::Conv | Role::ConvTranspose | Role::Embedding
    ) && row % 32 == 0
        && row > 0;
    match requested {
        StoreAs::Q8Block32 | StoreAs::Q8Block32x8 if blockable => {
            if spec.role == Role::Embedding {
                StoreAs::Q8Block32
            } else {
                StoreAs::Q8Block32x8
            }
        }
        StoreAs::Q4Block32 | StoreAs::Q4Block32x8 if blockable => {
            if spec.role == Role::Embedding {
                StoreAs::Q4Block32
            } else {
                StoreAs::Q4Block32x8
            }
        }
        _ => StoreAs::F16,
    }
}

/// Whether a tensor stored as `stored` is written in GEMM order: a
/// ConvTranspose1d weight in a blocked type (its blocks run along `in`).
fn gemm_order(spec: &TensorSpec, stored: StoreAs) -> bool {
    spec.gemm_dims().is_some() && !matches!(stored, StoreAs::F32 | StoreAs::F16)
}

/// The shape a tensor is written with when stored as `stored`: the
/// schema's, or GEMM order ([`to_stored_order`]).
pub fn stored_dims(spec: &TensorSpec, stored: StoreAs) -> Vec<u32> {
    match spec.gemm_dims() {
        Some(gemm) if gemm_order(spec, stored) => gemm.to_vec(),
        _ => spec.dims().to_vec(),
    }
}

/// The shape and values a tensor is written with when stored as `stored`
/// (`values` in PyTorch order, as the schema lists the tensor): a
/// ConvTranspose1d weight `(in, out, k)` stored blocked becomes the GEMM
/// order `(out * k, in)`, row `o * k + j` = `W[:, o, j]` (docs/FORMAT.md
/// §6); everything else as it is.
pub fn to_stored_order(
    spec: &TensorSpec,
    stored: StoreAs,
    values: Vec<f32>,
) -> (Vec<u32>, Vec<f32>) {
    match (spec.dims(), spec.gemm_dims()) {
        (&[c_in, c_out, k], Some(gemm)) if gemm_order(spec, stored) => {
            let (c_in, zk) = (c_in as usize, c_out as usize * k as usize);
            let mut t = vec![0.0f32; values.len()];
            for (i, row) in values.chunks_exact(zk).enumerate() {
                for (r, &v) in row.iter().enumerate() {
                    t[r * c_in + i] = v;
                }
            }
            (gemm.to_vec(), t)
        }
        _ => (spec.dims().to_vec(), values),
    }
}

/// Pulls every schema tensor of `cfg` out of the sources (checked, upcast
/// to f32, stored as [`storage_for`]`(store_as, ..)`) and verifies nothing unknown is left over.
pub fn collect_tensors(
    cfg: &ModelConfig,
    sources: &Sources<'_>,
    store_as: StoreAs,
) -> Result<(Vec<Tensor>, Report), ConvertError> {
    let parsed = [
        Source::parse(sources.gpt.0, sources.gpt.1)?,
        Source::parse(sources.vqvae.0, sources.vqvae.1)?,
        Source::parse(sources.transl.0, sources.transl.1)?,
    ];
    let mut used: [BTreeSet<String>; 3] = Default::default();
    let mut tensors = Vec::new();
    let prefixes = Component::ALL.map(|c| c.prefix());
    for_each_tensor::<ConvertError>(cfg, &mut |spec: &TensorSpec| {
        tensors.push(take_tensor(spec, &parsed, &prefixes, &mut used, store_as)?);
        Ok(())
    })?;
    let mut report = Report {
        written: tensors.len(),
        ..Report::default()
    };
    for (c, component) in Component::ALL.iter().enumerate() {
        let src = &parsed[c];
        let mut extra = Vec::new();
        for name in src.tensors.keys().filter(|n| !used[c].contains(*n)) {
            match classify(*component, name) {
                Some(Skip::Mask(kind)) => {
                    check_mask(src, name, kind, cfg)?;
                    report.masks_checked += 1;
                    report.skipped += 1;
                }
                Some(Skip::Unused) => report.skipped += 1,
                None => extra.push(name.clone()),
            }
        }
        if !extra.is_empty() {
            return Err(ConvertError::Extra {
                path: src.path.clone(),
                tensors: extra,
            });
        }
    }
    Ok((tensors, report))
}

/// The schema tensor `spec` out of the source whose component prefix
/// (`prefixes[i]` for `sources[i]`) its name carries: checked against the
/// schema shape, upcast to f32, refused if not finite, stored as
/// [`storage_for`]`(store_as, spec)`; its source name is added to `used[i]`.
pub fn take_tensor(
    spec: &TensorSpec,
    sources: &[Source<'_>],
    prefixes: &[&str],
    used: &mut [BTreeSet<String>],
    store_as: StoreAs,
) -> Result<Tensor, ConvertError> {
    let duo_name = spec.name.as_str();
    let (c, rest) = prefixes
        .iter()
        .enumerate()
        .find_map(|(i, p)| duo_name.strip_prefix(p).map(|r| (i, r)))
        .ok_or_else(|| ConvertError::ConfigKey {
            path: PathBuf::from("<schema>"),
            key: duo_name.to_string(),
            problem: format!("schema name without one of the prefixes {prefixes:?}"),
        })?;
    let src = &sources[c];
    let values = src.f32_values(rest, duo_name, spec.dims())?;
    if let Some((index, &value)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(ConvertError::NonFinite {
            path: src.path.clone(),
            tensor: rest.to_string(),
            index,
            value,
        });
    }
    used[c].insert(rest.to_string());
    let stored = storage_for(store_as, spec);
    let (shape, values) = to_stored_order(spec, stored, values);
    Ok(Tensor {
        name: duo_name.to_string(),
        shape,
        values,
        store_as: stored,
    })
}

/// The whole conversion in memory: YAML text (labelled by `config.0`) +
/// three safetensors -> `.duo` bytes.
pub fn convert_bytes(
    config: (&Path, &str),
    sources: &Sources<'_>,
    store_as: StoreAs,
) -> Result<(Vec<u8>, Report), ConvertError> {
    let cfg = parse_config(config.0, config.1)?;
    convert_with_config(&cfg, sources, store_as, Path::new("<memory>"))
}

/// [`convert_bytes`] with an already mapped config; `label` names the output in errors.
pub fn convert_with_config(
    cfg: &ModelConfig,
    sources: &Sources<'_>,
    store_as: StoreAs,
    label: &Path,
) -> Result<(Vec<u8>, Report), ConvertError> {
    let (tensors, mut report) = collect_tensors(cfg, sources, store_as)?;
    let bytes = write_duo(cfg, &tensors).map_err(|source| ConvertError::Write {
        path: label.into(),
        source,
    })?;
    report.bytes = bytes.len();
    Ok((bytes, report))
}

/// Converts files on disk and writes `out` (via a temporary file, renamed
/// into place).
pub fn convert_files(
    config: &Path,
    gpt: &Path,
    vqvae: &Path,
    transl: &Path,
    store_as: StoreAs,
    out: &Path,
) -> Result<Report, ConvertError> {
    let cfg = load_config(config)?;
    let (m_gpt, m_vq, m_tr) = (map(gpt)?, map(vqvae)?, map(transl)?);
    let sources = Sources {
        gpt: (gpt, &m_gpt),
        vqvae: (vqvae, &m_vq),
        transl: (transl, &m_tr),
    };
    let (bytes, report) = convert_with_config(&cfg, &sources, store_as, out)?;
    write_atomically(out, &bytes)?;
    Ok(report)
}

/// Writes `bytes` to `out` via a temporary file renamed into place (a
/// failed write leaves no half-written model).
pub fn write_atomically(out: &Path, bytes: &[u8]) -> Result<(), ConvertError> {
    let io = |source| ConvertError::Io {
        path: out.into(),
        source,
    };
    let mut tmp = out.as_os_str().to_owned();
    tmp.push(".partial");
    std::fs::write(&tmp, bytes).map_err(io)?;
    std::fs::rename(&tmp, out).map_err(io)
}

/// Read-only map of a source file (an empty file maps to nothing).
fn map(path: &Path) -> Result<Mapped, ConvertError> {
    let io = |source| ConvertError::Io {
        path: path.into(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    if file.metadata().map_err(io)?.len() == 0 {
        return Ok(Mapped::Empty);
    }
    // SAFETY: read-only map of an input file we do not modify; the caller
    // must not modify it during conversion (the usual mmap contract).
    #[allow(unsafe_code)]
    let m = unsafe { memmap2::Mmap::map(&file) }.map_err(io)?;
    Ok(Mapped::Map(m))
}

enum Mapped {
    Empty,
    Map(memmap2::Mmap),
}

impl std::ops::Deref for Mapped {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            Mapped::Empty => &[],
            Mapped::Map(m) => m,
        }
    }
}
