//! A team of worker threads started once per simulation and reused by every
//! parallel phase of a step (the contacts, the assembly, the PCG, the update
//! after the solve).
//!
//! This is the solver's only threading mechanism: [`Team::run_each`] hands
//! item t of a phase to thread t, and work whose threads must meet inside
//! it (the PCG, three times per iteration) runs in stages whose parts any
//! thread may take ([`Team::run_stages`]).
//!
//! The threads are not started per phase (`std::thread::scope`): the kernel
//! places each new thread anew and may put two of them on one core. A worker
//! that lives for the whole run and waits between phases stays on its own
//! core.
//!
//! Every wait (a worker's for the next phase, the caller's for the workers
//! or for a stage's parts) spins for [`SPIN_ALONE`], then spins and yields
//! its core between looks, then sleeps on a condition variable ([`SPIN`]
//! between phases, [`PATIENCE`] inside them) until the thread it waits for
//! wakes it. So a thread whose partner is descheduled (another process has
//! its core) gives its own core away instead of spinning out the time slice,
//! and an idle node does not burn a core. An item of a phase whose worker has
//! not started it by the time the caller has finished its own runs on the
//! caller's thread, and so do the parts of staged work a worker away from
//! its core cannot take (a worker that would wait long for a stage leaves
//! the rest to the caller): with another process on the worker's core the
//! work goes on at one core's speed. What an item or a part computes does
//! not depend on the thread that runs it, so results do not change.

use std::cell::{Cell, UnsafeCell};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering};
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
/// once ([`super::team::Team`]) a PCG stage's hand-over costs well under a
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
/// of the stages' hand-overs).
pub const VERTICES_PER_THREAD: usize = 250;

/// How long an idle worker waits for the next phase before it sleeps:
/// longer than the serial parts of a step (contacts, position update: ~0.5
/// ms on a 101 × 101 grid), so a running simulation does not put its workers
/// to sleep.
pub const SPIN: Duration = Duration::from_millis(1);

/// How long the caller waits for the workers to finish a phase, or for a
/// stage's parts in flight ([`Team::run_stages`]), before it sleeps (a
/// worker waiting for a stage leaves instead): a partner that has not arrived by
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
        if spin_for(&ready, patience, hurry) {
            return;
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
    alone: Alone,
}

/// A wait for a worker in the middle of a phase at least this long says its
/// core is taken by a process as busy as the simulation (an equal share of
/// the core is a time slice of milliseconds); shorter ones (a process of
/// lower priority, an interrupt) are waited out.
pub const AWAY: Duration = Duration::from_millis(2);

/// Two waits of [`AWAY`] or more within this say the worker's core is taken
/// for a while (one alone is waited out).
pub const RECUR: Duration = Duration::from_millis(50);

/// How long the caller runs every phase alone after it waited [`AWAY`] for
/// a worker twice within [`RECUR`], the first time: every phase that waits
/// for the worker would wait out a time slice.
pub const ALONE_FIRST: Duration = Duration::from_millis(20);

/// The longest a caller runs alone: a worker found late again soon after it
/// came back doubles the time, up to this; the next phase after it tries
/// the workers again.
pub const ALONE_MAX: Duration = Duration::from_millis(320);

/// When the caller runs the phases alone ([`ALONE_FIRST`]). Which thread runs
/// an item changes no result, so neither does this.
#[derive(Debug)]
struct Alone {
    first: Duration,
    until: Option<Instant>,
    length: Duration,
    /// The last wait of [`AWAY`] or more.
    last_away: Option<Instant>,
}

impl Alone {
    fn new(first: Duration) -> Alone {
        Alone {
            first,
            until: None,
            length: first,
            last_away: None,
        }
    }

    fn now(&self) -> bool {
        self.until.is_some_and(|u| Instant::now() < u)
    }

