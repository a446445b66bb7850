//! Key and value rows as the attention reads them: `n` rows of width `C`
//! in key order, stored as up to three runs (a ring's older rows up to the
//! wrap, then the rest, then a tail of the newest rows kept elsewhere) of
//! f32 or binary16 (an f16 cache, widened exactly
//! lane by lane inside the kernels). Reading a cache in place this way
//! needs no mirrored copy and no widened copy: the session's rings and
//! K/V caches are stored once, in their own element type.
//!
//! Every operation is written once over [`DenseElem`] (f32 / f16) and
//! gives, for f16 rows, bit for bit what the f32 kernels give on the
//! widened rows (`simd::dot_rows_f16`, `simd::axpy_f16`; tested).

use super::weights::DenseElem;

/// One run of whole rows.
#[derive(Clone, Copy, Debug)]
pub enum RowData<'a> {
    F32(&'a [f32]),
    /// IEEE binary16 bit patterns.
    F16(&'a [u16]),
}

impl RowData<'_> {
    fn len(&self) -> usize {
        match self {
            RowData::F32(d) => d.len(),
            RowData::F16(d) => d.len(),
        }
    }
}

/// Most runs of one [`KvRows`].
const RUNS: usize = 3;

/// `n` rows of width `C`: the rows of `parts[0]`, then those of `parts[1]`,
/// then those of `parts[2]` (row-major: row `j` at `j C`; `parts[0]` may be
/// head-major instead: [`KvRows::head_major`], [`KvRows::head_major_then`]).
#[derive(Clone, Copy, Debug)]
pub struct KvRows<'a> {
    parts: [RowData<'a>; RUNS],
    heads: Option<HeadMajor>,
}

/// Where a head-major run keeps its rows: head `h`'s `hd` lanes of row `j`
/// at `(h cap + j) hd`; rows `0..rows` are visible.
#[derive(Clone, Copy, Debug)]
struct HeadMajor {
    rows: usize,
    cap: usize,
    hd: usize,
}

impl<'a> KvRows<'a> {
    /// One run.
    pub fn one(d: RowData<'a>) -> Self {
        KvRows {
            parts: [d, RowData::F32(&[]), RowData::F32(&[])],
            heads: None,
        }
    }

    /// `first`'s rows, then `second`'s (each a whole number of rows).
    pub fn two(first: RowData<'a>, second: RowData<'a>) -> Self {
        KvRows {
            parts: [first, second, RowData::F32(&[])],
            heads: None,
        }
    }

    /// These rows, then `tail`'s (whole rows of the width): a ring's rows
    /// (one or two runs) followed by its newest rows kept apart, read as
    /// one set. None if every run is taken.
    pub fn then(self, tail: RowData<'a>) -> Option<Self> {
        // The run after the last one holding anything (a head-major first
        // run counts as held).
        let free = self
            .parts
            .iter()
            .enumerate()
            .rposition(|(i, p)| p.len() > 0 || (i == 0 && self.heads.is_some()))
            .map_or(0, |i| i + 1);
        if free >= RUNS {
            return None;
        }
        let mut parts = self.parts;
        parts[free] = tail;
        Some(KvRows { parts, ..self })
    }

    /// One head-major run: head `h`'s `hd` lanes of row `j` at `(h cap +
    /// j) hd` of `d`, rows `0..rows` visible (`rows <= cap`). A pass over
    /// one head's rows then reads one contiguous stretch, where row-major
    /// rows put `hd` lanes of every `C` apart (a cold cache's reads: the
    /// hardware prefetchers follow a stretch, not a stride). The heads
    /// whose rows `d` holds in full are the heads there are: [`Self::rows`]
    /// is 0 for a width `c` with more. None if `hd == 0` or `rows > cap`.
    pub fn head_major(d: RowData<'a>, rows: usize, cap: usize, hd: usize) -> Option<Self> {
        (hd > 0 && rows <= cap).then_some(KvRows {
            parts: [d, RowData::F32(&[]), RowData::F32(&[])],
            heads: Some(HeadMajor { rows, cap, hd }),
        })
    }

    /// [`Self::head_major`]'s rows, then the row-major rows of `tail`
    /// (whole rows of the width; the GPT cache's newest rows, read only by
    /// the call that makes them). None as for `head_major`.
    pub fn head_major_then(
        d: RowData<'a>,
        rows: usize,
        cap: usize,
        hd: usize,
        tail: RowData<'a>,
    ) -> Option<Self> {
        Self::head_major(d, rows, cap, hd).map(|k| KvRows {
            parts: [k.parts[0], tail, RowData::F32(&[])],
            ..k
        })
    }

