//! The authors' options, as a checkpoint directory's `hparams.yaml` holds
//! them (flat `key: value` lines; generate.py loads it over the option
//! defaults): [`Hparams`] keeps every option that changes the computation,
//! including those the engine refuses, so that
//! [`crate::transflower::config::TransflowerConfig::from_hparams`] can
//! refuse them BY NAME. [`Hparams::set`] reads one `key: value` pair
//! (no allocation); unknown keys are ignored (training-only options).
//!
//! Defaults are the authors' argparse defaults (models/transflower_model.py
//! `modify_commandline_options`, models/base_model.py): a published
//! hparams.yaml sets every key, so they matter only for hand-written files.

use crate::transflower::config::{ModalityName, MAX_INPUTS};

/// Why a `key: value` pair could not be read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HparamsError {
    /// The value of `key` is not what the key takes (a number, a bool, a
    /// list of at most [`MAX_INPUTS`] items, a modality name, `[[n, 0], ..]`).
    Value { key: Key },
}

/// The keys [`Hparams::set`] reads (named in errors).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Key {
    Model,
    InputModalities,
    OutputModalities,
    Dins,
    Douts,
    InputLengths,
    OutputLengths,
    InputTimeOffsets,
    OutputTimeOffsets,
    InputTypes,
    InputFixLengthTypes,
    InputNumTokens,
    ConditioningSeqLens,
    Dhid,
    Nhead,
    Nlayers,
    DhidFlow,
    NumHeadsFlow,
    NumGlowCouplingBlocks,
    Scales,
    GlowNormLayer,
    FlowDist,
    FlowDistParam,
    CondConcatDims,
    NumMixtureComponents,
    UseTransformerNn,
    UsePosEmbInputs,
    UsePosEmbOutput,
    UsePosEmbCoupling,
    UseRelPosEmbInputs,
    UseRelPosEmbOutput,
    UseRelPosEmbCoupling,
    Residual,
    UseXTransformers,
    UseRotaryPosEmb,
}

const KEYS: [(&str, Key); 35] = [
    ("model", Key::Model),
    ("input_modalities", Key::InputModalities),
    ("output_modalities", Key::OutputModalities),
    ("dins", Key::Dins),
    ("douts", Key::Douts),
    ("input_lengths", Key::InputLengths),
    ("output_lengths", Key::OutputLengths),
    ("input_time_offsets", Key::InputTimeOffsets),
    ("output_time_offsets", Key::OutputTimeOffsets),
    ("input_types", Key::InputTypes),
    ("input_fix_length_types", Key::InputFixLengthTypes),
    ("input_num_tokens", Key::InputNumTokens),
    ("conditioning_seq_lens", Key::ConditioningSeqLens),
    ("dhid", Key::Dhid),
    ("nhead", Key::Nhead),
    ("nlayers", Key::Nlayers),
    ("dhid_flow", Key::DhidFlow),
    ("num_heads_flow", Key::NumHeadsFlow),
    ("num_glow_coupling_blocks", Key::NumGlowCouplingBlocks),
    ("scales", Key::Scales),
    ("glow_norm_layer", Key::GlowNormLayer),
    ("flow_dist", Key::FlowDist),
    ("flow_dist_param", Key::FlowDistParam),
    ("cond_concat_dims", Key::CondConcatDims),
    ("num_mixture_components", Key::NumMixtureComponents),
    ("use_transformer_nn", Key::UseTransformerNn),
    ("use_pos_emb_inputs", Key::UsePosEmbInputs),
    ("use_pos_emb_output", Key::UsePosEmbOutput),
    ("use_pos_emb_coupling", Key::UsePosEmbCoupling),
    ("use_rel_pos_emb_inputs", Key::UseRelPosEmbInputs),
    ("use_rel_pos_emb_output", Key::UseRelPosEmbOutput),
    ("use_rel_pos_emb_coupling", Key::UseRelPosEmbCoupling),
    ("residual", Key::Residual),
    ("use_x_transformers", Key::UseXTransformers),
    ("use_rotary_pos_emb", Key::UseRotaryPosEmb),
];

/// `glow_norm_layer`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NormOption {
    /// `None` / null: no norm module in a flow step.
    None,
    BatchNorm,
    ActNorm,
    /// Any other string (the authors' code would fail or skip it).
    Other,
}

/// `flow_dist`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DistOption {
    Normal,
    StudentT,
    Other,
}

/// A per-input list option (`dins`, `input_lengths`, ...): `n` items.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct List<T> {
    pub n: usize,
    pub items: [T; MAX_INPUTS],
}

impl<T: Copy> List<T> {
    pub fn as_slice(&self) -> &[T] {
        &self.items[..self.n]
    }
}

