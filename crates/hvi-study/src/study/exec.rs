//! Executes a set of jobs through the store: cached runs are skipped, the rest run in
//! parallel, each failure is recorded and the others go on.
//!
//! Threads: with T worker threads and P runs to do, min(T, P) runs go at once, each on its own
//! pool of max(1, T / min(T, P)) threads (so a single run, e.g. one refinement step of
//! `calibrate`, uses every core, and a grid spreads runs across cores). Results do not depend
//! on the thread counts (the engine is bit-identical at any count).

use std::io::IsTerminal;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use super::store::{Job, Record, RunStatus, Store};

/// How to execute.
#[derive(Debug, Clone, Copy)]
pub struct ExecOptions {
    /// Worker threads in all (0: every core).
    pub threads: usize,
    /// Runs at once (None: as many as threads, at most the runs to do).
    pub jobs: Option<usize>,
    /// Progress bar and one line per finished run on stderr.
    pub progress: bool,
}

impl Default for ExecOptions {
    fn default() -> Self {
        ExecOptions {
            threads: 0,
            jobs: None,
            progress: true,
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
    /// Runs found finished in the store.
    pub cached: usize,
    /// Runs that failed (now or before, when not re-run).
    pub failed: usize,
    /// Wall time, s.
    pub wall_seconds: f64,
}

impl ExecReport {
    /// One line: `runs: 12 total, 4 cached, 8 ran, 1 failed, 93.2 s`.
    pub fn line(&self) -> String {
        format!(
            "runs: {} total, {} cached, {} ran, {} failed, {:.1} s",
            self.records.len(),
            self.cached,
            self.ran,
            self.failed,
            self.wall_seconds
        )
    }
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
    let mut records: Vec<Option<Record>> = Vec::with_capacity(jobs.len());
    let mut pending: Vec<usize> = Vec::new();
    for (i, job) in jobs.iter().enumerate() {
        match store.lookup(&job.fingerprint)? {
            Some(r) if r.status == RunStatus::Completed => records.push(Some(r)),
            _ => {
                records.push(None);
                // The same fingerprint twice in one execution (e.g. a refinement point that
                // repeats) runs once.
                if !pending
                    .iter()
                    .any(|&p| jobs[p].fingerprint == job.fingerprint)
                {
                    pending.push(i);
                }
            }
        }
    }
    let cached = records.iter().filter(|r| r.is_some()).count();
    let (at_once, per_run) = thread_split(opts.threads, opts.jobs, pending.len());

    let bar = if opts.progress && !pending.is_empty() {
        let target = if std::io::stderr().is_terminal() {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        };
        let b = ProgressBar::with_draw_target(Some(pending.len() as u64), target);
        b.set_style(
            ProgressStyle::with_template(
                "{bar:30} {pos}/{len} runs  {msg}  elapsed {elapsed}  ETA {eta}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        b.set_message(format!("cached {cached}, failed 0"));
        b.enable_steady_tick(Duration::from_millis(500));
        Some(b)
    } else {
        None
    };
    let say = |line: String| {
        if opts.progress {
            match &bar {
                Some(b) if !b.is_hidden() => b.println(line),
                _ => eprintln!("{line}"),
            }
        }
    };
    if opts.progress {
        say(format!(
            "{} runs: {} cached, {} to run ({} at once, {} threads each)",
            jobs.len(),
            cached,
            pending.len(),
            if pending.is_empty() { 0 } else { at_once },
            per_run
        ));
    }

    let done = AtomicUsize::new(0);
    let next = AtomicUsize::new(0);
    let failed_now = AtomicUsize::new(0);
    let run_one = |i: usize| -> Result<Record> {
        let r = store.execute(&jobs[i], per_run);
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        let line = match &r {
            Ok(rec) if rec.status == RunStatus::Completed => {
                let o = &rec.observables;
                let f = |x: Option<f64>| x.map_or("n/a".into(), |v| format!("{v:.3}"));
                format!(
                    "[{n}/{}] run {} ({}): completed in {:.1} s; F = {}, R = {}, va/v0 = {}",
                    pending.len(),
                    i,
                    describe(i),
                    rec.wall_seconds,
                    f(o.fragmentation),
                    f(o.length_ratio),
                    f(o.front_velocity_ratio)
                )
            }
            Ok(rec) => {
                failed_now.fetch_add(1, Ordering::Relaxed);
                format!(
                    "[{n}/{}] run {} ({}): FAILED after {:.1} s: {}",
                    pending.len(),
                    i,
                    describe(i),
                    rec.wall_seconds,
                    rec.error.as_deref().unwrap_or("")
                )
            }
            Err(e) => {
                failed_now.fetch_add(1, Ordering::Relaxed);
                format!("[{n}/{}] run {i}: store error: {e:#}", pending.len())
            }
        };
        say(line);
        if let Some(b) = &bar {
            b.inc(1);
            b.set_message(format!(
                "cached {cached}, failed {}",
                failed_now.load(Ordering::Relaxed)
            ));
        }
        r
    };
    // One plain OS thread per concurrent run, each taking the next pending run in plan order;
    // the run itself goes to its own rayon pool. (Outer rayon workers would, while waiting
    // for a run's pool, steal further runs onto their stacks and start every run at once.)
    let results: Vec<(usize, Result<Record>)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..at_once)
            .map(|_| {
                scope.spawn(|| {
                    let mut out = Vec::new();
                    loop {
                        let k = next.fetch_add(1, Ordering::Relaxed);
                        let Some(&i) = pending.get(k) else { break };
                        out.push((i, run_one(i)));
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
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let ran = results.len();
    let mut first_error = None;
    for (i, r) in results {
        match r {
            Ok(rec) => records[i] = Some(rec),
            Err(e) => {
                first_error.get_or_insert(e.context(format!("run {i}")));
            }
        }
    }
    if let Some(e) = first_error {
        return Err(e);
    }
    // Duplicates of a pending fingerprint take the record of the one that ran.
    for i in 0..jobs.len() {
        if records[i].is_none() {
            records[i] = store.lookup(&jobs[i].fingerprint)?;
        }
    }
    let records: Vec<Record> = records
        .into_iter()
        .enumerate()
        .map(|(i, r)| r.with_context(|| format!("run {i} has no record after execution")))
        .collect::<Result<_>>()?;
    let failed = records
        .iter()
        .filter(|r| r.status == RunStatus::Failed)
        .count();
    Ok(ExecReport {
        records,
        ran,
        cached,
        failed,
        wall_seconds: t0.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threads_go_to_runs_first_then_inside_runs() {
        assert_eq!(thread_split(2, None, 12), (2, 1));
        assert_eq!(thread_split(2, None, 1), (1, 2));
        assert_eq!(thread_split(8, None, 3), (3, 2));
        assert_eq!(thread_split(8, Some(1), 3), (1, 8));
        assert_eq!(thread_split(4, None, 0), (1, 4));
    }
}
