//! Transflower's configuration (what the engine implements of the
//! authors' options; tools/reference/transflower/README.md "Options that
//! change the computation"): the input modalities and their windows, the
//! input and cross-modal transformers, the flow, the base distribution.
//! [`TransflowerConfig::from_hparams`] maps the authors' options onto it
//! and refuses what the engine does not implement BY NAME
//! ([`Unsupported`]); [`TransflowerConfig::validate`] checks every size.

use serde::{Deserialize, Serialize};

use crate::limits::{MAX_EMBD, MAX_HEADS, MAX_VOCAB};
use crate::transflower::hparams::{DistOption, Hparams, NormOption};

/// Frames per second of the published features (motion and audio at 20
/// fps: the `*_scaled_20` arrays). Bookkeeping only: nothing computed
/// depends on it.
pub const FPS: u32 = 20;
/// Most input modalities (published: 2 or 3).
pub const MAX_INPUTS: usize = 4;
/// Longest modality name in bytes (it is part of tensor names).
pub const MODALITY_NAME_CAP: usize = 32;
/// Longest input window (published: 140 rows) and longest flow sample.
pub const MAX_WINDOW: u32 = 4096;
/// Most layers of the cross-modal transformer (published: 12).
pub const MAX_LAYERS: u32 = 24;
/// Most layers of a coupling transformer (`num_glow_coupling_blocks`;
/// published: 2). Kept small: the model holds one per flow step.
pub const MAX_COUPLING_LAYERS: u32 = 4;
/// Most flow steps (published: 16, 24).
pub const MAX_FLOW_STEPS: u32 = 32;
/// Layers of every input transformer: hard-coded `2` in the authors'
/// `TransflowerModel.__init__`.
pub const INPUT_LAYERS: u32 = 2;

/// A modality name (`expmap_scaled_20`, `audio_feats_scaled_20`, ...):
/// ASCII letters, digits and `_`, 1 to [`MODALITY_NAME_CAP`] bytes. Tensor
/// names embed it (`net_input_<name>.`), as in the authors' state dict.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ModalityName {
    len: u8,
    bytes: [u8; MODALITY_NAME_CAP],
}

impl ModalityName {
    /// None if empty, too long or not `[A-Za-z0-9_]`.
    pub fn new(s: &str) -> Option<ModalityName> {
        let b = s.as_bytes();
        if b.is_empty()
            || b.len() > MODALITY_NAME_CAP
            || !b.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_')
        {
            return None;
        }
        let mut bytes = [0u8; MODALITY_NAME_CAP];
        bytes[..b.len()].copy_from_slice(b);
        Some(ModalityName {
            len: b.len() as u8,
            bytes,
        })
    }
    /// Whether the stored bytes are what [`ModalityName::new`] makes (a
    /// name decoded from a file may not be: length over the cap, bytes
    /// outside `[A-Za-z0-9_]`, or non-zero bytes past the length).
    pub fn is_valid(&self) -> bool {
        (self.len as usize) <= MODALITY_NAME_CAP
            && ModalityName::new(self.as_str()).as_ref() == Some(self)
    }
    pub fn as_str(&self) -> &str {
        // Only ASCII is ever stored (`new`); a corrupt value reads as "".
        core::str::from_utf8(&self.bytes[..(self.len as usize).min(MODALITY_NAME_CAP)])
            .unwrap_or("")
    }
}

/// One input modality: its transformer (`net_input_<name>`) and window.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct InputConfig {
    pub name: ModalityName,
    /// `dins[i]`: feature width (continuous) or embedding width (discrete).
    pub dim: u32,
    /// `input_lengths[i]`: rows of the window.
    pub length: u32,
    /// `input_num_tokens[i]` of a discrete input (`input_types` d, whose
    /// window is one label for the whole sequence: `single`); 0 = continuous.
    pub tokens: u32,
}

impl InputConfig {
    pub fn is_discrete(&self) -> bool {
        self.tokens > 0
    }
}

/// `glow_norm_layer`: the norm module at the head of every flow step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum NormLayer {
    /// No norm module (a step is [1x1 conv, coupling]).
    None,
    /// The authors' `BatchNorm` (running statistics, eps on the std).
    BatchNorm,
    /// `ActNorm` (`mean`, `inv_std`).
    ActNorm,
}

