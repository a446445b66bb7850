//! The latency budget of a streaming session (docs/STREAMING.md §2) and
//! the arithmetic every part of S shares: step readiness, window
//! schedule, latency in frames.

use crate::duolando::config::ModelConfig;
use crate::nn::kv_store::KvType;
use crate::nn::stream_conv::{future_max, StackKind};

pub use crate::nn::sampler::Sampling;

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
    /// Slack of the backlog rule: `push_leader_frame` answers `Backlog`
    /// when the leader frames pushed minus the follower frames pulled reach
    /// `latency + 1 + pending_frames` (pull ready frames first).
    pub pending_frames: u32,
    /// Music frames that may wait in the session (pushed, not yet read by
    /// the music LAT) before `push_music_frame` answers `Backlog`.
    pub music_buffer_frames: u32,
    /// GPT cache schedule (the same values under each, docs/STREAMING.md
    /// §3.5). Every preset: `Spread` (no step carries a window's re-prefill
    /// after the first jump); `Reprefill` holds one cache less.
    pub schedule: CacheSchedule,
    /// Element type of the GPT K/V cache (f16: half the cache bytes).
    pub kv: KvType,
}

pub use crate::nn::window::CacheSchedule;

/// Most GPT caches a staggered session may hold.
pub const MAX_WINDOWS: usize = 16;

pub use crate::error::Setting;
pub use crate::nn::window::{
    for_each_live_window, next_window, two_row_shift, window_context, window_pool, window_start,
};

/// Largest `pending_frames` / `music_buffer_frames` (keeps every size far
/// from overflow; about 18 minutes at 30 fps).
pub const MAX_BUFFER_FRAMES: u32 = 1 << 15;

/// Encoder future context at which S's leader codes equal R's (max over parts).
pub fn enc_future_max(cfg: &ModelConfig) -> u32 {
    cfg.parts
        .iter()
        .map(|p| future_max(p, StackKind::Encoder) as u32)
        .max()
        .unwrap_or(0)
}

/// Decoder future context at which S's frames equal R's (max over the 4
/// parts and the translation).
pub fn dec_future_max(cfg: &ModelConfig) -> u32 {
    cfg.parts
        .iter()
        .chain(core::iter::once(&cfg.transl))
        .map(|p| future_max(p, StackKind::Decoder) as u32)
        .max()
        .unwrap_or(0)
}

impl SessionConfig {
    /// The reference budget: `a = a_m = look_forward`, `e`, `d` at their
    /// maxima (R's leader codes and frames), and the largest window shift
    /// whose spread step computes at most two GPT rows (15 for block size
    /// 30, [`two_row_shift`]; 22 until 2026-12-07, which computes four:
    /// docs/STREAMING.md §7.3 has both shifts' agreement with R). A larger
    /// `shift` (up to `block_size - 1`, R's sliding window) is closer to R
    /// and costs more per step.
    pub fn reference(cfg: &ModelConfig) -> Self {
        let m = cfg.gpt.block_size.saturating_sub(1).max(1);
        let shift = two_row_shift(m as usize) as u32;
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
    pub fn with(
        cfg: &ModelConfig,
        lookahead: u32,
        enc_future: u32,
        dec_future: u32,
        shift: u32,
    ) -> Self {
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
            // No step over the re-prefill's spike (docs/STREAMING.md §3.5):
            // the same numbers as `Reprefill`, which holds one cache less.
            schedule: CacheSchedule::Spread,
            kv: KvType::F32,
        }
    }

    /// Checks every setting against the model. `Err((setting, value, max))`.
    pub fn check(&self, cfg: &ModelConfig) -> Result<(), (Setting, u32, u32)> {
        let lf = cfg.gpt.look_forward;
        let m = cfg.gpt.block_size.saturating_sub(1);
        let range = |s: Setting, v: u32, lo: u32, hi: u32| {
            if v < lo || v > hi {
                Err((s, v, hi))
            } else {
                Ok(())
            }
        };
        range(Setting::Lookahead, self.lookahead, 0, lf)?;
        range(Setting::EncFuture, self.enc_future, 0, enc_future_max(cfg))?;
        range(Setting::DecFuture, self.dec_future, 0, dec_future_max(cfg))?;
        range(Setting::Shift, self.shift, 1, m)?;
        range(Setting::MusicLookahead, self.music_lookahead, 0, lf)?;
        range(Setting::LatPast, self.lat_past, 0, lf)?;
        self.sampling.check()?;
        range(
            Setting::PendingFrames,
            self.pending_frames,
            0,
            MAX_BUFFER_FRAMES,
        )?;
        // The music LAT reads 4 frames per step ahead of what it has consumed.
        let min_music = 4 * cfg.music_motion_rate;
        range(
            Setting::MusicBuffer,
            self.music_buffer_frames,
            min_music,
            MAX_BUFFER_FRAMES,
        )?;
        if self.schedule == CacheSchedule::Staggered {
            let pool = window_pool(m as usize, self.shift as usize) as u32;
            range(Setting::Windows, pool, 1, MAX_WINDOWS as u32)?;
        }
        Ok(())
    }

