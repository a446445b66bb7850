//! viewer: writes `DIR/index.html`, a self-contained page that plays the
//! leader and follower skeletons with the music, a scrub bar and a timeline
//! of music beats and follower tokens.
//!
//! The page needs no network: the web sources in `viewer/` at the repository
//! root (HTML template, canvas-2D script, stylesheet; no third-party code) are
//! compiled into this crate with `include_str!` and inlined into one file, and
//! the motion is embedded as base64 little-endian float32 inside a
//! `<script type="application/json">` block. Every string that reaches the page
//! is escaped for its context (HTML text, JSON inside a script element, a URL in
//! an attribute), so a title such as `</script><script>alert(1)` stays text.
//!
//! ```no_run
//! use duolando::viewer::{write_index_html, ViewerData};
//! # let leader = vec![0.0f32; 165 * 30]; let follower = leader.clone();
//! let page = write_index_html(std::path::Path::new("out"), &ViewerData {
//!     title: "demo",
//!     fps: 30.0,
//!     leader_pos3d: Some(&leader), // (T, 165); None for a solo dancer
//!     follower_pos3d: &follower, // (T2, 165)
//!     beats: None,               // (T,) per-frame 0/1
//!     tokens: None,              // (K, 5) follower tokens
//!     audio_file: None,          // e.g. Some("music.wav"), a file in `out/`
//!     see_also: None,            // e.g. a link to solo/index.html
//! })?;
//! # Ok::<(), std::io::Error>(())
//! ```
//!
//! See docs/VIEWER.md for the page's controls and its headless-browser test.

// `len % n != 0` rather than `is_multiple_of` (stable since 1.87; MSRV is 1.80).
#![allow(clippy::manual_is_multiple_of)]

use std::fmt::Write as _;
use std::io;
use std::path::{Path, PathBuf};

/// Joints per SMPL-X skeleton.
pub const JOINTS: usize = 55;
/// Floats per motion row: world xyz per joint.
pub const ROW: usize = JOINTS * 3;
/// Follower token streams in the order of the GPT heads: up, down, lhand, rhand, transl.
pub const TOKEN_STREAMS: usize = 5;
/// Motion frames per token (the VQ-VAE downsampling).
pub const FRAMES_PER_TOKEN: usize = 4;
/// Names of the token streams, shown on the timeline.
pub const TOKEN_STREAM_NAMES: [&str; TOKEN_STREAMS] = ["up", "down", "lhand", "rhand", "transl"];
/// Parent of each SMPL-X joint (-1 for the pelvis); the bones the page draws.
pub const SMPLX_PARENTS: [i8; JOINTS] = [
    -1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15, 20, 25,
    26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38, 21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49,
    50, 21, 52, 53,
];
/// Largest frame rate accepted (a sanity cap, not a limit of the page).
pub const MAX_FPS: f32 = 1000.0;

/// The HTML template; `{{NAME}}` placeholders are filled by [`render_index_html`].
const TEMPLATE_HTML: &str = include_str!("../../../viewer/index.html");
const VIEWER_JS: &str = include_str!("../../../viewer/viewer.js");
const VIEWER_CSS: &str = include_str!("../../../viewer/viewer.css");

/// What the page shows. Everything is borrowed; nothing is copied until the page is rendered.
#[derive(Clone, Copy, Debug)]
pub struct ViewerData<'a> {
    /// Page title (any text; escaped).
    pub title: &'a str,
    /// Frames per second of both motions (30 for Duolando).
    pub fps: f32,
    /// Leader world joint positions, (T, 165), metres, y-up; None for a
    /// solo dancer (a Bailando model: the page shows one dancer).
    pub leader_pos3d: Option<&'a [f32]>,
    /// Follower (or solo dancer) world joint positions, (T2, 165), metres, y-up.
    pub follower_pos3d: &'a [f32],
    /// Music beats per leader frame (per dancer frame without a leader),
    /// (T,), 0 or 1 (the last column of the 54-d music features).
    pub beats: Option<&'a [f32]>,
    /// Follower tokens, (K, 5) row-major, one row per 4 frames, streams in [`TOKEN_STREAM_NAMES`] order.
    pub tokens: Option<&'a [u32]>,
    /// Audio file name relative to the output directory (a sibling of index.html).
    pub audio_file: Option<&'a str>,
    /// A link in the page's header to a related page (the bundled demo's
    /// duet and solo dancer point at each other).
    pub see_also: Option<ViewerLink<'a>>,
}