/// The base distribution the flow maps from (`flow_dist`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum BaseDist {
    /// `GaussianDiag`: N(0, 1) per value.
    Normal,
    /// `StudentT`: N(0, 1) / sqrt(chi2(df) / df), one chi2 per output
    /// position (a multivariate t per frame).
    StudentT { df: u32 },
}

/// The flow (`FlowPlusPlus` with one scale `[[steps, 0]]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FlowConfig {
    /// `n` of `scales [[n, 0]]`: flow steps.
    pub steps: u32,
    pub norm: NormLayer,
    /// `dhid_flow`: width of the coupling transformers (and their FFN).
    pub dhid: u32,
    /// `num_heads_flow`.
    pub heads: u32,
    /// `num_glow_coupling_blocks`: layers of each coupling transformer.
    pub layers: u32,
    /// `cond_concat_dims`: True = x_id and the conditioning rows side by
    /// side (channels), False = x_id encoded then stacked above them (rows).
    pub concat_dims: bool,
    /// `use_pos_emb_coupling`: the coupling transformers add `pe`.
    pub pos_emb: bool,
    pub base: BaseDist,
}

/// The whole model (batch 1, one autoregressive output modality).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TransflowerConfig {
    /// Inputs in `input_modalities` order (the latent rows' order).
    pub n_inputs: u32,
    pub inputs: [InputConfig; MAX_INPUTS],
    /// Which input is the output modality (fed back): `output_modalities`.
    pub output: u32,
    /// `output_lengths` (H): frames the flow samples per step (row 0 kept).
    pub output_length: u32,
    /// `output_time_offsets`: song row of output 0 (bookkeeping only).
    pub output_time_offset: u32,
    /// Conditioning rows: `conditioning_seq_lens`, or `output_lengths`.
    pub cond_len: u32,
    /// `dhid`: width of every input and the cross-modal transformer (and their FFN).
    pub dhid: u32,
    /// `nhead`.
    pub nhead: u32,
    /// `nlayers`: layers of the cross-modal transformer.
    pub nlayers: u32,
    /// `use_rel_pos_emb_inputs`: a learned (L, L) score bias `pos_emb` in
    /// every input transformer of more than one row.
    pub rel_pos_emb_inputs: bool,
    /// `use_pos_emb_output`: the cross-modal transformer adds `pe`.
    pub pos_emb_output: bool,
    pub flow: FlowConfig,
}

/// A config field named in a [`ConfigError`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Field {
    Inputs,
    /// Of input `i`.
    InputDim(u8),
    InputLength(u8),
    InputTokens(u8),
    Output,
    /// `douts` (C, the output's channels).
    Channels,
    OutputLength,
    CondLen,
    Dhid,
    Nhead,
    Nlayers,
    FlowSteps,
    DhidFlow,
    HeadsFlow,
    CouplingLayers,
    StudentTDf,
}

/// An option of the authors' code the engine does not implement (none is
/// used by the published configs unless said; tools/reference/transflower/README.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unsupported {
    /// `model` is not `transflower`.
    NotTransflower,
    /// `residual: True` (3 published configs): a mean network adds to the sample.
    Residual,
    /// `scales` with more than one level (squeeze, halved split, doubled cond).
    MultiLevelScales {
        levels: u32,
    },
    /// `scales [[n, s]]` with a checkerboard part `s > 0`.
    CheckerboardScales,
    /// `num_mixture_components > 0`: mixture-of-logistics couplings.
    MixtureCouplings {
        components: u32,
    },
    /// `use_transformer_nn: False`: convolutional coupling nets.
    ConvCouplingNets,
    UseXTransformers,
    UseRotaryPosEmb,
    UsePosEmbInputs,
    UseRelPosEmbOutput,
    UseRelPosEmbCoupling,
    /// `glow_norm_layer` other than batchnorm, actnorm or none.
    NormLayer,
    /// `flow_dist` other than normal or studentT.
    FlowDist,
    /// More than one output modality.
    SeveralOutputs,
    /// The output modality is not an input (nothing to feed back).
    OutputNotAnInput,
    /// `input_time_offsets` other than 0.
    InputTimeOffsets,
    /// A discrete input that is not `single`, or a `single` continuous input.
    WindowType {
        input: u8,
    },
    /// `douts` other than the output input's `dins`.
    OutputWidth,
    /// Per-input lists (`dins`, `input_lengths`, ...) of another length
    /// than `input_modalities`.
    ListLength,
}

