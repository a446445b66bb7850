//! A Bailando (solo) streaming session on the btiny fixture driven by an
//! arbitrary config and up to `MAX_OPS` operations: music pushes of 0..=3
//! rows (sometimes ragged; NaN, ±Inf, huge, at-the-limit, subnormal and
//! raw-bit values), `finish` with either padding, `step`, pulls (also into
//! a wrong-length buffer), drains and resets (in- and out-of-vocabulary
//! seeds), in any order. Three sessions run:
//!
//! - `main`: `Session::new`, stepped by its own `step` / `pull`;
//! - `twin`: `Session::new_batched`, stepped only through a `StepBatch`
//!   (batch size 1..=3, optionally shared with a `decoy` session that gets
//!   its own music, before or after the twin in the slice), its pull
//!   emulating `Session::pull` (step until a frame is ready);
//! - `decoy`: noise in the batch; its frames must be finite.
//!
//! Checked after every operation (docs/ROBUSTNESS.md §2): no panic; the
//! answer of every call is the one a shadow model predicts (a refusal is
//! exactly the documented `Error`: `State`, `Ragged`, `NonFinite` at the
//! first NaN/Inf, `OutOfRange` at the first finite |v| > 1e6, `Backlog`,
//! `Length`, `Token`, `Setting`); a predicted refusal goes to both
//! sessions or to one only (chosen by the input), so bit equality later
//! proves it changed nothing; `music_rows`, `tokens`, `frames_ready`,
//! `done` and the newest token agree between the two sessions and with
//! the shadow; frames decoded = `hop * tokens.saturating_sub(d)` (0 before
//! the first step, all once the last step of an ended session ran); every
//! pulled frame is finite, its index consecutive, and bit-identical
//! between main and twin; after `finish`, pulling drains to `done()` with
//! exactly `padded_rows(padding, rows) * hop` frames pulled since the last
//! reset (checked whenever a pull of an ended session answers `None`, and
//! by a final drain of every run). `DUO_FUZZ_TRACE` prints every operation and the counters after it.
#![no_main]

use std::sync::OnceLock;

use arbitrary::{Result as AResult, Unstructured};
use duolando_core::bailando::config::POSE_DIM;
use duolando_core::bailando::exact::{padded_rows, MusicPadding};
use duolando_core::bailando::model::Model;
use duolando_core::bailando::session::config::MAX_BUFFER;
use duolando_core::bailando::session::{dec_future_max, window_rows, CacheSchedule, Session, SessionConfig, StepBatch};
use duolando_core::error::{Buffer, Error, Setting};
use duolando_core::format::DuoFile;
use duolando_core::input::MAX_MUSIC_FEATURE;
use duolando_core::nn::kv_store::KvType;
use duolando_core::nn::sampler::Sampling;
use libfuzzer_sys::fuzz_target;

const MAX_OPS: usize = 192;
/// Rows of music the decoy takes before it is finished (then drained and
/// reset).
const DECOY_ROWS: usize = 24;

#[repr(C, align(64))]
struct Aligned<T: ?Sized>(T);
/// `DuoFile::parse` wants a 64-byte aligned buffer.
static BTINY: &Aligned<[u8]> = &Aligned(*include_bytes!("../../tests/fixtures/bailando_btiny/model.duo"));

fn model() -> &'static Model<'static> {
    static D: OnceLock<DuoFile<'static>> = OnceLock::new();
    static M: OnceLock<Model<'static>> = OnceLock::new();
    M.get_or_init(|| {
        let duo = D.get_or_init(|| DuoFile::parse(&BTINY.0).expect("btiny model.duo parses"));
        Model::from_duo(duo).expect("btiny binds as Bailando")
    })
}

/// Music rows after the loader's padding (independent of core's
/// `padded_rows`: the authors' loaders, docs/BAILANDO.md).
/// `dec_future_max` of the fixture (a simulation of the decoder stacks:
/// computed once).
fn dmax(m: &Model<'_>) -> u32 {
    static D: OnceLock<u32> = OnceLock::new();
    *D.get_or_init(|| dec_future_max(&m.cfg))
}

