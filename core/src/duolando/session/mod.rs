//! S: the streaming session (docs/STREAMING.md). One leader frame in per
//! tick, follower frames out as soon as the latency budget allows, in
//! fixed memory carved once from a caller arena, at a bounded cost per
//! step.
//!
//! Data flow of one leader frame (one file per concept):
//! normalise ([`crate::duolando::motion`]) -> every `hop` frames, the streaming VQ
//! encoders ([`crate::nn::stream_conv`]) + quantiser give leader code `q` ->
//! the leader LATs ([`lat_stream`]) give condition row `q - a` -> when
//! step `k`'s rows exist (and music row `k`, from the music LAT), the
//! GPT over its chunked window with a K/V cache ([`gpt_cache`]) gives
//! logits -> the sampler chooses follower token `k + 1` -> the streaming
//! VQ decoders give the frames of token `k + 1 - d` -> frames wait for
//! their leader root and are pulled with [`Session::pull_follower_frame`].
//!
//! Thread rule: a [`Model`] is immutable and `Sync` (share it between
//! threads and sessions); a [`Session`] is used by one thread at a time
//! (it is `Send`).

pub mod batch;
pub mod config;

pub mod lat_stream;
mod state;
mod vq_stream;

pub use crate::nn::kv_store::KvType;
pub use batch::{BatchError, StepBatch, StepDims, StepScratch, MAX_BATCH, REPREFILL_CHUNK};
pub use config::{
    dec_future_max, enc_future_max, for_each_live_window, window_context, window_pool,
    window_start, CacheSchedule, Preset, Sampling, SessionConfig, Setting, MAX_WINDOWS,
};

use crate::arena::{Arena, Planner};
use crate::duolando::config::{ModelConfig, POSE_DIM, ROT_DIM};
use crate::duolando::model::Model;
use crate::duolando::motion::{denormalise, normalise};
use crate::error::{check_len, Buffer, Error};
use crate::input;
use crate::nn::sampler::Rng;
use batch::Append;
use state::State;

/// Relative translation scale of the translation VQ-VAE (R's `* 20`).
const TRANSL_SCALE: f32 = 20.0;

/// One follower frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FollowerFrame {
    /// Frame index (the leader frame of the same index is its partner).
    pub index: u64,
    /// (55, 3) joint world positions, metres, in the leader's input
    /// coordinates (SMPL-X: right-handed, y-up).
    pub positions: [f32; POSE_DIM],
    /// (55, 3, 3) per-joint local rotation matrices, row-major, raw
    /// decoder output (not re-orthogonalised).
    pub rotations: [f32; ROT_DIM],
    /// Root (pelvis) world position = `positions[0..3]`.
    pub root: [f32; 3],
}

impl Default for FollowerFrame {
    fn default() -> Self {
        FollowerFrame {
            index: 0,
            positions: [0.0; POSE_DIM],
            rotations: [0.0; ROT_DIM],
            root: [0.0; 3],
        }
    }
}

/// What step `k` did (for agreement measurements and tests).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepReport {
    pub k: usize,
    /// GPT window length and start (token index) of the step.
    pub context: usize,
    pub window_lo: usize,
    /// Window rows computed by this step (1, or the window at a re-prefill).
    pub rows_computed: usize,
    /// S's own choice per head (up, down, lhand, rhand, transl).
    pub pred: [u32; 5],
    /// Token appended to the history (= `pred` unless history is forced).
    pub token: [u32; 5],
}

impl Model<'_> {
    /// Arena bytes [`Session::new`] needs for `cfg` (for a buffer at any
    /// address). Exact: the session carves this and nothing else.
    pub fn session_bytes(&self, cfg: &SessionConfig) -> Result<usize, Error> {
        session_bytes_for(&self.cfg, cfg)
    }
}

impl Model<'_> {
    /// Arena bytes [`Session::new_batched`] needs for `cfg`: the session's
    /// state alone (caches, rings, LAT and conv state), without the working
    /// memory of a step, which a [`StepBatch`] lends it. Exact, for a buffer
    /// at any address.
    pub fn batched_session_bytes(&self, cfg: &SessionConfig) -> Result<usize, Error> {
        batched_session_bytes_for(&self.cfg, cfg)
    }
}