/// Why a config was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConfigError {
    Zero {
        field: Field,
    },
    TooLarge {
        field: Field,
        value: u32,
        max: u32,
    },
    TooSmall {
        field: Field,
        value: u32,
        min: u32,
    },
    NotDivisible {
        field: Field,
        value: u32,
        divisor: u32,
    },
    Mismatch {
        field: Field,
        value: u32,
        expected: u32,
    },
    Unsupported(Unsupported),
    /// Input `input`'s modality name is empty, too long or not
    /// `[A-Za-z0-9_]` (only a corrupt `.duo` header can hold one).
    BadName {
        input: u8,
    },
    /// Inputs `input` and `previous` have the same modality name (their
    /// tensor names would collide).
    DuplicateName {
        input: u8,
        previous: u8,
    },
    /// Slot `input` at or past `n_inputs` is not empty (all zero).
    UnusedInput {
        input: u8,
    },
}

fn range(field: Field, value: u32, min: u32, max: u32) -> Result<(), ConfigError> {
    if value == 0 && min > 0 {
        return Err(ConfigError::Zero { field });
    }
    if value < min {
        return Err(ConfigError::TooSmall { field, value, min });
    }
    if value > max {
        return Err(ConfigError::TooLarge { field, value, max });
    }
    Ok(())
}

fn unsupported(u: Unsupported) -> ConfigError {
    ConfigError::Unsupported(u)
}

impl TransflowerConfig {
    /// The inputs in order.
    pub fn inputs(&self) -> &[InputConfig] {
        &self.inputs[..(self.n_inputs as usize).min(MAX_INPUTS)]
    }
    /// The output modality's input.
    pub fn output_input(&self) -> &InputConfig {
        &self.inputs[(self.output as usize).min(MAX_INPUTS - 1)]
    }
    /// C: channels of the output (`douts`).
    pub fn channels(&self) -> usize {
        self.output_input().dim as usize
    }
    /// Rows of the latent sequence: the sum of the input windows.
    pub fn latent_rows(&self) -> usize {
        self.inputs().iter().map(|i| i.length as usize).sum()
    }
    /// The longest input window (the step count is `rows of the last input - this + 1`).
    pub fn max_window(&self) -> usize {
        self.inputs()
            .iter()
            .map(|i| i.length as usize)
            .max()
            .unwrap_or(0)
    }
    /// Whether input `i`'s transformer has a `pos_emb` score bias.
    pub fn input_has_bias(&self, i: usize) -> bool {
        self.rel_pos_emb_inputs && self.inputs.get(i).is_some_and(|c| c.length > 1)
    }
    /// `cc = ceil(C / 2)`: channels the couplings change (the FIRST ones).
    pub fn change_channels(&self) -> usize {
        self.channels().div_ceil(2)
    }
    /// Rows of a coupling transformer's sequence: H (channel concat) or H + cond_len.
    pub fn coupling_rows(&self) -> usize {
        let h = self.output_length as usize;
        if self.flow.concat_dims {
            h
        } else {
            h + self.cond_len as usize
        }
    }
    /// Input width of a coupling transformer: C - cc + dhid (channel
    /// concat) or dhid (rows stacked after `input_encoder`).
    pub fn coupling_in(&self) -> usize {
        let c = self.channels();
        if self.flow.concat_dims {
            c - self.change_channels() + self.dhid as usize
        } else {
            self.dhid as usize
        }
    }
    /// Modules per flow step (`flows.channels.<k>`): 3 with a norm, else 2.
    pub fn modules_per_step(&self) -> u32 {
        if self.flow.norm == NormLayer::None {
            2
        } else {
            3
        }
    }