    /// Whole rows of width `c` held (a part's partial last row is not one;
    /// head-major: the visible rows if every head of `c` is held, else 0,
    /// and the tail's whole rows).
    pub fn rows(&self, c: usize) -> usize {
        if c == 0 {
            return 0;
        }
        match self.heads {
            None => self.parts.iter().map(|p| p.len() / c).sum(),
            Some(hm) => {
                let heads = c / hm.hd;
                let whole = c % hm.hd == 0
                    && heads > 0
                    && (heads - 1) * hm.cap * hm.hd + hm.rows * hm.hd <= self.parts[0].len();
                if whole {
                    hm.rows + self.parts[1..].iter().map(|p| p.len() / c).sum::<usize>()
                } else {
                    0
                }
            }
        }
    }

    /// Rows of run `run`.
    fn run_rows(&self, run: usize, c: usize) -> usize {
        match self.heads {
            Some(hm) if run == 0 => hm.rows,
            _ => self.parts[run].len() / c,
        }
    }

    /// Where lanes `h_off..` of row `lo` of run `run` start, and the
    /// distance from one row to the next (`h_off`: a head's first lane, or
    /// inside it). Only the first run may be head-major.
    fn at(&self, run: usize, lo: usize, c: usize, h_off: usize) -> (usize, usize) {
        match self.heads {
            Some(hm) if run == 0 => ((h_off / hm.hd * hm.cap + lo) * hm.hd + h_off % hm.hd, hm.hd),
            _ => (lo * c + h_off, c),
        }
    }

    /// Rows `a..b` as at most three pieces, one per run: `(part, lo, hi,
    /// at)`, rows `lo..hi` of the run being rows `a + at ..` of the range
    /// (empty pieces have `lo == hi`).
    fn pieces(&self, a: usize, b: usize, c: usize) -> [(&RowData<'a>, usize, usize, usize); RUNS] {
        let mut start = 0;
        core::array::from_fn(|run| {
            let n = self.run_rows(run, c);
            let lo = a.clamp(start, start + n) - start;
            let hi = b.clamp(start, start + n).max(a.clamp(start, start + n)) - start;
            // Within 0..=b - a also for the empty pieces (callers slice by it).
            let at = (start + lo).clamp(a, b.max(a)) - a;
            start += n;
            (&self.parts[run], lo, hi, at)
        })
    }

    /// `out[j - a] = qh . row j [h_off .. h_off + qh.len()]` for keys
    /// `a..b` (`b <= rows(c)`, `h_off + qh.len() <= c`; `out`: b - a).
    pub(crate) fn dot_rows(
        &self,
        qh: &[f32],
        a: usize,
        b: usize,
        c: usize,
        h_off: usize,
        out: &mut [f32],
    ) {
        for (run, (part, lo, hi, at)) in self.pieces(a, b, c).into_iter().enumerate() {
            let out = &mut out[at..at + (hi - lo)];
            let (s, stride) = self.at(run, lo, c, h_off);
            match part {
                _ if hi == lo => {}
                RowData::F32(d) => dots(qh, &d[s..], stride, out),
                RowData::F16(d) => dots(qh, &d[s..], stride, out),
            }
        }
    }

    /// `y += s * row j [h_off .. h_off + y.len()]` (the key-by-key path):
    /// [`KvRows::axpy_rows`] on one row.
    pub(crate) fn axpy(&self, s: f32, j: usize, c: usize, h_off: usize, y: &mut [f32]) {
        self.axpy_rows(&[s], j, j + 1, c, h_off, y)
    }

    /// `y += sum_j coef[j - a] * row j [h_off .. h_off + y.len()]` for rows
    /// `a..b` in order (`coef`: b - a): per lane the `axpy` of each row in
    /// turn, bit for bit, in one kernel call per run.
    pub(crate) fn axpy_rows(
        &self,
        coef: &[f32],
        a: usize,
        b: usize,
        c: usize,
        h_off: usize,
        y: &mut [f32],
    ) {
        let n = y.len();
        for (run, (part, lo, hi, at)) in self.pieces(a, b, c).into_iter().enumerate() {
            let (s, stride) = self.at(run, lo, c, h_off);
            let (coef, e) = (
                &coef[at..at + (hi - lo)],
                s + (hi - lo).saturating_sub(1) * stride + n,
            );
            match part {
                _ if hi == lo => {}
                RowData::F32(d) => f32::axpy_rows(coef, &d[s..e], stride, y),
                RowData::F16(d) => u16::axpy_rows(coef, &d[s..e], stride, y),
            }
        }
    }

    /// [`KvRows::dot_rows`] for `g` queries of `hd` lanes `q_stride` apart
    /// in `q`: query `m`'s score of key `j` goes to `out[m out_stride + j -
    /// a]` (`out_stride >= b - a`); each key row read once for the group
    /// where the ISA allows, bit for bit the per-query call.
    /// `side`: bytes prefetched into L2 over the pass (the first non-empty
    /// run's call; [`simd::dot_rows_group`](super::simd::dot_rows_group)).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn dot_rows_group(
        &self,
        q: &[f32],
        hd: usize,
        q_stride: usize,
        g: usize,
        a: usize,
        b: usize,
        c: usize,
        h_off: usize,
        out: &mut [f32],
        out_stride: usize,
        mut side: &[u8],
    ) {
        for (run, (part, lo, hi, at)) in self.pieces(a, b, c).into_iter().enumerate() {
            let out = &mut out[at..];
            let (s, stride) = self.at(run, lo, c, h_off);
            match part {
                _ if hi == lo => continue,
                RowData::F32(d) => f32::dot_rows_group(
                    q,
                    hd,
                    q_stride,
                    g,
                    &d[s..],
                    stride,
                    hi - lo,
                    out,
                    out_stride,
                    side,
                ),
                RowData::F16(d) => u16::dot_rows_group(
                    q,
                    hd,
                    q_stride,
                    g,
                    &d[s..],
                    stride,
                    hi - lo,
                    out,
                    out_stride,
                    side,
                ),
            }
            side = &[];
        }
    }

