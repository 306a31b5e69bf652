//! The solver's threads: a team that stays awake between the phases of a step.
//!
//! A step of the parallel solver runs three short parallel phases (the element blocks, the
//! forces kept aside, the node blocks), each a few tens of µs on the built-in scene. A pool
//! that parks its idle threads on a futex (rayon's) pays a wake-up at every phase, and on a
//! virtual machine a wake-up costs about as much as the phase: `perf` on `pe bench
//! --elements 2000 --threads 2` put a third of the time in the kernel's wake and switch
//! paths, and two threads were slower than one. The team's threads wait for work by
//! spinning for [`SPIN_WAIT`] and park only when none comes in that time (between runs, or
//! while the caller writes output).
//!
//! Each call ([`Team::for_each`], [`Team::map`], [`Team::map_mut`]) runs one task per index
//! on the team's threads, the caller's included, and returns when every task has finished.
//! Which thread runs which index is not fixed (each claims the next from a counter), so a
//! caller whose result must not depend on the thread count makes every task's result
//! independent of where it ran, and combines them in index order.
//!
//! The tasks run in the caller's floating-point mode (a worker takes the caller's
//! [`Mode`] for each call): the solver's steps flush subnormals on every thread
//! ([`crate::subnormals`]).
//!
//! Panics: a task that panics does not take its thread down; the first panic's payload is
//! resumed on the caller once every thread is done with the call. A team is used from one
//! thread at a time (it is `Send`, not `Sync`).

use std::any::Any;
use std::cell::{Cell, UnsafeCell};
use std::hint::spin_loop;
use std::marker::PhantomData;
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::{JoinHandle, Thread};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Result};

use crate::subnormals::Mode;

/// How long an idle thread spins for the next task before it parks: longer than the serial
/// work between two phases of a step (contact, external forces: a few µs to tens of µs),
/// short enough that an idle team costs nothing measurable.
pub const SPIN_WAIT: Duration = Duration::from_micros(200);

/// How many times the caller spins for a worker's last task before it yields the core
/// instead (a spin-loop hint is about 50 ns here: some tens of µs).
const ACK_SPINS: u32 = 1 << 10;

/// A call's tasks, the closure's lifetime erased (see [`Team::for_each`] for why that is
/// sound).
#[derive(Clone, Copy)]
struct Job {
    task: *const (dyn Fn(usize) + Sync + 'static),
    count: usize,
    /// The caller's floating-point mode, which the workers take for the call's tasks.
    mode: Mode,
}

/// A value alone on its cache line(s), so threads polling one do not slow the others.
#[repr(align(128))]
struct Padded<T>(T);

struct Shared {
    /// Bumped by the caller for each call, after writing `job` and resetting `next`.
    generation: AtomicU64,
    /// Written by the caller only while no worker reads it (every worker has acknowledged
    /// the previous generation).
    job: UnsafeCell<Job>,
    /// The next task index to claim.
    next: Padded<AtomicUsize>,
    /// Per worker: the last generation it finished.
    done: Vec<Padded<AtomicU64>>,
    /// Per worker: parked, or about to park (the caller then unparks it).
    parked: Vec<AtomicBool>,
    stop: AtomicBool,
    panic: Mutex<Option<Box<dyn Any + Send>>>,
}

// SAFETY: `job` is written by the team's caller only between calls, when every worker has
// acknowledged the last generation and none reads it (see `Team::for_each`); every other
// field is atomic or locked.
unsafe impl Sync for Shared {}
// SAFETY: the raw task pointer in `job` points at a `Sync` closure, dereferenced only while
// the call that published it is running.
unsafe impl Send for Shared {}

impl Shared {
    /// Claims and runs tasks of `job` until none is left.
    fn work(&self, job: Job) {
        job.mode.set();
        loop {
            let i = self.next.0.fetch_add(1, Ordering::Relaxed);
            if i >= job.count {
                return;
            }
            // SAFETY: the caller of the call that published `job` keeps the closure alive
            // until every worker has acknowledged this generation (after this loop).
            let task = unsafe { &*job.task };
            if let Err(p) = catch_unwind(AssertUnwindSafe(|| task(i))) {
                if let Ok(mut slot) = self.panic.lock() {
                    slot.get_or_insert(p);
                }
            }
        }
    }

    /// Waits (spinning, then parked) for a generation other than `seen`.
    fn wait(&self, worker: usize, seen: u64) -> u64 {
        let start = Instant::now();
        let mut spins = 0u32;
        loop {
            let g = self.generation.load(Ordering::Acquire);
            if g != seen {
                return g;
            }
            spins = spins.wrapping_add(1);
            if !spins.is_multiple_of(64) || start.elapsed() < SPIN_WAIT {
                spin_loop();
                continue;
            }
            // Announce the park, then look once more: the caller stores the generation
            // before it reads `parked` (both sequentially consistent), so either this load
            // sees the new generation or the caller sees the flag and unparks.
            self.parked[worker].store(true, Ordering::SeqCst);
            if self.generation.load(Ordering::SeqCst) == seen {
                std::thread::park();
            }
            self.parked[worker].store(false, Ordering::SeqCst);
        }
    }