    /// Checks every size against the engine's caps and the model's rules.
    pub fn validate(&self) -> Result<(), ConfigError> {
        range(Field::Inputs, self.n_inputs, 1, MAX_INPUTS as u32)?;
        if let Some(k) = self.inputs[self.n_inputs as usize..]
            .iter()
            .position(|i| *i != InputConfig::default())
        {
            return Err(ConfigError::UnusedInput {
                input: (self.n_inputs as usize + k) as u8,
            });
        }
        for (i, inp) in self.inputs().iter().enumerate() {
            if !inp.name.is_valid() {
                return Err(ConfigError::BadName { input: i as u8 });
            }
            if let Some(p) = self.inputs()[..i].iter().position(|q| q.name == inp.name) {
                return Err(ConfigError::DuplicateName {
                    input: i as u8,
                    previous: p as u8,
                });
            }
            let i = i as u8;
            range(Field::InputDim(i), inp.dim, 1, MAX_EMBD)?;
            range(Field::InputLength(i), inp.length, 1, MAX_WINDOW)?;
            range(Field::InputTokens(i), inp.tokens, 0, MAX_VOCAB)?;
            if inp.is_discrete() && inp.length != 1 {
                return Err(unsupported(Unsupported::WindowType { input: i }));
            }
        }
        if self.output >= self.n_inputs {
            return Err(ConfigError::TooLarge {
                field: Field::Output,
                value: self.output,
                max: self.n_inputs - 1,
            });
        }
        if self.output_input().is_discrete() {
            return Err(unsupported(Unsupported::WindowType {
                input: self.output as u8,
            }));
        }
        range(Field::Channels, self.channels() as u32, 2, MAX_EMBD)?;
        range(Field::OutputLength, self.output_length, 1, MAX_WINDOW)?;
        range(Field::CondLen, self.cond_len, 1, self.latent_rows() as u32)?;
        range(Field::Dhid, self.dhid, 1, MAX_EMBD)?;
        range(Field::Nhead, self.nhead, 1, MAX_HEADS)?;
        if !self.dhid.is_multiple_of(self.nhead) {
            return Err(ConfigError::NotDivisible {
                field: Field::Dhid,
                value: self.dhid,
                divisor: self.nhead,
            });
        }
        range(Field::Nlayers, self.nlayers, 1, MAX_LAYERS)?;
        let f = &self.flow;
        range(Field::FlowSteps, f.steps, 1, MAX_FLOW_STEPS)?;
        range(Field::DhidFlow, f.dhid, 1, MAX_EMBD)?;
        range(Field::HeadsFlow, f.heads, 1, MAX_HEADS)?;
        if !f.dhid.is_multiple_of(f.heads) {
            return Err(ConfigError::NotDivisible {
                field: Field::DhidFlow,
                value: f.dhid,
                divisor: f.heads,
            });
        }
        range(Field::CouplingLayers, f.layers, 1, MAX_COUPLING_LAYERS)?;
        if f.concat_dims && self.cond_len != self.output_length {
            // `cat((x_id, cond), dim=1)` needs as many conditioning rows as frames.
            return Err(ConfigError::Mismatch {
                field: Field::CondLen,
                value: self.cond_len,
                expected: self.output_length,
            });
        }
        if let BaseDist::StudentT { df } = f.base {
            range(Field::StudentTDf, df, 1, u32::MAX)?;
        }
        Ok(())
    }

