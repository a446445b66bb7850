//! Streaming music features for live audio: push samples, get (frames, 54)
//! rows back a fixed number of frames later.
//!
//! Policy (windowed recomputation): every `block` frames the offline
//! pipeline runs over a window of `context` past frames, the block, and
//! `lookahead` future frames; the block's rows are emitted. The window
//! edges stand in for the whole song:
//! - dB reference of the MFCC spectrogram: the running max of the mel
//!   power seen so far (offline: the max over the whole song);
//! - HPSS and CQT are computed with `lookahead` frames of future audio
//!   (the harmonic median needs 15, the lowest CQT filter ~24);
//! - tempo and beats: `beat_track` on the window's onset envelope; a beat is
//!   emitted when it falls in the block (online: no revision later).
//!
//! Latency: a frame is emitted at most `block - 1 + lookahead` frames after
//! its own audio arrived, plus 2 frames of STFT half window
//! ([`Streaming::latency_frames`]). The deviation from the offline features
//! is measured in `tests/music_streaming.rs` and reported in docs/MUSIC.md.
//! Memory: the audio ring is bounded; each block allocates its window's
//! buffers (do not call `push` on a real-time audio thread).

use super::extractor::{assemble, Extractor};
use super::{MusicError, FEATURE_DIM, HOP, N_FFT};

/// Window sizes of the streaming extractor, in frames (30 per second).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StreamingConfig {
    /// Past frames recomputed with each block.
    pub context: usize,
    /// Frames emitted per recomputation.
    pub block: usize,
    /// Future frames awaited before a block is emitted.
    pub lookahead: usize,
}

impl Default for StreamingConfig {
    fn default() -> Self {
        Self { context: 96, block: 16, lookahead: 24 }
    }
}

/// Live feature extractor (one per audio stream; `Send`, not shared).
pub struct Streaming {
    ex: Extractor,
    cfg: StreamingConfig,
    /// (kept,) the most recent samples; `base` is the absolute index of `audio[0]`.
    audio: Vec<f32>,
    base: usize,
    /// absolute number of samples pushed
    total: usize,
    /// frames emitted so far
    emitted: usize,
    /// running max of the MFCC mel power
    db_ref: f32,
}

impl Streaming {
    pub fn new(cfg: StreamingConfig) -> Self {
        Self { ex: Extractor::new(), cfg, audio: Vec::new(), base: 0, total: 0, emitted: 0, db_ref: 0.0 }
    }

    /// Worst-case delay from a frame's centre sample arriving to its row being emitted.
    pub fn latency_frames(&self) -> usize {
        self.cfg.block - 1 + self.cfg.lookahead + N_FFT / (2 * HOP)
    }

    /// Frames emitted so far.
    pub fn emitted(&self) -> usize {
        self.emitted
    }

    /// Appends `samples` (mono, 15360 Hz) and writes every row that became
    /// ready to `out` ((n, 54) appended). Returns the number of rows.
    pub fn push(&mut self, samples: &[f32], out: &mut Vec<f32>) -> Result<usize, MusicError> {
        if let Some((i, &v)) = samples.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(MusicError::NonFinite { index: self.total + i, value: v });
        }
        self.audio.extend_from_slice(samples);
        self.total += samples.len();
        let mut n = 0;
        // a frame t is complete when samples up to t*hop + n_fft/2 are in
        while (self.emitted + self.cfg.block + self.cfg.lookahead) * HOP + N_FFT / 2 <= self.total {
            n += self.run_block(self.emitted + self.cfg.block, out)?;
        }
        Ok(n)
    }

    /// End of stream: emits the remaining rows (with whatever future exists).
    pub fn finish(&mut self, out: &mut Vec<f32>) -> Result<usize, MusicError> {
        let frames = 1 + self.total / HOP;
        let mut n = 0;
        while self.emitted < frames {
            let end = (self.emitted + self.cfg.block).min(frames);
            n += self.run_block(end, out)?;
        }
        Ok(n)
    }

    /// Computes the window around frames `emitted..end` and emits them.
    fn run_block(&mut self, end: usize, out: &mut Vec<f32>) -> Result<usize, MusicError> {
        let t0 = self.emitted;
        let w0 = t0.saturating_sub(self.cfg.context);
        let s0 = w0 * HOP;
        let s1 = ((end + self.cfg.lookahead) * HOP + N_FFT / 2).min(self.total);
        let window = &self.audio[s0 - self.base..s1 - self.base];
        if window.len() < super::MIN_SAMPLES {
            // too little audio for any feature: emit zero rows rather than fail mid-stream
            out.resize(out.len() + (end - t0) * FEATURE_DIM, 0.0);
            self.emitted = end;
            return Ok(end - t0);
        }
        let running = &mut self.db_ref;
        let parts = self.ex.parts_with_reference(window, |m| {
            *running = running.max(m);
            *running
        })?;
        let f = assemble(&parts);
        let rows = (end - t0).min(f.frames.saturating_sub(t0 - w0));
        out.extend_from_slice(&f.data[(t0 - w0) * FEATURE_DIM..(t0 - w0 + rows) * FEATURE_DIM]);
        // pad if the window was shorter than the block (end of stream)
        out.resize(out.len() + (end - t0 - rows) * FEATURE_DIM, 0.0);
        self.emitted = end;
        // drop audio no later window needs
        let keep_from = self.emitted.saturating_sub(self.cfg.context) * HOP;
        if keep_from > self.base {
            self.audio.drain(..keep_from - self.base);
            self.base = keep_from;
        }
        Ok(end - t0)
    }
}
