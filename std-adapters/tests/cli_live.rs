//! `duolando live` end to end through the binary: it prints its URL, serves
//! the live page and an event stream on 127.0.0.1, and the stream carries,
//! in order, every leader frame and exactly the follower frames (positions,
//! readiness, latency) of the same session driven in this process by
//! `duolando::streaming::run_streaming`. Plain `TcpStream` HTTP, no client
//! library. Bad inputs and a port in use fail with named errors.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use duolando::cli::generate::seed_tokens;
use duolando::model_file::ModelFile;
use duolando::npy::{read_f32_2d, write_f32};
use duolando::streaming::run_streaming_with;
use duolando_core::duolando::exact::Seed;
use duolando_core::duolando::model::Model;
use duolando_core::duolando::session::SessionConfig;
use serde_json::Value;

const ROW: usize = 165;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn roll() -> PathBuf {
    fixtures().join("rollout_tiny_long")
}

fn tiny() -> PathBuf {
    fixtures().join("tiny/model.duo")
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// The tiny model on the 600-frame rollout clip, unpaced.
fn tiny_args(extra: &[&str]) -> Vec<String> {
    let (m, r) = (tiny(), roll());
    let mut a: Vec<String> = [
        "--model",
        p(&m),
        "--leader",
        p(&r.join("leader_pos3d.npy")),
        "--music",
        p(&r.join("music.npy")),
        "--follower-start",
        p(&r.join("follower_start.npy")),
        "--no-pace",
        "--port",
        "0",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    a.extend(extra.iter().map(|s| s.to_string()));
    a
}

/// A running `duolando live`, killed if the test fails before it exits.
struct Live {
    child: Child,
    port: u16,
    stderr: mpsc::Receiver<String>,
}

impl Drop for Live {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Live {
    /// Starts `duolando live ARGS` and reads the URL it prints on stdout.
    fn start(args: &[String]) -> Live {
        let mut child = Command::new(env!("CARGO_BIN_EXE_duolando"))
            .arg("live")
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let (tx, rx) = mpsc::channel();
        let out = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines() {
                let Ok(line) = line else { break };
                let _ = tx.send(line);
            }
        });
        let (etx, erx) = mpsc::channel();
        let err = child.stderr.take().unwrap();
        std::thread::spawn(move || {
            let mut s = String::new();
            let _ = BufReader::new(err).read_to_string(&mut s);
            let _ = etx.send(s);
        });
        let line = match rx.recv_timeout(Duration::from_secs(120)) {
            Ok(l) => l,
            Err(_) => {
                let _ = child.kill();
                let _ = child.wait();
                panic!(
                    "no URL on stdout; stderr: {}",
                    erx.recv_timeout(Duration::from_secs(5)).unwrap_or_default()
                );
            }
        };
        let rest = line
            .strip_prefix("http://127.0.0.1:")
            .unwrap_or_else(|| panic!("stdout line is not a 127.0.0.1 URL: {line:?}"));
        let port: u16 = rest
            .strip_suffix('/')
            .and_then(|p| p.parse().ok())
            .unwrap_or_else(|| panic!("no port in {line:?}"));
        assert_ne!(port, 0);
        Live {
            child,
            port,
            stderr: erx,
        }
    }

    /// Waits for the process to exit by itself; returns (success, stderr).
    fn wait_exit(&mut self, within: Duration) -> (bool, String) {
        let t = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                let err = self
                    .stderr
                    .recv_timeout(Duration::from_secs(10))
                    .unwrap_or_default();
                return (status.success(), err);
            }
            assert!(
                t.elapsed() < within,
                "duolando live still running after {within:?}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// One HTTP/1.1 request over a plain TcpStream; the whole response (the
/// server closes every connection). Returns (status code, head, body).
fn http(port: u16, request_line: &str, headers: &[&str]) -> (u16, String, Vec<u8>) {
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    let mut req = format!("{request_line}\r\n");
    for h in headers {
        req.push_str(h);
        req.push_str("\r\n");
    }
    req.push_str("\r\n");
    s.write_all(req.as_bytes()).unwrap();
    let mut buf = Vec::new();
    s.read_to_end(&mut buf).unwrap();
    let split = buf
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("no end of response head");
    let head = String::from_utf8(buf[..split].to_vec()).unwrap();
    let body = buf[split + 4..].to_vec();
    let code = head
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("bad status line: {head}"));
    (code, head, body)
}

fn get(port: u16, path: &str, extra: &[&str]) -> (u16, String, Vec<u8>) {
    let host = format!("Host: 127.0.0.1:{port}");
    let mut h = vec![host.as_str()];
    h.extend_from_slice(extra);
    http(port, &format!("GET {path} HTTP/1.1"), &h)
}

fn header<'a>(head: &'a str, name: &str) -> Option<&'a str> {
    head.lines().skip(1).find_map(|l| {
        let (n, v) = l.split_once(':')?;
        n.eq_ignore_ascii_case(name).then(|| v.trim())
    })
}

