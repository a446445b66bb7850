//! `duolando features song.mp3 -o music.npy`: the 54-d Duolando music
//! features of an audio file as a (T, 54) float32 `.npy` (see `crate::music`).

use std::path::PathBuf;

use anyhow::Context;

use crate::music::{Extractor, FEATURE_DIM, SAMPLE_RATE};

/// Flags of `duolando features`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Audio file: WAV, MP3, OGG Vorbis or FLAC (any rate, any channel count).
    pub input: PathBuf,
    /// Output `.npy`, (T, 54) float32 at 30 frames/s.
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let t0 = std::time::Instant::now();
    let y = crate::audio::load_mono(&args.input, SAMPLE_RATE)?;
    let f = Extractor::new().features(&y).with_context(|| format!("{}: feature extraction", args.input.display()))?;
    crate::npy::write_f32(&args.out, &f.data, &[f.frames, FEATURE_DIM]).with_context(|| format!("{}: cannot write", args.out.display()))?;
    eprintln!(
        "{}: {:.1} s of audio -> ({}, {}) features, tempo {:.1} BPM, {:.2} s",
        args.input.display(),
        y.len() as f64 / SAMPLE_RATE as f64,
        f.frames,
        FEATURE_DIM,
        f.tempo_bpm,
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
