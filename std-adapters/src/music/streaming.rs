//! Streaming music features for live audio: push samples, get (frames, 54)
//! rows (Duolando, [`Streaming::new`]) or (frames, 438) rows (Bailando,
//! [`Streaming::bailando`]) back a fixed number of frames later.
//!
//! Policy (windowed recomputation): every `block` frames the offline
//! pipeline runs over a window of `context` past frames, the block, and
//! `lookahead` future frames; the block's rows are emitted. The window
//! edges stand in for the whole song:
//! - dB reference of the MFCC spectrogram: the running max of the mel
//!   power seen so far (offline: the max over the whole song); Bailando
//!   also hangs the onset spectrogram's 80 dB floor from a running max (its
//!   onset, a median over 128 bands of which 64 are empty, is half the
//!   smallest rise of the 64 live bands: the floor decides it);
//! - HPSS and CQT are computed with `lookahead` frames of future audio
//!   (the harmonic median needs 15, the lowest CQT filter ~24);
//! - tempo and beats: `beat_track` on the window's onset envelope; a beat is
//!   emitted when it falls in the block (online: no revision later);
//! - Bailando's tempogram (offline: a 384-frame window centred on the row,
//!   +-25.6 s): the same autocorrelation over the 384 most recent onset
//!   frames known when the row is emitted (emitted values, then the current
//!   window's), i.e. centred `192 - lookahead` frames in the past; the
//!   song's start is ramp-padded as offline, and once the stream is finished
//!   the remaining rows use centred windows with the offline end padding.
//!
//! Latency: a frame is emitted at most `block - 1 + lookahead` frames after
//! its own audio arrived, plus 2 frames of STFT half window
//! ([`Streaming::latency_frames`]). The deviation from the offline features
//! is measured in `tests/music_streaming.rs` and reported in docs/MUSIC.md.
//! Memory: the audio ring is bounded; each block allocates its window's
//! buffers (do not call `push` on a real-time audio thread).

use super::bailando::TEMPOGRAM_WIN;
use super::extractor::{assemble, Extractor, FeatureSet};
use super::tempo::LocalAutocorr;
use super::{MusicError, FEATURE_DIM, HOP, N_FFT};

/// Window sizes of the streaming extractor, in frames (30 per second for
/// Duolando, 7.5 for Bailando).
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
    /// Duolando's: 3.2 s of context, 0.53 s blocks, 0.8 s of look-ahead.
    fn default() -> Self {
        Self {
            context: 96,
            block: 16,
            lookahead: 24,
        }
    }
}

impl StreamingConfig {
    /// Bailando's default at 7.5 frames/s: 8.5 s of context (the tempo
    /// estimate wants 8 s), 0.53 s blocks, 0.8 s of look-ahead.
    pub fn bailando() -> Self {
        Self {
            context: 64,
            block: 4,
            lookahead: 6,
        }
    }
}

/// Bailando's causal tempogram: the emitted onset history and the
/// autocorrelation plan.
struct TempogramState {
    ac: LocalAutocorr,
    /// onset values of frames `base..base + hist.len()`, as emitted
    hist: Vec<f32>,
    base: usize,
    /// onset value of frame 0 (the left ramp's end value)
    first: Option<f32>,
    /// (384,) the virtual envelope segment of one row
    seg: Vec<f32>,
    /// (384,) one tempogram row
    col: Vec<f64>,
}

impl TempogramState {
    fn new() -> Self {
        let w = TEMPOGRAM_WIN;
        Self {
            ac: LocalAutocorr::new(w),
            hist: Vec::new(),
            base: 0,
            first: None,
            seg: vec![0.0; w],
            col: vec![0.0; w],
        }
    }

    /// Appends the tempogram row of frame `t` to `out`. `window` holds the
    /// current estimate of onset frames `t0..t0 + window.len()` (frames
    /// before `t0` come from the history); `at_end`: the window's last frame
    /// is the song's last frame.
    fn row(&mut self, t: usize, t0: usize, window: &[f32], at_end: bool, out: &mut Vec<f32>) {
        let half = TEMPOGRAM_WIN / 2;
        let newest = t0 + window.len() - 1;
        // offline: frames t - half ..= t + half - 1; live: shifted back until all are
        // known (early on into the left padding: the window then holds all known frames)
        let centre = if at_end {
            t as i64
        } else {
            (t as i64).min(newest as i64 + 1 - half as i64)
        };
        let first = self
            .first
            .or(if t0 == 0 {
                window.first().copied()
            } else {
                None
            })
            .unwrap_or(0.0);
        let last = window[window.len() - 1];
        let (hist, base) = (&self.hist, self.base);
        let value_at = |f: i64| -> f32 {
            if f < 0 {
                // numpy linear_ramp from 0 up to the first value
                let j = f + half as i64;
                if j < 0 {
                    0.0
                } else {
                    first * (j as f32 / half as f32)
                }
            } else if (f as usize) < t0 {
                (f as usize)
                    .checked_sub(base)
                    .and_then(|i| hist.get(i))
                    .copied()
                    .unwrap_or(0.0)
            } else if (f as usize) <= newest {
                window[f as usize - t0]
            } else {
                // past the song's end (read only when `at_end`): ramp from the last value down to 0
                let k = f as usize - newest - 1;
                if at_end && k < half {
                    last * ((half - 1 - k) as f32 / half as f32)
                } else {
                    0.0
                }
            }
        };
        for (j, s) in self.seg.iter_mut().enumerate() {
            *s = value_at(centre - half as i64 + j as i64);
        }
        self.ac.column(&self.seg, &mut self.col);
        out.extend(self.col.iter().map(|&v| v as f32));
    }