/// `StepBatch::bytes` for 1..=3 sessions (each call simulates the decoder
/// stacks; computed once, so no run allocates memory that outlives it).
fn batch_bytes(m: &Model<'_>, n: usize) -> usize {
    static B: OnceLock<[usize; 3]> = OnceLock::new();
    B.get_or_init(|| [1, 2, 3].map(|n| StepBatch::bytes(&m.cfg, n).expect("StepBatch::bytes")))[n - 1]
}

fn padded(p: MusicPadding, rows: usize) -> usize {
    match p {
        MusicPadding::Aist => rows + 1,
        MusicPadding::Demo => (rows / 8 + 1) * 8,
    }
}

/// The input policy (docs/ROBUSTNESS.md §3), re-stated: the first NaN/Inf,
/// else the first finite value over the limit.
fn policy(x: &[f32]) -> Result<(), Error> {
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFinite { buffer: Buffer::Music, index });
    }
    match x.iter().position(|v| v.abs() > MAX_MUSIC_FEATURE) {
        Some(index) => Err(Error::OutOfRange { buffer: Buffer::Music, index }),
        None => Ok(()),
    }
}

fn special(u: &mut Unstructured<'_>) -> AResult<f32> {
    Ok(match u.int_in_range(0u8..=14)? {
        0 => f32::NAN,
        1 => -f32::NAN,
        2 => f32::INFINITY,
        3 => f32::NEG_INFINITY,
        4 => 1e30,
        5 => -2e6,
        6 => f32::MAX,
        7 => f32::MIN,
        8 => MAX_MUSIC_FEATURE,
        9 => -MAX_MUSIC_FEATURE,
        10 => f32::from_bits(MAX_MUSIC_FEATURE.to_bits() + 1),
        11 => f32::from_bits(1),
        12 => -0.0,
        13 => 5e5,
        _ => f32::from_bits(u.arbitrary()?),
    })
}

fn lcg(x: &mut u32) -> u32 {
    *x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
    *x
}

/// `len` floats of music from the input: a pattern, then up to 4 pokes.
fn music_values(u: &mut Unstructured<'_>, nm: usize, clock: &mut u32) -> AResult<Vec<f32>> {
    let n = u.int_in_range(0usize..=3)?;
    let mut len = n * nm;
    if u.ratio(1u8, 12)? {
        let delta = u.int_in_range(1..=nm - 1)?;
        len = if n > 0 && u.arbitrary()? { len - delta } else { len + delta };
    }
    let mut v = vec![0f32; len];
    let mut x: u32 = u.arbitrary()?;
    match u.int_in_range(0u8..=4)? {
        0 => v.fill(u.arbitrary::<i16>()? as f32 / 256.0),
        1 => {
            let amp = *u.choose(&[1.0f32, 10.0, 1e3, 1e6])?;
            v.iter_mut().for_each(|a| *a = amp * ((lcg(&mut x) >> 8) as f32 / (1u32 << 23) as f32 - 1.0));
        }
        2 => {
            // A smooth "track" on the session's own clock.
            for (i, a) in v.iter_mut().enumerate() {
                let t = (*clock as usize + i / nm) as f32;
                *a = (0.3 * t + 0.07 * (i % nm) as f32).sin();
            }
            *clock = clock.wrapping_add((len / nm) as u32);
        }
        3 => v.iter_mut().for_each(|a| *a = if lcg(&mut x) & 0x100 == 0 { MAX_MUSIC_FEATURE } else { -MAX_MUSIC_FEATURE }),
        _ => {
            for a in v.iter_mut().take(16) {
                *a = f32::from_bits(u.arbitrary()?);
            }
        }
    }
    if !v.is_empty() {
        for _ in 0..u.int_in_range(0u8..=3)? {
            let i = u.arbitrary::<u16>()? as usize % v.len();
            v[i] = special(u)?;
        }
    }
    Ok(v)
}

fn seed(u: &mut Unstructured<'_>, vocab: [u32; 2]) -> AResult<[u32; 2]> {
    let mut s = [0u32; 2];
    for (j, t) in s.iter_mut().enumerate() {
        let raw: u32 = u.arbitrary()?;
        *t = match u.int_in_range(0u8..=7)? {
            0 => vocab[j] + raw % 4,
            1 => u32::MAX,
            2 => raw,
            _ => raw % vocab[j],
        };
    }
    Ok(s)
}

