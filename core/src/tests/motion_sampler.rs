use crate::duolando::config::{Part, POSE_DIM};
use crate::duolando::motion::{denormalise, gather_part, normalise, scatter_part};
use crate::nn::sampler::{argmax, softmax_top_k, top_k, Rng, Sampling, MAX_TOP_K};

fn pose(seed: u32) -> Vec<f32> {
    (0..POSE_DIM)
        .map(|i| (((i as u32).wrapping_mul(2654435761u32) ^ seed) % 2000) as f32 / 1000.0 - 1.0)
        .collect()
}

#[test]
fn normalise_round_trip() {
    for s in 0..20 {
        let raw = pose(s);
        let mut n = vec![0.0; POSE_DIM];
        normalise(&raw, &mut n);
        // Root channel keeps the absolute pelvis; body joints are pelvis-relative.
        assert_eq!(&n[..3], &raw[..3]);
        assert!((n[3 * 5] - (raw[15] - raw[0])).abs() < 1e-6);
        // Left index1 (25) relative to the left wrist (20), scaled by 10.
        assert!((n[75] - (raw[75] - raw[60]) * 10.0).abs() < 1e-5);
        // Right thumb3 (54) relative to the right wrist (21).
        assert!((n[162 + 2] - (raw[164] - raw[65]) * 10.0).abs() < 1e-5);
        denormalise(&mut n);
        for (a, b) in n.iter().zip(&raw) {
            assert!((a - b).abs() < 1e-5, "{a} {b}");
        }
    }
}

#[test]
fn parts_cover_every_joint_once_and_first_joint_is_zeroed() {
    let raw = pose(7);
    let mut full = vec![f32::NAN; POSE_DIM];
    let mut rot = vec![f32::NAN; 495];
    for p in Part::ALL {
        let j = p.joints().len();
        let mut x = vec![0.0; 3 * j];
        gather_part(p, &raw, &mut x);
        assert_eq!(&x[..3], &[0.0, 0.0, 0.0]);
        assert_eq!(
            &x[3..6],
            &raw[3 * p.joints()[1] as usize..3 * p.joints()[1] as usize + 3]
        );
        let first = p.joints()[0] as usize;
        x[..3].copy_from_slice(&raw[3 * first..3 * first + 3]);
        scatter_part(p, 3, &x, &mut full);
        let r: Vec<f32> = (0..9 * j).map(|i| i as f32).collect();
        scatter_part(p, 9, &r, &mut rot);
    }
    assert_eq!(full, raw);
    assert!(rot.iter().all(|v| v.is_finite()));
}

#[test]
fn greedy_and_top_k() {
    assert_eq!(argmax(&[0.1, 0.5, 0.5, -1.0]), 1);
    assert_eq!(argmax(&[f32::NAN, 0.2, 0.1]), 1);
    assert_eq!(argmax(&[]), 0);
    let logits = [0.0, 3.0, 1.0, 2.0, 3.0];
    let mut rng = Rng(42);
    let mut seen = [0u32; 5];
    for _ in 0..1000 {
        seen[top_k(&logits, 3, &mut rng) as usize] += 1;
    }
    // Top-3 = {1, 4, 3} uniformly; 0 and 2 never.
    assert_eq!((seen[0], seen[2]), (0, 0));
    for i in [1, 3, 4] {
        assert!((250..420).contains(&seen[i]), "{seen:?}");
    }
    assert_eq!(top_k(&logits, 1, &mut rng), 1);
    // Same seed, same sequence.
    let (mut a, mut b) = (Rng(9), Rng(9));
    assert!((0..50).all(|_| top_k(&logits, 4, &mut a) == top_k(&logits, 4, &mut b)));
}

