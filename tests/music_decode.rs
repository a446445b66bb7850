//! Decoded-file test: a committed stereo 44.1 kHz FLAC through
//! `audio::load_mono` (symphonia, mono mix, our resampler) against the
//! original loader's view of it (mean of channels, libsamplerate
//! SINC_MEDIUM to 15360 Hz) and librosa 0.8.1's features of that; plus the
//! error paths (missing, garbage, truncated files name the file).

#[path = "music_util.rs"]
mod music_util;

use duolando::audio::{load_mono, AudioError};
use duolando::music::{Extractor, SAMPLE_RATE};
use music_util::*;

/// Resampler deviation from libsamplerate SINC_MEDIUM, max abs over interior samples
/// (measured 8.3e-5, rms 6.5e-6).
const RESAMPLE_ABS: f32 = 2e-4;
/// Feature deviation caused by that resampler difference (measured: MFCC 0.14,
/// delta 0.081, chroma 1.5e-6, onset 5.7e-5 x peak; see docs/MUSIC.md).
const DECODED_MFCC_ABS: f32 = 0.3;
const DECODED_CHROMA_ABS: f32 = 1e-4;
const DECODED_ONSET_REL: f32 = 1e-3;

#[test]
fn flac_decodes_mixes_and_resamples_close_to_the_original_loader() {
    let y = load_mono(dir().join("stereo_44k.flac"), SAMPLE_RATE).expect("decode flac");
    let (_, want) = read_npy_f32(&dir().join("stereo_44k_mono_15360.npy"));
    assert_eq!(y.len(), want.len(), "length after resampling");
    let edge = 64;
    let err = y[edge..y.len() - edge]
        .iter()
        .zip(&want[edge..want.len() - edge])
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    let rms = (y
        .iter()
        .zip(&want)
        .map(|(a, b)| ((a - b) as f64).powi(2))
        .sum::<f64>()
        / y.len() as f64)
        .sqrt();
    eprintln!(
        "resampler vs libsamplerate sinc_medium: max abs {err:.3e} (interior), rms {rms:.3e}"
    );
    assert!(err <= RESAMPLE_ABS, "resampler deviation {err}");

    let f = Extractor::new().features(&y).unwrap();
    let golden = read_features("stereo_44k");
    assert_eq!(f.data.len(), golden.len());
    let e = group_errors(&golden, &f.data);
    // and the feature code alone on the exact same samples
    let f_same = Extractor::new().features(&want).unwrap();
    let e_same = group_errors(&golden, &f_same.data);
    eprintln!("decoded file, our loader: {e:?}\ndecoded file, librosa's samples: {e_same:?}");
    assert!(
        e_same.mfcc <= MFCC_ABS
            && e_same.delta <= MFCC_ABS
            && e_same.chroma_interior <= CHROMA_ABS
            && e_same.onset_rel <= ONSET_REL_PEAK
    );
    assert!(e_same.beats_exact);
    assert!(
        e.mfcc <= DECODED_MFCC_ABS && e.delta <= DECODED_MFCC_ABS,
        "{e:?}"
    );
    assert!(
        e.chroma_interior <= DECODED_CHROMA_ABS && e.onset_rel <= DECODED_ONSET_REL,
        "{e:?}"
    );
    assert!(e.beat_f >= BEAT_F_MIN, "{e:?}");
}

#[test]
fn wav_is_read_and_channels_are_averaged() {
    let path = std::env::temp_dir().join(format!("duolando_music_{}.wav", std::process::id()));
    // a hand-written 16-bit stereo PCM WAV at 15360 Hz
    let mut data = Vec::new();
    for i in 0..2000i32 {
        data.extend_from_slice(&((i * 7 % 2000 - 1000) as i16).to_le_bytes());
        data.extend_from_slice(&1000i16.to_le_bytes());
    }
    let mut wav = Vec::new();
    wav.extend_from_slice(b"RIFF");
    wav.extend_from_slice(&(36 + data.len() as u32).to_le_bytes());
    wav.extend_from_slice(b"WAVEfmt ");
    wav.extend_from_slice(&16u32.to_le_bytes());
    wav.extend_from_slice(&1u16.to_le_bytes()); // PCM
    wav.extend_from_slice(&2u16.to_le_bytes()); // channels
    wav.extend_from_slice(&15360u32.to_le_bytes());
    wav.extend_from_slice(&(15360u32 * 4).to_le_bytes());
    wav.extend_from_slice(&4u16.to_le_bytes());
    wav.extend_from_slice(&16u16.to_le_bytes());
    wav.extend_from_slice(b"data");
    wav.extend_from_slice(&(data.len() as u32).to_le_bytes());
    wav.extend_from_slice(&data);
    std::fs::write(&path, &wav).unwrap();
    let y = load_mono(&path, SAMPLE_RATE).unwrap();
    assert_eq!(y.len(), 2000);
    for (i, v) in y.iter().enumerate() {
        let l = (i as i32 * 7 % 2000 - 1000) as f32 / 32768.0;
        assert_eq!(*v, (l + 1000.0 / 32768.0) * 0.5);
    }
    std::fs::remove_file(&path).ok();
}