fn seed_answer(s: [u32; 2], vocab: [u32; 2]) -> Result<(), Error> {
    for j in 0..2 {
        if s[j] >= vocab[j] {
            return Err(Error::Token { stream: j as u8, token: s[j], vocab: vocab[j] });
        }
    }
    Ok(())
}

/// A config in range (the fields the brief names, small buffers).
fn config(u: &mut Unstructured<'_>, m: &Model<'_>) -> AResult<SessionConfig> {
    let dmax = dmax(m);
    let win = window_rows(&m.cfg) as u32;
    let kmax = m.cfg.gpt.vocab[0].min(m.cfg.gpt.vocab[1]);
    let dec_future = u.int_in_range(0..=dmax)?;
    let shift = u.int_in_range(1..=win)?;
    let sampling = if u.arbitrary()? { Sampling::Greedy } else { duolando_gen::session::sampling_of(u.int_in_range(1..=kmax)?, u.arbitrary()?) };
    let pending_frames = u.int_in_range(0..=24)?;
    // The schedule (the same numbers either way) from a bit already drawn,
    // so that the committed seeds decode as before: odd pending sizes spread.
    let schedule = if pending_frames % 2 == 1 { CacheSchedule::Spread } else { CacheSchedule::Reprefill };
    Ok(SessionConfig {
        dec_future,
        shift,
        sampling,
        pending_frames,
        music_buffer_rows: u.int_in_range(1..=8)?,
        kv: if u.arbitrary()? { KvType::F32 } else { KvType::F16 },
        schedule,
    })
}

/// One setting pushed out of its range, and the refusal it must get.
fn bad_config(u: &mut Unstructured<'_>, m: &Model<'_>, good: SessionConfig) -> AResult<(SessionConfig, Error)> {
    let dmax = dmax(m);
    let win = window_rows(&m.cfg) as u32;
    let kmax = m.cfg.gpt.vocab[0].min(m.cfg.gpt.vocab[1]);
    let over = |u: &mut Unstructured<'_>, max: u32| -> AResult<u32> { Ok(max.saturating_add(1 + u.int_in_range(0u32..=3)? * u.int_in_range(0u32..=1 << 20)?)) };
    let e = |setting, value, max| Error::Setting { setting, value, max };
    Ok(match u.int_in_range(0u8..=6)? {
        0 => {
            let v = over(u, dmax)?;
            (SessionConfig { dec_future: v, ..good }, e(Setting::DecFuture, v, dmax))
        }
        1 => (SessionConfig { shift: 0, ..good }, e(Setting::Shift, 0, win)),
        2 => {
            let v = over(u, win)?;
            (SessionConfig { shift: v, ..good }, e(Setting::Shift, v, win))
        }
        3 => (SessionConfig { sampling: Sampling::TopK { k: 0, rng_seed: 1 }, ..good }, e(Setting::TopK, 0, kmax)),
        4 => {
            let v = over(u, kmax)?;
            (SessionConfig { sampling: Sampling::TopK { k: v, rng_seed: 1 }, ..good }, e(Setting::TopK, v, kmax))
        }
        5 => {
            let v = over(u, MAX_BUFFER)?;
            (SessionConfig { pending_frames: v, ..good }, e(Setting::PendingFrames, v, MAX_BUFFER))
        }
        _ => {
            let v = if u.arbitrary()? { 0 } else { over(u, MAX_BUFFER)? };
            (SessionConfig { music_buffer_rows: v, ..good }, e(Setting::MusicBuffer, v, MAX_BUFFER))
        }
    })
}

/// Who gets an operation whose answer is a refusal.
#[derive(Clone, Copy, PartialEq, Eq)]
enum To {
    Both,
    Main,
    Twin,
}

/// What the shadow knows of the current episode (since the last reset).
#[derive(Default)]
struct Shadow {
    rows: usize,
    /// Padded rows once finished.
    end: Option<usize>,
    pulled: usize,
}

struct Decoy<'a> {
    s: Session<'a>,
    first: bool,
    clock: u32,
    seed: [u32; 2],
}

struct Run<'a> {
    m: &'a Model<'a>,
    main: Session<'a>,
    twin: Session<'a>,
    decoy: Option<Decoy<'a>>,
    batch: StepBatch<'a>,
    cfg: SessionConfig,
    sh: Shadow,
    hop: usize,
    nm: usize,
}

