//! Studies on a Slurm cluster: `hvi-study submit STUDY --slurm` runs the runs a study directory
//! lacks as one job array, each array task one `hvi-study run-unit`.
//!
//! Nothing of ours runs on the cluster but `hvi-study run-unit`: Slurm schedules, the study
//! directory (on a filesystem the nodes share) holds everything. A submission lives in
//! `<study dir>/slurm/submission-NNN/`:
//!
//! ```text
//! job.sbatch       the job array's script (`--array=0-(n-1)[%K]`)
//! tasks.txt        line k = the plan index that array task k runs
//! plan.json        the plan as submitted (a later `plan`/`sweep` with other overrides rewrites
//!                  the study's plan.json; queued tasks keep running what was submitted)
//! submission.json  job id, time, and each task's run index and fingerprint (written once
//!                  sbatch has answered)
//! task-<k>.log     each task's output
//! ```
//!
//! Results land in the study's run store exactly as a local run's (`runs/<fingerprint>/`,
//! complete or absent), so a study started locally can be finished on the cluster or the
//! reverse: whatever is done is never submitted or run again, and runs of different inputs
//! never mix (their fingerprints differ). `hvi-study status` and `collect` read the same store.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::ErrorKind;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use crate::plan::describe_values;
use crate::plan::Plan;
use crate::store::{RunStatus, Store};
use hvi_run::error::{Result, ResultExt, RunError};
use hvi_run::files::write_atomic_bytes;

/// Seconds before a task's time limit at which Slurm sends it SIGTERM (`--signal`), so that
/// its run writes a checkpoint ([`hvi_run::checkpoint`]).
pub const SIGNAL_BEFORE_LIMIT_S: u32 = 120;

/// How `submit --slurm` asks Slurm to run a study's missing runs.
#[derive(Debug, Clone, Default)]
pub struct SlurmOptions {
    /// Slurm partition (`#SBATCH --partition`); `None`: the cluster's default.
    pub partition: Option<String>,
    /// Time limit of each run, in Slurm's format.
    pub time: Option<String>,
    /// CPUs of each run: its worker threads.
    pub cpus_per_task: usize,
    /// At most K runs at once (`--array=0-(n-1)%K`).
    pub array_limit: Option<usize>,
    /// Further `#SBATCH` options.
    pub sbatch_options: Vec<String>,
    /// Print the script and what would be submitted; write nothing, submit nothing.
    pub dry_run: bool,
    /// No per-task lines and hints after submitting.
    pub quiet: bool,
    /// How often each task's run writes a checkpoint (`--checkpoint-every`).
    pub checkpoint_every: hvi_run::checkpoint::Every,
}

/// One array task of a submission.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SubmittedRun {
    /// `SLURM_ARRAY_TASK_ID`.
    pub task: usize,
    /// The run's index in the submitted plan.
    pub index: usize,
    /// The run's fingerprint.
    pub fingerprint: String,
}

/// `submission.json`: what was submitted, when, as which job.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Submission {
    /// Slurm's job id of the array.
    pub job_id: String,
    /// Submission time, seconds since the Unix epoch.
    pub submitted_unix_s: u64,
    /// Submission time, UTC (`YYYY-MM-DDTHH:MM:SSZ`).
    pub submitted_utc: String,
    /// The study's name.
    pub study: String,
    /// The tier.
    pub tier: String,
    /// The job script.
    pub script: PathBuf,
    /// The plan the tasks run (a frozen copy).
    pub plan: PathBuf,
    /// The `#SBATCH` options.
    pub sbatch: Vec<String>,
    /// The runs, one per array task.
    pub runs: Vec<SubmittedRun>,
}

/// A task's state in the queue (`squeue`): only jobs still queued or running are listed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TaskState {
    /// Waiting (PENDING, held, requeued, suspended).
    Queued,
    /// RUNNING, CONFIGURING or COMPLETING.
    Running,
}

/// An active task of a recorded submission.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ActiveTask {
    /// The array's job id.
    pub job_id: String,
    /// The array task id.
    pub task: usize,
    /// Queued or running.
    pub state: TaskState,
}

