//! `duolando features song.mp3 -o music.npy`: the music features of an
//! audio file as a float32 `.npy`: Duolando's (T, 54) at 30 frames/s by
//! default, Bailando's (T, 438) at 7.5 frames/s with `--for bailando`
//! (see `crate::music`).

use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::music::madmom::{self, DownbeatRnn};
use crate::music::transflower::{self, Beats, TfAudio};
use crate::music::{Extractor, FeatureSet, Features};
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
    /// onset envelope, beat/downbeat from madmom's networks with --madmom
    /// or substituted, 2 PCA columns substituted).
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
    /// With --for transflower: madmom's downbeat networks (converted from a
    /// madmom install by tools/madmom_weights.py) compute columns 81, 82 as
    /// the authors' madmom call does; without it the engine's beat tracker
    /// stands in (docs/TRANSFLOWER.md "Audio features").
    #[arg(long, value_name = "NETWORKS")]
    pub madmom: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let t0 = std::time::Instant::now();
    let out = args.out.or(args.out_pos).context("no output path (give OUT or -o OUT)")?;
    let set = match args.for_model {
        For::Duolando => FeatureSet::Duolando,
        For::Bailando => FeatureSet::Bailando,
        For::Transflower => return run_transflower(&args.input, &out, args.scaler.as_deref(), args.madmom.as_deref(), t0),
    };
    if let Some(s) = &args.scaler {
        anyhow::bail!("--scaler {}: only Transflower's features are standardised (give --for transflower)", s.display());
    }
    if let Some(m) = &args.madmom {
        anyhow::bail!("--madmom {}: madmom's beat networks make Transflower's features only (give --for transflower)", m.display());
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
    input: &Path,
    out: &Path,
    scaler: Option<&Path>,
    madmom: Option<&Path>,
    t0: std::time::Instant,
) -> anyhow::Result<()> {
    let scaler = match scaler {
        Some(p) => Some(read_audio_scaler(p, "scaler")?),
        None => None,
    };
    let tf = transflower_file_features(input, madmom, scaler.as_ref())?;
    let f = &tf.features;
    crate::npy::write_f32(out, &f.data, &[f.frames, f.dim]).with_context(|| format!("{}: cannot write", out.display()))?;
    eprintln!(
        "{}: {:.1} s of audio -> ({}, {}) transflower features at {} fps ({}), {}, {:.2} s",
        input.display(),
        tf.seconds,
        f.frames,
        f.dim,
        transflower::FPS,
        if scaler.is_some() { "scaled" } else { "unscaled" },
        tf.beats_said(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// A Transflower audio scaler file (85 columns), `flag` naming it in errors.
pub(crate) fn read_audio_scaler(p: &Path, flag: &str) -> anyhow::Result<Scaler> {
    let s = Scaler::read(p)?;
    if s.width() != transflower::FEATURE_DIM {
        anyhow::bail!(
            "--{flag} {}: {} columns, Transflower's audio features have {}: it is the scaler of another feature set",
            p.display(),
            s.width(),
            transflower::FEATURE_DIM
        );
    }
    Ok(s)
}

/// Transflower features of one audio file and where their beat columns came from.
pub(crate) struct TfFileFeatures {
    pub features: Features,
    pub seconds: f64,
    /// madmom's networks in the ensemble; None: the substitute beat tracker.
    pub madmom_networks: Option<usize>,
}

impl TfFileFeatures {
    /// "beat/downbeat from madmom's 8 networks" or the substitute's tempo.
    pub fn beats_said(&self) -> String {
        match self.madmom_networks {
            Some(n) => format!("beat/downbeat from madmom's {n} networks"),
            None => format!("substitute beat tracker (no --madmom) tempo {:.1} BPM", self.features.tempo_bpm),
        }
    }
}

/// Transflower's (T, 85) features of the audio file `input`: decoded once,
/// mel and envelope from it at 96 kHz, columns 81, 82 from madmom's
/// networks (`madmom`, read first) on its 44.1 kHz int16 signal or the
/// substitute, standardised by `scaler` if given.
pub(crate) fn transflower_file_features(input: &Path, madmom: Option<&Path>, scaler: Option<&Scaler>) -> anyhow::Result<TfFileFeatures> {
    let rnn = madmom.map(|p| DownbeatRnn::read(p).map(|r| (r, p))).transpose()?;
    let d = crate::audio::decode(input)?;
    let y = crate::audio::mono_at(&d, input, transflower::SAMPLE_RATE)?;
    let rows = match &rnn {
        Some((r, p)) => Some(
            r.activations(&madmom::signal_44k(&d), transflower::FPS)
                .with_context(|| format!("{}: madmom's networks ({}) on this audio", input.display(), p.display()))?,
        ),
        None => None,
    };
    let beats = match &rows {
        Some(r) => Beats::Madmom(r),
        None => Beats::Substitute,
    };
    let a = TfAudio::new();
    let features = match scaler {
        Some(s) => a.features_scaled_with(&y, beats, &s.mean, &s.scale),
        None => a.features_with(&y, beats),
    }
    .with_context(|| format!("{}: transflower feature extraction", input.display()))?;
    Ok(TfFileFeatures {
        features,
        seconds: y.len() as f64 / transflower::SAMPLE_RATE as f64,
        madmom_networks: rnn.as_ref().map(|(r, _)| r.networks()),
    })
}
