//! Source tensors that inference never reads, and why each is skipped
//! (docs/FORMAT.md §6). Anything else left over after the schema has taken
//! its tensors is an error.
//!
//! The attention masks are registered buffers fully determined by the
//! config; they are not stored (the engine builds them), but their values
//! are checked here so a checkpoint trained with different masks is caught.

use duolando_core::duolando::config::ModelConfig;

use super::error::ConvertError;
use super::source::{upcast, Source};

/// Which original module a source file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Component {
    /// GPT2nt, `.duo` prefix `gpt.`.
    Gpt,
    /// SepVQVAEXM, `.duo` prefix `motion.`.
    Motion,
    /// The translation VQVAE, `.duo` prefix `transl.`.
    Transl,
}

impl Component {
    pub const ALL: [Component; 3] = [Component::Gpt, Component::Motion, Component::Transl];
    /// The `.duo` name prefix, dot included.
    pub const fn prefix(self) -> &'static str {
        match self {
            Component::Gpt => "gpt.",
            Component::Motion => "motion.",
            Component::Transl => "transl.",
        }
    }
}

const LATS: [&str; 5] = [
    "music_trans",
    "leader_up_trans",
    "leader_down_trans",
    "leader_lhand_trans",
    "leader_rhand_trans",
];
const GPT_BASE_UNUSED: [&str; 5] = [
    "cond_emb",
    "cond_up_emb",
    "cond_down_emb",
    "cond_lhand_emb",
    "cond_rhand_emb",
];

/// What to do with a source tensor the schema does not ask for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Skip {
    /// An attention-mask buffer: checked against the expected mask.
    Mask(MaskKind),
    /// A parameter or buffer inference never reads.
    Unused,
}

/// The expected mask of an `attn.mask` buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaskKind {
    /// LAT band (`get_subsequent_mask`): `(1,1,L,L)`, 1 where
    /// `|i-j| <= look_forward*ds`, `L = (block_size+look_forward)*ds`,
    /// `ds` = the music LAT's downsample rate.
    MusicBand,
    /// The same band for a leader LAT (its own downsample rate).
    LeaderBand,
    /// GPT base/head: `(1,1,block_size,block_size)` lower-triangular ones.
    Causal,
}

/// Classifies a leftover source tensor (name without `module.`).
pub fn classify(component: Component, name: &str) -> Option<Skip> {
    match component {
        Component::Gpt => {
            if name.ends_with(".attn.mask") {
                let lat = LATS
                    .iter()
                    .position(|l| name.starts_with(&format!("{l}.blocks.")));
                return Some(Skip::Mask(match lat {
                    Some(0) => MaskKind::MusicBand,
                    Some(_) => MaskKind::LeaderBand,
                    None => MaskKind::Causal,
                }));
            }
            if LATS.iter().any(|l| name == format!("{l}.pos_emb")) {
                return Some(Skip::Unused);
            }
            if GPT_BASE_UNUSED.iter().any(|m| {
                name == format!("gpt_base.{m}.weight") || name == format!("gpt_base.{m}.bias")
            }) {
                return Some(Skip::Unused);
            }
            None
        }
        Component::Motion => name
            .starts_with("vqvae_down.decoders_root.")
            .then_some(Skip::Unused),
        Component::Transl => None,
    }
}

/// Checks a mask buffer's shape and every value against what the config implies.
pub fn check_mask(
    src: &Source<'_>,
    name: &str,
    kind: MaskKind,
    cfg: &ModelConfig,
) -> Result<(), ConvertError> {
    let g = &cfg.gpt;
    let (len, band) = match kind {
        MaskKind::Causal => (g.block_size as u64, None),
        MaskKind::MusicBand | MaskKind::LeaderBand => {
            let ds = if kind == MaskKind::MusicBand {
                g.music.downsample_rate
            } else {
                g.leader.downsample_rate
            };
            (
                (g.block_size as u64 + g.look_forward as u64) * ds as u64,
                Some(g.look_forward as u64 * ds as u64),
            )
        }
    };
    check_mask_values(src, name, len, band)
}

/// Checks a `(1, 1, len, len)` mask: ones where `|i - j| <= band`, or on
/// and below the diagonal when `band` is None (causal).
pub fn check_mask_values(
    src: &Source<'_>,
    name: &str,
    len: u64,
    band: Option<u64>,
) -> Result<(), ConvertError> {
    let view = src.tensors.get(name).ok_or_else(|| ConvertError::Missing {
        path: src.path.clone(),
        tensor: name.to_string(),
        duo_name: String::from("(attention mask, checked only)"),
        expected: vec![1, 1, len as u32, len as u32],
    })?;
    let expected = [1u32, 1, len as u32, len as u32];
    let found = view.shape();
    if found.len() != 4
        || found
            .iter()
            .zip(expected)
            .any(|(&f, e)| f as u64 != e as u64)
    {
        return Err(ConvertError::Shape {
            path: src.path.clone(),
            tensor: name.to_string(),
            expected: expected.to_vec(),
            found: found.to_vec(),
        });
    }
    let values = upcast(view).ok_or_else(|| ConvertError::Dtype {
        path: src.path.clone(),
        tensor: name.to_string(),
        found: format!("{:?}", view.dtype()),
    })?;
    for (idx, &v) in values.iter().enumerate() {
        let (i, j) = ((idx as u64) / len, (idx as u64) % len);
        let on = match band {
            Some(b) => i.abs_diff(j) <= b,
            None => j <= i,
        };
        if v != if on { 1.0 } else { 0.0 } {
            return Err(ConvertError::Mask {
                path: src.path.clone(),
                tensor: name.to_string(),
                row: i,
                col: j,
                expected: if on { 1.0 } else { 0.0 },
                found: v,
            });
        }
    }
    Ok(())
}