/// One server-sent event.
#[derive(Debug)]
struct Event {
    id: usize,
    kind: String,
    data: Value,
}

/// Parses a whole `text/event-stream` body (comments and `retry` skipped).
fn parse_sse(body: &[u8]) -> Vec<Event> {
    let text = std::str::from_utf8(body).unwrap();
    let mut out = Vec::new();
    for block in text.split("\n\n").filter(|b| !b.trim().is_empty()) {
        let (mut id, mut kind, mut data) = (None, None, None);
        for line in block.lines() {
            if let Some(v) = line.strip_prefix("id: ") {
                id = Some(v.parse().unwrap());
            } else if let Some(v) = line.strip_prefix("event: ") {
                kind = Some(v.to_string());
            } else if let Some(v) = line.strip_prefix("data: ") {
                assert!(data.is_none(), "one data line per event: {block}");
                data =
                    Some(serde_json::from_str(v).unwrap_or_else(|e| panic!("bad JSON ({e}): {v}")));
            } else {
                assert!(
                    line.starts_with(':') || line.starts_with("retry: "),
                    "unexpected line {line:?}"
                );
            }
        }
        if let (Some(id), Some(kind), Some(data)) = (id, kind, data) {
            out.push(Event { id, kind, data });
        }
    }
    out
}

/// A JSON array of 165 finite numbers, as f32.
fn pose(v: &Value, what: &str) -> Vec<f32> {
    let a = v
        .as_array()
        .unwrap_or_else(|| panic!("{what} is not an array: {v}"));
    assert_eq!(a.len(), ROW, "{what}: {} values, expected {ROW}", a.len());
    a.iter()
        .map(|x| {
            let f = x
                .as_f64()
                .unwrap_or_else(|| panic!("{what}: {x} is not a number"));
            assert!(f.is_finite(), "{what}: {f}");
            f as f32
        })
        .collect()
}

fn uint(v: &Value, key: &str) -> usize {
    v[key]
        .as_u64()
        .unwrap_or_else(|| panic!("{key} missing or not an integer in {v}")) as usize
}

/// The same session driven in this process: (run, latency frames).
fn reference_run(
    cfg_of: impl Fn(&duolando_core::duolando::config::ModelConfig) -> SessionConfig,
) -> duolando::streaming::StreamRun {
    let file = ModelFile::open(tiny()).unwrap();
    let duo = file.duo().unwrap();
    let model = Model::from_duo(&duo).unwrap();
    let leader = read_f32_2d(&roll().join("leader_pos3d.npy"), Some(ROW), "leader").unwrap();
    let music = read_f32_2d(&roll().join("music.npy"), Some(54), "music").unwrap();
    let start = read_f32_2d(&roll().join("follower_start.npy"), Some(ROW), "start").unwrap();
    let seed = seed_tokens(&model, Seed::FollowerFrames(&start.data), &leader.data).unwrap();
    let sc = cfg_of(&model.cfg);
    run_streaming_with(
        &model,
        &leader.data,
        &music.data,
        &sc,
        seed,
        None,
        true,
        &mut |_, _| {},
    )
    .unwrap()
}

