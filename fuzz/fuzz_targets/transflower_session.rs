//! A Transflower streaming session on the paper fixture driven by an
//! arbitrary config and up to `MAX_OPS` operations: audio pushes of 0..=3
//! rows (sometimes ragged; NaN, ±Inf, huge, at-the-limit, subnormal and
//! raw-bit values), steps (seeded, or with a caller's base sample that may
//! be the wrong length or hold NaN), pulls (also into a short buffer) and
//! resets, in any order. Two sessions take every operation:
//!
//! - `main`: `Session::new`, stepped by its own `step` / `step_with`;
//! - `twin`: `Session::new_batched`, seeded steps through a `StepBatch`
//!   (`step_with` is refused on it: `State`), caller-noise steps skipped.
//!
//! Checked after every operation (docs/ROBUSTNESS.md §2): no panic; every
//! answer is the one a shadow model predicts (`Ragged`, `NonFinite` at the
//! first NaN/Inf, `OutOfRange` at the first |v| > 1e6, `Backlog` of the
//! audio feed or of the pending frames, `Length` of a base sample), and a
//! refused call changes nothing (the sessions stay bit-identical, rows held
//! and frames made as the shadow says); every frame is finite and main's
//! equals twin's bit for bit while both stepped the same way.
//! `DUO_FUZZ_TRACE` prints every operation.
#![no_main]

use std::sync::OnceLock;

use arbitrary::{Result as AResult, Unstructured};
use duolando_core::error::{Buffer, Error};
use duolando_core::format::DuoFile;
use duolando_core::input::MAX_MUSIC_FEATURE;
use duolando_core::nn::kv_store::KvType;
use duolando_core::transflower::model::Model;
use duolando_core::transflower::session::{batched_session_bytes, session_bytes, Session, SessionConfig, StepBatch};
use libfuzzer_sys::fuzz_target;

const MAX_OPS: usize = 160;

#[repr(C, align(64))]
struct Aligned<T: ?Sized>(T);
/// `DuoFile::parse` wants a 64-byte aligned buffer.
static PAPER: &Aligned<[u8]> = &Aligned(*include_bytes!("../../tests/fixtures/transflower_paper/model.duo"));

fn model() -> &'static Model<'static> {
    static D: OnceLock<DuoFile<'static>> = OnceLock::new();
    static M: OnceLock<Model<'static>> = OnceLock::new();
    M.get_or_init(|| {
        let duo = D.get_or_init(|| DuoFile::parse(&PAPER.0).expect("paper model.duo parses"));
        Model::from_duo(duo).expect("paper binds as Transflower")
    })
}

/// `DUO_FUZZ_TRACE` set: every operation is printed.
fn trace() -> bool {
    static T: OnceLock<bool> = OnceLock::new();
    *T.get_or_init(|| std::env::var_os("DUO_FUZZ_TRACE").is_some())
}

fn value(u: &mut Unstructured<'_>) -> AResult<f32> {
    Ok(match u.int_in_range(0..=15u8)? {
        0 => f32::NAN,
        1 => f32::INFINITY,
        2 => f32::NEG_INFINITY,
        3 => MAX_MUSIC_FEATURE,
        4 => -MAX_MUSIC_FEATURE,
        5 => 2.0e6,
        6 => f32::MIN_POSITIVE / 4.0,
        7 => f32::from_bits(u.arbitrary()?),
        _ => (u.int_in_range(-3000..=3000i32)? as f32) / 1000.0,
    })
}

/// The first refusal `input::check` gives (NaN/Inf first, then the limit).
fn check_of(x: &[f32]) -> Option<Error> {
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Some(Error::NonFinite { buffer: Buffer::Features, index });
    }
    x.iter().position(|v| v.abs() > MAX_MUSIC_FEATURE).map(|index| Error::OutOfRange { buffer: Buffer::Features, index })
}

