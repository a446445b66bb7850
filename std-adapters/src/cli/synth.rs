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
    /// Put every beat on a grid of this many frames (30 fps): each take's
    /// tempo moves to the nearest one (72-163 BPM) whose beat lasts a whole
    /// number of grid steps, and its first beat onto the grid. 4 frames =
    /// one Bailando token (8 frames at 60 fps): 150, 112.5, 90 or 75 BPM.
    /// Default: tempi as drawn.
    #[arg(long, value_name = "FRAMES")]
    pub beat_grid_frames: Option<u32>,
}

/// Runs `duolando synth`.
pub fn run(args: Args) -> Result<()> {
    if !(args.minutes.is_finite() && args.minutes > 0.0 && args.minutes <= 10_000.0) {
        bail!(
            "--minutes must be a positive number of minutes (at most 10000), got {}",
            args.minutes
        );
    }
    let grid = match args.beat_grid_frames {
        None => None,
        Some(f @ 1..=48) => Some(f as f32 / crate::synth::FPS),
        Some(f) => bail!("--beat-grid-frames must be 1 to 48 frames (30 fps), got {f}"),
    };
    let bar = indicatif::ProgressBar::new(0);
    let summary = crate::synth::dataset::write_dataset(
        &args.out,
        args.minutes,
        args.seed,
        grid,
        |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        },
    )?;
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
