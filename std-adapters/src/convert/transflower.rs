//! Transflower's checkpoint -> `.duo` (format version 2, family
//! Transflower): the authors' `hparams.yaml` (the checkpoint directory's:
//! every option as generate.py resolves it) and the Lightning checkpoint's
//! `state_dict` as safetensors (tools/transflower_ckpt_to_safetensors.py;
//! names unchanged, `module.` prefix accepted).
//!
//! The options are read by core's `Hparams::parse` and mapped by
//! `TransflowerConfig::from_hparams`, which refuses by name every option
//! that changes the computation and is not implemented
//! (tools/reference/transflower/README.md, "Options that change the
//! computation"). The schema (`transflower::schema`) then drives the
//! weights: every tensor it lists is taken by its state-dict name, shape
//! checked, upcast to f32 and stored as `--dtype` says (flow parameters,
//! biases, norms, `pe` and `pos_emb` always f32); the buffers inference
//! never reads (`*.is_initialized` of the flow's norm layers, the flow's
//! `bounds`) are skipped and counted; anything else left over is an error.

use std::collections::BTreeSet;
use std::path::Path;

use duolando_core::family::FamilyConfig;
use duolando_core::nn::names::TensorSpec;
use duolando_core::transflower::config::TransflowerConfig;
use duolando_core::transflower::hparams::{Hparams, HparamsError, Key};

use super::error::ConvertError;
use super::source::Source;
use super::{take_tensor, Report};
use crate::duo_writer::{write_model, StoreAs};

/// What a Transflower conversion did: the common report plus the buffers
/// skipped.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TransflowerReport {
    pub report: Report,
    /// `*.is_initialized` buffers of the flow's norm layers (training-time
    /// data-init flags) skipped.
    pub is_initialized_skipped: usize,
    /// `*.bounds` buffers of the flow skipped (unused at inference).
    pub bounds_skipped: usize,
}

/// Whether a YAML text is one of the authors' flat option files (a
/// checkpoint directory's `hparams.yaml` of guillefix/transflower-lightning):
/// a top-level `model:` key. Its value is checked by
/// [`parse_transflower_config`] (`model: transformer`, another model of the
/// same repository, is refused by name there).
pub fn is_transflower(text: &str) -> bool {
    text.lines().any(|l| l.strip_prefix("model:").is_some())
}

/// The authors' YAML key of an option (for messages).
fn key_name(k: Key) -> &'static str {
    use Key::*;
    match k {
        Model => "model",
        InputModalities => "input_modalities",
        OutputModalities => "output_modalities",
        Dins => "dins",
        Douts => "douts",
        InputLengths => "input_lengths",
        OutputLengths => "output_lengths",
        InputTimeOffsets => "input_time_offsets",
        OutputTimeOffsets => "output_time_offsets",
        InputTypes => "input_types",
        InputFixLengthTypes => "input_fix_length_types",
        InputNumTokens => "input_num_tokens",
        ConditioningSeqLens => "conditioning_seq_lens",
        Dhid => "dhid",
        Nhead => "nhead",
        Nlayers => "nlayers",
        DhidFlow => "dhid_flow",
        NumHeadsFlow => "num_heads_flow",
        NumGlowCouplingBlocks => "num_glow_coupling_blocks",
        Scales => "scales",
        GlowNormLayer => "glow_norm_layer",
        FlowDist => "flow_dist",
        FlowDistParam => "flow_dist_param",
        CondConcatDims => "cond_concat_dims",
        NumMixtureComponents => "num_mixture_components",
        UseTransformerNn => "use_transformer_nn",
        UsePosEmbInputs => "use_pos_emb_inputs",
        UsePosEmbOutput => "use_pos_emb_output",
        UsePosEmbCoupling => "use_pos_emb_coupling",
        UseRelPosEmbInputs => "use_rel_pos_emb_inputs",
        UseRelPosEmbOutput => "use_rel_pos_emb_output",
        UseRelPosEmbCoupling => "use_rel_pos_emb_coupling",
        Residual => "residual",
        UseXTransformers => "use_x_transformers",
        UseRotaryPosEmb => "use_rotary_pos_emb",
    }
}

/// Maps the authors' `hparams.yaml` text onto the engine's config; `path`
/// only labels errors. A value of the wrong kind names its key; an option
/// the engine does not implement is refused by name.
pub fn parse_transflower_config(
    path: &Path,
    text: &str,
) -> Result<TransflowerConfig, ConvertError> {
    let h = Hparams::parse(text).map_err(|HparamsError::Value { key }| ConvertError::ConfigKey {
        path: path.into(),
        key: key_name(key).to_string(),
        problem: "not a value this option takes (a number, a bool, a comma-separated list of at most 4 items, a modality name [A-Za-z0-9_], or [[n, 0]])".into(),
    })?;
    TransflowerConfig::from_hparams(&h).map_err(|e| ConvertError::TransflowerConfig {
        path: path.into(),
        detail: duolando_runtime::engine_errors::describe_transflower_config(&e),
    })
}

/// Converts in memory: `cfg` (from [`parse_transflower_config`]) and the
/// state dict as safetensors (labelled by its path).
pub fn convert_transflower(
    cfg: &TransflowerConfig,
    weights: (&Path, &[u8]),
    store_as: StoreAs,
    label: &Path,
) -> Result<(Vec<u8>, TransflowerReport), ConvertError> {
    let sources = [Source::parse(weights.0, weights.1)?];
    let mut used: [BTreeSet<String>; 1] = Default::default();
    let mut tensors = Vec::new();
    let family = FamilyConfig::Transflower(*cfg);
    family.for_each_tensor::<ConvertError>(&mut |spec: &TensorSpec| {
        tensors.push(take_tensor(spec, &sources, &[""], &mut used, store_as)?);
        Ok(())
    })?;
    let mut out = TransflowerReport {
        report: Report {
            written: tensors.len(),
            ..Report::default()
        },
        ..TransflowerReport::default()
    };
    let src = &sources[0];
    let mut extra = Vec::new();
    for name in src.tensors.keys().filter(|n| !used[0].contains(*n)) {
        if name.ends_with(".is_initialized") {
            out.is_initialized_skipped += 1;
        } else if name.ends_with(".bounds") {
            out.bounds_skipped += 1;
        } else {
            extra.push(name.clone());
            continue;
        }
        out.report.skipped += 1;
    }
    if !extra.is_empty() {
        return Err(ConvertError::Extra {
            path: src.path.clone(),
            tensors: extra,
        });
    }
    let bytes = write_model(&family, &tensors).map_err(|source| ConvertError::Write {
        path: label.into(),
        source,
    })?;
    out.report.bytes = bytes.len();
    Ok((bytes, out))
}
