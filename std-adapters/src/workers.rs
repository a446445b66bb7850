//! Multi-threaded GEMMs: the std thread pool behind
//! `duolando_core::kernels::parallel`.
//!
//! Core runs on the caller's thread and never spawns one. [`set_threads`]
//! installs a process-wide pool of `n - 1` parked worker threads; from then
//! on every large `linear` (weight bytes x rows >= 128 KiB) hands each of
//! the `n` threads (the caller's included) its own share of the output
//! columns, so each thread reads only its share of the weights. Results
//! are bit-identical to one thread (tests/threads.rs).
//!
//! One split GEMM runs on the pool at a time: a second thread that calls a
//! kernel while the pool is busy (two sessions on two threads) runs its
//! GEMM alone on its own thread, so nothing waits on anything but its own
//! work. Workers spin for a short while after a task (the next GEMM of a
//! step follows within microseconds), then sleep on a condition variable.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};

use duolando_core::kernels::parallel::{self, Installed, Workers};

/// Spins of an idle worker before it sleeps (~tens of microseconds).
const IDLE_SPINS: u32 = 1 << 14;

/// A task of the current job with its lifetime erased; valid while the
/// job is published (see `Pool::run`).
#[derive(Clone, Copy)]
struct Job {
    task: *const (dyn Fn(usize) + Sync + 'static),
    n: usize,
}

// SAFETY: the pointee is `Sync` (a `dyn Fn + Sync`), so calling it from any
// thread is sound while it lives; `Pool::run` keeps it alive until no
// worker holds it (the `active` count).
#[allow(unsafe_code)]
unsafe impl Send for Job {}

struct Slot {
    job: Option<Job>,
    epoch: u64,
}

struct Shared {
    slot: Mutex<Slot>,
    wake: Condvar,
    /// `slot.epoch`, readable without the lock (idle workers spin on it).
    epoch: AtomicU64,
    /// Next task index of the current job.
    next: AtomicUsize,
    /// Tasks of the current job not finished yet.
    left: AtomicUsize,
    /// Workers inside the current job.
    active: AtomicUsize,
    panicked: AtomicBool,
}

/// `threads - 1` workers plus the calling thread.
struct Pool {
    threads: usize,
    shared: Arc<Shared>,
    busy: Mutex<()>,
}

impl Pool {
    fn new(threads: usize) -> std::io::Result<Pool> {
        let shared = Arc::new(Shared {
            slot: Mutex::new(Slot { job: None, epoch: 0 }),
            wake: Condvar::new(),
            epoch: AtomicU64::new(0),
            next: AtomicUsize::new(0),
            left: AtomicUsize::new(0),
            active: AtomicUsize::new(0),
            panicked: AtomicBool::new(false),
        });
        for i in 1..threads {
            let sh = Arc::clone(&shared);
            std::thread::Builder::new().name(format!("duolando-gemm-{i}")).spawn(move || worker(&sh))?;
        }
        Ok(Pool { threads, shared, busy: Mutex::new(()) })
    }
}

/// Runs tasks of `job` until none is left.
fn drain(sh: &Shared, job: Job) {
    loop {
        let i = sh.next.fetch_add(1, Ordering::AcqRel);
        if i >= job.n {
            return;
        }
        // SAFETY: the job is published, so `task` is alive (`Pool::run`
        // waits for `left == 0` and `active == 0` before returning).
        #[allow(unsafe_code)]
        let task = unsafe { &*job.task };
        if catch_unwind(AssertUnwindSafe(|| task(i))).is_err() {
            sh.panicked.store(true, Ordering::Release);
        }
        sh.left.fetch_sub(1, Ordering::AcqRel);
    }
}

fn worker(sh: &Shared) {
    let mut seen = 0u64;
    loop {
        let mut spins = 0;
        while sh.epoch.load(Ordering::Acquire) == seen && spins < IDLE_SPINS {
            std::hint::spin_loop();
            spins += 1;
        }
        let mut slot = sh.slot.lock().unwrap_or_else(|e| e.into_inner());
        while slot.epoch == seen {
            slot = sh.wake.wait(slot).unwrap_or_else(|e| e.into_inner());
        }
        seen = slot.epoch;
        let Some(job) = slot.job else { continue };
        // Registered under the lock while the job is published: the caller
        // unpublishes under the same lock and then waits for `active == 0`.
        sh.active.fetch_add(1, Ordering::AcqRel);
        drop(slot);
        drain(sh, job);
        sh.active.fetch_sub(1, Ordering::AcqRel);
    }
}

fn wait_zero(a: &AtomicUsize) {
    let mut spins = 0u32;
    while a.load(Ordering::Acquire) != 0 {
        if spins < IDLE_SPINS {
            std::hint::spin_loop();
            spins += 1;
        } else {
            std::thread::yield_now();
        }
    }
}

// SAFETY: `run` calls `task(i)` exactly once per `i < n` (indices come from
// one `fetch_add` counter reset per job, and a job is published to workers
// only between that reset and the wait for `left == 0` and `active == 0`)
// and returns only after every call returned.
#[allow(unsafe_code)]
unsafe impl Workers for Pool {
    fn threads(&self) -> usize {
        self.threads
    }