/// Every option that changes the computation (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hparams {
    /// `model` (must be `transflower`).
    pub is_transflower: bool,
    pub input_modalities: List<ModalityName>,
    /// `output_modalities` (several: refused).
    pub output_modalities: List<ModalityName>,
    pub dins: List<u32>,
    pub douts: List<u32>,
    pub input_lengths: List<u32>,
    pub output_lengths: List<u32>,
    /// Default "0" (one value: broadcast to every input).
    pub input_time_offsets: List<u32>,
    pub output_time_offsets: List<u32>,
    /// `c` / `d` per input; unset (n = 0): all continuous.
    pub input_types_discrete: List<bool>,
    /// `single` per input; unset: all `end`.
    pub input_fix_single: List<bool>,
    pub input_num_tokens: List<u32>,
    /// Unset: `output_lengths`.
    pub conditioning_seq_lens: Option<u32>,
    pub dhid: u32,
    pub nhead: u32,
    pub nlayers: u32,
    pub dhid_flow: u32,
    pub num_heads_flow: u32,
    pub num_glow_coupling_blocks: u32,
    /// `scales`: one `[n, split]` pair per level (`n` flow steps).
    pub scales: List<(u32, u32)>,
    pub glow_norm_layer: NormOption,
    pub flow_dist: DistOption,
    pub flow_dist_param: u32,
    pub cond_concat_dims: bool,
    pub num_mixture_components: u32,
    pub use_transformer_nn: bool,
    pub use_pos_emb_inputs: bool,
    pub use_pos_emb_output: bool,
    pub use_pos_emb_coupling: bool,
    pub use_rel_pos_emb_inputs: bool,
    pub use_rel_pos_emb_output: bool,
    pub use_rel_pos_emb_coupling: bool,
    pub residual: bool,
    pub use_x_transformers: bool,
    pub use_rotary_pos_emb: bool,
}

impl Default for Hparams {
    /// The authors' argparse defaults (models/transflower_model.py; note
    /// `num_glow_coupling_blocks` 10 and `scales` `[[10,0]]` there).
    fn default() -> Self {
        let zero = List {
            n: 1,
            items: [0; MAX_INPUTS],
        };
        Hparams {
            is_transflower: false,
            input_modalities: List::default(),
            output_modalities: List::default(),
            dins: List::default(),
            douts: List::default(),
            input_lengths: List::default(),
            output_lengths: List::default(),
            input_time_offsets: zero,
            output_time_offsets: List::default(),
            input_types_discrete: List::default(),
            input_fix_single: List::default(),
            input_num_tokens: List::default(),
            conditioning_seq_lens: None,
            dhid: 512,
            nhead: 8,
            nlayers: 6,
            dhid_flow: 512,
            num_heads_flow: 8,
            num_glow_coupling_blocks: 10,
            scales: List {
                n: 1,
                items: [(10, 0); MAX_INPUTS],
            },
            glow_norm_layer: NormOption::None,
            flow_dist: DistOption::Normal,
            flow_dist_param: 50,
            cond_concat_dims: false,
            num_mixture_components: 0,
            use_transformer_nn: false,
            use_pos_emb_inputs: false,
            use_pos_emb_output: false,
            use_pos_emb_coupling: false,
            use_rel_pos_emb_inputs: false,
            use_rel_pos_emb_output: false,
            use_rel_pos_emb_coupling: false,
            residual: false,
            use_x_transformers: false,
            use_rotary_pos_emb: false,
        }
    }
}

/// A YAML scalar without quotes and surrounding blanks.
fn unquote(v: &str) -> &str {
    let v = v.trim();
    let b = v.as_bytes();
    if b.len() >= 2 && (b[0] == b'\'' || b[0] == b'"') && b[b.len() - 1] == b[0] {
        return v[1..v.len() - 1].trim();
    }
    v
}

fn is_null(v: &str) -> bool {
    matches!(v, "" | "null" | "None" | "~")
}

fn num(v: &str) -> Option<u32> {
    v.trim().parse().ok()
}

fn flag(v: &str) -> Option<bool> {
    match v {
        "true" | "True" => Some(true),
        "false" | "False" => Some(false),
        _ => None,
    }
}

/// A comma-separated list of at most [`MAX_INPUTS`] items.
fn list<T: Copy + Default>(v: &str, item: impl Fn(&str) -> Option<T>) -> Option<List<T>> {
    let mut l = List {
        n: 0,
        items: [T::default(); MAX_INPUTS],
    };
    for s in v.split(',') {
        if l.n == MAX_INPUTS {
            return None;
        }
        l.items[l.n] = item(s.trim())?;
        l.n += 1;
    }
    Some(l)
}

/// `[[n, s], [n, s]]` (the authors `literal_eval` it).
fn scales(v: &str) -> Option<List<(u32, u32)>> {
    let inner = v.trim().strip_prefix('[')?.strip_suffix(']')?;
    let mut l = List {
        n: 0,
        items: [(0, 0); MAX_INPUTS],
    };
    for part in inner.split(']') {
        let part = part.trim().trim_start_matches(',').trim();
        if part.is_empty() {
            continue;
        }
        let pair = part.strip_prefix('[')?;
        let mut it = pair.split(',');
        let (a, b) = (num(it.next()?)?, num(it.next()?)?);
        if it.next().is_some() || l.n == MAX_INPUTS {
            return None;
        }
        l.items[l.n] = (a, b);
        l.n += 1;
    }
    (l.n > 0).then_some(l)
}