/// Softmax sampling draws each of the k best with its probability under
/// softmax(logits / t) (a chi-square-free check: every count within 5
/// standard deviations of its expectation over 20 000 draws), never a
/// token outside them, approaches greedy at a small t and uniform at a
/// large one, and one draw per call (the same RNG state after as TopK).
#[test]
fn softmax_sampling_follows_the_tempered_distribution() {
    let logits = [0.5f32, 2.0, -1.0, 1.0, 2.0, f32::NAN, 0.0];
    let n = 20_000;
    for (k, milli) in [(3usize, 1000u32), (7, 1000), (4, 500), (7, 2500)] {
        let t = milli as f32 / 1000.0;
        // The k best by logit, lower id first on ties (NaN never counts).
        let mut order: Vec<usize> = (0..logits.len()).filter(|&i| !logits[i].is_nan()).collect();
        order.sort_by(|&a, &b| logits[b].partial_cmp(&logits[a]).unwrap().then(a.cmp(&b)));
        order.truncate(k.min(order.len()));
        let z: f64 = order
            .iter()
            .map(|&i| ((logits[i] - 2.0) as f64 / t as f64).exp())
            .sum();
        let mut rng = Rng(7);
        let mut seen = [0u32; 7];
        for _ in 0..n {
            seen[softmax_top_k(&logits, k, milli, &mut rng) as usize] += 1;
        }
        for i in 0..logits.len() {
            let p = if order.contains(&i) {
                ((logits[i] - 2.0) as f64 / t as f64).exp() / z
            } else {
                0.0
            };
            let (mean, sd) = (n as f64 * p, (n as f64 * p * (1.0 - p)).sqrt());
            assert!(
                (seen[i] as f64 - mean).abs() <= 5.0 * sd + 0.5,
                "k {k} t {t}: token {i} drawn {} times, expected {mean:.0} (sd {sd:.1}): {seen:?}",
                seen[i]
            );
        }
    }
    // Near greedy at a small temperature (1 vs 2 apart by 1: e^-1000), and
    // equal logits 1 and 4 stay equally likely.
    let mut rng = Rng(3);
    let mut seen = [0u32; 7];
    for _ in 0..2000 {
        seen[softmax_top_k(&logits, 7, 1, &mut rng) as usize] += 1;
    }
    assert_eq!(seen[1] + seen[4], 2000, "{seen:?}");
    assert!((800..1200).contains(&seen[1]), "{seen:?}");
    // One draw per call, and the same seed gives the same sequence.
    let (mut a, mut b) = (Rng(9), Rng(9));
    for _ in 0..50 {
        let x = softmax_top_k(&logits, 5, 800, &mut a);
        assert_eq!(x, softmax_top_k(&logits, 5, 800, &mut b));
    }
    let (mut a, mut b) = (Rng(11), Rng(11));
    softmax_top_k(&logits, 5, 800, &mut a);
    b.next_u64();
    assert_eq!(a, b);
    // Empty and all-NaN logits give 0, as the other rules.
    assert_eq!(softmax_top_k(&[], 3, 1000, &mut Rng(1)), 0);
    assert_eq!(softmax_top_k(&[f32::NAN; 4], 3, 1000, &mut Rng(1)), 0);
}

/// The rules' settings: k in 1..=MAX_TOP_K, a temperature in
/// 1..=100 000 thousandths, each refused by name; the RNG seed and k read
/// back for both sampling rules.
#[test]
fn sampling_settings_are_checked_by_name() {
    use crate::error::Setting;
    let soft = |k, t| Sampling::Softmax {
        k,
        temperature_milli: t,
        rng_seed: 5,
    };
    assert_eq!(soft(3, 700).check(), Ok(()));
    assert_eq!(
        soft(0, 700).check(),
        Err((Setting::TopK, 0, MAX_TOP_K as u32))
    );
    assert_eq!(soft(3, 0).check(), Err((Setting::Temperature, 0, 100_000)));
    assert_eq!(
        soft(3, 100_001).check(),
        Err((Setting::Temperature, 100_001, 100_000))
    );
    assert_eq!(
        Sampling::TopK { k: 65, rng_seed: 1 }.check(),
        Err((Setting::TopK, 65, 64))
    );
    assert_eq!(Sampling::Greedy.check(), Ok(()));
    assert_eq!((soft(3, 700).k(), soft(3, 700).rng_seed()), (Some(3), 5));
    assert_eq!(
        (Sampling::Greedy.k(), Sampling::Greedy.rng_seed()),
        (None, 0)
    );
}
