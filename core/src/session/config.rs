//! The latency budget of a streaming session (docs/STREAMING.md §2) and
//! the arithmetic every part of S shares: step readiness, window
//! schedule, latency in frames.

use crate::config::ModelConfig;
use crate::stream_conv::{future_max, StackKind};

/// How the follower token of each head is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sampling {
    /// Argmax, lowest id on ties. No RNG draw.
    Greedy,
    /// Uniform over the `k` largest logits (the original `samplek`), the
    /// set sorted by id (docs/STREAMING.md §3.6); SplitMix64 seeded with
    /// `rng_seed`, 5 draws per step.
    TopK { k: u32, rng_seed: u64 },
}

/// Everything that shapes a session: its latency budget, window policy,
/// sampling and buffer capacities. All counts are tokens (4 frames)
/// unless named frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SessionConfig {
    /// `a`: leader look-ahead of the first LAT layer, `0..=look_forward`.
    pub lookahead: u32,
    /// `e`: encoder future context, `0..=enc_future_max`.
    pub enc_future: u32,
    /// `d`: decoder future context, `0..=dec_future_max`.
    pub dec_future: u32,
    /// `s`: chunk shift of the GPT window, `1..=block_size - 1`.
    pub shift: u32,
    /// `a_m`: music look-ahead, `0..=look_forward`.
    pub music_lookahead: u32,
    /// Past band of every LAT layer in tokens, `0..=look_forward` (the
    /// original band is `look_forward`).
    pub lat_past: u32,
    pub sampling: Sampling,
    /// Follower frames the caller may leave unpulled beyond the latency
    /// before `push_leader_frame` answers `Backlog`.
    pub pending_frames: u32,
    /// Music frames that may wait in the session (pushed, not yet read by
    /// the music LAT) before `push_music_frame` answers `Backlog`.
    pub music_buffer_frames: u32,
}

/// A setting outside its range (`Error::Setting`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Setting {
    Lookahead,
    EncFuture,
    DecFuture,
    Shift,
    MusicLookahead,
    LatPast,
    TopK,
    PendingFrames,
    MusicBuffer,
}

/// Largest `pending_frames` / `music_buffer_frames` (keeps every size far
/// from overflow; about 18 minutes at 30 fps).
pub const MAX_BUFFER_FRAMES: u32 = 1 << 15;

/// Encoder future context at which S's leader codes equal R's (max over parts).
pub fn enc_future_max(cfg: &ModelConfig) -> u32 {
    cfg.parts.iter().map(|p| future_max(p, StackKind::Encoder) as u32).max().unwrap_or(0)
}

/// Decoder future context at which S's frames equal R's (max over the 4
/// parts and the translation).
pub fn dec_future_max(cfg: &ModelConfig) -> u32 {
    cfg.parts.iter().chain(core::iter::once(&cfg.transl)).map(|p| future_max(p, StackKind::Decoder) as u32).max().unwrap_or(0)
}

impl SessionConfig {
    /// The reference-quality budget (closest to R): `a = a_m = look_forward`,
    /// `e`, `d` at their maxima, shift 22 for block size 30 (scaled as
    /// `round(22 (bs-1) / 29)` for other block sizes).
    pub fn reference(cfg: &ModelConfig) -> Self {
        let m = cfg.gpt.block_size.saturating_sub(1).max(1);
        let shift = ((22 * m + 14) / 29).clamp(1, m);
        let lf = cfg.gpt.look_forward;
        Self::with(cfg, lf, enc_future_max(cfg), dec_future_max(cfg), shift)
    }

    /// The smallest budget: no leader look-ahead, no encoder or decoder
    /// future (latency 0 frames); the reference shift; music look-ahead kept
    /// (music is usually known ahead).
    pub fn minimum(cfg: &ModelConfig) -> Self {
        let r = Self::reference(cfg);
        Self::with(cfg, 0, 0, 0, r.shift)
    }

    /// A budget with defaults for everything else.
    pub fn with(cfg: &ModelConfig, lookahead: u32, enc_future: u32, dec_future: u32, shift: u32) -> Self {
        let lf = cfg.gpt.look_forward;
        SessionConfig {
            lookahead,
            enc_future,
            dec_future,
            shift,
            music_lookahead: lf,
            lat_past: lf,
            sampling: Sampling::Greedy,
            pending_frames: 64,
            music_buffer_frames: 4 * (2 * lf + 2 * enc_future_max(cfg) + 8),
        }
    }

    /// Checks every setting against the model. `Err((setting, value, max))`.
    pub fn check(&self, cfg: &ModelConfig) -> Result<(), (Setting, u32, u32)> {
        let lf = cfg.gpt.look_forward;
        let m = cfg.gpt.block_size.saturating_sub(1);
        let range = |s: Setting, v: u32, lo: u32, hi: u32| if v < lo || v > hi { Err((s, v, hi)) } else { Ok(()) };
        range(Setting::Lookahead, self.lookahead, 0, lf)?;
        range(Setting::EncFuture, self.enc_future, 0, enc_future_max(cfg))?;
        range(Setting::DecFuture, self.dec_future, 0, dec_future_max(cfg))?;
        range(Setting::Shift, self.shift, 1, m)?;
        range(Setting::MusicLookahead, self.music_lookahead, 0, lf)?;
        range(Setting::LatPast, self.lat_past, 0, lf)?;
        if let Sampling::TopK { k, .. } = self.sampling {
            range(Setting::TopK, k, 1, crate::sampler::MAX_TOP_K as u32)?;
        }
        range(Setting::PendingFrames, self.pending_frames, 0, MAX_BUFFER_FRAMES)?;
        // The music LAT reads 4 frames per step ahead of what it has consumed.
        let min_music = 4 * cfg.music_motion_rate;
        range(Setting::MusicBuffer, self.music_buffer_frames, min_music, MAX_BUFFER_FRAMES)?;
        Ok(())
    }

    /// Delay between a leader frame and the follower frame of the same
    /// index, with music known ahead: `max(0, 4(a+e+d) - 1)` frames
    /// (docs/STREAMING.md §2). `hop` = frames per token.
    pub fn latency_frames(&self, hop: u32) -> u32 {
        (hop * (self.lookahead + self.enc_future + self.dec_future)).saturating_sub(1)
    }
}

/// Context length of GPT step `k` under the authors' chunked window
/// (`sample(shift=s)`): `k+1` for `k < m`, then
/// `s + (k - m - 1) mod (m - s + 1)` (Python modulo).
pub fn window_context(k: usize, m: usize, s: usize) -> usize {
    if k < m {
        return k + 1;
    }
    let period = (m + 1).saturating_sub(s).max(1) as i64;
    let r = (k as i64 - m as i64 - 1).rem_euclid(period);
    s + r as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_schedule_matches_the_reference_formula() {
        // m = 29, s = 22: 1..29 on steps 0..28, 29 at step 29, then chunks of 8 from 22.
        let c: [usize; 40] = core::array::from_fn(|k| window_context(k, 29, 22));
        assert_eq!(&c[..29], &core::array::from_fn::<usize, 29, _>(|k| k + 1));
        assert_eq!(c[29], 29);
        assert_eq!(&c[30..40], &[22, 23, 24, 25, 26, 27, 28, 29, 22, 23]);
        // s = m: sliding window.
        assert!((29..100).all(|k| window_context(k, 29, 29) == 29));
    }
}
