//! Bailando's checkpoints -> `.duo` (format version 2, family Bailando):
//! the authors' YAML (`configs/actor_critic.yaml` structure), the actor
//! GPT state dict (`CrossCondGPT2AC`; its `critic_net.*` weights are
//! training-only: skipped and counted) and the `SepVQVAER` state dict, as
//! safetensors (`module.` prefix accepted).

use std::collections::BTreeSet;
use std::path::Path;

use duolando_core::bailando::config::BailandoConfig;
use duolando_core::family::FamilyConfig;
use duolando_core::nn::names::TensorSpec;

use super::error::ConvertError;
use super::skipped::check_mask_values;
use super::source::Source;
use super::{take_tensor, Report};
use crate::duo_writer::{write_model, StoreAs};

/// What a Bailando conversion did: the common report plus the critic's
/// weights skipped.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BailandoReport {
    pub report: Report,
    /// `critic_net.*` tensors skipped (training only).
    pub critic_skipped: usize,
}

/// Converts in memory: `cfg` (from [`super::parse_bailando_config`]), the
/// GPT and VQ-VAE safetensors (each labelled by its path).
pub fn convert_bailando(
    cfg: &BailandoConfig,
    gpt: (&Path, &[u8]),
    vqvae: (&Path, &[u8]),
    store_as: StoreAs,
    label: &Path,
) -> Result<(Vec<u8>, BailandoReport), ConvertError> {
    let sources = [
        Source::parse(gpt.0, gpt.1)?,
        Source::parse(vqvae.0, vqvae.1)?,
    ];
    let prefixes = ["gpt.", "motion."];
    let mut used: [BTreeSet<String>; 2] = Default::default();
    let mut tensors = Vec::new();
    let family = FamilyConfig::Bailando(*cfg);
    family.for_each_tensor::<ConvertError>(&mut |spec: &TensorSpec| {
        tensors.push(take_tensor(spec, &sources, &prefixes, &mut used, store_as)?);
        Ok(())
    })?;
    let mut out = BailandoReport {
        report: Report {
            written: tensors.len(),
            ..Report::default()
        },
        critic_skipped: 0,
    };
    for (c, src) in sources.iter().enumerate() {
        let mut extra = Vec::new();
        for name in src.tensors.keys().filter(|n| !used[c].contains(*n)) {
            if c == 0 && name.starts_with("critic_net.") {
                out.critic_skipped += 1;
                out.report.skipped += 1;
            } else if c == 0 && name.ends_with(".attn.mask") {
                check_mask_values(src, name, cfg.gpt.block_size as u64, None)?;
                out.report.masks_checked += 1;
                out.report.skipped += 1;
            } else {
                extra.push(name.clone());
            }
        }
        if !extra.is_empty() {
            return Err(ConvertError::Extra {
                path: src.path.clone(),
                tensors: extra,
            });
        }
    }
    let bytes = write_model(&family, &tensors).map_err(|source| ConvertError::Write {
        path: label.into(),
        source,
    })?;
    out.report.bytes = bytes.len();
    Ok((bytes, out))
}
