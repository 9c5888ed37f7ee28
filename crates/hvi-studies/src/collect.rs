//! `hvi-study status` and `hvi-study collect`: a study directory's progress and tables read
//! from its run store, running nothing. They serve a study run anywhere (locally, on a Slurm
//! cluster through [`hvi_store::slurm`], or both): the store is the one place results live.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use hvi_run::bail;
use hvi_run::error::Result;

use crate::options::StudyOptions;
use crate::sweep::print_failures;
use crate::validity::{validity_outputs, Cut, ValidityConfig};
use hvi_analysis::observable::Observables;
use hvi_store::plan::{describe_values, Plan, DIR_DIGITS};
use hvi_store::slurm::{QueueView, TaskState};
use hvi_store::spec::Study;
use hvi_store::store::{Record, RunStatus, Store};
use hvi_store::table::{results_table, Table};

/// Reads a plan and its study directory: a study directory or its `plan.json` as is, or a
/// study file planned like every other command (which writes plan.json when `write`; a
/// command that only looks, `status`, writes nothing: the directory may hold another plan,
/// a ladder level's or a running calibration's).
pub fn open_plan(args: &StudyOptions, write: bool) -> Result<(Plan, PathBuf)> {
    let p = &args.study;
    let plan_path = if p.is_dir() {
        Some(p.join("plan.json"))
    } else if p.extension().is_some_and(|e| e == "json") {
        Some(p.clone())
    } else {
        None
    };
    let Some(path) = plan_path else {
        let (_, plan, out) = if write {
            args.plan()?
        } else {
            args.build_plan()?
        };
        return Ok((plan, out));
    };
    let s = args;
    if s.tier.is_some() || s.particles.is_some() || !s.sets.is_empty() || s.out.is_some() {
        bail!(
            "{} is a study directory's plan: --tier, --particles, --set and --out apply to a \
             study file",
            p.display()
        );
    }
    if !path.exists() {
        bail!(
            "{} has no plan.json: give the study file (with its --tier/--out), or plan it first \
             (`hvi-study plan`)",
            p.display()
        );
    }
    let plan = Plan::load(&path)?;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or_else(|| Path::new("."))
        .to_path_buf();
    Ok((plan, dir))
}

/// Where a run stands.
#[derive(Debug, Clone, PartialEq)]
pub enum RunState {
    /// Completed: its result is in the store.
    Done,
    /// Failed (recorded; a new sweep or submission runs it again unless the failure is
    /// reproducible: `Record::reproducible`).
    Failed(String),
    /// Running: in Slurm (job, task), or in progress in the store (process, host).
    Running(String),
    /// Not done: queued in Slurm, or not started (with a note where a submitted task ended
    /// without a result).
    Pending {
        /// Queued in Slurm (job and task).
        queued: Option<String>,
        /// Anything worth knowing (a Slurm task that ended without a result).
        note: Option<String>,
    },
}

impl RunState {
    fn word(&self) -> &'static str {
        match self {
            RunState::Done => "done",
            RunState::Failed(_) => "failed",
            RunState::Running(_) => "running",
            RunState::Pending { .. } => "pending",
        }
    }
}

/// A study directory's state: one entry per plan run, and what the queue said.
#[derive(Debug, Clone)]
pub struct Survey {
    /// Per run: its record and state.
    pub runs: Vec<(Option<Record>, RunState)>,
    /// Slurm's view of the directory's submissions.
    pub queue: QueueView,
    /// Runs in the store beyond the plan (a calibration's search, a batch's plan): done, and
    /// in progress here now.
    pub beyond_plan: (usize, usize),
    /// The runs in progress beyond the plan, one line each: directory, process and progress.
    pub running_beyond: Vec<String>,
}

