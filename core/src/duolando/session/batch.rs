//! The phases of a streaming step over several sessions at once
//! ([`Session::step_many`](super::Session::step_many)), and over one (every
//! single-session call runs the same phases with the session's own
//! scratch: one code path).
//!
//! The weight-heavy work is batched across sessions: the LATs (one new
//! position per session per push, `LatStream::push_many`), the GPT over
//! each session's window (`GptCache::append_many`) and the heads. Every
//! weight matrix is then read once per phase for all sessions instead of
//! once per session. A session's numbers do not depend on the others in
//! its batch (row-independent kernels, per-session attention), so a
//! batched session gives bit for bit what it gives alone (tested).
//! So are the streaming VQ encoders and decoders (`vq_stream`: each conv
//! unit computed for every session's new columns at once). The sampler
//! runs per session.

use heapless::Vec;

use crate::arena::{ArenaError, Carve, Planner, Split};
use crate::duolando::config::ModelConfig;
use crate::duolando::coordinated_attention::{
    follower_table, FIRST_FOLLOWER_STREAM, FOLLOWER_STREAMS,
};
use crate::duolando::gpt::{head_rows, logits_len};
use crate::duolando::model::Model;
use crate::duolando::session::config::{
    for_each_live_window, next_window, window_context, CacheSchedule, Setting, MAX_WINDOWS,
};
use crate::duolando::session::lat_stream::{max_keys, LatInputs, LatStepScratch, LatStream};
use crate::duolando::session::state::State;
use crate::duolando::session::{vq_stream, Session, SessionConfig};
use crate::error::Error;
use crate::kernels::{linear, Q8Room};
use crate::nn::block::BlockScratch;
use crate::nn::gpt_cache::{GptCache, GptItem};
use crate::nn::stream_conv::{ScratchNeed, StreamScratch};

/// Most sessions stepped together (and most LAT pushes / GPT windows in
/// one batched call).
pub use crate::nn::gpt_cache::MAX_BATCH;

/// Window rows one GPT call appends at most for a session alone: a
/// re-prefill (up to `block_size - 1` rows at a window jump) runs in
/// chunks of this many rows, so the block scratch holds 8 window rows
/// (80 stream rows) rather than a whole window (290). Chunks give the same
/// numbers as one call (row-independent kernels; a chunk's rows attend the
/// cached rows before them and themselves, as they would in one call); a
/// re-prefill then reads the weights `ceil(rows / 8)` times.
pub const REPREFILL_CHUNK: usize = 8;

/// Sizes of a [`StepScratch`]; a session fits a scratch whose every size is
/// at least the session's own.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct StepDims {
    /// Sessions (LAT pushes, head rows) at once.
    pub n: usize,
    /// GPT rows (window rows x streams) at once: [`REPREFILL_CHUNK`] window
    /// rows per session alone, one window row per session of a batch. A
    /// longer append (a re-prefill) runs in chunks of this many rows.
    pub rows: usize,
    /// Attention keys of one query: a LAT's band or a whole GPT window.
    pub keys: usize,
    pub c: usize,
    /// Input floats of one session's music-LAT push (`music_burst` x
    /// n_music; the leader LATs take token ids).
    pub lat_in: usize,
    /// Widest LAT input row (the music frames' n_music; token inputs are
    /// embedding rows, C wide, which the LAT scratch always holds).
    pub lat_width: usize,
    /// Music frames one music-LAT push carries per session
    /// ([`music_burst`]).
    pub music_burst: usize,
    pub ds_max: usize,
    pub logits: usize,
    /// One VQ stack's conv scratch (the widest of the model); the step
    /// scratch holds `n` of them, for the encoders/decoders of `n` sessions
    /// computed together.
    pub conv: ScratchNeed,
}

