//! The streaming latency budget as command-line flags (shared by
//! `generate --mode streaming`, `compare` and `inspect`).

use anyhow::{bail, Result};
use clap::ValueEnum;
use duolando_core::duolando::config::ModelConfig;
use duolando_core::duolando::session::{CacheSchedule, Sampling, SessionConfig};
use duolando_core::nn::sampler::{MAX_TEMPERATURE_MILLI, MAX_TOP_K};
// One list of presets for every command and the C ABI (core/src/duolando/session/config.rs).
use duolando_core::bailando::config::BailandoConfig;
use duolando_core::bailando::session::{Preset as SoloPreset, SessionConfig as SoloConfig};
pub use duolando_core::duolando::session::Preset;
use duolando_core::transflower::session::{Preset as TfPreset, SessionConfig as TfConfig};

/// `--preset` values: the names of every family's presets ([`Preset::ALL`],
/// [`SoloPreset::ALL`]), checked by clap (listed in `--help`); each family
/// refuses the names that are not its own by name.
fn preset_parser() -> clap::builder::PossibleValuesParser {
    let mut names: Vec<&'static str> = Preset::ALL.map(Preset::name).to_vec();
    for p in SoloPreset::ALL {
        if !names.contains(&p.name()) {
            names.push(p.name());
        }
    }
    for p in TfPreset::ALL {
        if !names.contains(&p.name()) {
            names.push(p.name());
        }
    }
    clap::builder::PossibleValuesParser::new(names)
}

/// `--preset` and per-setting overrides (docs/STREAMING.md §2).
#[derive(clap::Args, Debug, Clone)]
pub struct BudgetArgs {
    /// Starting point of the streaming budget (`duolando inspect` lists each
    /// preset's settings and latency); the flags below override single settings.
    /// live-music: music pushed in lockstep with the leader, no music look-ahead.
    /// exact (Bailando): R's sliding window and full decoder future.
    #[arg(long, default_value = "reference", value_parser = preset_parser())]
    pub preset: String,
    /// Leader look-ahead in tokens (4 frames each), 0..=look_forward.
    #[arg(long)]
    pub lookahead: Option<u32>,
    /// Encoder future context in tokens, 0..=enc_future_max.
    #[arg(long)]
    pub enc_future: Option<u32>,
    /// Decoder future context in tokens, 0..=dec_future_max.
    #[arg(long)]
    pub dec_future: Option<u32>,
    /// Chunk shift of the GPT window, 1..=block_size-1 (block_size-1 = R's sliding window).
    #[arg(long)]
    pub shift: Option<u32>,
    /// Music look-ahead in tokens, 0..=look_forward (music known ahead: look_forward).
    #[arg(long)]
    pub music_lookahead: Option<u32>,
    /// Top-k sampling (uniform over the k best tokens) instead of greedy.
    #[arg(long)]
    pub topk: Option<u32>,
    /// Sample each token with its probability under softmax(logits / T)
    /// among the --topk best (64 without --topk) instead of uniformly:
    /// the likely tokens most of the time (T: 0.001..=100; small T is
    /// near greedy, 1 the model's own distribution).
    #[arg(long)]
    pub temperature: Option<f32>,
    /// RNG seed of top-k sampling (deterministic for a given seed).
    #[arg(long, default_value_t = 0)]
    pub rng_seed: u64,
    /// One GPT cache per live window, fed one row per step: a flat cost per
    /// step instead of a re-prefill spike at every window jump (more memory).
    #[arg(long)]
    pub staggered: bool,
    /// Two GPT caches, the next window filled a few rows per step ahead of
    /// its jump: a flat cost per step at the re-prefill schedule's mean
    /// (a second cache of `shift - 1` rows; at start-up, part of the first
    /// full window at its jump). The
    /// presets' schedule: this flag only names it.
    #[arg(long, conflicts_with = "staggered")]
    pub spread: bool,
    /// One GPT cache, re-prefilled at every window jump: the least memory
    /// (one cache less than the presets' spread schedule), the same
    /// numbers, but that step costs most of an R step (a spike every
    /// chunk).
    #[arg(long, conflicts_with_all = ["staggered", "spread"])]
    pub reprefill: bool,
    /// Element type of the session's keys and values (GPT cache, LAT rings;
    /// Transflower: the kept rows of the stale-rows mode). Default: the
    /// preset's (f32, but f16 for Transflower's `realtime`).
    #[arg(long, value_enum)]
    pub kv: Option<Kv>,
    /// Transflower: steps between recomputations of every row (1 = R;
    /// more: the stale-rows approximation, faster).
    #[arg(long)]
    pub refresh: Option<u32>,
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum Kv {
    F32,
    /// Half the K/V bytes (GPT cache and LAT rings); keys and values rounded to f16.
    F16,
}

/// What a preset name refused by a model's family is: "is a Duolando
/// preset", "is a Duolando and Bailando preset" (other families', named),
/// or "is no preset".
fn whose_preset(name: &str) -> String {
    let families: Vec<&str> = [
        ("Duolando", Preset::from_name(name).is_some()),
        ("Bailando", SoloPreset::from_name(name).is_some()),
        ("Transflower", TfPreset::from_name(name).is_some()),
    ]
    .iter()
    .filter(|(_, has)| *has)
    .map(|(f, _)| *f)
    .collect();
    if families.is_empty() {
        "is no preset".into()
    } else {
        format!("is a {} preset", families.join(" and "))
    }
}

impl BudgetArgs {
    /// The first streaming flag given, if any (`--preset` counts when it is
    /// not the default): R mode (`--mode exact`) refuses them by name rather
    /// than ignoring them.
    pub fn first_given(&self) -> Option<&'static str> {
        self.flags()
            .into_iter()
            .find_map(|(given, name)| given.then_some(name))
    }