/// Surveys a study directory: records from the store, running and queued runs from Slurm (when
/// the directory has submissions and squeue answers) and from the store's in-progress
/// directories.
pub fn survey(plan: &Plan, dir: &Path) -> Result<Survey> {
    let store = Store::open(dir)?;
    let queue = QueueView::of(dir)?;
    let markers = store.in_progress()?;
    let in_plan: std::collections::HashSet<&str> = plan
        .runs
        .iter()
        .map(|r| &r.fingerprint[..DIR_DIGITS.min(r.fingerprint.len())])
        .collect();
    let done_beyond = store
        .run_dirs()?
        .iter()
        .filter(|d| {
            d.file_name()
                .is_some_and(|n| !in_plan.contains(n.to_string_lossy().as_ref()))
        })
        .count();
    let mut running_beyond: Vec<&str> = markers
        .iter()
        .filter(|m| m.alive != Some(false) && !in_plan.contains(m.digits.as_str()))
        .map(|m| m.digits.as_str())
        .collect();
    running_beyond.sort_unstable();
    running_beyond.dedup();
    let beyond_plan = (done_beyond, running_beyond.len());
    let running_beyond: Vec<String> = running_beyond
        .iter()
        .filter_map(|d| {
            markers
                .iter()
                .find(|m| m.digits == *d && m.alive != Some(false))
        })
        .map(|m| format!("runs/{} {}", m.digits, in_progress_words(m)))
        .collect();
    let mut runs = Vec::with_capacity(plan.runs.len());
    for run in &plan.runs {
        let record = store.record(&run.fingerprint)?;
        let digits = &run.fingerprint[..DIR_DIGITS.min(run.fingerprint.len())];
        let marker = markers
            .iter()
            .filter(|m| m.digits == digits && m.alive != Some(false))
            .map(in_progress_words)
            .next();
        let active = queue.active.get(&run.fingerprint);
        let state = if matches!(&record, Some(r) if r.status == RunStatus::Completed) {
            RunState::Done
        } else if let Some(t) = active.filter(|t| t.state == TaskState::Running) {
            RunState::Running(format!("Slurm job {} task {}", t.job_id, t.task))
        } else if let Some(m) = marker {
            RunState::Running(m)
        } else if let Some(t) = active {
            RunState::Pending {
                queued: Some(format!("queued in Slurm job {} task {}", t.job_id, t.task)),
                note: None,
            }
        } else if let Some(r) = &record {
            RunState::Failed(r.error.clone().unwrap_or_default())
        } else {
            RunState::Pending {
                queued: None,
                note: pending_note(&store, &queue, &run.fingerprint),
            }
        };
        runs.push((record, state));
    }
    Ok(Survey {
        runs,
        queue,
        beyond_plan,
        running_beyond,
    })
}

/// Why a run that is neither done, failed, running nor queued has not finished, if known: a
/// Slurm task that ended without a result, a checkpoint it resumes from.
fn pending_note(store: &Store, queue: &QueueView, fingerprint: &str) -> Option<String> {
    let checkpoint =
        hvi_run::checkpoint::header_of(&store.checkpoint_path(fingerprint)).map(|(_, step)| {
            format!("stopped mid-way; resumes from its checkpoint at base step {step}")
        });
    let ended = queue.ended_task(fingerprint).map(|(job, task, log)| {
        format!(
            "Slurm job {job} task {task} ended without a result: see {}",
            log.display()
        )
    });
    match (ended, checkpoint) {
        (Some(e), Some(c)) => Some(format!("{e}; {c}")),
        (e, c) => e.or(c),
    }
}

/// A run in progress in the store: where, and how far (from its progress file).
fn in_progress_words(m: &hvi_store::store::InProgress) -> String {
    let at = match (&m.host, m.alive) {
        (Some(h), None) => format!("in progress on {h}, process {} (not checkable here)", m.pid),
        _ => format!("in progress here, process {}", m.pid),
    };
    at + &hvi_run::run::Progress::read(&m.path)
        .map_or(String::new(), |p| format!(": {}", p.describe()))
}

impl Survey {
    /// (done, failed, running, pending, of which queued in Slurm).
    pub fn counts(&self) -> (usize, usize, usize, usize, usize) {
        let mut c = (0, 0, 0, 0, 0);
        for (_, s) in &self.runs {
            match s {
                RunState::Done => c.0 += 1,
                RunState::Failed(_) => c.1 += 1,
                RunState::Running(_) => c.2 += 1,
                RunState::Pending { queued, .. } => {
                    c.3 += 1;
                    c.4 += usize::from(queued.is_some());
                }
            }
        }
        c
    }
}

/// What `status` looks at: the study's store and how much it says.
#[derive(Debug, Clone)]
pub struct StatusOptions {
    /// The study (a study file with its selection, or a study directory or its plan.json).
    pub study: StudyOptions,
    /// One line per run: its state, where it runs, its directory.
    pub verbose: bool,
}

/// Which command's outputs `collect` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CollectAs {
    /// results.csv / results.json, as `sweep`.
    Sweep,
    /// The results with the objective and each target's score, as the grid stage of
    /// `calibrate` (the refinement needs new runs: `hvi-study calibrate` does it).
    Calibrate,
    /// The results with `valid`, the map, its boundary and the snapshots, as `validity-map`.
    ValidityMap,
}

/// What `collect` writes, and from which store.
#[derive(Debug, Clone)]
pub struct CollectOptions {
    /// The study (a study file with its selection, or a study directory or its plan.json).
    pub study: StudyOptions,
    /// Write what this command writes (None: `calibrate` for a study with `[calibrate]`,
    /// `validity-map` for one with `[validity]`, else `sweep`).
    pub kind: Option<CollectAs>,
    /// The validity cut-off (with `CollectAs::ValidityMap`; None: the study's, else 0.3).
    pub cutoff: Option<f64>,
}

