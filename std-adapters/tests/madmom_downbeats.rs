//! madmom's downbeat activations (Transflower's audio columns 81, 82)
//! against madmom 0.16.1's own classes: tests/fixtures/madmom/ was written
//! by tools/madmom_goldens.py (the whole `RNNDownBeatProcessor` chain on
//! tests/fixtures/music/stereo_44k.flac, its trained networks replaced by
//! two random ones of the same architecture, committed in our format).
//!
//! With `DUOLANDO_MADMOM_NETWORKS=FILE` (madmom's trained networks converted
//! by tools/madmom_weights.py; not committed: CC BY-NC-SA 4.0), one more
//! test holds the engine to madmom's real output in
//! tests/fixtures/transflower_audio/stereo_44k.golden.npy.

use std::path::{Path, PathBuf};

use duolando::audio::decode;
use duolando::music::madmom::{signal_44k, DownbeatRnn, Frontend, RnnFileError};
use duolando::npy::read_f32_2d;

/// Largest |difference| of an input value (log10(1 + x) of filtered
/// magnitudes, values up to ~2): madmom stores the STFT as complex64 and
/// sums the filterbank in f32, we sum in f32 over f64 FFTs.
const INPUT_TOL: f32 = 1e-5;
/// Largest |difference| of an activation (f32 LSTMs, summation order).
const ACT_TOL: f32 = 1e-5;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn stereo_signal() -> Vec<i16> {
    let d = decode(&fixtures().join("music/stereo_44k.flac")).unwrap();
    assert_eq!((d.sample_rate, d.channels), (44_100, 2));
    signal_44k(&d)
}

fn random_rnn() -> DownbeatRnn {
    DownbeatRnn::from_bytes(&std::fs::read(fixtures().join("madmom/random_downbeats.bin")).unwrap())
        .unwrap()
}

/// A network file of zero weights with these sizes (3 outputs).
fn network_file(nets: u32, inputs: u32, layers: u32, hidden: u32) -> Vec<u8> {
    let (i, l, h) = (inputs as usize, layers as usize, hidden as usize);
    let dir = |w: usize| 4 * (w + h + 1) * h + 3 * h;
    let per_net = 2 * dir(i) + (l - 1) * 2 * dir(2 * h) + 2 * h * 3 + 3;
    let mut v = b"DUOMMRNN".to_vec();
    for x in [1, nets, inputs, layers, hidden, 3] {
        v.extend_from_slice(&x.to_le_bytes());
    }
    v.resize(v.len() + nets as usize * per_net * 4, 0);
    v
}

fn max_diff(a: &[f32], b: &[f32]) -> (f32, usize) {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .enumerate()
        .map(|(i, (x, y))| ((x - y).abs(), i))
        .fold((0.0, 0), |m, d| if d.0 > m.0 { d } else { m })
}

#[test]
fn inputs_equal_madmoms_at_20_and_100_fps() {
    let s = stereo_signal();
    let rnn = random_rnn();
    for (fps, golden) in [
        (20.0, "stereo_44k_fps20.input.npy"),
        (100.0, "stereo_44k_fps100.input.npy"),
    ] {
        let g = read_f32_2d(&fixtures().join("madmom").join(golden), Some(314), "golden").unwrap();
        let x = rnn.inputs(&s, fps);
        assert_eq!(x.len() / 314, Frontend::frames(s.len(), fps));
        let (d, i) = max_diff(&x[..g.data.len()], &g.data);
        eprintln!("fps {fps}: inputs within {d:e} of madmom's");
        assert!(
            d <= INPUT_TOL,
            "fps {fps}: input differs by {d} at row {}, column {}",
            i / 314,
            i % 314
        );
        // not a vacuous match: the rows move, and the differences are in it
        assert!(g.data.iter().any(|&v| v > 0.5) && g.data[314..].iter().any(|&v| v > 0.0));
    }
}

#[test]
fn activations_equal_madmoms_random_networks() {
    let s = stereo_signal();
    let rnn = random_rnn();
    assert_eq!(rnn.networks(), 2);
    for (fps, golden) in [
        (20.0, "stereo_44k_fps20.act.npy"),
        (100.0, "stereo_44k_fps100.act.npy"),
    ] {
        let g = read_f32_2d(&fixtures().join("madmom").join(golden), Some(2), "golden").unwrap();
        let a: Vec<f32> = rnn.activations(&s, fps).unwrap().concat();
        assert_eq!(a.len(), g.data.len(), "fps {fps}: rows");
        let (d, i) = max_diff(&a, &g.data);
        eprintln!("fps {fps}: activations within {d:e} of madmom's");
        assert!(
            d <= ACT_TOL,
            "fps {fps}: activation differs by {d} at row {}, column {}",
            i / 2,
            i % 2
        );
        let spread = g.data.iter().cloned().fold(f32::MIN, f32::max)
            - g.data.iter().cloned().fold(f32::MAX, f32::min);
        assert!(
            spread > 100.0 * ACT_TOL,
            "fps {fps}: golden too flat to test ({spread})"
        );
    }
}

