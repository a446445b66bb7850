//! The session's rings: every run of held rows comes back in order (across
//! the wrap, in f32 and f16 storage), and reads of evicted or future rows
//! are errors.

use crate::arena::Arena;
use crate::error::Error;
use crate::nn::kv_store::{KvRing, KvType};
use crate::nn::ring::RowRing;

fn row(i: usize, w: usize) -> Vec<f32> {
    // f16-exact values (small integers and halves).
    (0..w).map(|j| (i * 7 + j) as f32 * 0.5 - 3.0).collect()
}

#[test]
fn kv_ring_serves_every_held_run_in_order() {
    for kv in [KvType::F32, KvType::F16] {
        let (cap, w) = (5usize, 3usize);
        let mut mem = vec![0u8; 4096];
        let mut a = Arena::new(&mut mem);
        let mut ring = KvRing::carve(&mut a, kv, cap, w).unwrap();
        for n in 1..=13 {
            ring.push(&row(n - 1, w)).unwrap();
            assert_eq!(ring.len(), n);
            let oldest = n.saturating_sub(cap);
            for lo in oldest..=n {
                for hi in lo..=n {
                    let rows = ring.rows(lo, hi).unwrap();
                    assert_eq!(rows.rows(w), hi - lo, "{kv:?} n={n} [{lo},{hi})");
                    for (j, i) in (lo..hi).enumerate() {
                        let mut got = vec![0.0f32; w];
                        rows.axpy(1.0, j, w, 0, &mut got);
                        assert_eq!(got, row(i, w), "{kv:?} n={n} [{lo},{hi}) row {i}");
                    }
                }
            }
            if oldest > 0 {
                assert!(
                    matches!(ring.rows(oldest - 1, n), Err(Error::Evicted { .. })),
                    "{kv:?} n={n}: evicted row served"
                );
            }
            assert!(
                matches!(ring.rows(oldest, n + 1), Err(Error::Evicted { .. })),
                "{kv:?} n={n}: future row served"
            );
            assert!(
                ring.rows(n, n - 1).is_err(),
                "{kv:?} n={n}: reversed range served"
            );
        }
        assert!(ring.push(&[0.0; 2]).is_err(), "wrong width accepted");
    }
}

#[test]
fn f16_kv_ring_rounds_to_nearest() {
    let mut mem = vec![0u8; 1024];
    let mut a = Arena::new(&mut mem);
    let mut ring = KvRing::carve(&mut a, KvType::F16, 2, 2).unwrap();
    ring.push(&[1.0 + 1e-4, -65504.0]).unwrap();
    let mut got = [0.0f32; 2];
    ring.rows(0, 1).unwrap().axpy(1.0, 0, 2, 0, &mut got);
    assert_eq!(got, [half::f16::from_f32(1.0 + 1e-4).to_f32(), -65504.0]);
}

#[test]
fn row_ring_serves_held_rows_only() {
    let mut mem = vec![0u8; 1024];
    let mut a = Arena::new(&mut mem);
    let mut ring = RowRing::carve(&mut a, 3, 4).unwrap();
    assert!(matches!(ring.row(0), Err(Error::Evicted { .. })));
    for i in 0..8 {
        ring.push(&row(i, 4)).unwrap();
        for j in 0..=i {
            match ring.row(j) {
                Ok(r) => {
                    assert!(j + 3 > i, "row {j} served after eviction at len {}", i + 1);
                    assert_eq!(r, &row(j, 4)[..]);
                }
                Err(Error::Evicted { .. }) => assert!(j + 3 <= i),
                Err(e) => panic!("{e:?}"),
            }
        }
    }
}