#[test]
fn live_streams_the_sessions_frames_in_order() {
    let mut live = Live::start(&tiny_args(&[
        "--lookahead",
        "4",
        "--enc-future",
        "2",
        "--dec-future",
        "2",
        "--linger",
        "120",
    ]));
    let port = live.port;

    // The page.
    let (code, head, body) = get(port, "/", &[]);
    assert_eq!(code, 200, "{head}");
    assert_eq!(
        header(&head, "content-type"),
        Some("text/html; charset=utf-8")
    );
    assert_eq!(
        header(&head, "content-length").and_then(|v| v.parse().ok()),
        Some(body.len())
    );
    let page = String::from_utf8(body).unwrap();
    for needle in [
        "<canvas id=\"view\"",
        "new EventSource(\"events\")",
        "id=\"live-latency-frames\"",
        "id=\"live-step-ms\"",
        "--follower: #ff7a1a",
    ] {
        assert!(page.contains(needle), "the page lacks {needle}");
    }
    assert!(!page.contains("{{"), "unfilled placeholder");

    // The whole event stream (the server closes it after the end event).
    let (code, head, body) = get(port, "/events", &[]);
    assert_eq!(code, 200, "{head}");
    assert_eq!(header(&head, "content-type"), Some("text/event-stream"));
    let events = parse_sse(&body);
    for (k, e) in events.iter().enumerate() {
        assert_eq!(e.id, k, "event ids in order");
    }
    let run = reference_run(|c| SessionConfig::with(c, 4, 2, 2, SessionConfig::reference(c).shift));
    let leader = read_f32_2d(&roll().join("leader_pos3d.npy"), Some(ROW), "leader").unwrap();
    let t = leader.rows;
    let drained = run
        .frame_ready
        .iter()
        .filter(|&&f| f == run.frames_in)
        .count();
    assert!(drained > 0, "the drain gives frames");
    assert_eq!(
        events.len(),
        t + 2 + drained,
        "hello, one frame event per leader frame, one drain event per drained frame, end"
    );

    let hello = &events[0];
    assert_eq!(hello.kind, "hello");
    assert_eq!(uint(&hello.data, "frames"), t);
    assert_eq!(
        uint(&hello.data, "latency_frames"),
        run.latency_frames as usize
    );
    assert_eq!(run.latency_frames, 31);
    assert_eq!(uint(&hello.data, "joints"), 55);
    assert_eq!(hello.data["parents"].as_array().map(Vec::len), Some(55));
    assert_eq!(hello.data["paced"], Value::Bool(false));

    let mut follower: Vec<(usize, Vec<f32>)> = Vec::new(); // (leader frame it came with, pose)
    let mut steps = 0;
    let mut refused = Vec::new();
    for (i, e) in events[1..=t].iter().enumerate() {
        assert_eq!(e.kind, "frame");
        let d = &e.data;
        assert_eq!(uint(d, "i"), i, "frames in order");
        if d["refused"].as_bool().unwrap() {
            refused.push(i);
        }
        assert_eq!(
            pose(&d["leader"], "leader"),
            leader.data[i * ROW..(i + 1) * ROW],
            "leader frame {i} as read"
        );
        for f in d["follower"].as_array().unwrap() {
            assert_eq!(
                uint(f, "index"),
                follower.len(),
                "follower frames in order, none skipped"
            );
            follower.push((i, pose(&f["pos"], "follower")));
        }
        assert_eq!(uint(d, "follower_frames"), follower.len());
        steps += uint(d, "stepped");
        assert_eq!(uint(d, "steps"), steps);
        match follower.last() {
            Some(_) => {
                // The newest follower frame's latency, in frames and measured ms.
                assert_eq!(
                    uint(d, "latency_frames"),
                    i - (follower.len() - 1),
                    "latency at leader frame {i}"
                );
                assert!(
                    d["latency_ms"]
                        .as_f64()
                        .is_some_and(|v| v.is_finite() && v >= 0.0),
                    "{d}"
                );
            }
            None => assert!(d["latency_frames"].is_null() && d["latency_ms"].is_null()),
        }
        assert!(d["tick_ms"]
            .as_f64()
            .is_some_and(|v| v.is_finite() && v >= 0.0));
        if steps > 0 {
            assert!(
                d["step_ms"]
                    .as_f64()
                    .is_some_and(|v| v.is_finite() && v >= 0.0),
                "{d}"
            );
        }
    }

    // After the leader: the drained frames, one per event.
    let ticked = follower.len();
    for (d, e) in events[t + 1..t + 1 + drained].iter().enumerate() {
        assert_eq!(e.kind, "drain");
        assert_eq!(uint(&e.data, "d"), d);
        let fs = e.data["follower"].as_array().unwrap();
        assert_eq!(fs.len(), 1, "one drained frame per tick");
        assert_eq!(
            uint(&fs[0], "index"),
            follower.len(),
            "drained frames in order"
        );
        follower.push((run.frames_in, pose(&fs[0]["pos"], "follower")));
        assert_eq!(uint(&e.data, "follower_frames"), follower.len());
    }

    // The session took the leader frames run_streaming could push (it stops
    // at the first backlog: music past the end of the track), then refused
    // every later one.
    assert_eq!(
        refused,
        (run.frames_in..t).collect::<Vec<_>>(),
        "refused leader frames"
    );
    // Exactly the session's frames, at the same leader frames.
    assert_eq!(follower.len(), run.frames_out(), "follower frame count");
    assert!(
        follower.len() > t / 2,
        "{} follower frames for {t} leader frames",
        follower.len()
    );
    assert_eq!(
        uint(&events[t + drained].data, "steps"),
        run.steps(),
        "steps, the drain's included"
    );
    assert!(steps <= run.steps());
    let mut worst = 0.0f32;
    for (j, (at, pos)) in follower.iter().enumerate() {
        assert_eq!(
            *at, run.frame_ready[j],
            "follower frame {j} came with leader frame {at}, the session had it after {}",
            run.frame_ready[j]
        );
        for (a, b) in pos.iter().zip(&run.pos[j * ROW..(j + 1) * ROW]) {
            worst = worst.max((a - b).abs());
        }
    }
    assert_eq!(
        worst, 0.0,
        "follower positions differ from the session's by up to {worst}"
    );
    // The follower trails by at most the session's latency, and by all of it
    // at the last frame of each token (frames come out a token, 4 frames, at a time).
    let lat: Vec<usize> = follower[..ticked]
        .iter()
        .enumerate()
        .map(|(j, (at, _))| at - j)
        .collect();
    assert!(
        lat.iter().all(|&l| l <= 31) && lat.iter().max() == Some(&31),
        "latencies: {:?}",
        &lat[..lat.len().min(40)]
    );

    let end = &events[t + 1 + drained];
    assert_eq!(end.kind, "end");
    assert_eq!(uint(&end.data, "frames"), t);
    assert_eq!(uint(&end.data, "follower_frames"), follower.len());
    assert_eq!(uint(&end.data, "frames_accepted"), run.frames_in);
    assert_eq!(uint(&end.data, "drained_frames"), drained);
    assert_eq!(
        uint(&end.data, "follower_frames_pending"),
        run.frames_in.saturating_sub(follower.len())
    );
    assert_eq!(uint(&end.data, "steps"), run.steps());
    assert_eq!(
        uint(&end.data["step_ms"], "count"),
        steps,
        "step times of the ticks that stepped"
    );

    // Its one stream got everything: it exits by itself, long before --linger 120.
    let (ok, err) = live.wait_exit(Duration::from_secs(60));
    assert!(ok, "{err}");
    assert!(
        err.contains("every open page received the whole stream"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn live_serves_only_its_routes_and_resumes_after_an_event_id() {
    let mut live = Live::start(&tiny_args(&[
        "--preset", "minimum", "--frames", "40", "--linger", "120",
    ]));
    let port = live.port;
    assert_eq!(get(port, "/nope", &[]).0, 404);
    assert_eq!(get(port, "/index.html?x=1", &[]).0, 200);
    let (code, head, _) = http(port, "GET / HTTP/1.1", &["Host: evil.example:80"]);
    assert_eq!(code, 403, "a foreign Host is refused: {head}");
    assert_eq!(http(port, "GET / HTTP/1.1", &[]).0, 403, "no Host");
    let (code, head, _) = http(
        port,
        "POST /events HTTP/1.1",
        &[&format!("Host: localhost:{port}")],
    );
    assert_eq!(code, 405);
    assert_eq!(header(&head, "allow"), Some("GET, HEAD"));
    assert_eq!(http(port, "NONSENSE", &[]).0, 400);
    let (code, _, body) = http(
        port,
        "HEAD / HTTP/1.1",
        &[&format!("Host: 127.0.0.1:{port}")],
    );
    assert_eq!((code, body.len()), (200, 0));

    // A page reconnecting after event 10 gets 11.. only (40 frames: ids 0..=41).
    let (code, _, body) = get(port, "/events", &["Last-Event-ID: 10"]);
    assert_eq!(code, 200);
    let ev = parse_sse(&body);
    assert_eq!(ev.first().map(|e| e.id), Some(11));
    assert_eq!(
        ev.iter().map(|e| e.id).collect::<Vec<_>>(),
        (11..=41).collect::<Vec<_>>()
    );
    assert_eq!(uint(&ev[0].data, "i"), 10);
    assert_eq!(ev.last().map(|e| e.kind.as_str()), Some("end"));
    // Latency 0: the follower frame of each leader frame comes with it.
    let e = &ev[ev.len() - 2].data;
    assert_eq!(uint(e, "latency_frames"), 0);
    let (ok, err) = live.wait_exit(Duration::from_secs(60));
    assert!(ok, "{err}");
}

#[test]
fn live_without_flags_streams_the_bundled_demo() {
    let demo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/demo.duo");
    if !demo.is_file() {
        eprintln!("skipped: no bundled demo model at {}", demo.display());
        return;
    }
    let mut live = Live::start(&[
        "--no-pace".to_string(),
        "--port".to_string(),
        "0".to_string(),
        "--linger".to_string(),
        "120".to_string(),
    ]);
    let (code, _, body) = get(live.port, "/events", &[]);
    assert_eq!(code, 200);
    let ev = parse_sse(&body);
    let hello = &ev[0].data;
    assert!(
        hello["model"].as_str().unwrap().ends_with("demo.duo"),
        "{hello}"
    );
    assert!(
        hello["leader"]
            .as_str()
            .unwrap()
            .ends_with("demo_leader_pos3d.npy"),
        "{hello}"
    );
    let frames = uint(hello, "frames");
    assert_eq!(frames, 748);
    let end = &ev.last().unwrap().data;
    let drained = uint(end, "drained_frames");
    assert_eq!(ev.len(), frames + 2 + drained, "hello, frames, drain, end");
    let latency = uint(hello, "latency_frames");
    assert_eq!(latency, 291, "the reference preset by default");
    // Drained, the follower has R's frame count: 4 (K + 1), K = (T4 - 4) / 4 - 29.
    let k = (frames / 4 * 4 - 4) / 4 - 29;
    assert_eq!(uint(end, "follower_frames"), 4 * (k + 1), "{end}");
    assert!(
        drained > 0 && drained <= latency,
        "the drain gives at most what the latency held back: {end}"
    );
    let (ok, err) = live.wait_exit(Duration::from_secs(60));
    assert!(ok, "{err}");
}

fn live_fails(args: &[String]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_duolando"))
        .arg("live")
        .args(args)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "expected a failure: {err}");
    assert!(
        o.stdout.is_empty(),
        "no URL printed on failure: {}",
        String::from_utf8_lossy(&o.stdout)
    );
    assert!(!err.contains("panicked"), "{err}");
    err
}

#[test]
fn live_bad_inputs_and_a_busy_port_are_named_errors() {
    // A port in use.
    let held = std::net::TcpListener::bind(("127.0.0.1", 0)).unwrap();
    let port = held.local_addr().unwrap().port().to_string();
    let mut a = tiny_args(&["--port", &port]);
    a.retain(|s| s != "0"); // drop "--port 0"'s value ...
    let i = a.iter().position(|s| s == "--port").unwrap();
    a.remove(i); // ... and its flag, keeping ours
    let err = live_fails(&a);
    assert!(
        err.contains(&format!("127.0.0.1:{port}")) && err.contains("already in use"),
        "{err}"
    );
    drop(held);

    let dir = std::env::temp_dir().join(format!("duo-live-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Not an npy.
    let junk = dir.join("junk.npy");
    std::fs::write(&junk, b"not an npy file").unwrap();
    let mut a = tiny_args(&[]);
    let li = a.iter().position(|s| s == "--leader").unwrap();
    a[li + 1] = p(&junk).to_string();
    let err = live_fails(&a);
    assert!(err.contains(p(&junk)), "{err}");
    // A NaN in the leader.
    let leader = read_f32_2d(&roll().join("leader_pos3d.npy"), Some(ROW), "leader").unwrap();
    let mut bad = leader.data.clone();
    bad[3 * ROW + 7] = f32::NAN;
    let nan = dir.join("nan.npy");
    write_f32(&nan, &bad, &[leader.rows, ROW]).unwrap();
    a[li + 1] = p(&nan).to_string();
    let err = live_fails(&a);
    assert!(err.contains(p(&nan)) && err.contains("not finite"), "{err}");
    // Music shorter than the leader.
    let music = read_f32_2d(&roll().join("music.npy"), Some(54), "music").unwrap();
    let short = dir.join("short_music.npy");
    write_f32(&short, &music.data[..100 * 54], &[100, 54]).unwrap();
    let mut a = tiny_args(&[]);
    let mi = a.iter().position(|s| s == "--music").unwrap();
    a[mi + 1] = p(&short).to_string();
    let err = live_fails(&a);
    assert!(
        err.contains(p(&short)) && err.contains("must cover"),
        "{err}"
    );
    // A clip no longer than the latency (reference: 291 frames).
    let err = live_fails(&tiny_args(&["--frames", "200"]));
    assert!(err.contains("no follower frame would come out"), "{err}");
    // Bad --linger.
    for v in ["--linger=-1", "--linger=NaN", "--linger=1e9"] {
        let err = live_fails(&tiny_args(&[v]));
        assert!(err.contains("--linger"), "{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn live_paces_one_leader_frame_per_tick() {
    // Paced (no --no-pace): frame i is pushed no earlier than i / 30 s after
    // the clock starts, which --wait holds until this stream opens.
    let mut a = tiny_args(&[
        "--preset", "minimum", "--frames", "45", "--linger", "120", "--wait",
    ]);
    a.retain(|s| s != "--no-pace");
    let mut live = Live::start(&a);
    let t0 = Instant::now();
    let (code, _, body) = get(live.port, "/events", &[]);
    let wall = t0.elapsed();
    assert_eq!(code, 200);
    let ev = parse_sse(&body);
    assert_eq!(ev.len(), 47);
    assert_eq!(ev[0].data["paced"], Value::Bool(true));
    let slot_ms = 1000.0 / 30.0;
    let mut prev = -1.0;
    for (i, e) in ev[1..46].iter().enumerate() {
        let t = e.data["t_ms"].as_f64().unwrap();
        assert!(
            t >= i as f64 * slot_ms - 1.0 && t > prev,
            "frame {i} pushed at {t} ms, its slot starts at {:.1} ms",
            i as f64 * slot_ms
        );
        prev = t;
    }
    assert!(
        wall >= Duration::from_millis(44 * 1000 / 30),
        "45 paced frames streamed in {wall:?}"
    );
    let (ok, err) = live.wait_exit(Duration::from_secs(60));
    assert!(ok, "{err}");
}