    /// Every session flag's name and whether it was given (`--preset`: not
    /// the default), in `--help` order.
    fn flags(&self) -> [(bool, &'static str); 14] {
        [
            (self.preset != "reference", "preset"),
            (self.lookahead.is_some(), "lookahead"),
            (self.enc_future.is_some(), "enc-future"),
            (self.dec_future.is_some(), "dec-future"),
            (self.shift.is_some(), "shift"),
            (self.music_lookahead.is_some(), "music-lookahead"),
            (self.topk.is_some(), "topk"),
            (self.temperature.is_some(), "temperature"),
            (self.rng_seed != 0, "rng-seed"),
            (self.staggered, "staggered"),
            (self.spread, "spread"),
            (self.reprefill, "reprefill"),
            (self.kv.is_some(), "kv"),
            (self.refresh.is_some(), "refresh"),
        ]
    }

    /// The session configuration for `cfg`, checked.
    pub fn config(&self, cfg: &ModelConfig) -> Result<SessionConfig> {
        let Some(preset) = Preset::from_name(&self.preset) else {
            bail!(
                "--preset {} {}; a Duolando model takes {} (R itself: --mode exact)",
                self.preset,
                whose_preset(&self.preset),
                Preset::ALL.map(Preset::name).join(", ")
            );
        };
        if self.refresh.is_some() {
            bail!("--refresh is a Transflower setting; a Duolando model's budget is --lookahead, --enc-future, --dec-future, --shift, --music-lookahead");
        }
        let base = SessionConfig::preset(cfg, preset);
        let mut sc = SessionConfig {
            lookahead: self.lookahead.unwrap_or(base.lookahead),
            enc_future: self.enc_future.unwrap_or(base.enc_future),
            dec_future: self.dec_future.unwrap_or(base.dec_future),
            shift: self.shift.unwrap_or(base.shift),
            ..base
        };
        if let Some(m) = self.music_lookahead {
            sc.music_lookahead = m;
        }
        if self.staggered {
            sc.schedule = CacheSchedule::Staggered;
        } else if self.spread {
            sc.schedule = CacheSchedule::Spread;
        } else if self.reprefill {
            sc.schedule = CacheSchedule::Reprefill;
        }
        sc.kv = match self.kv.unwrap_or(Kv::F32) {
            Kv::F32 => duolando_core::duolando::session::KvType::F32,
            Kv::F16 => duolando_core::duolando::session::KvType::F16,
        };
        if let Some(s) = sampling(self.topk, self.temperature, self.rng_seed)? {
            sc.sampling = s;
        }
        if let Err((setting, value, max)) = sc.check(cfg) {
            bail!(
                "--{} {value} is outside its range for this model (largest allowed: {max})",
                flag(setting)
            );
        }
        Ok(sc)
    }
}

impl BudgetArgs {
    /// The session configuration of a solo (Bailando) model, checked; the
    /// settings a solo model does not have are refused by name.
    pub fn solo_config(&self, cfg: &BailandoConfig) -> Result<SoloConfig> {
        let Some(preset) = SoloPreset::from_name(&self.preset) else {
            bail!(
                "--preset {} {}; a Bailando model takes {}",
                self.preset,
                whose_preset(&self.preset),
                SoloPreset::ALL.map(SoloPreset::name).join(", ")
            );
        };
        if self.refresh.is_some() {
            bail!("--refresh is a Transflower setting; a Bailando model's settings are --preset, --dec-future, --shift, --spread, --reprefill, --topk, --kv");
        }
        for (given, name) in [
            (self.lookahead.is_some(), "lookahead"),
            (self.enc_future.is_some(), "enc-future"),
            (self.music_lookahead.is_some(), "music-lookahead"),
            (self.staggered, "staggered"),
        ] {
            if given {
                bail!("--{name} is a Duolando setting: a Bailando model has no leader and reads no music ahead (its settings: --preset, --dec-future, --shift, --spread, --reprefill, --topk, --kv)");
            }
        }
        let base = SoloConfig::preset(cfg, preset);
        let mut sc = SoloConfig {
            dec_future: self.dec_future.unwrap_or(base.dec_future),
            shift: self.shift.unwrap_or(base.shift),
            ..base
        };
        if self.spread {
            sc.schedule = duolando_core::nn::window::CacheSchedule::Spread;
        } else if self.reprefill {
            sc.schedule = duolando_core::nn::window::CacheSchedule::Reprefill;
        }
        sc.kv = match self.kv.unwrap_or(Kv::F32) {
            Kv::F32 => duolando_core::nn::kv_store::KvType::F32,
            Kv::F16 => duolando_core::nn::kv_store::KvType::F16,
        };
        if let Some(s) = sampling(self.topk, self.temperature, self.rng_seed)? {
            sc.sampling = s;
        }
        if let Err((setting, value, max)) = sc.check(cfg) {
            bail!(
                "--{} {value} is outside its range for this model (largest allowed: {max})",
                flag(setting)
            );
        }
        Ok(sc)
    }
}

/// The sampling rule of `--topk K`, `--temperature T` and `--rng-seed`:
/// uniform among the K best (the authors' `samplek`) without a
/// temperature, softmax(logits / T) among the K best (64 without `--topk`)
/// with one; None (the preset's: greedy) without either. Shared by every
/// command that runs a session (`generate`, `dance`, `compare`).
pub fn sampling(
    topk: Option<u32>,
    temperature: Option<f32>,
    rng_seed: u64,
) -> Result<Option<Sampling>> {
    let Some(t) = temperature else {
        return Ok(topk.map(|k| Sampling::TopK { k, rng_seed }));
    };
    let milli = t * 1000.0;
    if !milli.is_finite() || milli.round() < 1.0 || milli.round() > MAX_TEMPERATURE_MILLI as f32 {
        bail!("--temperature {t} is outside 0.001..=100");
    }
    Ok(Some(Sampling::Softmax {
        k: topk.unwrap_or(MAX_TOP_K as u32),
        temperature_milli: milli.round() as u32,
        rng_seed,
    }))
}

pub fn flag(s: duolando_core::duolando::session::Setting) -> &'static str {
    use duolando_core::duolando::session::Setting::*;
    match s {
        Lookahead => "lookahead",
        EncFuture => "enc-future",
        DecFuture => "dec-future",
        Shift => "shift",
        MusicLookahead => "music-lookahead",
        LatPast => "lat-past",
        TopK => "topk",
        Temperature => "temperature (in thousandths)",
        PendingFrames => "pending-frames",
        MusicBuffer => "music-buffer-frames",
        Windows => "staggered",
        Batch => "sessions",
        Refresh => "refresh",
    }
}

