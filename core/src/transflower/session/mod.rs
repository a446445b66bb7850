//! S mode for Transflower: a streaming session that takes audio feature
//! rows (live, or a whole track pushed ahead) and gives motion frames, in
//! fixed memory carved once from the caller's arena (no allocation, ever).
//!
//! ```text
//! new(seed motion (L_out, C), labels, rng seed)
//! push(input i, rows) ─► feed i ─► step t (every sliding input holds its
//!   window from row t; the last input R's longest window) ─► base sample
//!   (the session's seeded RNG, or the caller's) ─► transformers ─► flow
//!   ─► frame t (C) ─► pending ─► pull()
//! ```
//!
//! Frame t is song row `output_time_offset + t`, as in R. With
//! `refresh = 1` ([`Preset::Exact`]) every step is R's
//! (`transflower::exact`), bit for bit; `refresh > 1` is the stale-rows
//! approximation ([`config`]). The seeded RNG is `base::Seeded` (the same
//! numbers as `exact::generate` with `Seeded::new(seed, cfg)`).

pub mod config;
pub mod state;
pub mod step;

use crate::arena::{Arena, ArenaError, Planner};
use crate::error::{check_len, Buffer, Error};
use crate::input;
use crate::transflower::base::{BaseSample, Seeded};
use crate::transflower::config::{TransflowerConfig, MAX_INPUTS};
use crate::transflower::exact::{buffer_of, prepare, Prepared};
use crate::transflower::model::Model;

pub use config::{lookahead_rows, Preset, SessionConfig, MAX_BUFFER, MAX_REFRESH};
pub use step::Scratch;

use state::{is_fed, State};

fn check(model: &TransflowerConfig, cfg: &SessionConfig) -> Result<(), Error> {
    cfg.check()
        .map_err(|(setting, value, max)| Error::Setting {
            setting,
            value,
            max,
        })?;
    model.validate().map_err(|_| Error::State)?;
    Ok(())
}

fn total(p: Planner) -> Result<usize, Error> {
    p.total_for_any_base()
        .ok_or(Error::Arena(ArenaError::Overflow))
}

/// Arena bytes of a session with its own step memory.
pub fn session_bytes(model: &TransflowerConfig, cfg: &SessionConfig) -> Result<usize, Error> {
    check(model, cfg)?;
    let mut p = Planner::new();
    State::carve(&mut p, model, cfg)?;
    Prepared::carve(&mut p, model)?;
    Scratch::carve(&mut p, model, Some(cfg))?;
    total(p)
}

/// Arena bytes of a session stepped only through a [`StepBatch`].
pub fn batched_session_bytes(
    model: &TransflowerConfig,
    cfg: &SessionConfig,
) -> Result<usize, Error> {
    check(model, cfg)?;
    let mut p = Planner::new();
    State::carve(&mut p, model, cfg)?;
    total(p)
}

/// The step memory sessions share ([`StepBatch::step`]), with the flow's
/// reverse 1x1 weights computed once.
pub struct StepBatch<'a> {
    model: *const u8,
    prepared: Prepared<'a>,
    scratch: Scratch<'a>,
}

impl<'a> StepBatch<'a> {
    /// Bytes for sessions of `model` (stale ones too).
    pub fn bytes(model: &TransflowerConfig) -> Result<usize, Error> {
        let mut p = Planner::new();
        Prepared::carve(&mut p, model)?;
        Scratch::carve(&mut p, model, None)?;
        total(p)
    }

    pub fn new(model: &Model<'_>, arena: &'a mut [u8]) -> Result<Self, Error> {
        let mut a = Arena::new(arena);
        let mut prepared = Prepared::carve(&mut a, &model.cfg)?;
        prepare(model, &mut prepared);
        Ok(StepBatch {
            model: model as *const Model<'_> as *const u8,
            prepared,
            scratch: Scratch::carve(&mut a, &model.cfg, None)?,
        })
    }