    /// Delay between a leader frame and the follower frame of the same
    /// index, with music known ahead (a track): `max(0, 4(a+e+d) - 1)`
    /// frames (docs/STREAMING.md §2). `hop` = frames per token.
    pub fn latency_frames(&self, hop: u32) -> u32 {
        (hop * (self.lookahead + self.enc_future + self.dec_future)).saturating_sub(1)
    }

    /// The same delay with music pushed frame by frame exactly
    /// `music_lookahead` tokens ahead of the leader (music frame
    /// `f + hop a_m` in before leader frame `f`; `a_m = 0`: in lockstep):
    /// `max(latency_frames, hop (d + 1) - 1)`. The music row of step `k` is
    /// the music of token `k + 1` (R feeds music from frame
    /// `music_motion_rate`), so step `k` waits for music frame
    /// `hop (k + 2 + a_m) - 1`, one token after leader token `k + a_m`:
    /// with `a + e = 0` this, not the leader, sets the delay
    /// (docs/STREAMING.md §2).
    pub fn live_latency_frames(&self, hop: u32) -> u32 {
        self.latency_frames(hop)
            .max((hop * (self.dec_future + 1)).saturating_sub(1))
    }

    /// The named budget `preset` for `cfg` ([`Preset::ALL`] lists them).
    pub fn preset(cfg: &ModelConfig, preset: Preset) -> Self {
        let r = Self::reference(cfg);
        let lf = cfg.gpt.look_forward;
        match preset {
            Preset::Reference => r,
            Preset::Interactive => Self::with(
                cfg,
                4.min(lf),
                2.min(enc_future_max(cfg)),
                2.min(dec_future_max(cfg)),
                r.shift,
            ),
            Preset::LiveMusic => SessionConfig {
                music_lookahead: 0,
                ..Self::preset(cfg, Preset::Interactive)
            },
            Preset::Minimum => Self::minimum(cfg),
        }
    }
}

/// The named streaming budgets, one list for every front end (`duolando
/// inspect`, `generate`, `compare`, the C ABI's `duo_session_config_preset`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// R's leader codes and frames: full look-ahead and conv context (291 frames = 9.7 s
    /// on the published model), music known ahead (a track).
    Reference,
    /// An example interactive budget: `a = 4`, `e = d = 2` (31 frames,
    /// 1.0 s), music known ahead (a track).
    Interactive,
    /// Live music: the interactive budget with `music_lookahead = 0`, for
    /// music pushed in lockstep with the leader (one music frame with each
    /// leader frame, no look-ahead); since `a + e > 0` the music never
    /// delays a step, so the latency is the interactive one (31 frames).
    LiveMusic,
    /// No look-ahead, no conv future context: latency 0 frames with a track.
    Minimum,
}

impl Preset {
    /// Every preset, in the order front ends list them.
    pub const ALL: [Preset; 4] = [
        Preset::Reference,
        Preset::Interactive,
        Preset::LiveMusic,
        Preset::Minimum,
    ];

