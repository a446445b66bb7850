//! `duolando features song.mp3 -o music.npy`: the music features of an
//! audio file as a float32 `.npy`: Duolando's (T, 54) at 30 frames/s by
//! default, Bailando's (T, 438) at 7.5 frames/s with `--for bailando`
//! (see `crate::music`).

use std::path::PathBuf;

use anyhow::Context;

use crate::music::{Extractor, FeatureSet};

/// Which model's features `--for` names.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum For {
    /// (T, 54) at 30 frames/s from audio at 15360 Hz.
    #[default]
    Duolando,
    /// (T, 438) at 7.5 frames/s from audio at 3840 Hz (Bailando, CVPR 2022).
    Bailando,
}

impl From<For> for FeatureSet {
    fn from(f: For) -> Self {
        match f {
            For::Duolando => FeatureSet::Duolando,
            For::Bailando => FeatureSet::Bailando,
        }
    }
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
    /// Whose features: duolando (54-d, 15360 Hz, 30 fps) or bailando (438-d, 3840 Hz, 7.5 fps).
    #[arg(long = "for", value_enum, default_value_t = For::Duolando)]
    pub for_model: For,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let t0 = std::time::Instant::now();
    let out = args.out.or(args.out_pos).context("no output path (give OUT or -o OUT)")?;
    let set = FeatureSet::from(args.for_model);
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