fn run(data: &[u8]) -> AResult<()> {
    let m = model();
    let cfg = &m.cfg;
    let mut u = Unstructured::new(data);
    let sc = SessionConfig {
        refresh: u.int_in_range(1..=6)?,
        kv: if u.arbitrary()? { KvType::F16 } else { KvType::F32 },
        rolling: u.arbitrary()?,
        input_buffer_rows: u.int_in_range(0..=8)?,
        pending_frames: u.int_in_range(1..=4)?,
    };
    if trace() {
        eprintln!("{sc:?}");
    }
    let (c, h) = (cfg.channels(), cfg.output_length as usize);
    let audio = cfg.inputs().len() - 1;
    let d = cfg.inputs[audio].dim as usize;
    let window = cfg.max_window();
    let cap = window + sc.input_buffer_rows as usize;
    let seed: Vec<f32> = (0..cfg.output_input().length as usize * c).map(|i| ((i % 7) as f32 - 3.0) / 4.0).collect();
    let mut a1 = vec![0u8; session_bytes(cfg, &sc).expect("bytes")];
    let mut a2 = vec![0u8; batched_session_bytes(cfg, &sc).expect("bytes")];
    let mut ab = vec![0u8; StepBatch::bytes(cfg).expect("batch bytes")];
    let rng = u.arbitrary::<u8>()? as u64;
    let mut main = Session::new(m, &sc, &seed, &[], rng, &mut a1).expect("session");
    let mut twin = Session::new_batched(m, &sc, &seed, &[], rng, &mut a2).expect("twin");
    let mut batch = StepBatch::new(m, &mut ab).expect("batch");
    // Shadow: rows held, frames pending, whether twin still matches main.
    let (mut held, mut pending, mut same) = (0usize, 0usize, true);
    let mut fm = vec![0f32; c];
    let mut ft = vec![0f32; c];
    for _ in 0..MAX_OPS {
        if u.is_empty() {
            break;
        }
        match u.int_in_range(0..=5u8)? {
            0 | 1 => {
                let rows = u.int_in_range(0..=3usize)?;
                let ragged = u.ratio(1, 8)?;
                let n = rows * d + ragged as usize;
                let mut x = Vec::with_capacity(n);
                for _ in 0..n {
                    x.push(if u.ratio(1, 6)? { value(&mut u)? } else { 0.25 });
                }
                let want = if ragged {
                    Err(Error::Ragged { buffer: Buffer::Features, len: n, row: d })
                } else if let Some(e) = check_of(&x) {
                    Err(e)
                } else if held + rows > cap {
                    Err(Error::Backlog { buffer: Buffer::Features, held: held + rows, capacity: cap })
                } else {
                    Ok(())
                };
                if trace() {
                    eprintln!("push {rows} rows ragged {ragged}: max |x| {:e} -> {want:?}", x.iter().fold(0f32, |a, v| a.max(v.abs())));
                }
                assert_eq!(main.push(audio, &x), want, "push of {rows} rows (ragged {ragged})");
                assert_eq!(twin.push(audio, &x), want, "twin push");
                if want.is_ok() {
                    held += rows;
                }
            }
            2 => {
                // A seeded step: main alone, twin through the batch.
                let ready = held >= window;
                let want = if pending >= sc.pending_frames as usize { Err(Error::Backlog { buffer: Buffer::Output, held: pending, capacity: sc.pending_frames as usize }) } else { Ok(ready) };
                if trace() {
                    eprintln!("step -> {want:?} (held {held}, pending {pending})");
                }
                assert_eq!(main.step(), want, "step");
                let twin_n = batch.step(&mut [&mut twin]).expect("batch step");
                assert_eq!(twin_n, usize::from(want == Ok(true)), "batch stepped");
                if want == Ok(true) {
                    held -= 1;
                    pending += 1;
                }
            }
            3 => {
                // The caller's base sample (main only: twin cannot take one).
                let len = if u.ratio(1, 6)? { c * h - 1 } else { c * h };
                let mut z = vec![0.1f32; len];
                if u.ratio(1, 6)? && len > 0 {
                    z[len / 2] = f32::NAN;
                }
                let want = if len != c * h {
                    Err(Error::Length { buffer: Buffer::Features, len, expected: c * h })
                } else if z.iter().any(|v| !v.is_finite()) {
                    Err(Error::NonFinite { buffer: Buffer::Features, index: len / 2 })
                } else if pending >= sc.pending_frames as usize {
                    Err(Error::Backlog { buffer: Buffer::Output, held: pending, capacity: sc.pending_frames as usize })
                } else {
                    Ok(held >= window)
                };
                if trace() {
                    eprintln!("step_with len {len} -> {want:?}");
                }
                assert_eq!(main.step_with(&z), want, "step_with");
                if want == Ok(true) {
                    // Twin keeps pace on the feeds with a seeded step: its
                    // frames differ from here on.
                    assert_eq!(batch.step(&mut [&mut twin]).expect("batch step"), 1);
                    same = false;
                    held -= 1;
                    pending += 1;
                }
            }
            4 => {
                let short = u.ratio(1, 8)?;
                let len = if short { c - 1 } else { c };
                let (nm, nt) = (main.pull(&mut fm[..len]), twin.pull(&mut ft[..len]));
                let want = usize::from(!short && pending > 0);
                assert_eq!((nm, nt), (want, want), "pull");
                if trace() {
                    eprintln!("pull -> {want}: {:?} / {:?}", &fm[..3], &ft[..3]);
                }
                if want == 1 {
                    pending -= 1;
                    assert!(fm.iter().chain(&ft).all(|v| v.is_finite()), "non-finite frame");
                    if same {
                        assert!(fm == ft, "main and twin differ");
                    }
                }
            }
            _ => {
                let r = u.arbitrary::<u8>()? as u64;
                main.reset(Some(r));
                twin.reset(Some(r));
                (held, pending, same) = (0, 0, true);
            }
        }
        assert_eq!((main.held(audio), twin.held(audio)), (held, held), "rows held");
        assert_eq!((main.pending(), twin.pending()), (pending, pending), "frames pending");
    }
    Ok(())
}

fuzz_target!(|data: &[u8]| {
    let _ = run(data);
});
