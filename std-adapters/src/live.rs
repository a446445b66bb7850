//! live: the local web server of `duolando live` — the live viewer page and
//! a server-sent-events stream of the frames as a session produces them.
//!
//! A deliberately small HTTP/1.1 server on `std::net` (no dependency):
//! it listens on 127.0.0.1 only, answers `GET /` (the page, `viewer/live.*`
//! compiled in) and `GET /events` (`text/event-stream`), one thread per
//! connection, every response `Connection: close`. Every event published
//! is kept, so a page that connects late (or reconnects with
//! `Last-Event-ID`) first receives what it missed, then the new events as
//! they come. Requests whose `Host` is not this server's own address
//! (`127.0.0.1:PORT` or `localhost:PORT`) are refused (403), so a web page
//! elsewhere cannot read the stream through DNS rebinding.
//!
//! ```no_run
//! use duolando::live::LiveServer;
//! let server = LiveServer::bind(0)?;                  // any free port
//! println!("{}", server.url());                       // http://127.0.0.1:PORT/
//! server.publish("frame", r#"{"i":0}"#);              // one line of JSON
//! server.finish(std::time::Duration::from_secs(10));  // end event, then linger
//! # Ok::<(), duolando::live::ServeError>(())
//! ```
//!
//! See docs/VIEWER.md ("The live page") and docs/CLI.md (`duolando live`).

use std::io::{self, BufWriter, Read, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

const LIVE_HTML: &str = include_str!("../../viewer/live.html");
const LIVE_JS: &str = include_str!("../../viewer/live.js");
const VIEWER_CSS: &str = include_str!("../../viewer/viewer.css");
const LIVE_CSS: &str = include_str!("../../viewer/live.css");

/// Largest request head (request line and headers) read, bytes.
pub const MAX_REQUEST_HEAD: usize = 8 * 1024;
/// Connections served at once; more are answered 503.
pub const MAX_CONNECTIONS: usize = 64;
/// How long a client may take to send its request.
const READ_TIMEOUT: Duration = Duration::from_secs(5);
/// How long a write may block before the client is dropped.
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);
/// An SSE comment is sent after this long without an event (keeps proxies
/// and the browser from timing the stream out).
const KEEPALIVE: Duration = Duration::from_secs(15);

/// Why the server cannot start.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error("cannot listen on 127.0.0.1:{port}: the port is already in use (pass another --port, or --port 0 for any free port)")]
    PortInUse { port: u16 },
    #[error("cannot listen on 127.0.0.1:{port}: permission denied (ports below 1024 need privileges; pass --port 0 for any free port)")]
    PermissionDenied { port: u16 },
    #[error("cannot listen on 127.0.0.1:{port}: {source}")]
    Bind { port: u16, source: io::Error },
}

/// The page served at `/`: `viewer/live.html` with its stylesheets and
/// script inlined (no other request is needed).
pub fn render_live_page() -> String {
    let mut out =
        String::with_capacity(LIVE_HTML.len() + LIVE_JS.len() + VIEWER_CSS.len() + LIVE_CSS.len());
    let mut rest = LIVE_HTML;
    while let Some(start) = rest.find("{{") {
        out.push_str(&rest[..start]);
        let after = &rest[start + 2..];
        let Some(end) = after.find("}}") else {
            out.push_str("{{");
            rest = after;
            continue;
        };
        match &after[..end] {
            // Our own files; a closing tag inside them would still end the element.
            "STYLE" => {
                out.push_str(&VIEWER_CSS.replace("</", "<\\/"));
                out.push_str(&LIVE_CSS.replace("</", "<\\/"));
            }
            "SCRIPT" => out.push_str(&LIVE_JS.replace("</", "<\\/")),
            _ => out.push_str(&rest[start..start + 2 + end + 2]),
        }
        rest = &after[end + 2..];
    }
    out.push_str(rest);
    out
}

/// Events and viewers, shared by the publisher and the connection threads.
#[derive(Default)]
struct State {
    /// Every event so far, as its whole SSE block (`id`, `event`, `data`).
    events: Vec<Arc<str>>,
    /// No more events will come (the `end` event is the last).
    ended: bool,
    /// Event streams open now.
    open_streams: usize,
    /// Event streams that were sent every event, the last included.
    delivered: usize,
    /// Connections being served (any route).
    connections: usize,
}

#[derive(Default)]
struct Shared {
    state: Mutex<State>,
    changed: Condvar,
}

impl Shared {
    /// The state, also after a connection thread panicked holding it.
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// How [`LiveServer::finish`] ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Finished {
    /// Event streams that received every event.
    pub delivered: usize,
    /// The linger time ran out (rather than every open stream being done).
    pub timed_out: bool,
}

