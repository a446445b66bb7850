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
        (((self.next_u64() >> 32) * n as u64) >> 32) as u32
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

/// Largest temperature of [`Sampling::Softmax`], in thousandths (100.0).
pub const MAX_TEMPERATURE_MILLI: u32 = 100_000;

/// The `k` largest logits (the lower id ranks first on equal logits), in
/// ASCENDING id order, one chosen with probability `softmax(logit / t)`
/// over the set (`t = temperature_milli / 1000`): `exp((l - l_max) / t)`
/// by the engine's own [`crate::kernels::simd::scalar::exp`] (plain IEEE
/// operations: the same bits on every target), summed in id order, and
/// exactly one draw (24 bits of `rng`). `k` is clamped to
/// `1..=min(MAX_TOP_K, logits.len())`, the temperature to at least 0.001.
/// A large `k` and `t = 1` is plain sampling from the model's distribution
/// (restricted to its [`MAX_TOP_K`] best tokens); a small `t` approaches
/// greedy.
pub fn softmax_top_k(logits: &[f32], k: usize, temperature_milli: u32, rng: &mut Rng) -> u32 {
    let k = k.clamp(1, MAX_TOP_K).min(logits.len().max(1));
    let (mut idx, n) = top_ids(logits, k);
    let u = (rng.next_u64() >> 40) as f32 * (1.0 / (1u32 << 24) as f32);
    if n == 0 {
        return 0;
    }
    // top_ids' first id holds the largest logit.
    let max = logits[idx[0] as usize];
    let set = &mut idx[..n];
    set.sort_unstable();
    let inv_t = 1000.0 / temperature_milli.max(1) as f32;
    let mut w = [0f32; MAX_TOP_K];
    let mut total = 0f32;
    for (wi, &id) in w.iter_mut().zip(set.iter()) {
        *wi = crate::kernels::simd::scalar::exp((logits[id as usize] - max) * inv_t);
        total += *wi;
    }
    let target = u * total;
    let mut acc = 0f32;
    for (&wi, &id) in w.iter().zip(set.iter()) {
        acc += wi;
        if target < acc {
            return id;
        }
    }
    // Rounding left `target` at the sum: the last id with any weight.
    set.iter()
        .zip(w.iter())
        .rev()
        .find(|(_, &wi)| wi > 0.0)
        .map_or(set[n - 1], |(&id, _)| id)
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
    /// Over the `k` largest logits, each with its probability under
    /// `softmax(logits / t)`, `t = temperature_milli / 1000`
    /// ([`softmax_top_k`]): the model's likely tokens most of the time,
    /// a near-equal one as often as the model rates it (where `TopK`
    /// picks the k-th best as often as the best). The same RNG and one
    /// draw per head per step as `TopK`.
    Softmax {
        k: u32,
        temperature_milli: u32,
        rng_seed: u64,
    },
}

impl Sampling {
    /// The token of one head from its logits (`rng`: the session's).
    #[inline]
    pub fn choose(&self, logits: &[f32], rng: &mut Rng) -> u32 {
        match *self {
            Sampling::Greedy => argmax(logits),
            Sampling::TopK { k, .. } => top_k_by_id(logits, k as usize, rng),
            Sampling::Softmax {
                k,
                temperature_milli,
                ..
            } => softmax_top_k(logits, k as usize, temperature_milli, rng),
        }
    }

    /// The seed of the session's RNG (0 for greedy, which draws nothing).
    pub fn rng_seed(&self) -> u64 {
        match *self {
            Sampling::Greedy => 0,
            Sampling::TopK { rng_seed, .. } | Sampling::Softmax { rng_seed, .. } => rng_seed,
        }
    }

    /// The `k` of a sampling rule that draws among the best tokens.
    pub fn k(&self) -> Option<u32> {
        match *self {
            Sampling::Greedy => None,
            Sampling::TopK { k, .. } | Sampling::Softmax { k, .. } => Some(k),
        }
    }

    /// The setting out of its range, with its value and largest allowed
    /// value: `k` in `1..=MAX_TOP_K`, the temperature in
    /// `1..=MAX_TEMPERATURE_MILLI` thousandths.
    pub fn check(&self) -> Result<(), (crate::error::Setting, u32, u32)> {
        use crate::error::Setting;
        let (k, t) = match *self {
            Sampling::Greedy => return Ok(()),
            Sampling::TopK { k, .. } => (k, None),
            Sampling::Softmax {
                k,
                temperature_milli,
                ..
            } => (k, Some(temperature_milli)),
        };
        if !(1..=MAX_TOP_K as u32).contains(&k) {
            return Err((Setting::TopK, k, MAX_TOP_K as u32));
        }
        match t {
            Some(t) if !(1..=MAX_TEMPERATURE_MILLI).contains(&t) => {
                Err((Setting::Temperature, t, MAX_TEMPERATURE_MILLI))
            }
            _ => Ok(()),
        }
    }
}
