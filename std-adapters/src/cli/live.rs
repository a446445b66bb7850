//! `duolando live`: streams a leader clip through a streaming session at
//! 30 fps, as a game engine would (one leader frame pushed per 1/30 s tick,
//! follower frames pulled as they become ready), and shows both dancers in
//! the browser as the frames arrive: the live page and a server-sent-events
//! stream on 127.0.0.1 ([`crate::live`]). Each `frame` event carries the
//! tick's leader frame, the follower frames that came out, the latency
//! (frames and measured ms) and the time the tick took. Exits when the clip
//! ends, once the pages have the last event (or after `--linger`).
//! See docs/CLI.md and docs/VIEWER.md.
//!
//! When the clip ends the session is told (`Session::finish`): the follower
//! frames its look-ahead held back come out one per tick in `drain` events
//! (R's frame count in all), then the `end` event.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use duolando_core::duolando::config::POSE_DIM;
use duolando_core::error::Error;
use duolando_core::duolando::exact::Seed;
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::{FollowerFrame, Session, SessionConfig};
use serde::Serialize;

use crate::cli::budget::BudgetArgs;
use crate::cli::dance::inputs::{self, SeedChoice};
use crate::cli::generate::seed_tokens;
use crate::engine_errors::describe;
use crate::live::LiveServer;
use crate::model_file::ModelFile;
use crate::viewer::{JOINTS, SMPLX_PARENTS};

/// Frames per second of the model's motion: one tick per frame.
pub const FPS: f64 = 30.0;
/// Largest `--linger`, seconds.
pub const MAX_LINGER_S: f64 = 3600.0;

/// Flags of `duolando live`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Leader motion: (T, 165) float .npy (world joint positions, metres, 30 fps) or a 30 fps .bvh
    /// with the SMPL-X joint names. Default: the bundled demo clip.
    #[arg(long, requires = "music")]
    pub leader: Option<PathBuf>,
    /// Music: an audio file (WAV, MP3, OGG Vorbis, FLAC) or (T, 54) features .npy at 30 fps,
    /// known ahead as a whole track. Default: the bundled demo clip's music.
    #[arg(long, requires = "leader")]
    pub music: Option<PathBuf>,
    /// The `.duo` model. Default: assets/demo.duo.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// The follower's first frames, (F, 165) float .npy, F >= 4.
    #[arg(long, conflicts_with = "seed_tokens")]
    pub follower_start: Option<PathBuf>,
    /// Seed tokens "up,down,lhand,rhand,transl" instead of start frames.
    #[arg(long)]
    pub seed_tokens: Option<String>,
    /// Streaming budget: latency and cache schedule (as `generate --mode streaming`).
    #[command(flatten)]
    pub budget: BudgetArgs,
    /// Port on 127.0.0.1 to serve the page and the event stream on; 0 picks a free one.
    /// The URL is printed on stdout.
    #[arg(long, default_value_t = 0)]
    pub port: u16,
    /// Push leader frames as fast as the engine goes instead of one per 1/30 s (for tests).
    #[arg(long, alias = "fast")]
    pub no_pace: bool,
    /// Stream only the first N leader frames of the clip.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub frames: Option<u64>,
    /// Seconds the server stays up after the last frame for pages to catch up; it exits
    /// sooner once every open page has received the end of the stream.
    #[arg(long, default_value_t = 10.0)]
    pub linger: f64,
    /// Start the clock only when the first page has opened the event stream.
    #[arg(long)]
    pub wait: bool,
    /// Threads the large matrix products are split over (the output does not
    /// depend on it). Default: every core, at most 8.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub threads: Option<u32>,
}

/// The first event: what the page needs before any frame.
#[derive(Serialize)]
struct Hello<'a> {
    title: String,
    fps: f64,
    joints: usize,
    parents: &'a [i8],
    /// Leader frames that will be streamed.
    frames: usize,
    hop: usize,
    /// The session's latency (frames between a leader frame and the
    /// follower frame of the same index).
    latency_frames: u32,
    budget: Budget,
    paced: bool,
    model: String,
    leader: String,
    music: String,
    seed: &'a str,
    session_bytes: usize,
}

#[derive(Serialize)]
struct Budget {
    preset: String,
    lookahead: u32,
    enc_future: u32,
    dec_future: u32,
    shift: u32,
    music_lookahead: u32,
}

/// One follower frame in a `frame` event.
#[derive(Serialize)]
struct FollowerOut<'a> {
    index: u64,
    pos: &'a [f32],
}

