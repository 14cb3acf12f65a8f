//! A team of worker threads started once per simulation and reused by every
//! parallel phase of a step (the contacts, the assembly, the PCG, the update
//! after the solve).
//!
//! This is the solver's only threading mechanism: [`Team::run_each`] hands
//! item t of a phase to thread t, and a phase whose threads must meet inside
//! it (the PCG, three times per iteration) uses a [`Barrier`].
//!
//! The threads are not started per phase (`std::thread::scope`): the kernel
//! places each new thread anew and may put two of them on one core, where a
//! spin barrier waits out whole time slices. A worker that lives for the
//! whole run and spins between phases stays on its own core. After [`SPIN`]
//! without work it sleeps on a condition variable (an idle node does not burn
//! a core), and the next phase wakes it.

use std::cell::UnsafeCell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Vertices from which a simulation uses every core. With threads started
/// once ([`super::team::Team`]) a PCG barrier costs well under a
/// microsecond, and two threads paid on every grid measured down to 11 × 11
/// (121 vertices: 0.088 → 0.058 ms per step); below a few hundred vertices
/// a step takes tens of microseconds, and a second busy thread is not worth
/// its core to whatever else runs (a ROS node's other work, parallel tests).
pub const PARALLEL_FROM: usize = 500;

/// Threads of a simulation (the assembly, the PCG, the contacts): one per
/// core from [`PARALLEL_FROM`] vertices, at most 8 and at most one per
/// [`VERTICES_PER_THREAD`] vertices.
pub fn threads_for(n: usize) -> usize {
    let cores = std::thread::available_parallelism()
        .map(|p| p.get())
        .unwrap_or(1);
    threads_for_cores(n, cores)
}

/// [`threads_for`] on a machine with `cores` cores.
pub fn threads_for_cores(n: usize, cores: usize) -> usize {
    if n < PARALLEL_FROM {
        1
    } else {
        cores.min(8).min(n / VERTICES_PER_THREAD).max(1)
    }
}

/// Fewest vertices per thread: on a many-core machine a small cloth gets a
/// few threads, not one per core (each thread's rows must outweigh its share
/// of the barriers).
pub const VERTICES_PER_THREAD: usize = 250;

/// How long an idle worker spins before it sleeps: longer than the serial
/// parts of a step (contacts, position update: ~0.5 ms on a 101 × 101 grid),
/// so a running simulation never puts its workers to sleep.
pub const SPIN: Duration = Duration::from_millis(1);

/// The caller's thread (index 0) and `size − 1` workers (indices 1..size).
pub struct Team {
    shared: Arc<Shared>,
    workers: Vec<JoinHandle<()>>,
}

/// A phase's closure, type-erased: its address and the function that calls it.
#[derive(Clone, Copy)]
struct Job {
    data: *const (),
    call: unsafe fn(*const (), usize),
}

/// # Safety
/// `data` must point to a live `F`.
unsafe fn call<F: Fn(usize) + Sync>(data: *const (), t: usize) {
    (*(data as *const F))(t)
}

struct Shared {
    size: usize,
    /// How long an idle worker spins before it sleeps.
    spin: Duration,
    /// Phases started so far; a worker runs the job when it sees it change.
    epoch: AtomicUsize,
    /// Workers done with the current phase.
    done: AtomicUsize,
    /// Written by [`Team::run`] only while no worker reads it (before the
    /// epoch changes; every worker has finished the previous phase).
    job: UnsafeCell<Option<Job>>,
    sleeping: AtomicUsize,
    lock: Mutex<()>,
    wake: Condvar,
    stop: AtomicBool,
    /// Idle workers sleep at once instead of spinning (until the next phase).
    rest: AtomicBool,
    panicked: AtomicBool,
}

// SAFETY: `job` is written only by the team's owner between phases (see the
// field), and the closures it points to are `Sync`.
unsafe impl Sync for Shared {}
unsafe impl Send for Shared {}

impl Team {
    /// A team of `size` threads in all (the caller counts as one); `size` ≤ 1
    /// runs every phase on the caller's thread.
    pub fn new(size: usize) -> Team {
        Team::with_spin(size, SPIN)
    }

    /// [`Team::new`] with idle workers spinning for `spin` before they sleep.
    pub fn with_spin(size: usize, spin: Duration) -> Team {
        let size = size.max(1);
        let shared = Arc::new(Shared {
            size,
            spin,
            epoch: AtomicUsize::new(0),
            done: AtomicUsize::new(0),
            job: UnsafeCell::new(None),
            sleeping: AtomicUsize::new(0),
            lock: Mutex::new(()),
            wake: Condvar::new(),
            stop: AtomicBool::new(false),
            rest: AtomicBool::new(false),
            panicked: AtomicBool::new(false),
        });
        let workers = (1..size)
            .map(|t| {
                let sh = Arc::clone(&shared);
                std::thread::Builder::new()
                    .name(format!("garment_sim-{t}"))
                    .spawn(move || worker(&sh, t))
                    .expect("cannot start a worker thread")
            })
            .collect();
        Team { shared, workers }
    }