impl StepDims {
    /// The sizes for `n` sessions of `cfg` under session config `sc`.
    pub fn new(cfg: &ModelConfig, sc: &SessionConfig, n: usize) -> Result<StepDims, ArenaError> {
        let g = &cfg.gpt;
        let m = (g.block_size as usize)
            .checked_sub(1)
            .ok_or(ArenaError::Overflow)?;
        let streams = g.n_streams as usize;
        let (lds, mds) = (
            g.leader.downsample_rate as usize,
            g.music.downsample_rate as usize,
        );
        let past = sc.lat_past as usize;
        let keys = max_keys(past * mds, sc.music_lookahead as usize * mds)
            .max(max_keys(past * lds, sc.lookahead as usize * lds));
        let window = streams.checked_mul(m).ok_or(ArenaError::Overflow)?;
        let chunk = streams
            .checked_mul(REPREFILL_CHUNK.min(m.max(1)))
            .ok_or(ArenaError::Overflow)?;
        Ok(StepDims {
            n,
            rows: chunk.max(n.checked_mul(streams).ok_or(ArenaError::Overflow)?),
            keys: keys.max(window),
            c: g.n_embd as usize,
            lat_in: music_burst(cfg) * g.music.n_in as usize,
            lat_width: g.music.n_in as usize,
            music_burst: music_burst(cfg),
            ds_max: lds.max(mds),
            logits: logits_len(cfg),
            conv: ScratchNeed::for_model(cfg).ok_or(ArenaError::Overflow)?,
        })
    }

    /// Every size of `self` at least that of `need` (same width).
    pub fn holds(&self, need: &StepDims) -> bool {
        self.c == need.c
            && self.n >= need.n
            && self.rows >= need.rows
            && self.keys >= need.keys
            && self.lat_in >= need.lat_in
            && self.lat_width >= need.lat_width
            && self.music_burst >= need.music_burst
            && self.ds_max >= need.ds_max
            && self.logits >= need.logits
            && self.conv.holds(&need.conv)
    }
}

/// The working memory of a step, for up to `dims.n` sessions. Every
/// session carves one for itself (`n = 1`); a [`StepBatch`] carves one for
/// many.
#[derive(Default)]
pub struct StepScratch<'s> {
    pub dims: StepDims,
    /// (rows, C) GPT window rows of the items of one batched append,
    /// position-major per item.
    pub x: &'s mut [f32],
    /// The block scratch of the GPT phase, the LAT scratch and a block
    /// scratch of the LAT rows of the LAT phase, and the conv scratch of
    /// the VQ encoder/decoder phases, in turn ([`block_scratch`],
    /// [`lat_scratch`], [`conv_scratch`]): the largest of the three, not
    /// their sum.
    pub pool: &'s mut [f32],
    /// (n, lat_in) music-LAT inputs (a session's positions of one push side by
    /// side); (n, C) LAT outputs.
    pub lat_in: &'s mut [f32],
    pub lat_out: &'s mut [f32],
    /// (5, n, C) the follower rows each head reads, head-major.
    pub heads_in: &'s mut [f32],
    /// (n, logits) logits, head-major blocks of (n, head rows).
    pub logits: &'s mut [f32],
}

impl<'s> StepScratch<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, dims: StepDims) -> Result<Self, ArenaError> {
        let StepDims {
            n,
            rows,
            keys: _,
            c,
            lat_in,
            lat_width: _,
            music_burst: _,
            ds_max: _,
            logits,
            conv: _,
        } = dims;
        let mul = |x: usize, y: usize| x.checked_mul(y).ok_or(ArenaError::Overflow);
        Ok(StepScratch {
            dims,
            x: a.f32(mul(rows, c)?)?,
            pool: a.f32(pool_floats(&dims)?)?,
            lat_in: a.f32(mul(n, lat_in)?)?,
            lat_out: a.f32(mul(n, c)?)?,
            heads_in: a.f32(mul(mul(5, n)?, c)?)?,
            logits: a.f32(mul(n, logits)?)?,
        })
    }
}

/// Floats of the shared pool of a [`StepScratch`]: the largest of the
/// GPT block scratch, the LAT phase's scratch and the conv scratch for
/// `dims`.
fn pool_floats(d: &StepDims) -> Result<usize, ArenaError> {
    let mut blk = Planner::new();
    carve_block(&mut blk, d)?;
    let mut lat = Planner::new();
    carve_lat(&mut lat, d)?;
    let mut conv = Planner::new();
    StreamScratch::carve(&mut conv, d.conv, d.n)?;
    Ok(Split::floats_for(&blk)
        .max(Split::floats_for(&lat))
        .max(Split::floats_for(&conv)))
}