/// [`Model::batched_session_bytes`] from the model's config alone.
pub fn batched_session_bytes_for(model: &ModelConfig, cfg: &SessionConfig) -> Result<usize, Error> {
    check_config(model, cfg)?;
    let mut p = Planner::new();
    State::carve(&mut p, model, cfg)?;
    p.total_for_any_base()
        .ok_or(Error::Arena(crate::arena::ArenaError::Overflow))
}

/// [`Model::session_bytes`] from the model's config alone (no weights):
/// for sizing before a model is loaded, `inspect` and `bench`.
pub fn session_bytes_for(model: &ModelConfig, cfg: &SessionConfig) -> Result<usize, Error> {
    check_config(model, cfg)?;
    let mut p = Planner::new();
    State::carve(&mut p, model, cfg)?;
    StepScratch::carve(&mut p, StepDims::new(model, cfg, 1)?)?;
    p.total_for_any_base()
        .ok_or(Error::Arena(crate::arena::ArenaError::Overflow))
}

pub(crate) fn check_config(model: &ModelConfig, cfg: &SessionConfig) -> Result<(), Error> {
    model
        .validate()
        .map_err(|e| Error::Bind(crate::nn::bind::BindError::Config(e)))?;
    cfg.check(model)
        .map_err(|(setting, value, max)| Error::Setting {
            setting,
            value,
            max,
        })?;
    crate::duolando::coordinated_attention::check_layout(model.gpt.n_streams as usize)
}

fn check_seed(model: &Model<'_>, seed: &[u32; 5]) -> Result<(), Error> {
    let vocab = model.cfg.gpt.vocab;
    for (j, &v) in seed.iter().enumerate() {
        if v >= vocab[j] {
            return Err(Error::Token {
                stream: j as u8,
                token: v,
                vocab: vocab[j],
            });
        }
    }
    Ok(())
}

/// A streaming session over one [`Model`]. All state lives in the arena
/// given to [`Session::new`]; nothing allocates afterwards.
pub struct Session<'a> {
    model: &'a Model<'a>,
    cfg: SessionConfig,
    st: State<'a>,
    /// The working memory of this session's own steps (`n = 1`).
    sc: StepScratch<'a>,
    seed: [u32; 5],
    /// Forced follower history (n, 5): row 0 the seed, row k+1 appended by step k.
    forced: Option<&'a [u32]>,
    /// A preloaded music track (frames, n_music).
    track: Option<&'a [f32]>,
    rng: Rng,
    /// Leader frames pushed.
    frames: usize,
    /// Music frames pushed (ring) or held (track).
    music_frames: usize,
    /// Leader codes emitted.
    codes: usize,
    last_code: Option<[u32; 4]>,
    /// Next step, its GPT appends and the window rows they computed.
    k: usize,
    appends: heapless::Vec<Append, MAX_WINDOWS>,
    rows_computed: usize,
    last_step: Option<StepReport>,
    /// Follower tokens fed to the decoders.
    dec_fed: usize,
    /// Follower frames decoded / pulled.
    decoded: usize,
    emitted: usize,
    root0: [f32; 3],
    /// The leader has ended ([`Session::finish`]): no more leader frames;
    /// steps run up to `step_limit`, then the decoders' tail is decoded.
    ended: bool,
    /// Steps a drained session runs in all (`usize::MAX` while streaming).
    step_limit: usize,
}

impl<'a> Session<'a> {
    /// A session of `model` in `arena` (>= [`Model::session_bytes`]),
    /// seeded with follower tokens `seed` (up, down, lhand, rhand, transl;
    /// from frames: [`crate::duolando::exact::seed_tokens`]).
    pub fn new(
        model: &'a Model<'a>,
        arena: &'a mut [u8],
        cfg: &SessionConfig,
        seed: [u32; 5],
    ) -> Result<Self, Error> {
        let mut s = Self::carve(model, arena, cfg, seed, true)?;
        s.restart()?;
        Ok(s)
    }

