//! A team of worker threads started once per simulation and reused by every
//! parallel phase of a step (the contacts, the assembly, the PCG, the update
//! after the solve).
//!
//! This is the solver's only threading mechanism: [`Team::run_each`] hands
//! item t of a phase to thread t, and a phase whose threads must meet inside
//! it (the PCG, three times per iteration) uses a [`Barrier`].
//!
//! The threads are not started per phase (`std::thread::scope`): the kernel
//! places each new thread anew and may put two of them on one core. A worker
//! that lives for the whole run and waits between phases stays on its own
//! core.
//!
//! Every wait (a worker's for the next phase, the caller's for the workers,
//! a thread's at a barrier) spins for [`SPIN_ALONE`], then spins and yields
//! its core between looks, then sleeps on a condition variable ([`SPIN`]
//! between phases, [`PATIENCE`] inside them) until the thread it waits for
//! wakes it. So a thread whose partner is descheduled (another process has
//! its core) gives its own core away instead of spinning out the time slice,
//! and an idle node does not burn a core. An item of a phase whose worker has
//! not started it by the time the caller has finished its own runs on the
//! caller's thread: a phase without barriers goes on at one core's speed
//! while another process has the worker's core. What each item computes does
//! not depend on the thread that runs it, so results do not change.

use std::cell::{Cell, UnsafeCell};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::cpu::current_cpu;

thread_local! {
    /// This thread's index in its team (0: not a worker, e.g. the caller).
    static INDEX: Cell<usize> = const { Cell::new(0) };
}

/// The CPUs the threads of a team were last seen on ([`current_cpu`]), by
/// index: a waiter whose partner was last seen on its own CPU knows the
/// partner cannot run while it spins there, and sleeps at once.
struct Seen(Vec<AtomicU32>);

impl Seen {
    const UNKNOWN: u32 = u32::MAX;

    fn new(n: usize) -> Seen {
        Seen((0..n).map(|_| AtomicU32::new(Seen::UNKNOWN)).collect())
    }

    /// Notes the calling thread (index `me`) on its CPU, and returns the CPU.
    fn note(&self, me: usize) -> Option<u32> {
        let cpu = current_cpu();
        if let (Some(c), Some(slot)) = (cpu, self.0.get(me)) {
            slot.store(c, Ordering::Relaxed);
        }
        cpu
    }

    /// Another thread than `me` was last seen on `cpu`, among `others`.
    fn shares(&self, me: usize, cpu: Option<u32>, others: impl Iterator<Item = usize>) -> bool {
        let Some(c) = cpu else { return false };
        let mut others = others;
        others.any(|j| {
            j != me
                && self
                    .0
                    .get(j)
                    .is_some_and(|s| s.load(Ordering::Relaxed) == c)
        })
    }
}

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

/// How long an idle worker waits for the next phase before it sleeps:
/// longer than the serial parts of a step (contacts, position update: ~0.5
/// ms on a 101 × 101 grid), so a running simulation does not put its workers
/// to sleep.
pub const SPIN: Duration = Duration::from_millis(1);

/// How long a thread waits at a [`Barrier`], or the caller for the workers
/// to finish a phase, before it sleeps: a partner that has not arrived by
/// then is not running (another process has its core, for a time slice or
/// more). Past [`SPIN_ALONE`] the waiter yields its core between looks, so
/// up to then it takes only time nothing else on its core wants; sleeping
/// sooner costs more when the partner was away briefly (a sleeper that is
/// woken may wait for a core again).
pub const PATIENCE: Duration = Duration::from_millis(1);

/// How long a waiter spins before it also yields its core between looks:
/// the waits of a step on free cores (the imbalance of a phase) are mostly
/// shorter; a waiter sharing its core with the partner it waits for lets
/// the partner run after this.
pub const SPIN_ALONE: Duration = Duration::from_micros(5);

/// Where threads wait for a condition another thread makes true: spin
/// ([`SPIN_ALONE`]), then spin and yield the core between looks, then sleep
/// on a condition variable. The thread that makes the condition true calls
/// [`Parking::wake`], which costs one load when nobody sleeps.
struct Parking {
    /// Waiters that have stopped spinning (counted before their last look
    /// at the condition, under `lock`).
    parked: AtomicUsize,
    lock: Mutex<()>,
    cv: Condvar,
}

impl Parking {
    fn new() -> Parking {
        Parking {
            parked: AtomicUsize::new(0),
            lock: Mutex::new(()),
            cv: Condvar::new(),
        }
    }

