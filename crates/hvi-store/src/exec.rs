//! Executes a set of jobs through the store: cached runs are skipped, the rest run in
//! parallel, each failure is recorded and the others go on.
//!
//! Threads: with T worker threads and P runs to do, min(T, P) runs go at once, each on its own
//! pool of max(1, T / min(T, P)) threads (so a single run, e.g. one refinement step of
//! `calibrate`, uses every core, and a grid spreads runs across cores). Results do not depend
//! on the thread counts (the engine is bit-identical at any count).
//!
//! Order ([`schedule`]): a run's pool cannot grow once it started, so a run that costs more
//! than the others' share would finish last on one pool while the other cores idle. The runs
//! to do are therefore ordered by cost (particles x base steps, [`run_cost`]), largest first;
//! and while the largest costs more than [`ALONE_ABOVE_SHARE`] times its share of what is left
//! (1/(runs at once)), it runs alone on every thread before the rest (unless `--jobs` fixes the
//! runs at once). Fig. 5's
//! convergence stage, say, is one 7.5e5-particle run and four smaller ones that together cost
//! less than half of it.

use hvi_analysis::observable::Observable;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use hvi_run::progress::{Bar, Unit};
use rayon::prelude::*;

use crate::store::{Job, Record, RunStatus, Store};
use hvi_run::error::{Result, RunError};

/// How to execute.
#[derive(Debug, Clone, Copy)]
pub struct ExecOptions {
    /// Worker threads in all (0: every core).
    pub threads: usize,
    /// Runs at once (None: as many as threads, at most the runs to do).
    pub jobs: Option<usize>,
    /// Progress bar and one line per finished run on stderr.
    pub progress: bool,
    /// How often each run writes a checkpoint.
    pub checkpoint_every: hvi_run::checkpoint::Every,
}

impl Default for ExecOptions {
    fn default() -> Self {
        ExecOptions {
            threads: 0,
            jobs: None,
            progress: true,
            checkpoint_every: hvi_run::checkpoint::Every::default(),
        }
    }
}

/// What an execution did.
#[derive(Debug, Clone)]
pub struct ExecReport {
    /// One record per job, in job order.
    pub records: Vec<Record>,
    /// Runs simulated now.
    pub ran: usize,
    /// Runs measured now from another run's kept state instead of simulated
    /// ([`crate::remeasured`]).
    pub measured: usize,
    /// Runs found finished in the store.
    pub cached: usize,
    /// Runs another process finished while this one waited for them (not run here).
    pub elsewhere: usize,
    /// Runs that failed (now or before, when not re-run).
    pub failed: usize,
    /// Wall time, s.
    pub wall_seconds: f64,
}

impl ExecReport {
    /// One line: `runs: 12 total, 4 cached, 8 ran, 1 failed, 93.2 s` (with `, 2 measured from
    /// kept states` after the runs simulated when some were measured, and `, 3 done by another
    /// process` before the time when another process finished some meanwhile).
    pub fn line(&self) -> String {
        let elsewhere = if self.elsewhere > 0 {
            format!(", {} done by another process", self.elsewhere)
        } else {
            String::new()
        };
        let measured = if self.measured > 0 {
            format!(", {} measured from kept states", self.measured)
        } else {
            String::new()
        };
        format!(
            "runs: {} total, {} cached, {} ran{measured}, {} failed{elsewhere}, {:.1} s",
            self.records.len(),
            self.cached,
            self.ran,
            self.failed,
            self.wall_seconds
        )
    }
}

/// What a run costs, in particles x base steps (the scene built by the engine, so the base
/// step is the one it would run with), and its particle count.
pub fn run_cost(scene: &hvi_engine::scene::SceneSpec) -> Result<(usize, f64)> {
    let setup = scene.build()?;
    let n = setup.particles.len();
    Ok((n, n as f64 * setup.derived.steps as f64))
}

/// One phase of an execution: runs (indices into the costs), taken in this order by `at_once`
/// workers of `per_run` threads each.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Phase {
    /// Runs, in the order they start.
    pub runs: Vec<usize>,
    /// Runs at once.
    pub at_once: usize,
    /// Threads per run.
    pub per_run: usize,
}

