//! Token choice from logits: greedy argmax (what the original eval uses:
//! `topk(softmax(logits), 1)`), and the original's `samplek` rule (uniform
//! choice among the top-k) driven by an explicit, seeded RNG.

/// Largest `k` for [`top_k`].
pub const MAX_TOP_K: usize = 64;

/// Index of the largest logit; ties to the lowest index; NaN never wins
/// over a number. Empty input gives 0.
pub fn argmax(logits: &[f32]) -> u32 {
    let mut best = 0usize;
    let mut best_v = f32::NEG_INFINITY;
    let mut seen = false;
    for (i, &v) in logits.iter().enumerate() {
        if !seen || v > best_v {
            if v.is_nan() && seen {
                continue;
            }
            best = i;
            best_v = v;
            seen = !v.is_nan();
        }
    }
    best as u32
}

/// A small deterministic RNG (SplitMix64): the same seed gives the same
/// sequence on every target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `0..n` (n > 0; 0 gives 0).
    pub fn below(&mut self, n: u32) -> u32 {
        if n == 0 {
            return 0;
        }
        ((self.next_u64() >> 32) * n as u64 >> 32) as u32
    }
}

/// The `k` largest logits (descending, ties to the lower index; NaN
/// skipped): `(ids, n)` with `n = min(k, finite count)`, `k` clamped to
/// `1..=min(MAX_TOP_K, logits.len())`.
fn top_ids(logits: &[f32], k: usize) -> ([u32; MAX_TOP_K], usize) {
    let k = k.clamp(1, MAX_TOP_K).min(logits.len().max(1));
    let mut idx = [0u32; MAX_TOP_K];
    let mut n = 0usize;
    for (i, &v) in logits.iter().enumerate() {
        if v.is_nan() {
            continue;
        }
        // Insertion into the sorted top list (descending; equal values keep order).
        let mut pos = n;
        while pos > 0 && logits[idx[pos - 1] as usize] < v {
            pos -= 1;
        }
        if pos >= k {
            continue;
        }
        let end = if n < k { n } else { k - 1 };
        let mut m = end;
        while m > pos {
            idx[m] = idx[m - 1];
            m -= 1;
        }
        idx[pos] = i as u32;
        if n < k {
            n += 1;
        }
    }
    (idx, n)
}

/// The original `samplek` rule: the `k` largest logits (descending, ties
/// to the lower index), one of them chosen uniformly by `rng`. `k` is
/// clamped to `1..=min(MAX_TOP_K, logits.len())`.
pub fn top_k(logits: &[f32], k: usize, rng: &mut Rng) -> u32 {
    let (idx, n) = top_ids(logits, k);
    if n == 0 {
        return 0;
    }
    idx[rng.below(n as u32) as usize]
}

/// S's top-k rule (docs/STREAMING.md §3.6): the `k` ids with the largest
/// logits (the lower id ranks first on equal logits), taken in ASCENDING
/// id order, and the `r`-th of them with `r = rng.below(k)`: exactly one
/// draw, so the choice depends on set membership only. `k` is clamped to
/// `1..=min(MAX_TOP_K, logits.len())`.
pub fn top_k_by_id(logits: &[f32], k: usize, rng: &mut Rng) -> u32 {
    let k = k.clamp(1, MAX_TOP_K).min(logits.len().max(1));
    let (mut idx, n) = top_ids(logits, k);
    let r = rng.below(k as u32) as usize;
    if n == 0 {
        return 0;
    }
    let set = &mut idx[..n];
    set.sort_unstable();
    set[r.min(n - 1)]
}

/// How a session chooses the token of each head.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sampling {
    /// Argmax, lowest id on ties. No RNG draw.
    Greedy,
    /// Uniform over the `k` largest logits (the original `samplek`), the
    /// set sorted by id (docs/STREAMING.md §3.6); SplitMix64 seeded with
    /// `rng_seed`, one draw per head per step (Duolando 5, Bailando 2).
    TopK { k: u32, rng_seed: u64 },
}
