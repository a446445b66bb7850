//! Session configurations and operation sequences (push leader / push
//! music / pull / reset / force history / music track, with hostile
//! floats and wrong lengths), and [`run_ops`], which runs a sequence on a
//! session and checks the contract of docs/STREAMING.md §6.2 against a
//! shadow session that only sees the operations the first one accepted:
//!
//! - nothing panics; an `Err` is one of the documented refusals;
//! - an `Err` leaves the session unchanged (the shadow, which never saw
//!   the refused input, pulls bit-identical frames);
//! - `NonFinite` exactly when the input holds NaN/Inf, `OutOfRange`
//!   exactly when it is finite but above `input::limit_of` (the input
//!   policy, docs/ROBUSTNESS.md §3);
//! - pulled frames are always finite and their indices consecutive from 0
//!   after every reset;
//! - afterwards the session is usable: a reset and a clean drive produce
//!   finite frames;
//! - a batched twin that gets every operation, its leader frames through
//!   `Session::step_many` (a one-session `StepBatch`), answers every call
//!   as the session does and pulls bit-identical frames.

use arbitrary::Arbitrary;
use duolando_core::duolando::config::{POSE_DIM, ROT_DIM};
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::config::MAX_BUFFER_FRAMES;
use duolando_core::duolando::session::{
    dec_future_max, enc_future_max, CacheSchedule, FollowerFrame, Sampling, Session, SessionConfig,
    StepBatch,
};
use duolando_core::error::{Buffer, Error};
use duolando_core::input;
use duolando_core::nn::sampler::MAX_TOP_K;

use crate::fixture::Clip;
use crate::floats::{synthetic_leader, Hostile};

/// Largest session arena the harness allocates (larger configs are
/// sized with `session_bytes` only).
pub const MAX_ARENA: usize = 48 << 20;

/// A setting: folded into its valid range, or any value.
#[derive(Arbitrary, Clone, Copy, Debug)]
pub enum Field {
    In(u32),
    Any(u32),
}

impl Field {
    fn get(self, lo: u32, hi: u32) -> u32 {
        match self {
            Field::In(v) => lo + v % (hi - lo + 1),
            Field::Any(v) => v,
        }
    }
}

#[derive(Arbitrary, Clone, Copy, Debug)]
pub struct ConfigGen {
    pub lookahead: Field,
    pub enc_future: Field,
    pub dec_future: Field,
    pub shift: Field,
    pub music_lookahead: Field,
    pub lat_past: Field,
    pub top_k: Option<(Field, u64)>,
    pub pending_frames: Field,
    pub music_buffer_frames: Field,
    pub staggered: bool,
}

impl ConfigGen {
    /// The config; `In` fields stay small where the range is huge (buffer
    /// sizes to 512 frames) so most inputs run quickly.
    pub fn build(&self, model: &Model<'_>) -> SessionConfig {
        let c = &model.cfg;
        let lf = c.gpt.look_forward;
        let m = c.gpt.block_size.saturating_sub(1).max(1);
        let min_music = 4 * c.music_motion_rate;
        let mut s = SessionConfig::reference(c);
        s.lookahead = self.lookahead.get(0, lf);
        s.enc_future = self.enc_future.get(0, enc_future_max(c));
        s.dec_future = self.dec_future.get(0, dec_future_max(c));
        s.shift = self.shift.get(1, m);
        s.music_lookahead = self.music_lookahead.get(0, lf);
        s.lat_past = self.lat_past.get(0, lf);
        s.sampling = match self.top_k {
            None => Sampling::Greedy,
            Some((k, rng_seed)) => sampling_of(k.get(1, MAX_TOP_K as u32), rng_seed),
        };
        s.pending_frames = self.pending_frames.get(0, 512.min(MAX_BUFFER_FRAMES));
        s.music_buffer_frames = self.music_buffer_frames.get(min_music, 512.max(min_music));
        s.schedule = if self.staggered {
            CacheSchedule::Staggered
        } else {
            CacheSchedule::Reprefill
        };
        s
    }
}