impl BudgetArgs {
    /// The session configuration of a Transflower model, checked; the
    /// settings it does not have are refused by name.
    pub fn transflower_config(&self) -> Result<TfConfig> {
        let Some(preset) = TfPreset::from_name(&self.preset) else {
            bail!(
                "--preset {} {}; a Transflower model takes {}",
                self.preset,
                whose_preset(&self.preset),
                TfPreset::ALL.map(TfPreset::name).join(", ")
            );
        };
        // Transflower's own settings are --preset, --refresh and --kv.
        let others = self
            .flags()
            .into_iter()
            .filter(|(_, n)| !matches!(*n, "preset" | "refresh" | "kv"));
        for (given, name) in others {
            if given {
                bail!("--{name} is a Duolando / Bailando setting; a Transflower session's settings are --preset, --refresh, --kv (its base samples: --seed N or --noise FILE.npy)");
            }
        }
        let mut sc = TfConfig::preset(preset);
        if let Some(r) = self.refresh {
            sc.refresh = r;
        }
        if let Some(kv) = self.kv {
            sc.kv = match kv {
                Kv::F32 => duolando_core::nn::kv_store::KvType::F32,
                Kv::F16 => duolando_core::nn::kv_store::KvType::F16,
            };
        }
        if let Err((setting, value, max)) = sc.check() {
            bail!(
                "--{} {value} is outside its range (largest allowed: {max})",
                flag(setting)
            );
        }
        Ok(sc)
    }
}