    /// A session without step memory of its own, in `arena` (>=
    /// [`Model::batched_session_bytes`]: the state alone, 1.8 MB less than
    /// [`Model::session_bytes`] at full size): for many sessions stepped
    /// together ([`Session::step_many`]), which all run in one
    /// [`StepBatch`]'s memory. Everything else that may run a step (the
    /// seed's decoding here; [`Session::push_music_frame`],
    /// [`Session::set_music_track`], [`Session::reset`],
    /// [`Session::push_leader_frame`]) runs inside [`Session::with_batch`]:
    /// called alone, they answer [`Error::State`] and change nothing. The
    /// numbers are those of [`Session::new`]'s session, bit for bit.
    pub fn new_batched(
        model: &'a Model<'a>,
        arena: &'a mut [u8],
        cfg: &SessionConfig,
        seed: [u32; 5],
        batch: &mut StepBatch<'a>,
    ) -> Result<Self, Error> {
        let mut s = Self::carve(model, arena, cfg, seed, false)?;
        s.with_batch(batch, |s| s.restart())??;
        Ok(s)
    }

    /// The state, and the session's own step scratch where `own_scratch`
    /// (else none: its dims only, for [`StepBatch`] checks).
    fn carve(
        model: &'a Model<'a>,
        arena: &'a mut [u8],
        cfg: &SessionConfig,
        seed: [u32; 5],
        own_scratch: bool,
    ) -> Result<Self, Error> {
        check_config(&model.cfg, cfg)?;
        check_seed(model, &seed)?;
        let mut a = Arena::new(arena);
        let st = State::carve(&mut a, &model.cfg, cfg)?;
        let dims = StepDims::new(&model.cfg, cfg, 1)?;
        let sc = if own_scratch {
            StepScratch::carve(&mut a, dims)?
        } else {
            StepScratch {
                dims,
                ..StepScratch::default()
            }
        };
        let mut s = Session {
            model,
            cfg: *cfg,
            st,
            sc,
            seed,
            forced: None,
            track: None,
            rng: Rng(0),
            frames: 0,
            music_frames: 0,
            codes: 0,
            last_code: None,
            k: 0,
            appends: heapless::Vec::new(),
            rows_computed: 0,
            last_step: None,
            dec_fed: 0,
            decoded: 0,
            emitted: 0,
            root0: [0.0; 3],
            ended: false,
            step_limit: usize::MAX,
        };
        s.st.init_codebooks(model);
        Ok(s)
    }

    /// Runs `f` on this session with `batch`'s memory as its step memory
    /// (lent for the call, then given back), and returns what `f` returns:
    /// how a session made by [`Session::new_batched`] pushes music, sets a
    /// track, resets or steps alone. [`Error::State`] (and `f` not run)
    /// if `batch` is smaller than the session needs (made for another
    /// config).
    pub fn with_batch<R>(
        &mut self,
        batch: &mut StepBatch<'a>,
        f: impl FnOnce(&mut Self) -> R,
    ) -> Result<R, Error> {
        if !batch.sc.dims.holds(&self.sc.dims) {
            return Err(Error::State);
        }
        core::mem::swap(&mut self.sc, &mut batch.sc);
        let r = f(self);
        core::mem::swap(&mut self.sc, &mut batch.sc);
        Ok(r)
    }

    /// [`Error::State`] where the session has no step memory now.
    fn check_step_memory(&self) -> Result<(), Error> {
        if self.has_step_memory() {
            Ok(())
        } else {
            Err(Error::State)
        }
    }

    /// Whether the session holds step memory now: its own, or a batch's
    /// lent by [`Session::with_batch`].
    pub fn has_step_memory(&self) -> bool {
        !self.sc.x.is_empty()
    }

    /// Back to the start with a new seed (forced history and music track
    /// are dropped). Nothing allocates.
    pub fn reset(&mut self, seed: [u32; 5]) -> Result<(), Error> {
        self.check_step_memory()?;
        check_seed(self.model, &seed)?;
        self.seed = seed;
        self.forced = None;
        self.track = None;
        self.restart()
    }

    fn restart(&mut self) -> Result<(), Error> {
        self.st.reset();
        self.rng = Rng(self.cfg.sampling.rng_seed());
        self.frames = 0;
        self.music_frames = 0;
        self.codes = 0;
        self.last_code = None;
        self.k = 0;
        self.appends.clear();
        self.rows_computed = 0;
        self.last_step = None;
        self.dec_fed = 0;
        self.decoded = 0;
        self.emitted = 0;
        self.root0 = [0.0; 3];
        self.ended = false;
        self.step_limit = usize::MAX;
        let seed = self.seed;
        self.st.toks.push(&seed)?;
        self.with_own_scratch(|ss, sc| vq_stream::decode(ss, &[0], &[seed], sc))
    }