/// Top-k or, where the seed's top bit is set, softmax sampling at a
/// temperature from its bits 32-48 (1..=100 000 thousandths), drawn from
/// the seed so that committed inputs decode as before.
pub fn sampling_of(k: u32, rng_seed: u64) -> Sampling {
    if rng_seed >> 63 == 0 {
        return Sampling::TopK { k, rng_seed };
    }
    Sampling::Softmax {
        k,
        temperature_milli: 1 + ((rng_seed >> 32) as u32 & 0x1_ffff) % 100_000,
        rng_seed,
    }
}

/// Contents of one pushed frame.
#[derive(Arbitrary, Clone, Copy, Debug)]
pub enum FrameGen {
    /// The next recorded frame.
    Clip,
    /// Synthetic motion at time `t`.
    Synthetic(u16),
    /// The next recorded frame with one value replaced.
    Poke { at: u16, value: Hostile },
    /// Every value the same.
    Fill(Hostile),
    /// The next recorded frame scaled by a hostile factor.
    Scale(Hostile),
    /// A frame of the wrong length.
    Len(u16),
}

#[derive(Arbitrary, Clone, Copy, Debug)]
pub enum SeedGen {
    Clip,
    Tokens([u32; 5]),
    InVocab([u16; 5]),
}

/// One operation on the session.
#[derive(Arbitrary, Clone, Debug)]
pub enum Op {
    Leader(FrameGen),
    Music(FrameGen),
    /// Up to `n` pulls.
    Pull(u8),
    PullAll,
    /// `n` clean ticks: music as needed, one leader frame, pull all.
    Ticks(u8),
    Reset(SeedGen),
    /// A forced history of `rows` rows (row 0 the clip seed unless
    /// `wrong_seed`), tokens folded into the vocabularies unless `raw`.
    Force {
        rows: u8,
        tokens: Vec<u32>,
        wrong_seed: bool,
        raw: bool,
    },
    /// A preloaded music track of `frames` recorded frames, one value
    /// optionally replaced, optionally cut mid-row.
    Track {
        frames: u16,
        poke: Option<(u16, Hostile)>,
        ragged: bool,
    },
}

/// A whole session input.
#[derive(Arbitrary, Clone, Debug)]
pub struct SessionInput {
    pub config: ConfigGen,
    pub seed: SeedGen,
    pub ops: Vec<Op>,
}

/// Most operations one input runs (keeps a fuzz execution short).
pub const MAX_OPS: usize = 256;

/// What a run saw.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Report {
    pub config_rejected: Option<Error>,
    pub arena_bytes: usize,
    pub pushed: usize,
    pub pulled: usize,
    pub refused: usize,
    pub non_finite_refused: usize,
    pub backlog_refused: usize,
    /// Frames refused as finite but out of range.
    pub out_of_range_refused: usize,
    /// Frames of the clean drive after a reset at the end.
    pub recovered: usize,
}

/// Refusals the session documents (anything else is an engine bug).
fn documented(e: &Error) -> bool {
    matches!(
        e,
        Error::NonFinite { .. }
            | Error::OutOfRange { .. }
            | Error::Length { .. }
            | Error::Backlog { .. }
            | Error::State
            | Error::Token { .. }
            | Error::Ragged { .. }
    )
}

fn frame_bits(f: &FollowerFrame) -> impl Iterator<Item = u32> + '_ {
    f.positions
        .iter()
        .chain(&f.rotations)
        .chain(&f.root)
        .map(|v| v.to_bits())
        .chain([f.index as u32, (f.index >> 32) as u32])
}

pub fn frame_finite(f: &FollowerFrame) -> bool {
    f.positions
        .iter()
        .chain(&f.rotations)
        .chain(&f.root)
        .all(|v| v.is_finite())
}

fn seed_of(g: SeedGen, model: &Model<'_>, clip: &Clip) -> [u32; 5] {
    let v = model.cfg.gpt.vocab;
    match g {
        SeedGen::Clip => clip.seed,
        SeedGen::Tokens(t) => t,
        SeedGen::InVocab(t) => core::array::from_fn(|j| t[j] as u32 % v[j].max(1)),
    }
}

