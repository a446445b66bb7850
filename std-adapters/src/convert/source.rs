//! One source checkpoint (a safetensors file of an original `state_dict`):
//! names with the optional DataParallel `module.` prefix stripped, and
//! tensors upcast to f32.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use safetensors::tensor::TensorView;
use safetensors::{Dtype, SafeTensors};

use super::error::ConvertError;

const DATA_PARALLEL_PREFIX: &str = "module.";

/// A parsed safetensors checkpoint borrowed from its bytes.
pub struct Source<'a> {
    /// Where the bytes came from (for messages).
    pub path: PathBuf,
    /// Tensors by their original name without `module.`.
    pub tensors: BTreeMap<String, TensorView<'a>>,
}

impl<'a> Source<'a> {
    /// Parses `bytes` (the contents of `path`). Accepts names that all carry
    /// the `module.` prefix or that all lack it.
    pub fn parse(path: &Path, bytes: &'a [u8]) -> Result<Source<'a>, ConvertError> {
        let st = SafeTensors::deserialize(bytes).map_err(|e| ConvertError::Safetensors {
            path: path.into(),
            detail: explain(bytes, &e),
        })?;
        let all = st.tensors();
        let with = all
            .iter()
            .find(|(n, _)| n.starts_with(DATA_PARALLEL_PREFIX));
        let without = all
            .iter()
            .find(|(n, _)| !n.starts_with(DATA_PARALLEL_PREFIX));
        if let (Some((w, _)), Some((wo, _))) = (with, without) {
            return Err(ConvertError::MixedPrefix {
                path: path.into(),
                with_prefix: w.clone(),
                without_prefix: wo.clone(),
            });
        }
        let tensors = all
            .into_iter()
            .map(|(n, v)| {
                (
                    n.strip_prefix(DATA_PARALLEL_PREFIX)
                        .map(str::to_string)
                        .unwrap_or(n),
                    v,
                )
            })
            .collect();
        Ok(Source {
            path: path.into(),
            tensors,
        })
    }

    /// The tensor `name` as f32 values, after checking its shape is `expected`.
    pub fn f32_values(
        &self,
        name: &str,
        duo_name: &str,
        expected: &[u32],
    ) -> Result<Vec<f32>, ConvertError> {
        let view = self
            .tensors
            .get(name)
            .ok_or_else(|| ConvertError::Missing {
                path: self.path.clone(),
                tensor: name.to_string(),
                duo_name: duo_name.to_string(),
                expected: expected.to_vec(),
            })?;
        let found = view.shape();
        if found.len() != expected.len()
            || found
                .iter()
                .zip(expected)
                .any(|(&f, &e)| f as u64 != e as u64)
        {
            return Err(ConvertError::Shape {
                path: self.path.clone(),
                tensor: name.to_string(),
                expected: expected.to_vec(),
                found: found.to_vec(),
            });
        }
        upcast(view).ok_or_else(|| ConvertError::Dtype {
            path: self.path.clone(),
            tensor: name.to_string(),
            found: format!("{:?}", view.dtype()),
        })
    }
}

/// Little-endian F32/F16/BF16 payload -> f32 (exact for all three); None
/// for other dtypes.
pub fn upcast(view: &TensorView<'_>) -> Option<Vec<f32>> {
    let data = view.data();
    Some(match view.dtype() {
        Dtype::F32 => data
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
        Dtype::F16 => data
            .chunks_exact(2)
            .map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32())
            .collect(),
        Dtype::BF16 => data
            .chunks_exact(2)
            .map(|c| half::bf16::from_le_bytes([c[0], c[1]]).to_f32())
            .collect(),
        _ => return None,
    })
}

/// A safetensors parse failure in words, with the numbers behind it.
fn explain(bytes: &[u8], e: &safetensors::SafeTensorError) -> String {
    use safetensors::SafeTensorError as E;
    let hint = "a safetensors file starts with an 8-byte little-endian header length and a JSON header; \
                PyTorch checkpoints (.pt, .pth, .bin) must be turned into safetensors first: tools/pt_to_safetensors.py";
    let header_len = bytes
        .get(..8)
        .map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])));
    match (e, header_len) {
        (E::HeaderTooSmall, _) => format!("the file has {} bytes, fewer than the 8 of a header length; {hint}", bytes.len()),
        (E::HeaderTooLarge | E::InvalidHeaderLength, Some(n)) => format!(
            "the first 8 bytes give a header of {n} bytes, but the file has {} bytes (and headers are at most 100 MB): \
             not a safetensors file, or a truncated one; {hint}",
            bytes.len()
        ),
        (E::InvalidHeader, _) => format!("the header is not UTF-8 text; {hint}"),
        (E::InvalidHeaderStart, _) => format!("the header does not start with `{{`; {hint}"),
        (E::InvalidHeaderDeserialization, _) | (E::JsonError(_), _) => format!("the header is not the JSON a safetensors file holds ({e:?}); {hint}"),
        (E::MetadataIncompleteBuffer, _) => format!(
            "the tensors listed in the header do not cover the file's {} data bytes exactly (truncated or padded file)",
            bytes.len().saturating_sub(8 + header_len.unwrap_or(0) as usize)
        ),
        (E::InvalidOffset(name), _) => format!("tensor `{name}`: its data offsets in the header are out of order or out of the file"),
        (E::TensorInvalidInfo, _) | (E::ValidationOverflow, _) => {
            format!("a tensor's shape, dtype and data offsets disagree ({e:?})")
        }
        _ => format!("{e:?}"),
    }
}