/// `DUO_FUZZ_TRACE=1`: every operation and the state after it on stderr
/// (to read a crash or check a seed: `fuzz run solo_session FILE`).
fn trace() -> bool {
    static T: OnceLock<bool> = OnceLock::new();
    *T.get_or_init(|| std::env::var_os("DUO_FUZZ_TRACE").is_some())
}

fn finite(f: &[f32]) -> bool {
    f.iter().all(|v| v.is_finite())
}

impl<'a> Run<'a> {
    fn can_step(&self) -> bool {
        let avail = self.sh.end.unwrap_or(self.sh.rows);
        self.main.tokens() < avail && self.main.frames_ready() <= self.cfg.pending_frames as usize
    }

    /// The decoy gets a row of its own music (or is finished / drained /
    /// reset), once per twin step request.
    fn feed_decoy(&mut self) {
        let Some(d) = self.decoy.as_mut() else { return };
        if d.s.done() {
            d.s.reset(d.seed).expect("decoy reset");
            return;
        }
        if d.s.music_rows() >= DECOY_ROWS {
            let _ = d.s.finish(MusicPadding::Demo);
            return;
        }
        let row: Vec<f32> = (0..self.nm).map(|i| (0.21 * d.clock as f32 + 0.05 * i as f32).cos() * 3.0).collect();
        match d.s.push_music(&row) {
            Ok(()) => d.clock += 1,
            Err(Error::Backlog { .. }) => {}
            Err(e) => panic!("decoy push refused: {e:?}"),
        }
    }

    fn pull_decoy(&mut self) {
        let Some(d) = self.decoy.as_mut() else { return };
        let mut f = [0f32; POSE_DIM];
        while d.s.pull(&mut f).expect("decoy pull").is_some() {
            assert!(finite(&f), "decoy frame not finite");
        }
    }

    /// One batch step for the twin (other sessions of the batch may step
    /// first); whether the twin stepped.
    fn twin_step(&mut self) -> bool {
        let before = self.twin.tokens();
        self.feed_decoy();
        for _ in 0..4 * (DECOY_ROWS + 8) {
            let r = match self.decoy.as_mut() {
                None => self.batch.step(&mut [&mut self.twin]),
                Some(d) if d.first => self.batch.step(&mut [&mut d.s, &mut self.twin]),
                Some(d) => self.batch.step(&mut [&mut self.twin, &mut d.s]),
            };
            let n = r.unwrap_or_else(|e| panic!("batch step refused: {e:?}"));
            self.pull_decoy();
            let after = self.twin.tokens();
            if after != before {
                assert_eq!(after, before + 1, "twin stepped more than once in one batch step");
                return true;
            }
            if n == 0 {
                return false;
            }
        }
        panic!("the batch never stepped the twin nor ran dry");
    }

    /// `Session::pull` for a batched session: step until a frame is ready.
    fn twin_pull(&mut self, out: &mut [f32]) -> Result<Option<u64>, Error> {
        if out.len() == POSE_DIM {
            while self.twin.frames_ready() == 0 && self.twin_step() {}
        }
        self.twin.pull(out)
    }