    /// Steps every ready session once with its own RNG; returns how many
    /// stepped. A session of another model is [`Error::State`] (nothing
    /// stepped); a session whose pending frames are full is skipped.
    pub fn step(&mut self, sessions: &mut [&mut Session<'_>]) -> Result<usize, Error> {
        if sessions
            .iter()
            .any(|s| s.model as *const Model<'_> as *const u8 != self.model)
        {
            return Err(Error::State);
        }
        let mut n = 0;
        for s in sessions.iter_mut() {
            if s.ready() && s.st.pend_len < s.cfg.pending_frames as usize {
                s.draw();
                s.run(Some((&self.prepared, &mut self.scratch)));
                n += 1;
            }
        }
        Ok(n)
    }
}

/// A streaming Transflower dancer.
pub struct Session<'a> {
    model: &'a Model<'a>,
    cfg: SessionConfig,
    st: State<'a>,
    /// The session's own step memory (None: stepped through a [`StepBatch`]).
    own: Option<(Prepared<'a>, Scratch<'a>)>,
    labels: [u32; MAX_INPUTS],
    rng_seed: u64,
    rng: Seeded,
    /// Steps done (= frames made).
    steps: usize,
}

impl<'a> Session<'a> {
    /// A session with its own step memory: `seed` (L_out, C) the motion
    /// seed (the output modality's scaled rows), `labels` one per
    /// discrete input in input order, `rng_seed` the base samples' seed.
    pub fn new(
        model: &'a Model<'a>,
        cfg: &SessionConfig,
        seed: &[f32],
        labels: &[u32],
        rng_seed: u64,
        arena: &'a mut [u8],
    ) -> Result<Self, Error> {
        Self::build(model, cfg, seed, labels, rng_seed, arena, true)
    }

    /// A session that holds only its state; step it with a [`StepBatch`].
    pub fn new_batched(
        model: &'a Model<'a>,
        cfg: &SessionConfig,
        seed: &[f32],
        labels: &[u32],
        rng_seed: u64,
        arena: &'a mut [u8],
    ) -> Result<Self, Error> {
        Self::build(model, cfg, seed, labels, rng_seed, arena, false)
    }

    fn build(
        model: &'a Model<'a>,
        cfg: &SessionConfig,
        seed: &[f32],
        labels: &[u32],
        rng_seed: u64,
        arena: &'a mut [u8],
        own: bool,
    ) -> Result<Self, Error> {
        let mc = &model.cfg;
        check(mc, cfg)?;
        let c = mc.channels();
        check_len(
            Buffer::SeedFrames,
            seed.len(),
            mc.output_input().length as usize * c,
        )?;
        input::check(Buffer::SeedFrames, seed)?;
        let mut lab = [0u32; MAX_INPUTS];
        let discrete: usize = mc.inputs().iter().filter(|i| i.is_discrete()).count();
        check_len(Buffer::Tokens, labels.len(), discrete)?;
        let mut it = labels.iter();
        for (i, ic) in mc.inputs().iter().enumerate() {
            if ic.is_discrete() {
                let v = *it.next().unwrap_or(&0);
                if v >= ic.tokens {
                    return Err(Error::Token {
                        stream: i as u8,
                        token: v,
                        vocab: ic.tokens,
                    });
                }
                lab[i] = v;
            }
        }
        let mut a = Arena::new(arena);
        let st = State::carve(&mut a, mc, cfg)?;
        let own = if own {
            let mut p = Prepared::carve(&mut a, mc)?;
            prepare(model, &mut p);
            Some((p, Scratch::carve(&mut a, mc, Some(cfg))?))
        } else {
            None
        };
        st.seed.copy_from_slice(seed);
        st.window.copy_from_slice(seed);
        Ok(Session {
            model,
            cfg: *cfg,
            st,
            own,
            labels: lab,
            rng_seed,
            rng: Seeded::new(rng_seed, mc),
            steps: 0,
        })
    }

    pub fn config(&self) -> &SessionConfig {
        &self.cfg
    }

    /// The model's configuration.
    pub fn config_model(&self) -> &TransflowerConfig {
        &self.model.cfg
    }