    /// Returns once `ready()`. Sleeps after `patience`, or at once when
    /// `hurry()` (looked at before and between spins). `ready` must read
    /// with `SeqCst` what the waker writes with `SeqCst` before
    /// [`Parking::wake`].
    fn wait(&self, ready: impl Fn() -> bool, patience: Duration, hurry: impl Fn() -> bool) {
        if ready() {
            return;
        }
        let start = Instant::now();
        while !hurry() {
            for _ in 0..64 {
                if ready() {
                    return;
                }
                std::hint::spin_loop();
            }
            let waited = start.elapsed();
            if waited >= patience {
                break;
            }
            if waited >= SPIN_ALONE {
                std::thread::yield_now();
            }
        }
        let mut g = self.lock.lock().unwrap_or_else(|e| e.into_inner());
        // counted before the last look: a waker that made `ready` true after
        // that look sees the count and notifies, which it can do only once
        // this thread waits (it holds the lock until then)
        self.parked.fetch_add(1, Ordering::SeqCst);
        while !ready() {
            g = self.cv.wait(g).unwrap_or_else(|e| e.into_inner());
        }
        self.parked.fetch_sub(1, Ordering::SeqCst);
    }

    /// Wakes the sleeping waiters; called after making their condition true
    /// (a `SeqCst` write).
    fn wake(&self) {
        if self.parked.load(Ordering::SeqCst) > 0 {
            self.notify();
        }
    }

    fn notify(&self) {
        // taking the lock waits out a waiter between its last look and its
        // sleep; notified after the lock is let go, the woken waiter does not
        // wait for the waker's lock (on a shared core, one switch less)
        drop(self.lock.lock().unwrap_or_else(|e| e.into_inner()));
        self.cv.notify_all();
    }

    /// Waiters asleep (or about to be).
    #[cfg(test)]
    fn parked(&self) -> usize {
        self.parked.load(Ordering::SeqCst)
    }
}

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
    /// How long an idle worker waits before it sleeps.
    spin: Duration,
    /// How long the caller waits for the workers before it sleeps.
    patience: Duration,
    /// Phases started so far; a worker runs the job when it sees it change.
    epoch: AtomicUsize,
    /// Items 1..size of the current phase finished (by their worker, or by
    /// the caller that took them).
    done: AtomicUsize,
    /// `claim[t]`: the last phase (epoch) whose item t a thread has taken;
    /// the thread that raises it runs the item, its worker or the caller.
    claim: Vec<AtomicUsize>,
    /// Written by [`Team::run`] only while no worker reads it (before the
    /// epoch changes; every worker has finished the previous phase).
    job: UnsafeCell<Option<Job>>,
    /// Where idle workers wait for the next phase.
    idle: Parking,
    /// Where the caller waits for the workers to finish a phase.
    finish: Parking,
    /// Where the caller (0) and the workers were last seen.
    seen: Seen,
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
        Team::with_waits(size, SPIN, PATIENCE)
    }

    /// [`Team::new`] with idle workers waiting for `spin` before they sleep.
    #[cfg(test)]
    pub fn with_spin(size: usize, spin: Duration) -> Team {
        Team::with_waits(size, spin, PATIENCE)
    }

    /// [`Team::new`] with idle workers waiting for `spin` before they sleep,
    /// and the caller `patience` for the workers to finish a phase.
    pub fn with_waits(size: usize, spin: Duration, patience: Duration) -> Team {
        let size = size.max(1);
        let shared = Arc::new(Shared {
            size,
            spin,
            patience,
            epoch: AtomicUsize::new(0),
            done: AtomicUsize::new(0),
            claim: (0..size).map(|_| AtomicUsize::new(0)).collect(),
            job: UnsafeCell::new(None),
            idle: Parking::new(),
            finish: Parking::new(),
            seen: Seen::new(size),
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
    #[cfg(test)]
    pub fn sleeping(&self) -> usize {
        self.shared.idle.parked()
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
        let cpu = sh.seen.note(0);
        sh.done.store(0, Ordering::Relaxed);
        sh.rest.store(false, Ordering::SeqCst);
        let epoch = sh.epoch.fetch_add(1, Ordering::SeqCst) + 1;
        sh.idle.wake();
        struct Wait<'a>(&'a Shared, Option<u32>);
        impl Drop for Wait<'_> {
            fn drop(&mut self) {
                let sh = self.0;
                // a worker on this CPU runs only once the caller gives it up
                sh.finish.wait(
                    || sh.done.load(Ordering::SeqCst) + 1 >= sh.size,
                    sh.patience,
                    || sh.seen.shares(0, self.1, 1..sh.size),
                );
            }
        }
        let wait = Wait(sh, cpu);
        f(0);
        // items no worker has taken yet (their workers are not running:
        // another process has their cores) run here; an item that waits at
        // a barrier for the others is always taken by its worker before
        // f(0) returns
        for t in 1..sh.size {
            if sh.claim[t].fetch_max(epoch, Ordering::SeqCst) < epoch {
                sh.run_item(t);
                sh.done.fetch_add(1, Ordering::SeqCst);
            }
        }
        drop(wait);
        if sh.panicked.swap(false, Ordering::Relaxed) {
            panic!("a worker thread of the simulation panicked");
        }
    }
}