    /// The engine's config from the authors' options, refusing by name what
    /// it does not implement, then [`Self::validate`].
    pub fn from_hparams(h: &Hparams) -> Result<TransflowerConfig, ConfigError> {
        let u = |x| Err(unsupported(x));
        if !h.is_transflower {
            return u(Unsupported::NotTransflower);
        }
        if h.residual {
            return u(Unsupported::Residual);
        }
        if h.scales.n != 1 {
            return u(Unsupported::MultiLevelScales {
                levels: h.scales.n as u32,
            });
        }
        if h.scales.items[0].1 != 0 {
            return u(Unsupported::CheckerboardScales);
        }
        if h.num_mixture_components > 0 {
            return u(Unsupported::MixtureCouplings {
                components: h.num_mixture_components,
            });
        }
        if !h.use_transformer_nn {
            return u(Unsupported::ConvCouplingNets);
        }
        for (on, what) in [
            (h.use_x_transformers, Unsupported::UseXTransformers),
            (h.use_rotary_pos_emb, Unsupported::UseRotaryPosEmb),
            (h.use_pos_emb_inputs, Unsupported::UsePosEmbInputs),
            (h.use_rel_pos_emb_output, Unsupported::UseRelPosEmbOutput),
            (
                h.use_rel_pos_emb_coupling,
                Unsupported::UseRelPosEmbCoupling,
            ),
        ] {
            if on {
                return u(what);
            }
        }
        let norm = match h.glow_norm_layer {
            NormOption::None => NormLayer::None,
            NormOption::BatchNorm => NormLayer::BatchNorm,
            NormOption::ActNorm => NormLayer::ActNorm,
            NormOption::Other => return u(Unsupported::NormLayer),
        };
        let base = match h.flow_dist {
            DistOption::Normal => BaseDist::Normal,
            DistOption::StudentT => BaseDist::StudentT {
                df: h.flow_dist_param,
            },
            DistOption::Other => return u(Unsupported::FlowDist),
        };
        let n = h.input_modalities.n;
        if h.output_modalities.n != 1 || h.douts.n != 1 || h.output_lengths.n != 1 {
            return u(Unsupported::SeveralOutputs);
        }
        let out_name = h.output_modalities.items[0];
        let output = h
            .input_modalities
            .as_slice()
            .iter()
            .position(|m| *m == out_name);
        let Some(output) = output else {
            return u(Unsupported::OutputNotAnInput);
        };
        let per_input = |len: usize, optional: bool| len == n || (optional && len == 0);
        if !per_input(h.dins.n, false)
            || !per_input(h.input_lengths.n, false)
            || !per_input(h.input_types_discrete.n, true)
            || !per_input(h.input_fix_single.n, true)
            || !per_input(h.input_num_tokens.n, true)
        {
            return u(Unsupported::ListLength);
        }
        let offs = h.input_time_offsets.as_slice();
        if offs.iter().any(|&o| o != 0) || !(offs.len() == 1 || offs.len() == n) {
            return u(Unsupported::InputTimeOffsets);
        }
        let mut inputs = [InputConfig::default(); MAX_INPUTS];
        for (i, slot) in inputs.iter_mut().enumerate().take(n) {
            let discrete = h.input_types_discrete.n > 0 && h.input_types_discrete.items[i];
            let single = h.input_fix_single.n > 0 && h.input_fix_single.items[i];
            if discrete != single {
                return u(Unsupported::WindowType { input: i as u8 });
            }
            let tokens = if discrete {
                h.input_num_tokens.items[i]
            } else {
                0
            };
            if discrete && tokens == 0 {
                return Err(ConfigError::Zero {
                    field: Field::InputTokens(i as u8),
                });
            }
            *slot = InputConfig {
                name: h.input_modalities.items[i],
                dim: h.dins.items[i],
                length: h.input_lengths.items[i],
                tokens,
            };
        }
        if h.douts.items[0] != inputs[output].dim {
            return u(Unsupported::OutputWidth);
        }
        let output_length = h.output_lengths.items[0];
        let cfg = TransflowerConfig {
            n_inputs: n as u32,
            inputs,
            output: output as u32,
            output_length,
            output_time_offset: h
                .output_time_offsets
                .as_slice()
                .first()
                .copied()
                .unwrap_or(0),
            cond_len: h.conditioning_seq_lens.unwrap_or(output_length),
            dhid: h.dhid,
            nhead: h.nhead,
            nlayers: h.nlayers,
            rel_pos_emb_inputs: h.use_rel_pos_emb_inputs,
            pos_emb_output: h.use_pos_emb_output,
            flow: FlowConfig {
                steps: h.scales.items[0].0,
                norm,
                dhid: h.dhid_flow,
                heads: h.num_heads_flow,
                layers: h.num_glow_coupling_blocks,
                concat_dims: h.cond_concat_dims,
                pos_emb: h.use_pos_emb_coupling,
                base,
            },
        };
        cfg.validate()?;
        Ok(cfg)
    }
}