/// The LAT phase's scratch of dims `d`: the LAT scratch for `d.n` pushes
/// of up to `music_burst` positions each, and a block scratch for those
/// rows (their queries see at most `d.keys` keys), with an int8 panel for
/// them in a batch's scratch (as [`carve_block`]).
fn carve_lat<'x, A: Carve<'x>>(
    a: &mut A,
    d: &StepDims,
) -> Result<(LatStepScratch<'x>, BlockScratch<'x>), ArenaError> {
    let rows = d.n.checked_mul(d.music_burst).ok_or(ArenaError::Overflow)?;
    let lat = LatStepScratch::carve(a, d.c, d.ds_max, d.n, rows, d.lat_width)?;
    let mut s = BlockScratch::carve_keys(a, lat.rows, d.keys, d.c)?;
    if d.n > 1 {
        s.panel = Q8Room::carve(
            a,
            lat.rows.checked_mul(4 * d.c).ok_or(ArenaError::Overflow)?,
        )?;
    }
    Ok((lat, s))
}

/// The LAT phase's scratch over the pool of a [`StepScratch`] with dims `d`.
pub fn lat_scratch<'x>(
    pool: &'x mut [f32],
    d: &StepDims,
) -> Result<(LatStepScratch<'x>, BlockScratch<'x>), Error> {
    Ok(carve_lat(&mut Split::new(pool), d)?)
}

/// The block scratch of dims `d`. A scratch for several sessions (a
/// [`StepBatch`]'s, outside every session's arena) also carves an int8
/// panel for all its rows x 4C, so each of a batch's GEMMs quantises its
/// rows once and reads every weight tile once (the stack panel holds 64
/// rows of the MLP's 3072-wide input: 16 sessions' 160 rows took 3 panels,
/// each reading the weights again). A session's own scratch carves none
/// (its arena stays as small as it is).
fn carve_block<'x, A: Carve<'x>>(a: &mut A, d: &StepDims) -> Result<BlockScratch<'x>, ArenaError> {
    let mut s = BlockScratch::carve_keys(a, d.rows, d.keys, d.c)?;
    if d.n > 1 {
        s.panel = Q8Room::carve(a, d.rows.checked_mul(4 * d.c).ok_or(ArenaError::Overflow)?)?;
    }
    Ok(s)
}

/// The block scratch (LAT pushes, GPT appends) over the pool of a
/// [`StepScratch`] with dims `d`.
pub fn block_scratch<'x>(pool: &'x mut [f32], d: &StepDims) -> Result<BlockScratch<'x>, Error> {
    Ok(carve_block(&mut Split::new(pool), d)?)
}

/// The conv scratch of the streaming VQ stacks of `d.n` sessions over the
/// pool of a [`StepScratch`] with dims `d`.
pub fn conv_scratch<'x>(pool: &'x mut [f32], d: &StepDims) -> Result<StreamScratch<'x>, Error> {
    Ok(StreamScratch::carve(&mut Split::new(pool), d.conv, d.n)?)
}

/// Scratch for stepping up to `n` sessions of one model together
/// ([`Session::step_many`]), carved once from a caller arena
/// ([`StepBatch::bytes`]).
pub struct StepBatch<'s> {
    pub(super) sc: StepScratch<'s>,
}

impl<'s> StepBatch<'s> {
    /// Arena bytes for `n` (1..=[`MAX_BATCH`]) sessions of `cfg` under
    /// session config `sc` (sessions with smaller needs fit too).
    pub fn bytes(cfg: &ModelConfig, sc: &SessionConfig, n: usize) -> Result<usize, Error> {
        let dims = batch_dims(cfg, sc, n)?;
        let mut p = crate::arena::Planner::new();
        StepScratch::carve(&mut p, dims)?;
        p.total_for_any_base()
            .ok_or(Error::Arena(ArenaError::Overflow))
    }

    pub fn new(
        cfg: &ModelConfig,
        sc: &SessionConfig,
        n: usize,
        arena: &'s mut [u8],
    ) -> Result<Self, Error> {
        let dims = batch_dims(cfg, sc, n)?;
        let mut a = crate::arena::Arena::new(arena);
        Ok(StepBatch {
            sc: StepScratch::carve(&mut a, dims)?,
        })
    }

    /// Sessions it can step at once.
    pub fn capacity(&self) -> usize {
        self.sc.dims.n
    }
}

fn batch_dims(cfg: &ModelConfig, sc: &SessionConfig, n: usize) -> Result<StepDims, Error> {
    if n == 0 || n > MAX_BATCH {
        return Err(Error::Setting {
            setting: Setting::Batch,
            value: n.min(u32::MAX as usize) as u32,
            max: MAX_BATCH as u32,
        });
    }
    super::check_config(cfg, sc)?;
    Ok(StepDims::new(cfg, sc, n)?)
}

