//! Validation of a Duolando [`ModelConfig`] (caps and field names:
//! [`crate::limits`]): the head split, the stream count, the vocabulary
//! quirk of the original heads, and every VQ-VAE's channels.

use crate::duolando::config::{GptConfig, LatConfig, ModelConfig, Part};
use crate::limits::*;

impl LatConfig {
    fn validate(&self, which: LatWhich, n_embd: u32) -> Result<(), ConfigError> {
        let f = |v| ConfigField::Lat(which, v);
        range(f(LatField::NIn), self.n_in, 1, MAX_MUSIC_DIM)?;
        range(f(LatField::NLayer), self.n_layer, 1, MAX_LAT_LAYERS)?;
        range(f(LatField::NHead), self.n_head, 1, MAX_HEADS)?;
        divisible(ConfigField::NEmbd, n_embd, self.n_head)?;
        range(
            f(LatField::DownsampleRate),
            self.downsample_rate,
            1,
            MAX_DOWNSAMPLE,
        )?;
        Ok(())
    }
}

impl GptConfig {
    fn validate(&self) -> Result<(), ConfigError> {
        range(ConfigField::NEmbd, self.n_embd, 1, MAX_EMBD)?;
        range(ConfigField::NHead, self.n_head, 1, MAX_HEADS)?;
        divisible(ConfigField::NEmbd, self.n_embd, self.n_head)?;
        range(
            ConfigField::NLayerBase,
            self.n_layer_base,
            1,
            MAX_GPT_LAYERS,
        )?;
        range(
            ConfigField::NLayerHead,
            self.n_layer_head,
            1,
            MAX_GPT_LAYERS,
        )?;
        // The follower context is block_size - 1 tokens: at least one.
        range(ConfigField::BlockSize, self.block_size, 2, MAX_BLOCK_SIZE)?;
        // The original drops the last `look_forward` LAT rows with
        // `x[:, :-look_forward]`, which is empty for 0: at least one.
        range(
            ConfigField::LookForward,
            self.look_forward,
            1,
            MAX_LOOK_FORWARD,
        )?;
        for (i, &v) in self.vocab.iter().enumerate() {
            range(ConfigField::Vocab(i as u8), v, 1, MAX_VOCAB)?;
        }
        // Quirks of the original heads and tables: head_lhand has
        // vocab_up rows, head_rhand vocab_down rows, and follower
        // right-hand tokens index the LEFT-hand embedding table. Every
        // produced token must index every table it reaches.
        equal(ConfigField::Vocab(2), self.vocab[2], self.vocab[0])?;
        equal(ConfigField::Vocab(3), self.vocab[3], self.vocab[1])?;
        if self.vocab[1] > self.vocab[2] {
            return Err(ConfigError::TooLarge {
                field: ConfigField::Vocab(1),
                value: self.vocab[1],
                max: self.vocab[2],
            });
        }
        if self.n_streams != DUOLANDO_STREAMS {
            return Err(ConfigError::Unsupported {
                field: ConfigField::NStreams,
                value: self.n_streams,
            });
        }
        if self.final_ln {
            return Err(ConfigError::Unsupported {
                field: ConfigField::FinalLn,
                value: 1,
            });
        }
        self.music.validate(LatWhich::Music, self.n_embd)?;
        self.leader.validate(LatWhich::Leader, self.n_embd)?;
        // Leader LATs read token embeddings, one row per token.
        equal(
            ConfigField::Lat(LatWhich::Leader, LatField::NIn),
            self.leader.n_in,
            self.n_embd,
        )?;
        equal(
            ConfigField::Lat(LatWhich::Leader, LatField::DownsampleRate),
            self.leader.downsample_rate,
            1,
        )?;
        Ok(())
    }
}

impl ModelConfig {
    /// Checks every size and cross-constraint the engine relies on. The
    /// `.duo` decoder calls this before trusting a header; [`crate::duolando::model`]
    /// and every `*_scratch_bytes` assume it passed.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.gpt.validate()?;
        for (i, part) in Part::ALL.iter().enumerate() {
            let joints = part.joints().len() as u32;
            self.parts[i].validate(VqWhich::Part(*part), 3 * joints, 9 * joints)?;
            equal(
                ConfigField::Vocab(i as u8),
                self.gpt.vocab[i],
                self.parts[i].l_bins,
            )?;
        }
        self.transl.validate(VqWhich::Transl, 3, 0)?;
        equal(ConfigField::Vocab(4), self.gpt.vocab[4], self.transl.l_bins)?;
        // Every stream advances one token per `hop` frames, and the music
        // LAT folds `downsample_rate` frames into one token: all equal.
        let hop = self.parts[0].hop().unwrap_or(0);
        for (i, part) in Part::ALL.iter().enumerate() {
            let h = self.parts[i].hop().unwrap_or(0);
            equal(ConfigField::Vq(VqWhich::Part(*part), VqField::Hop), h, hop)?;
        }
        equal(
            ConfigField::Vq(VqWhich::Transl, VqField::Hop),
            self.transl.hop().unwrap_or(0),
            hop,
        )?;
        equal(
            ConfigField::Lat(LatWhich::Music, LatField::DownsampleRate),
            self.gpt.music.downsample_rate,
            hop,
        )?;
        range(
            ConfigField::MusicMotionRate,
            self.music_motion_rate,
            1,
            MAX_MUSIC_MOTION_RATE,
        )?;
        Ok(())
    }

    /// Frames per token (the common `hop` of every VQ-VAE; valid after
    /// [`ModelConfig::validate`]).
    pub fn hop(&self) -> usize {
        self.parts[0].hop().unwrap_or(1) as usize
    }
}
