//! The worker threads that step a [`super::VecEnv`] in lockstep (and run the two heads of a PPO
//! update side by side).
//!
//! Written here rather than taken from rayon because a vector step is a fork-join of a few
//! hundred microseconds repeated thousands of times a second. `rayon::ThreadPool::install`
//! from outside the pool puts the caller to sleep on a futex and lets idle workers fall
//! asleep between steps, so every step paid two or three wake-ups: 2 envs on 2 threads ran
//! 1.28× one thread, where two free-running threads reached 1.85× (2-core host).
//! Here the caller steps its own share, and workers spin for a short window before parking
//! (as EnvPool's workers do), so a step that follows the last one within the window costs no
//! system call at all.

use std::cell::UnsafeCell;
use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::thread::{self, JoinHandle, Thread};
use std::time::{Duration, Instant};

/// How long a thread waits actively for the next step (or for the workers to finish) before it
/// parks. It covers a policy's forward pass between two vector steps (about 50–300 µs for the
/// default MLPs), and is short enough that a pool left idle during a PPO update gives its core
/// back within a fraction of a millisecond.
const SPIN_WINDOW: Duration = Duration::from_micros(300);

/// The first part of the window is pure `spin_loop`; after that the waiting thread yields
/// between checks, so an oversubscribed host (more threads than cores) still makes progress.
const PURE_SPIN: Duration = Duration::from_micros(30);

type Task = dyn Fn(usize) + Sync;

/// State shared between the caller and the workers.
struct Shared {
    /// Bumped (Release) by the caller once `task` and `caller` are written; a worker that sees a
    /// new value (Acquire) runs the task.
    generation: AtomicU64,
    /// Workers that have not finished the current task.
    pending: AtomicUsize,
    shutdown: AtomicBool,
    /// The current task, with its lifetime erased. Written only by the caller while no worker
    /// is running a task; valid until `pending` reaches zero, which `run` waits for.
    task: UnsafeCell<Option<*const Task>>,
    /// The thread to wake when the last worker finishes.
    caller: UnsafeCell<Option<Thread>>,
    /// The first panic payload of a worker's part, re-raised on the caller.
    panic: std::sync::Mutex<Option<Box<dyn std::any::Any + Send>>>,
}

// SAFETY: `task` and `caller` are written by the caller only before it publishes a generation
// (Release) and while `pending` is zero; workers read them only after observing that
// generation (Acquire) and before decrementing `pending`. The task itself is `Sync`.
unsafe impl Sync for Shared {}
unsafe impl Send for Shared {}

/// Fork-join over `threads` parts: part 0 on the calling thread, parts 1.. on workers.
pub struct LockstepPool {
    shared: Arc<Shared>,
    workers: Vec<JoinHandle<()>>,
}

impl LockstepPool {
    /// Starts `threads - 1` workers (none for `threads <= 1`).
    pub fn new(threads: usize) -> std::io::Result<Self> {
        let shared = Arc::new(Shared {
            generation: AtomicU64::new(0),
            pending: AtomicUsize::new(0),
            shutdown: AtomicBool::new(false),
            task: UnsafeCell::new(None),
            caller: UnsafeCell::new(None),
            panic: std::sync::Mutex::new(None),
        });
        let mut pool = Self {
            shared,
            workers: Vec::new(),
        };
        for part in 1..threads.max(1) {
            let shared = Arc::clone(&pool.shared);
            // On failure `pool` is dropped here, which stops the workers already started.
            let handle = thread::Builder::new()
                .name(format!("fairgrasp-vecenv-{part}"))
                .spawn(move || worker(&shared, part))?;
            pool.workers.push(handle);
        }
        Ok(pool)
    }

    /// Parts per call: the workers plus the caller.
    pub fn threads(&self) -> usize {
        self.workers.len() + 1
    }

