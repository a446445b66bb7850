//! Running median of width `w` (odd) with scipy.ndimage's `reflect` boundary,
//! the kernel of HPSS (`median_filter(size=31, mode='reflect')`). A sorted
//! window is updated by one removal and one insertion per output sample.

use super::pad::scipy_reflect;

/// Reusable buffers of the running median.
pub struct RunningMedian {
    w: usize,
    /// (n + w - 1,) the reflected input sequence.
    ext: Vec<f32>,
    /// (w,) the sorted window.
    sorted: Vec<f32>,
}

impl RunningMedian {
    /// Width `w`, odd.
    pub fn new(w: usize) -> Self {
        assert!(w % 2 == 1, "median width must be odd");
        Self {
            w,
            ext: Vec::new(),
            sorted: Vec::with_capacity(w),
        }
    }

    /// `out[i] = median(x[i-h ..= i+h])`, `h = w/2`, reflected at both ends.
    /// Inputs must be free of NaN.
    pub fn filter(&mut self, x: &[f32], out: &mut [f32]) {
        let n = x.len();
        let h = (self.w / 2) as isize;
        self.ext.clear();
        self.ext
            .extend((0..(n + self.w - 1) as isize).map(|j| x[scipy_reflect(j - h, n)]));
        self.sorted.clear();
        self.sorted.extend_from_slice(&self.ext[..self.w]);
        self.sorted.sort_unstable_by(f32::total_cmp);
        let mid = self.w / 2;
        for i in 0..n {
            out[i] = self.sorted[mid];
            if i + 1 == n {
                break;
            }
            let old = self.ext[i];
            let new = self.ext[i + self.w];
            replace_sorted(&mut self.sorted, old, new);
        }
    }
}

/// Removes one copy of `old` from the sorted slice and inserts `new`, keeping it sorted.
#[inline]
fn replace_sorted(s: &mut [f32], old: f32, new: f32) {
    let mut i = s.partition_point(|&v| v < old);
    // `old` is present: it was inserted earlier.
    if new >= old {
        while i + 1 < s.len() && s[i + 1] < new {
            s[i] = s[i + 1];
            i += 1;
        }
    } else {
        while i > 0 && s[i - 1] > new {
            s[i] = s[i - 1];
            i -= 1;
        }
    }
    s[i] = new;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_brute_force() {
        let x: Vec<f32> = (0..200)
            .map(|i| ((i * 37 % 101) as f32) * 0.5 - ((i % 7) as f32))
            .collect();
        for &w in &[1usize, 3, 31] {
            let mut rm = RunningMedian::new(w);
            let mut out = vec![0.0; x.len()];
            rm.filter(&x, &mut out);
            let h = (w / 2) as isize;
            for i in 0..x.len() {
                let mut win: Vec<f32> = (-h..=h)
                    .map(|d| x[scipy_reflect(i as isize + d, x.len())])
                    .collect();
                win.sort_by(f32::total_cmp);
                assert_eq!(out[i], win[w / 2], "w={w} i={i}");
            }
        }
    }

    #[test]
    fn short_input_reflects_repeatedly() {
        let x = [3.0f32, 1.0];
        let mut rm = RunningMedian::new(31);
        let mut out = [0.0; 2];
        rm.filter(&x, &mut out);
        assert!(out.iter().all(|v| *v == 1.0 || *v == 3.0));
    }
}