    /// Frames made so far (frame t is song row `output_time_offset + t`).
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Rows of input `i` held (from the next step's window on).
    pub fn held(&self, i: usize) -> usize {
        self.st.feeds.get(i).map_or(0, |f| f.held())
    }

    /// Rows input `i` can take now (its capacity less what it holds).
    pub fn room(&self, i: usize) -> usize {
        self.st.feeds.get(i).map_or(0, |f| f.cap() - f.held())
    }

    /// Appends rows (n, d_i) of sliding input `i` (the audio features,
    /// scaled). Refused, nothing kept: the output modality or a label
    /// ([`Error::State`]), a ragged or non-finite buffer, more rows than
    /// the feed holds ([`Error::Backlog`]: step and pull first).
    pub fn push(&mut self, i: usize, rows: &[f32]) -> Result<(), Error> {
        let mc = &self.model.cfg;
        if i >= mc.inputs().len() || !is_fed(mc, i) {
            return Err(Error::State);
        }
        let buffer = buffer_of(mc, i);
        let d = mc.inputs[i].dim as usize;
        if !rows.len().is_multiple_of(d) {
            return Err(Error::Ragged {
                buffer,
                len: rows.len(),
                row: d,
            });
        }
        input::check(buffer, rows)?;
        self.st.feeds[i].push(rows, buffer)
    }

    /// Whether the session was made by [`Session::new_batched`] (it holds
    /// no step memory: only a [`StepBatch`] steps it).
    pub fn batched(&self) -> bool {
        self.own.is_none()
    }

    /// Whether the next step has its rows.
    pub fn ready(&self) -> bool {
        step::ready(&self.model.cfg, &self.st)
    }

    /// Frames waiting to be pulled.
    pub fn pending(&self) -> usize {
        self.st.pend_len
    }

    fn draw(&mut self) {
        self.rng.sample(self.steps, self.st.z);
    }

    fn precheck(&self) -> Result<bool, Error> {
        if self.st.pend_len >= self.cfg.pending_frames as usize {
            return Err(Error::Backlog {
                buffer: Buffer::Output,
                held: self.st.pend_len,
                capacity: self.cfg.pending_frames as usize,
            });
        }
        if self.own.is_none() {
            return Err(Error::State);
        }
        Ok(self.ready())
    }

    /// One step with the session's seeded base samples: `Ok(true)` made a
    /// frame, `Ok(false)` the inputs are not there yet. Refused: pending
    /// frames full ([`Error::Backlog`]), a batched session (`State`).
    pub fn step(&mut self) -> Result<bool, Error> {
        if !self.precheck()? {
            return Ok(false);
        }
        self.draw();
        self.run(None);
        Ok(true)
    }

    /// [`Session::step`] with the caller's base sample `z` (C, H)
    /// channel-major (e.g. recorded noise); the session's RNG is not drawn.
    pub fn step_with(&mut self, z: &[f32]) -> Result<bool, Error> {
        check_len(Buffer::Features, z.len(), self.st.z.len())?;
        input::check(Buffer::Features, z)?;
        if !self.precheck()? {
            return Ok(false);
        }
        self.st.z.copy_from_slice(z);
        self.run(None);
        Ok(true)
    }

    fn run(&mut self, batch: Option<(&Prepared<'_>, &mut Scratch<'_>)>) {
        let model = self.model;
        match batch {
            Some((p, s)) => step::step(model, p, &self.cfg, &self.labels, &mut self.st, s),
            None => match self.own.as_mut() {
                Some((p, s)) => step::step(model, p, &self.cfg, &self.labels, &mut self.st, s),
                None => return,
            },
        }
        let c = model.cfg.channels();
        let cap = self.cfg.pending_frames as usize;
        let at = (self.st.pend_head + self.st.pend_len) % cap;
        self.st.pending[at * c..(at + 1) * c].copy_from_slice(&self.st.frames[..c]);
        self.st.pend_len += 1;
        self.steps += 1;
    }

    /// Moves up to `out.len() / C` frames (C each) into `out`, oldest
    /// first; returns how many.
    pub fn pull(&mut self, out: &mut [f32]) -> usize {
        let c = self.model.cfg.channels();
        let cap = self.cfg.pending_frames as usize;
        let n = (out.len() / c.max(1)).min(self.st.pend_len);
        for k in 0..n {
            let at = self.st.pend_head;
            out[k * c..(k + 1) * c].copy_from_slice(&self.st.pending[at * c..(at + 1) * c]);
            self.st.pend_head = (at + 1) % cap;
        }
        self.st.pend_len -= n;
        n
    }

    /// Back to the start: the seed motion, no input rows, no frames, the
    /// RNG reseeded with `rng_seed` (or the first seed).
    pub fn reset(&mut self, rng_seed: Option<u64>) {
        self.st.window.copy_from_slice(self.st.seed);
        for f in self.st.feeds.iter_mut() {
            f.clear();
        }
        self.st.pend_head = 0;
        self.st.pend_len = 0;
        if let Some(x) = self.st.stale.as_mut() {
            x.since = 0;
        }
        self.rng_seed = rng_seed.unwrap_or(self.rng_seed);
        self.rng = Seeded::new(self.rng_seed, &self.model.cfg);
        self.steps = 0;
    }
}
