//! Soak test: ONE streaming session on tests/fixtures/tiny2/model.duo, never
//! reset, fed synthetic leader motion (a recorded pose swaying and walking a
//! bounded circle) and the fixture music looped (pushed live, ahead of the
//! leader), pulling every ready follower frame. Checks, for every frame:
//! finite output and consecutive indices; and that the resident set size
//! (VmRSS, /proc/self/status) does not grow after warm-up. Prints figures;
//! exits 1 on any violation.
//!
//! `cargo run --release -p duolando-gen --bin soak -- --steps 1000000
//! [--max-seconds S] [--greedy] [--warmup-frames N] [--rss-tolerance-kb K]`
//! (`--steps` counts session steps = follower tokens; 4 leader frames each.)
#![forbid(unsafe_code)]

use std::time::{Duration, Instant};

use duolando_core::duolando::session::{FollowerFrame, Sampling, Session, SessionConfig};
use duolando_gen::fixture::{tiny2_clip, tiny2_model};
use duolando_gen::floats::synthetic_leader;
use duolando_gen::session::{frame_finite, tick};

fn rss_kb() -> (u64, u64) {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| {
        s.lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

struct Args {
    steps: u64,
    max_seconds: u64,
    greedy: bool,
    warmup_frames: u64,
    rss_tolerance_kb: u64,
}

fn args() -> Args {
    let mut a = Args {
        steps: 1_000_000,
        max_seconds: u64::MAX,
        greedy: false,
        warmup_frames: 20_000,
        rss_tolerance_kb: 256,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut num = || {
            it.next()
                .and_then(|v| v.parse::<u64>().ok())
                .unwrap_or_else(|| panic!("{k} needs a number"))
        };
        match k.as_str() {
            "--steps" => a.steps = num(),
            "--max-seconds" => a.max_seconds = num(),
            "--warmup-frames" => a.warmup_frames = num(),
            "--rss-tolerance-kb" => a.rss_tolerance_kb = num(),
            "--greedy" => a.greedy = true,
            other => panic!("unknown argument {other}"),
        }
    }
    a
}

fn main() {
    let a = args();
    let model = tiny2_model();
    let clip = tiny2_clip();
    let mut cfg = SessionConfig::reference(&model.cfg);
    if !a.greedy {
        cfg.sampling = Sampling::TopK {
            k: 8,
            rng_seed: 0x5eed,
        };
    }
    let bytes = model.session_bytes(&cfg).expect("session_bytes");
    let mut arena = vec![0u8; bytes];
    let mut s = Session::new(model, &mut arena, &cfg, clip.seed).expect("session");
    println!(
        "soak: tiny2, {cfg:?}\n  arena {bytes} B, latency {} frames, target {} steps, limit {} s",
        s.latency_frames(),
        a.steps,
        if a.max_seconds == u64::MAX {
            "none".to_string()
        } else {
            a.max_seconds.to_string()
        }
    );
    let base = clip.leader_frame(0).to_vec();
    let mut leader = vec![0f32; base.len()];
    let mut out = FollowerFrame::default();
    let (mut music_t, mut frames_in) = (0usize, 0u64);
    let (mut next_index, mut non_finite, mut out_of_order) = (0u64, 0u64, 0u64);
    // log2 histogram of tick times in ns.
    let mut hist = [0u64; 40];
    let mut worst = Duration::ZERO;
    let start = Instant::now();
    let (mut rss_warm, mut rss_max_after) = (0u64, 0u64);
    let mut last_report = Instant::now();
    let limit = Duration::from_secs(a.max_seconds);
    let mut stuck = false;
    while (s.steps() as u64) < a.steps && start.elapsed() < limit {
        synthetic_leader(&base, frames_in, &mut leader);
        let t0 = Instant::now();
        let mut sink = |f: &FollowerFrame| {
            if !frame_finite(f) {
                non_finite += 1;
            }
            if f.index != next_index {
                out_of_order += 1;
            }
            next_index = f.index + 1;
        };
        match tick(
            &mut s,
            None,
            clip,
            &leader,
            &mut music_t,
            frames_in as usize,
            &mut out,
            &mut sink,
        ) {
            Ok(true) => {}
            Ok(false) => {
                stuck = true;
                break;
            }
            Err(e) => {
                eprintln!("soak: error at frame {frames_in}: {e:?}");
                std::process::exit(1);
            }
        }
        let dt = t0.elapsed();
        worst = worst.max(dt);
        hist[(64 - (dt.as_nanos() as u64).max(1).leading_zeros() as usize).min(39)] += 1;
        frames_in += 1;
        if frames_in == a.warmup_frames {
            rss_warm = rss_kb().0;
        }
        if frames_in > a.warmup_frames && frames_in % 4096 == 0 {
            rss_max_after = rss_max_after.max(rss_kb().0);
        }
        if last_report.elapsed() > Duration::from_secs(60) {
            last_report = Instant::now();
            let el = start.elapsed().as_secs_f64();
            println!(
                "  {:>6.0} s: {} steps, {} frames in, {} out, {:.0} frames/s, RSS {} kB (warm {rss_warm}, max after {rss_max_after})",
                el,
                s.steps(),
                frames_in,
                next_index,
                frames_in as f64 / el,
                rss_kb().0
            );
        }
    }
    let el = start.elapsed().as_secs_f64();
    let (rss_end, hwm) = rss_kb();
    rss_max_after = rss_max_after.max(rss_end);
    let pct = |q: f64| {
        let total: u64 = hist.iter().sum();
        let mut acc = 0;
        for (i, &h) in hist.iter().enumerate() {
            acc += h;
            if acc as f64 >= q * total as f64 {
                return 1u64 << i;
            }
        }
        0
    };
    println!("soak result:");
    println!("  steps {} (follower tokens), leader frames in {frames_in}, follower frames out {next_index}, music frames in {music_t}", s.steps());
    println!("  wall {el:.1} s, {:.0} leader frames/s, {:.1} us per frame; tick p50 <= {} ns, p99 <= {} ns, max {} us", frames_in as f64 / el, el * 1e6 / frames_in.max(1) as f64, pct(0.5), pct(0.99), worst.as_micros());
    println!(
        "  non-finite frames {non_finite}, out-of-order indices {out_of_order}, stuck {stuck}"
    );
    let growth = rss_max_after.saturating_sub(rss_warm);
    println!("  RSS after warm-up ({} frames) {rss_warm} kB, max after {rss_max_after} kB, end {rss_end} kB, growth {growth} kB (tolerance {} kB), peak (VmHWM) {hwm} kB", a.warmup_frames, a.rss_tolerance_kb);
    let ok = non_finite == 0
        && out_of_order == 0
        && !stuck
        && (frames_in <= a.warmup_frames || growth <= a.rss_tolerance_kb);
    println!("  {}", if ok { "PASS" } else { "FAIL" });
    if !ok {
        std::process::exit(1);
    }
}