/// One tick: a `frame` event.
#[derive(Serialize)]
struct Tick<'a> {
    /// Leader frame index pushed at this tick.
    i: usize,
    /// Milliseconds since the clock started, when the tick began.
    t_ms: f64,
    leader: &'a [f32],
    /// Follower frames that became ready at this tick, in order.
    follower: Vec<FollowerOut<'a>>,
    /// Steps the session ran at this tick (0 or 1; a model step).
    stepped: usize,
    /// Steps so far.
    steps: usize,
    /// Wall time of the push and the pulls, ms.
    tick_ms: f64,
    /// Wall time of the latest tick that ran a step, ms (None before the first).
    step_ms: Option<f64>,
    /// How far the follower trails now: `i` minus the newest follower
    /// index out so far (None before the first), and the measured wall time
    /// from the tick that pushed that frame's leader frame to the end of
    /// this tick, ms.
    latency_frames: Option<usize>,
    latency_ms: Option<f64>,
    /// Follower frames out so far.
    follower_frames: usize,
    /// The tick started later than its slot (1/30 s each) by more than one frame.
    late: bool,
    /// The session refused this leader frame (backlog: no step can run).
    refused: bool,
}

/// One tick after the leader's end: a follower frame the drain gave.
#[derive(Serialize)]
struct Drain<'a> {
    /// Drain tick, from 0.
    d: usize,
    t_ms: f64,
    follower: Vec<FollowerOut<'a>>,
    stepped: usize,
    steps: usize,
    tick_ms: f64,
    follower_frames: usize,
}

/// The last event.
#[derive(Serialize)]
struct End {
    /// Leader frames streamed, and those the session accepted.
    frames: usize,
    frames_accepted: usize,
    follower_frames: usize,
    /// Follower frames of accepted leader frames that did not come out even
    /// after the drain (R too gives none for the leader's last frames: they
    /// are look-ahead only).
    follower_frames_pending: usize,
    /// Follower frames given by the drain, after the leader's last frame.
    drained_frames: usize,
    steps: usize,
    latency_frames: u32,
    /// The first leader frame the session refused (every later one was refused too).
    refused_from: Option<usize>,
    step_ms: Stats,
    tick_ms: Stats,
    late_ticks: usize,
    seconds: f64,
    paced: bool,
}

#[derive(Serialize, Default, Clone, Copy)]
struct Stats {
    count: usize,
    mean: f64,
    median: f64,
    max: f64,
}

fn stats(v: &[f64]) -> Stats {
    if v.is_empty() {
        return Stats::default();
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    Stats { count: v.len(), mean: v.iter().sum::<f64>() / v.len() as f64, median: s[s.len() / 2], max: s[s.len() - 1] }
}

/// Milliseconds, to the microsecond.
fn ms(d: Duration) -> f64 {
    (d.as_secs_f64() * 1e6).round() / 1000.0
}

fn preset_name(args: &BudgetArgs) -> String {
    let base = format!("{:?}", args.preset).to_lowercase();
    let overridden = args.lookahead.is_some() || args.enc_future.is_some() || args.dec_future.is_some() || args.shift.is_some() || args.music_lookahead.is_some();
    if overridden {
        format!("{base} + overrides")
    } else {
        base
    }
}

fn file_name(p: &Path) -> String {
    p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| p.display().to_string())
}