fn worker(sh: &Shared, t: usize) {
    INDEX.with(|i| i.set(t));
    let mut seen = 0;
    loop {
        // the caller on this CPU (its serial part of the step) runs only
        // once this worker gives it up
        let cpu = sh.seen.note(t);
        sh.idle.wait(
            || sh.epoch.load(Ordering::SeqCst) != seen || sh.stop.load(Ordering::SeqCst),
            sh.spin,
            || sh.rest.load(Ordering::Relaxed) || sh.seen.shares(t, cpu, 0..1),
        );
        if sh.stop.load(Ordering::SeqCst) {
            return;
        }
        seen = sh.epoch.load(Ordering::SeqCst);
        // the item is this worker's unless the caller took it, or the phase
        // is over (then the caller took it, and `claim[t]` ≥ `seen`)
        if sh.claim[t].fetch_max(seen, Ordering::SeqCst) < seen {
            sh.seen.note(t);
            sh.run_item(t);
            if sh.done.fetch_add(1, Ordering::SeqCst) + 2 >= sh.size {
                sh.finish.wake();
            }
        }
    }
}

impl Shared {
    /// Runs item t of the current phase; its taker has raised `claim[t]` to
    /// the current epoch.
    fn run_item(&self, t: usize) {
        // SAFETY: `run` wrote the job before the epoch changed, and waits for
        // this item (counted in `done`) before the closure goes away or the
        // job is written again
        let job = unsafe { *self.job.get() };
        if let Some(job) = job {
            if catch_unwind(AssertUnwindSafe(|| unsafe { (job.call)(job.data, t) })).is_err() {
                self.panicked.store(true, Ordering::Relaxed);
            }
        }
    }
}

impl Drop for Team {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        self.shared.idle.notify();
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

/// Sense-reversing barrier whose waiters spin briefly, then yield, then
/// sleep ([`PATIENCE`]): the machine may be shared, and a thread waiting for
/// a partner another process has taken the core from must not keep its own.
pub struct Barrier {
    n: usize,
    patience: Duration,
    count: AtomicUsize,
    generation: AtomicUsize,
    parking: Parking,
    /// Where each thread (by its index in the team) last arrived.
    seen: Seen,
}

impl Barrier {
    pub fn new(n: usize) -> Self {
        Barrier::with_patience(n, PATIENCE)
    }

    /// A barrier whose waiters sleep after `patience`.
    pub fn with_patience(n: usize, patience: Duration) -> Self {
        Barrier {
            n,
            patience,
            count: AtomicUsize::new(0),
            generation: AtomicUsize::new(0),
            parking: Parking::new(),
            seen: Seen::new(n),
        }
    }