    fn worker(&self, worker: usize) {
        let mut seen = 0;
        loop {
            seen = self.wait(worker, seen);
            if self.stop.load(Ordering::Acquire) {
                return;
            }
            // SAFETY: published before `generation` (release/acquire), and not written
            // again until this worker acknowledges `seen`.
            let job = unsafe { *self.job.get() };
            self.work(job);
            self.done[worker].0.store(seen, Ordering::Release);
        }
    }
}

/// `threads` threads (the caller plus `threads − 1` workers) that run a call's tasks.
pub struct Team {
    shared: Arc<Shared>,
    handles: Vec<JoinHandle<()>>,
    threads: Vec<Thread>,
    /// Not `Sync`: one caller at a time publishes jobs.
    _one_caller: PhantomData<Cell<()>>,
}

impl Team {
    /// A team of `threads` threads (at least 1; 1 runs every task on the caller).
    pub fn new(threads: usize) -> Result<Team> {
        let workers = threads.max(1) - 1;
        let noop: &(dyn Fn(usize) + Sync + 'static) = &|_| {};
        let shared = Arc::new(Shared {
            generation: AtomicU64::new(0),
            job: UnsafeCell::new(Job {
                task: noop,
                count: 0,
                mode: Mode::current(),
            }),
            next: Padded(AtomicUsize::new(0)),
            done: (0..workers).map(|_| Padded(AtomicU64::new(0))).collect(),
            parked: (0..workers).map(|_| AtomicBool::new(false)).collect(),
            stop: AtomicBool::new(false),
            panic: Mutex::new(None),
        });
        let mut team = Team {
            shared,
            handles: Vec::with_capacity(workers),
            threads: Vec::with_capacity(workers),
            _one_caller: PhantomData,
        };
        for w in 0..workers {
            let s = Arc::clone(&team.shared);
            let h = std::thread::Builder::new()
                .name(format!("pe-solver-{}", w + 1))
                .spawn(move || s.worker(w))
                .map_err(|e| anyhow!("starting solver thread {} of {threads}: {e}", w + 2))?;
            team.threads.push(h.thread().clone());
            team.handles.push(h);
        }
        Ok(team)
    }

    /// The threads the team runs on, the caller's included.
    pub fn threads(&self) -> usize {
        self.handles.len() + 1
    }

    /// Runs `task(i)` for every `i` in `0..count` on the team's threads, and returns when
    /// all have finished.
    pub fn for_each(&self, count: usize, task: impl Fn(usize) + Sync) {
        if self.handles.is_empty() || count <= 1 {
            (0..count).for_each(task);
            return;
        }
        self.run(count, &task);
    }

    fn run(&self, count: usize, task: &(dyn Fn(usize) + Sync)) {
        let s = &*self.shared;
        // SAFETY (lifetime erased): the pointer is only dereferenced by `Shared::work` for
        // this generation, and this function does not return (nor unwind) before every
        // worker has acknowledged it.
        let task: *const (dyn Fn(usize) + Sync + 'static) = unsafe {
            std::mem::transmute::<
                *const (dyn Fn(usize) + Sync + '_),
                *const (dyn Fn(usize) + Sync + 'static),
            >(task)
        };
        let job = Job {
            task,
            count,
            mode: Mode::current(),
        };
        let g = s.generation.load(Ordering::Relaxed).wrapping_add(1);
        // SAFETY: every worker acknowledged the last generation (below), so none reads it.
        unsafe { *s.job.get() = job };
        s.next.0.store(0, Ordering::Relaxed);
        s.generation.store(g, Ordering::SeqCst);
        for (w, t) in self.threads.iter().enumerate() {
            if s.parked[w].load(Ordering::SeqCst) {
                t.unpark();
            }
        }
        s.work(job);
        for d in &s.done {
            let mut spins = 0u32;
            while d.0.load(Ordering::Acquire) != g {
                spins = spins.saturating_add(1);
                if spins < ACK_SPINS {
                    spin_loop();
                } else {
                    // The worker is likely descheduled (more threads than cores, as under
                    // `cargo test`): give it the core rather than spin through its slice.
                    std::thread::yield_now();
                }
            }
        }
        let panic = s.panic.lock().ok().and_then(|mut p| p.take());
        if let Some(p) = panic {
            resume_unwind(p);
        }
    }

    /// `f(i)` for `i` in `0..count`, in index order.
    pub fn map<R: Send>(&self, count: usize, f: impl Fn(usize) -> R + Sync) -> Vec<R> {
        let mut out: Vec<Option<R>> = (0..count).map(|_| None).collect();
        self.for_each_mut(&mut out, |i, slot| *slot = Some(f(i)));
        // Every slot is filled: a task that panicked was resumed above.
        out.into_iter().flatten().collect()
    }

    /// `f(i, &mut items[i])` for every item, in index order.
    pub fn map_mut<X: Send, R: Send>(
        &self,
        items: &mut [X],
        f: impl Fn(usize, &mut X) -> R + Sync,
    ) -> Vec<R> {
        let mut pairs: Vec<(&mut X, Option<R>)> = items.iter_mut().map(|x| (x, None)).collect();
        self.for_each_mut(&mut pairs, |i, (x, r)| *r = Some(f(i, x)));
        pairs.into_iter().filter_map(|(_, r)| r).collect()
    }

    /// `f(i, &mut items[i])` for every item.
    pub fn for_each_mut<X: Send>(&self, items: &mut [X], f: impl Fn(usize, &mut X) + Sync) {
        let n = items.len();
        let base = Items(items.as_mut_ptr());
        self.for_each(n, |i| {
            if i < n {
                // SAFETY: in bounds, and each index is run exactly once, so no two tasks
                // hold the same item; `items` is borrowed mutably for the whole call.
                f(i, unsafe { base.at(i) })
            }
        });
    }
}

/// The items of [`Team::for_each_mut`], shared by its tasks.
struct Items<X>(*mut X);

// SAFETY: the tasks take disjoint items (one index each), so this only sends `&mut X`s.
unsafe impl<X: Send> Sync for Items<X> {}

impl<X> Items<X> {
    /// # Safety
    /// `i` in bounds, and no other reference to item `i` alive.
    #[allow(clippy::mut_from_ref)]
    unsafe fn at(&self, i: usize) -> &mut X {
        // SAFETY: the caller's.
        unsafe { &mut *self.0.add(i) }
    }
}

impl Drop for Team {
    fn drop(&mut self) {
        let s = &*self.shared;
        s.stop.store(true, Ordering::SeqCst);
        s.generation.fetch_add(1, Ordering::SeqCst);
        for t in &self.threads {
            t.unpark();
        }
        for h in self.handles.drain(..) {
            // A worker catches its tasks' panics, so joining fails only if the thread
            // could not be run at all; there is nothing to recover then.
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tasks run in the caller's floating-point mode, whichever thread runs them: with
    /// subnormals flushed and kept in turn, every task (64 of them, on 2 and 3 threads)
    /// reports the caller's mode, and its product `1e-30 · 1e-10` (subnormal in IEEE) is
    /// zero exactly when flushed.
    #[test]
    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
    fn tasks_run_in_the_callers_floating_point_mode() {
        use crate::subnormals::{FlushGuard, Subnormals};
        use std::hint::black_box;
        for threads in [2, 3] {
            let team = Team::new(threads).expect("threads");
            for s in [Subnormals::Flush, Subnormals::Keep, Subnormals::Flush] {
                let _g = FlushGuard::enter(s);
                let seen = team.map(64, |_| {
                    let p = black_box(1e-30f32) * black_box(1e-10f32);
                    (Mode::current().flushes(), p.to_bits() == 0)
                });
                assert_eq!(seen.len(), 64);
                let flush = s == Subnormals::Flush;
                assert!(seen.iter().all(|&v| v == (flush, flush)), "{s:?}: {seen:?}");
            }
        }
    }

    /// Every index runs exactly once, results come back in index order, on 1-4 threads
    /// and for counts below, at and above the thread count.
    #[test]
    fn every_index_runs_once_in_order() {
        for threads in 1..=4 {
            let team = Team::new(threads).expect("threads");
            assert_eq!(team.threads(), threads);
            for count in [0usize, 1, 2, 3, 7, 64, 1000] {
                let runs: Vec<AtomicUsize> = (0..count).map(|_| AtomicUsize::new(0)).collect();
                let out = team.map(count, |i| {
                    runs[i].fetch_add(1, Ordering::Relaxed);
                    3 * i + 1
                });
                assert_eq!(out.len(), count);
                assert!(out.iter().enumerate().all(|(i, &v)| v == 3 * i + 1));
                assert!(runs.iter().all(|r| r.load(Ordering::Relaxed) == 1));
            }
        }
    }

    /// Items are handed out mutably, each once; many calls in a row (the workers wait by
    /// spinning between them) and after a pause long enough for them to park.
    #[test]
    fn items_are_updated_across_calls_and_parking() {
        let team = Team::new(3).expect("threads");
        let mut v: Vec<u64> = (0..100).collect();
        for round in 0..500u64 {
            if round % 100 == 50 {
                std::thread::sleep(SPIN_WAIT * 5);
            }
            let sums = team.map_mut(&mut v, |i, x| {
                *x += i as u64;
                *x
            });
            assert_eq!(sums.len(), 100);
        }
        assert!(v.iter().enumerate().all(|(i, &x)| x == i as u64 * 501));
    }

    /// A panicking task reaches the caller, and the team still works after it.
    #[test]
    fn a_panic_reaches_the_caller() {
        let team = Team::new(2).expect("threads");
        let r = catch_unwind(AssertUnwindSafe(|| {
            team.for_each(10, |i| {
                if i == 7 {
                    panic!("task 7");
                }
            })
        }));
        let p = r.expect_err("the panic is resumed");
        assert_eq!(p.downcast_ref::<&str>(), Some(&"task 7"));
        assert_eq!(team.map(5, |i| i * i), vec![0, 1, 4, 9, 16]);
    }
}