/// What Slurm says about a study directory's submissions.
#[derive(Debug, Clone, Default)]
pub struct QueueView {
    /// The recorded submissions, oldest first.
    pub submissions: Vec<Submission>,
    /// Whether squeue answered (false without submissions, without squeue, or on its error;
    /// `note` says which of the last two).
    pub known: bool,
    /// Why the queue is unknown.
    pub note: Option<String>,
    /// Active tasks by run fingerprint.
    pub active: HashMap<String, ActiveTask>,
}

impl QueueView {
    /// The submissions of a study directory and their tasks still queued or running (asks
    /// squeue only when there are submissions).
    pub fn of(study_dir: &Path) -> Result<QueueView> {
        let submissions = submissions(study_dir)?;
        if submissions.is_empty() {
            return Ok(QueueView::default());
        }
        let ids: Vec<&str> = submissions.iter().map(|s| s.job_id.as_str()).collect();
        let tasks = match squeue(&ids) {
            Ok(Some(t)) => t,
            Ok(None) => {
                return Ok(QueueView {
                    submissions,
                    note: Some("squeue not found: Slurm's queue not consulted".into()),
                    ..QueueView::default()
                })
            }
            Err(e) => {
                return Ok(QueueView {
                    submissions,
                    note: Some(format!("{e:#}")),
                    ..QueueView::default()
                })
            }
        };
        let mut active = HashMap::new();
        for s in &submissions {
            for r in &s.runs {
                if let Some(&state) = tasks.get(&(s.job_id.clone(), r.task)) {
                    let t = ActiveTask {
                        job_id: s.job_id.clone(),
                        task: r.task,
                        state,
                    };
                    // A run in two live submissions: the running one counts.
                    let keep = matches!(
                        active.get(&r.fingerprint),
                        Some(ActiveTask {
                            state: TaskState::Running,
                            ..
                        })
                    );
                    if !keep {
                        active.insert(r.fingerprint.clone(), t);
                    }
                }
            }
        }
        Ok(QueueView {
            submissions,
            known: true,
            note: None,
            active,
        })
    }

    /// The latest submission that ran `fingerprint` and whose task is no longer in the queue:
    /// (job id, task, its log). For a run with no result, the place to look.
    pub fn ended_task(&self, fingerprint: &str) -> Option<(String, usize, PathBuf)> {
        if !self.known || self.active.contains_key(fingerprint) {
            return None;
        }
        self.submissions.iter().rev().find_map(|s| {
            let r = s.runs.iter().find(|r| r.fingerprint == fingerprint)?;
            let log = s
                .script
                .parent()
                .unwrap_or_else(|| Path::new("."))
                .join(format!("task-{}.log", r.task));
            Some((s.job_id.clone(), r.task, log))
        })
    }
}

/// The submissions recorded under `<study dir>/slurm/`, oldest first. A submission directory
/// without `submission.json` (sbatch refused it, or a dry run) is not one.
pub fn submissions(study_dir: &Path) -> Result<Vec<Submission>> {
    let dir = study_dir.join("slurm");
    let mut v = Vec::new();
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Ok(v);
    };
    for e in entries {
        let path = e?.path().join("submission.json");
        if !path.exists() {
            continue;
        }
        let text = std::fs::read_to_string(&path).map_err(|e| RunError::read(&path, e))?;
        let s: Submission = serde_json::from_str(&text).map_err(|e| RunError::Parse {
            message: format!("{} is not a submission record", path.display()),
            source: Some(Box::new(e)),
        })?;
        v.push(s);
    }
    v.sort_by_key(|s| (s.submitted_unix_s, s.script.clone()));
    Ok(v)
}

/// Runs a Slurm client command; `Ok(None)` when it is not installed.
fn slurm_command(
    program: &str,
    args: &[&str],
    cwd: Option<&Path>,
) -> Result<Option<std::process::Output>> {
    let mut cmd = Command::new(program);
    cmd.args(args);
    if let Some(d) = cwd {
        cmd.current_dir(d);
    }
    match cmd.output() {
        Ok(o) => Ok(Some(o)),
        Err(e) if e.kind() == ErrorKind::NotFound => Ok(None),
        Err(e) => Err(RunError::External(format!("cannot run {program}: {e}"))),
    }
}

