//! Keeping the thread pool's workers awake through a run.
//!
//! A step runs three to five short parallel loops (drift, bonds, contacts and, at builds, the
//! neighbour search) with short serial parts between them. Between two loops rayon's idle
//! worker yields a few dozen times and then sleeps, and waking it again costs tens of
//! microseconds on virtual machines: about once per loop, a large part of a small scene's
//! step (measured: `reports/benchmark-0.6.0`).
//!
//! [`with_awake_workers`] runs a closure (a run's step loop) while every other worker of the
//! current pool runs a spinner: a task that keeps asking rayon for work
//! ([`rayon::yield_now`]) and, when there is none, yields its core to the operating system
//! instead of sleeping on rayon's condition variable. A spinner holds its core while the run
//! lasts, as an OpenMP program does under `OMP_WAIT_POLICY=active`; `sched_yield` hands the
//! core over whenever another thread wants it.
//!
//! [`for_each_chunk`] runs the step's kernels over their chunks of particles, and the
//! neighbour build over its chunks of cells and its one range of particles per thread: the
//! stepping thread takes chunks from the front, the others from the back, and it waits for
//! their last chunks by spinning. Each chunk writes its own partial results, which the caller combines
//! in chunk order, so results are the same whichever thread took a chunk, at any thread
//! count.
//!
//! A spinner never runs on a thread that is inside a [`with_awake_workers`] closure or another
//! spinner (it returns at once there): a closure waiting on its own loop must not be buried
//! under a task that waits for the closure to end.
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

thread_local! {
    /// Whether this thread is inside a [`with_awake_workers`] closure or a spinner.
    static BUSY: Cell<bool> = const { Cell::new(false) };
}

/// How long the closure waits for the spinners to start on other threads before it goes on
/// without those that have not (a worker busy with other work, say).
const START_WAIT: Duration = Duration::from_millis(50);

/// Runs `body` as `hvi-study` runs a scene: inside a new rayon pool (`RAYON_NUM_THREADS`
/// threads, or one per core), on one of its workers, with the others spinning between the
/// kernels' loops ([`with_awake_workers`]). A step loop run from outside a pool instead wakes
/// the pool at every parallel loop, which costs a tenth of a small scene's time on one
/// thread. For the engine's examples and tools.
pub fn in_pool<R: Send>(body: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .build()
        .expect("a thread pool")
        .install(|| with_awake_workers(body))
}

/// Runs `body` on this thread while the other workers of the current rayon pool spin instead
/// of sleeping between parallel loops (see the module's doc). With one thread, or when called
/// inside another such closure, it runs `body` alone.
pub fn with_awake_workers<R>(body: impl FnOnce() -> R) -> R {
    let spinners = rayon::current_num_threads().saturating_sub(1);
    if spinners == 0 || BUSY.with(Cell::get) {
        return body();
    }
    let stop = AtomicBool::new(false);
    let started = AtomicUsize::new(0);
    let _busy = Flag::set();
    rayon::in_place_scope(|s| {
        // Stops the spinners however the body ends, a panic included: the scope waits for
        // them before it returns or unwinds.
        let _stop = StopOnDrop(&stop);
        for _ in 0..spinners {
            s.spawn(|_| spin(&stop, &started));
        }
        // The spinners are on this thread's queue: wait (without taking work, which could be
        // a spinner) until other workers have taken them.
        let t0 = Instant::now();
        while started.load(Ordering::Acquire) < spinners && t0.elapsed() < START_WAIT {
            std::thread::yield_now();
        }
        body()
    })
}

/// Calls `f(k, item)` for each of `items` (numbered from 0) on the current pool's threads,
/// each item on one thread: the caller takes items from the front, the other threads from the
/// back, as they come free (one lock of a queue per item). For the step's kernels and the
/// neighbour build, whose items each write their own results: unlike a rayon parallel
/// iterator, the calling thread waits for the other threads' last items by spinning, not on
/// rayon's latch, where it would go to sleep after a few dozen yields and wake tens of
/// microseconds late (see the module's doc).
pub fn for_each_chunk<I, F>(items: I, f: F)
where
    I: ExactSizeIterator + DoubleEndedIterator + Send,
    I::Item: Send,
    F: Fn(usize, I::Item) + Sync,
{
    let n = items.len();
    let helpers = rayon::current_num_threads().min(n).saturating_sub(1);
    if helpers == 0 {
        items.enumerate().for_each(|(k, item)| f(k, item));
        return;
    }
    let queue = Mutex::new(items.enumerate());
    let done = AtomicUsize::new(0);
    // The caller takes items from the front, the others from the back: each thread works on
    // a contiguous run of the items, the same from one call to the next.
    let work = |front: bool| loop {
        // A poisoned queue only means another thread panicked in `f`: the scope re-raises it.
        let mut q = queue.lock().unwrap_or_else(|e| e.into_inner());
        let next = if front { q.next() } else { q.next_back() };
        drop(q);
        let Some((k, item)) = next else { return };
        // Counted done even when `f` panics, so that the caller's wait ends.
        let _count = CountOnDrop(&done);
        f(k, item);
    };
    rayon::in_place_scope(|s| {
        for _ in 0..helpers {
            s.spawn(|_| work(false));
        }
        work(true);
        while done.load(Ordering::Acquire) < n {
            std::hint::spin_loop();
        }
    });
}

/// A spinner: runs whatever work the pool has until `stop`, yielding the core when idle.
fn spin(stop: &AtomicBool, started: &AtomicUsize) {
    started.fetch_add(1, Ordering::Release);
    if BUSY.with(Cell::get) {
        return;
    }
    let _busy = Flag::set();
    while !stop.load(Ordering::Acquire) {
        match rayon::yield_now() {
            Some(rayon::Yield::Executed) => {}
            Some(rayon::Yield::Idle) => std::thread::yield_now(),
            None => return,
        }
    }
}

/// Marks this thread busy until dropped.
struct Flag;

impl Flag {
    fn set() -> Self {
        BUSY.with(|b| b.set(true));
        Flag
    }
}

impl Drop for Flag {
    fn drop(&mut self) {
        BUSY.with(|b| b.set(false));
    }
}

struct CountOnDrop<'a>(&'a AtomicUsize);

impl Drop for CountOnDrop<'_> {
    fn drop(&mut self) {
        self.0.fetch_add(1, Ordering::Release);
    }
}

struct StopOnDrop<'a>(&'a AtomicBool);

impl Drop for StopOnDrop<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    fn pool(n: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .expect("pool")
    }

    #[test]
    fn parallel_loops_inside_run_and_the_spinners_stop() {
        for n in [1, 2, 3] {
            let sum = pool(n).install(|| {
                with_awake_workers(|| {
                    (0..200)
                        .map(|k| (0..1000u64).into_par_iter().map(|i| i * k).sum::<u64>())
                        .sum::<u64>()
                })
            });
            assert_eq!(sum, 499_500 * 19_900, "{n} threads");
        }
    }

    #[test]
    fn nested_calls_and_a_panicking_body_end() {
        let p = pool(2);
        let r = p.install(|| with_awake_workers(|| with_awake_workers(|| 7)));
        assert_eq!(r, 7);
        let caught =
            p.install(|| std::panic::catch_unwind(|| with_awake_workers(|| panic!("body fails"))));
        assert!(caught.is_err());
        // The pool still works: no spinner was left behind.
        assert_eq!(p.install(|| (0..100u32).into_par_iter().sum::<u32>()), 4950);
    }
}