#[test]
fn a_bad_network_file_is_refused_by_name() {
    let good = std::fs::read(fixtures().join("madmom/random_downbeats.bin")).unwrap();
    assert!(matches!(
        DownbeatRnn::from_bytes(b"RIFF1234"),
        Err(RnnFileError::Magic { .. })
    ));
    assert!(matches!(
        DownbeatRnn::from_bytes(&good[..20]),
        Err(RnnFileError::Magic { .. })
    ));
    let mut v = good.clone();
    v[8] = 2;
    assert_eq!(
        DownbeatRnn::from_bytes(&v).err(),
        Some(RnnFileError::Version(2))
    );
    for (field, at, value) in [
        ("networks", 12, 0u32),
        ("inputs", 16, 0),
        ("layers", 20, 99),
        ("hidden", 24, 0),
        ("outputs", 28, 2),
    ] {
        let mut v = good.clone();
        v[at..at + 4].copy_from_slice(&value.to_le_bytes());
        match DownbeatRnn::from_bytes(&v) {
            Err(RnnFileError::Header {
                field: f,
                value: got,
                ..
            }) => assert_eq!((f, got), (field, value)),
            other => panic!("{field} = {value}: {:?}", other.err()),
        }
    }
    // a whole, valid file of networks that take other inputs than the front end's 314
    let small = network_file(1, 5, 1, 1);
    assert_eq!(
        duolando::music::madmom::Ensemble::from_bytes(&small)
            .unwrap()
            .inputs(),
        5
    );
    match DownbeatRnn::from_bytes(&small) {
        Err(RnnFileError::Header {
            field: "inputs",
            value: 5,
            ..
        }) => {}
        other => panic!("{:?}", other.err()),
    }
    let mut v = good.clone();
    v[16..20].copy_from_slice(&313u32.to_le_bytes());
    assert!(matches!(
        DownbeatRnn::from_bytes(&v),
        Err(RnnFileError::Length { .. })
    ));
    assert!(matches!(
        DownbeatRnn::from_bytes(&good[..good.len() - 4]),
        Err(RnnFileError::Length { .. })
    ));
    let mut long = good.clone();
    long.extend_from_slice(&[0; 4]);
    assert!(matches!(
        DownbeatRnn::from_bytes(&long),
        Err(RnnFileError::Length { .. })
    ));
    let mut nan = good.clone();
    let at = 32 + 4 * 1000;
    nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(matches!(
        DownbeatRnn::from_bytes(&nan),
        Err(RnnFileError::NonFinite { index: 1000, .. })
    ));
    // finite weights that overflow f32 on real audio: refused when run, by name
    let mut huge = network_file(1, 314, 1, 1);
    for c in huge[32..].chunks_exact_mut(4) {
        c.copy_from_slice(&f32::MAX.to_le_bytes());
    }
    let r = DownbeatRnn::from_bytes(&huge).unwrap();
    match r.activations(&stereo_signal(), 20.0) {
        Err(RnnFileError::NonFiniteOutput { frame: 0 }) => {}
        other => panic!("{other:?}"),
    }
    // random corruptions: refused or parsed, never a panic; a parsed one runs
    let mut state = 0x9e3779b97f4a7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let signal: Vec<i16> = (0..8820).map(|i| ((i * 37) % 2000) as i16 - 1000).collect();
    let (mut parsed, mut refused) = (0, 0);
    for _ in 0..300 {
        let mut v = good.clone();
        for _ in 0..1 + next() % 4 {
            let at = (next() % 64) as usize
                + if next() % 2 == 0 {
                    0
                } else {
                    (next() as usize) % v.len()
                };
            let at = at.min(v.len() - 1);
            v[at] = next() as u8;
        }
        match DownbeatRnn::from_bytes(&v) {
            Ok(r) => {
                parsed += 1;
                match r.activations(&signal, 20.0) {
                    Ok(a) => assert!(a.len() == 4 && a.iter().flatten().all(|v| v.is_finite())),
                    Err(e) => assert!(matches!(e, RnnFileError::NonFiniteOutput { .. }), "{e}"),
                }
            }
            Err(_) => refused += 1,
        }
    }
    assert!(
        parsed > 0 && refused > 0,
        "{parsed} parsed, {refused} refused"
    );
    // every truncation of the file is refused, none panics
    for n in (0..good.len()).step_by(997) {
        assert!(DownbeatRnn::from_bytes(&good[..n]).is_err(), "{n} bytes");
    }
}

/// madmom's trained networks against madmom's own output on the same file
/// (the authors' call: `RNNDownBeatProcessor()(wav, fps=20)`), where the
/// converted networks are given. Not in CI (the networks are not ours to ship).
#[test]
fn trained_networks_equal_madmom_where_given() {
    let Some(path) = std::env::var_os("DUOLANDO_MADMOM_NETWORKS") else {
        eprintln!("DUOLANDO_MADMOM_NETWORKS not set: madmom's trained networks not checked");
        return;
    };
    let rnn = DownbeatRnn::read(Path::new(&path)).unwrap();
    assert_eq!(rnn.networks(), 8);
    let g = read_f32_2d(
        &fixtures().join("transflower_audio/stereo_44k.golden.npy"),
        Some(83),
        "golden",
    )
    .unwrap();
    let a = rnn.activations(&stereo_signal(), 20.0).unwrap();
    assert!(a.len() >= g.rows);
    let mut worst = 0f32;
    for (t, row) in g.data.chunks_exact(83).enumerate() {
        for k in 0..2 {
            worst = worst.max((a[t][k] - row[81 + k]).abs());
        }
    }
    eprintln!(
        "madmom's trained networks: largest activation difference {worst:e} over {} rows",
        g.rows
    );
    assert!(worst <= ACT_TOL, "{worst}");
}