    /// The preset's name on the command line and in the C ABI.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Reference => "reference",
            Preset::Interactive => "interactive",
            Preset::LiveMusic => "live-music",
            Preset::Minimum => "minimum",
        }
    }

    /// The preset called `name` ([`Preset::name`]), if any.
    pub fn from_name(name: &str) -> Option<Preset> {
        Preset::ALL.iter().copied().find(|p| p.name() == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_one_named_list_and_live_latency_covers_the_music() {
        let cfg = crate::duolando::presets::duolando_published();
        for p in Preset::ALL {
            assert_eq!(Preset::from_name(p.name()), Some(p));
            assert!(SessionConfig::preset(&cfg, p).check(&cfg).is_ok(), "{p:?}");
        }
        assert_eq!(Preset::from_name("fastest"), None);
        let lat = |p: Preset| {
            let c = SessionConfig::preset(&cfg, p);
            (
                c.latency_frames(4),
                c.live_latency_frames(4),
                c.music_lookahead,
            )
        };
        assert_eq!(lat(Preset::Reference), (291, 291, 29));
        assert_eq!(lat(Preset::Interactive), (31, 31, 29));
        assert_eq!(lat(Preset::LiveMusic), (31, 31, 0));
        // a + e = 0: step k waits for music frame 4(k + 2 + a_m) - 1, 4 (d + 1) - 1 after the leader's.
        assert_eq!(lat(Preset::Minimum), (0, 3, 29));
        assert_eq!(
            SessionConfig::with(&cfg, 0, 0, 5, 22).live_latency_frames(4),
            23
        );
        assert_eq!(
            SessionConfig::with(&cfg, 1, 0, 5, 22).live_latency_frames(4),
            23
        );
    }
}

#[cfg(test)]
mod published {
    use super::*;
    use crate::duolando::session::{session_bytes_for, KvType};

    /// Arena of a full-size (published config) session, from the config
    /// alone; figures quoted in docs/STREAMING.md §4.
    #[test]
    fn published_session_arena() {
        let cfg = crate::duolando::presets::duolando_published();
        // The preset's schedule (spread) and the lean one (one cache).
        let spread = session_bytes_for(&cfg, &SessionConfig::reference(&cfg)).unwrap();
        let r = SessionConfig {
            schedule: CacheSchedule::Reprefill,
            ..SessionConfig::reference(&cfg)
        };
        let f32kv = session_bytes_for(&cfg, &r).unwrap();
        let f16kv = session_bytes_for(
            &cfg,
            &SessionConfig {
                kv: KvType::F16,
                ..r
            },
        )
        .unwrap();
        let stag = session_bytes_for(
            &cfg,
            &SessionConfig {
                schedule: CacheSchedule::Staggered,
                ..r
            },
        )
        .unwrap();
        let min = session_bytes_for(&cfg, &SessionConfig::minimum(&cfg)).unwrap();
        let batched = crate::duolando::session::batched_session_bytes_for(
            &cfg,
            &SessionConfig {
                kv: KvType::F16,
                ..r
            },
        )
        .unwrap();
        assert!(batched + 1_000_000 < f16kv, "{batched} vs {f16kv}");
        // Issue #37's 16 MB (10^6 bytes each): met by a session stepped only
        // in a batch (15,994,815 B since the LATs' push rows left their
        // rings), not by one with its own step memory (17,500,159 B).
        assert!(batched <= 16_000_000, "{batched}");
        // The figures docs/STREAMING.md §4, docs/C_API.md and the header quote.
        assert_eq!((batched, f16kv), (15_994_815, 17_500_159));
        // And a 16-session StepBatch for that configuration (docs/STREAMING.md §4).
        let kv16 = SessionConfig {
            kv: KvType::F16,
            ..r
        };
        let batch16 = crate::duolando::session::StepBatch::bytes(&cfg, &kv16, 16).unwrap();
        assert_eq!(batch16, 5_027_391);
        // One f32 cache is 12 layers x 2 x (10 x 29 x 768) floats = 21.4 MB (§4).
        let cache = 12 * 2 * 10 * 29 * 768 * 4;
        assert!(f32kv > cache && f32kv < cache + 40_000_000, "{f32kv}");
        assert!(f16kv < f32kv - cache / 3, "{f16kv} vs {f32kv}");
        let row = cache / 29;
        // Staggered: window_pool(29, 15) = 3 caches of 28 rows and a tail,
        // two more than the lean one.
        assert_eq!(r.shift, 15);
        assert!(
            stag > f32kv + 2 * 28 * row && stag < f32kv + 2 * 29 * row,
            "{stag}"
        );
        // Spread: a second cache of shift - 1 = 14 rows (the next window's
        // rows before its jump) and its one-row tail.
        assert!(
            spread > f32kv + 14 * row && spread < f32kv + 15 * row,
            "{spread} vs {f32kv}"
        );
        let spread16 = session_bytes_for(
            &cfg,
            &SessionConfig {
                kv: KvType::F16,
                ..SessionConfig::reference(&cfg)
            },
        )
        .unwrap();
        std::println!("published arena: reference f32 KV {f32kv} B (spread, the preset's schedule: {spread} B; with f16 KV {spread16} B), f16 KV {f16kv} B (state alone, Session::new_batched: {batched} B), staggered f32 {stag} B, minimum {min} B");
    }
}