pub fn run(args: Args) -> Result<()> {
    if !(args.linger.is_finite() && (0.0..=MAX_LINGER_S).contains(&args.linger)) {
        bail!("--linger {}: expected seconds between 0 and {MAX_LINGER_S}", args.linger);
    }
    let demo = args.leader.is_none();
    let model_path = match &args.model {
        Some(m) => m.clone(),
        None => inputs::require_asset(inputs::DEMO_MODEL, "model")?,
    };
    let (leader_path, music_path) = match (&args.leader, &args.music) {
        (Some(l), Some(m)) => (l.clone(), m.clone()),
        _ => (
            inputs::require_asset(inputs::DEMO_LEADER, "leader clip")?,
            inputs::require_asset(inputs::DEMO_MUSIC, "music features")?,
        ),
    };
    let threads = args.threads.map_or_else(crate::workers::default_threads, |n| n as usize);
    crate::workers::set_threads(threads).with_context(|| format!("starting {threads} threads"))?;

    eprintln!("[1/3] model {}, {threads} thread(s)", model_path.display());
    let file = ModelFile::open(&model_path)?;
    super::print_kernels();
    let duo = file.duo()?;
    let model = Model::from_duo(&duo)
        .map_err(|e| anyhow::anyhow!("{}: {}", model_path.display(), crate::engine_errors::describe_bind(&e)))?;
    let cfg = model.cfg;
    let hop = cfg.hop();
    let sc: SessionConfig = args.budget.config(&cfg)?;

    eprintln!("[2/3] inputs: leader {}, music {}", leader_path.display(), music_path.display());
    let leader = inputs::load_leader(&leader_path)?;
    let music = inputs::load_music(&music_path, cfg.gpt.music.n_in as usize, &model_path)?;
    let n = args.frames.map_or(leader.frames, |f| (f.min(leader.frames as u64)) as usize);
    if music.frames < n {
        bail!(
            "{}: the music has {} frames ({:.1} s at 30 fps) but {n} leader frames of {} are to be streamed; the music must cover the whole dance \
             (or pass --frames {})",
            music_path.display(),
            music.frames,
            music.frames as f64 / FPS,
            leader_path.display(),
            music.frames
        );
    }
    let latency = sc.latency_frames(hop as u32);
    if n <= latency as usize {
        bail!(
            "{}: {n} leader frames to stream, but the session's latency is {latency} frames: no follower frame would come out. \
             Stream a longer clip or choose a shorter budget (e.g. --preset minimum, or --lookahead 4 --enc-future 2 --dec-future 2)",
            leader_path.display()
        );
    }
    let (seed, seed_text) =
        inputs::choose_seed(args.seed_tokens.as_deref(), args.follower_start.as_deref(), demo, &leader, &cfg, &model_path)?;
    let seed = match &seed {
        SeedChoice::Tokens(t) => seed_tokens(&model, Seed::Tokens(*t), &leader.pos3d)?,
        SeedChoice::Frames(f) => seed_tokens(&model, Seed::FollowerFrames(f), &leader.pos3d)?,
    };
    // The whole track, known ahead (also past the frames streamed).
    let track = &music.features[..music.frames * music.cols];
    let bytes = model.session_bytes(&sc).map_err(|e| anyhow::anyhow!("the streaming session cannot be set up: {}", describe(&e)))?;
    let mut arena = vec![0u8; bytes];
    let mut s = Session::new(&model, &mut arena, &sc, seed)
        .map_err(|e| anyhow::anyhow!("the streaming session cannot start: {}", describe(&e)))?;
    s.set_music_track(track).map_err(|e| anyhow::anyhow!("{}: the music cannot be used: {}", music_path.display(), describe(&e)))?;
    eprintln!(
        "      leader {} frames ({}), streaming {n}; music {} frames; seed: {seed_text}; latency {latency} frames ({:.2} s), session {:.2} MiB",
        leader.frames,
        leader.source,
        music.frames,
        latency as f64 / FPS,
        bytes as f64 / (1024.0 * 1024.0)
    );

    let server = LiveServer::bind(args.port)?;
    let url = server.url();
    // Not println!: a closed stdout is an error here, not a panic.
    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "{url}").and_then(|()| stdout.flush()).context("writing the URL to stdout")?;
    drop(stdout);
    let hello = Hello {
        title: format!("duolando live: {} + {}", file_name(&leader_path), file_name(&music_path)),
        fps: FPS,
        joints: JOINTS,
        parents: &SMPLX_PARENTS,
        frames: n,
        hop,
        latency_frames: latency,
        budget: Budget {
            preset: preset_name(&args.budget),
            lookahead: sc.lookahead,
            enc_future: sc.enc_future,
            dec_future: sc.dec_future,
            shift: sc.shift,
            music_lookahead: sc.music_lookahead,
        },
        paced: !args.no_pace,
        model: model_path.display().to_string(),
        leader: leader_path.display().to_string(),
        music: music_path.display().to_string(),
        seed: &seed_text,
        session_bytes: bytes,
    };
    server.publish("hello", &serde_json::to_string(&hello)?);
    eprintln!("[3/3] serving the live viewer at {url} (127.0.0.1 only); open it in a browser");
    if args.wait {
        eprintln!("      waiting for a page to open the stream (--wait)");
        server.wait_for_stream(None);
    }

    let tick = Duration::from_secs_f64(1.0 / FPS);
    let start = Instant::now();
    let mut tick_at: Vec<Instant> = Vec::with_capacity(n);
    let mut frame = FollowerFrame::default();
    let mut out: Vec<(u64, [f32; POSE_DIM])> = Vec::new();
    let (mut step_times, mut tick_times) = (Vec::new(), Vec::with_capacity(n));
    let (mut last_step_ms, mut newest, mut late_ticks, mut pulled) = (None, None, 0usize, 0usize);
    let mut refused_from: Option<usize> = None;
    for i in 0..n {
        let slot = start + tick * i as u32;
        let mut late = false;
        if !args.no_pace {
            let now = Instant::now();
            if now < slot {
                std::thread::sleep(slot - now);
            } else if now - slot > tick {
                late = true;
                late_ticks += 1;
            }
        }
        let t0 = Instant::now();
        tick_at.push(t0);
        let steps_before = s.steps();
        let refused = match s.push_leader_frame(&leader.pos3d[i * POSE_DIM..(i + 1) * POSE_DIM]) {
            Ok(()) => false,
            // No step can run any more (the steps wait for music past the end
            // of the track): the session keeps refusing, unchanged; the
            // engine keeps ticking and the page keeps showing the leader.
            Err(e @ Error::Backlog { .. }) => {
                if refused_from.is_none() {
                    refused_from = Some(i);
                    eprintln!(
                        "      note: from leader frame {i} on, the session refuses leader frames ({}): its steps need music up to {} frames \
                         ahead (--music-lookahead {}) and the track has {} frames",
                        describe(&e),
                        sc.music_lookahead as usize * hop,
                        sc.music_lookahead,
                        music.frames
                    );
                }
                true
            }
            Err(e) => bail!("{}: leader frame {i} was refused: {}", leader_path.display(), describe(&e)),
        };
        out.clear();
        loop {
            match s.pull_follower_frame(&mut frame) {
                Ok(true) => out.push((frame.index, frame.positions)),
                Ok(false) => break,
                Err(e) => bail!("pulling a follower frame after leader frame {i}: {}", describe(&e)),
            }
        }
        let done = Instant::now();
        let tick_ms = ms(done - t0);
        tick_times.push(tick_ms);
        let stepped = s.steps() - steps_before;
        if stepped > 0 {
            step_times.push(tick_ms);
            last_step_ms = Some(tick_ms);
        }
        pulled += out.len();
        if let Some((j, _)) = out.last() {
            newest = Some(*j as usize);
        }
        let ev = Tick {
            i,
            t_ms: ms(t0 - start),
            leader: &leader.pos3d[i * POSE_DIM..(i + 1) * POSE_DIM],
            follower: out.iter().map(|(index, pos)| FollowerOut { index: *index, pos }).collect(),
            stepped,
            steps: s.steps(),
            tick_ms,
            step_ms: last_step_ms,
            latency_frames: newest.map(|j| i - j),
            latency_ms: newest.map(|j| ms(done - tick_at[j])),
            follower_frames: pulled,
            late,
            refused,
        };
        server.publish("frame", &serde_json::to_string(&ev)?);
    }
    // The end of the leader: the session is told (Session::finish) and gives
    // what its look-ahead held back (R's frame count, docs/STREAMING.md §2
    // "Drain"), one follower frame per tick as a player would show them,
    // each in a `drain` event.
    s.finish().map_err(|e| anyhow::anyhow!("ending the leader (drain): {}", describe(&e)))?;
    let mut drained = 0usize;
    for d in 0.. {
        let slot = start + tick * (n + d) as u32;
        if !args.no_pace {
            let now = Instant::now();
            if now < slot {
                std::thread::sleep(slot - now);
            }
        }
        let t0 = Instant::now();
        let steps_before = s.steps();
        let got = match s.pull_follower_frame(&mut frame) {
            Ok(got) => got,
            Err(e) => bail!("pulling a drained follower frame: {}", describe(&e)),
        };
        if !got {
            break;
        }
        let tick_ms = ms(Instant::now() - t0);
        drained += 1;
        pulled += 1;
        let ev = Drain {
            d,
            t_ms: ms(t0 - start),
            follower: vec![FollowerOut { index: frame.index, pos: &frame.positions }],
            stepped: s.steps() - steps_before,
            steps: s.steps(),
            tick_ms,
            follower_frames: pulled,
        };
        server.publish("drain", &serde_json::to_string(&ev)?);
    }
    let seconds = start.elapsed().as_secs_f64();
    let accepted = refused_from.unwrap_or(n);
    let end = End {
        frames: n,
        follower_frames: pulled,
        frames_accepted: accepted,
        follower_frames_pending: accepted.saturating_sub(pulled),
        drained_frames: drained,
        steps: s.steps(),
        latency_frames: latency,
        refused_from,
        step_ms: stats(&step_times),
        tick_ms: stats(&tick_times),
        late_ticks,
        seconds,
        paced: !args.no_pace,
    };
    server.publish("end", &serde_json::to_string(&end)?);
    eprintln!(
        "clip ended after {seconds:.1} s: {accepted} of {n} leader frames in, {pulled} follower frames out ({drained} of them drained after the leader's end, {} not given), \
         {} steps of {:.2} ms on average (max {:.2} ms), {late_ticks} late ticks",
        end.follower_frames_pending,
        end.steps,
        end.step_ms.mean,
        end.step_ms.max
    );
    let linger = Duration::from_secs_f64(args.linger);
    let f = server.finish(linger);
    if f.timed_out {
        eprintln!("stopped after --linger {} s ({} page(s) received the whole stream)", args.linger, f.delivered);
    } else {
        eprintln!("every open page received the whole stream ({}); stopping", f.delivered);
    }
    Ok(())
}