    pub fn config(&self) -> &SessionConfig {
        &self.cfg
    }

    /// Delay in frames between a leader frame and the follower frame of
    /// the same index: with a music track ([`Session::set_music_track`]),
    /// [`SessionConfig::latency_frames`] = `max(0, hop (a + e + d) - 1)`;
    /// otherwise (music pushed frame by frame, at least `music_lookahead`
    /// tokens ahead of the leader) [`SessionConfig::live_latency_frames`]
    /// = `max(that, hop (d + 1) - 1)`. Every follower frame `f` is
    /// ready once leader frame `f + latency_frames` is pushed (tested).
    pub fn latency_frames(&self) -> u32 {
        let hop = self.model.cfg.hop() as u32;
        match self.track {
            Some(_) => self.cfg.latency_frames(hop),
            None => self.cfg.live_latency_frames(hop),
        }
    }

    /// Leader frames pushed so far.
    pub fn frames_pushed(&self) -> usize {
        self.frames
    }

    /// Steps run so far (= follower tokens predicted).
    pub fn steps(&self) -> usize {
        self.k
    }

    /// The most recent step (at most one step runs per leader frame when
    /// music is known ahead).
    pub fn last_step(&self) -> Option<StepReport> {
        self.last_step
    }

    /// Leader codes computed so far and the latest (up, down, lhand, rhand).
    pub fn leader_codes(&self) -> (usize, Option<[u32; 4]>) {
        (self.codes, self.last_code)
    }

    /// Forced-history mode (one-step agreement, seeding motion): `tokens`
    /// (n, 5), row 0 must equal the seed; step `k` still computes and
    /// reports its own choice, but appends `tokens[k + 1]`. Steps stop at
    /// `n - 1`. Only before the first leader frame.
    pub fn force_history(&mut self, tokens: &'a [u32]) -> Result<(), Error> {
        if self.ended {
            return Err(Error::Ended {
                frames: self.frames,
            });
        }
        if self.frames > 0 || self.k > 0 {
            return Err(Error::State);
        }
        if tokens.len() < 5 || tokens.len() % 5 != 0 {
            return Err(Error::Ragged {
                buffer: Buffer::Tokens,
                len: tokens.len(),
                row: 5,
            });
        }
        let vocab = self.model.cfg.gpt.vocab;
        for (i, &t) in tokens.iter().enumerate() {
            if t >= vocab[i % 5] {
                return Err(Error::Token {
                    stream: (i % 5) as u8,
                    token: t,
                    vocab: vocab[i % 5],
                });
            }
        }
        if tokens[..5] != self.seed {
            return Err(Error::State);
        }
        self.forced = Some(tokens);
        Ok(())
    }

    /// Uses a whole music track (frames, n_music), known in advance, instead
    /// of [`Session::push_music_frame`]. The session borrows it. Only before
    /// any music frame was pushed.
    pub fn set_music_track(&mut self, track: &'a [f32]) -> Result<(), Error> {
        self.check_step_memory()?;
        let n_music = self.model.cfg.gpt.music.n_in as usize;
        if self.music_frames > 0 || self.track.is_some() {
            return Err(Error::State);
        }
        if n_music == 0 || track.len() % n_music != 0 {
            return Err(Error::Ragged {
                buffer: Buffer::Music,
                len: track.len(),
                row: n_music,
            });
        }
        input::check(Buffer::Music, track)?;
        self.track = Some(track);
        self.music_frames = track.len() / n_music;
        self.with_own_scratch(batch::pump)
    }

    /// Appends one music feature frame (n_music). Non-finite values are
    /// rejected (`NonFinite`, or `OutOfRange` above `input::MAX_MUSIC_FEATURE`)
    /// and leave the session unchanged; so does a
    /// full music buffer (`Backlog`: push leader frames first).
    pub fn push_music_frame(&mut self, features: &[f32]) -> Result<(), Error> {
        self.check_step_memory()?;
        if self.track.is_some() {
            return Err(Error::State);
        }
        check_len(
            Buffer::Music,
            features.len(),
            self.model.cfg.gpt.music.n_in as usize,
        )?;
        input::check(Buffer::Music, features)?;
        let held = self.music_held();
        let cap = self.st.music.capacity();
        if held >= cap {
            return Err(Error::Backlog {
                buffer: Buffer::Music,
                held,
                capacity: cap,
            });
        }
        self.st.music.push(features)?;
        self.music_frames += 1;
        self.with_own_scratch(batch::pump)
    }