/// The array tasks of these jobs still queued or running, by (job id, task id); `Ok(None)`
/// when squeue is not installed.
pub fn squeue(job_ids: &[&str]) -> Result<Option<HashMap<(String, usize), TaskState>>> {
    let ids = job_ids.join(",");
    // -r: one line per array task, pending ones too; %F the array's job id, %K the task id.
    let Some(out) = slurm_command("squeue", &["-h", "-r", "-j", &ids, "-o", "%F|%K|%T"], None)?
    else {
        return Ok(None);
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        // A single job id Slurm has forgotten (finished long ago) is an error of squeue's.
        if stderr.contains("Invalid job id") {
            return Ok(Some(HashMap::new()));
        }
        // Its last line says why (the earlier ones are the steps that led there).
        let why = stderr
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("");
        return Err(RunError::External(format!(
            "squeue failed ({}): {}",
            out.status,
            why.trim()
        )));
    }
    Ok(Some(parse_squeue(&String::from_utf8_lossy(&out.stdout))))
}

/// Parses `squeue -h -r -o '%F|%K|%T'` lines.
fn parse_squeue(text: &str) -> HashMap<(String, usize), TaskState> {
    let mut m = HashMap::new();
    for line in text.lines() {
        let mut f = line.trim().split('|');
        let (Some(job), Some(task), Some(state)) = (f.next(), f.next(), f.next()) else {
            continue;
        };
        let Ok(task) = task.parse::<usize>() else {
            continue;
        };
        let state = match state {
            "RUNNING" | "CONFIGURING" | "COMPLETING" | "STAGE_OUT" | "SIGNALING" => {
                TaskState::Running
            }
            "COMPLETED" | "CANCELLED" | "FAILED" | "TIMEOUT" | "NODE_FAIL" | "PREEMPTED"
            | "BOOT_FAIL" | "DEADLINE" | "OUT_OF_MEMORY" | "SPECIAL_EXIT" | "REVOKED" => continue,
            _ => TaskState::Queued,
        };
        m.insert((job.to_string(), task), state);
    }
    m
}