/// The running server. Dropping it leaves the listener thread running
/// until the process exits (the CLI returns right after [`LiveServer::finish`]).
pub struct LiveServer {
    addr: SocketAddr,
    shared: Arc<Shared>,
}

impl LiveServer {
    /// Listens on 127.0.0.1:`port` (0: a free port chosen by the system)
    /// and starts serving in background threads.
    pub fn bind(port: u16) -> Result<LiveServer, ServeError> {
        let listener =
            TcpListener::bind((Ipv4Addr::LOCALHOST, port)).map_err(|source| {
                match source.kind() {
                    io::ErrorKind::AddrInUse => ServeError::PortInUse { port },
                    io::ErrorKind::PermissionDenied => ServeError::PermissionDenied { port },
                    _ => ServeError::Bind { port, source },
                }
            })?;
        let addr = listener
            .local_addr()
            .map_err(|source| ServeError::Bind { port, source })?;
        let shared = Arc::new(Shared::default());
        let page: Arc<str> = render_live_page().into();
        let sh = Arc::clone(&shared);
        std::thread::Builder::new()
            .name("live-accept".into())
            .spawn(move || accept_loop(listener, addr, sh, page))
            .map_err(|source| ServeError::Bind { port, source })?;
        Ok(LiveServer { addr, shared })
    }

    /// The address listened on (the actual port when 0 was asked for).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// `http://127.0.0.1:PORT/`, the page.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// Appends one event (`data` must be one line, e.g. compact JSON) and
    /// wakes every stream. Returns its id (0, 1, 2, ...). Ignored after
    /// [`LiveServer::finish`].
    pub fn publish(&self, event: &str, data: &str) -> usize {
        debug_assert!(!data.contains('\n') && !event.contains('\n'));
        let mut st = self.shared.lock();
        let id = st.events.len();
        if st.ended {
            return id;
        }
        let block = format!(
            "id: {id}\nevent: {event}\ndata: {}\n\n",
            data.replace(['\r', '\n'], " ")
        );
        st.events.push(block.into());
        drop(st);
        self.shared.changed.notify_all();
        id
    }

    /// Event streams open now.
    pub fn open_streams(&self) -> usize {
        self.shared.lock().open_streams
    }

    /// Blocks until at least one page has opened the event stream, or
    /// `timeout` (None: forever). Returns whether one has.
    pub fn wait_for_stream(&self, timeout: Option<Duration>) -> bool {
        let deadline = timeout.map(|t| Instant::now() + t);
        let mut st = self.shared.lock();
        while st.open_streams == 0 && st.delivered == 0 {
            let wait = match deadline {
                Some(d) => match d.checked_duration_since(Instant::now()) {
                    Some(w) if !w.is_zero() => w,
                    _ => return false,
                },
                None => KEEPALIVE,
            };
            st = self
                .shared
                .changed
                .wait_timeout(st, wait)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
        true
    }

    /// Marks the stream as ended (no more events; streams close once they
    /// have sent everything), then waits until every open stream has sent
    /// every event, at least one stream having done so, or until `linger`
    /// has passed — whichever comes first.
    pub fn finish(&self, linger: Duration) -> Finished {
        let deadline = Instant::now() + linger;
        let mut st = self.shared.lock();
        st.ended = true;
        self.shared.changed.notify_all();
        loop {
            if st.delivered > 0 && st.open_streams == 0 {
                return Finished {
                    delivered: st.delivered,
                    timed_out: false,
                };
            }
            let Some(wait) = deadline
                .checked_duration_since(Instant::now())
                .filter(|w| !w.is_zero())
            else {
                return Finished {
                    delivered: st.delivered,
                    timed_out: true,
                };
            };
            st = self
                .shared
                .changed
                .wait_timeout(st, wait)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }
}

fn accept_loop(listener: TcpListener, addr: SocketAddr, shared: Arc<Shared>, page: Arc<str>) {
    for conn in listener.incoming() {
        let stream = match conn {
            Ok(s) => s,
            // Out of file descriptors and the like: let it pass, do not spin.
            Err(_) => {
                std::thread::sleep(Duration::from_millis(50));
                continue;
            }
        };
        {
            let mut st = shared.lock();
            if st.connections >= MAX_CONNECTIONS {
                drop(st);
                let _ = stream.set_write_timeout(Some(WRITE_TIMEOUT));
                let _ = respond(
                    &stream,
                    "503 Service Unavailable",
                    "text/plain; charset=utf-8",
                    b"too many connections\n",
                    false,
                );
                continue;
            }
            st.connections += 1;
        }
        let (sh, pg) = (Arc::clone(&shared), Arc::clone(&page));
        let spawned = std::thread::Builder::new()
            .name("live-conn".into())
            .spawn(move || {
                let _ = serve(stream, addr, &sh, &pg);
                sh.lock().connections -= 1;
                sh.changed.notify_all();
            });
        if spawned.is_err() {
            shared.lock().connections -= 1;
        }
    }
}

/// One parsed request head.
#[derive(Debug, PartialEq, Eq)]
struct Request {
    method: String,
    /// The path without the query.
    path: String,
    host: Option<String>,
    last_event_id: Option<String>,
}

/// Why a request head could not be read.
#[derive(Debug, PartialEq, Eq)]
enum HeadError {
    /// The client closed or timed out before a whole head arrived.
    Incomplete,
    TooLarge,
    Malformed,
}

/// Reads bytes until the blank line that ends the head (at most
/// [`MAX_REQUEST_HEAD`]); a body is never read (only GET/HEAD are served).
fn read_head(stream: &mut impl Read) -> Result<Vec<u8>, HeadError> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            buf.truncate(end + 2);
            return Ok(buf);
        }
        if buf.len() >= MAX_REQUEST_HEAD {
            return Err(HeadError::TooLarge);
        }
        let want = chunk.len().min(MAX_REQUEST_HEAD + 4 - buf.len());
        match stream.read(&mut chunk[..want]) {
            Ok(0) | Err(_) => return Err(HeadError::Incomplete),
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
        }
    }
}