/// Index of the session an error belongs to.
pub type BatchError = (usize, Error);

pub(super) fn at(i: usize) -> impl Fn(Error) -> BatchError {
    move |e| (i, e)
}

/// The sessions `ss` (one model, each fitting `sc`) have accepted their
/// inputs: runs the encoders on the tokens completed (their codes wait in
/// `State::codes`), then the LAT pushes and every step whose inputs exist.
pub(super) fn advance(
    ss: &mut [&mut Session<'_>],
    sc: &mut StepScratch<'_>,
) -> Result<(), BatchError> {
    vq_stream::encode(ss, sc)?;
    run_steps(ss, sc)
}

/// The states of sessions `chunk` (increasing indices into `ss`), in order.
pub(super) fn states<'x, 'a>(
    ss: &'x mut [&mut Session<'a>],
    chunk: &[usize],
) -> Result<Vec<&'x mut State<'a>, MAX_BATCH>, BatchError> {
    let mut v = Vec::new();
    let mut ci = 0;
    for (i, s) in ss.iter_mut().enumerate() {
        if ci < chunk.len() && chunk[ci] == i {
            v.push(&mut s.st).map_err(|_| (i, Error::State))?;
            ci += 1;
        }
    }
    if ci != chunk.len() {
        return Err((chunk.first().copied().unwrap_or(0), Error::State));
    }
    Ok(v)
}