/// `YYYY-MM-DDTHH:MM:SSZ` of seconds since the Unix epoch (civil-from-days, H. Hinnant).
pub fn utc(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1_460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// Quotes a word for the shell: `'...'`, with `'` as `'\''`.
fn sh_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// A path as an `#SBATCH` option value: double-quoted (sbatch strips the quotes).
fn sbatch_path(p: &Path) -> String {
    format!("\"{}\"", p.display())
}

/// Checks a Slurm time limit: `M`, `M:S`, `H:M:S`, `D-H`, `D-H:M`, `D-H:M:S`, `UNLIMITED`.
fn valid_time(t: &str) -> bool {
    if t.eq_ignore_ascii_case("unlimited") || t.eq_ignore_ascii_case("infinite") {
        return true;
    }
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let (days, rest) = match t.split_once('-') {
        Some((d, r)) => (Some(d), r),
        None => (None, t),
    };
    let parts: Vec<&str> = rest.split(':').collect();
    let days_ok = match days {
        Some(d) => digits(d),
        None => true,
    };
    days_ok && (1..=3).contains(&parts.len()) && parts.iter().all(|p| digits(p))
}

/// What goes into a job array's script.
#[derive(Debug, Clone)]
pub struct ScriptSpec {
    /// `--job-name`.
    pub job_name: String,
    /// A comment line saying what the job is.
    pub what: String,
    /// Array tasks (runs).
    pub tasks: usize,
    /// `%K`: tasks at once.
    pub array_limit: Option<usize>,
    /// `--cpus-per-task`, also the runs' threads.
    pub cpus_per_task: usize,
    /// `--partition`.
    pub partition: Option<String>,
    /// `--time`.
    pub time: Option<String>,
    /// Further `#SBATCH` options.
    pub extra: Vec<String>,
    /// The runs' checkpoint interval (`run-unit --checkpoint-every`).
    pub checkpoint_every: hvi_run::checkpoint::Every,
    /// The study directory (absolute): the run store, and the tasks' working directory.
    pub study_dir: PathBuf,
    /// The submission's directory (absolute): tasks file, plan, logs.
    pub submission_dir: PathBuf,
    /// The hvi-study binary (absolute).
    pub exe: PathBuf,
}

impl ScriptSpec {
    /// The `#SBATCH` options, without the prefix.
    pub fn options(&self) -> Vec<String> {
        let mut o = vec![format!("--job-name={}", self.job_name)];
        let mut array = format!("--array=0-{}", self.tasks.saturating_sub(1));
        if let Some(k) = self.array_limit {
            let _ = write!(array, "%{k}");
        }
        o.push(array);
        o.push(format!("--cpus-per-task={}", self.cpus_per_task));
        if let Some(p) = &self.partition {
            o.push(format!("--partition={p}"));
        }
        if let Some(t) = &self.time {
            o.push(format!("--time={t}"));
        }
        o.push(format!(
            "--output={}",
            sbatch_path(&self.submission_dir.join("task-%a.log"))
        ));
        o.push(format!("--chdir={}", sbatch_path(&self.study_dir)));
        // SIGTERM to the task (the batch shell execs run-unit) two minutes before its time
        // limit: the run writes a checkpoint and the next submission resumes from it.
        if self.checkpoint_every != hvi_run::checkpoint::Every::Off {
            o.push(format!("--signal=B:TERM@{SIGNAL_BEFORE_LIMIT_S}"));
        }
        o.extend(self.extra.iter().cloned());
        o
    }

    /// The script: array task k runs the plan index on line k + 1 of tasks.txt.
    pub fn script(&self) -> String {
        let mut s = String::from("#!/bin/bash\n");
        let _ = writeln!(s, "# {}", self.what);
        for o in self.options() {
            let _ = writeln!(s, "#SBATCH {o}");
        }
        let tasks = self.submission_dir.join("tasks.txt");
        let plan = self.submission_dir.join("plan.json");
        let _ = write!(
            s,
            r#"set -euo pipefail
tasks={tasks}
index=$(sed -n "$((SLURM_ARRAY_TASK_ID + 1))p" "$tasks")
if [ -z "$index" ]; then
    echo "array task $SLURM_ARRAY_TASK_ID has no line in $tasks" >&2
    exit 2
fi
echo "job ${{SLURM_ARRAY_JOB_ID:-?}} task $SLURM_ARRAY_TASK_ID: run $index on $(hostname)"
exec {exe} run-unit {plan} "$index" --study-dir {dir} --threads "${{SLURM_CPUS_PER_TASK:-{cpus}}}" --checkpoint-every {every}
"#,
            tasks = sh_quote(&tasks.display().to_string()),
            exe = sh_quote(&self.exe.display().to_string()),
            plan = sh_quote(&plan.display().to_string()),
            dir = sh_quote(&self.study_dir.display().to_string()),
            cpus = self.cpus_per_task,
            every = self.checkpoint_every,
        );
        s
    }
}

/// An absolute form of a path (symlinks resolved where it exists).
pub fn absolute(p: &Path) -> Result<PathBuf> {
    match std::fs::canonicalize(p) {
        Ok(a) => Ok(a),
        Err(_) => std::path::absolute(p)
            .read_context(p, || format!("cannot make {} absolute", p.display())),
    }
}

impl SlurmOptions {
    /// Checks the Slurm options before anything is written.
    pub fn validate(&self) -> Result<()> {
        let args = self;
        if args.cpus_per_task == 0 {
            return Err(RunError::Input(
                "invalid value for `--cpus-per-task`: 0 (allowed: an integer >= 1)".into(),
            ));
        }
        if args.array_limit == Some(0) {
            return Err(RunError::Input(
                "invalid value for `--array-limit`: 0 (allowed: an integer >= 1)".into(),
            ));
        }
        if let Some(p) = &args.partition {
            if p.is_empty()
                || !p
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | ','))
            {
                return Err(RunError::Input(format!(
                    "invalid value for `--partition`: `{p}` (allowed: partition names of letters, \
                 digits, `_`, `-`, `.`, comma-separated)"
                )));
            }
        }
        if let Some(t) = &args.time {
            if !valid_time(t) {
                return Err(RunError::Input(format!(
                "invalid value for `--time`: `{t}` (allowed: Slurm's MM, MM:SS, HH:MM:SS, D-HH, \
                 D-HH:MM, D-HH:MM:SS or UNLIMITED)"
            )));
            }
        }
        for o in &args.sbatch_options {
            if !o.starts_with('-') || o.contains(['\n', '\r']) {
                return Err(RunError::Input(format!(
                "invalid value for `--sbatch-option`: `{o}` (allowed: one sbatch option such as \
                 --account=NAME, on one line)"
            )));
            }
        }
        Ok(())
    }
}