impl Hparams {
    /// Reads one `key: value` pair (value as written in the YAML, quotes
    /// allowed). Unknown keys are ignored.
    pub fn set(&mut self, key: &str, value: &str) -> Result<(), HparamsError> {
        let Some(&(_, k)) = KEYS.iter().find(|(n, _)| *n == key.trim()) else {
            return Ok(());
        };
        let v = unquote(value);
        let bad = HparamsError::Value { key: k };
        let nums = |v: &str| list(v, num).ok_or(bad);
        let flags = |v: &str| flag(v).ok_or(bad);
        match k {
            Key::Model => self.is_transflower = v == "transflower",
            Key::InputModalities => {
                self.input_modalities = list(v, ModalityName::new).ok_or(bad)?
            }
            Key::OutputModalities => {
                self.output_modalities = list(v, ModalityName::new).ok_or(bad)?
            }
            Key::Dins => self.dins = nums(v)?,
            Key::Douts => self.douts = nums(v)?,
            Key::InputLengths => self.input_lengths = nums(v)?,
            Key::OutputLengths => self.output_lengths = nums(v)?,
            Key::InputTimeOffsets => self.input_time_offsets = nums(v)?,
            Key::OutputTimeOffsets => self.output_time_offsets = nums(v)?,
            Key::InputTypes if is_null(v) => self.input_types_discrete = List::default(),
            Key::InputTypes => {
                self.input_types_discrete = list(v, |s| match s {
                    "c" => Some(false),
                    "d" => Some(true),
                    _ => None,
                })
                .ok_or(bad)?
            }
            Key::InputFixLengthTypes if is_null(v) => self.input_fix_single = List::default(),
            Key::InputFixLengthTypes => {
                self.input_fix_single = list(v, |s| Some(s == "single")).ok_or(bad)?
            }
            Key::InputNumTokens if is_null(v) => self.input_num_tokens = List::default(),
            Key::InputNumTokens => self.input_num_tokens = nums(v)?,
            Key::ConditioningSeqLens if is_null(v) => self.conditioning_seq_lens = None,
            Key::ConditioningSeqLens => {
                let l = nums(v)?;
                if l.n != 1 {
                    return Err(bad);
                }
                self.conditioning_seq_lens = Some(l.items[0]);
            }
            Key::Dhid => self.dhid = num(v).ok_or(bad)?,
            Key::Nhead => self.nhead = num(v).ok_or(bad)?,
            Key::Nlayers => self.nlayers = num(v).ok_or(bad)?,
            Key::DhidFlow => self.dhid_flow = num(v).ok_or(bad)?,
            Key::NumHeadsFlow => self.num_heads_flow = num(v).ok_or(bad)?,
            Key::NumGlowCouplingBlocks => self.num_glow_coupling_blocks = num(v).ok_or(bad)?,
            Key::Scales => self.scales = scales(v).ok_or(bad)?,
            Key::GlowNormLayer => {
                self.glow_norm_layer = match v {
                    _ if is_null(v) => NormOption::None,
                    "batchnorm" => NormOption::BatchNorm,
                    "actnorm" => NormOption::ActNorm,
                    _ => NormOption::Other,
                }
            }
            Key::FlowDist => {
                self.flow_dist = match v {
                    "normal" => DistOption::Normal,
                    "studentT" => DistOption::StudentT,
                    _ => DistOption::Other,
                }
            }
            Key::FlowDistParam => self.flow_dist_param = num(v).ok_or(bad)?,
            Key::CondConcatDims => self.cond_concat_dims = flags(v)?,
            Key::NumMixtureComponents => self.num_mixture_components = num(v).ok_or(bad)?,
            Key::UseTransformerNn => self.use_transformer_nn = flags(v)?,
            Key::UsePosEmbInputs => self.use_pos_emb_inputs = flags(v)?,
            Key::UsePosEmbOutput => self.use_pos_emb_output = flags(v)?,
            Key::UsePosEmbCoupling => self.use_pos_emb_coupling = flags(v)?,
            Key::UseRelPosEmbInputs => self.use_rel_pos_emb_inputs = flags(v)?,
            Key::UseRelPosEmbOutput => self.use_rel_pos_emb_output = flags(v)?,
            Key::UseRelPosEmbCoupling => self.use_rel_pos_emb_coupling = flags(v)?,
            Key::Residual => self.residual = flags(v)?,
            Key::UseXTransformers => self.use_x_transformers = flags(v)?,
            Key::UseRotaryPosEmb => self.use_rotary_pos_emb = flags(v)?,
        }
        Ok(())
    }

    /// Reads a whole flat YAML text (`key: value` per line; blank lines,
    /// comments and indented lines skipped).
    pub fn parse(text: &str) -> Result<Hparams, HparamsError> {
        let mut h = Hparams::default();
        for line in text.lines() {
            if line.starts_with([' ', '\t', '#', '-']) {
                continue;
            }
            if let Some((k, v)) = line.split_once(':') {
                h.set(k, v)?;
            }
        }
        Ok(h)
    }
}