fn parse_head(head: &[u8]) -> Result<Request, HeadError> {
    let text = std::str::from_utf8(head).map_err(|_| HeadError::Malformed)?;
    let mut lines = text.split("\r\n");
    let mut parts = lines.next().ok_or(HeadError::Malformed)?.split(' ');
    let (Some(method), Some(target), Some(version), None) =
        (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Err(HeadError::Malformed);
    };
    if method.is_empty() || !version.starts_with("HTTP/1.") || !target.starts_with('/') {
        return Err(HeadError::Malformed);
    }
    let path = target.split(['?', '#']).next().unwrap_or("/").to_string();
    let mut req = Request {
        method: method.to_string(),
        path,
        host: None,
        last_event_id: None,
    };
    for line in lines.filter(|l| !l.is_empty()) {
        let (name, value) = line.split_once(':').ok_or(HeadError::Malformed)?;
        let value = value.trim();
        if name.eq_ignore_ascii_case("host") {
            req.host = Some(value.to_ascii_lowercase());
        } else if name.eq_ignore_ascii_case("last-event-id") {
            req.last_event_id = Some(value.to_string());
        }
    }
    Ok(req)
}

/// Writes a whole response with `Content-Length` and `Connection: close`.
fn respond(
    mut stream: &TcpStream,
    status: &str,
    content_type: &str,
    body: &[u8],
    head_only: bool,
) -> io::Result<()> {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nCache-Control: no-store\r\n\
         X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    if !head_only {
        stream.write_all(body)?;
    }
    stream.flush()
}

fn serve(mut stream: TcpStream, addr: SocketAddr, shared: &Shared, page: &str) -> io::Result<()> {
    stream.set_read_timeout(Some(READ_TIMEOUT))?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    let _ = stream.set_nodelay(true);
    let text = "text/plain; charset=utf-8";
    let req = match read_head(&mut stream).and_then(|h| parse_head(&h)) {
        Ok(r) => r,
        Err(HeadError::Incomplete) => return Ok(()),
        Err(HeadError::TooLarge) => {
            return respond(
                &stream,
                "431 Request Header Fields Too Large",
                text,
                b"request head too large\n",
                false,
            )
        }
        Err(HeadError::Malformed) => {
            return respond(
                &stream,
                "400 Bad Request",
                text,
                b"malformed request\n",
                false,
            )
        }
    };
    let port = addr.port();
    let host_ok = req
        .host
        .as_deref()
        .is_some_and(|h| h == format!("127.0.0.1:{port}") || h == format!("localhost:{port}"));
    if !host_ok {
        return respond(
            &stream,
            "403 Forbidden",
            text,
            b"this server answers only requests for its own address (127.0.0.1 or localhost)\n",
            false,
        );
    }
    let head_only = req.method == "HEAD";
    if req.method != "GET" && !head_only {
        let mut s = &stream;
        let body = b"only GET and HEAD\n";
        let head = format!(
            "HTTP/1.1 405 Method Not Allowed\r\nAllow: GET, HEAD\r\nContent-Type: {text}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
            body.len()
        );
        s.write_all(head.as_bytes())?;
        s.write_all(body)?;
        return s.flush();
    }
    match req.path.as_str() {
        "/" | "/index.html" => respond(
            &stream,
            "200 OK",
            "text/html; charset=utf-8",
            page.as_bytes(),
            head_only,
        ),
        "/events" => {
            let from = req
                .last_event_id
                .as_deref()
                .and_then(|v| v.parse::<usize>().ok())
                .map_or(0, |id| id.saturating_add(1));
            stream_events(stream, shared, from, head_only)
        }
        _ => respond(
            &stream,
            "404 Not Found",
            text,
            b"not found: the page is at / and the event stream at /events\n",
            head_only,
        ),
    }
}