/// The next free `slurm/submission-NNN` directory (created, unless `create` is false).
fn submission_dir(study_dir: &Path, create: bool) -> Result<PathBuf> {
    let root = study_dir.join("slurm");
    let mut n = std::fs::read_dir(&root)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .filter_map(|e| {
                    e.file_name()
                        .to_string_lossy()
                        .strip_prefix("submission-")
                        .and_then(|d| d.parse::<usize>().ok())
                })
                .max()
                .unwrap_or(0)
        })
        .unwrap_or(0)
        + 1;
    if !create {
        return Ok(root.join(format!("submission-{n:03}")));
    }
    std::fs::create_dir_all(&root)
        .write_context(&root, || format!("cannot create {}", root.display()))?;
    loop {
        let dir = root.join(format!("submission-{n:03}"));
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            // Another submit took this number meanwhile.
            Err(e) if e.kind() == ErrorKind::AlreadyExists => n += 1,
            Err(e) => {
                return Err(RunError::Write {
                    message: format!("cannot create {}", dir.display()),
                    path: dir,
                    source: e,
                })
            }
        }
    }
}

/// Submits the job script with `sbatch --parsable`; returns the job id.
pub fn sbatch(script: &Path) -> Result<String> {
    let dir = script.parent().unwrap_or_else(|| Path::new("."));
    let script_arg = script.display().to_string();
    let out =
        slurm_command("sbatch", &["--parsable", &script_arg], Some(dir))?.ok_or_else(|| {
            RunError::External(
                "sbatch not found: `submit --slurm` needs Slurm's client commands on PATH (run it \
                 on the cluster's login node; `--dry-run` prints the job script without them)"
                    .into(),
            )
        })?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        return Err(RunError::External(format!(
            "sbatch failed ({}): {}",
            out.status,
            stderr.trim()
        )));
    }
    // --parsable: `jobid` or `jobid;cluster`.
    let id = stdout
        .lines()
        .next()
        .unwrap_or("")
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_string();
    if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
        return Err(RunError::External(format!(
            "sbatch printed `{}` instead of a job id{}",
            stdout.trim(),
            if stderr.trim().is_empty() {
                String::new()
            } else {
                format!(" ({})", stderr.trim())
            }
        )));
    }
    Ok(id)
}

/// What a study lacks, as a submission sees it.
struct Pending {
    /// Completed runs.
    done: usize,
    /// Failed runs whose failure the engine repeats (kept, not submitted again).
    kept: usize,
    /// Failed runs (submitted again).
    failed: usize,
    /// Plan indices to submit.
    todo: Vec<usize>,
    /// Job ids of earlier submissions still running some of the plan's runs, and how many.
    in_queue: (Vec<String>, usize),
}

/// The runs of `plan` that `out`'s store lacks and Slurm is not already running.
fn pending(plan: &Plan, out: &Path) -> Result<Pending> {
    // What is done: read the store only if there is one (a dry run creates nothing).
    let store = if out.join("runs").is_dir() {
        Some(Store::open(out)?)
    } else {
        None
    };
    let (mut done, mut kept, mut failed, mut todo) = (0, 0, 0, Vec::new());
    for r in &plan.runs {
        let rec = match &store {
            Some(s) => s.record(&r.fingerprint)?,
            None => None,
        };
        match rec {
            Some(r) if r.status == RunStatus::Completed => done += 1,
            // A failure the engine repeats is the run's result, as in a local run.
            Some(r) if r.is_final() => kept += 1,
            // Any other failed run is run again, as a local run would.
            Some(_) => {
                failed += 1;
                todo.push(r.index);
            }
            None => todo.push(r.index),
        }
    }
    // Runs already queued or running from an earlier submission are not submitted twice.
    let queue = if todo.is_empty() {
        QueueView::default()
    } else {
        QueueView::of(out)?
    };
    if let Some(note) = &queue.note {
        log::warn!("note: {note}");
    }
    let mut jobs = Vec::new();
    let mut queued = 0;
    todo.retain(|&i| match queue.active.get(&plan.runs[i].fingerprint) {
        Some(t) => {
            jobs.push(t.job_id.clone());
            queued += 1;
            false
        }
        None => true,
    });
    jobs.sort();
    jobs.dedup();
    Ok(Pending {
        done,
        kept,
        failed,
        todo,
        in_queue: (jobs, queued),
    })
}

