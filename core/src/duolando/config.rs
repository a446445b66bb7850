//! Model configuration: every size the engine needs, read from the `.duo`
//! header (and, by the converter, from the original YAML files).
//!
//! Field names follow the original YAML keys where one exists
//! (`n_embd`, `n_head`, `block_size`, `look_forward`, `width`, `depth`,
//! `emb_width`, `l_bins`, `downs_t`, `strides_t`, `dilation_growth_rate`).
//! Everything the sibling models (Bailando, see DESIGN.md §7) vary is a
//! field here, not code: stream count, downsampling stages, final LayerNorm,
//! look-ahead.

use serde::{Deserialize, Serialize};

pub use crate::nn::vq_config::VqConfig;

/// One Look-Ahead Transformer (music LAT or a leader LAT; `MusicTrans` in
/// the original code): `Linear(n_in -> n_embd)`, `n_layer` pre-LN blocks
/// with the band mask `|i-j| <= look_forward * downsample_rate`, no
/// position embedding, then `downsample_rate` consecutive rows concatenated
/// -> `Linear(n_embd*downsample_rate -> n_embd)`; the last `look_forward`
/// output rows are dropped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LatConfig {
    /// Input width (`n_music`: 54 for music; n_embd for leader token embeddings).
    pub n_in: u32,
    pub n_layer: u32,
    pub n_head: u32,
    /// Input rows per output token (`downsample_rate`: 4 for music, 1 for leaders).
    pub downsample_rate: u32,
}

/// The follower GPT (`GPT2nt`): LATs + base blocks + head blocks + 5 heads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GptConfig {
    pub n_embd: u32,
    /// Heads of the coordinated-attention blocks (base and head).
    pub n_head: u32,
    pub n_layer_base: u32,
    pub n_layer_head: u32,
    /// Tokens per stream in the window (`block_size`, 30); the follower
    /// context is at most `block_size - 1` tokens.
    pub block_size: u32,
    /// Leader/music look-ahead in tokens (`look_forward`, 29).
    pub look_forward: u32,
    /// Vocabulary of each follower/leader stream: up, down, lhand, rhand, transl.
    pub vocab: [u32; 5],
    pub music: LatConfig,
    /// One config shared by the four leader LATs (up, down, lhand, rhand).
    pub leader: LatConfig,
    /// Number of streams in the coordinated attention (10 for Duolando).
    pub n_streams: u32,
    /// Final LayerNorm before the heads (false for Duolando's GPT2nt).
    pub final_ln: bool,
}

/// The whole inference path: GPT + four part VQ-VAEs + translation VQ-VAE.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelConfig {
    pub gpt: GptConfig,
    /// Part VQ-VAEs in token-stream order: up, down, lhand, rhand.
    pub parts: [VqConfig; 4],
    /// Relative-translation VQ-VAE (3 input channels, no rotation decoder).
    pub transl: VqConfig,
    /// Music feature frames per motion token (`music_motion_rate`, 4).
    pub music_motion_rate: u32,
}

impl ModelConfig {
    /// Every VQ-VAE config: the four parts (up, down, lhand, rhand), then
    /// the translation.
    pub fn vqs(&self) -> [VqConfig; 5] {
        [
            self.parts[0],
            self.parts[1],
            self.parts[2],
            self.parts[3],
            self.transl,
        ]
    }
}

/// Body parts in token-stream order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Part {
    Up = 0,
    Down = 1,
    LHand = 2,
    RHand = 3,
}

impl Part {
    pub const ALL: [Part; 4] = [Part::Up, Part::Down, Part::LHand, Part::RHand];
    /// Name used in the original module names (`vqvae_up`, `leader_up_trans`, `tok_emb_up`).
    pub const fn name(self) -> &'static str {
        match self {
            Part::Up => "up",
            Part::Down => "down",
            Part::LHand => "lhand",
            Part::RHand => "rhand",
        }
    }
    /// SMPL-X joint indices of the part, channel order = list order (xyz interleaved).
    pub const fn joints(self) -> &'static [u8] {
        match self {
            Part::Down => &[0, 1, 2, 4, 5, 7, 8, 10, 11],
            Part::Up => &[3, 6, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24],
            Part::LHand => &[25, 26, 27, 28, 29, 30, 31, 32, 33, 34, 35, 36, 37, 38, 39],
            Part::RHand => &[40, 41, 42, 43, 44, 45, 46, 47, 48, 49, 50, 51, 52, 53, 54],
        }
    }
}

/// SMPL-X joints used by Duolando.
pub const N_JOINTS: usize = 55;
/// Floats per pose row (`pos3d`): 55 joints x xyz.
pub const POSE_DIM: usize = N_JOINTS * 3;
/// Floats per rotation row: 55 row-major 3x3 matrices.
pub const ROT_DIM: usize = N_JOINTS * 9;