    /// The caller waited `waited` for a worker in the middle of a phase: the
    /// second wait of [`AWAY`] or more within [`RECUR`] sends it alone for
    /// [`ALONE_FIRST`], or twice as long as the last time if that ended a
    /// short while ago.
    fn waited(&mut self, waited: Duration) {
        let now = Instant::now();
        if waited < AWAY || self.until.is_some_and(|u| now < u) {
            return;
        }
        let recurs = self
            .last_away
            .is_some_and(|l| now.duration_since(l) < RECUR);
        self.last_away = Some(now);
        if !recurs {
            return;
        }
        let again = self
            .until
            .is_some_and(|u| now.duration_since(u) < 4 * self.length);
        self.length = match again {
            true => (2 * self.length).min(ALONE_MAX),
            false => self.first,
        };
        self.until = Some(now + self.length);
    }
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

    /// [`Team::new`] with the caller running every phase alone for `first`
    /// after a worker was found late ([`ALONE_FIRST`]; zero: never).
    #[cfg(test)]
    pub fn with_alone(size: usize, first: Duration) -> Team {
        let mut team = Team::new(size);
        team.alone = Alone::new(first);
        team
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
        Team {
            shared,
            workers,
            alone: Alone::new(ALONE_FIRST),
        }
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
    /// and returns when all have returned (all of them on the caller's
    /// thread for a while after a worker was found late, [`ALONE_FIRST`]). A
    /// panic in a worker is raised here, after every thread has finished.
    pub fn run<F: Fn(usize) + Sync>(&mut self, f: F) {
        let sh = &*self.shared;
        if sh.size == 1 || self.alone.now() {
            (0..sh.size).for_each(f);
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
        // the caller waits only for items in flight on workers (it runs the
        // others): how long says whether one was taken off its core
        struct Wait<'a>(&'a Shared, Option<u32>, &'a Cell<Duration>);
        impl Drop for Wait<'_> {
            fn drop(&mut self) {
                let sh = self.0;
                let start = Instant::now();
                // a worker on this CPU runs only once the caller gives it up
                sh.finish.wait(
                    || sh.done.load(Ordering::SeqCst) + 1 >= sh.size,
                    sh.patience,
                    || sh.seen.shares(0, self.1, 1..sh.size),
                );
                self.2.set(start.elapsed());
            }
        }
        let waited = Cell::new(Duration::ZERO);
        let wait = Wait(sh, cpu, &waited);
        f(0);
        // items no worker has taken yet (their workers are not running:
        // another process has their cores) run here (a worker's share of
        // staged work is over when the caller's is)
        for t in 1..sh.size {
            if sh.claim[t].fetch_max(epoch, Ordering::SeqCst) < epoch {
                sh.run_item(t);
                sh.done.fetch_add(1, Ordering::SeqCst);
            }
        }
        drop(wait);
        self.alone.waited(waited.get());
        if sh.panicked.swap(false, Ordering::Relaxed) {
            panic!("a worker thread of the simulation panicked");
        }
    }
}

/// Work done in stages, each split into the same number of parts: the
/// parts of a stage may run on any thread of a team and at the same time,
/// each exactly once; a stage starts once every part of the one before has
/// finished ([`Team::run_stages`]).
pub trait Stages: Sync {
    /// Runs part `p` of the stage open now.
    fn part(&self, p: usize);

    /// Called once every part of the stage has finished, on the thread that
    /// finished the last one, before any part of the next stage runs:
    /// opens the next stage (true) or ends the work (false).
    fn next(&self) -> bool;
}

/// How long the caller waits for a part another thread is running before
/// it counts that thread as away from its core (another process has it):
/// the imbalance of a stage on free cores is a few microseconds, a thread
/// taken off its core is gone for a time slice (milliseconds).
pub const LATE: Duration = Duration::from_micros(200);

/// Where the threads of [`Team::run_stages`] are: stage s's parts are the
/// tickets `s · parts .. (s + 1) · parts`, taken in order by whichever
/// thread asks first.
struct Staging {
    parts: usize,
    /// The next ticket to take.
    ticket: AtomicUsize,
    /// Parts finished, every stage's.
    done: AtomicUsize,
    /// The stage open now.
    open: AtomicUsize,
    /// The work is over ([`Stages::next`] said so, or a part panicked).
    over: AtomicBool,
    panicked: AtomicBool,
    /// The caller waited past [`LATE`] for a part: the workers take no
    /// more parts, and the caller runs the rest.
    late: AtomicBool,
    /// Where the caller waits for a part in flight.
    parking: Parking,
    /// The caller's longest wait for a part in flight, ns.
    longest_wait: AtomicU64,
}

impl Staging {
    /// Takes a part of stage `s` if one is left.
    fn claim(&self, s: usize) -> Option<usize> {
        let n = self.parts;
        let mut k = self.ticket.load(Ordering::SeqCst);
        // stage s opened once every part of s − 1 had finished, so k ≥ s · n
        while k < (s + 1) * n {
            match self
                .ticket
                .compare_exchange_weak(k, k + 1, Ordering::SeqCst, Ordering::SeqCst)
            {
                Ok(_) => return Some(k - s * n),
                Err(now) => k = now,
            }
        }
        None
    }