/// Fills `buf` per `g`; returns the frame length used.
fn make_frame(g: FrameGen, recorded: &[f32], base: &[f32], buf: &mut Vec<f32>) {
    buf.clear();
    match g {
        FrameGen::Clip => buf.extend_from_slice(recorded),
        FrameGen::Synthetic(t) => {
            buf.resize(recorded.len(), 0.0);
            if base.len() == recorded.len() {
                synthetic_leader(base, t as u64, buf);
            } else {
                buf.copy_from_slice(recorded);
            }
        }
        FrameGen::Poke { at, value } => {
            buf.extend_from_slice(recorded);
            let n = buf.len();
            buf[at as usize % n] = value.value();
        }
        FrameGen::Fill(v) => buf.resize(recorded.len(), v.value()),
        FrameGen::Scale(v) => buf.extend(recorded.iter().map(|x| x * v.value())),
        FrameGen::Len(n) => buf.extend(recorded.iter().copied().cycle().take(n as usize % 1024)),
    }
}

/// Finite values above the buffer's input limit.
fn over_limit(buffer: Buffer, x: &[f32]) -> bool {
    let lim = input::limit_of(buffer);
    x.iter().all(|v| v.is_finite()) && x.iter().any(|v| v.abs() > lim)
}

/// One leader frame into `s`: alone, or through `batch` (`Session::step_many`
/// with `s` alone in it).
pub fn push_leader<'a>(
    s: &mut Session<'a>,
    batch: Option<&mut StepBatch<'_>>,
    leader: &[f32],
) -> Result<(), Error> {
    match batch {
        Some(b) => Session::step_many(&mut [s], &[leader], b).map_err(|(i, e)| {
            assert_eq!(i, 0, "step_many of one session blamed session {i}");
            e
        }),
        None => s.push_leader_frame(leader),
    }
}

/// A clean tick: music pushed ahead (until refused or `a_m + 3` tokens
/// ahead), one leader frame (pulling / pushing music on backlog), then
/// every ready frame pulled into `sink`. `Ok(false)`: the session is stuck
/// (track or forced history exhausted).
#[allow(clippy::too_many_arguments)]
pub fn tick<'a>(
    s: &mut Session<'a>,
    mut batch: Option<&mut StepBatch<'_>>,
    clip: &Clip,
    leader: &[f32],
    music_t: &mut usize,
    frames_in: usize,
    out: &mut FollowerFrame,
    sink: &mut dyn FnMut(&FollowerFrame),
) -> Result<bool, Error> {
    let ahead = 4 * (s.config().music_lookahead as usize + 3);
    while *music_t < frames_in + ahead {
        match s.push_music_frame(clip.music_frame(*music_t)) {
            Ok(()) => *music_t += 1,
            Err(Error::Backlog { .. }) | Err(Error::State) => break,
            Err(e) => return Err(e),
        }
    }
    let mut pushed = false;
    for _ in 0..4 {
        match push_leader(s, batch.as_deref_mut(), leader) {
            Ok(()) => {
                pushed = true;
                break;
            }
            Err(Error::Backlog {
                buffer: Buffer::FollowerPos3d,
                ..
            }) => {
                let mut any = false;
                while s.pull_follower_frame(out)? {
                    sink(out);
                    any = true;
                }
                if !any {
                    return Ok(false);
                }
            }
            Err(Error::Backlog { .. }) => match s.push_music_frame(clip.music_frame(*music_t)) {
                Ok(()) => *music_t += 1,
                Err(Error::Backlog { .. }) | Err(Error::State) => return Ok(false),
                Err(e) => return Err(e),
            },
            Err(e) => return Err(e),
        }
    }
    while s.pull_follower_frame(out)? {
        sink(out);
    }
    Ok(pushed)
}

