//! Multi-threaded GEMMs: the std thread pool behind
//! `duolando_core::kernels::parallel`.
//!
//! Core runs on the caller's thread and never spawns one. [`set_threads`]
//! installs a process-wide pool of `n - 1` parked worker threads; from then
//! on every large `linear` (weight bytes x rows >= 128 KiB) hands each of
//! the `n` threads (the caller's included) its own share of the output
//! columns, so each thread reads only its share of the weights, and every
//! large `attention` its own share of the queries. Results are
//! bit-identical to one thread (tests/threads.rs).
//!
//! `set_threads(1)` stops and joins the workers.
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
    /// Set (under `slot`'s lock) to make the workers exit.
    stop: AtomicBool,
}

/// `threads - 1` workers plus the calling thread.
struct Pool {
    threads: usize,
    shared: Arc<Shared>,
    busy: Mutex<()>,
    /// The running workers (empty: stopped).
    handles: Mutex<Vec<std::thread::JoinHandle<()>>>,
}

impl Pool {
    fn new(threads: usize) -> Pool {
        let shared = Arc::new(Shared {
            slot: Mutex::new(Slot {
                job: None,
                epoch: 0,
            }),
            wake: Condvar::new(),
            epoch: AtomicU64::new(0),
            next: AtomicUsize::new(0),
            left: AtomicUsize::new(0),
            active: AtomicUsize::new(0),
            panicked: AtomicBool::new(false),
            stop: AtomicBool::new(true),
        });
        Pool {
            threads,
            shared,
            busy: Mutex::new(()),
            handles: Mutex::new(Vec::new()),
        }
    }

    /// Starts the workers (nothing when running); on failure none runs.
    fn start(&self) -> std::io::Result<()> {
        let mut hs = self.handles.lock().unwrap_or_else(|e| e.into_inner());
        if !hs.is_empty() {
            return Ok(());
        }
        let seen = {
            let slot = self.shared.slot.lock().unwrap_or_else(|e| e.into_inner());
            self.shared.stop.store(false, Ordering::Release);
            slot.epoch
        };
        for i in 1..self.threads {
            let sh = Arc::clone(&self.shared);
            match std::thread::Builder::new()
                .name(format!("duolando-gemm-{i}"))
                .spawn(move || worker(&sh, seen))
            {
                Ok(h) => hs.push(h),
                Err(e) => {
                    drop(hs);
                    self.stop();
                    return Err(e);
                }
            }
        }
        Ok(())
    }

    /// Makes the workers exit and waits for them. A GEMM running on the
    /// pool meanwhile finishes on its caller's thread.
    fn stop(&self) {
        let hs = std::mem::take(&mut *self.handles.lock().unwrap_or_else(|e| e.into_inner()));
        {
            let _slot = self.shared.slot.lock().unwrap_or_else(|e| e.into_inner());
            self.shared.stop.store(true, Ordering::Release);
        }
        self.shared.wake.notify_all();
        for h in hs {
            let _ = h.join();
        }
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

fn worker(sh: &Shared, mut seen: u64) {
    loop {
        let mut spins = 0;
        while sh.epoch.load(Ordering::Acquire) == seen
            && spins < IDLE_SPINS
            && !sh.stop.load(Ordering::Acquire)
        {
            std::hint::spin_loop();
            spins += 1;
        }
        let mut slot = sh.slot.lock().unwrap_or_else(|e| e.into_inner());
        while slot.epoch == seen && !sh.stop.load(Ordering::Acquire) {
            slot = sh.wake.wait(slot).unwrap_or_else(|e| e.into_inner());
        }
        // A job published meanwhile is drained by its caller.
        if sh.stop.load(Ordering::Acquire) {
            return;
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
            Ok(b) if n > 1 && self.threads > 1 && !self.shared.stop.load(Ordering::Acquire) => b,
            // Pool taken by another thread's GEMM, stopped, or nothing to
            // share: run here.
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
        let erased: &'static (dyn Fn(usize) + Sync + 'static) =
            unsafe { std::mem::transmute(task) };
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

/// The pool of each thread count used so far (kept for the life of the
/// process; at most one has running workers: the installed one).
static POOLS: Mutex<Vec<(&'static Pool, &'static Installed)>> = Mutex::new(Vec::new());

/// Splits every large GEMM of this process over `n` threads from now on:
/// the calling thread and `n - 1` pooled workers (started here; the
/// workers of a previous count are stopped and joined). `n <= 1` runs
/// everything on the caller's thread again (the default) and stops the
/// workers. Outputs do not depend on `n`. Errors when the operating system
/// refuses a thread (then one thread is in use).
pub fn set_threads(n: usize) -> std::io::Result<()> {
    let mut pools = POOLS.lock().unwrap_or_else(|e| e.into_inner());
    let mut result = Ok(());
    let mut installed = None;
    if n > 1 {
        let found = pools.iter().copied().find(|(p, _)| p.threads == n);
        let (pool, inst) = found.unwrap_or_else(|| {
            let pool: &'static Pool = Box::leak(Box::new(Pool::new(n)));
            let inst: &'static Installed = Box::leak(Box::new(Installed(pool)));
            pools.push((pool, inst));
            (pool, inst)
        });
        match pool.start() {
            Ok(()) => installed = Some(inst),
            Err(e) => result = Err(e),
        }
    }
    parallel::set_workers(installed);
    for (p, _) in pools
        .iter()
        .filter(|(p, _)| installed.is_none() || p.threads != n)
    {
        p.stop();
    }
    result
}

/// The CLI's default thread count: every core the process may use, at
/// most 8 (results do not depend on it).
pub fn default_threads() -> usize {
    std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(8)
}

/// Threads the GEMMs are split over now (1: no pool).
pub fn threads() -> usize {
    parallel::workers().map_or(1, |w| w.threads())
}
