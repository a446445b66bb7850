use crate::duolando::config::{Part, POSE_DIM};
use crate::duolando::motion::{denormalise, gather_part, normalise, scatter_part};
use crate::nn::sampler::{argmax, top_k, Rng};

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