    /// [`KvRows::axpy_rows`] for `g` queries: query `m`'s coefficient of
    /// row `j` is `coef[m coef_stride + j - a]`, its output `y[m y_stride
    /// ..][..n]`; bit for bit the per-query call.
    /// `side` as in [`KvRows::dot_rows_group`].
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn axpy_rows_group(
        &self,
        coef: &[f32],
        coef_stride: usize,
        a: usize,
        b: usize,
        c: usize,
        h_off: usize,
        y: &mut [f32],
        y_stride: usize,
        n: usize,
        g: usize,
        mut side: &[u8],
    ) {
        for (run, (part, lo, hi, at)) in self.pieces(a, b, c).into_iter().enumerate() {
            let (s, stride) = self.at(run, lo, c, h_off);
            let (coef, e) = (&coef[at..], s + (hi - lo).saturating_sub(1) * stride + n);
            match part {
                _ if hi == lo => continue,
                RowData::F32(d) => f32::axpy_rows_group(
                    coef,
                    coef_stride,
                    hi - lo,
                    &d[s..e],
                    stride,
                    y,
                    y_stride,
                    n,
                    g,
                    side,
                ),
                RowData::F16(d) => u16::axpy_rows_group(
                    coef,
                    coef_stride,
                    hi - lo,
                    &d[s..e],
                    stride,
                    y,
                    y_stride,
                    n,
                    g,
                    side,
                ),
            }
            side = &[];
        }
    }

    /// The stored bytes of the first run (all the rows of a one-run set;
    /// head-major: every head's, with the rows between them): what a
    /// caller prefetches ahead of attending them.
    pub fn lead_bytes(&self) -> &'a [u8] {
        match self.parts[0] {
            RowData::F32(d) => bytemuck::cast_slice(d),
            RowData::F16(d) => bytemuck::cast_slice(d),
        }
    }

    /// `qh . row j [h_off .. h_off + qh.len()]` (the key-by-key path): the
    /// kernel of [`KvRows::dot_rows`] on one key, so f16 rows give what
    /// the widened f32 rows give on every ISA.
    pub(crate) fn dot(&self, qh: &[f32], j: usize, c: usize, h_off: usize) -> f32 {
        let mut out = [0.0f32];
        self.dot_rows(qh, j, j + 1, c, h_off, &mut out);
        out[0]
    }
}

fn dots<E: DenseElem>(qh: &[f32], rows: &[E], stride: usize, out: &mut [f32]) {
    E::dot_rows(qh, rows, stride, out)
}

impl<'a> From<&'a [f32]> for KvRows<'a> {
    fn from(d: &'a [f32]) -> Self {
        KvRows::one(RowData::F32(d))
    }
}

impl<'a> From<&'a mut [f32]> for KvRows<'a> {
    fn from(d: &'a mut [f32]) -> Self {
        KvRows::one(RowData::F32(d))
    }
}