    /// Music frames the session holds: pushed and not yet read by the
    /// music LAT. The LAT reads from frame `music_motion_rate` on (R's
    /// offset); the frames before it count as held until it starts
    /// reading, so at most `music_buffer_frames` frames are ever pushed
    /// beyond those read (before: `music_motion_rate` more in a fresh
    /// session).
    pub fn music_held(&self) -> usize {
        let mmr = self.model.cfg.music_motion_rate as usize;
        let read = match self.st.music_lat.pushed() {
            0 => 0,
            p => p + mmr,
        };
        self.music_frames.saturating_sub(read)
    }

    /// Appends one leader frame (165 floats: 55 joints x xyz, metres, world
    /// coordinates, SMPL-X order). Non-finite values are rejected
    /// (`NonFinite`, or `OutOfRange` above `input::MAX_POSITION_M`) and leave
    /// the session unchanged (the caller may push
    /// its last good frame instead); so does a full output buffer
    /// (`Backlog`: pull follower frames first).
    pub fn push_leader_frame(&mut self, pos3d: &[f32]) -> Result<(), Error> {
        self.check_step_memory()?;
        self.check_leader_frame(pos3d)?;
        self.accept_leader_frame(pos3d)?;
        self.with_own_scratch(batch::advance)
    }

    /// Pushes one leader frame into each session (`frames[i]` into
    /// `sessions[i]`) and runs the steps that become possible, with the
    /// weight-heavy work (LATs, GPT, heads) batched: each weight matrix is
    /// read once for all sessions. Every session ends exactly as after its
    /// own [`Session::push_leader_frame`] (bit for bit).
    ///
    /// The sessions must share one model and fit `batch` (at most
    /// [`StepBatch::capacity`] sessions, configs no larger than the one
    /// `batch` was made for); else `Err((i, Error::State))` /
    /// `Setting::Batch` before anything changes. A refused frame
    /// (non-finite, out of range, wrong length, backlog) gives `Err((i, e))`
    /// for the first such session, and no session changes. A failure
    /// inside a step (an engine bug) names a session of the failing group.
    pub fn step_many(
        sessions: &mut [&mut Session<'a>],
        frames: &[&[f32]],
        batch: &mut StepBatch<'_>,
    ) -> Result<(), BatchError> {
        let n = sessions.len();
        if n > batch.capacity() {
            return Err((
                0,
                Error::Setting {
                    setting: Setting::Batch,
                    value: n.min(u32::MAX as usize) as u32,
                    max: batch.capacity() as u32,
                },
            ));
        }
        check_len(Buffer::LeaderPos3d, frames.len(), n).map_err(|e| (0, e))?;
        let Some(first) = sessions.first() else {
            return Ok(());
        };
        let model = first.model;
        for (i, s) in sessions.iter().enumerate() {
            // The session's own scratch was carved for its needs (`StepDims::new(cfg, s.cfg, 1)`).
            if !core::ptr::eq(s.model, model) || !batch.sc.dims.holds(&s.sc.dims) {
                return Err((i, Error::State));
            }
            s.check_leader_frame(frames[i]).map_err(|e| (i, e))?;
        }
        for (i, s) in sessions.iter_mut().enumerate() {
            s.accept_leader_frame(frames[i]).map_err(|e| (i, e))?;
        }
        batch::advance(sessions, &mut batch.sc)
    }

    /// Runs `f` over this session alone with its step scratch ([`Error::State`]
    /// where it has none: [`Session::new_batched`] outside [`Session::with_batch`]).
    fn with_own_scratch(
        &mut self,
        f: impl FnOnce(&mut [&mut Session<'a>], &mut StepScratch<'a>) -> Result<(), BatchError>,
    ) -> Result<(), Error> {
        self.check_step_memory()?;
        let mut sc = core::mem::take(&mut self.sc);
        let r = f(&mut [&mut *self], &mut sc);
        self.sc = sc;
        r.map_err(|(_, e)| e)
    }

    /// Every refusal of [`Session::push_leader_frame`], changing nothing.
    fn check_leader_frame(&self, pos3d: &[f32]) -> Result<(), Error> {
        if self.ended {
            return Err(Error::Ended {
                frames: self.frames,
            });
        }
        check_len(Buffer::LeaderPos3d, pos3d.len(), POSE_DIM)?;
        input::check(Buffer::LeaderPos3d, pos3d)?;
        let held = self.frames - self.emitted;
        let cap = self.latency_frames() as usize + 1 + self.cfg.pending_frames as usize;
        if held >= cap {
            return Err(Error::Backlog {
                buffer: Buffer::FollowerPos3d,
                held,
                capacity: cap,
            });
        }
        // Leader rows there would be with every code in the LATs (codes
        // minus the look-ahead), beyond step k's.
        let waiting = self
            .codes
            .saturating_sub(self.cfg.lookahead as usize)
            .saturating_sub(self.k);
        if waiting >= self.st.cond_slack {
            return Err(Error::Backlog {
                buffer: Buffer::Music,
                held: waiting,
                capacity: self.st.cond_slack,
            });
        }
        Ok(())
    }

    /// Takes a checked leader frame: normalised into the token being
    /// filled (a complete token runs the encoders in the step that follows:
    /// `vq_stream::encode`).
    fn accept_leader_frame(&mut self, pos3d: &[f32]) -> Result<(), Error> {
        if self.frames == 0 {
            self.root0 = [pos3d[0], pos3d[1], pos3d[2]];
        }
        self.st.roots.push(&pos3d[..3])?;
        let hop = self.model.cfg.hop();
        let slot = self.frames % hop;
        normalise(
            pos3d,
            &mut self.st.block[slot * POSE_DIM..(slot + 1) * POSE_DIM],
        );
        self.frames += 1;
        Ok(())
    }

    /// Ends step `k` with the sampler's choice `pred`: appends the token
    /// (or the forced one) to the history and returns it (for the decoders:
    /// `vq_stream::decode`).
    fn finish_step(&mut self, pred: [u32; 5]) -> Result<[u32; 5], Error> {
        let k = self.k;
        let m = self.model.cfg.gpt.block_size as usize - 1;
        let c = window_context(k, m, self.cfg.shift as usize);
        let token = match self.forced {
            Some(f) => {
                let mut t = [0u32; 5];
                t.copy_from_slice(f.get((k + 1) * 5..(k + 2) * 5).ok_or(Error::State)?);
                t
            }
            None => pred,
        };
        self.st.toks.push(&token)?;
        self.last_step = Some(StepReport {
            k,
            context: c,
            window_lo: k + 1 - c,
            rows_computed: self.rows_computed,
            pred,
            token,
        });
        self.rows_computed = 0;
        self.k += 1;
        Ok(token)
    }

    /// The next follower frame, if it is ready (decoded, and its leader
    /// frame pushed): `Ok(true)` and `out` written; `Ok(false)` otherwise
    /// (`out` untouched).
    pub fn pull_follower_frame(&mut self, out: &mut FollowerFrame) -> Result<bool, Error> {
        let f = self.emitted;
        if self.ended && f >= self.decoded && f < self.frames {
            // Drained: the steps left, as many as the frame ring holds,
            // then the next token's frames from the decoders' final prefix.
            if self.steps_left() {
                self.with_own_scratch(batch::pump)?;
            }
            if f >= self.decoded && self.tail_left() {
                self.with_own_scratch(|ss, sc| vq_stream::decode_end(ss, sc))?;
            }
        }
        if f >= self.decoded || f >= self.frames {
            return Ok(false);
        }
        let row = self.st.pending.row(f)?;
        let root = self.st.roots.row(f)?;
        let mut pos = [0.0f32; POSE_DIM];
        pos.copy_from_slice(&row[..POSE_DIM]);
        let tr = &row[POSE_DIM + ROT_DIM..POSE_DIM + ROT_DIM + 3];
        for a in 0..3 {
            pos[a] = (root[a] - self.root0[a]) + tr[a] / TRANSL_SCALE;
        }
        denormalise(&mut pos);
        for (j, v) in pos.iter_mut().enumerate() {
            *v += self.root0[j % 3];
        }
        out.index = f as u64;
        out.rotations
            .copy_from_slice(&row[POSE_DIM..POSE_DIM + ROT_DIM]);
        out.root = [pos[0], pos[1], pos[2]];
        out.positions = pos;
        self.emitted += 1;
        Ok(true)
    }

    /// Follower frames pulled so far.
    pub fn frames_pulled(&self) -> usize {
        self.emitted
    }

    /// The leader has ended: decode what the look-ahead allows, as R does
    /// at the end of a clip (docs/STREAMING.md §2 "Drain"). With `T`
    /// leader frames pushed (`Q = T / hop` whole tokens):
    /// - the last leader codes (those still waiting for `e` tokens of
    ///   future) come from the encoders run on all `Q` tokens, with the end
    ///   padding there (S's definition, `n_q = min(T4, ...)`: R's codes);
    /// - steps run up to R's step count for `T` frames, `K = (T4 - 4) / 4 -
    ///   29` ([`crate::duolando::exact::output_shape`]), or the steps already run if
    ///   more (music pushed with less look-ahead than `look_forward`); as
    ///   ever each step waits for its music (push the music up to frame
    ///   `T4` if it is not a track; R needs it too);
    /// - then the frames of the last `d` tokens are decoded from the whole
    ///   token sequence (R's decoding of its end), pulled as usual.
    ///
    /// The steps left run here and in [`Session::pull_follower_frame`], as
    /// many at a time as the decoded-frame ring has room for (no leader
    /// push paces them any more), so pull until it answers `false`.
    ///
    /// So a drained session outputs `hop (K + 1)` frames, R's count
    /// (`music_lookahead = look_forward`); fewer than `hop` leader frames
    /// give only the seed token's frames up to `T`. Afterwards leader
    /// frames and forced history answer [`Error::Ended`] (the session
    /// unchanged) until [`Session::reset`]; music may still be pushed.
    /// Calling it again does nothing. A session of
    /// [`Session::new_batched`] finishes and pulls its drained frames
    /// inside [`Session::with_batch`] ([`Error::State`] otherwise).
    pub fn finish(&mut self) -> Result<(), Error> {
        self.check_step_memory()?;
        if self.ended {
            return Ok(());
        }
        let r_steps = crate::duolando::exact::output_shape(&self.model.cfg, self.frames)
            .map_or(0, |sh| sh.steps);
        self.ended = true;
        self.step_limit = self.k.max(r_steps);
        self.with_own_scratch(batch::pump)
    }

    /// Follower token row `j` of the history (row 0 the seed, row `k + 1`
    /// appended by step `k`), while the session still holds it (the
    /// newest `block_size` rows; [`Error::Evicted`] otherwise).
    pub fn history_row(&self, j: usize) -> Result<[u32; 5], Error> {
        let mut t = [0u32; 5];
        t.copy_from_slice(self.st.toks.row(j)?);
        Ok(t)
    }

    /// Whether [`Session::finish`] was called (since the last reset).
    pub fn is_finished(&self) -> bool {
        self.ended
    }

    /// A drained session whose steps are all done (or cannot run: the
    /// forced history ended) still has decoded frames to compute.
    fn tail_left(&self) -> bool {
        let hop = self.model.cfg.hop();
        self.ended && !self.steps_left() && self.decoded < hop * self.dec_fed
    }

    /// Steps are left to run (the limit of a drained session, the forced
    /// history), inputs aside.
    fn steps_left(&self) -> bool {
        self.k < self.step_limit && self.forced.is_none_or(|f| self.k + 1 < f.len() / 5)
    }

    /// Step `k` may run now, inputs aside: steps are left and, in a
    /// drained session (whose steps no leader push paces any more), the
    /// frames it completes fit the frame ring: the rest run as frames are
    /// pulled.
    pub(crate) fn step_possible(&self) -> bool {
        let room = !self.ended
            || self.decoded - self.emitted + self.model.cfg.hop() <= self.st.pending.capacity();
        self.steps_left() && room
    }

    /// A drained session wants its next leader code (the steps left need
    /// it, and it fits the code ring: the push-time rule of
    /// [`Session::push_leader_frame`]).
    pub(crate) fn end_code_wanted(&self) -> bool {
        let hop = self.model.cfg.hop();
        let a = self.cfg.lookahead as usize;
        let need = (self.frames / hop).min(self.step_limit.saturating_add(a));
        let waiting = self.codes.saturating_sub(a).saturating_sub(self.k);
        self.ended && self.codes < need && waiting < self.st.cond_slack
    }
}