/// `hvi-study status`: counts on the first line (`... N runs: D done, F failed, R running, P
/// pending (Q queued in Slurm)`), then the Slurm jobs, then with --verbose one line per run.
pub fn status(args: &StatusOptions) -> Result<()> {
    let (plan, dir) = open_plan(&args.study, false)?;
    let survey = survey(&plan, &dir)?;
    let (done, failed, running, pending, queued) = survey.counts();
    // Failures the engine repeats stay as they are; the others run again.
    let kept = survey
        .runs
        .iter()
        .filter(|(r, s)| {
            matches!(s, RunState::Failed(_)) && r.as_ref().is_some_and(|r| r.reproducible)
        })
        .count();
    let failed = match (kept, failed - kept) {
        (0, _) => format!("{failed} failed"),
        (_, 0) => format!("{failed} {}", hvi_store::store::FAILED_FOR_GOOD),
        (k, again) => {
            format!("{failed} failed ({k} for good, kept; {again} run again when the study does)")
        }
    };
    let mut s = format!(
        "study `{}` at tier `{}` in {}: {} runs: {done} done, {failed}, {running} running, {pending} pending",
        plan.study,
        plan.tier,
        dir.display(),
        plan.runs.len()
    );
    if queued > 0 {
        let _ = write!(s, " ({queued} queued in Slurm)");
    }
    s.push('\n');
    if pending > 0 {
        if let Some(line) = design_line(&dir) {
            let _ = writeln!(s, "{line}");
        }
    }
    let (done_beyond, running_beyond) = survey.beyond_plan;
    if done_beyond + running_beyond > 0 {
        let _ = writeln!(
            s,
            "beyond the plan (a calibration's search, or runs of another plan in this store): {done_beyond} done, {running_beyond} in progress here"
        );
        if args.verbose {
            for line in &survey.running_beyond {
                let _ = writeln!(s, "  {line}");
            }
        }
    }
    slurm_lines(&mut s, &survey.queue);
    if args.verbose {
        run_lines(&mut s, &plan, &survey);
    }
    log::info!(target: hvi_run::STDOUT, "{}", s.trim_end_matches('\n'));
    Ok(())
}

/// Why grid runs are pending after a calibration whose grid stage ran a sparser design
/// (`calibrate.initial_design`, read from the directory's calibration.json): they were left
/// out on purpose. None without such a calibration.
fn design_line(dir: &Path) -> Option<String> {
    let text = std::fs::read_to_string(dir.join("calibration.json")).ok()?;
    let c: serde_json::Value = serde_json::from_str(&text).ok()?;
    let d = &c["initial_design"];
    let (points, of) = (d["points"].as_u64()?, d["grid_points"].as_u64()?);
    (points < of).then(|| {
        format!(
            "the calibration here ran the {} design ({points} of the grid's {of} points): grid \
             runs it left out count as pending; `sweep` or `calibrate --initial-design grid` \
             runs them",
            d["name"].as_str().unwrap_or("?")
        )
    })
}

/// The Slurm jobs of a study, a line each, and the queue's note.
fn slurm_lines(s: &mut String, q: &QueueView) {
    for sub in &q.submissions {
        let mut n = (0, 0, 0);
        for r in &sub.runs {
            match q.active.get(&r.fingerprint) {
                Some(t) if t.job_id == sub.job_id && t.state == TaskState::Running => n.0 += 1,
                Some(t) if t.job_id == sub.job_id => n.1 += 1,
                _ => n.2 += 1,
            }
        }
        let _ = write!(
            s,
            "Slurm job {} (submitted {}, {} runs)",
            sub.job_id,
            sub.submitted_utc,
            sub.runs.len()
        );
        if q.known {
            let _ = write!(s, ": {} running, {} queued, {} finished", n.0, n.1, n.2);
        }
        s.push('\n');
    }
    if let Some(note) = &q.note {
        let _ = writeln!(
            s,
            "note: {note}; running runs are those in progress in the store"
        );
    }
}

/// One line per run of the plan: index, state, directory, values and the state's detail.
fn run_lines(s: &mut String, plan: &Plan, survey: &Survey) {
    for (run, (rec, state)) in plan.runs.iter().zip(&survey.runs) {
        let detail = match state {
            RunState::Done => rec
                .as_ref()
                .map(|r| format!("{:.1} s", r.wall_seconds))
                .unwrap_or_default(),
            RunState::Failed(e) => e.clone(),
            RunState::Running(w) => w.clone(),
            RunState::Pending { queued, note } => queued
                .clone()
                .or_else(|| note.clone())
                .unwrap_or_else(|| "not started".into()),
        };
        let _ = writeln!(
            s,
            "{:>5}  {:<8} {}  {}  {}",
            run.index,
            state.word(),
            run.dir,
            describe_values(&plan.axes, &run.values),
            detail
        );
    }
}