    /// Threads in the team, the caller's included.
    pub fn size(&self) -> usize {
        self.shared.size
    }

    /// Sends the idle workers to sleep now instead of after their spin (for
    /// a caller about to wait: a node pacing itself with the wall clock would
    /// otherwise keep a core busy up to 1 ms after every step). The next
    /// [`Team::run`] wakes them.
    pub fn rest(&self) {
        if self.shared.size > 1 {
            self.shared.rest.store(true, Ordering::SeqCst);
        }
    }

    /// Workers asleep now.
    pub fn sleeping(&self) -> usize {
        self.shared.sleeping.load(Ordering::SeqCst)
    }

    /// Runs `f(t, &mut items[t])` on the team's thread t, for every item
    /// (items beyond the team's size are left alone).
    pub fn run_each<T: Send>(&mut self, items: &mut [T], f: impl Fn(usize, &mut T) + Sync) {
        debug_assert!(items.len() <= self.size());
        let cells: Vec<Mutex<&mut T>> = items.iter_mut().map(Mutex::new).collect();
        self.run(|t| {
            if let Some(c) = cells.get(t) {
                f(t, &mut c.lock().unwrap_or_else(|e| e.into_inner()));
            }
        });
    }

    /// Runs `f(t)` for every t in `0..size()`, t = 0 on the caller's thread,
    /// and returns when all have returned. A panic in a worker is raised
    /// here, after every thread has finished.
    pub fn run<F: Fn(usize) + Sync>(&mut self, f: F) {
        let sh = &*self.shared;
        if sh.size == 1 {
            f(0);
            return;
        }
        // SAFETY: every worker finished the previous phase (waited for
        // below), so none reads `job` now; `f` outlives the phase because
        // this function waits for the workers before returning, also when
        // `f(0)` panics (`Wait`'s drop).
        unsafe {
            *sh.job.get() = Some(Job {
                data: &f as *const F as *const (),
                call: call::<F>,
            });
        }
        sh.done.store(0, Ordering::Relaxed);
        sh.rest.store(false, Ordering::SeqCst);
        sh.epoch.fetch_add(1, Ordering::SeqCst);
        if sh.sleeping.load(Ordering::SeqCst) > 0 {
            let _g = sh.lock.lock().unwrap_or_else(|e| e.into_inner());
            sh.wake.notify_all();
        }
        struct Wait<'a>(&'a Shared);
        impl Drop for Wait<'_> {
            fn drop(&mut self) {
                let mut spins = 0u32;
                while self.0.done.load(Ordering::Acquire) + 1 < self.0.size {
                    if spins < 1 << 16 {
                        std::hint::spin_loop();
                        spins += 1;
                    } else {
                        std::thread::yield_now();
                    }
                }
            }
        }
        let wait = Wait(sh);
        f(0);
        drop(wait);
        if sh.panicked.swap(false, Ordering::Relaxed) {
            panic!("a worker thread of the simulation panicked");
        }
    }
}

fn worker(sh: &Shared, t: usize) {
    let mut seen = 0;
    loop {
        let start = Instant::now();
        let mut spins = 0u32;
        loop {
            if sh.epoch.load(Ordering::Acquire) != seen || sh.stop.load(Ordering::Acquire) {
                break;
            }
            std::hint::spin_loop();
            spins += 1;
            if spins.is_multiple_of(256)
                && (sh.rest.load(Ordering::Relaxed) || start.elapsed() > sh.spin)
            {
                let mut g = sh.lock.lock().unwrap_or_else(|e| e.into_inner());
                sh.sleeping.fetch_add(1, Ordering::SeqCst);
                while sh.epoch.load(Ordering::SeqCst) == seen && !sh.stop.load(Ordering::SeqCst) {
                    g = sh.wake.wait(g).unwrap_or_else(|e| e.into_inner());
                }
                sh.sleeping.fetch_sub(1, Ordering::SeqCst);
                break;
            }
        }
        if sh.stop.load(Ordering::Acquire) {
            return;
        }
        seen = sh.epoch.load(Ordering::Acquire);
        // SAFETY: the epoch changed after `run` wrote the job, and `run`
        // waits for this worker before the closure goes away
        let job = unsafe { *sh.job.get() };
        if let Some(job) = job {
            if catch_unwind(AssertUnwindSafe(|| unsafe { (job.call)(job.data, t) })).is_err() {
                sh.panicked.store(true, Ordering::Relaxed);
            }
        }
        sh.done.fetch_add(1, Ordering::Release);
    }
}

