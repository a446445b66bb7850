//! S mode for Bailando: a streaming session that takes music rows (live,
//! or a whole track pushed ahead) and gives SMPL-24 frames at the latency
//! its [`SessionConfig`] chooses, in fixed memory carved once from the
//! caller's arena (no allocation, ever).
//!
//! ```text
//! push_music(rows) ─► music ring ─► step k: GPT window row k (token k,
//!   music row k + 1) ─► heads ─► token k + 1 ─► decoders (up, down, root)
//!   ─► frames of token q once token q + d exists ─► pending ─► pull()
//! ```
//!
//! With [`Preset::Exact`] (sliding window, full decoder future) the tokens
//! and frames are R's (`bailando::exact`), tested against the authors'
//! goldens; other budgets trade that for speed and latency
//! (docs/BAILANDO.md "S mode").

pub mod config;
pub mod state;
pub mod step;

use crate::arena::{Arena, ArenaError, Planner};
use crate::bailando::config::{BailandoConfig, POSE_DIM};
use crate::bailando::exact::{padded_rows, MusicPadding};
use crate::bailando::model::Model;
use crate::error::{check_len, Buffer, Error};
use crate::input;
use crate::nn::sampler::Rng;

pub use config::{dec_future_max, window_rows, CacheSchedule, Preset, SessionConfig};
pub use state::{StepScratch, PREFILL_CHUNK};
pub use step::{step_many, BatchError};

use state::State;

/// Arena bytes of a session with its own step memory.
pub fn session_bytes_for(model: &BailandoConfig, cfg: &SessionConfig) -> Result<usize, Error> {
    check_config(model, cfg)?;
    let mut p = Planner::new();
    State::carve(&mut p, model, cfg)?;
    StepScratch::carve_own(&mut p, model, cfg)?;
    p.total_for_any_base()
        .ok_or(Error::Arena(ArenaError::Overflow))
}

/// Arena bytes of a session stepped only through a [`StepBatch`] (its
/// state alone).
pub fn batched_session_bytes_for(
    model: &BailandoConfig,
    cfg: &SessionConfig,
) -> Result<usize, Error> {
    check_config(model, cfg)?;
    let mut p = Planner::new();
    State::carve(&mut p, model, cfg)?;
    p.total_for_any_base()
        .ok_or(Error::Arena(ArenaError::Overflow))
}

fn check_config(model: &BailandoConfig, cfg: &SessionConfig) -> Result<(), Error> {
    model
        .validate()
        .map_err(|e| Error::Bind(crate::nn::bind::BindError::Config(e)))?;
    cfg.check(model)
        .map_err(|(setting, value, max)| Error::Setting {
            setting,
            value,
            max,
        })?;
    // `SessionConfig::check` bounds k by the vocabularies and by MAX_TOP_K
    // (`Sampling::check`).
    Ok(())
}

impl Model<'_> {
    /// Arena bytes [`Session::new`] needs (exact, any base address).
    pub fn session_bytes(&self, cfg: &SessionConfig) -> Result<usize, Error> {
        session_bytes_for(&self.cfg, cfg)
    }

    /// Arena bytes [`Session::new_batched`] needs.
    pub fn batched_session_bytes(&self, cfg: &SessionConfig) -> Result<usize, Error> {
        batched_session_bytes_for(&self.cfg, cfg)
    }
}

/// Working memory for stepping up to `n` sessions of one model together
/// ([`step_many`]), carved from its own arena.
pub struct StepBatch<'a> {
    pub scratch: StepScratch<'a>,
}

impl<'a> StepBatch<'a> {
    pub fn bytes(model: &BailandoConfig, n: usize) -> Result<usize, Error> {
        check_batch(n)?;
        let mut p = Planner::new();
        StepScratch::carve(&mut p, model, n)?;
        p.total_for_any_base()
            .ok_or(Error::Arena(ArenaError::Overflow))
    }

    pub fn new(model: &BailandoConfig, n: usize, arena: &'a mut [u8]) -> Result<Self, Error> {
        check_batch(n)?;
        let mut a = Arena::new(arena);
        Ok(StepBatch {
            scratch: StepScratch::carve(&mut a, model, n)?,
        })
    }

    /// Steps every ready session once (see [`step_many`]).
    pub fn step(&mut self, ss: &mut [&mut Session<'_>]) -> Result<usize, BatchError> {
        step_many(ss, &mut self.scratch)
    }
}

fn check_batch(n: usize) -> Result<(), Error> {
    let max = crate::nn::gpt_cache::MAX_BATCH;
    if n == 0 || n > max {
        return Err(Error::Setting {
            setting: crate::error::Setting::Batch,
            value: n.min(u32::MAX as usize) as u32,
            max: max as u32,
        });
    }
    Ok(())
}

/// What step `k` did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepReport {
    pub k: usize,
    /// Token `k + 1` (up, down).
    pub token: [u32; 2],
}

