//! Splitting one GEMM over worker threads.
//!
//! Core never spawns a thread. Every kernel runs on the caller's thread
//! unless the std side installs a [`Workers`] pool ([`set_workers`];
//! `duolando::workers::set_threads` does it). With a pool installed,
//! [`linear`](super::linear) hands each thread its own range of output
//! columns (weight rows), cut at multiples of [`SPLIT_ALIGN`]: each thread
//! reads only its share of the weights, which is what a weight-bound step
//! needs; [`attention`](super::attention) hands each thread its own whole
//! query rows. Every output value is computed by the same code over the
//! same data as without a pool, so results are bit-identical for any
//! thread count (tests: `split_gemm_*`, `split_attention_*` and
//! `split_cols_*` in core, `tests/threads.rs`).

// The module's unsafe: the pool pointer, the disjoint output views and the
// pool contract, each with a SAFETY note (tests/unsafe_audit.rs).
#![allow(unsafe_code)]

use core::marker::PhantomData;
use core::sync::atomic::{AtomicPtr, Ordering};

/// A pool of threads that runs the tasks of one split GEMM.
///
/// # Safety
/// [`Workers::run`] must call `task(i)` exactly once for every `i` in
/// `0..n` (never twice, never an `i >= n`) and return only after every one
/// of those calls has returned: the tasks write disjoint parts of one
/// output through raw pointers, which is sound only under that contract.
// SAFETY: an unsafe trait: implementors promise the contract above.
pub unsafe trait Workers: Sync {
    /// Threads that run tasks at once, the caller's included (>= 1).
    fn threads(&self) -> usize;
    /// Runs `task(i)` for every `i` in `0..n` on any of its threads (the
    /// caller's included) and returns when all have returned.
    fn run(&self, n: usize, task: &(dyn Fn(usize) + Sync));
}

/// An installed pool, behind a thin pointer (see [`set_workers`]).
pub struct Installed(pub &'static dyn Workers);

static WORKERS: AtomicPtr<Installed> = AtomicPtr::new(core::ptr::null_mut());

/// Installs `w` for every later kernel call of this process (None: run
/// everything on the caller's thread, the default).
pub fn set_workers(w: Option<&'static Installed>) {
    let p = w.map_or(core::ptr::null_mut(), |w| {
        w as *const Installed as *mut Installed
    });
    WORKERS.store(p, Ordering::Release);
}

/// The installed pool, if any.
pub fn workers() -> Option<&'static dyn Workers> {
    let p = WORKERS.load(Ordering::Acquire);
    // SAFETY: `p` is null or came from a `&'static Installed` in
    // `set_workers`; it is only ever read through.
    unsafe { p.as_ref() }.map(|i| i.0)
}

/// Output columns per split range are a multiple of this (the packed
/// int8 tile's 8 weight rows, two f32/f16 tiles).
pub const SPLIT_ALIGN: usize = 8;

/// Smallest GEMM (weight bytes x activation rows) that is split: below
/// it the hand-off costs more than the second thread saves.
pub const MIN_SPLIT_WORK: usize = 128 * 1024;

/// How many ranges a GEMM of `n_out` output columns and `work` (weight
/// bytes x activation rows) is split into now: 1 without a pool.
pub fn split_count(n_out: usize, work: usize) -> usize {
    split_units(n_out / SPLIT_ALIGN, work)
}

/// Ranges for `units` splittable units of `work`: 1 without a pool.
fn split_units(units: usize, work: usize) -> usize {
    match workers() {
        Some(w) if work >= MIN_SPLIT_WORK => w.threads().min(units).max(1),
        _ => 1,
    }
}

/// Columns `lo..hi` of every row of a row-major output `(rows, stride)`:
/// the part of one GEMM's output a single task writes.
pub struct Cols<'y> {
    ptr: *mut f32,
    len: usize,
    stride: usize,
    lo: usize,
    hi: usize,
    _y: PhantomData<&'y mut [f32]>,
}