impl Drop for Team {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        {
            let _g = self.shared.lock.lock().unwrap_or_else(|e| e.into_inner());
            self.shared.wake.notify_all();
        }
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

impl std::fmt::Debug for Team {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Team").field("size", &self.size()).finish()
    }
}

/// Sense-reversing barrier that spins briefly, then yields (the machine may
/// be shared, so it never spins for long).
pub struct Barrier {
    n: usize,
    count: AtomicUsize,
    generation: AtomicUsize,
}

impl Barrier {
    pub fn new(n: usize) -> Self {
        Barrier {
            n,
            count: AtomicUsize::new(0),
            generation: AtomicUsize::new(0),
        }
    }
    pub fn wait(&self) {
        if self.n == 1 {
            return;
        }
        let g = self.generation.load(Ordering::Acquire);
        if self.count.fetch_add(1, Ordering::AcqRel) + 1 == self.n {
            self.count.store(0, Ordering::Relaxed);
            self.generation.fetch_add(1, Ordering::AcqRel);
            return;
        }
        let mut spins = 0u32;
        while self.generation.load(Ordering::Acquire) == g {
            if spins < 4000 {
                std::hint::spin_loop();
                spins += 1;
            } else {
                std::thread::yield_now();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicU64;

    #[test]
    fn every_thread_runs_each_phase_once() {
        for size in [1, 2, 3] {
            let mut team = Team::new(size);
            let hits: Vec<AtomicU64> = (0..size).map(|_| AtomicU64::new(0)).collect();
            for phase in 0..2000u64 {
                team.run(|t| {
                    hits[t].fetch_add(phase + 1, Ordering::Relaxed);
                });
            }
            for h in &hits {
                assert_eq!(h.load(Ordering::Relaxed), 2000 * 2001 / 2);
            }
        }
    }

    #[test]
    fn workers_wake_after_sleeping() {
        let mut team = Team::new(2);
        let hits = AtomicU64::new(0);
        for _ in 0..3 {
            std::thread::sleep(SPIN * 5);
            team.run(|t| {
                hits.fetch_add(t as u64 + 1, Ordering::Relaxed);
            });
        }
        assert_eq!(hits.load(Ordering::Relaxed), 3 * 3);
    }

    #[test]
    fn rest_puts_idle_workers_to_sleep_at_once() {
        // workers that would spin for a minute
        let mut team = Team::with_spin(3, Duration::from_secs(60));
        let hits = AtomicU64::new(0);
        team.run(|_| {
            hits.fetch_add(1, Ordering::Relaxed);
        });
        std::thread::sleep(Duration::from_millis(20));
        assert_eq!(team.sleeping(), 0, "spinning, not asleep");
        team.rest();
        let t0 = Instant::now();
        while team.sleeping() < 2 {
            assert!(t0.elapsed() < Duration::from_secs(5), "still spinning");
            std::thread::sleep(Duration::from_millis(1));
        }
        // and the next phase wakes them
        team.run(|_| {
            hits.fetch_add(1, Ordering::Relaxed);
        });
        assert_eq!(hits.load(Ordering::Relaxed), 6);
    }

    #[test]
    fn a_worker_panic_reaches_the_caller_and_the_team_goes_on() {
        let mut team = Team::new(2);
        let r = catch_unwind(AssertUnwindSafe(|| {
            team.run(|t| {
                if t == 1 {
                    panic!("worker fails");
                }
            })
        }));
        assert!(r.is_err());
        let hits = AtomicU64::new(0);
        team.run(|_| {
            hits.fetch_add(1, Ordering::Relaxed);
        });
        assert_eq!(hits.load(Ordering::Relaxed), 2);
    }

    #[test]
    fn threads_grow_with_the_cloth_and_the_cores() {
        // below PARALLEL_FROM: one thread whatever the cores
        assert_eq!(threads_for_cores(121, 2), 1);
        assert_eq!(threads_for_cores(PARALLEL_FROM - 1, 64), 1);
        // the 2, 1 and 0.5 cm table drapes
        for n in [676, 2601, 10201] {
            assert_eq!(threads_for_cores(n, 1), 1);
            assert_eq!(threads_for_cores(n, 2), 2);
        }
        assert_eq!(threads_for_cores(676, 64), 2);
        assert_eq!(threads_for_cores(2601, 64), 8);
        assert_eq!(threads_for_cores(10201, 4), 4);
    }
}