    pub fn wait(&self) {
        if self.n == 1 {
            return;
        }
        let me = INDEX.with(|i| i.get());
        let cpu = self.seen.note(me);
        let g = self.generation.load(Ordering::Acquire);
        if self.count.fetch_add(1, Ordering::AcqRel) + 1 == self.n {
            self.count.store(0, Ordering::Relaxed);
            self.generation.fetch_add(1, Ordering::SeqCst);
            self.parking.wake();
            return;
        }
        // a partner last seen on this CPU runs only once this thread gives
        // it up
        self.parking.wait(
            || self.generation.load(Ordering::SeqCst) != g,
            self.patience,
            || self.seen.shares(me, cpu, 0..self.n),
        );
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
        // (a worker last seen on the caller's CPU sleeps at once, the others
        // would spin for the minute)
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

    /// A relaxation over `x` in rounds, each thread owning a contiguous
    /// range and reading its neighbours' values across the barrier, as the
    /// PCG does: `x_i ← (x_{i−1} + x_i + x_{i+1}) / 3 + b_i`, then a sum of
    /// the thread's range. `nap(t, round)` sleeps where a descheduled thread
    /// would. Returns x and the sums, every round's, in thread order.
    fn relax(team: &mut Team, rounds: usize, nap: impl Fn(usize, usize) + Sync) -> Vec<f64> {
        let n = 1000;
        let nt = team.size();
        let barrier = Barrier::new(nt);
        let x: Vec<AtomicU64> = (0..n)
            .map(|i| AtomicU64::new((i as f64).sin().to_bits()))
            .collect();
        let next: Vec<AtomicU64> = (0..n).map(|_| AtomicU64::new(0)).collect();
        let sums: Vec<AtomicU64> = (0..rounds * nt).map(|_| AtomicU64::new(0)).collect();
        let get = |v: &[AtomicU64], i: usize| f64::from_bits(v[i].load(Ordering::Relaxed));
        team.run(|t| {
            let (lo, hi) = (t * n / nt, (t + 1) * n / nt);
            for round in 0..rounds {
                nap(t, round);
                let mut sum = 0.0;
                for i in lo..hi {
                    let l = if i > 0 { get(&x, i - 1) } else { 0.0 };
                    let r = if i + 1 < n { get(&x, i + 1) } else { 0.0 };
                    let v = (l + get(&x, i) + r) / 3.0 + 1e-3 * (i as f64).cos();
                    next[i].store(v.to_bits(), Ordering::Relaxed);
                    sum += v;
                }
                sums[round * nt + t].store(sum.to_bits(), Ordering::Relaxed);
                // every thread has written next before anyone copies it
                barrier.wait();
                for i in lo..hi {
                    x[i].store(next[i].load(Ordering::Relaxed), Ordering::Relaxed);
                }
                // every thread has copied before anyone reads x again
                barrier.wait();
            }
        });
        let mut out: Vec<f64> = (0..n).map(|i| get(&x, i)).collect();
        out.extend((0..rounds * nt).map(|k| get(&sums, k)));
        out
    }

    #[test]
    fn napping_threads_give_the_serial_result() {
        let rounds = 300;
        // the reference: the same ranges run one after another, each round's
        // sums added in thread order
        let serial = |nt: usize| {
            let n = 1000;
            let mut x: Vec<f64> = (0..n).map(|i| (i as f64).sin()).collect();
            let mut sums = Vec::new();
            for _ in 0..rounds {
                let next: Vec<f64> = (0..n)
                    .map(|i| {
                        let l = if i > 0 { x[i - 1] } else { 0.0 };
                        let r = if i + 1 < n { x[i + 1] } else { 0.0 };
                        (l + x[i] + r) / 3.0 + 1e-3 * (i as f64).cos()
                    })
                    .collect();
                for t in 0..nt {
                    let (lo, hi) = (t * n / nt, (t + 1) * n / nt);
                    sums.push(next[lo..hi].iter().sum::<f64>());
                }
                x = next;
            }
            x.extend(sums);
            x
        };
        for nt in [1, 2, 3] {
            // workers, and then the caller, sleep past the waits' patience
            // in some rounds: their partners must wait (and sleep) for them
            for sleeper in 0..nt {
                let mut team = Team::new(nt);
                let got = relax(&mut team, rounds, |t, round| {
                    if t == sleeper && round % 7 == 3 {
                        std::thread::sleep(PATIENCE * 3);
                    } else if round % 11 == 5 {
                        std::thread::yield_now();
                    }
                });
                let want = serial(nt);
                assert_eq!(got.len(), want.len());
                for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                    assert_eq!(
                        g.to_bits(),
                        w.to_bits(),
                        "{nt} threads, sleeper {sleeper}, value {k}: {g} != {w}"
                    );
                }
            }
        }
    }

    #[test]
    fn sleeping_waiters_are_always_woken() {
        // no patience: every wait that is not over at once sleeps, so a
        // wake-up lost between a waiter's last look and its sleep would hang
        // a round; the rounds run on a thread of their own, watched
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for size in [2, 3] {
                let mut team = Team::with_waits(size, Duration::ZERO, Duration::ZERO);
                let barrier = Barrier::with_patience(size, Duration::ZERO);
                let hits = AtomicU64::new(0);
                for _ in 0..5000 {
                    team.run(|_| {
                        hits.fetch_add(1, Ordering::Relaxed);
                        barrier.wait();
                        hits.fetch_add(1, Ordering::Relaxed);
                        barrier.wait();
                    });
                }
                tx.send((size, hits.load(Ordering::Relaxed))).unwrap();
            }
        });
        for size in [2, 3] {
            let got = rx.recv_timeout(Duration::from_secs(120));
            assert_eq!(
                got,
                Ok((size, 2 * 5000 * size as u64)),
                "a sleeping waiter was not woken"
            );
        }
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