/// A run goes alone on every thread when it costs more than this times its share of what is
/// left (1/(runs at once)). Above 1, because a run on T threads goes at less than T times its
/// speed on one: going alone pays only for a run clearly larger than its share.
pub const ALONE_ABOVE_SHARE: f64 = 1.2;

/// The order and thread split of runs costing `costs`: first, alone on every thread, each
/// run that costs more than [`ALONE_ABOVE_SHARE`] times its share of what is left (only when
/// `jobs` is not fixed); then the rest, largest first (ties in the given order), split by
/// [`thread_split`].
pub fn schedule(threads: usize, jobs: Option<usize>, costs: &[f64]) -> Vec<Phase> {
    let mut order: Vec<usize> = (0..costs.len()).collect();
    order.sort_by(|&a, &b| costs[b].total_cmp(&costs[a]).then(a.cmp(&b)));
    let mut phases = Vec::new();
    let mut rest: &[usize] = &order;
    if jobs.is_none() {
        let (_, all) = thread_split(threads, Some(1), 1);
        while let Some((&first, tail)) = rest.split_first() {
            let (at_once, _) = thread_split(threads, None, rest.len());
            let left: f64 = rest.iter().map(|&i| costs[i]).sum();
            if at_once < 2 || costs[first] <= ALONE_ABOVE_SHARE * left / at_once as f64 {
                break;
            }
            phases.push(Phase {
                runs: vec![first],
                at_once: 1,
                per_run: all,
            });
            rest = tail;
        }
    }
    if !rest.is_empty() {
        let (at_once, per_run) = thread_split(threads, jobs, rest.len());
        phases.push(Phase {
            runs: rest.to_vec(),
            at_once,
            per_run,
        });
    }
    phases
}

/// The thread split: (runs at once, threads per run).
pub fn thread_split(threads: usize, jobs: Option<usize>, pending: usize) -> (usize, usize) {
    let threads = if threads == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        threads
    };
    let at_once = jobs.unwrap_or(threads).min(pending).max(1);
    (at_once, (threads / at_once).max(1))
}

/// Executes `jobs` (label each with `describe` for the progress lines). Completed runs in the
/// store are reused; failed and missing ones run. A failed simulation does not stop the others.
pub fn execute(
    store: &Store,
    jobs: &[Job],
    describe: &(dyn Fn(usize) -> String + Sync),
    opts: &ExecOptions,
) -> Result<ExecReport> {
    let t0 = Instant::now();
    let elsewhere_before = store.done_elsewhere();
    let (records, pending) = look_up(store, jobs)?;
    let cached = records.iter().filter(|r| r.is_some()).count();
    // Runs measured from a kept state cost about a second, not a simulation.
    let to_measure: Vec<usize> = pending
        .iter()
        .copied()
        .filter(|&i| store.source_for(&jobs[i]).is_some())
        .collect();
    let (phases, costs) = order_runs(jobs, &pending, &to_measure, opts);
    let total_cost: f64 = costs.values().sum();
    let bar = progress_bar(opts, pending.len(), cached);
    let say = |line: String| {
        if opts.progress {
            match &bar {
                Some(b) => b.line(line),
                None => log::info!("{line}"),
            }
        }
    };
    if opts.progress {
        say(opening_line(
            jobs.len(),
            cached,
            (pending.len(), to_measure.len()),
            &phases,
        ));
    }
    let tally = Tally {
        store,
        jobs,
        t0,
        pending: pending.len(),
        cached,
        costs: &costs,
        total_cost,
        done: AtomicUsize::new(0),
        failed_now: AtomicUsize::new(0),
        store_failed: AtomicBool::new(false),
        done_cost: std::sync::Mutex::new((0.0, 0.0)),
    };
    let run_one = |i: usize, per_run: usize| tally.run(i, per_run, describe, &say, bar.as_deref());
    let results = run_phases(&phases, &run_one);
    if let Some(b) = &bar {
        b.finish();
    }
    let elsewhere = store.done_elsewhere() - elsewhere_before;
    let measured = results
        .iter()
        .filter(|(_, r)| matches!(r, Some(Ok(rec)) if rec.measured_from.is_some()))
        .count();
    let ran = results.len() - elsewhere - measured;
    let records = gather_records(store, jobs, records, results)?;
    let failed = records
        .iter()
        .filter(|r| r.status == RunStatus::Failed)
        .count();
    Ok(ExecReport {
        records,
        ran,
        measured,
        cached,
        elsewhere,
        failed,
        wall_seconds: t0.elapsed().as_secs_f64(),
    })
}