    /// Runs part `p` of stage `s`; the thread that finishes the stage's
    /// last part opens the next one (or ends the work).
    fn run_part(&self, work: &impl Stages, s: usize, p: usize) {
        if catch_unwind(AssertUnwindSafe(|| work.part(p))).is_err() {
            self.panicked.store(true, Ordering::SeqCst);
        }
        if self.done.fetch_add(1, Ordering::SeqCst) + 1 == (s + 1) * self.parts {
            let more = !self.panicked.load(Ordering::SeqCst)
                && match catch_unwind(AssertUnwindSafe(|| work.next())) {
                    Ok(more) => more,
                    Err(_) => {
                        self.panicked.store(true, Ordering::SeqCst);
                        false
                    }
                };
            if !more {
                self.over.store(true, Ordering::SeqCst);
            }
            self.open.store(s + 1, Ordering::SeqCst);
            self.parking.wake();
        }
    }

    /// Thread t's share of the work: every part it can take, until the
    /// work is over, or (a worker) until it would have to wait long for a
    /// stage to open.
    fn work_on(&self, work: &impl Stages, sh: &Shared, t: usize) {
        let (size, seen) = (sh.size, &sh.seen);
        loop {
            let s = self.open.load(Ordering::SeqCst);
            if self.over.load(Ordering::SeqCst) {
                return;
            }
            // a worker takes no more parts once the caller has found one
            // late (it is likely to be taken off its core again)
            while !(t != 0 && self.late.load(Ordering::SeqCst)) {
                let Some(p) = self.claim(s) else { break };
                self.run_part(work, s, p);
            }
            let ready = || self.open.load(Ordering::SeqCst) != s;
            if ready() {
                continue;
            }
            let cpu = seen.note(t);
            if t == 0 {
                // the parts in flight are other threads'; one away from its
                // core is waited for, and the workers take no more parts
                let start = Instant::now();
                let late = || {
                    if !self.late.load(Ordering::Relaxed) && start.elapsed() >= LATE {
                        self.late.store(true, Ordering::SeqCst);
                    }
                };
                self.parking.wait(ready, sh.patience, || {
                    late();
                    seen.shares(0, cpu, 1..size)
                });
                // (also when it slept at once, sharing its core)
                late();
                let waited = start.elapsed().as_nanos().min(u64::MAX as u128) as u64;
                self.longest_wait.fetch_max(waited, Ordering::Relaxed);
            } else if self.late.load(Ordering::SeqCst)
                || !spin_for(ready, sh.patience, || seen.shares(t, cpu, 0..1))
            {
                // a worker that would wait long, or shares the caller's
                // core, leaves the rest to the caller (who takes every part
                // left: it never waits on a thread that is not running one)
                return;
            }
        }
    }
}

/// Spins (then yields between looks past [`SPIN_ALONE`]) until `ready()`;
/// false if `patience` ran out or `hurry()` (looked at before and between
/// spins) first.
fn spin_for(ready: impl Fn() -> bool, patience: Duration, hurry: impl Fn() -> bool) -> bool {
    if ready() {
        return true;
    }
    let start = Instant::now();
    while !hurry() {
        for _ in 0..64 {
            if ready() {
                return true;
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
    ready()
}

impl Team {
    /// Runs `work` in stages of `parts` parts ([`Stages`]) on the team's
    /// threads: each takes the parts of the open stage one at a time, and
    /// the thread that finishes a stage's last part opens the next. Which
    /// thread runs a part does not change what it computes, so the result
    /// depends on `parts`, never on the threads or their scheduling. A
    /// thread waits only for parts in flight: a worker that would wait long
    /// (its partners are away from their cores, or it shares the caller's
    /// core) leaves the rest of the work to the caller, and once the caller
    /// has waited past [`LATE`] for a worker's part, every worker leaves
    /// after the part it runs; so with a core taken by another process the
    /// work goes on at about one core's speed instead of waiting out time
    /// slices at every stage. A panic in a part ends the work and is
    /// raised here.
    pub fn run_stages(&mut self, parts: usize, work: &impl Stages) {
        let st = Staging {
            parts: parts.max(1),
            ticket: AtomicUsize::new(0),
            done: AtomicUsize::new(0),
            open: AtomicUsize::new(0),
            over: AtomicBool::new(false),
            panicked: AtomicBool::new(false),
            late: AtomicBool::new(false),
            parking: Parking::new(),
            longest_wait: AtomicU64::new(0),
        };
        let shared = Arc::clone(&self.shared);
        self.run(|t| st.work_on(work, &shared, t));
        self.alone
            .waited(Duration::from_nanos(st.longest_wait.load(Ordering::SeqCst)));
        if st.panicked.load(Ordering::SeqCst) {
            panic!("a part of the simulation's staged work panicked");
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

#[cfg(test)]
mod tests {
    use super::*;

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

    /// A relaxation over `x` in rounds of two stages, as the PCG's: in the
    /// first each of `parts` contiguous ranges computes
    /// `next_i = (x_{i−1} + x_i + x_{i+1}) / 3 + b_i` (reading its
    /// neighbours' values) and the sum of its range, in the second copies
    /// `next` to `x`. `nap(part, round, thread)` sleeps where a descheduled
    /// thread would. The sums are added in range order by [`Stages::next`],
    /// which also counts its calls.
    struct Relax<F> {
        parts: usize,
        rounds: usize,
        x: Vec<AtomicU64>,
        next: Vec<AtomicU64>,
        sums: Vec<AtomicU64>,
        /// Per round, the sum of the ranges' sums (added by `next`).
        totals: Vec<AtomicU64>,
        /// The stage open now (round · 2 + which), kept by `next`.
        stage: AtomicUsize,
        /// Parts run, per stage, and by a worker (any stage).
        runs: Vec<AtomicUsize>,
        by_workers: AtomicUsize,
        nap: F,
    }

    const N: usize = 1000;

    impl<F: Fn(usize, usize, usize) + Sync> Relax<F> {
        fn new(parts: usize, rounds: usize, nap: F) -> Self {
            let zeros = |n: usize| (0..n).map(|_| AtomicU64::new(0)).collect::<Vec<_>>();
            Relax {
                parts,
                rounds,
                x: (0..N)
                    .map(|i| AtomicU64::new((i as f64).sin().to_bits()))
                    .collect(),
                next: zeros(N),
                sums: zeros(parts),
                totals: zeros(rounds),
                stage: AtomicUsize::new(0),
                runs: (0..2 * rounds).map(|_| AtomicUsize::new(0)).collect(),
                by_workers: AtomicUsize::new(0),
                nap,
            }
        }

        fn get(v: &[AtomicU64], i: usize) -> f64 {
            f64::from_bits(v[i].load(Ordering::Relaxed))
        }

        /// x, then every round's total.
        fn result(&self) -> Vec<f64> {
            let mut out: Vec<f64> = (0..N).map(|i| Self::get(&self.x, i)).collect();
            out.extend((0..self.rounds).map(|r| Self::get(&self.totals, r)));
            out
        }
    }

    impl<F: Fn(usize, usize, usize) + Sync> Stages for Relax<F> {
        fn part(&self, p: usize) {
            let stage = self.stage.load(Ordering::Relaxed);
            self.runs[stage].fetch_add(1, Ordering::Relaxed);
            let me = INDEX.with(|i| i.get());
            if me != 0 {
                self.by_workers.fetch_add(1, Ordering::Relaxed);
            }
            let (round, copy) = (stage / 2, stage % 2 == 1);
            let (lo, hi) = (p * N / self.parts, (p + 1) * N / self.parts);
            if copy {
                for i in lo..hi {
                    self.x[i].store(self.next[i].load(Ordering::Relaxed), Ordering::Relaxed);
                }
                return;
            }
            (self.nap)(p, round, me);
            let x = |i: usize| Self::get(&self.x, i);
            let mut sum = 0.0;
            for i in lo..hi {
                let l = if i > 0 { x(i - 1) } else { 0.0 };
                let r = if i + 1 < N { x(i + 1) } else { 0.0 };
                let v = (l + x(i) + r) / 3.0 + 1e-3 * (i as f64).cos();
                self.next[i].store(v.to_bits(), Ordering::Relaxed);
                sum += v;
            }
            self.sums[p].store(sum.to_bits(), Ordering::Relaxed);
        }

        fn next(&self) -> bool {
            let stage = self.stage.load(Ordering::Relaxed);
            if stage.is_multiple_of(2) {
                let total: f64 = (0..self.parts).map(|p| Self::get(&self.sums, p)).sum();
                self.totals[stage / 2].store(total.to_bits(), Ordering::Relaxed);
            }
            self.stage.store(stage + 1, Ordering::Relaxed);
            stage + 1 < 2 * self.rounds
        }
    }

    /// The relaxation's result done in order on one thread.
    fn relax_serial(parts: usize, rounds: usize) -> Vec<f64> {
        let mut x: Vec<f64> = (0..N).map(|i| (i as f64).sin()).collect();
        let mut totals = Vec::new();
        for _ in 0..rounds {
            let next: Vec<f64> = (0..N)
                .map(|i| {
                    let l = if i > 0 { x[i - 1] } else { 0.0 };
                    let r = if i + 1 < N { x[i + 1] } else { 0.0 };
                    (l + x[i] + r) / 3.0 + 1e-3 * (i as f64).cos()
                })
                .collect();
            let sums =
                (0..parts).map(|p| next[p * N / parts..(p + 1) * N / parts].iter().sum::<f64>());
            totals.push(sums.sum::<f64>());
            x = next;
        }
        x.extend(totals);
        x
    }

    #[test]
    fn staged_work_gives_the_serial_result_whatever_runs_it() {
        let rounds = 300;
        for parts in [1, 2, 3] {
            let want = relax_serial(parts, rounds);
            for size in [1, 2, 3] {
                // parts that sleep past the waits' patience in some rounds
                // (a thread taken off its core), others that yield
                for sleeper in 0..parts {
                    let mut team = Team::new(size);
                    let work = Relax::new(parts, rounds, |p, round, _| {
                        if p == sleeper && round % 7 == 3 {
                            std::thread::sleep(PATIENCE * 3);
                        } else if round % 11 == 5 {
                            std::thread::yield_now();
                        }
                    });
                    team.run_stages(parts, &work);
                    let got = work.result();
                    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                        assert_eq!(
                            g.to_bits(),
                            w.to_bits(),
                            "{parts} parts on {size} threads, sleeper {sleeper}, value {k}"
                        );
                    }
                    // every part of every stage ran once
                    for (stage, runs) in work.runs.iter().enumerate() {
                        assert_eq!(runs.load(Ordering::Relaxed), parts, "stage {stage}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_worker_found_late_leaves_the_rest_to_the_caller() {
        // a worker away from its core for 5 ms in every part it takes (far
        // past LATE; the caller's parts take 0.1 ms, so the worker comes
        // in before the caller has run them all): once the caller has
        // waited for it, it takes no more, and the work ends at the
        // caller's pace, with the serial result
        let (parts, rounds) = (2, 200);
        let mut team = Team::new(2);
        let work = Relax::new(parts, rounds, |_, _, thread| {
            std::thread::sleep(Duration::from_micros(if thread == 0 { 100 } else { 5000 }));
        });
        team.run_stages(parts, &work);
        assert_eq!(work.result(), relax_serial(parts, rounds));
        // 800 parts, of which a worker that went on taking them would take
        // hundreds; it takes a few while the caller is itself away from its
        // core, at most
        let by_workers = work.by_workers.load(Ordering::Relaxed);
        assert!(
            by_workers <= 10,
            "the late worker took {by_workers} parts of 800"
        );
    }

    #[test]
    fn after_a_late_worker_the_caller_runs_alone_for_a_while() {
        let mut team = Team::with_alone(2, Duration::from_millis(300));
        let on_worker = AtomicUsize::new(0);
        let count = |t: usize| {
            if t != 0 && INDEX.with(|i| i.get()) != 0 {
                on_worker.fetch_add(1, Ordering::Relaxed);
            }
        };
        // the worker away from its core 8 ms in its item (the caller, 2 ms
        // in its own, waits for it: an item in flight is not taken back),
        // twice (once is waited out); again if the worker was not there in
        // time to take it
        for _ in 0..40 {
            team.run(|t| {
                count(t);
                let on_worker = INDEX.with(|i| i.get()) != 0;
                std::thread::sleep(Duration::from_millis(if on_worker { 8 } else { 2 }));
            });
            if on_worker.load(Ordering::Relaxed) == 2 {
                break;
            }
        }
        let before = on_worker.load(Ordering::Relaxed);
        assert_eq!(before, 2, "the worker did not take its item twice");
        // the caller's items take 1 ms, so a worker woken for a phase
        // comes in time for its own (below), but the next 50 phases run
        // every item on the caller
        let slow_caller = |t: usize| {
            count(t);
            if t == 0 {
                std::thread::sleep(Duration::from_millis(1));
            }
        };
        for _ in 0..50 {
            team.run(slow_caller);
        }
        assert_eq!(
            on_worker.load(Ordering::Relaxed),
            before,
            "a worker ran an item"
        );
        // and after the while, the workers again
        std::thread::sleep(Duration::from_millis(400));
        for _ in 0..200 {
            team.run(slow_caller);
            if on_worker.load(Ordering::Relaxed) > before {
                break;
            }
        }
        assert!(
            on_worker.load(Ordering::Relaxed) > before,
            "the worker never came back"
        );
    }

    #[test]
    fn a_panic_in_a_part_reaches_the_caller_and_the_team_goes_on() {
        struct Fails(AtomicUsize);
        impl Stages for Fails {
            fn part(&self, p: usize) {
                if self.0.fetch_add(1, Ordering::SeqCst) == 5 {
                    panic!("part {p} fails");
                }
            }
            fn next(&self) -> bool {
                true
            }
        }
        for size in [1, 2] {
            let mut team = Team::new(size);
            let fails = Fails(AtomicUsize::new(0));
            let r = catch_unwind(AssertUnwindSafe(|| team.run_stages(2, &fails)));
            assert!(r.is_err(), "{size} threads");
            // the work stopped at the stage of the panic
            assert!(fails.0.load(Ordering::SeqCst) <= 6);
            let work = Relax::new(2, 10, |_, _, _| {});
            team.run_stages(2, &work);
            assert_eq!(work.result(), relax_serial(2, 10));
        }
    }

    #[test]
    fn sleeping_waiters_are_always_woken() {
        // no patience: every wait that is not over at once sleeps (the
        // caller's) or leaves (a worker's), so a wake-up lost between the
        // caller's last look and its sleep would hang a stage; the work runs
        // on a thread of its own, watched
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for size in [2, 3] {
                let mut team = Team::with_waits(size, Duration::ZERO, Duration::ZERO);
                // (every stage with workers: a slow wake-up must not send the
                // caller alone)
                team.alone = Alone::new(Duration::ZERO);
                for _ in 0..200 {
                    let work = Relax::new(size, 20, |_, _, _| {});
                    team.run_stages(size, &work);
                    assert_eq!(work.result(), relax_serial(size, 20));
                }
                tx.send(size).unwrap();
            }
        });
        for size in [2, 3] {
            let got = rx.recv_timeout(Duration::from_secs(120));
            assert_eq!(got, Ok(size), "a sleeping waiter was not woken");
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
