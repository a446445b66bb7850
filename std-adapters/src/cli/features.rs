//! `duolando features song.mp3 -o music.npy`: the music features of an
//! audio file as a float32 `.npy`: Duolando's (T, 54) at 30 frames/s by
//! default, Bailando's (T, 438) at 7.5 frames/s with `--for bailando`
//! (see `crate::music`).

use std::path::PathBuf;

use anyhow::Context;

use crate::music::transflower::{self, TfAudio};
use crate::music::{Extractor, FeatureSet};
use crate::transflower_motion::scaler::Scaler;

/// Which model's features `--for` names.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum For {
    /// (T, 54) at 30 frames/s from audio at 15360 Hz.
    #[default]
    Duolando,
    /// (T, 438) at 7.5 frames/s from audio at 3840 Hz (Bailando, CVPR 2022).
    Bailando,
    /// (T, 85) at 20 frames/s from audio at 96 kHz (Transflower: mel 80,
    /// onset envelope; beat/downbeat and 2 PCA columns substituted).
    Transflower,
}

/// Flags of `duolando features`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Audio file: WAV, MP3, OGG Vorbis or FLAC (any rate, any channel count).
    pub input: PathBuf,
    /// Output `.npy` (or give it with `-o`).
    #[arg(value_name = "OUT", required_unless_present = "out")]
    pub out_pos: Option<PathBuf>,
    /// Output `.npy`: (T, 54) float32 at 30 frames/s, or (T, 438) at 7.5 frames/s with `--for bailando`.
    #[arg(short = 'o', long = "out", conflicts_with = "out_pos")]
    pub out: Option<PathBuf>,
    /// Whose features: duolando (54-d, 15360 Hz, 30 fps), bailando (438-d, 3840 Hz, 7.5 fps) or transflower (85-d, 96 kHz, 20 fps).
    #[arg(long = "for", visible_alias = "family", value_enum, default_value_t = For::Duolando)]
    pub for_model: For,
    /// With --for transflower: standardise with this scaler (the authors'
    /// audio StandardScaler, e.g. `audio_feats_scaled_20_scaler.pkl`, as
    /// tools/transflower_scalers.py writes it; 85 columns).
    #[arg(long)]
    pub scaler: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let t0 = std::time::Instant::now();
    let out = args.out.or(args.out_pos).context("no output path (give OUT or -o OUT)")?;
    let set = match args.for_model {
        For::Duolando => FeatureSet::Duolando,
        For::Bailando => FeatureSet::Bailando,
        For::Transflower => return run_transflower(&args.input, &out, args.scaler.as_deref(), t0),
    };
    if let Some(s) = &args.scaler {
        anyhow::bail!("--scaler {}: only Transflower's features are standardised (give --for transflower)", s.display());
    }
    let sr = set.sample_rate();
    let y = crate::audio::load_mono(&args.input, sr)?;
    let f = Extractor::for_set(set).features(&y).with_context(|| format!("{}: {} feature extraction", args.input.display(), set.name()))?;
    crate::npy::write_f32(&out, &f.data, &[f.frames, f.dim]).with_context(|| format!("{}: cannot write", out.display()))?;
    eprintln!(
        "{}: {:.1} s of audio -> ({}, {}) {} features at {} fps, tempo {:.1} BPM, {:.2} s",
        args.input.display(),
        y.len() as f64 / sr as f64,
        f.frames,
        f.dim,
        set.name(),
        set.frame_rate(),
        f.tempo_bpm,
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `--for transflower`: (T, 85) at 20 fps, standardised with `scaler` if given.
fn run_transflower(
    input: &std::path::Path,
    out: &std::path::Path,
    scaler: Option<&std::path::Path>,
    t0: std::time::Instant,
) -> anyhow::Result<()> {
    let scaler = match scaler {
        Some(p) => {
            let s = Scaler::read(p)?;
            if s.width() != transflower::FEATURE_DIM {
                anyhow::bail!(
                    "scaler {}: {} columns, Transflower's audio features have {}: it is the scaler of another feature set",
                    p.display(),
                    s.width(),
                    transflower::FEATURE_DIM
                );
            }
            Some(s)
        }
        None => None,
    };
    let sr = transflower::SAMPLE_RATE;
    let y = crate::audio::load_mono(input, sr)?;
    let a = TfAudio::new();
    let f = match &scaler {
        Some(s) => a.features_scaled(&y, &s.mean, &s.scale),
        None => a.features(&y),
    }
    .with_context(|| format!("{}: transflower feature extraction", input.display()))?;
    crate::npy::write_f32(out, &f.data, &[f.frames, f.dim]).with_context(|| format!("{}: cannot write", out.display()))?;
    eprintln!(
        "{}: {:.1} s of audio -> ({}, {}) transflower features at {} fps ({}), substitute beat tracker tempo {:.1} BPM, {:.2} s",
        input.display(),
        y.len() as f64 / sr as f64,
        f.frames,
        f.dim,
        transflower::FPS,
        if scaler.is_some() { "scaled" } else { "unscaled" },
        f.tempo_bpm,
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
