//! Configs of the published model (the authors' YAML files
//! `follower_gpt_beta0.9_final.yaml`, `sep_vqvaexm_full_final.yaml`,
//! `transl_vqvaex_final.yaml`), for tests, docs and size planning.

use crate::duolando::config::{GptConfig, LatConfig, ModelConfig, Part};
use crate::nn::vq_config::VqConfig;

/// A part or translation VQ-VAE of the published model (width 512, depth 3,
/// growth 3, one stride-2 stage pair, 512 x 512 codebook).
pub const fn published_vq(in_channels: u32, rot_channels: u32) -> VqConfig {
    VqConfig {
        in_channels,
        rot_channels,
        width: 512,
        depth: 3,
        dilation_growth_rate: 3,
        down_t: 2,
        stride_t: 2,
        emb_width: 512,
        l_bins: 512,
        m_conv_num: 1,
        m_conv_den: 1,
    }
}

/// The published Duolando follower model (GPT 768 wide, 6 + 6 blocks,
/// 3-block LATs, block_size 30, look_forward 29).
pub fn duolando_published() -> ModelConfig {
    let part = |p: Part| {
        let j = p.joints().len() as u32;
        published_vq(3 * j, 9 * j)
    };
    ModelConfig {
        gpt: GptConfig {
            n_embd: 768,
            n_head: 12,
            n_layer_base: 6,
            n_layer_head: 6,
            block_size: 30,
            look_forward: 29,
            vocab: [512; 5],
            music: LatConfig {
                n_in: 54,
                n_layer: 3,
                n_head: 12,
                downsample_rate: 4,
            },
            leader: LatConfig {
                n_in: 768,
                n_layer: 3,
                n_head: 12,
                downsample_rate: 1,
            },
            n_streams: 10,
            final_ln: false,
        },
        parts: [
            part(Part::Up),
            part(Part::Down),
            part(Part::LHand),
            part(Part::RHand),
        ],
        transl: published_vq(3, 0),
        music_motion_rate: 4,
    }
}
