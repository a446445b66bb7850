//! The latency budget of a Bailando streaming session and the arithmetic
//! its parts share (docs/BAILANDO.md "S mode").
//!
//! Bailando's GPT is causal in the music (step `k` reads music row `k + 1`
//! and makes token `k + 1`), so a session has no music look-ahead to
//! choose. Its two approximations of R are the GPT window schedule (R's
//! window slides every step, which re-runs the whole window; S keeps the
//! window's keys and values and jumps the window by `block_size - shift`
//! tokens at a time, `nn::window`) and the VQ decoders' future (R decodes
//! the whole token sequence; S gives a token's frames once `dec_future`
//! later tokens exist).

use crate::bailando::config::BailandoConfig;
use crate::error::Setting;
use crate::nn::kv_store::KvType;
pub use crate::nn::sampler::Sampling;
use crate::nn::stream_conv::{future_max, StackKind};
pub use crate::nn::window::CacheSchedule;

/// Largest `pending_frames` / `music_buffer_rows` (keeps every size far
/// from overflow).
pub const MAX_BUFFER: u32 = 1 << 15;

/// Everything that shapes a session. Counts are tokens (8 frames at the
/// published hop) unless named frames or rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SessionConfig {
    /// `d`: decoder future context, `0..=dec_future_max`. At the maximum
    /// a token's frames are R's (given the same tokens).
    pub dec_future: u32,
    /// `s`: window shift, `1..=block_size - 1`. `block_size - 1` is R's
    /// sliding window (every step re-runs the window); smaller shifts keep
    /// the window's keys and values between jumps.
    pub shift: u32,
    pub sampling: Sampling,
    /// Decoded frames that may wait unpulled: with more waiting, no step
    /// runs (`step` answers `Ok(None)`; pull first).
    pub pending_frames: u32,
    /// Music rows that may wait pushed and not yet read by a step before
    /// `push_music` answers `Backlog` (a whole track pushed ahead needs
    /// as many as it has rows).
    pub music_buffer_rows: u32,
    /// Element type of the GPT K/V cache (f16: half the cache bytes).
    pub kv: KvType,
    /// `Reprefill` (one cache, re-run at each window jump: a spike of
    /// `shift - 1` rows) or `Spread` (two caches: the next window's rows
    /// appended a few per step before its jump, in the same pass over the
    /// weights; the same numbers). `Staggered` is Duolando's only.
    pub schedule: CacheSchedule,
}

/// Named budgets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// R's numbers: sliding window, full decoder future (the slowest S:
    /// every step re-runs the window, as R's step does).
    Exact,
    /// Full decoder future, window shift `round(21 m / 28)` (21 of 28 at
    /// the published size; Duolando's presets took 22 of 29 until
    /// 2026-12-07, now 15). Bailando keeps the closer shift: its GPT rows
    /// are cheap next to its step's weight read (at 15 the spread step is
    /// 22 % faster), and at 15 the demo clip's one-step agreement with R
    /// fell from 0.997 to 0.957 (docs/BAILANDO.md).
    Reference,
    /// Decoder future 2 tokens (a token's frames come 2 tokens later).
    Interactive,
    /// Decoder future 0: a token's frames as soon as it exists.
    Minimum,
}

impl Preset {
    pub const ALL: [Preset; 4] = [
        Preset::Exact,
        Preset::Reference,
        Preset::Interactive,
        Preset::Minimum,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Preset::Exact => "exact",
            Preset::Reference => "reference",
            Preset::Interactive => "interactive",
            Preset::Minimum => "minimum",
        }
    }

    pub fn from_name(name: &str) -> Option<Preset> {
        Preset::ALL.into_iter().find(|p| p.name() == name)
    }
}

/// Window rows of the GPT (`block_size - 1`).
pub fn window_rows(cfg: &BailandoConfig) -> usize {
    (cfg.gpt.block_size as usize).saturating_sub(1)
}

/// Decoder future at which S's frames equal R's (max over the up, down
/// and root decoders; the root decoder has the down half's geometry).
pub fn dec_future_max(cfg: &BailandoConfig) -> u32 {
    cfg.parts
        .iter()
        .map(|vq| future_max(vq, StackKind::Decoder))
        .max()
        .unwrap_or(0) as u32
}

