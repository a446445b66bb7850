//! Weight matrices as rows: the one abstraction every weight-reading
//! kernel is generic over.

/// A `(rows, cols)` weight matrix read row by row.
///
/// Implementations: [`F32Rows`] now; f16 and blocked int8 later (dequantise
/// a row chunk, accumulate in f32 / i32). Callers guarantee `r < rows()`
/// and slice lengths equal to `cols()`.
pub trait RowMatrix {
    fn rows(&self) -> usize;
    fn cols(&self) -> usize;
    /// `row(r) . x`.
    fn dot(&self, r: usize, x: &[f32]) -> f32;
    /// `y += a * row(r)`.
    fn axpy(&self, r: usize, a: f32, y: &mut [f32]);
    /// `out = row(r)` as f32 (embedding lookups, codebook rows).
    fn row_into(&self, r: usize, out: &mut [f32]);
}

/// Dot product with 8 independent accumulators (vectorisable; the
/// summation order differs from a plain loop by rounding only).
#[inline]
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f32; 8];
    let (ac, ar) = a.split_at(n - n % 8);
    let (bc, br) = b.split_at(n - n % 8);
    for (x, y) in ac.chunks_exact(8).zip(bc.chunks_exact(8)) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut tail = 0.0f32;
    for (x, y) in ar.iter().zip(br) {
        tail += x * y;
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// Row-major f32 weights borrowed from the model bytes.
#[derive(Clone, Copy, Debug)]
pub struct F32Rows<'a> {
    data: &'a [f32],
    rows: usize,
    cols: usize,
}

impl<'a> F32Rows<'a> {
    /// None unless `data.len() == rows * cols`.
    pub fn new(data: &'a [f32], rows: usize, cols: usize) -> Option<Self> {
        if rows.checked_mul(cols)? != data.len() {
            return None;
        }
        Some(F32Rows { data, rows, cols })
    }
    pub fn row(&self, r: usize) -> &'a [f32] {
        &self.data[r * self.cols..(r + 1) * self.cols]
    }
}

impl RowMatrix for F32Rows<'_> {
    fn rows(&self) -> usize {
        self.rows
    }
    fn cols(&self) -> usize {
        self.cols
    }
    #[inline]
    fn dot(&self, r: usize, x: &[f32]) -> f32 {
        dot(self.row(r), x)
    }
    #[inline]
    fn axpy(&self, r: usize, a: f32, y: &mut [f32]) {
        for (yi, wi) in y.iter_mut().zip(self.row(r)) {
            *yi += a * wi;
        }
    }
    fn row_into(&self, r: usize, out: &mut [f32]) {
        out.copy_from_slice(self.row(r));
    }
}

/// A weight matrix of any stored dtype; kernels match once per call and
/// run their generic body. One arm per supported dtype.
#[derive(Clone, Copy, Debug)]
pub enum Matrix<'a> {
    F32(F32Rows<'a>),
}

impl Matrix<'_> {
    pub fn rows(&self) -> usize {
        match self {
            Matrix::F32(m) => m.rows(),
        }
    }
    pub fn cols(&self) -> usize {
        match self {
            Matrix::F32(m) => m.cols(),
        }
    }
    /// `out = row(r)`; callers guarantee `r < rows()` and `out.len() == cols()`.
    pub fn row_into(&self, r: usize, out: &mut [f32]) {
        match self {
            Matrix::F32(m) => m.row_into(r, out),
        }
    }
    /// `row(r) . x`.
    pub fn dot(&self, r: usize, x: &[f32]) -> f32 {
        match self {
            Matrix::F32(m) => m.dot(r, x),
        }
    }
}
