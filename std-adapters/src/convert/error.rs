//! Everything that can go wrong converting the original checkpoints; every
//! message names the file, the key or tensor, and expected vs found.

use std::path::PathBuf;

use duolando_core::limits::ConfigError;

use crate::duo_writer::WriteError;

#[derive(Debug, thiserror::Error)]
pub enum ConvertError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },

    /// A Transflower `hparams.yaml` whose options the engine refuses
    /// (`TransflowerConfig::from_hparams`): the message names the option.
    #[error("{}: the Transflower config is not supported: {detail}", path.display())]
    TransflowerConfig { path: PathBuf, detail: String },

    #[error("{}: not valid YAML: {source}", path.display())]
    Yaml {
        path: PathBuf,
        source: serde_yaml::Error,
    },

    /// A YAML key is missing, has the wrong type, or holds a value the
    /// `.duo` format cannot represent.
    #[error("{}: `{key}`: {problem}", path.display())]
    ConfigKey {
        path: PathBuf,
        key: String,
        problem: String,
    },

    /// The mapped config fails `ModelConfig::validate`.
    #[error("{}: the model config is not supported: {detail}", path.display())]
    Config {
        path: PathBuf,
        error: ConfigError,
        detail: String,
    },

    #[error("{}: not a readable safetensors file: {detail}", path.display())]
    Safetensors { path: PathBuf, detail: String },

    #[error(
        "{}: some tensor names carry the DataParallel `module.` prefix and some do not \
         (e.g. `{with_prefix}` and `{without_prefix}`)",
        path.display()
    )]
    MixedPrefix {
        path: PathBuf,
        with_prefix: String,
        without_prefix: String,
    },

    #[error("{}: missing tensor `{tensor}` (expected shape {expected:?}; needed for `{duo_name}`)", path.display())]
    Missing {
        path: PathBuf,
        tensor: String,
        duo_name: String,
        expected: Vec<u32>,
    },

    #[error(
        "{}: {} unexpected tensor(s) the model does not use: {}",
        path.display(),
        tensors.len(),
        list(tensors)
    )]
    Extra { path: PathBuf, tensors: Vec<String> },

    #[error("{}: tensor `{tensor}` has shape {found:?}, the config requires {expected:?}", path.display())]
    Shape {
        path: PathBuf,
        tensor: String,
        expected: Vec<u32>,
        found: Vec<usize>,
    },

    #[error("{}: tensor `{tensor}` has dtype {found}; only F32, F16 and BF16 are accepted", path.display())]
    Dtype {
        path: PathBuf,
        tensor: String,
        found: String,
    },

    #[error(
        "{}: attention mask `{tensor}` is {found} at ({row}, {col}), expected {expected} \
         (the engine builds masks from block_size/look_forward; this checkpoint disagrees)",
        path.display()
    )]
    Mask {
        path: PathBuf,
        tensor: String,
        row: u64,
        col: u64,
        expected: f32,
        found: f32,
    },

    #[error("{}: tensor `{tensor}` element {index} is {value} (weights must be finite)", path.display())]
    NonFinite {
        path: PathBuf,
        tensor: String,
        index: usize,
        value: f32,
    },

    #[error("{}: {source}", path.display())]
    Write { path: PathBuf, source: WriteError },
}

fn list(names: &[String]) -> String {
    const SHOWN: usize = 8;
    let mut s = names
        .iter()
        .take(SHOWN)
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > SHOWN {
        s.push_str(&format!(" and {} more", names.len() - SHOWN));
    }
    s
}