/// A link shown in the viewer's header: `href` a relative path of plain
/// names (`solo/index.html`, `../index.html`), `text` any text (escaped).
#[derive(Clone, Copy, Debug)]
pub struct ViewerLink<'a> {
    pub href: &'a str,
    pub text: &'a str,
}

/// Why [`ViewerData`] cannot be shown. Returned inside an [`io::Error`] of kind
/// `InvalidInput` (reach it with `err.get_ref()` and `downcast_ref`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ViewerDataError {
    #[error("fps must be finite and in (0, {MAX_FPS}], got {0}")]
    BadFps(f32),
    #[error("{which}_pos3d is empty: expected (T, {ROW}) floats with T >= 1")]
    EmptyMotion { which: &'static str },
    #[error("{which}_pos3d has {len} floats, not a multiple of {ROW} (expected (T, {ROW}))")]
    RaggedMotion { which: &'static str, len: usize },
    #[error("{which}_pos3d[{frame}, {channel}] is not finite ({value})")]
    NonFiniteMotion {
        which: &'static str,
        frame: usize,
        channel: usize,
        value: f32,
    },
    #[error("beats has {len} values but the leader has {frames} frames (expected (T,))")]
    BeatsLength { len: usize, frames: usize },
    #[error("beats[{frame}] is not finite ({value})")]
    NonFiniteBeat { frame: usize, value: f32 },
    #[error("tokens has {len} values, not a multiple of {TOKEN_STREAMS} (expected (K, {TOKEN_STREAMS}))")]
    RaggedTokens { len: usize },
    #[error("audio_file {name:?} must be a plain file name inside the output directory ({why})")]
    BadAudioName { name: String, why: &'static str },
    #[error("audio_file {path:?} does not exist; write the audio before the page")]
    MissingAudio { path: PathBuf },
    #[error("see_also href {href:?} must be a relative path of plain names ({why})")]
    BadLink { href: String, why: &'static str },
}

impl From<ViewerDataError> for io::Error {
    fn from(e: ViewerDataError) -> Self {
        io::Error::new(io::ErrorKind::InvalidInput, e)
    }
}

/// Shape of validated data.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ViewerDims {
    /// Leader frames T.
    pub leader_frames: usize,
    /// Follower frames T2.
    pub follower_frames: usize,
    /// Token rows K (0 when no tokens).
    pub token_rows: usize,
}

fn check_motion(which: &'static str, m: &[f32]) -> Result<usize, ViewerDataError> {
    if m.is_empty() {
        return Err(ViewerDataError::EmptyMotion { which });
    }
    if m.len() % ROW != 0 {
        return Err(ViewerDataError::RaggedMotion {
            which,
            len: m.len(),
        });
    }
    if let Some(i) = m.iter().position(|v| !v.is_finite()) {
        return Err(ViewerDataError::NonFiniteMotion {
            which,
            frame: i / ROW,
            channel: i % ROW,
            value: m[i],
        });
    }
    Ok(m.len() / ROW)
}

/// Checks an audio name: one non-empty path component, no separators, no `.`/`..`,
/// no control characters.
fn check_audio_name(name: &str) -> Result<(), ViewerDataError> {
    let bad = |why| {
        Err(ViewerDataError::BadAudioName {
            name: name.to_owned(),
            why,
        })
    };
    if name.is_empty() {
        return bad("empty");
    }
    if name == "." || name == ".." {
        return bad("a directory");
    }
    if name.contains(['/', '\\']) {
        return bad("contains a path separator");
    }
    if name.chars().any(char::is_control) {
        return bad("contains a control character");
    }
    if name.contains(':') {
        return bad("contains ':'");
    }
    Ok(())
}

/// A [`ViewerLink::href`]: `/`-separated segments, each `..` or a plain
/// file name ([`check_audio_name`]'s rules: no scheme, no backslash, no
/// control character), not absolute, not empty.
fn check_link(href: &str) -> Result<(), ViewerDataError> {
    let bad = |why| {
        Err(ViewerDataError::BadLink {
            href: href.to_owned(),
            why,
        })
    };
    if href.is_empty() {
        return bad("empty");
    }
    for seg in href.split('/') {
        match seg {
            "" => return bad("absolute or an empty segment"),
            "." => return bad("a '.' segment"),
            ".." => {}
            _ => {
                if let Err(ViewerDataError::BadAudioName { why, .. }) = check_audio_name(seg) {
                    return bad(why);
                }
            }
        }
    }
    Ok(())
}

impl ViewerData<'_> {
    /// Checks every shape and value the page relies on (does not touch the file system).
    pub fn validate(&self) -> Result<ViewerDims, ViewerDataError> {
        if !(self.fps.is_finite() && self.fps > 0.0 && self.fps <= MAX_FPS) {
            return Err(ViewerDataError::BadFps(self.fps));
        }
        let leader_frames = self
            .leader_pos3d
            .map(|l| check_motion("leader", l))
            .transpose()?
            .unwrap_or(0);
        let follower_frames = check_motion("follower", self.follower_pos3d)?;
        if let Some(b) = self.beats {
            let frames = if self.leader_pos3d.is_some() {
                leader_frames
            } else {
                follower_frames
            };
            if b.len() != frames {
                return Err(ViewerDataError::BeatsLength {
                    len: b.len(),
                    frames,
                });
            }
            if let Some(i) = b.iter().position(|v| !v.is_finite()) {
                return Err(ViewerDataError::NonFiniteBeat {
                    frame: i,
                    value: b[i],
                });
            }
        }
        let token_rows = match self.tokens {
            Some(t) if t.len() % TOKEN_STREAMS != 0 => {
                return Err(ViewerDataError::RaggedTokens { len: t.len() })
            }
            Some(t) => t.len() / TOKEN_STREAMS,
            None => 0,
        };
        if let Some(a) = self.audio_file {
            check_audio_name(a)?;
        }
        if let Some(l) = self.see_also {
            check_link(l.href)?;
        }
        Ok(ViewerDims {
            leader_frames,
            follower_frames,
            token_rows,
        })
    }
}

/// Validates `data`, renders the page and writes `dir/index.html` (creating `dir`).
/// An `audio_file` must already exist in `dir`. Returns the page's path.
pub fn write_index_html(dir: &Path, data: &ViewerData) -> io::Result<PathBuf> {
    let html = render_index_html(data)?;
    if let Some(a) = data.audio_file {
        let path = dir.join(a);
        if !path.is_file() {
            return Err(ViewerDataError::MissingAudio { path }.into());
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| {
        io::Error::new(
            e.kind(),
            format!("creating viewer directory {}: {e}", dir.display()),
        )
    })?;
    let path = dir.join("index.html");
    std::fs::write(&path, html)
        .map_err(|e| io::Error::new(e.kind(), format!("writing {}: {e}", path.display())))?;
    Ok(path)
}

/// Validates `data` and returns the whole page as a string (no file system access).
pub fn render_index_html(data: &ViewerData) -> Result<String, ViewerDataError> {
    let dims = data.validate()?;
    let json = data_json(data, &dims);
    let audio = match data.audio_file {
        Some(a) => format!(
            "<audio id=\"audio\" preload=\"auto\" src=\"{}\"></audio>",
            escape_html(&percent_encode_file_name(a))
        ),
        None => String::new(),
    };
    let link = match data.see_also {
        Some(l) => {
            let href: Vec<String> = l.href.split('/').map(percent_encode_file_name).collect();
            format!(
                "<a id=\"see-also\" href=\"{}\">{}</a>",
                escape_html(&href.join("/")),
                escape_html(l.text)
            )
        }
        None => String::new(),
    };
    let mut out = String::with_capacity(
        TEMPLATE_HTML.len() + VIEWER_JS.len() + VIEWER_CSS.len() + json.len() + 256,
    );
    fill_template(TEMPLATE_HTML, &mut out, |name, out| match name {
        "TITLE" => {
            out.push_str(&escape_html(data.title));
            true
        }
        // The stylesheet and the script are ours; still refuse a closing tag in them.
        "STYLE" => {
            out.push_str(&VIEWER_CSS.replace("</", "<\\/"));
            true
        }
        "SCRIPT" => {
            out.push_str(&VIEWER_JS.replace("</", "<\\/"));
            true
        }
        "DATA" => {
            out.push_str(&json);
            true
        }
        "AUDIO" => {
            out.push_str(&audio);
            true
        }
        "LINK" => {
            out.push_str(&link);
            true
        }
        _ => false,
    });
    Ok(out)
}

/// One pass over `template`: each `{{NAME}}` is replaced by `fill`, so substituted text
/// is never scanned again. Unknown names are copied through unchanged.
fn fill_template(
    template: &str,
    out: &mut String,
    mut fill: impl FnMut(&str, &mut String) -> bool,
) {
    let mut rest = template;
    while let Some(start) = rest.find("{{") {
        out.push_str(&rest[..start]);
        let after = &rest[start + 2..];
        match after.find("}}") {
            Some(end)
                if after[..end]
                    .bytes()
                    .all(|b| b.is_ascii_uppercase() || b == b'_') =>
            {
                let name = &after[..end];
                if !fill(name, out) {
                    out.push_str(&rest[start..start + 2 + end + 2]);
                }
                rest = &after[end + 2..];
            }
            _ => {
                out.push_str("{{");
                rest = after;
            }
        }
    }
    out.push_str(rest);
}

/// The embedded data block. Safe inside `<script type="application/json">`: the only
/// free text is the title, whose `<`, `>`, `&` and line separators are `\u` escaped.
fn data_json(d: &ViewerData, dims: &ViewerDims) -> String {
    let mut s = String::new();
    let title = json_string(d.title);
    let _ = write!(
        s,
        "{{\"version\":1,\"title\":{title},\"fps\":{},\"joints\":{JOINTS},\"parents\":{:?},",
        d.fps, SMPLX_PARENTS
    );
    match d.leader_pos3d {
        Some(l) => {
            let _ = write!(
                s,
                "\"leader\":{{\"frames\":{},\"f32\":\"{}\"}},",
                dims.leader_frames,
                base64_f32(l)
            );
        }
        None => s.push_str("\"leader\":null,"),
    }
    let _ = write!(
        s,
        "\"follower\":{{\"frames\":{},\"f32\":\"{}\"}},",
        dims.follower_frames,
        base64_f32(d.follower_pos3d)
    );
    match d.beats {
        Some(b) => {
            let _ = write!(
                s,
                "\"beats\":{{\"frames\":{},\"f32\":\"{}\"}},",
                b.len(),
                base64_f32(b)
            );
        }
        None => s.push_str("\"beats\":null,"),
    }
    match d.tokens {
        Some(t) => {
            let _ = write!(
                s,
                "\"tokens\":{{\"rows\":{},\"streams\":{TOKEN_STREAMS},\"frames_per_token\":{FRAMES_PER_TOKEN},\"names\":{:?},\"ids\":{:?}}},",
                dims.token_rows, TOKEN_STREAM_NAMES, t
            );
        }
        None => s.push_str("\"tokens\":null,"),
    }
    let _ = write!(s, "\"audio\":{}}}", d.audio_file.is_some());
    s
}

/// A JSON string literal that is also safe inside an HTML `<script>` element:
/// quotes, backslashes and control characters as JSON requires, plus `<`, `>`, `&`
/// and the JavaScript line separators as `\u` escapes.
fn json_string(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 2);
    out.push('"');
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            '<' | '>' | '&' | '\u{2028}' | '\u{2029}' => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// HTML text / attribute escaping.
fn escape_html(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Percent-encodes everything but RFC 3986 unreserved characters, so the file name is
/// a relative URL path segment (a name like `a#b?.wav` stays a file name).
fn percent_encode_file_name(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    for b in name.bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b'~') {
            out.push(b as char);
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

/// Little-endian float32 bytes, base64 (standard alphabet, padded).
fn base64_f32(v: &[f32]) -> String {
    let mut bytes = Vec::with_capacity(v.len() * 4);
    for x in v {
        bytes.extend_from_slice(&x.to_le_bytes());
    }
    base64(&bytes)
}

/// RFC 4648 base64 with padding.
fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        out.push(A[(n >> 18) as usize & 63] as char);
        out.push(A[(n >> 12) as usize & 63] as char);
        out.push(if chunk.len() > 1 {
            A[(n >> 6) as usize & 63] as char
        } else {
            '='
        });
        out.push(if chunk.len() > 2 {
            A[n as usize & 63] as char
        } else {
            '='
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn motion(frames: usize) -> Vec<f32> {
        (0..frames * ROW).map(|i| (i % 97) as f32 * 0.01).collect()
    }

    fn data<'a>(l: &'a [f32], f: &'a [f32]) -> ViewerData<'a> {
        ViewerData {
            title: "t",
            fps: 30.0,
            leader_pos3d: Some(l),
            follower_pos3d: f,
            beats: None,
            tokens: None,
            audio_file: None,
            see_also: None,
        }
    }

    #[test]
    fn base64_matches_rfc4648_vectors() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, enc) in cases {
            assert_eq!(base64(plain.as_bytes()), enc, "{plain:?}");
        }
        // 1.0f32 little-endian is 00 00 80 3f.
        assert_eq!(base64_f32(&[1.0]), "AACAPw==");
    }

    #[test]
    fn validates_shapes_and_values() {
        let l = motion(8);
        let f = motion(6);
        assert_eq!(
            data(&l, &f).validate(),
            Ok(ViewerDims {
                leader_frames: 8,
                follower_frames: 6,
                token_rows: 0
            })
        );
        assert_eq!(
            data(&[], &f).validate(),
            Err(ViewerDataError::EmptyMotion { which: "leader" })
        );
        assert_eq!(
            data(&l, &l[..ROW + 1]).validate(),
            Err(ViewerDataError::RaggedMotion {
                which: "follower",
                len: ROW + 1
            })
        );
        let mut bad = l.clone();
        bad[2 * ROW + 4] = f32::NAN;
        assert!(matches!(
            data(&bad, &f).validate(),
            Err(ViewerDataError::NonFiniteMotion {
                which: "leader",
                frame: 2,
                channel: 4,
                ..
            })
        ));
        for fps in [0.0, -30.0, f32::NAN, f32::INFINITY, 5000.0] {
            assert!(
                matches!(
                    ViewerData {
                        fps,
                        ..data(&l, &f)
                    }
                    .validate(),
                    Err(ViewerDataError::BadFps(_))
                ),
                "{fps}"
            );
        }
        let beats = vec![0.0; 7];
        assert_eq!(
            ViewerData {
                beats: Some(&beats),
                ..data(&l, &f)
            }
            .validate(),
            Err(ViewerDataError::BeatsLength { len: 7, frames: 8 })
        );
        let beats = [0.0, 1.0, 0.0, f32::INFINITY, 0.0, 0.0, 0.0, 0.0];
        assert!(matches!(
            ViewerData {
                beats: Some(&beats),
                ..data(&l, &f)
            }
            .validate(),
            Err(ViewerDataError::NonFiniteBeat { frame: 3, .. })
        ));
        let tokens = [1u32; 7];
        assert_eq!(
            ViewerData {
                tokens: Some(&tokens),
                ..data(&l, &f)
            }
            .validate(),
            Err(ViewerDataError::RaggedTokens { len: 7 })
        );
        let tokens = [1u32; 10];
        assert_eq!(
            ViewerData {
                tokens: Some(&tokens),
                ..data(&l, &f)
            }
            .validate()
            .map(|d| d.token_rows),
            Ok(2)
        );
        for name in [
            "", ".", "..", "../x.wav", "a/b.wav", "a\\b.wav", "a\nb.wav", "C:x.wav",
        ] {
            assert!(
                matches!(
                    ViewerData {
                        audio_file: Some(name),
                        ..data(&l, &f)
                    }
                    .validate(),
                    Err(ViewerDataError::BadAudioName { .. })
                ),
                "{name:?}"
            );
        }
    }

    #[test]
    fn see_also_links_are_relative_encoded_and_escaped() {
        let l = motion(2);
        let link = |href, text| ViewerData {
            see_also: Some(ViewerLink { href, text }),
            ..data(&l, &l)
        };
        assert!(!render_index_html(&data(&l, &l))
            .unwrap()
            .contains("see-also\""));
        let html = render_index_html(&link("solo/my dance.html", "a <solo> & more")).unwrap();
        assert!(
            html.contains(
                "<a id=\"see-also\" href=\"solo/my%20dance.html\">a &lt;solo&gt; &amp; more</a>"
            ),
            "{}",
            &html[..600]
        );
        assert!(render_index_html(&link("../index.html", "the duet")).is_ok());
        for href in [
            "",
            "/etc/passwd",
            "a//b",
            "./x",
            "javascript:alert(1)",
            "http://x/y",
            "a\\b",
            "solo/\n.html",
            "solo/",
        ] {
            assert!(
                matches!(
                    link(href, "x").validate(),
                    Err(ViewerDataError::BadLink { .. })
                ),
                "{href:?}"
            );
        }
    }

    #[test]
    fn title_cannot_break_out_of_the_page() {
        let l = motion(2);
        let title = "</script><script>alert(1)</script><!-- & \u{2028} \"q\" {{DATA}}";
        let html = render_index_html(&ViewerData {
            title,
            ..data(&l, &l)
        })
        .unwrap();
        // The only script elements are the page's own: one data block and one program.
        assert_eq!(html.matches("<script").count(), 2, "{}", &html[..400]);
        assert_eq!(html.matches("</script>").count(), 2);
        assert!(!html.contains("alert(1)</"));
        assert!(
            html.contains("&lt;/script&gt;&lt;script&gt;alert(1)"),
            "title shown as text"
        );
        assert!(
            html.contains("\\u003c/script\\u003e\\u003cscript\\u003ealert(1)"),
            "title escaped in JSON"
        );
        // The placeholder inside the title is not expanded a second time.
        assert_eq!(html.matches("\"leader\":").count(), 1);
        for name in [
            "{{TITLE}}",
            "{{STYLE}}",
            "{{SCRIPT}}",
            "{{AUDIO}}",
            "{{LINK}}",
        ] {
            assert!(!html.contains(name), "{name} is filled");
        }
    }

    #[test]
    fn audio_name_is_url_encoded_and_must_exist() {
        let dir = std::env::temp_dir().join(format!("duolando-viewer-test-{}", std::process::id()));
        let l = motion(2);
        let d = ViewerData {
            audio_file: Some("my song #1.wav"),
            ..data(&l, &l)
        };
        let err = write_index_html(&dir, &d).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
        assert!(matches!(
            err.get_ref()
                .and_then(|e| e.downcast_ref::<ViewerDataError>()),
            Some(ViewerDataError::MissingAudio { .. })
        ));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("my song #1.wav"), b"RIFF").unwrap();
        let page = write_index_html(&dir, &d).unwrap();
        let html = std::fs::read_to_string(&page).unwrap();
        assert!(html.contains("src=\"my%20song%20%231.wav\""));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn json_strings_are_escaped() {
        assert_eq!(json_string("a\"b\\c\nd\u{1}"), r#""a\"b\\c\nd\u0001""#);
        assert_eq!(
            json_string("</script>&\u{2028}é"),
            r#""\u003c/script\u003e\u0026\u2028é""#
        );
    }

    #[test]
    fn embedded_data_block_carries_every_array() {
        let l = motion(3);
        let f: Vec<f32> = motion(2).iter().map(|v| -v).collect();
        let beats = [1.0, 0.0, 0.0];
        let tokens = [5u32, 6, 7, 8, 511];
        let d = ViewerData {
            beats: Some(&beats),
            tokens: Some(&tokens),
            ..data(&l, &f)
        };
        let html = render_index_html(&d).unwrap();
        let start = html.find("id=\"duolando-data\">").unwrap() + "id=\"duolando-data\">".len();
        let end = start + html[start..].find("</script>").unwrap();
        let block = &html[start..end];
        assert!(
            block.starts_with("{\"version\":1,") && block.ends_with("\"audio\":false}"),
            "{block}"
        );
        assert!(block.contains(&format!(
            "\"leader\":{{\"frames\":3,\"f32\":\"{}\"}}",
            base64_f32(&l)
        )));
        assert!(block.contains(&format!(
            "\"follower\":{{\"frames\":2,\"f32\":\"{}\"}}",
            base64_f32(&f)
        )));
        assert!(block.contains(&format!(
            "\"beats\":{{\"frames\":3,\"f32\":\"{}\"}}",
            base64_f32(&beats)
        )));
        assert!(
            block.contains("\"rows\":1,") && block.contains("\"ids\":[5, 6, 7, 8, 511]"),
            "{block}"
        );
        assert!(block.contains("\"parents\":[-1, 0, 0, 0, 1,") && block.contains("52, 53]"));
    }
}