    /// Records the emitted onset values of frames `t0..t0 + v.len()` and
    /// forgets frames no later row reads.
    fn record(&mut self, t0: usize, v: &[f32]) {
        if t0 == 0 && self.first.is_none() {
            self.first = v.first().copied();
        }
        if self.hist.is_empty() {
            self.base = t0;
        }
        debug_assert_eq!(self.base + self.hist.len(), t0);
        self.hist.extend_from_slice(v);
        if self.hist.len() > 2 * TEMPOGRAM_WIN {
            let drop = self.hist.len() - TEMPOGRAM_WIN;
            self.hist.drain(..drop);
            self.base += drop;
        }
    }
}

/// Live feature extractor (one per audio stream; `Send`, not shared).
pub struct Streaming {
    ex: Extractor,
    /// Bailando only
    tempogram: Option<TempogramState>,
    /// the stream has ended (set by `finish`)
    finished: bool,
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
    /// Bailando: running max of the onset spectrogram's dB (its 80 dB floor
    /// hangs from it; offline from the song's max). Duolando keeps the
    /// window's own max, as measured in docs/MUSIC.md.
    onset_top: Option<f32>,
}

impl Streaming {
    /// Duolando's 54-d rows from audio at 15360 Hz.
    pub fn new(cfg: StreamingConfig) -> Self {
        Self::for_set(FeatureSet::Duolando, cfg)
    }

    /// Bailando's 438-d rows from audio at 3840 Hz (see [`StreamingConfig::bailando`]).
    pub fn bailando(cfg: StreamingConfig) -> Self {
        Self::for_set(FeatureSet::Bailando, cfg)
    }

    pub fn for_set(set: FeatureSet, cfg: StreamingConfig) -> Self {
        let tempogram = (set == FeatureSet::Bailando).then(TempogramState::new);
        Self {
            ex: Extractor::for_set(set),
            tempogram,
            finished: false,
            cfg,
            audio: Vec::new(),
            base: 0,
            total: 0,
            emitted: 0,
            db_ref: 0.0,
            onset_top: (set == FeatureSet::Bailando).then_some(f32::NEG_INFINITY),
        }
    }

    /// Which features the rows are.
    pub fn set(&self) -> FeatureSet {
        self.ex.set()
    }

    /// Worst-case delay from a frame's centre sample arriving to its row being emitted.
    pub fn latency_frames(&self) -> usize {
        self.cfg.block - 1 + self.cfg.lookahead + N_FFT / (2 * HOP)
    }

    /// Frames emitted so far.
    pub fn emitted(&self) -> usize {
        self.emitted
    }

    /// Appends `samples` (mono, at the set's sample rate) and writes every
    /// row that became ready to `out` ((n, dim) appended). Returns the number of rows.
    pub fn push(&mut self, samples: &[f32], out: &mut Vec<f32>) -> Result<usize, MusicError> {
        if let Some((i, &v)) = samples.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(MusicError::NonFinite {
                index: self.total + i,
                value: v,
            });
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
        self.finished = true;
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
        let dim = self.ex.set().dim();
        if window.len() < super::MIN_SAMPLES {
            // too little audio for any feature: emit zero rows rather than fail mid-stream
            out.resize(out.len() + (end - t0) * dim, 0.0);
            if let Some(tg) = self.tempogram.as_mut() {
                tg.record(t0, &vec![0.0; end - t0]);
            }
            self.emitted = end;
            return Ok(end - t0);
        }
        let running = &mut self.db_ref;
        let onset_top = &mut self.onset_top;
        let parts = self.ex.parts_with_levels(
            window,
            |m| {
                *running = running.max(m);
                *running
            },
            |max_db| match onset_top {
                Some(top) => {
                    *top = top.max(max_db);
                    *top
                }
                None => max_db,
            },
        )?;
        let f = assemble(&parts);
        let rows = (end - t0).min(f.frames.saturating_sub(t0 - w0));
        match self.tempogram.as_mut() {
            None => out.extend_from_slice(
                &f.data[(t0 - w0) * FEATURE_DIM..(t0 - w0 + rows) * FEATURE_DIM],
            ),
            Some(tg) => {
                let onset = &parts.onset[t0 - w0..]; // frames t0.., newest last
                                                     // `finish` windows reach the last sample
                let at_end = self.finished && s1 == self.total;
                for t in t0..t0 + rows {
                    out.extend_from_slice(f.row(t - w0));
                    tg.row(t, t0, onset, at_end, out);
                }
                tg.record(t0, &onset[..rows]);
                if rows < end - t0 {
                    tg.record(t0 + rows, &vec![0.0; end - t0 - rows]);
                }
            }
        }
        // pad if the window was shorter than the block (end of stream)
        out.resize(out.len() + (end - t0 - rows) * dim, 0.0);
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
