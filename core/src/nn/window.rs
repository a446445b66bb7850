//! The GPT window schedule of the authors' chunked sampling
//! (`sample(shift=s)`), shared by every family whose GPT sees a window of
//! its last `m` tokens: step `k` sees `window_context(k, m, s)` tokens.
//! `s = m` is a window that slides every step (Bailando's `AC.eval`);
//! smaller shifts jump the window start by `m + 1 - s` tokens at a time,
//! which lets a streaming session keep the window's keys and values
//! between jumps (docs/STREAMING.md §3.5).

/// Context length of GPT step `k` under the authors' chunked window
/// (`sample(shift=s)`): `k+1` for `k < m`, then
/// `s + (k - m - 1) mod (m - s + 1)` (Python modulo).
pub fn window_context(k: usize, m: usize, s: usize) -> usize {
    if k < m {
        return k + 1;
    }
    let period = (m + 1).saturating_sub(s).max(1) as i64;
    let r = (k as i64 - m as i64 - 1).rem_euclid(period);
    s + r as usize
}

/// Start (token index) of the GPT window of step `k`.
pub fn window_start(k: usize, m: usize, s: usize) -> usize {
    k + 1 - window_context(k, m, s)
}

/// The first step after `k` whose window starts later than step `k`'s,
/// and that start: `(k2, lo2)` (window starts never decrease and move at
/// least every `m` steps).
pub fn next_window(k: usize, m: usize, s: usize) -> (usize, usize) {
    let lo = window_start(k, m, s);
    let mut k2 = k + 1;
    while window_start(k2, m, s) == lo && k2 <= k + m.max(1) {
        k2 += 1;
    }
    (k2, window_start(k2, m, s))
}

/// Calls `f(lo)` for every window start `lo <= k` of a step `>= k`: the
/// windows that contain token row `k` and are still to be used, in
/// increasing order (the window starts never decrease).
pub fn for_each_live_window(k: usize, m: usize, s: usize, mut f: impl FnMut(usize)) {
    let mut last = None;
    for k2 in k..k + m.max(1) {
        let lo = window_start(k2, m, s);
        if lo > k {
            break;
        }
        if last != Some(lo) {
            f(lo);
            last = Some(lo);
        }
    }
}

/// Window rows a spread step computes after start-up at shift `s`: its
/// own and its share of the next window's `s - 1` rows, which exist one
/// per step over the `m + 1 - s` steps of a chunk (docs/STREAMING.md §3.5).
pub fn spread_rows(m: usize, s: usize) -> usize {
    let ahead = s.saturating_sub(1);
    let chunk = (m + 1).saturating_sub(s).max(1);
    1 + ahead.div_ceil(chunk.min(ahead).max(1))
}

/// The largest shift whose spread step computes at most two window rows
/// (its own and one of the next window's): `s - 1 <= m + 1 - s`, 15 at
/// `m = 29`. The presets' shift: a larger one costs a row more per step for
/// every row the next window keeps (4 at 22), and the GPT's rows are what
/// a step beyond the weights' read pays for (docs/PERFORMANCE.md).
pub fn two_row_shift(m: usize) -> usize {
    ((m + 2) / 2).clamp(1, m.max(1))
}

/// Caches a staggered schedule needs: the most windows live at one step
/// (the schedule is periodic after step `m`, so `3m + 2` steps cover it).
pub fn window_pool(m: usize, s: usize) -> usize {
    let mut most = 0;
    for k in 0..3 * m + 2 {
        let mut n = 0;
        for_each_live_window(k, m, s, |_| n += 1);
        most = most.max(n);
    }
    most
}

/// How a session keeps the GPT window's keys and values as the window moves.
/// The presets take `Spread` (the default): a streaming step must not miss
/// its deadline, and the re-prefill's step costs most of an R step (12x a
/// step's median at full size, docs/PERFORMANCE.md). `Reprefill` is the
/// memory-lean choice.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum CacheSchedule {
    /// One cache, re-prefilled when the window jumps (least memory, a spike
    /// of `shift` rows every chunk).
    Reprefill,
    /// One cache per live window, each fed one row per step (flat cost,
    /// [`window_pool`] caches).
    Staggered,
    /// Two caches, the next window's rows appended a few per step over the
    /// steps before its jump into the second (`shift - 1` rows), moved into
    /// the first at the jump (flat cost at the re-prefill schedule's mean;
    /// at start-up the first full window's other rows at its jump).
    #[default]
    Spread,
}