/// A streaming Bailando dancer.
pub struct Session<'a> {
    pub(crate) model: &'a Model<'a>,
    pub(crate) cfg: SessionConfig,
    pub(crate) st: State<'a>,
    /// The session's own step memory (None for a batched session).
    own: Option<StepScratch<'a>>,
    seed: [u32; 2],
    pub(crate) rng: Rng,
    /// Steps done (tokens made = steps + 1, the seed first).
    pub(crate) steps: usize,
    /// Music rows pushed.
    rows: usize,
    /// Music rows after the end padding, once the music has ended.
    end: Option<usize>,
    /// Tokens fed to the decoders.
    pub(crate) dec_fed: usize,
    /// Frames decoded (into the pending ring) and pulled.
    pub(crate) decoded: usize,
    pulled: usize,
    /// Root position of the next frame decoded.
    pub(crate) root: [f32; 3],
    /// Window rows re-run at window jumps, in total (a cost measure).
    pub prefilled: usize,
    /// Rows of next windows appended ahead (spread schedule), in total.
    pub spread_rows: usize,
}

impl<'a> Session<'a> {
    /// A session with its own step memory; `seed` is token 0 (up, down):
    /// the authors' demo uses (423, 12) for their model.
    pub fn new(
        model: &'a Model<'a>,
        arena: &'a mut [u8],
        cfg: &SessionConfig,
        seed: [u32; 2],
    ) -> Result<Self, Error> {
        Self::carve(model, arena, cfg, seed, true)
    }

    /// A session without step memory: stepped only by [`step_many`] /
    /// [`StepBatch::step`] ([`Session::pull`] gives the frames decoded).
    pub fn new_batched(
        model: &'a Model<'a>,
        arena: &'a mut [u8],
        cfg: &SessionConfig,
        seed: [u32; 2],
    ) -> Result<Self, Error> {
        Self::carve(model, arena, cfg, seed, false)
    }

    fn carve(
        model: &'a Model<'a>,
        arena: &'a mut [u8],
        cfg: &SessionConfig,
        seed: [u32; 2],
        own: bool,
    ) -> Result<Self, Error> {
        check_config(&model.cfg, cfg)?;
        check_seed(model, seed)?;
        let mut a = Arena::new(arena);
        let st = State::carve(&mut a, &model.cfg, cfg)?;
        let own = if own {
            Some(StepScratch::carve_own(&mut a, &model.cfg, cfg)?)
        } else {
            None
        };
        let mut s = Session {
            model,
            cfg: *cfg,
            st,
            own,
            seed,
            rng: Rng(0),
            steps: 0,
            rows: 0,
            end: None,
            dec_fed: 0,
            decoded: 0,
            pulled: 0,
            root: [0.0; 3],
            prefilled: 0,
            spread_rows: 0,
        };
        s.restart(seed)?;
        Ok(s)
    }

    fn restart(&mut self, seed: [u32; 2]) -> Result<(), Error> {
        self.st.reset();
        self.st.toks.push(&seed)?;
        self.seed = seed;
        self.rng = Rng(self.cfg.sampling.rng_seed());
        (
            self.steps,
            self.rows,
            self.end,
            self.dec_fed,
            self.decoded,
            self.pulled,
            self.root,
            self.prefilled,
            self.spread_rows,
        ) = (0, 0, None, 0, 0, 0, [0.0; 3], 0, 0);
        Ok(())
    }

    /// Back to a new session with seed `seed` (no allocation); a bad seed
    /// changes nothing.
    pub fn reset(&mut self, seed: [u32; 2]) -> Result<(), Error> {
        check_seed(self.model, seed)?;
        self.restart(seed)
    }

    pub fn config(&self) -> &SessionConfig {
        &self.cfg
    }

    /// Frames of latency (see [`SessionConfig::latency_frames`]).
    pub fn latency_frames(&self) -> u32 {
        self.cfg.latency_frames(self.model.cfg.hop() as u32)
    }

    /// Music rows pushed so far.
    pub fn music_rows(&self) -> usize {
        self.rows
    }

    /// Tokens made so far (the seed first), and the newest.
    pub fn tokens(&self) -> usize {
        self.steps + 1
    }

    /// Token `i` (up, down) while the session still holds it (the last
    /// `block_size` tokens).
    pub fn token(&self, i: usize) -> Result<[u32; 2], Error> {
        let t = self.st.toks.row(i)?;
        Ok([t[0], t[1]])
    }

    /// Frames decoded and not yet pulled.
    pub fn frames_ready(&self) -> usize {
        self.decoded - self.pulled
    }

