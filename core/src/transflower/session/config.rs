//! What a Transflower session trades: how often every row of the
//! transformers is recomputed (`refresh`), where the kept keys and values
//! live (`kv`), and how much input and output it holds.
//!
//! R mode recomputes the input transformers over their whole windows and
//! the cross-modal transformer over every latent row at every step (no
//! causal mask, no positions: every row sees every row, so nothing can be
//! reused exactly). `refresh = 1` does the same (R's numbers, bit for
//! bit). `refresh = k > 1` recomputes everything only every k-th step and,
//! in between, computes only the rows that changed: each input's newest
//! row through its transformer, and the cross-modal transformer's newest
//! rows and its conditioning rows, against the keys and values every
//! other row had when it was last computed (stale rows). That is ~8x less
//! work per in-between step at the published size (5 of 260 cross-modal
//! rows), and an approximation whose distance from R is measured
//! (docs/TRANSFLOWER.md "S mode").

use crate::error::Setting;
use crate::nn::kv_store::KvType;
use crate::transflower::config::TransflowerConfig;

/// Most steps between refreshes.
pub const MAX_REFRESH: u32 = 4096;
/// Most rows an input may hold beyond its window, and most frames held
/// unpulled.
pub const MAX_BUFFER: u32 = 1 << 16;

/// Named settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// R's numbers: every row recomputed at every step.
    Exact,
    /// Every row recomputed every 4th step; f32 keys and values.
    Reference,
    /// Every row recomputed every 16th step; f16 keys and values (the mean
    /// step within real time at the published size on one core).
    Realtime,
}

impl Preset {
    pub const ALL: [Preset; 3] = [Preset::Exact, Preset::Reference, Preset::Realtime];

    pub fn name(self) -> &'static str {
        match self {
            Preset::Exact => "exact",
            Preset::Reference => "reference",
            Preset::Realtime => "realtime",
        }
    }

    pub fn from_name(s: &str) -> Option<Preset> {
        Preset::ALL.into_iter().find(|p| p.name() == s)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SessionConfig {
    /// Steps between recomputations of every row (1 = R).
    pub refresh: u32,
    /// Storage of the kept keys and values (only with `refresh > 1`).
    pub kv: KvType,
    /// Rows each sliding input (the audio) holds beyond its window.
    pub input_buffer_rows: u32,
    /// Frames held until pulled (a step that would exceed it is refused).
    pub pending_frames: u32,
}

impl SessionConfig {
    pub fn preset(p: Preset) -> Self {
        let (refresh, kv) = match p {
            Preset::Exact => (1, KvType::F32),
            Preset::Reference => (4, KvType::F32),
            Preset::Realtime => (16, KvType::F16),
        };
        SessionConfig {
            refresh,
            kv,
            input_buffer_rows: 400,
            pending_frames: 64,
        }
    }

    /// `(setting, value, max)` of the first setting outside its range.
    pub fn check(&self) -> Result<(), (Setting, u32, u32)> {
        let range = |s: Setting, v: u32, lo: u32, hi: u32| {
            if v < lo || v > hi {
                Err((s, v, hi))
            } else {
                Ok(())
            }
        };
        range(Setting::Refresh, self.refresh, 1, MAX_REFRESH)?;
        range(Setting::MusicBuffer, self.input_buffer_rows, 0, MAX_BUFFER)?;
        range(Setting::PendingFrames, self.pending_frames, 1, MAX_BUFFER)
    }

    /// Whether the session keeps keys and values between steps.
    pub fn stale(&self) -> bool {
        self.refresh > 1
    }
}

/// Rows of the last input (the audio) between a frame's song row and the
/// last row the step that makes it reads: frame t is song row
/// `output_time_offset + t` and needs rows up to `t + max_window - 1` (19
/// rows, 0.95 s at 20 fps, in the published configs). Negative: the frame
/// is later than the rows it needs.
pub fn lookahead_rows(cfg: &TransflowerConfig) -> i64 {
    cfg.max_window() as i64 - 1 - cfg.output_time_offset as i64
}