impl CacheSchedule {
    /// GPT caches a session with this schedule holds (`m` = block size - 1).
    pub fn caches(self, m: usize, shift: usize) -> usize {
        match self {
            CacheSchedule::Reprefill => 1,
            CacheSchedule::Staggered => window_pool(m, shift),
            CacheSchedule::Spread => 2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_two_row_shift_is_the_largest_with_two_rows_a_step() {
        // docs/STREAMING.md §3.5's table: 2 rows at s = 8 and 15, 4 at 22, 10 at 27.
        let r: [usize; 4] = [8, 15, 22, 27].map(|s| spread_rows(29, s));
        assert_eq!(r, [2, 2, 4, 10]);
        assert_eq!(spread_rows(29, 1), 1);
        for m in 1..64 {
            let s = two_row_shift(m);
            assert!((1..=m).contains(&s), "m {m}: {s}");
            assert!(spread_rows(m, s) <= 2, "m {m} s {s}");
            assert!(
                s == m || spread_rows(m, s + 1) > 2,
                "m {m}: {s} is not the largest"
            );
        }
        assert_eq!(two_row_shift(29), 15);
        assert_eq!(two_row_shift(5), 3);
    }

    #[test]
    fn next_window_finds_each_jump() {
        // m = 29, s = 22: lo 0 on steps 0..28, 1 at step 29, 9 on 30..37, 17 from 38.
        assert_eq!(next_window(0, 29, 22), (29, 1));
        assert_eq!(next_window(28, 29, 22), (29, 1));
        assert_eq!(next_window(29, 29, 22), (30, 9));
        assert_eq!(next_window(30, 29, 22), (38, 17));
        assert_eq!(next_window(37, 29, 22), (38, 17));
        // s = m: a sliding window moves every step.
        assert_eq!(next_window(40, 29, 29), (41, 13));
    }

    #[test]
    fn window_schedule_matches_the_reference_formula() {
        // m = 29, s = 22: 1..29 on steps 0..28, 29 at step 29, then chunks of 8 from 22.
        let c: [usize; 40] = core::array::from_fn(|k| window_context(k, 29, 22));
        assert_eq!(&c[..29], &core::array::from_fn::<usize, 29, _>(|k| k + 1));
        assert_eq!(c[29], 29);
        assert_eq!(&c[30..40], &[22, 23, 24, 25, 26, 27, 28, 29, 22, 23]);
        // s = m: sliding window.
        assert!((29..100).all(|k| window_context(k, 29, 29) == 29));
    }

    #[test]
    fn live_windows_cover_every_step_that_reads_a_row() {
        for (m, s) in [
            (29, 22),
            (29, 15),
            (29, 8),
            (29, 27),
            (7, 5),
            (7, 7),
            (29, 1),
        ] {
            let pool = window_pool(m, s);
            for k in 0..200 {
                let mut live: [usize; 64] = [usize::MAX; 64];
                let mut n = 0;
                for_each_live_window(k, m, s, |lo| {
                    live[n] = lo;
                    n += 1;
                });
                assert!(n <= pool, "m {m} s {s} k {k}: {n} > pool {pool}");
                // Brute force: every later step whose window contains row k has its start listed.
                for k2 in k..k + 2 * m {
                    let lo = window_start(k2, m, s);
                    if lo <= k {
                        assert!(
                            live[..n].contains(&lo),
                            "m {m} s {s} k {k}: window {lo} of step {k2} missing"
                        );
                    }
                }
                assert!(live[..n].contains(&window_start(k, m, s)));
            }
        }
        // docs/STREAMING.md §3.5: ceil(m / (m - s + 1)) caches in steady state (4 at s = 22, 2 at
        // s = 15 and 8, 10 at s = 27), one more during start-up for the one-step window of step 29.
        let steady = |s: usize| {
            (60..200)
                .map(|k| {
                    let mut n = 0;
                    for_each_live_window(k, 29, s, |_| n += 1);
                    n
                })
                .max()
                .unwrap()
        };
        assert_eq!(
            [steady(22), steady(15), steady(8), steady(27)],
            [4, 2, 2, 10]
        );
        assert_eq!(
            [
                window_pool(29, 22),
                window_pool(29, 15),
                window_pool(29, 8),
                window_pool(29, 27)
            ],
            [5, 3, 3, 11]
        );
    }
}