/// The runs of one [`execute`] as they finish: their count, the failures, the work done (for
/// the time left) and each one's line.
struct Tally<'a> {
    store: &'a Store,
    jobs: &'a [Job],
    t0: Instant,
    /// Runs to do in all.
    pending: usize,
    /// Runs found in the store.
    cached: usize,
    /// Each pending run's estimated cost.
    costs: &'a std::collections::HashMap<usize, f64>,
    total_cost: f64,
    done: AtomicUsize,
    failed_now: AtomicUsize,
    /// After a store error (a full disk, an unwritable directory) no further run starts: it
    /// would fail the same way.
    store_failed: AtomicBool,
    /// (cost run in this process, cost of the finished runs)
    done_cost: std::sync::Mutex<(f64, f64)>,
}

impl Tally<'_> {
    /// Runs job `i` on `per_run` threads and counts it. `None`: not started, because an
    /// earlier run hit a store error.
    fn run(
        &self,
        i: usize,
        per_run: usize,
        describe: &(dyn Fn(usize) -> String + Sync),
        say: &(dyn Fn(String) + Sync),
        bar: Option<&dyn Bar>,
    ) -> Option<Result<Record>> {
        // After Ctrl-C or SIGTERM no run starts, and a stopped run is no failure.
        if let Err(e) = hvi_run::interrupt::check() {
            return Some(Err(e));
        }
        if self.store_failed.load(Ordering::Relaxed) {
            return None;
        }
        let r = self.store.execute(&self.jobs[i], per_run);
        if r.as_ref()
            .err()
            .and_then(|e| hvi_run::interrupt::of(e))
            .is_some()
        {
            return Some(r);
        }
        if r.is_err() {
            self.store_failed.store(true, Ordering::Relaxed);
        }
        if !matches!(&r, Ok(rec) if rec.status == RunStatus::Completed) {
            self.failed_now.fetch_add(1, Ordering::Relaxed);
        }
        self.finished(i, &r, describe, say);
        if let Some(b) = bar {
            b.inc(format!(
                "cached {}, failed {}",
                self.cached,
                self.failed_now.load(Ordering::Relaxed)
            ));
        }
        Some(r)
    }

    /// Counts a finished run and says its line. One finished run at a time: its count, the
    /// work done and its line together (under one lock), so the lines come out in the order
    /// of their counts when two runs end at once.
    fn finished(
        &self,
        i: usize,
        r: &Result<Record>,
        describe: &(dyn Fn(usize) -> String + Sync),
        say: &(dyn Fn(String) + Sync),
    ) {
        let mut c = self.done_cost.lock().unwrap_or_else(|p| p.into_inner());
        let n = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        // A run resumed from a checkpoint ran only its rest in this process's time.
        let cost = self.costs.get(&i).copied().unwrap_or(0.0);
        c.0 += cost * (1.0 - self.store.resumed_share(&self.jobs[i].fingerprint));
        c.1 += cost;
        let eta = time_left(
            self.t0.elapsed().as_secs_f64(),
            (n, self.pending),
            (c.0, c.1, self.total_cost),
        );
        say(finished_line(n, self.pending, i, r, describe) + &eta);
    }
}

/// Each job's completed record from the store (None where there is none), and the jobs to
/// run: those missing or failed, each fingerprint once (a refinement point that repeats, say,
/// runs once).
fn look_up(store: &Store, jobs: &[Job]) -> Result<(Vec<Option<Record>>, Vec<usize>)> {
    let mut records: Vec<Option<Record>> = Vec::with_capacity(jobs.len());
    let mut pending: Vec<usize> = Vec::new();
    for (i, job) in jobs.iter().enumerate() {
        match store.record(&job.fingerprint)? {
            Some(r) if r.is_final() => records.push(Some(r)),
            _ => {
                records.push(None);
                if !pending
                    .iter()
                    .any(|&p| jobs[p].fingerprint == job.fingerprint)
                {
                    pending.push(i);
                }
            }
        }
    }
    Ok((records, pending))
}

