//! Drives a streaming [`Session`] over a whole clip held in memory, frame
//! by frame as a game would (leader frame pushed, ready follower frames
//! pulled after every push), and records what happened when: the shared
//! runner of `duolando generate --mode streaming`, `duolando compare` and
//! the S golden tests.

use duolando_core::duolando::config::{POSE_DIM, ROT_DIM};
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::{FollowerFrame, Session, SessionConfig};
use duolando_core::error::Error;

/// Everything a streaming run produced, with readiness.
#[derive(Clone, Debug, Default)]
pub struct StreamRun {
    /// (K+1, 5) the follower history: row 0 the seed, row k+1 appended by step k.
    pub tokens: Vec<u32>,
    /// (K, 5) S's own choice at step k (differs from `tokens` only when forced).
    pub pred: Vec<u32>,
    /// (n_codes, 4) leader codes in the order computed.
    pub leader_codes: Vec<u32>,
    /// (K) leader frame index after whose push step k ran.
    pub step_ready: Vec<usize>,
    /// (K) window length, window start and rows computed per step.
    pub context: Vec<usize>,
    pub window_lo: Vec<usize>,
    pub rows_computed: Vec<usize>,
    /// (N, 165) follower world positions; (N, 495) raw rotation matrices.
    pub pos: Vec<f32>,
    pub rot: Vec<f32>,
    /// (N) leader frame index after whose push frame f was first pullable.
    pub frame_ready: Vec<usize>,
    /// Leader frames pushed.
    pub frames_in: usize,
    pub latency_frames: u32,
    pub arena_bytes: usize,
}

impl StreamRun {
    pub fn steps(&self) -> usize {
        self.step_ready.len()
    }
    pub fn frames_out(&self) -> usize {
        self.frame_ready.len()
    }
}

/// Runs a session over `leader` (T, 165) with `music` (>= T4 rows) as a
/// preloaded track, both truncated to `T4 = T - T mod hop` frames as R
/// does. `forced`: (n, 5) forced history (row 0 = `seed`).
/// `progress(frames_pushed, total)` is called after every push.
/// Without drain: the leader frames as a live session gets them and no
/// end (the S goldens).
pub fn run_streaming(
    model: &Model<'_>,
    leader: &[f32],
    music: &[f32],
    cfg: &SessionConfig,
    seed: [u32; 5],
    forced: Option<&[u32]>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<StreamRun, Error> {
    run_streaming_with(model, leader, music, cfg, seed, forced, false, progress)
}

/// [`run_streaming`], then, with `drain`, [`Session::finish`] after the
/// last leader frame (or the first one the session refused for backlog:
/// the track's end stops the steps) and every remaining follower frame
/// pulled: R's frame count (docs/STREAMING.md §2 "Drain"). Steps run by
/// the drain have `step_ready` = `frames_in` and `rows_computed` 0 (not
/// reported per step) and no `pred` row (`pred` covers the streamed
/// steps); drained frames have `frame_ready` = `frames_in`.
#[allow(clippy::too_many_arguments)]
pub fn run_streaming_with(
    model: &Model<'_>,
    leader: &[f32],
    music: &[f32],
    cfg: &SessionConfig,
    seed: [u32; 5],
    forced: Option<&[u32]>,
    drain: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<StreamRun, Error> {
    let hop = model.cfg.hop();
    let n_music = model.cfg.gpt.music.n_in as usize;
    let t4 = leader.len() / POSE_DIM / hop * hop;
    let music = &music[..(t4 * n_music).min(music.len() / n_music.max(1) * n_music)];
    let bytes = model.session_bytes(cfg)?;
    let mut arena = vec![0u8; bytes];
    let mut s = Session::new(model, &mut arena, cfg, seed)?;
    if let Some(f) = forced {
        s.force_history(f)?;
    }
    s.set_music_track(music)?;
    let mut run = StreamRun {
        latency_frames: s.latency_frames(),
        arena_bytes: bytes,
        ..Default::default()
    };
    run.tokens.extend_from_slice(&seed);
    let mut frame = FollowerFrame::default();
    let mut seen_codes = 0;
    for f in 0..t4 {
        match s.push_leader_frame(&leader[f * POSE_DIM..(f + 1) * POSE_DIM]) {
            Ok(()) => {}
            // The music track (or the forced history) is exhausted: no step can
            // run any more, so follower frames stop and leader frames back up.
            Err(Error::Backlog { .. }) => break,
            Err(e) => return Err(e),
        }
        run.frames_in = f + 1;
        let (n_codes, code) = s.leader_codes();
        if n_codes > seen_codes {
            seen_codes = n_codes;
            run.leader_codes
                .extend_from_slice(&code.unwrap_or_default());
        }
        if s.steps() > run.step_ready.len() + 1 {
            // More than one step after one push cannot happen with a preloaded track.
            return Err(Error::State);
        }
        if let Some(st) = s.last_step() {
            if st.k == run.step_ready.len() {
                run.step_ready.push(f);
                run.context.push(st.context);
                run.window_lo.push(st.window_lo);
                run.rows_computed.push(st.rows_computed);
                run.pred.extend_from_slice(&st.pred);
                run.tokens.extend_from_slice(&st.token);
            }
        }
        while s.pull_follower_frame(&mut frame)? {
            run.pos.extend_from_slice(&frame.positions);
            run.rot.extend_from_slice(&frame.rotations);
            run.frame_ready.push(f);
        }
        progress(f + 1, t4);
    }
    if drain {
        // The drained steps run as their frames are pulled.
        s.finish()?;
        while s.pull_follower_frame(&mut frame)? {
            run.pos.extend_from_slice(&frame.positions);
            run.rot.extend_from_slice(&frame.rotations);
            run.frame_ready.push(run.frames_in);
        }
        let m = model.cfg.gpt.block_size as usize - 1;
        for k in run.step_ready.len()..s.steps() {
            let c = duolando_core::duolando::session::window_context(k, m, cfg.shift as usize);
            run.step_ready.push(run.frames_in);
            run.context.push(c);
            run.window_lo.push(k + 1 - c);
            run.rows_computed.push(0);
            run.tokens.extend_from_slice(&s.history_row(k + 1)?);
        }
    }
    debug_assert_eq!(run.pos.len(), run.frame_ready.len() * POSE_DIM);
    debug_assert_eq!(run.rot.len(), run.frame_ready.len() * ROT_DIM);
    Ok(run)
}