#[test]
fn bad_files_are_errors_that_name_the_file() {
    let missing = dir().join("no_such_song.mp3");
    let e = load_mono(&missing, SAMPLE_RATE).unwrap_err();
    assert!(matches!(e, AudioError::Io { .. }), "{e}");
    assert!(e.to_string().contains("no_such_song.mp3"));

    let tmp = std::env::temp_dir();
    let garbage = tmp.join(format!("duolando_garbage_{}.mp3", std::process::id()));
    std::fs::write(
        &garbage,
        b"this is not audio at all, just text bytes................",
    )
    .unwrap();
    let e = load_mono(&garbage, SAMPLE_RATE).unwrap_err();
    assert!(e.to_string().contains("duolando_garbage_"), "{e}");
    assert!(e.to_string().contains("expected"), "{e}");

    let truncated = tmp.join(format!("duolando_trunc_{}.wav", std::process::id()));
    std::fs::write(&truncated, b"RIFF\x24\x00\x00\x00WAVEfmt ").unwrap();
    let e = load_mono(&truncated, SAMPLE_RATE).unwrap_err();
    assert!(matches!(e, AudioError::Wav { .. }), "{e}");
    assert!(e.to_string().contains("duolando_trunc_"), "{e}");

    let empty = tmp.join(format!("duolando_empty_{}.flac", std::process::id()));
    std::fs::write(&empty, b"").unwrap();
    assert!(load_mono(&empty, SAMPLE_RATE).is_err());
    for p in [garbage, truncated, empty] {
        std::fs::remove_file(p).ok();
    }
}

/// MP3 (LAME 3.100, 128 kb/s CBR, made from the same 2 s stereo clip:
/// `lame -b 128`), whose encoder delay and padding are recorded in the LAME
/// tag. With gapless trimming the decoded clip has the source's length and
/// no time shift; without it, ~1105 extra samples at 44.1 kHz would lead.
#[test]
fn mp3_is_trimmed_gaplessly_and_matches_the_source() {
    let y = load_mono(dir().join("stereo_44k.mp3"), SAMPLE_RATE).expect("decode mp3");
    let (_, want) = read_npy_f32(&dir().join("stereo_44k_mono_15360.npy"));
    assert_eq!(
        y.len(),
        want.len(),
        "decoded MP3 length (encoder delay/padding not trimmed?)"
    );
    // The best alignment lag must be 0 (a leftover encoder delay would shift it by ~385 samples at 15360 Hz).
    let corr = |lag: isize| -> f64 {
        let mut s = 0f64;
        for i in 0..want.len() as isize {
            let j = i + lag;
            if j >= 0 && (j as usize) < y.len() {
                s += want[i as usize] as f64 * y[j as usize] as f64;
            }
        }
        s
    };
    let best = (-600isize..=600)
        .max_by(|&a, &b| corr(a).partial_cmp(&corr(b)).unwrap())
        .unwrap();
    let rms_err = (y
        .iter()
        .zip(&want)
        .map(|(a, b)| ((a - b) as f64).powi(2))
        .sum::<f64>()
        / y.len() as f64)
        .sqrt();
    let rms = (want.iter().map(|a| (*a as f64).powi(2)).sum::<f64>() / want.len() as f64).sqrt();
    eprintln!("mp3: best lag {best}, rms error {rms_err:.3e} vs signal rms {rms:.3e}");
    assert_eq!(best, 0, "decoded MP3 is shifted by {best} samples");
    // Lossy coding at 128 kb/s: error well below the signal (measured figure printed above).
    assert!(
        rms_err < 0.1 * rms,
        "MP3 rms error {rms_err} vs signal rms {rms}"
    );
}