/// The phases of the `pending` jobs (indices into `jobs`): largest first, the dominant ones
/// alone (see the module's doc); those `to_measure` from a kept state cost nothing. Costing
/// builds each scene once, in parallel, which is cheap against the runs; a single run needs no
/// order.
fn order_runs(
    jobs: &[Job],
    pending: &[usize],
    to_measure: &[usize],
    opts: &ExecOptions,
) -> (Vec<Phase>, std::collections::HashMap<usize, f64>) {
    let costs: Vec<f64> = if pending.len() > 1 {
        pending
            .par_iter()
            .map(|&i| {
                if to_measure.contains(&i) {
                    return 0.0;
                }
                // A scene that does not build costs nothing here; its run fails with the reason.
                run_cost(&jobs[i].scene).map_or(0.0, |c| c.1)
            })
            .collect()
    } else {
        vec![0.0; pending.len()]
    };
    let phases = schedule(opts.threads, opts.jobs, &costs)
        .into_iter()
        .map(|p| Phase {
            runs: p.runs.iter().map(|&k| pending[k]).collect(),
            ..p
        })
        .collect();
    (phases, pending.iter().copied().zip(costs).collect())
}

/// The time left after `done.0` of `done.1` runs, `elapsed` seconds in: the elapsed time
/// scaled by the cost still to run over the cost run in that time (particles x base steps; by
/// the count when the costs are unknown), e.g. `; 6 left, about 4.2 min`. `cost` is (run in
/// this process, of the finished runs, of all): a run resumed from a checkpoint counts as
/// finished in full but as run here only from its checkpoint on. Empty after the last run.
fn time_left(elapsed: f64, done: (usize, usize), cost: (f64, f64, f64)) -> String {
    let (n, total) = done;
    if n >= total || n == 0 {
        return String::new();
    }
    let (here, finished, all) = cost;
    let left = if here > 0.0 && all > finished {
        elapsed * (all - finished) / here
    } else {
        elapsed * (total - n) as f64 / n as f64
    };
    format!(
        "; {} left, about {}",
        total - n,
        hvi_analysis::number::fmt_duration(left)
    )
}

/// The progress bar over the `pending` runs (when the command draws bars), when progress is on
/// and there is something to run.
fn progress_bar(opts: &ExecOptions, pending: usize, cached: usize) -> Option<Box<dyn Bar>> {
    if !(opts.progress && pending > 0) {
        return None;
    }
    let b = hvi_run::progress::bar(pending as u64, Unit::Runs)?;
    b.set(0, format!("cached {cached}, failed 0"));
    Some(b)
}

/// The line that opens an execution: runs, cached, to run (`pending.0`, of which `pending.1`
/// are measured from kept states), and how they go over the threads, e.g. `12 runs: 4 cached,
/// 8 to run (2 at once, 1 thread each)` or `12 runs: 4 cached, 8 to run, 3 of them measured
/// from kept states (...)`.
fn opening_line(
    jobs: usize,
    cached: usize,
    (pending, measured): (usize, usize),
    phases: &[Phase],
) -> String {
    let solo: Vec<&Phase> = phases.iter().take_while(|p| p.at_once == 1).collect();
    let mut parts: Vec<String> = Vec::new();
    if phases.len() > 1 && !solo.is_empty() {
        parts.push(format!(
            "{} one at a time on {} threads",
            solo.len(),
            solo[0].per_run
        ));
    }
    let shared = if phases.len() > 1 {
        &phases[solo.len()..]
    } else {
        phases
    };
    for p in shared {
        parts.push(format!(
            "{} at once, {} thread{} each",
            p.at_once,
            p.per_run,
            if p.per_run == 1 { "" } else { "s" }
        ));
    }
    let measured = if measured > 0 {
        format!(", {measured} of them measured from kept states")
    } else {
        String::new()
    };
    format!(
        "{} runs: {} cached, {} to run{measured} ({}{})",
        jobs,
        cached,
        pending,
        if pending == 0 {
            "0 at once".to_string()
        } else {
            parts.join(", then ")
        },
        if phases.len() > 1 {
            "; largest first"
        } else {
            ""
        }
    )
}

