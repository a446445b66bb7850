//! The model families and the one place that dispatches on them: a `.duo`
//! file's config is a [`FamilyConfig`]; the format's schema check, the
//! converters and the host interfaces ask it for the family's tensors,
//! skeleton and music width, and bind the family's own `Model` from it.

use serde::{Deserialize, Serialize};

use crate::bailando::config::BailandoConfig;
use crate::duolando::config::ModelConfig;
use crate::limits::ConfigError;
use crate::nn::names::{SchemaError, TensorSpec};
use crate::transflower::config::{ConfigError as TransflowerConfigError, TransflowerConfig};

/// A model family (one per paper). The discriminant is the family's tag in
/// a version-2 `.duo` header (docs/FORMAT.md §2) and in the C ABI.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum Family {
    /// Duolando (ICLR 2024): a follower dancing with a leader to music.
    Duolando = 0,
    /// Bailando (CVPR 2022): a solo dancer to music.
    Bailando = 1,
    /// Transflower (SIGGRAPH Asia 2021): a solo dancer's pose features
    /// from music (and a motion seed), sampled by a normalizing flow.
    Transflower = 2,
}

impl Family {
    /// Every family this build reads, in tag order.
    pub const ALL: [Family; 3] = [Family::Duolando, Family::Bailando, Family::Transflower];

    pub const fn name(self) -> &'static str {
        match self {
            Family::Duolando => "Duolando",
            Family::Bailando => "Bailando",
            Family::Transflower => "Transflower",
        }
    }

    /// The family of a header tag, None for a tag this build does not know.
    pub const fn from_tag(tag: u32) -> Option<Family> {
        match tag {
            0 => Some(Family::Duolando),
            1 => Some(Family::Bailando),
            2 => Some(Family::Transflower),
            _ => None,
        }
    }

    /// Joints of the family's skeleton (SMPL-X 55 for Duolando, SMPL 24 for
    /// Bailando); 0 for Transflower, whose motion is a feature vector of a
    /// config-dependent width (`douts`: the authors' expmap features), not
    /// joint positions.
    pub const fn joints(self) -> usize {
        match self {
            Family::Duolando => crate::duolando::config::N_JOINTS,
            Family::Bailando => crate::bailando::config::N_JOINTS,
            Family::Transflower => 0,
        }
    }

    /// Motion frames per second.
    pub const fn fps(self) -> u32 {
        match self {
            Family::Duolando => 30,
            Family::Bailando => crate::bailando::config::FPS,
            Family::Transflower => crate::transflower::config::FPS,
        }
    }

    /// Whether the family dances with a leader (takes leader frames).
    pub const fn has_leader(self) -> bool {
        matches!(self, Family::Duolando)
    }
}

/// A family's whole configuration, as a version-2 `.duo` header holds it
/// (postcard: the family tag as a varint, then that family's config).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum FamilyConfig {
    Duolando(ModelConfig),
    Bailando(BailandoConfig),
    Transflower(TransflowerConfig),
}

/// Why a family's config was refused by [`FamilyConfig::validate`]: the
/// shared caps (Duolando, Bailando) or Transflower's own checks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FamilyConfigError {
    Config(ConfigError),
    Transflower(TransflowerConfigError),
}

impl FamilyConfig {
    pub fn family(&self) -> Family {
        match self {
            FamilyConfig::Duolando(_) => Family::Duolando,
            FamilyConfig::Bailando(_) => Family::Bailando,
            FamilyConfig::Transflower(_) => Family::Transflower,
        }
    }

    /// The family's own validation (caps, head split, channel counts).
    pub fn validate(&self) -> Result<(), FamilyConfigError> {
        match self {
            FamilyConfig::Duolando(c) => c.validate().map_err(FamilyConfigError::Config),
            FamilyConfig::Bailando(c) => c.validate().map_err(FamilyConfigError::Config),
            FamilyConfig::Transflower(c) => c.validate().map_err(FamilyConfigError::Transflower),
        }
    }

    /// The tensors the family's schema lists for this config.
    pub fn for_each_tensor<E: From<SchemaError>>(
        &self,
        f: &mut dyn FnMut(&TensorSpec) -> Result<(), E>,
    ) -> Result<(), E> {
        match self {
            FamilyConfig::Duolando(c) => crate::duolando::schema::for_each_tensor(c, f),
            FamilyConfig::Bailando(c) => crate::bailando::schema::for_each_tensor(c, f),
            FamilyConfig::Transflower(c) => crate::transflower::schema::for_each_tensor(c, f),
        }
    }

    /// Number of tensors the config needs.
    pub fn tensor_count(&self) -> usize {
        match self {
            FamilyConfig::Duolando(c) => crate::duolando::schema::tensor_count(c),
            FamilyConfig::Bailando(c) => crate::bailando::schema::tensor_count(c),
            FamilyConfig::Transflower(c) => crate::transflower::schema::tensor_count(c),
        }
    }

    /// Music features per frame the model reads (Transflower: the width of
    /// its last input, the audio features in every published config).
    pub fn music_features(&self) -> u32 {
        match self {
            FamilyConfig::Duolando(c) => c.gpt.music.n_in,
            FamilyConfig::Bailando(c) => c.gpt.n_music,
            FamilyConfig::Transflower(c) => c.inputs().last().map_or(0, |i| i.dim),
        }
    }

    pub fn duolando(&self) -> Option<&ModelConfig> {
        match self {
            FamilyConfig::Duolando(c) => Some(c),
            _ => None,
        }
    }

    pub fn bailando(&self) -> Option<&BailandoConfig> {
        match self {
            FamilyConfig::Bailando(c) => Some(c),
            _ => None,
        }
    }

    pub fn transflower(&self) -> Option<&TransflowerConfig> {
        match self {
            FamilyConfig::Transflower(c) => Some(c),
            _ => None,
        }
    }
}

impl From<ModelConfig> for FamilyConfig {
    fn from(c: ModelConfig) -> Self {
        FamilyConfig::Duolando(c)
    }
}

impl From<BailandoConfig> for FamilyConfig {
    fn from(c: BailandoConfig) -> Self {
        FamilyConfig::Bailando(c)
    }
}

impl From<TransflowerConfig> for FamilyConfig {
    fn from(c: TransflowerConfig) -> Self {
        FamilyConfig::Transflower(c)
    }
}
