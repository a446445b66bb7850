//! Index mappings for the two boundary rules the reference mixes up:
//! numpy's `np.pad(mode='reflect')` (edge sample not repeated, used by the
//! centred STFT) and scipy.ndimage's `mode='reflect'` (edge sample repeated,
//! used by the HPSS median filters).

/// numpy `reflect`: `... c b | a b c d | c b ...`, applied as often as needed
/// (a period of `2(n-1)`). `i` may lie anywhere; `n >= 1`.
#[inline]
pub fn numpy_reflect(i: isize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n as isize - 1);
    let m = i.rem_euclid(period);
    if m < n as isize {
        m as usize
    } else {
        (period - m) as usize
    }
}

/// scipy.ndimage `reflect`: `... b a | a b c d | d c ...` (a period of `2n`).
#[inline]
pub fn scipy_reflect(i: isize, n: usize) -> usize {
    let period = 2 * n as isize;
    let m = i.rem_euclid(period);
    if m < n as isize {
        m as usize
    } else {
        (period - 1 - m) as usize
    }
}

/// Copies `y` centred into `out` (length `y.len() + 2 * pad`) with numpy reflect padding.
pub fn reflect_pad_into(y: &[f32], pad: usize, out: &mut Vec<f32>) {
    out.clear();
    out.reserve(y.len() + 2 * pad);
    let n = y.len();
    for j in 0..(n + 2 * pad) {
        out.push(y[numpy_reflect(j as isize - pad as isize, n)]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numpy_reflect_matches_np_pad() {
        // np.pad(np.arange(3), 7, mode='reflect')
        let want = [1, 2, 1, 0, 1, 2, 1, 0, 1, 2, 1, 0, 1, 2, 1, 0, 1];
        let got: Vec<usize> = (-7..10).map(|i| numpy_reflect(i, 3)).collect();
        assert_eq!(got, want);
    }

    #[test]
    fn scipy_reflect_repeats_edge() {
        let got: Vec<usize> = (-3..6).map(|i| scipy_reflect(i, 3)).collect();
        assert_eq!(got, [2, 1, 0, 0, 1, 2, 2, 1, 0]);
    }
}