impl Pending {
    /// The one line `submit` prints of the study's state.
    fn status_line(&self, plan: &Plan) -> String {
        let mut line = format!(
            "study `{}` at tier `{}`: {} runs, {} done",
            plan.study,
            plan.tier,
            plan.runs.len(),
            self.done
        );
        if self.kept > 0 {
            let _ = write!(line, ", {} {}", self.kept, crate::store::FAILED_FOR_GOOD);
        }
        if self.failed > 0 {
            let _ = write!(line, ", {} failed (submitted again)", self.failed);
        }
        let (jobs, queued) = &self.in_queue;
        if *queued > 0 {
            let _ = write!(
                line,
                ", {queued} already queued or running in job {}",
                jobs.join(", ")
            );
        }
        if self.todo.is_empty() {
            line.push_str("; nothing to submit");
        } else {
            let _ = write!(line, "; {} to submit", self.todo.len());
        }
        line
    }
}

/// A name safe for `--job-name`: letters, digits, `-`, `_` and `.`, the rest `_`.
fn job_name_part(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The `%K` suffix of the array range.
fn array_suffix(limit: Option<usize>) -> String {
    limit.map_or(String::new(), |k| format!("%{k}"))
}

/// What [`submit`] did: the caller prints the script of a dry run and the job id.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Submitted {
    /// Every run is done or already queued.
    Nothing,
    /// A dry run: the job script that would be submitted.
    DryRun {
        /// The script.
        script: String,
    },
    /// The job array's id.
    Job {
        /// Slurm's job id.
        id: String,
    },
}