    /// The two sessions agree, and agree with the shadow.
    fn check(&self, what: &str) {
        if trace() {
            eprintln!("{what:>20}: rows {} tokens {} ready {} pulled {} end {:?}", self.main.music_rows(), self.main.tokens(), self.main.frames_ready(), self.sh.pulled, self.sh.end);
        }
        let (a, b) = (&self.main, &self.twin);
        let obs = |s: &Session<'_>| (s.music_rows(), s.tokens(), s.frames_ready(), s.done());
        assert_eq!(obs(a), obs(b), "{what}: main and twin disagree (rows, tokens, ready, done)");
        let sh = &self.sh;
        assert_eq!(a.music_rows(), sh.rows, "{what}: music rows");
        let tok = a.tokens();
        let (ta, tb) = (a.token(tok - 1).expect("newest token held"), b.token(tok - 1).expect("twin newest token"));
        assert_eq!(ta, tb, "{what}: newest token differs");
        let vocab = self.m.cfg.gpt.vocab;
        assert!(ta[0] < vocab[0] && ta[1] < vocab[1], "{what}: token {ta:?} outside vocab");
        let d = self.cfg.dec_future as usize;
        let want = match sh.end {
            _ if tok == 1 => 0,
            Some(e) if tok == e => e,
            _ => tok.saturating_sub(d),
        };
        assert_eq!(sh.pulled + a.frames_ready(), want * self.hop, "{what}: frames decoded (tokens {tok}, d {d}, end {:?})", sh.end);
        // A step runs with at most pending_frames waiting and makes one
        // token's frames final; the first step two (the seed's and token
        // 1's, at d 0), the last of an ended session d + 1.
        let most = self.cfg.pending_frames as usize + self.hop * (d + 1).max(2);
        assert!(a.frames_ready() <= most, "{what}: {} frames ready, at most {most} expected", a.frames_ready());
        match sh.end {
            None => {
                assert!(tok <= sh.rows.max(1), "{what}: {tok} tokens from {} rows", sh.rows);
                assert!(sh.rows.saturating_sub(tok) <= self.cfg.music_buffer_rows as usize, "{what}: music backlog over the buffer");
                assert!(!a.done(), "{what}: done before finish");
            }
            Some(e) => {
                assert!(tok <= e, "{what}: {tok} tokens past the padded end {e}");
                assert_eq!(a.done(), tok == e && sh.pulled == e * self.hop, "{what}: done()");
            }
        }
    }

    fn expect_push(&self, v: &[f32]) -> Result<usize, Error> {
        let nm = self.nm;
        if self.sh.end.is_some() {
            return Err(Error::State);
        }
        if v.is_empty() || v.len() % nm != 0 {
            return Err(Error::Ragged { buffer: Buffer::Music, len: v.len(), row: nm });
        }
        policy(v)?;
        let n = v.len() / nm;
        let (rows, tok, cap) = (self.sh.rows, self.main.tokens(), self.cfg.music_buffer_rows as usize);
        if (rows + n).saturating_sub(tok) > cap {
            return Err(Error::Backlog { buffer: Buffer::Music, held: rows.saturating_sub(tok), capacity: cap });
        }
        Ok(n)
    }

