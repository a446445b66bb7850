//! Bailando's configuration: the actor GPT (`CrossCondGPT2`, the YAML's
//! `structure_generate` base/head) and the two VQ-VAEs of `SepVQVAER`
//! (`structure` up_half/down_half). The critic is training-only and has
//! no config here.

use serde::{Deserialize, Serialize};

use crate::duolando::config::Part;
use crate::limits::*;
use crate::nn::vq_config::VqConfig;

/// SMPL joints of a Bailando pose (positions, xyz per joint).
pub const N_JOINTS: usize = 24;
/// Floats per pose row: 24 joints x xyz.
pub const POSE_DIM: usize = N_JOINTS * 3;
/// Motion frame rate (AIST++ at 60 fps).
pub const FPS: u32 = 60;
/// Joints of the up half, channel order = list order (`smpl_up`).
pub const UP_JOINTS: [u8; 15] = [3, 6, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23];
/// Joints of the down half (`smpl_down`); joint 0 (the pelvis) is zeroed
/// before encoding and its slot decodes the root velocity.
pub const DOWN_JOINTS: [u8; 9] = [0, 1, 2, 4, 5, 7, 8, 10, 11];
/// Number of token streams: music, up, down.
pub const N_STREAMS: usize = 3;

/// The actor GPT (`CrossCondGPTBase` + `CrossCondGPTHead`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GptConfig {
    pub n_embd: u32,
    pub n_head: u32,
    pub n_layer_base: u32,
    pub n_layer_head: u32,
    /// `block_size`: rows per stream in `pos_emb`; the window holds at
    /// most `block_size - 1` tokens.
    pub block_size: u32,
    /// Vocabulary of the up and down streams.
    pub vocab: [u32; 2],
    /// Music feature width read by `cond_emb` (`n_music`, 438 published).
    pub n_music: u32,
}

/// The whole inference path: GPT + up and down VQ-VAEs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct BailandoConfig {
    pub gpt: GptConfig,
    /// `up_half` (45 channels) and `down_half` (27 channels, plus the
    /// root-velocity decoder); both have no rotation decoder.
    pub parts: [VqConfig; 2],
}

impl BailandoConfig {
    /// Frames per token.
    pub fn hop(&self) -> usize {
        self.parts[0].hop().unwrap_or(0) as usize
    }

    /// Both VQ-VAE configs (up, down).
    pub fn vqs(&self) -> [VqConfig; 2] {
        self.parts
    }

    /// Checks every size against the engine's caps and the model's own
    /// rules (head split, channel counts, equal hops, vocabulary = codebook).
    pub fn validate(&self) -> Result<(), ConfigError> {
        let g = &self.gpt;
        range(ConfigField::NEmbd, g.n_embd, 1, MAX_EMBD)?;
        range(ConfigField::NHead, g.n_head, 1, MAX_HEADS)?;
        divisible(ConfigField::NEmbd, g.n_embd, g.n_head)?;
        range(ConfigField::NLayerBase, g.n_layer_base, 0, MAX_GPT_LAYERS)?;
        range(ConfigField::NLayerHead, g.n_layer_head, 1, MAX_GPT_LAYERS)?;
        range(ConfigField::BlockSize, g.block_size, 2, MAX_BLOCK_SIZE)?;
        range(ConfigField::NMusic, g.n_music, 1, MAX_MUSIC_DIM)?;
        let channels = [(UP_JOINTS.len() * 3) as u32, (DOWN_JOINTS.len() * 3) as u32];
        for (i, part) in [Part::Up, Part::Down].into_iter().enumerate() {
            self.parts[i].validate(VqWhich::Part(part), channels[i], 0)?;
            range(ConfigField::Vocab(i as u8), g.vocab[i], 1, MAX_VOCAB)?;
            equal(
                ConfigField::Vocab(i as u8),
                g.vocab[i],
                self.parts[i].l_bins,
            )?;
        }
        let hop = self.parts[0].hop().unwrap_or(0);
        equal(
            ConfigField::Vq(VqWhich::Part(Part::Down), VqField::Hop),
            self.parts[1].hop().unwrap_or(0),
            hop,
        )?;
        Ok(())
    }
}

/// The published model (the authors' `configs/actor_critic.yaml`): actor
/// GPT n_embd 768, 12 heads, 6 + 6 layers, block_size 29, vocabularies 512,
/// 438 music features; VQ-VAEs width 512, depth 3, dilation growth 3, three
/// stride-2 stages (8 frames per token), 512 codes of 512.
pub fn published() -> BailandoConfig {
    let vq = |in_channels| VqConfig {
        in_channels,
        rot_channels: 0,
        width: 512,
        depth: 3,
        dilation_growth_rate: 3,
        down_t: 3,
        stride_t: 2,
        emb_width: 512,
        l_bins: 512,
        m_conv_num: 1,
        m_conv_den: 1,
    };
    BailandoConfig {
        gpt: GptConfig {
            n_embd: 768,
            n_head: 12,
            n_layer_base: 6,
            n_layer_head: 6,
            block_size: 29,
            vocab: [512, 512],
            n_music: 438,
        },
        parts: [
            vq((UP_JOINTS.len() * 3) as u32),
            vq((DOWN_JOINTS.len() * 3) as u32),
        ],
    }
}