    /// Pushes music rows (row-major, `n_music` floats each; one or more
    /// whole rows), all or none: `Backlog` when more than
    /// `music_buffer_rows` would wait unread by a step, `State` after
    /// [`Session::finish`], a named error for a wrong length or a NaN.
    pub fn push_music(&mut self, rows: &[f32]) -> Result<(), Error> {
        if self.end.is_some() {
            return Err(Error::State);
        }
        let nm = self.model.cfg.gpt.n_music as usize;
        if rows.is_empty() || rows.len() % nm != 0 {
            return Err(Error::Ragged {
                buffer: Buffer::Music,
                len: rows.len(),
                row: nm,
            });
        }
        input::check(Buffer::Music, rows)?;
        let n = rows.len() / nm;
        // Rows 0..=steps have been read (row 0 by none: step k reads k + 1).
        let waiting = self.rows.saturating_sub(self.steps + 1);
        let cap = self.cfg.music_buffer_rows as usize;
        if (self.rows + n).saturating_sub(self.steps + 1) > cap {
            return Err(Error::Backlog {
                buffer: Buffer::Music,
                held: waiting,
                capacity: cap,
            });
        }
        for r in rows.chunks_exact(nm) {
            self.st.music.push(r)?;
        }
        self.rows += n;
        Ok(())
    }

    /// The music has ended: the session pads it as the authors' loader of
    /// `padding`'s path does (copies of the last row) and runs to the end
    /// of the padded music. `State` without any music row, or if already
    /// ended.
    pub fn finish(&mut self, padding: MusicPadding) -> Result<(), Error> {
        if self.end.is_some() || self.rows == 0 {
            return Err(Error::State);
        }
        self.end = Some(padded_rows(padding, self.rows));
        Ok(())
    }

    /// True once the music has ended and every frame has been pulled.
    pub fn done(&self) -> bool {
        self.end
            .is_some_and(|e| self.steps + 1 == e && self.pulled == e * self.model.cfg.hop())
    }

    /// Music row `i` as the GPT reads it (past the end: the padding's
    /// copies of the last row).
    pub(crate) fn music_row(&self, i: usize) -> Result<&[f32], Error> {
        let i = if self.end.is_some() {
            i.min(self.rows.saturating_sub(1))
        } else {
            i
        };
        self.st.music.row(i)
    }

    /// Step `k = steps` can run: its music row exists and its frames
    /// would not overflow the pending ring.
    pub(crate) fn can_step(&self) -> bool {
        let avail = self.end.unwrap_or(self.rows);
        self.steps + 1 < avail && self.frames_ready() <= self.cfg.pending_frames as usize
    }

    /// The next token's frames are final: `dec_future` later tokens are
    /// in the decoders, or every token of an ended session is.
    pub(crate) fn frames_final(&self) -> bool {
        let hop = self.model.cfg.hop();
        let q = self.decoded / hop;
        let all_in = self.end.is_some_and(|e| self.dec_fed == e);
        q < self.dec_fed && (self.dec_fed > q + self.cfg.dec_future as usize || all_in)
    }

    /// One step if one can run (music row there, room for its frames),
    /// with the session's own step memory (`State` for a batched session).
    pub fn step(&mut self) -> Result<Option<StepReport>, Error> {
        let mut sc = self.own.take().ok_or(Error::State)?;
        let r = step_many(&mut [&mut *self], &mut sc);
        self.own = Some(sc);
        match r {
            Ok(0) => Ok(None),
            Ok(_) => Ok(Some(StepReport {
                k: self.steps - 1,
                token: self.token(self.steps)?,
            })),
            Err((_, e)) => Err(e),
        }
    }

    /// The next frame (72 floats: 24 joints x xyz, world positions, the
    /// root integrated from 0 as R does) into `out`, and its index; None
    /// when no frame can be given yet (push music, or `finish`). A session
    /// with its own step memory runs the steps a frame needs.
    pub fn pull(&mut self, out: &mut [f32]) -> Result<Option<u64>, Error> {
        check_len(Buffer::Output, out.len(), POSE_DIM)?;
        if self.frames_ready() == 0 && self.own.is_some() {
            while self.frames_ready() == 0 && self.step()?.is_some() {}
        }
        if self.frames_ready() == 0 {
            return Ok(None);
        }
        out.copy_from_slice(self.st.pending.row(self.pulled)?);
        self.pulled += 1;
        Ok(Some(self.pulled as u64 - 1))
    }
}

fn check_seed(model: &Model<'_>, seed: [u32; 2]) -> Result<(), Error> {
    for (j, &v) in seed.iter().enumerate() {
        if v >= model.cfg.gpt.vocab[j] {
            return Err(Error::Token {
                stream: j as u8,
                token: v,
                vocab: model.cfg.gpt.vocab[j],
            });
        }
    }
    Ok(())
}