    fn run(&self, n: usize, task: &(dyn Fn(usize) + Sync)) {
        let busy = match self.busy.try_lock() {
            Ok(b) if n > 1 && self.threads > 1 => b,
            // Pool taken by another thread's GEMM (or nothing to share): run here.
            _ => return (0..n).for_each(task),
        };
        SPLIT_JOBS.fetch_add(1, Ordering::Relaxed);
        let sh = &*self.shared;
        sh.next.store(0, Ordering::Release);
        sh.left.store(n, Ordering::Release);
        sh.panicked.store(false, Ordering::Release);
        // SAFETY: only the lifetime is erased; the job is unpublished and no
        // worker holds it when this function returns (below).
        #[allow(unsafe_code)]
        let erased: &'static (dyn Fn(usize) + Sync + 'static) = unsafe { std::mem::transmute(task) };
        let job = Job { task: erased, n };
        {
            let mut slot = sh.slot.lock().unwrap_or_else(|e| e.into_inner());
            slot.job = Some(job);
            slot.epoch += 1;
            sh.epoch.store(slot.epoch, Ordering::Release);
        }
        sh.wake.notify_all();
        drain(sh, job);
        wait_zero(&sh.left);
        sh.slot.lock().unwrap_or_else(|e| e.into_inner()).job = None;
        wait_zero(&sh.active);
        drop(busy);
        if sh.panicked.load(Ordering::Acquire) {
            panic!("a duolando GEMM task panicked");
        }
    }
}

/// GEMMs run split over a pool so far (all pools, this process).
static SPLIT_JOBS: AtomicU64 = AtomicU64::new(0);

/// GEMMs that ran split over more than one thread so far in this process
/// (for tests and benchmarks: shows that splitting happened).
pub fn split_jobs() -> u64 {
    SPLIT_JOBS.load(Ordering::Relaxed)
}

/// Pools made so far, by thread count (kept for the life of the process).
static POOLS: Mutex<Vec<&'static Installed>> = Mutex::new(Vec::new());

/// Splits every large GEMM of this process over `n` threads from now on
/// (the calling thread and `n - 1` pooled workers, started on first use of
/// `n`); `n <= 1` runs everything on the caller's thread again (the
/// default). Outputs do not depend on `n`.
pub fn set_threads(n: usize) -> std::io::Result<()> {
    if n <= 1 {
        parallel::set_workers(None);
        return Ok(());
    }
    let mut pools = POOLS.lock().unwrap_or_else(|e| e.into_inner());
    let found = pools.iter().copied().find(|p| p.0.threads() == n);
    let inst = match found {
        Some(p) => p,
        None => {
            let pool: &'static Pool = Box::leak(Box::new(Pool::new(n)?));
            let inst: &'static Installed = Box::leak(Box::new(Installed(pool)));
            pools.push(inst);
            inst
        }
    };
    parallel::set_workers(Some(inst));
    Ok(())
}

/// Threads the GEMMs are split over now (1: no pool).
pub fn threads() -> usize {
    parallel::workers().map_or(1, |w| w.threads())
}