impl SessionConfig {
    /// A budget: decoder future `dec_future`, window shift `shift`, greedy,
    /// f32 K/V, the spread schedule (no re-prefill spike after the first
    /// jump; the same numbers as `Reprefill`, which holds one cache less),
    /// 64 pending frames, 64 music rows ahead.
    pub fn with(dec_future: u32, shift: u32) -> Self {
        SessionConfig {
            dec_future,
            shift,
            sampling: Sampling::Greedy,
            pending_frames: 64,
            music_buffer_rows: 64,
            kv: KvType::F32,
            schedule: CacheSchedule::Spread,
        }
    }

    pub fn preset(cfg: &BailandoConfig, preset: Preset) -> Self {
        let m = window_rows(cfg) as u32;
        let dmax = dec_future_max(cfg);
        let shift = ((21 * m + 14) / 28).clamp(1, m.max(1));
        match preset {
            // The window slides every step: every step re-prefills (R's
            // cost), so a second cache would spread nothing.
            Preset::Exact => SessionConfig {
                schedule: CacheSchedule::Reprefill,
                ..Self::with(dmax, m.max(1))
            },
            Preset::Reference => Self::with(dmax, shift),
            Preset::Interactive => Self::with(2.min(dmax), shift),
            Preset::Minimum => Self::with(0, shift),
        }
    }

    /// `(setting, value, max)` of the first setting outside its range.
    pub fn check(&self, cfg: &BailandoConfig) -> Result<(), (Setting, u32, u32)> {
        let range = |s: Setting, v: u32, lo: u32, hi: u32| {
            if v < lo || v > hi {
                Err((s, v, hi))
            } else {
                Ok(())
            }
        };
        range(Setting::DecFuture, self.dec_future, 0, dec_future_max(cfg))?;
        range(Setting::Shift, self.shift, 1, window_rows(cfg) as u32)?;
        if let Some(k) = self.sampling.k() {
            range(Setting::TopK, k, 1, cfg.gpt.vocab[0].min(cfg.gpt.vocab[1]))?;
        }
        self.sampling.check()?;
        range(Setting::PendingFrames, self.pending_frames, 0, MAX_BUFFER)?;
        range(Setting::MusicBuffer, self.music_buffer_rows, 1, MAX_BUFFER)?;
        if self.schedule == CacheSchedule::Staggered {
            return Err((Setting::Windows, 0, 0));
        }
        Ok(())
    }

    /// Frames between a frame's time and the music row that lets the
    /// session give it, at most: frame `f` (of token `f / hop`) is final
    /// once music row `f / hop + dec_future` is pushed, at frame time
    /// `hop (f / hop + dec_future) <= f + hop dec_future`. The music
    /// features' own look-ahead comes on top (docs/MUSIC.md).
    pub fn latency_frames(&self, hop: u32) -> u32 {
        hop * self.dec_future
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_check_and_name_themselves() {
        let cfg = crate::bailando::config::published();
        assert_eq!(window_rows(&cfg), 28);
        let dmax = dec_future_max(&cfg);
        assert!(dmax > 0);
        for p in Preset::ALL {
            assert_eq!(Preset::from_name(p.name()), Some(p));
            assert!(SessionConfig::preset(&cfg, p).check(&cfg).is_ok(), "{p:?}");
        }
        assert_eq!(SessionConfig::preset(&cfg, Preset::Reference).shift, 21);
        assert_eq!(SessionConfig::preset(&cfg, Preset::Exact).shift, 28);
        assert_eq!(
            SessionConfig::preset(&cfg, Preset::Minimum).latency_frames(8),
            0
        );
        assert_eq!(
            SessionConfig::with(dmax + 1, 5).check(&cfg),
            Err((Setting::DecFuture, dmax + 1, dmax))
        );
        assert_eq!(
            SessionConfig::with(0, 29).check(&cfg),
            Err((Setting::Shift, 29, 28))
        );
        assert_eq!(
            SessionConfig::with(0, 0).check(&cfg),
            Err((Setting::Shift, 0, 28))
        );
    }
}
