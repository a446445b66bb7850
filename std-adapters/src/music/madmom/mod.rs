//! madmom's `RNNDownBeatProcessor` (madmom 0.16.1; Böck, Krebs and Widmer,
//! ISMIR 2016): beat and downbeat activations of a song, Transflower's audio
//! columns 81 and 82, computed as madmom computes them.
//!
//! - [`frontend`]: the 314 inputs per frame (three log-filtered STFTs and
//!   their positive differences) of the mono 44.1 kHz int16 signal.
//! - [`rnn`]: the BLSTM ensemble, read from a file the user converts from
//!   their own madmom install (`tools/madmom_weights.py`): madmom's trained
//!   networks are licensed CC BY-NC-SA 4.0, so the engine ships none.
//!
//! madmom reads the song as 44.1 kHz int16 (the authors give it a WAV);
//! [`signal_44k`] makes that signal from any decoded file: a 44.1 kHz
//! integer source gives madmom's exact samples (channels averaged and
//! truncated toward zero, as madmom's `remix` does), another rate is
//! resampled by the engine's resampler and rounded (madmom would call
//! ffmpeg there: close, not identical). Tested against madmom's own classes
//! in `std-adapters/tests/madmom_downbeats.rs` (docs/TRANSFLOWER.md).

pub mod frontend;
pub mod rnn;

use std::path::Path;

use crate::audio::{resample::resample, Decoded};

pub use frontend::{Frontend, SAMPLE_RATE};
pub use rnn::{Ensemble, RnnFileError};

/// The whole processor: front end and networks.
pub struct DownbeatRnn {
    frontend: Frontend,
    nets: Ensemble,
}

impl DownbeatRnn {
    /// From a network file's bytes; refused if the networks do not take the
    /// front end's 314 inputs.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, RnnFileError> {
        let nets = Ensemble::from_bytes(bytes)?;
        let frontend = Frontend::new();
        if nets.inputs() != frontend.width() {
            return Err(RnnFileError::Header {
                field: "inputs",
                value: nets.inputs() as u32,
                min: frontend.width() as u32,
                max: frontend.width() as u32,
            });
        }
        Ok(DownbeatRnn { frontend, nets })
    }

    /// Reads a network file (`tools/madmom_weights.py` writes one).
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        use anyhow::Context;
        let bytes = std::fs::read(path)
            .with_context(|| format!("{}: cannot read the madmom network file", path.display()))?;
        Self::from_bytes(&bytes)
            .with_context(|| format!("{}: not a usable madmom network file", path.display()))
    }

    /// The networks' input (frames, 314) for `signal` at `fps`.
    pub fn inputs(&self, signal: &[i16], fps: f64) -> Vec<f32> {
        self.frontend.features(signal, fps)
    }

    /// Beat and downbeat activations of `signal` (mono, 44.1 kHz, int16) at
    /// `fps` frames per second (madmom's `ceil(len * fps / 44100)` rows;
    /// Transflower calls it with fps 20 although the networks were trained
    /// at 100). Refused if the networks overflow f32 on it.
    pub fn activations(&self, signal: &[i16], fps: f64) -> Result<Vec<[f32; 2]>, RnnFileError> {
        self.nets.activations(&self.inputs(signal, fps))
    }

    /// Networks in the ensemble.
    pub fn networks(&self) -> usize {
        self.nets.len()
    }
}

/// madmom's signal of a decoded file: mono, 44.1 kHz, int16 (see the module docs).
pub fn signal_44k(d: &Decoded) -> Vec<i16> {
    let to_i16 = |v: f64| v.clamp(i16::MIN as f64, i16::MAX as f64) as i16; // `as` truncates toward zero
    let integral = d.samples.iter().all(|&v| (v * 32768.0).fract() == 0.0);
    if d.sample_rate == SAMPLE_RATE && integral {
        let ch = d.channels.max(1);
        return d
            .samples
            .chunks_exact(ch)
            .map(|f| to_i16(f.iter().map(|&v| (v * 32768.0) as f64).sum::<f64>() / ch as f64))
            .collect();
    }
    let mono = d.mono();
    resample(&mono, d.sample_rate, SAMPLE_RATE)
        .iter()
        .map(|&v| to_i16((v as f64 * 32768.0).round()))
        .collect()
}