/// `hvi-study submit STUDY --slurm`: the runs the store of `out` lacks (and Slurm is not
/// already running) as one job array of `run-unit`s.
pub fn submit(plan: &Plan, out: &Path, opts: &SlurmOptions) -> Result<Submitted> {
    opts.validate()?;
    let pending = pending(plan, out)?;
    log::info!("{}", pending.status_line(plan));
    let todo = &pending.todo;
    if todo.is_empty() {
        return Ok(Submitted::Nothing);
    }
    let study_dir = absolute(out)?;
    let sub_dir = if opts.dry_run {
        submission_dir(&study_dir, false)?
    } else {
        plan.write(out)?;
        submission_dir(&study_dir, true)?
    };
    let spec = script_spec(
        plan,
        todo.len(),
        opts,
        &study_dir,
        &sub_dir,
        "hvi-study submit",
    )?;
    if opts.dry_run {
        log::info!(
            "dry run: would submit {} runs as array 0-{}{} from {} (tasks.txt: {}); nothing written, nothing submitted",
            todo.len(),
            todo.len() - 1,
            array_suffix(opts.array_limit),
            sub_dir.display(),
            todo.iter()
                .map(|i| i.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        );
        return Ok(Submitted::DryRun {
            script: spec.script(),
        });
    }
    let job_id = submit_script(plan, todo, &spec)?;
    if !opts.quiet {
        print_submitted(plan, todo, opts, &job_id, &sub_dir, &study_dir);
    }
    Ok(Submitted::Job { id: job_id })
}

/// The job script of `tasks` runs of `plan` submitted from `sub_dir` by `who` (a command,
/// for the script's comment line).
fn script_spec(
    plan: &Plan,
    tasks: usize,
    opts: &SlurmOptions,
    study_dir: &Path,
    sub_dir: &Path,
    who: &str,
) -> Result<ScriptSpec> {
    let exe = std::env::current_exe()
        .and_then(std::fs::canonicalize)
        .context("cannot find the hvi-study binary's path for the job script")?;
    Ok(ScriptSpec {
        job_name: format!(
            "hvi-{}-{}",
            job_name_part(&plan.study),
            job_name_part(&plan.tier)
        ),
        what: format!(
            "{who}: study `{}` at tier `{}`, {tasks} runs of {} (array task k runs the plan index on line k + 1 of tasks.txt)",
            plan.study,
            plan.tier,
            study_dir.display()
        )
        .replace('\n', " "),
        tasks,
        array_limit: opts.array_limit,
        cpus_per_task: opts.cpus_per_task,
        partition: opts.partition.clone(),
        time: opts.time.clone(),
        extra: opts.sbatch_options.clone(),
        checkpoint_every: opts.checkpoint_every,
        study_dir: study_dir.to_path_buf(),
        submission_dir: sub_dir.to_path_buf(),
        exe,
    })
}

/// Submits the runs of a batch plan (a plan of some runs, e.g. one batch of a calibration's
/// search, not written as the study's plan.json) that the store of `out` lacks and Slurm is
/// not already running, as one job array. Returns the new job's id (None: nothing to submit)
/// and the job ids of earlier submissions still running some of its runs.
pub fn submit_batch(
    plan: &Plan,
    out: &Path,
    opts: &SlurmOptions,
    who: &str,
) -> Result<(Option<String>, Vec<String>)> {
    opts.validate()?;
    let pending = pending(plan, out)?;
    let earlier = pending.in_queue.0.clone();
    if pending.todo.is_empty() {
        return Ok((None, earlier));
    }
    let study_dir = absolute(out)?;
    let sub_dir = submission_dir(&study_dir, true)?;
    let spec = script_spec(plan, pending.todo.len(), opts, &study_dir, &sub_dir, who)?;
    let job_id = submit_script(plan, &pending.todo, &spec)?;
    if !opts.quiet {
        log::info!(
            "submitted job {job_id}: {} runs as array 0-{}{}, {} CPU(s) each; logs in {}",
            pending.todo.len(),
            pending.todo.len() - 1,
            array_suffix(opts.array_limit),
            opts.cpus_per_task,
            sub_dir.display()
        );
    }
    Ok((Some(job_id), earlier))
}

/// Writes the submission's plan, tasks and script, submits it, and records `submission.json`;
/// returns the job id. A failed `sbatch` leaves no submission directory behind.
fn submit_script(plan: &Plan, todo: &[usize], spec: &ScriptSpec) -> Result<String> {
    let sub_dir = &spec.submission_dir;
    write_atomic_bytes(
        &sub_dir.join("plan.json"),
        serde_json::to_string_pretty(plan)?.as_bytes(),
    )?;
    let tasks_text: String = todo.iter().map(|i| format!("{i}\n")).collect();
    write_atomic_bytes(&sub_dir.join("tasks.txt"), tasks_text.as_bytes())?;
    let script_path = sub_dir.join("job.sbatch");
    write_atomic_bytes(&script_path, spec.script().as_bytes())?;
    let job_id = match sbatch(&script_path) {
        Ok(id) => id,
        Err(e) => {
            // Leave no half submission behind (status would not count it anyway).
            let _ = std::fs::remove_dir_all(sub_dir);
            return Err(e.context("nothing submitted (`--dry-run` prints the job script)"));
        }
    };
    let now = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let submission = Submission {
        job_id: job_id.clone(),
        submitted_unix_s: now,
        submitted_utc: utc(now),
        study: plan.study.clone(),
        tier: plan.tier.clone(),
        script: script_path.clone(),
        plan: sub_dir.join("plan.json"),
        sbatch: spec.options(),
        runs: todo
            .iter()
            .enumerate()
            .map(|(task, &index)| SubmittedRun {
                task,
                index,
                fingerprint: plan.runs[index].fingerprint.clone(),
            })
            .collect(),
    };
    write_atomic_bytes(
        &sub_dir.join("submission.json"),
        serde_json::to_string_pretty(&submission)?.as_bytes(),
    )
    .with_context(|| format!("job {job_id} was submitted but its record was not written"))?;
    Ok(job_id)
}

/// What `submit` prints after submitting: each task's run, and how to follow the job.
fn print_submitted(
    plan: &Plan,
    todo: &[usize],
    opts: &SlurmOptions,
    job_id: &str,
    sub_dir: &Path,
    study_dir: &Path,
) {
    for (task, &i) in todo.iter().enumerate() {
        log::info!(
            "  task {task}: run {i} ({})",
            describe_values(&plan.axes, &plan.runs[i].values)
        );
    }
    log::info!(
        "submitted job {job_id}: {} runs as array 0-{}{}, {} CPU(s) each; logs and record in {}",
        todo.len(),
        todo.len() - 1,
        array_suffix(opts.array_limit),
        opts.cpus_per_task,
        sub_dir.display()
    );
    log::info!(
        "follow it with `hvi-study status {}`; `hvi-study collect {}` writes the tables when it is done",
        study_dir.display(),
        study_dir.display()
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates() {
        assert_eq!(utc(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc(1_700_000_000), "2023-11-14T22:13:20Z");
        assert_eq!(utc(4_107_542_399), "2100-02-28T23:59:59Z");
    }

    #[test]
    fn slurm_time_limits() {
        for ok in [
            "30",
            "30:00",
            "1:00:00",
            "2-0",
            "2-12:00",
            "2-12:00:00",
            "UNLIMITED",
        ] {
            assert!(valid_time(ok), "{ok}");
        }
        for bad in ["", "1h", "1:2:3:4", "-1", "2-", "1:00\n#SBATCH x", "a-1"] {
            assert!(!valid_time(bad), "{bad}");
        }
    }

    #[test]
    fn squeue_lines_become_task_states() {
        let m =
            parse_squeue("12|0|RUNNING\n12|3|PENDING\n12|4|COMPLETED\n13|N/A|RUNNING\ngarbage\n");
        assert_eq!(m.get(&("12".into(), 0)), Some(&TaskState::Running));
        assert_eq!(m.get(&("12".into(), 3)), Some(&TaskState::Queued));
        assert_eq!(m.len(), 2);
    }

    #[test]
    fn script_maps_array_tasks_to_plan_indices_with_absolute_paths() {
        let spec = ScriptSpec {
            job_name: "hvi-s-quick".into(),
            what: "test".into(),
            tasks: 5,
            array_limit: Some(2),
            cpus_per_task: 3,
            partition: Some("short".into()),
            time: Some("1:00:00".into()),
            extra: vec!["--account=p42".into()],
            checkpoint_every: hvi_run::checkpoint::Every::Wall(std::time::Duration::from_secs(300)),
            study_dir: PathBuf::from("/scratch/it's here"),
            submission_dir: PathBuf::from("/scratch/it's here/slurm/submission-001"),
            exe: PathBuf::from("/opt/hvi/bin/hvi-study"),
        };
        let s = spec.script();
        assert!(s.starts_with("#!/bin/bash\n"));
        for line in [
            "#SBATCH --array=0-4%2",
            "#SBATCH --cpus-per-task=3",
            "#SBATCH --partition=short",
            "#SBATCH --time=1:00:00",
            "#SBATCH --account=p42",
            "#SBATCH --signal=B:TERM@120",
            "#SBATCH --output=\"/scratch/it's here/slurm/submission-001/task-%a.log\"",
            "tasks='/scratch/it'\\''s here/slurm/submission-001/tasks.txt'",
            "exec '/opt/hvi/bin/hvi-study' run-unit '/scratch/it'\\''s here/slurm/submission-001/plan.json' \"$index\" --study-dir '/scratch/it'\\''s here' --threads \"${SLURM_CPUS_PER_TASK:-3}\" --checkpoint-every 300s",
        ] {
            assert!(s.lines().any(|l| l == line), "no line {line} in\n{s}");
        }
        let no_limit = ScriptSpec {
            array_limit: None,
            tasks: 1,
            ..spec
        };
        assert!(no_limit.script().contains("#SBATCH --array=0-0\n"));
    }
}
