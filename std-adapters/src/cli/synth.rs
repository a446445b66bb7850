//! `duolando synth`: writes a procedural duet dataset (see `crate::synth`).

use std::path::PathBuf;

use anyhow::{bail, Result};

/// Flags of `duolando synth`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Minutes of dance to generate (takes are 20-45 s each).
    #[arg(long, default_value_t = 10.0)]
    pub minutes: f32,
    /// Seed; the same seed writes the same files.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output directory (created; DD100 layout inside).
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `duolando synth`.
pub fn run(args: Args) -> Result<()> {
    if !(args.minutes.is_finite() && args.minutes > 0.0 && args.minutes <= 10_000.0) {
        bail!("--minutes must be a positive number of minutes (at most 10000), got {}", args.minutes);
    }
    let bar = indicatif::ProgressBar::new(0);
    let summary = crate::synth::dataset::write_dataset(&args.out, args.minutes, args.seed, |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    println!(
        "wrote {} takes ({:.1} min, {} frames) to {}",
        summary.takes,
        summary.seconds / 60.0,
        summary.frames,
        args.out.display()
    );
    Ok(())
}