/// Runs `input` on `model` and checks the contract (module docs). Panics
/// on a violation; returns what it saw.
pub fn run_ops(model: &Model<'_>, clip: &Clip, input: &SessionInput) -> Report {
    let mut rep = Report::default();
    let cfg = input.config.build(model);
    let bytes = match model.session_bytes(&cfg) {
        Ok(b) => b,
        Err(e) => {
            assert!(
                matches!(e, Error::Setting { .. }),
                "session_bytes: undocumented refusal {e:?} for {cfg:?}"
            );
            rep.config_rejected = Some(e);
            return rep;
        }
    };
    rep.arena_bytes = bytes;
    if bytes > MAX_ARENA {
        return rep;
    }
    let ops = &input.ops[..input.ops.len().min(MAX_OPS)];
    let vocab = model.cfg.gpt.vocab;
    let n_music = clip.n_music;
    // Borrowed inputs (tracks, forced histories) must outlive the sessions.
    let owned: Vec<Vec<f32>> = ops
        .iter()
        .map(|op| match op {
            Op::Track {
                frames,
                poke,
                ragged,
            } => {
                let n = (*frames as usize % (clip.music_frames() * 2)) * n_music;
                let mut t: Vec<f32> = (0..n).map(|i| clip.music[i % clip.music.len()]).collect();
                if let (Some((at, v)), false) = (poke, t.is_empty()) {
                    let len = t.len();
                    t[*at as usize % len] = v.value();
                }
                if *ragged && !t.is_empty() {
                    t.pop();
                }
                t
            }
            _ => Vec::new(),
        })
        .collect();
    let forced: Vec<Vec<u32>> = ops
        .iter()
        .map(|op| match op {
            Op::Force {
                rows,
                tokens,
                wrong_seed,
                raw,
            } => {
                let rows = *rows as usize % 64;
                let mut f: Vec<u32> = (0..rows * 5)
                    .map(|i| tokens.get(i).copied().unwrap_or(i as u32))
                    .collect();
                if !raw {
                    for (i, t) in f.iter_mut().enumerate() {
                        *t %= vocab[i % 5].max(1);
                    }
                }
                if rows > 0 && !wrong_seed {
                    f[..5].copy_from_slice(&clip.seed);
                }
                f
            }
            _ => Vec::new(),
        })
        .collect();
    let mut arena_a = vec![0u8; bytes];
    let mut arena_b = vec![0u8; bytes];
    let mut arena_c = vec![0u8; bytes];
    // The batched twin `c`: every operation `a` gets, its leader frames
    // through a one-session `StepBatch` (`Session::step_many`).
    let mut batch_arena =
        vec![0u8; StepBatch::bytes(&model.cfg, &cfg, 1).expect("a valid config has a batch size")];
    let mut batch = StepBatch::new(&model.cfg, &cfg, 1, &mut batch_arena).expect("batch of one");
    let seed = seed_of(input.seed, model, clip);
    let (mut a, mut b) = match (
        Session::new(model, &mut arena_a, &cfg, seed),
        Session::new(model, &mut arena_b, &cfg, seed),
    ) {
        (Ok(a), Ok(b)) => (a, b),
        (Err(e1), Err(e2)) => {
            assert_eq!(e1, e2);
            assert!(
                matches!(e1, Error::Token { .. }),
                "Session::new: undocumented refusal {e1:?}"
            );
            rep.config_rejected = Some(e1);
            return rep;
        }
        (r1, r2) => panic!(
            "two identical Session::new calls disagree: {:?} vs {:?}",
            r1.err(),
            r2.err()
        ),
    };
    let mut c =
        Session::new(model, &mut arena_c, &cfg, seed).expect("a third identical Session::new");
    let base = clip.leader_frame(0).to_vec();
    let (mut leader_t, mut music_t, mut next_index) = (0usize, 0usize, 0u64);
    let (mut fa, mut fb, mut fc) = (
        FollowerFrame::default(),
        FollowerFrame::default(),
        FollowerFrame::default(),
    );
    let mut buf = Vec::with_capacity(1024);
    // Checks one pulled pair.
    let pulled =
        |fa: &FollowerFrame, fb: &FollowerFrame, next_index: &mut u64, rep: &mut Report| {
            assert!(
                frame_bits(fa).eq(frame_bits(fb)),
                "frame {} differs from the shadow session's",
                fa.index
            );
            assert_eq!(fa.index, *next_index, "frame indices not consecutive");
            *next_index += 1;
            rep.pulled += 1;
            assert!(
                frame_finite(fa),
                "non-finite follower frame {} from accepted input",
                fa.index
            );
        };
    for (i, op) in ops.iter().enumerate() {
        match op {
            Op::Leader(g) | Op::Music(g) => {
                let is_leader = matches!(op, Op::Leader(_));
                let rec = if is_leader {
                    clip.leader_frame(leader_t)
                } else {
                    clip.music_frame(music_t)
                };
                make_frame(*g, rec, if is_leader { &base } else { &[] }, &mut buf);
                let ra = if is_leader {
                    a.push_leader_frame(&buf)
                } else {
                    a.push_music_frame(&buf)
                };
                let rc = if is_leader {
                    push_leader(&mut c, Some(&mut batch), &buf)
                } else {
                    c.push_music_frame(&buf)
                };
                assert_eq!(ra, rc, "op {i}: the batched twin answered differently");
                let want_len = if is_leader { POSE_DIM } else { n_music };
                let which = if is_leader {
                    Buffer::LeaderPos3d
                } else {
                    Buffer::Music
                };
                match ra {
                    Ok(()) => {
                        let rb = if is_leader {
                            b.push_leader_frame(&buf)
                        } else {
                            b.push_music_frame(&buf)
                        };
                        assert_eq!(rb, Ok(()), "shadow refused what the session accepted");
                        assert!(
                            buf.len() == want_len && input::check(which, &buf).is_ok(),
                            "accepted a bad frame"
                        );
                        rep.pushed += 1;
                        if is_leader {
                            leader_t += 1;
                        } else {
                            music_t += 1;
                        }
                    }
                    Err(e) => {
                        assert!(documented(&e), "op {i}: undocumented refusal {e:?}");
                        let bad = buf.len() == want_len && buf.iter().any(|v| !v.is_finite());
                        assert_eq!(
                            matches!(e, Error::NonFinite { .. }),
                            bad,
                            "op {i}: NonFinite iff non-finite input ({e:?})"
                        );
                        let over = buf.len() == want_len && over_limit(which, &buf);
                        assert_eq!(
                            matches!(e, Error::OutOfRange { .. }),
                            over,
                            "op {i}: OutOfRange iff finite over-limit input ({e:?})"
                        );
                        rep.refused += 1;
                        rep.non_finite_refused += bad as usize;
                        rep.out_of_range_refused += over as usize;
                        rep.backlog_refused += matches!(e, Error::Backlog { .. }) as usize;
                    }
                }
            }
            Op::Pull(n) => {
                for _ in 0..*n {
                    let (ra, rb) = (
                        a.pull_follower_frame(&mut fa),
                        b.pull_follower_frame(&mut fb),
                    );
                    assert_eq!(ra, rb, "pull differs from the shadow");
                    assert_eq!(
                        ra,
                        c.pull_follower_frame(&mut fc),
                        "pull differs from the batched twin"
                    );
                    assert!(
                        ra != Ok(true) || frame_bits(&fa).eq(frame_bits(&fc)),
                        "frame {} differs from the batched twin's",
                        fa.index
                    );
                    match ra {
                        Ok(true) => pulled(&fa, &fb, &mut next_index, &mut rep),
                        Ok(false) => break,
                        Err(e) => panic!("pull: {e:?}"),
                    }
                }
            }
            Op::PullAll => loop {
                let (ra, rb) = (
                    a.pull_follower_frame(&mut fa),
                    b.pull_follower_frame(&mut fb),
                );
                assert_eq!(ra, rb, "pull differs from the shadow");
                assert_eq!(
                    ra,
                    c.pull_follower_frame(&mut fc),
                    "pull differs from the batched twin"
                );
                assert!(
                    ra != Ok(true) || frame_bits(&fa).eq(frame_bits(&fc)),
                    "frame {} differs from the batched twin's",
                    fa.index
                );
                match ra {
                    Ok(true) => pulled(&fa, &fb, &mut next_index, &mut rep),
                    Ok(false) => break,
                    Err(e) => panic!("pull: {e:?}"),
                }
            },
            Op::Ticks(n) => {
                for _ in 0..(*n % 64) {
                    let lf = clip.leader_frame(leader_t).to_vec();
                    let (mut ma, mut mb, mut mc) = (music_t, music_t, music_t);
                    let (mut va, mut vb, mut vc) = (Vec::new(), Vec::new(), Vec::new());
                    let ra = tick(
                        &mut a,
                        None,
                        clip,
                        &lf,
                        &mut ma,
                        leader_t,
                        &mut fa,
                        &mut |f| va.push(*f),
                    );
                    let rb = tick(
                        &mut b,
                        None,
                        clip,
                        &lf,
                        &mut mb,
                        leader_t,
                        &mut fb,
                        &mut |f| vb.push(*f),
                    );
                    let rc = tick(
                        &mut c,
                        Some(&mut batch),
                        clip,
                        &lf,
                        &mut mc,
                        leader_t,
                        &mut fc,
                        &mut |f| vc.push(*f),
                    );
                    assert_eq!(ra, rb, "tick differs from the shadow");
                    assert_eq!(ra, rc, "tick differs from the batched twin");
                    assert_eq!((ma, ma), (mb, mc));
                    assert_eq!(va.len(), vb.len());
                    assert!(
                        va.len() == vc.len()
                            && va
                                .iter()
                                .zip(&vc)
                                .all(|(x, y)| frame_bits(x).eq(frame_bits(y))),
                        "tick frames differ from the batched twin's"
                    );
                    for (x, y) in va.iter().zip(&vb) {
                        pulled(x, y, &mut next_index, &mut rep);
                    }
                    music_t = ma;
                    match ra {
                        Ok(true) => leader_t += 1,
                        Ok(false) => break,
                        Err(e) => panic!("clean tick: {e:?}"),
                    }
                }
            }
            Op::Reset(g) => {
                let seed = seed_of(*g, model, clip);
                let (ra, rb) = (a.reset(seed), b.reset(seed));
                assert_eq!(ra, rb);
                assert_eq!(ra, c.reset(seed));
                match ra {
                    Ok(()) => {
                        next_index = 0;
                        leader_t = 0;
                        music_t = 0;
                    }
                    Err(e) => assert!(matches!(e, Error::Token { .. }), "reset: {e:?}"),
                }
            }
            Op::Force { .. } => {
                let ra = a.force_history(&forced[i]);
                assert_eq!(
                    ra,
                    c.force_history(&forced[i]),
                    "force_history differs from the batched twin"
                );
                if ra.is_ok() {
                    assert_eq!(b.force_history(&forced[i]), Ok(()));
                } else {
                    assert!(
                        documented(ra.as_ref().unwrap_err()),
                        "force_history: {ra:?}"
                    );
                }
            }
            Op::Track { .. } => {
                let ra = a.set_music_track(&owned[i]);
                assert_eq!(
                    ra,
                    c.set_music_track(&owned[i]),
                    "set_music_track differs from the batched twin"
                );
                match ra {
                    Ok(()) => assert_eq!(b.set_music_track(&owned[i]), Ok(())),
                    Err(e) => {
                        assert!(documented(&e), "set_music_track: {e:?}");
                        let t = &owned[i];
                        let bad = t.len() % n_music == 0 && t.iter().any(|v| !v.is_finite());
                        if matches!(e, Error::NonFinite { .. }) {
                            assert!(bad);
                        }
                        if matches!(e, Error::OutOfRange { .. }) {
                            assert!(t.len() % n_music == 0 && over_limit(Buffer::Music, t));
                        }
                    }
                }
            }
        }
    }
    // Usable afterwards: a reset and a clean drive give finite frames.
    a.reset(clip.seed).expect("reset with the clip seed");
    let (mut music_t, mut stuck) = (0usize, false);
    let mut index = 0u64;
    let mut bad = None;
    for t in 0..(a.latency_frames() as usize + 48) {
        let lf = clip.leader_frame(t).to_vec();
        let mut sink = |f: &FollowerFrame| {
            if f.index != index || !frame_finite(f) {
                bad = Some(f.index);
            }
            index += 1;
        };
        match tick(&mut a, None, clip, &lf, &mut music_t, t, &mut fa, &mut sink) {
            Ok(true) => {}
            Ok(false) => {
                stuck = true;
                break;
            }
            Err(e) => panic!("clean drive after reset: {e:?}"),
        }
    }
    assert_eq!(bad, None, "clean drive after reset: bad frame");
    assert!(!stuck, "clean drive after reset got stuck");
    assert!(index > 0, "clean drive after reset produced no frame");
    rep.recovered = index as usize;
    let _ = ROT_DIM;
    rep
}
