//! Golden test of the 54-d music features against librosa 0.8.1 on the
//! synthetic signals of `tools/music_goldens.py` (fed at 15360 Hz directly).
//! Run with `--nocapture` to see the per-group error table.

#[path = "music_util.rs"]
mod music_util;

use duolando::music::{Extractor, MusicError, FEATURE_DIM, MIN_SAMPLES};
use music_util::*;

fn is_click_track(name: &str) -> bool {
    name.starts_with("click_")
}

#[test]
fn every_golden_signal_matches_librosa_per_group() {
    let ex = Extractor::new();
    let mut failures = Vec::new();
    eprintln!(
        "{:<14} {:>9} {:>9} {:>9} {:>9} {:>9} {:>6} {:>7} {:>8}",
        "signal",
        "mfcc",
        "delta",
        "chroma_in",
        "chroma_all",
        "onset/pk",
        "beatF",
        "tempo",
        "tuning"
    );
    for g in manifest().into_iter().filter(|g| g.name != "stereo_44k") {
        let y = read_pcm16(&g.name);
        assert_eq!(y.len(), g.samples, "{}", g.name);
        let want = read_features(&g.name);
        let f = ex
            .features(&y)
            .unwrap_or_else(|e| panic!("{}: {e}", g.name));
        assert_eq!(f.frames, g.frames, "{}: frame count", g.name);
        assert_eq!(f.data.len(), g.frames * FEATURE_DIM);
        let e = group_errors(&want, &f.data);
        eprintln!(
            "{:<14} {:>9.2e} {:>9.2e} {:>9.2e} {:>9.2e} {:>9.2e} {:>6.3} {:>7.2} {:>8.2}",
            g.name,
            e.mfcc,
            e.delta,
            e.chroma_interior,
            e.chroma_all,
            e.onset_rel,
            e.beat_f,
            f.tempo_bpm,
            ex.parts(&y).unwrap().tuning
        );
        let mut check = |ok: bool, what: String| {
            if !ok {
                failures.push(format!("{}: {what}", g.name));
            }
        };
        check(
            e.mfcc <= MFCC_ABS,
            format!("mfcc {:.3e} > {MFCC_ABS}", e.mfcc),
        );
        check(
            e.delta <= MFCC_ABS,
            format!("delta {:.3e} > {MFCC_ABS}", e.delta),
        );
        check(
            e.chroma_interior <= CHROMA_ABS,
            format!("chroma {:.3e} > {CHROMA_ABS}", e.chroma_interior),
        );
        check(
            e.onset_rel <= ONSET_REL_PEAK,
            format!("onset {:.3e} x peak > {ONSET_REL_PEAK}", e.onset_rel),
        );
        check(
            (f.tempo_bpm - g.tempo).abs() < 1e-3,
            format!("tempo {} != {}", f.tempo_bpm, g.tempo),
        );
        if is_click_track(&g.name) {
            check(
                e.beats_exact,
                format!(
                    "beats {:?} != {:?}",
                    beat_frames(&f.data),
                    beat_frames(&want)
                ),
            );
        } else {
            check(
                e.beat_f >= BEAT_F_MIN,
                format!(
                    "beat F {:.3} < {BEAT_F_MIN}: {:?} vs {:?}",
                    e.beat_f,
                    beat_frames(&f.data),
                    beat_frames(&want)
                ),
            );
        }
    }
    assert!(
        failures.is_empty(),
        "golden mismatches:\n{}",
        failures.join("\n")
    );
}

#[test]
fn tuning_estimate_matches_librosa() {
    let ex = Extractor::new();
    // `short` (3 frames) is left out: librosa 0.8.1's harmonic part is undefined there.
    // scipy 1.12's median_filter(size=(1, 31)) on the Fortran-ordered 3-frame
    // magnitude reads outside the array (NaN or stale memory, varying per run),
    // so neither its tuning nor its chroma is a reference; it has no interior
    // chroma frames either.
    for g in manifest()
        .into_iter()
        .filter(|g| !matches!(g.name.as_str(), "stereo_44k" | "silence" | "short"))
    {
        let p = ex.parts(&read_pcm16(&g.name)).unwrap();
        assert!(
            (p.tuning - g.tuning).abs() < 0.011,
            "{}: tuning {} vs librosa {}",
            g.name,
            p.tuning,
            g.tuning
        );
    }
}

#[test]
fn too_short_and_non_finite_inputs_are_errors() {
    let ex = Extractor::new();
    let short = vec![0.1f32; MIN_SAMPLES - 1];
    assert_eq!(
        ex.features(&short).unwrap_err(),
        MusicError::TooShort {
            got: MIN_SAMPLES - 1,
            needed: MIN_SAMPLES
        }
    );
    assert!(ex.features(&[]).is_err());
    let mut y = vec![0.0f32; 4096];
    y[100] = f32::NAN;
    assert!(matches!(
        ex.features(&y),
        Err(MusicError::NonFinite { index: 100, .. })
    ));
    // exactly the minimum works and gives 3 frames
    assert_eq!(ex.features(&vec![0.01f32; MIN_SAMPLES]).unwrap().frames, 3);
}