    /// A call whose answer must be `want`: an accepted one goes to both
    /// sessions; a refusal to those `to` names.
    fn refusable<T: PartialEq + std::fmt::Debug>(&mut self, what: &str, to: To, want: Result<(), Error>, mut f: impl FnMut(&mut Session<'a>) -> Result<T, Error>, ok: T) {
        let (main, twin) = match want {
            Ok(()) => (true, true),
            Err(_) => (to != To::Twin, to != To::Main),
        };
        if trace() {
            eprintln!("{what:>20}: want {want:?} -> {}", if want.is_ok() { "both" } else { ["both", "main", "twin"][to as usize] });
        }
        let want = want.map(|()| ok);
        if main {
            assert_eq!(f(&mut self.main), want, "{what}: main");
        }
        if twin {
            assert_eq!(f(&mut self.twin), want, "{what}: twin");
        }
    }

    fn pull(&mut self, what: &str) -> bool {
        let (mut fa, mut fb) = ([0f32; POSE_DIM], [0f32; POSE_DIM]);
        let ra = self.main.pull(&mut fa);
        let rb = self.twin_pull(&mut fb);
        assert_eq!(ra, rb, "{what}: pull answers differ");
        match ra {
            Ok(Some(i)) => {
                assert_eq!(i as usize, self.sh.pulled, "{what}: frame index");
                assert!(finite(&fa), "{what}: frame {i} not finite");
                assert!(fa.iter().zip(&fb).all(|(x, y)| x.to_bits() == y.to_bits()), "{what}: frame {i} differs between main and twin");
                self.sh.pulled += 1;
                if let Some(e) = self.sh.end {
                    assert!(self.sh.pulled <= e * self.hop, "{what}: more frames than the padded music");
                }
                true
            }
            Ok(None) => {
                match self.sh.end {
                    None => assert!(self.main.tokens() >= self.sh.rows, "{what}: no frame while music waits ({} tokens, {} rows)", self.main.tokens(), self.sh.rows),
                    Some(e) => {
                        assert_eq!(self.sh.pulled, e * self.hop, "{what}: drained with {} frames, padded music {e} rows x hop {}", self.sh.pulled, self.hop);
                        assert!(self.main.done(), "{what}: drained but not done");
                        assert_eq!(self.main.tokens(), e, "{what}: tokens at the end");
                    }
                }
                false
            }
            Err(e) => panic!("{what}: pull refused: {e:?}"),
        }
    }

    fn drain(&mut self, what: &str) {
        let bound = (self.sh.rows + 16) * self.hop + 2;
        for _ in 0..bound {
            if !self.pull(what) {
                return;
            }
        }
        panic!("{what}: no end to the frames");
    }

    fn op(&mut self, u: &mut Unstructured<'_>, clock: &mut u32) -> AResult<()> {
        let to = *u.choose(&[To::Both, To::Main, To::Twin])?;
        let vocab = self.m.cfg.gpt.vocab;
        match u.int_in_range(0u8..=15)? {
            0..=5 => {
                let v = music_values(u, self.nm, clock)?;
                let want = self.expect_push(&v);
                let n = *want.as_ref().unwrap_or(&0);
                self.refusable("push_music", to, want.map(|_| ()), |s| s.push_music(&v), ());
                self.sh.rows += n;
                self.check("push_music");
            }
            6 => {
                let p = if u.arbitrary()? { MusicPadding::Demo } else { MusicPadding::Aist };
                let want = if self.sh.end.is_some() || self.sh.rows == 0 { Err(Error::State) } else { Ok(()) };
                let accepted = want.is_ok();
                self.refusable("finish", to, want, |s| s.finish(p), ());
                if accepted {
                    assert_eq!(padded(p, self.sh.rows), padded_rows(p, self.sh.rows), "padded_rows({p:?}, {})", self.sh.rows);
                    self.sh.end = Some(padded(p, self.sh.rows));
                }
                self.check("finish");
            }
            7 | 8 => {
                let want = self.can_step();
                let tok = self.main.tokens();
                let r = self.main.step().unwrap_or_else(|e| panic!("step refused: {e:?}"));
                assert_eq!(r.is_some(), want, "step: stepped {:?}, predicted {want}", r);
                if let Some(r) = r {
                    assert_eq!(r.k, tok - 1, "step report k");
                    assert_eq!(Ok(r.token), self.main.token(tok), "step report token");
                }
                assert_eq!(self.twin_step(), want, "twin step");
                self.check("step");
            }
            9..=11 => {
                for _ in 0..u.int_in_range(1u8..=12)? {
                    self.pull("pull");
                    self.check("pull");
                }
            }
            12 => {
                self.drain("drain");
                self.check("drain");
            }
            13 => {
                let mut len = u.int_in_range(0usize..=POSE_DIM + 8)?;
                if len == POSE_DIM {
                    len = 0;
                }
                let mut buf = vec![0f32; len];
                let want = Err(Error::Length { buffer: Buffer::Output, len, expected: POSE_DIM });
                self.refusable("pull (wrong length)", to, want, |s| s.pull(&mut buf).map(|_| ()), ());
                // A batched session has no step memory of its own.
                assert_eq!(self.twin.step(), Err(Error::State), "twin's own step");
                self.check("pull (wrong length)");
            }
            _ => {
                let s = seed(u, vocab)?;
                let want = seed_answer(s, vocab);
                let accepted = want.is_ok();
                self.refusable("reset", to, want, |x| x.reset(s), ());
                if accepted {
                    self.sh = Shadow::default();
                    assert_eq!((self.main.tokens(), self.main.music_rows(), self.main.frames_ready()), (1, 0, 0), "reset");
                    assert_eq!(self.main.token(0), Ok(s), "seed after reset");
                }
                self.check("reset");
            }
        }
        Ok(())
    }
}

fn run(u: &mut Unstructured<'_>) -> AResult<()> {
    let m = model();
    let vocab = m.cfg.gpt.vocab;
    let cfg = config(u, m)?;

    // An out-of-range setting: refused by every constructor, by name.
    if u.ratio(1u8, 8)? {
        let (bad, want) = bad_config(u, m, cfg)?;
        assert_eq!(m.session_bytes(&bad).err(), Some(want.clone()), "session_bytes({bad:?})");
        assert_eq!(m.batched_session_bytes(&bad).err(), Some(want.clone()), "batched_session_bytes");
        assert_eq!(Session::new(m, &mut [], &bad, [0, 0]).err(), Some(want.clone()), "Session::new({bad:?})");
        assert_eq!(Session::new_batched(m, &mut [], &bad, [0, 0]).err(), Some(want), "Session::new_batched");
    }

    let (nb, nt) = (m.session_bytes(&cfg).expect("session_bytes"), m.batched_session_bytes(&cfg).expect("batched_session_bytes"));
    // The seed: out of vocabulary is refused, then taken modulo.
    let mut s0 = seed(u, vocab)?;
    let want = seed_answer(s0, vocab);
    if want.is_err() {
        let mut a = vec![0u8; nb];
        assert_eq!(Session::new(m, &mut a, &cfg, s0).err(), want.clone().err(), "Session::new with seed {s0:?}");
        assert_eq!(Session::new_batched(m, &mut a, &cfg, s0).err(), want.err(), "new_batched with seed {s0:?}");
        s0 = [s0[0] % vocab[0], s0[1] % vocab[1]];
    }

    // Arenas at any base address (session_bytes is for any base).
    let off = u.int_in_range(0usize..=63)?;
    let n_batch = u.int_in_range(1usize..=3)?;
    let decoy_cfg = if u.arbitrary()? {
        let c = config(u, m)?;
        Some((c, u.arbitrary::<bool>()?))
    } else {
        None
    };
    let mut a_main = vec![0u8; nb + 64];
    let mut a_twin = vec![0u8; nt + 64];
    let mut a_batch = vec![0u8; batch_bytes(m, n_batch)];
    let mut a_decoy = vec![0u8; decoy_cfg.map_or(0, |(c, _)| m.batched_session_bytes(&c).expect("decoy bytes"))];
    let main = Session::new(m, &mut a_main[off..off + nb], &cfg, s0).expect("Session::new");
    let twin = Session::new_batched(m, &mut a_twin[off..off + nt], &cfg, s0).expect("Session::new_batched");
    let batch = StepBatch::new(&m.cfg, n_batch, &mut a_batch).expect("StepBatch::new");
    let decoy = decoy_cfg.map(|(c, first)| Decoy { s: Session::new_batched(m, &mut a_decoy, &c, [1, 2]).expect("decoy"), first, clock: 0, seed: [1, 2] });
    if trace() {
        eprintln!("config {cfg:?} seed {s0:?} offset {off} batch {n_batch} decoy {decoy_cfg:?}");
    }
    let mut r = Run { m, main, twin, decoy, batch, cfg, sh: Shadow::default(), hop: m.cfg.hop(), nm: m.cfg.gpt.n_music as usize };
    r.check("new");

    let mut clock = 0u32;
    for _ in 0..MAX_OPS {
        if u.is_empty() || r.op(u, &mut clock).is_err() {
            break;
        }
    }

    // Every run ends: finish (with a row if there is none) and drain.
    if r.sh.end.is_none() {
        if r.sh.rows == 0 {
            let row = vec![0.25f32; r.nm];
            assert_eq!(r.main.push_music(&row), Ok(()), "final row");
            assert_eq!(r.twin.push_music(&row), Ok(()), "final row (twin)");
            r.sh.rows = 1;
        }
        let p = if u.arbitrary().unwrap_or(false) { MusicPadding::Aist } else { MusicPadding::Demo };
        assert_eq!(r.main.finish(p), Ok(()), "final finish");
        assert_eq!(r.twin.finish(p), Ok(()), "final finish (twin)");
        r.sh.end = Some(padded(p, r.sh.rows));
    }
    r.check("final finish");
    r.drain("final drain");
    r.check("final drain");
    let e = r.sh.end.expect("ended");
    assert_eq!(r.sh.pulled, e * r.hop, "final frame count");
    assert!(r.main.done() && r.twin.done(), "done after the final drain");
    assert_eq!(r.main.push_music(&vec![0.0; r.nm]), Err(Error::State), "music after the end");
    assert_eq!(r.main.finish(MusicPadding::Demo), Err(Error::State), "finish twice");
    r.main.reset(s0).expect("reset after done");
    assert_eq!((r.main.tokens(), r.main.music_rows(), r.main.frames_ready(), r.main.done()), (1, 0, 0, false), "reset after done");
    Ok(())
}

fuzz_target!(|data: &[u8]| {
    let mut u = Unstructured::new(data);
    let _ = run(&mut u);
});