/// Splits `0..ss.len()` filtered by `want` into chunks of at most `n`.
pub(super) fn for_chunks(
    ss: &mut [&mut Session<'_>],
    n: usize,
    want: impl Fn(&Session<'_>) -> bool,
    mut f: impl FnMut(&mut [&mut Session<'_>], &[usize]) -> Result<(), BatchError>,
) -> Result<(), BatchError> {
    let mut chunk: Vec<usize, MAX_BATCH> = Vec::new();
    let cap = n.clamp(1, MAX_BATCH);
    for i in 0..ss.len() {
        if want(ss[i]) {
            chunk.push(i).map_err(|_| (i, Error::State))?;
            if chunk.len() == cap {
                f(ss, &chunk)?;
                chunk.clear();
            }
        }
    }
    if !chunk.is_empty() {
        f(ss, &chunk)?;
    }
    Ok(())
}

/// Music frames one music-LAT push carries per session: a step's frames
/// (the music LAT's downsampling, 4), so its weights are read once per step.
pub fn music_burst(cfg: &ModelConfig) -> usize {
    (cfg.gpt.music.downsample_rate as usize).clamp(1, 4)
}

/// A leader code waits to enter the leader LATs, and its position's
/// output row (position - look-ahead) is at most step `k`'s: one push
/// (all 4 parts) wanted.
fn leader_wanted(s: &Session<'_>) -> bool {
    let lat = &s.st.leader_lat[0];
    lat.pushed() < s.codes && lat.pushes_before_row(s.k) > 0
}

/// One leader-LAT position (the oldest waiting code) into all 4 parts'
/// LATs of every session that wants it ([`leader_wanted`]).
fn leader_lats(ss: &mut [&mut Session<'_>], sc: &mut StepScratch<'_>) -> Result<(), BatchError> {
    let n = sc.dims.n;
    for_chunks(ss, n, leader_wanted, |ss, chunk| {
        let model = ss[chunk[0]].model;
        let mut codes = [[0u32; 4]; MAX_BATCH];
        for (j, &i) in chunk.iter().enumerate() {
            let s = &ss[i];
            codes[j].copy_from_slice(s.st.codes.row(s.st.leader_lat[0].pushed()).map_err(at(i))?);
        }
        let ones = [1usize; MAX_BATCH];
        for p in 0..4 {
            let mut ids = [0u32; MAX_BATCH];
            for (id, code) in ids.iter_mut().zip(&codes[..chunk.len()]) {
                *id = code[p];
            }
            // Leader part p is embedded with the follower table of the same part.
            let inputs = LatInputs::Tokens(&ids[..chunk.len()], &model.gpt.tok_emb[p]);
            lat_push(
                ss,
                chunk,
                &ones[..chunk.len()],
                sc,
                Lat::Leader(p),
                &model.gpt.leaders[p],
                inputs,
            )?;
        }
        Ok(())
    })
}

/// Which LAT of a session.
#[derive(Clone, Copy)]
enum Lat {
    Music,
    /// Leader part 0..4.
    Leader(usize),
}

/// One LAT push of `counts[j]` positions per session `chunk[j]` (`inputs`:
/// one session's positions after another); produced rows go to the LAT's
/// condition stream.
fn lat_push(
    ss: &mut [&mut Session<'_>],
    chunk: &[usize],
    counts: &[usize],
    sc: &mut StepScratch<'_>,
    which: Lat,
    w: &crate::duolando::model::LatW<'_>,
    inputs: LatInputs<'_, '_>,
) -> Result<(), BatchError> {
    let cond = match which {
        Lat::Music => 0,
        Lat::Leader(p) => 1 + p,
    };
    let c = sc.dims.c;
    let n = chunk.len();
    let first = chunk[0];
    let mut produced: Vec<bool, MAX_BATCH> = Vec::new();
    {
        let mut lats: Vec<&mut LatStream<'_>, MAX_BATCH> = Vec::new();
        for st in states(ss, chunk)? {
            let lat = match which {
                Lat::Music => &mut st.music_lat,
                Lat::Leader(p) => st.leader_lat.get_mut(p).ok_or((first, Error::State))?,
            };
            lats.push(lat).map_err(|_| (first, Error::State))?;
            produced.push(false).map_err(|_| (first, Error::State))?;
        }
        let (mut lat, mut blk) = lat_scratch(sc.pool, &sc.dims).map_err(at(first))?;
        LatStream::push_many(
            w,
            &mut lats,
            counts,
            inputs,
            &mut lat,
            &mut blk,
            &mut sc.lat_out[..n * c],
            &mut produced,
        )
        .map_err(at(first))?;
    }
    for (j, &i) in chunk.iter().enumerate() {
        if produced[j] {
            ss[i].st.cond[cond]
                .push(&sc.lat_out[j * c..(j + 1) * c])
                .map_err(at(i))?;
        }
    }
    Ok(())
}

/// Step `k`'s leader row exists and step `k` may run (the forced history,
/// if any, goes on; a drained session's step limit).
fn leader_ready(s: &Session<'_>) -> bool {
    s.st.leader_lat[0].rows() > s.k && s.step_possible()
}

/// Step `k` still lacks its music row and a music frame for it is there.
fn music_wanted(s: &Session<'_>) -> bool {
    music_frames_wanted(s) > 0
}

/// Music frames the next music-LAT push of `s` carries: those step `k`'s
/// music row still needs, that are there, at most the LAT's burst (so one
/// push per step in the steady state).
fn music_frames_wanted(s: &Session<'_>) -> usize {
    let mmr = s.model.cfg.music_motion_rate as usize;
    let lat = &s.st.music_lat;
    if !leader_ready(s) || lat.rows() > s.k {
        return 0;
    }
    let need = lat.pushes_before_row(s.k);
    let there = s.music_frames.saturating_sub(lat.pushed() + mmr);
    need.min(there).min(lat.burst())
}

/// [`run_steps`], and for drained sessions ([`Session::finish`]) the
/// leader codes that the end of the leader makes computable, as many as
/// the steps left need and the code ring holds, until nothing changes.
pub(super) fn pump(
    ss: &mut [&mut Session<'_>],
    sc: &mut StepScratch<'_>,
) -> Result<(), BatchError> {
    loop {
        let mut more = false;
        for (i, s) in ss.iter_mut().enumerate() {
            while s.end_code_wanted() {
                vq_stream::encode_end(s, sc).map_err(at(i))?;
                more = true;
            }
        }
        let before: usize = ss.iter().map(|s| s.k).sum();
        run_steps(ss, sc)?;
        let after: usize = ss.iter().map(|s| s.k).sum();
        if !more && after == before {
            return Ok(());
        }
    }
}

/// Runs every step whose inputs exist, in every session.
pub(super) fn run_steps(
    ss: &mut [&mut Session<'_>],
    sc: &mut StepScratch<'_>,
) -> Result<(), BatchError> {
    loop {
        // Leader codes into the leader LATs up to step k's row.
        while ss.iter().any(|s| leader_wanted(s)) {
            leader_lats(ss, sc)?;
        }
        // Music LAT pushes until each session's step k has its music row
        // or runs out of music frames.
        while ss.iter().any(|s| music_wanted(s)) {
            let n = sc.dims.n;
            for_chunks(ss, n, music_wanted, |ss, chunk| {
                let model = ss[chunk[0]].model;
                let n_music = model.cfg.gpt.music.n_in as usize;
                let mmr = model.cfg.music_motion_rate as usize;
                let mut counts = [0usize; MAX_BATCH];
                let mut row = 0;
                for (j, &i) in chunk.iter().enumerate() {
                    let s = &ss[i];
                    counts[j] = music_frames_wanted(s);
                    for f in 0..counts[j] {
                        let frame = s.st.music_lat.pushed() + mmr + f;
                        let x = match s.track {
                            Some(t) => t
                                .get(frame * n_music..(frame + 1) * n_music)
                                .ok_or((i, Error::State))?,
                            None => s.st.music.row(frame).map_err(at(i))?,
                        };
                        sc.lat_in
                            .get_mut(row * n_music..(row + 1) * n_music)
                            .ok_or((i, Error::State))?
                            .copy_from_slice(x);
                        row += 1;
                    }
                }
                // The rows stay in `lat_in` (taken out of `sc` for the call).
                let x = core::mem::take(&mut sc.lat_in);
                let r = lat_push(
                    ss,
                    chunk,
                    &counts[..chunk.len()],
                    sc,
                    Lat::Music,
                    &model.gpt.music,
                    LatInputs::Rows(&x[..row * n_music]),
                );
                sc.lat_in = x;
                r
            })?;
        }
        let mut ready: Vec<usize, MAX_BATCH> = Vec::new();
        for (i, s) in ss.iter().enumerate() {
            if leader_ready(s) && s.st.music_lat.rows() > s.k {
                ready.push(i).map_err(|_| (i, Error::State))?;
            }
        }
        if ready.is_empty() {
            return Ok(());
        }
        for part in ready.chunks(sc.dims.n.max(1)) {
            gpt_step(ss, part, sc)?;
        }
    }
}

/// One GPT append of a step: window starting at token `lo` in cache `slot`,
/// new window rows `first..=last` (`last = k` but for a spread schedule's
/// prefill of the next window).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Append {
    slot: usize,
    lo: usize,
    first: usize,
    last: usize,
    need_output: bool,
}

/// Plans step `k` of `s` (cache choice, restarts): its appends in
/// `s.appends`: the current window's last (staggered) or first (spread: then
/// the next window's share of rows), or alone.
fn plan(s: &mut Session<'_>) -> Result<(), Error> {
    let g = &s.model.cfg.gpt;
    let m = g.block_size as usize - 1;
    let k = s.k;
    let shift = s.cfg.shift as usize;
    let lo = k + 1 - window_context(k, m, shift);
    s.appends.clear();
    let st = &mut s.st;
    if s.cfg.schedule == CacheSchedule::Staggered {
        // Every window that contains row k and is still to be used gets row k.
        let mut live: Vec<usize, MAX_WINDOWS> = Vec::new();
        let mut over = false;
        for_each_live_window(k, m, shift, |w| over |= live.push(w).is_err());
        if over {
            return Err(Error::Setting {
                setting: Setting::Windows,
                value: live.len() as u32 + 1,
                max: MAX_WINDOWS as u32,
            });
        }
        for &w in live.iter().rev() {
            let slot = match st.gpt.iter().position(|c| c.window_start() == Some(w)) {
                Some(i) => i,
                None => {
                    // A free cache: one whose window is not live any more.
                    let i = st
                        .gpt
                        .iter()
                        .position(|c| c.window_start().is_none_or(|x| !live.contains(&x)))
                        .ok_or(Error::Evicted {
                            index: w,
                            oldest: k,
                            len: st.gpt.len(),
                        })?;
                    st.gpt[i].restart(w);
                    i
                }
            };
            let first = w + st.gpt[slot].rows();
            s.appends
                .push(Append {
                    slot,
                    lo: w,
                    first,
                    last: k,
                    need_output: w == lo,
                })
                .map_err(|_| Error::State)?;
        }
    } else if s.cfg.schedule == CacheSchedule::Spread && st.gpt.len() >= 2 {
        // The window's own cache is the first; the second holds the next
        // window's first rows (at most its `shift - 1`), which move into
        // the first at the jump. A window the second could not hold whole
        // (the first full window, at start-up) has its other rows computed
        // at its jump.
        GptCache::enter_window(&mut st.gpt, lo)?;
        s.appends
            .push(Append {
                slot: 0,
                lo,
                first: lo + st.gpt[0].rows(),
                last: k,
                need_output: true,
            })
            .map_err(|_| Error::State)?;
        // The next window (start `nlo`, first used at step `k2`) in the
        // second cache: this step's share of its rows.
        let (k2, nlo) = next_window(k, m, shift);
        if nlo > lo {
            if let Some((first, rows)) = st.gpt[1].ahead_share(k, k2, nlo) {
                s.appends
                    .push(Append {
                        slot: 1,
                        lo: nlo,
                        first,
                        last: first + rows - 1,
                        need_output: false,
                    })
                    .map_err(|_| Error::State)?;
            }
        }
    } else {
        let first = if st.gpt[0].window_start() == Some(lo) {
            k
        } else {
            st.gpt[0].restart(lo);
            lo
        };
        s.appends
            .push(Append {
                slot: 0,
                lo,
                first,
                last: k,
                need_output: true,
            })
            .map_err(|_| Error::State)?;
    }
    if !s.appends.iter().any(|a| a.need_output) {
        return Err(Error::Evicted {
            index: lo,
            oldest: k,
            len: 0,
        });
    }
    Ok(())
}

/// Builds the inputs of token rows `first..=k` of the window starting at
/// `lo` (position rows added) into `x` ((k + 1 - first) * 10, C),
/// position-major.
fn window_rows(
    model: &Model<'_>,
    st: &State<'_>,
    lo: usize,
    first: usize,
    k: usize,
    x: &mut [f32],
) -> Result<(), Error> {
    let g = &model.cfg.gpt;
    let (e, bs) = (g.n_embd as usize, g.block_size as usize);
    let streams = g.n_streams as usize;
    for (r, j) in (first..=k).enumerate() {
        let i = j - lo;
        for s in 0..streams {
            let dst = &mut x[(r * streams + s) * e..(r * streams + s + 1) * e];
            if s < FIRST_FOLLOWER_STREAM {
                dst.copy_from_slice(st.cond[s].row(j)?);
            } else {
                let f = s - FIRST_FOLLOWER_STREAM;
                let tok = st.toks.row(j)?[f];
                model.gpt.tok_emb[follower_table(f)].row_into(tok as usize, dst);
            }
            let pos = &model.gpt.pos_emb[(s * bs + i) * e..(s * bs + i + 1) * e];
            for (a, b) in dst.iter_mut().zip(pos) {
                *a += b;
            }
        }
    }
    Ok(())
}

/// Step `k` of each session in `ready` (at most `sc.dims.n`): the GPT
/// appends (batched), the heads (batched), then per session the sampler,
/// the history and the decoders.
fn gpt_step(
    ss: &mut [&mut Session<'_>],
    ready: &[usize],
    sc: &mut StepScratch<'_>,
) -> Result<(), BatchError> {
    let nr = ready.len();
    for &i in ready {
        plan(ss[i]).map_err(at(i))?;
    }
    let model = ss[ready[0]].model;
    let g = &model.cfg.gpt;
    let (c, streams) = (g.n_embd as usize, g.n_streams as usize);
    // Each call takes, session after session, every next chunk that fits
    // in `sc.dims.rows` rows, at most one per cache (a chunk attends the
    // rows of its cache appended before it): a session's appends to
    // different caches (staggered windows) share one pass over the
    // weights. A chunk is window rows `first..=last` of one append, at
    // most `chunk` of them.
    let chunk = (sc.dims.rows / streams).max(1);
    // Per session of `ready`: (append index, first row of its next chunk).
    let mut cur: [(usize, usize); MAX_BATCH] = [(0, 0); MAX_BATCH];
    for (q, &i) in ready.iter().enumerate() {
        cur[q] = (0, ss[i].appends.first().map_or(0, |a| a.first));
    }
    // The next chunk of session `q` (append, first, last), if any is left.
    let next = |s: &Session<'_>, (ai, f): (usize, usize)| -> Option<(Append, usize, usize)> {
        let a = *s.appends.get(ai)?;
        Some((a, f, a.last.min(f + chunk - 1)))
    };
    // The cursor after chunk (append, .., last) of append `ai`.
    let advance = |s: &Session<'_>, ai: usize, l: usize| -> (usize, usize) {
        if s.appends.get(ai).is_none_or(|a| l >= a.last) {
            (ai + 1, s.appends.get(ai + 1).map_or(0, |n| n.first))
        } else {
            (ai, l + 1)
        }
    };
    loop {
        let mut any = false;
        let mut q = 0;
        while q < nr {
            // (session position in `ready`, append, first, last) of this call.
            let mut call: Vec<(usize, Append, usize, usize), MAX_BATCH> = Vec::new();
            let mut total = 0;
            let mut full = false;
            while q < nr && !full {
                let i = ready[q];
                let s = &ss[i];
                let mut cq = cur[q];
                let mut used = [false; MAX_WINDOWS];
                while let Some((a, f, l)) = next(s, cq) {
                    if used.get(a.slot).copied().unwrap_or(true) {
                        break;
                    }
                    let rows = (l + 1 - f) * streams;
                    if total + rows > sc.dims.rows && !call.is_empty() {
                        full = true;
                        break;
                    }
                    if rows > sc.dims.rows {
                        return Err((
                            i,
                            Error::Context {
                                c: rows,
                                max: sc.dims.rows,
                            },
                        ));
                    }
                    window_rows(
                        model,
                        &s.st,
                        a.lo,
                        f,
                        l,
                        &mut sc.x[total * c..(total + rows) * c],
                    )
                    .map_err(at(i))?;
                    total += rows;
                    call.push((q, a, f, l)).map_err(|_| (i, Error::State))?;
                    used[a.slot] = true;
                    cq = advance(s, cq.0, l);
                }
                if !full {
                    q += 1;
                }
            }
            if call.is_empty() {
                continue;
            }
            any = true;
            let first = ready[call[0].0];
            {
                let mut items: Vec<GptItem<'_, '_>, MAX_BATCH> = Vec::new();
                let mut ci = 0;
                for (i, s) in ss.iter_mut().enumerate() {
                    // The session's caches, each handed out at most once.
                    let mut caches: Vec<Option<&mut GptCache<'_>>, MAX_WINDOWS> =
                        s.st.gpt.iter_mut().map(Some).collect();
                    while ci < call.len() && ready[call[ci].0] == i {
                        let (_, a, f, l) = call[ci];
                        let cache = caches
                            .get_mut(a.slot)
                            .and_then(Option::take)
                            .ok_or((i, Error::State))?;
                        items
                            .push(GptItem {
                                cache,
                                rows: l + 1 - f,
                                need_output: a.need_output && l == a.last,
                            })
                            .map_err(|_| (i, Error::State))?;
                        ci += 1;
                    }
                }
                GptCache::append_many(
                    model.gpt.base.iter().chain(model.gpt.head.iter()),
                    g.n_head as usize,
                    FOLLOWER_STREAMS,
                    &mut items,
                    &mut sc.x[..total * c],
                    &mut block_scratch(sc.pool, &sc.dims).map_err(at(first))?,
                )
                .map_err(at(first))?;
            }
            // Advance the cursors; the follower rows of the output items, to the heads' inputs.
            let mut j = 0;
            for &(qi, a, f, l) in call.iter() {
                let i = ready[qi];
                ss[i].rows_computed += l + 1 - f;
                cur[qi] = advance(ss[i], cur[qi].0, l);
                if a.need_output && l == a.last {
                    for h in 0..FOLLOWER_STREAMS {
                        let src = (j * FOLLOWER_STREAMS + h) * c;
                        sc.heads_in[(h * nr + qi) * c..(h * nr + qi + 1) * c]
                            .copy_from_slice(&sc.x[src..src + c]);
                    }
                    j += 1;
                }
            }
        }
        if !any {
            break;
        }
    }
    // Heads: (nr, C) -> (nr, rows) per head, each matrix read once.
    let hr = head_rows(&model.cfg);
    let mut off = 0;
    for (h, &rows) in hr.iter().enumerate() {
        linear(
            &sc.heads_in[h * nr * c..(h + 1) * nr * c],
            &model.gpt.heads[h],
            None,
            &mut sc.logits[off..off + nr * rows],
        );
        off += nr * rows;
    }
    let mut tokens = [[0u32; 5]; MAX_BATCH];
    for (qi, &i) in ready.iter().enumerate() {
        let s = &mut *ss[i];
        let mut pred = [0u32; 5];
        let mut off = 0;
        for (h, &rows) in hr.iter().enumerate() {
            let lg = &mut sc.logits[off + qi * rows..off + (qi + 1) * rows];
            pred[h] = s.cfg.sampling.choose(lg, &mut s.rng);
            off += nr * rows;
        }
        tokens[qi] = s.finish_step(pred).map_err(at(i))?;
    }
    vq_stream::decode(ss, ready, &tokens[..nr], sc)
}