/// The line for the `n`-th of `total` finished runs, job `i`: its observables, or why it
/// failed.
fn finished_line(
    n: usize,
    total: usize,
    i: usize,
    r: &Result<Record>,
    describe: &dyn Fn(usize) -> String,
) -> String {
    match r {
        Ok(rec) if rec.status == RunStatus::Completed => {
            let o = &rec.observables;
            let f = |x: Option<f64>| x.map_or("n/a".into(), |v| format!("{v:.3}"));
            let how = match &rec.measured_from {
                Some(fp) => format!(
                    "measured from the state of run {}",
                    &fp[..hvi_run::files::DIR_DIGITS.min(fp.len())]
                ),
                None => "completed".to_string(),
            };
            format!(
                "[{n}/{total}] run {} ({}): {how} in {:.1} s; F = {}, R = {}, va/v0 = {}",
                i,
                describe(i),
                rec.wall_seconds,
                f(o.get(Observable::Fragmentation)),
                f(o.get(Observable::LengthRatio)),
                f(o.get(Observable::FrontVelocityRatio))
            )
        }
        Ok(rec) => format!(
            "[{n}/{total}] run {} ({}): FAILED after {:.1} s: {}",
            i,
            describe(i),
            rec.wall_seconds,
            rec.error.as_deref().unwrap_or("")
        ),
        Err(e) => format!("[{n}/{total}] run {i}: store error: {e:#}"),
    }
}

/// Runs the phases in order and returns every run's result with its job index (`None`: not
/// started after an earlier run's store error). Per phase, one
/// plain OS thread per concurrent run, each taking the phase's next run; the run itself goes
/// to its own rayon pool. (Outer rayon workers would, while waiting for a run's pool, steal
/// further runs onto their stacks and start every run at once.)
fn run_phases(
    phases: &[Phase],
    run_one: &(dyn Fn(usize, usize) -> Option<Result<Record>> + Sync),
) -> Vec<(usize, Option<Result<Record>>)> {
    let mut results: Vec<(usize, Option<Result<Record>>)> = Vec::new();
    for phase in phases {
        let next = AtomicUsize::new(0);
        let done_phase: Vec<(usize, Option<Result<Record>>)> = std::thread::scope(|scope| {
            let workers: Vec<_> = (0..phase.at_once)
                .map(|_| {
                    scope.spawn(|| {
                        let mut out = Vec::new();
                        loop {
                            let k = next.fetch_add(1, Ordering::Relaxed);
                            let Some(&i) = phase.runs.get(k) else { break };
                            out.push((i, run_one(i, phase.per_run)));
                        }
                        out
                    })
                })
                .collect();
            workers
                .into_iter()
                .flat_map(|w| match w.join() {
                    Ok(v) => v,
                    Err(p) => std::panic::resume_unwind(p),
                })
                .collect()
        });
        results.extend(done_phase);
    }
    results
}