    /// Calls `task(part)` for every part in `0..threads()`, part 0 on this thread, and returns
    /// when all have returned. A panic in any part is re-raised here after every part ended.
    pub fn run<'a>(&self, task: &'a (dyn Fn(usize) + Sync + 'a)) {
        if self.workers.is_empty() {
            task(0);
            return;
        }
        let shared = &*self.shared;
        // SAFETY: no worker reads these now: `pending` is zero (the previous call waited for
        // it) and the new generation is not published yet. The pointer outlives its use
        // because this function does not return before `pending` is zero again.
        unsafe {
            let erased =
                std::mem::transmute::<*const (dyn Fn(usize) + Sync + 'a), *const Task>(task);
            *shared.task.get() = Some(erased);
            *shared.caller.get() = Some(thread::current());
        }
        shared.pending.store(self.workers.len(), Ordering::Relaxed);
        shared.generation.fetch_add(1, Ordering::Release);
        for handle in &self.workers {
            // Cheap when the worker is spinning: std only makes a system call for a parked one.
            handle.thread().unpark();
        }
        let own = catch_unwind(AssertUnwindSafe(|| task(0)));
        wait_until(|| shared.pending.load(Ordering::Acquire) == 0);
        if let Err(payload) = own {
            resume_unwind(payload);
        }
        let worker_panic = shared
            .panic
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take();
        if let Some(payload) = worker_panic {
            resume_unwind(payload);
        }
    }
}

impl Drop for LockstepPool {
    fn drop(&mut self) {
        self.shared.shutdown.store(true, Ordering::Release);
        self.shared.generation.fetch_add(1, Ordering::Release);
        for handle in self.workers.drain(..) {
            handle.thread().unpark();
            // A worker's panics are caught around the task, so join only fails if the
            // bookkeeping itself panicked; nothing is left to clean up then.
            let _ = handle.join();
        }
    }
}

/// Waits for `done()`: spins, then yields, then parks (woken by `unpark`, re-checked on every
/// wake-up because park may return spuriously or on a stale token).
fn wait_until(done: impl Fn() -> bool) {
    let start = Instant::now();
    let mut checks = 0u32;
    while !done() {
        checks = checks.wrapping_add(1);
        // Reading the clock costs about as much as a few dozen spins; do it every 32 checks.
        let elapsed = if checks.is_multiple_of(32) {
            start.elapsed()
        } else {
            Duration::ZERO
        };
        if elapsed >= SPIN_WINDOW {
            thread::park();
        } else if elapsed >= PURE_SPIN {
            thread::yield_now();
        } else {
            std::hint::spin_loop();
        }
    }
}

fn worker(shared: &Shared, part: usize) {
    let mut seen = 0u64;
    loop {
        wait_until(|| shared.generation.load(Ordering::Acquire) != seen);
        seen = shared.generation.load(Ordering::Acquire);
        if shared.shutdown.load(Ordering::Acquire) {
            return;
        }
        // SAFETY: see `Shared`: published before the generation this worker observed, and kept
        // alive by the caller until `pending` reaches zero below.
        let (task, caller) = unsafe { (*shared.task.get(), (*shared.caller.get()).clone()) };
        if let Some(task) = task {
            let result = catch_unwind(AssertUnwindSafe(|| unsafe { (*task)(part) }));
            if let Err(payload) = result {
                let mut slot = shared.panic.lock().unwrap_or_else(|p| p.into_inner());
                slot.get_or_insert(payload);
            }
        }
        if shared.pending.fetch_sub(1, Ordering::AcqRel) == 1
            && let Some(caller) = caller
        {
            caller.unpark();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    #[test]
    fn every_part_runs_once_per_call() {
        let pool = LockstepPool::new(3).unwrap();
        assert_eq!(pool.threads(), 3);
        let counts: Vec<AtomicUsize> = (0..3).map(|_| AtomicUsize::new(0)).collect();
        for _ in 0..1000 {
            pool.run(&|part| {
                counts[part].fetch_add(1, Ordering::Relaxed);
            });
        }
        for c in &counts {
            assert_eq!(c.load(Ordering::Relaxed), 1000);
        }
    }

    #[test]
    fn parts_run_on_distinct_threads_and_results_are_visible_after_run() {
        let pool = LockstepPool::new(2).unwrap();
        let mut out = [0u64; 2];
        let ids: [std::sync::Mutex<Option<thread::ThreadId>>; 2] = Default::default();
        let cells: Vec<std::sync::Mutex<u64>> = (0..2).map(|_| Default::default()).collect();
        // Idle long enough between calls for the worker to park, then call again.
        for round in 0..5u64 {
            pool.run(&|part| {
                *cells[part].lock().unwrap() += round + part as u64;
                *ids[part].lock().unwrap() = Some(thread::current().id());
            });
            thread::sleep(Duration::from_millis(2));
        }
        for (i, c) in cells.iter().enumerate() {
            out[i] = *c.lock().unwrap();
        }
        assert_eq!(out, [10, 15]);
        assert_eq!(*ids[0].lock().unwrap(), Some(thread::current().id()));
        assert_ne!(*ids[1].lock().unwrap(), Some(thread::current().id()));
    }

    #[test]
    fn a_worker_panic_reaches_the_caller_and_the_pool_still_works() {
        let pool = LockstepPool::new(2).unwrap();
        let result = catch_unwind(AssertUnwindSafe(|| {
            pool.run(&|part| {
                if part == 1 {
                    panic!("part one broke");
                }
            })
        }));
        let payload = result.expect_err("the worker's panic must reach the caller");
        assert_eq!(payload.downcast_ref::<&str>(), Some(&"part one broke"));
        let ran = AtomicUsize::new(0);
        pool.run(&|_| {
            ran.fetch_add(1, Ordering::Relaxed);
        });
        assert_eq!(ran.load(Ordering::Relaxed), 2);
    }

    #[test]
    fn a_caller_panic_waits_for_the_workers_first() {
        let pool = LockstepPool::new(2).unwrap();
        let finished = AtomicBool::new(false);
        let result = catch_unwind(AssertUnwindSafe(|| {
            pool.run(&|part| {
                if part == 0 {
                    panic!("caller part broke");
                }
                thread::sleep(Duration::from_millis(20));
                finished.store(true, Ordering::Release);
            })
        }));
        assert!(result.is_err());
        assert!(
            finished.load(Ordering::Acquire),
            "run returned before the worker's part ended"
        );
    }
}