/// Sends events `from..` as they come; returns when the last was sent after
/// the end, or when the client is gone.
fn stream_events(
    stream: TcpStream,
    shared: &Shared,
    from: usize,
    head_only: bool,
) -> io::Result<()> {
    let mut w = BufWriter::new(stream);
    w.write_all(
        b"HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\n\
          X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
    )?;
    if head_only {
        return w.flush();
    }
    w.write_all(b"retry: 1000\n\n")?;
    w.flush()?;
    shared.lock().open_streams += 1;
    shared.changed.notify_all();
    let result = pump(&mut w, shared, from);
    let mut st = shared.lock();
    st.open_streams -= 1;
    if matches!(result, Ok(true)) {
        st.delivered += 1;
    }
    drop(st);
    shared.changed.notify_all();
    result.map(|_| ())
}

/// The loop of [`stream_events`]; `Ok(true)` when every event was sent.
fn pump(w: &mut BufWriter<TcpStream>, shared: &Shared, mut next: usize) -> io::Result<bool> {
    loop {
        let (batch, ended) = {
            let mut st = shared.lock();
            let mut waited = Duration::ZERO;
            while next >= st.events.len() && !st.ended && waited < KEEPALIVE {
                let t = Instant::now();
                st = shared
                    .changed
                    .wait_timeout(st, KEEPALIVE - waited)
                    .unwrap_or_else(|p| p.into_inner())
                    .0;
                waited += t.elapsed();
            }
            let batch: Vec<Arc<str>> = st.events.get(next..).map(<[_]>::to_vec).unwrap_or_default();
            (batch, st.ended)
        };
        if batch.is_empty() && !ended {
            w.write_all(b": keepalive\n\n")?;
        }
        for e in &batch {
            w.write_all(e.as_bytes())?;
        }
        w.flush()?;
        next += batch.len();
        if ended && next >= shared.lock().events.len() {
            return Ok(true);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_request_heads() {
        let r =
            parse_head(b"GET /events?x=1 HTTP/1.1\r\nHost: 127.0.0.1:80\r\nLast-Event-ID: 7\r\n")
                .unwrap();
        assert_eq!(
            r,
            Request {
                method: "GET".into(),
                path: "/events".into(),
                host: Some("127.0.0.1:80".into()),
                last_event_id: Some("7".into())
            }
        );
        for bad in [
            &b"GET\r\n"[..],
            b"GET / HTTP/1.1 x\r\n",
            b"GET nope HTTP/1.1\r\n",
            b"GET / SPDY\r\n",
            b"GET / HTTP/1.1\r\nno colon\r\n",
            b"\xff / HTTP/1.1\r\n",
        ] {
            assert_eq!(
                parse_head(bad),
                Err(HeadError::Malformed),
                "{}",
                String::from_utf8_lossy(bad)
            );
        }
    }

    #[test]
    fn head_reading_is_bounded() {
        let big = vec![b'a'; MAX_REQUEST_HEAD * 2];
        assert_eq!(read_head(&mut &big[..]), Err(HeadError::TooLarge));
        assert_eq!(
            read_head(&mut &b"GET / HTTP/1.1\r\n"[..]),
            Err(HeadError::Incomplete)
        );
        assert_eq!(
            read_head(&mut &b"GET / HTTP/1.1\r\n\r\nbody"[..]).unwrap(),
            b"GET / HTTP/1.1\r\n"
        );
    }

    #[test]
    fn page_inlines_style_and_script() {
        let p = render_live_page();
        assert!(!p.contains("{{STYLE}}") && !p.contains("{{SCRIPT}}"));
        assert!(p.contains("new EventSource") && p.contains("--follower"));
        assert_eq!(p.matches("</script>").count(), 1);
    }

    #[test]
    fn port_in_use_is_a_named_error() {
        let held = TcpListener::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        let port = held.local_addr().unwrap().port();
        match LiveServer::bind(port) {
            Err(ServeError::PortInUse { port: p }) => assert_eq!(p, port),
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("bound a port in use"),
        }
    }
}