/// A stand-in record for a run without a result, so the figures draw a gap there.
fn missing_record(plan: &Plan, i: usize) -> Record {
    Record {
        format: hvi_store::plan::STUDY_FORMAT_VERSION,
        fingerprint: plan.runs[i].fingerprint.clone(),
        study: plan.study.clone(),
        tier: plan.tier.clone(),
        params: serde_json::Map::new(),
        status: RunStatus::Failed,
        error: Some("missing: no result in the store".into()),
        reproducible: false,
        observables: Observables::default(),
        wall_seconds: f64::NAN,
        threads: 0,
        engine_version: plan.engine_version.clone(),
        measured_from: None,
        checksum: None,
    }
}

/// A study's runs as its store holds them, for `collect`: what to write (`kind`), the results
/// table, every run's record (a run without a result as a `missing` one) and which are missing.
pub struct Collected {
    /// The plan.
    pub plan: Plan,
    /// The study directory.
    pub dir: PathBuf,
    /// What to write.
    pub kind: CollectAs,
    /// One row per run.
    pub table: Table,
    /// One record per run; a run without a result has status `missing`.
    pub filled: Vec<Record>,
    /// The runs without a result.
    pub missing: Vec<usize>,
    /// No progress output.
    pub quiet: bool,
}

/// Reads a study's records from its store and decides what `collect` writes (the study's kind
/// unless `args.kind`); refuses `--cutoff` for another kind than `validity-map`. Failed runs
/// are said on the log.
pub fn gather(args: &CollectOptions) -> Result<Collected> {
    let (plan, dir) = open_plan(&args.study, true)?;
    let store = Store::open(&dir)?;
    let records: Vec<Option<Record>> = plan
        .runs
        .iter()
        .map(|r| store.record(&r.fingerprint))
        .collect::<Result<_>>()?;
    let kind = match args.kind {
        Some(k) => k,
        None => match Study::load(&plan.study_file) {
            Ok(s) if s.calibrate.is_some() => CollectAs::Calibrate,
            Ok(s) if s.validity.is_some() => CollectAs::ValidityMap,
            _ => CollectAs::Sweep,
        },
    };
    if args.cutoff.is_some() && kind != CollectAs::ValidityMap {
        bail!("--cutoff applies to `--as validity-map`");
    }
    let missing: Vec<usize> = (0..plan.runs.len())
        .filter(|&i| records[i].is_none())
        .collect();
    let filled: Vec<Record> = records
        .iter()
        .enumerate()
        .map(|(i, r)| r.clone().unwrap_or_else(|| missing_record(&plan, i)))
        .collect();
    let table = results_table(&plan, &records);
    let done = records.iter().flatten().cloned().collect::<Vec<_>>();
    print_failures(&done);
    Ok(Collected {
        plan,
        dir,
        kind,
        table,
        filled,
        missing,
        quiet: args.study.quiet,
    })
}

impl Collected {
    /// `sweep`'s tables: `results.csv` / `results.json`; their path on the log's stdout target.
    pub fn write_sweep(&self) -> Result<()> {
        self.table.write(&self.dir, "results")?;
        log::info!(target: hvi_run::STDOUT, "{}", self.dir.join("results.csv").display());
        Ok(())
    }

    /// `validity-map`'s outputs at `cutoff` (None: the study's, else 0.3).
    pub fn write_validity_map(&self, cutoff: Option<f64>) -> Result<()> {
        let cfg = ValidityConfig::of(&Study::load(&self.plan.study_file)?)?;
        let cut = Cut {
            observable: cfg.observable,
            cutoff: cfg.cutoff(cutoff)?,
        };
        validity_outputs(
            &self.plan,
            &self.dir,
            cut,
            self.table.clone(),
            &self.filled,
            self.quiet,
            None,
        )?;
        Ok(())
    }

    /// Names the runs without a result (the first ten), or says every run was collected.
    pub fn finish(&self) {
        report_missing(&self.plan, &self.missing, self.quiet);
    }
}

/// Names the runs without a result (`collect` ends with it) (the first ten), or says every run was collected.
fn report_missing(plan: &Plan, missing: &[usize], quiet: bool) {
    if !missing.is_empty() {
        let shown: Vec<String> = missing
            .iter()
            .take(10)
            .map(|&i| {
                format!(
                    "run {i} ({})",
                    describe_values(&plan.axes, &plan.runs[i].values)
                )
            })
            .collect();
        log::info!(
            "incomplete: {} of {} runs have no result yet (status `missing` in results.csv): {}{}",
            missing.len(),
            plan.runs.len(),
            shown.join(", "),
            if missing.len() > 10 { ", ..." } else { "" }
        );
    } else if !quiet {
        log::info!("all {} runs collected; nothing was run", plan.runs.len());
    }
}