impl<'y> Cols<'y> {
    /// All columns `0..stride` of `y` (no split).
    pub fn whole(y: &'y mut [f32], stride: usize) -> Self {
        Cols {
            ptr: y.as_mut_ptr(),
            len: y.len(),
            stride,
            lo: 0,
            hi: stride,
            _y: PhantomData,
        }
    }
    /// First column of the range.
    pub fn lo(&self) -> usize {
        self.lo
    }
    /// One past the last column of the range.
    pub fn hi(&self) -> usize {
        self.hi
    }
    /// `y[i][a..b]`. Panics unless `lo <= a <= b <= hi` and the row lies in `y`.
    #[inline]
    pub fn seg(&mut self, i: usize, a: usize, b: usize) -> &mut [f32] {
        assert!(
            self.lo <= a && a <= b && b <= self.hi,
            "column range outside the task's share"
        );
        let start = i * self.stride + a;
        assert!(start + (b - a) <= self.len, "row outside the output");
        // SAFETY: in bounds of the `y` this view was made from (checked
        // above); columns `lo..hi` belong to this view alone (`split_cols`
        // hands out disjoint ranges, `Workers` runs each task once), and
        // `&mut self` keeps one segment alive at a time.
        unsafe { core::slice::from_raw_parts_mut(self.ptr.add(start), b - a) }
    }
    /// Rows `i0 .. i0 + rows`, columns `a..b` of `y`: the block one kernel
    /// call writes in place. Panics unless `lo <= a <= b <= hi` and the
    /// rows lie in `y`.
    pub fn window(&mut self, i0: usize, rows: usize, a: usize, b: usize) -> Window<'_> {
        assert!(
            self.lo <= a && a <= b && b <= self.hi,
            "column range outside the task's share"
        );
        // One past the window's last float (nothing for no rows).
        let end = if rows == 0 {
            Some(0)
        } else {
            i0.checked_add(rows - 1)
                .and_then(|l| l.checked_mul(self.stride))
                .and_then(|o| o.checked_add(b))
        };
        assert!(
            end.is_some_and(|e| e <= self.len),
            "rows outside the output"
        );
        // SAFETY: i0 * stride + a <= len (checked above when rows > 0; an
        // empty window keeps the base pointer and is never written).
        let ptr = if rows == 0 {
            self.ptr
        } else {
            unsafe { self.ptr.add(i0 * self.stride + a) }
        };
        Window {
            ptr,
            stride: self.stride,
            rows,
            cols: b - a,
            _w: PhantomData,
        }
    }
}

/// `rows` rows of `cols` floats, row `m` at `m * stride` floats from the
/// first: a block of a [`Cols`] view ([`Cols::window`]), borrowed from it
/// alone.
pub struct Window<'w> {
    ptr: *mut f32,
    stride: usize,
    rows: usize,
    cols: usize,
    _w: PhantomData<&'w mut [f32]>,
}

impl<'w> Window<'w> {
    /// Rows of the block.
    pub fn rows(&self) -> usize {
        self.rows
    }
    /// Floats per row.
    pub fn cols(&self) -> usize {
        self.cols
    }
    /// Row `m` (`cols` floats). Panics unless `m < rows`.
    #[inline]
    pub fn row(&mut self, m: usize) -> &mut [f32] {
        assert!(m < self.rows, "row outside the window");
        // SAFETY: rows m < rows of `cols` floats at m * stride lie in the
        // view's columns of its output (checked by `Cols::window`), and
        // `&mut self` keeps one row borrowed at a time.
        unsafe { core::slice::from_raw_parts_mut(self.ptr.add(m * self.stride), self.cols) }
    }
    /// The first `k` rows and the rest (`k` clamped to `rows`).
    pub fn split_rows(self, k: usize) -> (Window<'w>, Window<'w>) {
        let k = k.min(self.rows);
        // SAFETY: row k starts inside the window's rows when k < rows; at
        // k == rows the rest is empty and keeps the base pointer.
        let rest = if k < self.rows {
            unsafe { self.ptr.add(k * self.stride) }
        } else {
            self.ptr
        };
        (
            Window { rows: k, ..self },
            Window {
                ptr: rest,
                rows: self.rows - k,
                ..self
            },
        )
    }
}

/// The output of a split GEMM, shared by its tasks (each takes its own
/// disjoint [`Cols`]).
struct SharedOut<'y> {
    ptr: *mut f32,
    len: usize,
    stride: usize,
    _y: PhantomData<&'y mut [f32]>,
}

// SAFETY: tasks only reach the output through `Cols` views of disjoint
// column ranges (see `split_cols`).
unsafe impl Sync for SharedOut<'_> {}

/// Runs `f` over the output columns `0..n_out` of `y` (rows of `n_out`):
/// once over all columns on the caller's thread, or, with a pool and
/// enough `work` (weight bytes x activation rows), once per thread over
/// disjoint ranges aligned to [`SPLIT_ALIGN`].
pub fn split_cols<F>(y: &mut [f32], n_out: usize, work: usize, f: F)
where
    F: Fn(Cols<'_>) + Sync,
{
    split_cols_aligned(y, n_out, SPLIT_ALIGN, work, f)
}

/// [`split_cols`] with ranges cut at multiples of `align` columns (an
/// attention output seen as one row of `n_out = queries * C` columns is
/// split at whole queries: `align = C`).
pub fn split_cols_aligned<F>(y: &mut [f32], n_out: usize, align: usize, work: usize, f: F)
where
    F: Fn(Cols<'_>) + Sync,
{
    let align = align.max(1);
    let tasks = split_units(n_out / align, work);
    let pool = match workers() {
        Some(w) if tasks > 1 => w,
        _ => return f(Cols::whole(y, n_out)),
    };
    let per = n_out.div_ceil(align).div_ceil(tasks) * align;
    let out = &SharedOut {
        ptr: y.as_mut_ptr(),
        len: y.len(),
        stride: n_out,
        _y: PhantomData,
    };
    pool.run(tasks, &|t| {
        let (lo, hi) = ((t * per).min(n_out), ((t + 1) * per).min(n_out));
        if lo < hi {
            f(Cols {
                ptr: out.ptr,
                len: out.len,
                stride: out.stride,
                lo,
                hi,
                _y: PhantomData,
            });
        }
    });
}