/// Every job's record: the ones just run into `records`, then the rest from the store
/// (duplicates of a pending fingerprint take the record of the one that ran). The first
/// store error of a run comes back instead.
fn gather_records(
    store: &Store,
    jobs: &[Job],
    mut records: Vec<Option<Record>>,
    results: Vec<(usize, Option<Result<Record>>)>,
) -> Result<Vec<Record>> {
    let mut first_error = None;
    for (i, r) in results {
        match r {
            Some(Ok(rec)) => records[i] = Some(rec),
            // Runs not started after another run's store error: that error is the one to say.
            None => {}
            Some(Err(e)) => {
                first_error.get_or_insert(e.context(format!("run {i}")));
            }
        }
    }
    if let Some(e) = first_error {
        return Err(e);
    }
    for i in 0..jobs.len() {
        if records[i].is_none() {
            records[i] = store.record(&jobs[i].fingerprint)?;
        }
    }
    records
        .into_iter()
        .enumerate()
        .map(|(i, r)| {
            r.ok_or_else(|| RunError::Store(format!("run {i} has no record after execution")))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_time_left_scales_the_elapsed_time_by_the_cost_still_to_run() {
        // A quarter of the cost done in 60 s: 180 s left, though half the runs are done.
        assert_eq!(
            time_left(60.0, (2, 4), (1.0, 1.0, 4.0)),
            "; 2 left, about 3.0 min"
        );
        // Costs unknown: by the count.
        assert_eq!(
            time_left(10.0, (1, 3), (0.0, 0.0, 0.0)),
            "; 2 left, about 20 s"
        );
        assert_eq!(
            time_left(3600.0, (1, 4), (1.0, 1.0, 4.0)),
            "; 3 left, about 3.0 h"
        );
        assert_eq!(time_left(10.0, (3, 3), (3.0, 3.0, 3.0)), "");
        // A run of cost 2 resumed at 3/4 of its course: 60 s bought 0.5 of cost, so the 2 of
        // cost left take 4 min, not the 1 min its full cost would promise.
        assert_eq!(
            time_left(60.0, (1, 2), (0.5, 2.0, 4.0)),
            "; 1 left, about 4.0 min"
        );
    }

    #[test]
    fn threads_go_to_runs_first_then_inside_runs() {
        assert_eq!(thread_split(2, None, 12), (2, 1));
        assert_eq!(thread_split(2, None, 1), (1, 2));
        assert_eq!(thread_split(8, None, 3), (3, 2));
        assert_eq!(thread_split(8, Some(1), 3), (1, 8));
        assert_eq!(thread_split(4, None, 0), (1, 4));
    }

    #[test]
    fn dominant_runs_go_alone_and_the_rest_largest_first() {
        // Fig. 5's stage: counts 3.4e4 .. 7.5e5, cost ~ N^(4/3): each run costs more than 0.6
        // of what is left after the larger ones, so all go one at a time, largest first.
        let costs = [1.0, 2.5, 6.4, 16.0, 62.0];
        let p = schedule(2, None, &costs);
        let order: Vec<usize> = p.iter().flat_map(|p| p.runs.clone()).collect();
        assert_eq!(order, vec![4, 3, 2, 1, 0]);
        assert!(p.iter().all(|p| p.at_once == 1 && p.per_run == 2), "{p:?}");
        // One large run among many: alone, then the others two at once, largest first.
        assert_eq!(
            schedule(2, None, &[1.0, 2.0, 30.0, 3.0, 2.0, 1.0]),
            vec![
                Phase {
                    runs: vec![2],
                    at_once: 1,
                    per_run: 2
                },
                Phase {
                    runs: vec![3, 1, 4, 0, 5],
                    at_once: 2,
                    per_run: 1
                },
            ]
        );
        // Equal costs: one phase, the given order.
        let even = [3.0; 4];
        assert_eq!(
            schedule(2, None, &even),
            vec![Phase {
                runs: vec![0, 1, 2, 3],
                at_once: 2,
                per_run: 1
            }]
        );
        // Up to 1.2 times its share it stays with the others; --jobs fixes the split; one
        // thread leaves nothing to move.
        assert_eq!(schedule(2, None, &[1.0, 1.0]).len(), 1);
        assert_eq!(schedule(2, None, &[1.4, 1.0]).len(), 1);
        assert_eq!(schedule(2, None, &[1.6, 1.0]).len(), 2);
        assert_eq!(schedule(2, Some(2), &costs).len(), 1);
        assert_eq!(schedule(2, Some(2), &costs)[0].runs, vec![4, 3, 2, 1, 0]);
        assert_eq!(schedule(1, None, &costs).len(), 1);
        // Two dominant runs on 4 threads: 40 of 52 (above 1.2 x 52/4), then 10 of 12 (above
        // 1.2 x 12/3); the last two share.
        let p = schedule(4, None, &[40.0, 10.0, 1.0, 1.0]);
        assert_eq!(p.len(), 3);
        assert_eq!((p[0].runs.clone(), p[0].per_run), (vec![0], 4));
        assert_eq!((p[1].runs.clone(), p[1].per_run), (vec![1], 4));
        assert_eq!(
            (p[2].runs.clone(), p[2].at_once, p[2].per_run),
            (vec![2, 3], 2, 2)
        );
        assert!(schedule(2, None, &[]).is_empty());
    }
}
