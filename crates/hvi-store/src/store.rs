//! The run store: one directory per fingerprint, each appearing complete or not at all.
//!
//! Layout under a study's output directory:
//!
//! ```text
//! runs/<first 16 hex digits of the fingerprint>/
//!     record.json      the run's record: fingerprint, status, error, observables (written last)
//!     summary.json     the engine run's summary (hvi_run::run::run_scene)
//!     energy.csv, cloud_track.csv, fragments.csv, cloud_side.png and the other pictures
//!     state.bin        the cloud's kept state (hvi_run::state), for `hvi-study reanalyse`
//! runs/.tmp-<digits>-<pid>-<n>-<host>/   a run in progress
//! runs/.lock-<digits>                     its lock (hvi_store::lock)
//! runs/.checkpoint-<digits>.bin           its last checkpoint (hvi_run::checkpoint)
//! ```
//!
//! A run works in a temporary directory and, once `record.json` is written and synced, renames
//! it to its final name. A process killed at any moment (even SIGKILL) therefore leaves either a
//! complete run directory or a temporary one, which the next execution removes (when the process
//! that made it is gone) and redoes. On a filesystem shared between machines (a cluster) a
//! process id only means something on the host that made the directory, so only that host's
//! leftovers are judged and removed. A directory whose `record.json` names another fingerprint
//! is refused, never reused.
//!
//! A long run also writes checkpoints beside its lock ([`hvi_run::checkpoint`], every
//! [`Store::with_checkpoint_every`] and when a signal stops it): a run killed mid-way resumes
//! from its last checkpoint in a new temporary directory and ends as it would have, and the
//! checkpoint is removed once the run is stored.
//!
//! A run whose scene differs from a completed run's of the store only in how the cloud is
//! measured ([`hvi_engine::scene::MEASUREMENT_KEYS`]: the quantile, the width, the camera, the
//! witness plate) is measured from that run's kept state rather than simulated again
//! ([`crate::remeasured`]); its record names the run it was measured from (`measured_from`).
//! The runs that can serve so are those completed, with a kept state, when the store first
//! looks for one ([`Store::source_for`]), so which runs are measured does not depend on the
//! order in which the runs of one execution finish. A run that cannot be measured so (its
//! source's state unreadable) is simulated.

use std::collections::HashMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use hvi_analysis::observable::Observables;
use hvi_engine::scene::SceneSpec;
use serde::{Deserialize, Serialize};

use sha2::{Digest, Sha256};

use hvi_run::error::{Result, ResultExt, RunError};
pub use hvi_run::files::host_name;
use hvi_run::files::{
    canonical_json, write_atomic_bytes, DIR_DIGITS, ENGINE_VERSION, STUDY_FORMAT_VERSION,
};
use hvi_run::run::{run_scene, RunOptions, Summary};

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunStatus {
    /// Reached its end time; observables measured.
    Completed,
    /// Stopped with an error (e.g. an instability); the error is recorded.
    Failed,
}

pub use hvi_run::run::read_summary;

/// `record.json`: the last file of a run's directory, and the proof that it is complete.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Record {
    /// [`STUDY_FORMAT_VERSION`].
    pub format: u32,
    /// The full fingerprint.
    pub fingerprint: String,
    /// The study that first ran it.
    pub study: String,
    /// The tier.
    pub tier: String,
    /// The run's parameters (axis key -> value) as the study named them.
    pub params: serde_json::Map<String, serde_json::Value>,
    /// How it ended.
    pub status: RunStatus,
    /// The error, when it failed.
    pub error: Option<String>,
    /// A failure the engine repeats on the same scene (an instability, a value the scene
    /// rejects: [`hvi_run::error::is_reproducible`]): the run's result, kept when a study runs
    /// again. False for a completed run and for a failure that may not recur (a panic, a
    /// damaged checkpoint), which runs again; absent in records of earlier versions.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub reproducible: bool,
    /// What was measured (also for a failed run, where the summary has anything).
    pub observables: Observables,
    /// Wall time of the run, s.
    pub wall_seconds: f64,
    /// Threads the run used.
    pub threads: usize,
    /// hvi-study version that ran it.
    pub engine_version: String,
    /// The fingerprint of the run whose kept state this one was measured from, when the store
    /// measured it rather than simulated it (see the module's doc); absent for a simulated run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_from: Option<String>,
    /// SHA-256 (hex) of the record's canonical JSON without this field ([`Record::digest`]):
    /// a record changed on disk is caught, not used. Absent in records of earlier versions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checksum: Option<String>,
}

/// The SHA-256 (hex) of a stored record's JSON text as written, canonical, with `checksum`
/// left out: the digest [`Record::sealed`] wrote, checked against the file itself rather than
/// against the record as this version would write it again, so that a later version that adds
/// an observable still reads the records of an earlier one.
fn stored_digest(text: &str) -> Result<String> {
    let mut value: serde_json::Value = serde_json::from_str(text).context("record as JSON")?;
    if let Some(map) = value.as_object_mut() {
        map.remove("checksum");
    }
    let digest = Sha256::digest(canonical_json(&value).as_bytes());
    Ok(digest.iter().map(|b| format!("{b:02x}")).collect())
}

impl Record {
    /// The SHA-256 (hex) of the record's canonical JSON with `checksum` left out.
    pub fn digest(&self) -> Result<String> {
        let mut bare = self.clone();
        bare.checksum = None;
        let value = serde_json::to_value(&bare).context("record as JSON")?;
        let digest = Sha256::digest(canonical_json(&value).as_bytes());
        Ok(digest.iter().map(|b| format!("{b:02x}")).collect())
    }

    /// Whether the run is finished for good: completed, or failed in a way running it again
    /// repeats ([`Record::reproducible`]). A study runs again only the runs that are not.
    pub fn is_final(&self) -> bool {
        self.status == RunStatus::Completed || self.reproducible
    }

    /// The unsealed record of `job` computed here now: completed, or failed with `error`, in
    /// `wall_seconds` on `threads` threads.
    pub(crate) fn of(
        job: &Job,
        error: Option<Failure>,
        observables: Observables,
        wall_seconds: f64,
        threads: usize,
    ) -> Record {
        Record {
            format: STUDY_FORMAT_VERSION,
            fingerprint: job.fingerprint.clone(),
            study: job.study.clone(),
            tier: job.tier.clone(),
            params: job.params.clone(),
            status: if error.is_none() {
                RunStatus::Completed
            } else {
                RunStatus::Failed
            },
            reproducible: error.as_ref().is_some_and(|f| f.reproducible),
            error: error.map(|f| f.message),
            observables,
            wall_seconds,
            threads,
            engine_version: ENGINE_VERSION.to_string(),
            measured_from: None,
            checksum: None,
        }
    }

    /// The record with its checksum set.
    pub fn sealed(mut self) -> Result<Record> {
        self.checksum = Some(self.digest()?);
        Ok(self)
    }
}

/// How a count of runs kept as failed for good ([`Record::reproducible`]) reads after its
/// number, in `submit`'s and `status`'s lines.
pub const FAILED_FOR_GOOD: &str = "failed for good (an instability or a rejected value: kept)";

/// Why a run failed, as its record keeps it.
#[derive(Debug, Clone)]
pub(crate) struct Failure {
    /// The error in words.
    pub message: String,
    /// Whether running it again fails the same way ([`Record::reproducible`]).
    pub reproducible: bool,
}

/// A run to execute: its scene and its identity.
#[derive(Debug, Clone)]
pub struct Job {
    /// The full fingerprint ([`crate::plan::fingerprint`]).
    pub fingerprint: String,
    /// The scene as it runs.
    pub scene: SceneSpec,
    /// The study's name.
    pub study: String,
    /// The tier.
    pub tier: String,
    /// The run's parameters, for the record and the tables.
    pub params: serde_json::Map<String, serde_json::Value>,
}

/// The run directories of one study output directory.
#[derive(Debug, Clone)]
pub struct Store {
    runs: PathBuf,
    /// Runs this store was asked to compute that another process finished meanwhile.
    elsewhere: std::sync::Arc<AtomicU64>,
    /// Whether a damaged run is moved aside (and so runs again) rather than an error.
    repair: bool,
    /// How often each run it computes writes a checkpoint ([`Store::with_checkpoint_every`]).
    checkpoint_every: hvi_run::checkpoint::Every,
    /// Per fingerprint, the share of a run (in base steps) done before this process resumed it
    /// from its checkpoint ([`Store::resumed_share`]).
    resumed: std::sync::Arc<std::sync::Mutex<std::collections::HashMap<String, f64>>>,
    /// The completed runs with a kept state, by simulation key, as the store held them when
    /// first asked ([`Store::source_for`]).
    sources: std::sync::Arc<std::sync::OnceLock<HashMap<String, Vec<Candidate>>>>,
}

/// A run of the index of sources ([`Store::source_for`]).
#[derive(Debug, Clone)]
struct Candidate {
    source: Source,
    /// Its analysis settings.
    analysis: hvi_engine::scene::Analysis,
    /// Whether it was simulated (not itself measured from a kept state).
    simulated: bool,
}

/// A completed run whose kept state can serve another run's measurement.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Source {
    /// Its fingerprint.
    pub fingerprint: String,
    /// Its directory.
    pub dir: PathBuf,
}

static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// The study's log of runs started and ended, in the study directory ([`Store::log_path`]).
pub const LOG_FILE: &str = "study.log";

/// Whether the process with this id is alive (Linux: /proc; elsewhere assumed alive, so
/// nothing of a running process is ever removed).
fn process_alive(pid: u32) -> bool {
    if !Path::new("/proc/self").exists() {
        return true;
    }
    Path::new(&format!("/proc/{pid}")).exists()
}

/// A run in progress (or abandoned): a temporary directory of the store.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InProgress {
    /// The fingerprint's first [`DIR_DIGITS`] hex digits.
    pub digits: String,
    /// The process that works in it.
    pub pid: u32,
    /// The host it runs on (`None` for directories named before hosts were recorded).
    pub host: Option<String>,
    /// Whether that process is alive: `None` when it runs on another host (unknowable here).
    pub alive: Option<bool>,
    /// The directory.
    pub path: PathBuf,
}

impl InProgress {
    /// Parses a temporary directory's name, `.tmp-<digits>-<pid>-<n>[-<host>]` (or `.old-`).
    fn parse(path: PathBuf) -> Option<InProgress> {
        let name = path.file_name()?.to_string_lossy().into_owned();
        let rest = name
            .strip_prefix(".tmp-")
            .or_else(|| name.strip_prefix(".old-"))?;
        let mut parts = rest.splitn(4, '-');
        let digits = parts.next()?.to_string();
        let pid = parts.next()?.parse::<u32>().ok()?;
        let _n = parts.next()?;
        let host = parts.next().map(str::to_string);
        let here = match host.as_deref() {
            Some(h) => h == host_name(),
            None => true,
        };
        Some(InProgress {
            digits,
            pid,
            alive: here.then(|| pid == std::process::id() || process_alive(pid)),
            host,
            path,
        })
    }
}

fn sync_dir(dir: &Path) {
    // Makes a rename durable; not every platform can open a directory, so errors are ignored.
    if let Ok(f) = fs::File::open(dir) {
        let _ = f.sync_all();
    }
}

impl Store {
    /// Opens (creates) `study_dir/runs` and removes what killed processes left there.
    pub fn open(study_dir: &Path) -> Result<Store> {
        let runs = study_dir.join("runs");
        fs::create_dir_all(&runs).write_context(&runs, || {
            format!("cannot create run store {}", runs.display())
        })?;
        let store = Store {
            runs,
            repair: true,
            elsewhere: Default::default(),
            resumed: Default::default(),
            sources: Default::default(),
            checkpoint_every: hvi_run::checkpoint::Every::default(),
        };
        store.sweep_stale()?;
        Ok(store)
    }

    /// The store, its runs writing a checkpoint this often ([`hvi_run::checkpoint::Every`];
    /// every 10 minutes of wall time unless set).
    pub fn with_checkpoint_every(self, every: hvi_run::checkpoint::Every) -> Store {
        Store {
            checkpoint_every: every,
            ..self
        }
    }

    /// The store of `study_dir` as it is, for reading: neither created nor swept (an error
    /// when `study_dir/runs` is not a directory).
    pub fn existing(study_dir: &Path) -> Result<Store> {
        let runs = study_dir.join("runs");
        if !runs.is_dir() {
            return Err(RunError::Store(format!(
                "{} has no run store (no runs/ directory)",
                study_dir.display()
            )));
        }
        Ok(Store {
            runs,
            repair: false,
            elsewhere: Default::default(),
            resumed: Default::default(),
            sources: Default::default(),
            checkpoint_every: hvi_run::checkpoint::Every::default(),
        })
    }

    /// The directories of finished runs (named by [`DIR_DIGITS`] hex digits and holding a
    /// `record.json`), by name; runs in progress are left out.
    pub fn run_dirs(&self) -> Result<Vec<PathBuf>> {
        let mut v = Vec::new();
        for entry in fs::read_dir(&self.runs).read_context(&self.runs, || {
            format!("cannot list {}", self.runs.display())
        })? {
            let path = entry?.path();
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
            let digits = name
                .is_some_and(|n| n.len() == DIR_DIGITS && n.chars().all(|c| c.is_ascii_hexdigit()));
            if digits && path.join("record.json").is_file() {
                v.push(path);
            }
        }
        v.sort();
        Ok(v)
    }

    /// Removes temporary directories whose process is gone (on this host: another host's
    /// process cannot be checked from here). Returns how many.
    pub fn sweep_stale(&self) -> Result<usize> {
        let mut n = 0;
        for t in self.in_progress()? {
            if t.alive == Some(false) {
                fs::remove_dir_all(&t.path).write_context(&t.path, || {
                    format!("cannot remove stale {}", t.path.display())
                })?;
                n += 1;
            }
        }
        Ok(n)
    }

    /// The temporary directories: runs in progress, or left by killed processes.
    pub fn in_progress(&self) -> Result<Vec<InProgress>> {
        let mut v = Vec::new();
        for entry in fs::read_dir(&self.runs)? {
            v.extend(InProgress::parse(entry?.path()));
        }
        v.sort_by(|a, b| a.path.cmp(&b.path));
        Ok(v)
    }

    /// How many runs [`Store::execute`] took from another process that finished them while
    /// this one waited, so far.
    pub fn done_elsewhere(&self) -> usize {
        self.elsewhere.load(Ordering::Relaxed) as usize
    }

    /// The directory of a run.
    pub fn dir(&self, fingerprint: &str) -> PathBuf {
        self.runs
            .join(&fingerprint[..DIR_DIGITS.min(fingerprint.len())])
    }

    /// The checkpoint file of a run in progress ([`hvi_run::checkpoint`]).
    pub fn checkpoint_path(&self, fingerprint: &str) -> PathBuf {
        self.runs.join(format!(
            ".checkpoint-{}.bin",
            &fingerprint[..DIR_DIGITS.min(fingerprint.len())]
        ))
    }

    /// The runs with a checkpoint (killed or stopped mid-way, or in progress): their
    /// fingerprints' first digits.
    pub fn checkpointed(&self) -> Result<Vec<String>> {
        let mut v = Vec::new();
        for entry in fs::read_dir(&self.runs)? {
            let name = entry?.file_name().to_string_lossy().into_owned();
            if let Some(d) = name
                .strip_prefix(".checkpoint-")
                .and_then(|r| r.strip_suffix(".bin"))
            {
                v.push(d.to_string());
            }
        }
        v.sort();
        Ok(v)
    }

    /// Whether the store holds the run `fingerprint` finished; a record it cannot read (a
    /// damaged one, in a store opened read-only) counts as not: the run repairs and re-runs it.
    pub fn holds_finished(&self, fingerprint: &str) -> bool {
        matches!(self.record(fingerprint), Ok(Some(r)) if r.is_final())
    }

    /// The record of a finished run, if there is one. A damaged run (a directory without
    /// `record.json`, a record that does not parse, or one whose checksum does not match its
    /// content) is moved aside to `runs/damaged-<digits>-<time>-<pid>` (kept for inspection,
    /// reported on stderr) and counts as not run, so it runs again; a store opened read-only
    /// ([`Store::existing`]) reports it as an error instead. A record with another fingerprint
    /// or format is an error: results of different inputs are never mixed.
    pub fn record(&self, fingerprint: &str) -> Result<Option<Record>> {
        let dir = self.dir(fingerprint);
        let path = dir.join("record.json");
        if !path.exists() {
            if dir.exists() {
                return self.damaged(&dir, "it has no record.json");
            }
            return Ok(None);
        }
        let text = fs::read_to_string(&path).map_err(|e| RunError::read(&path, e))?;
        let rec: Record = match serde_json::from_str(&text) {
            Ok(r) => r,
            Err(e) => {
                return self.damaged(&dir, &format!("its record.json is not a run record ({e})"))
            }
        };
        if rec.fingerprint != fingerprint {
            return Err(RunError::Store(format!(
                "refusing to mix results: {} holds fingerprint {} but this run's is {fingerprint}; \
                 move the directory away",
                dir.display(),
                rec.fingerprint
            )));
        }
        if rec.format != STUDY_FORMAT_VERSION {
            return Err(RunError::parse(format!(
                "{}: record format {} (this hvi-study writes {STUDY_FORMAT_VERSION})",
                path.display(),
                rec.format
            )));
        }
        if let Some(sum) = &rec.checksum {
            if *sum != stored_digest(&text)? {
                return self.damaged(
                    &dir,
                    "its record.json was changed after it was written (checksum mismatch)",
                );
            }
        }
        Ok(Some(rec))
    }

    /// A damaged run directory: moved aside (repairing store) or an error (read-only store).
    fn damaged(&self, dir: &Path, why: &str) -> Result<Option<Record>> {
        if !self.repair {
            return Err(RunError::Store(format!(
                "damaged run {}: {why}; the next sweep of the study moves it aside and runs it \
                 again",
                dir.display()
            )));
        }
        let digits = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let stamp = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let aside = self.runs.join(format!(
            "damaged-{digits}-{stamp}-{}-{}",
            std::process::id(),
            TMP_COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        fs::rename(dir, &aside).write_context(&aside, || {
            format!(
                "damaged run {} ({why}): cannot move it aside",
                dir.display()
            )
        })?;
        sync_dir(&self.runs);
        log::warn!(
            "run store: {} is damaged ({why}); moved it to {} and it runs again",
            dir.display(),
            aside.display()
        );
        Ok(None)
    }

    /// The completed run, with a kept state, that `job` can be measured from instead of
    /// simulated (see the module's doc): one whose scene differs from the job's only in how
    /// the cloud is measured. The candidates are the runs the store held when this was first
    /// asked. Of several, a simulated one whose track reads as the job's would (the same
    /// quantile and width, so the job keeps its track), else a simulated one, else any; each
    /// time the first by directory name.
    pub fn source_for(&self, job: &Job) -> Option<Source> {
        let key = crate::plan::simulation_key(&job.scene, &job.tier, ENGINE_VERSION).ok()?;
        let candidates = self
            .sources
            .get_or_init(|| self.index_sources())
            .get(&key)?;
        let rank = |c: &Candidate| match (
            c.simulated,
            c.analysis.same_track_reading(&job.scene.analysis),
        ) {
            (true, true) => 0,
            (true, false) => 1,
            (false, _) => 2,
        };
        candidates
            .iter()
            .filter(|c| c.source.fingerprint != job.fingerprint)
            .min_by_key(|c| rank(c))
            .map(|c| c.source.clone())
    }

    /// The store's completed runs with a kept state, by simulation key, each key's in the
    /// order of their directories. A run whose record, summary or checksum does not read is
    /// left out (it serves nothing, and is judged when a study asks for it).
    fn index_sources(&self) -> HashMap<String, Vec<Candidate>> {
        let mut index: HashMap<String, Vec<Candidate>> = HashMap::new();
        for dir in self.run_dirs().unwrap_or_default() {
            let Ok(text) = fs::read_to_string(dir.join("record.json")) else {
                continue;
            };
            let Ok(rec) = serde_json::from_str::<Record>(&text) else {
                continue;
            };
            let intact = match &rec.checksum {
                Some(sum) => stored_digest(&text).is_ok_and(|d| d == *sum),
                None => true,
            };
            if !intact
                || rec.format != STUDY_FORMAT_VERSION
                || rec.status != RunStatus::Completed
                || !dir.join(hvi_run::state::STATE_FILE).is_file()
            {
                continue;
            }
            let Some(summary) = read_summary(&dir) else {
                continue;
            };
            let Ok(key) =
                crate::plan::simulation_key(&summary.scene, &rec.tier, &rec.engine_version)
            else {
                continue;
            };
            index.entry(key).or_default().push(Candidate {
                source: Source {
                    fingerprint: rec.fingerprint,
                    dir,
                },
                analysis: summary.scene.analysis,
                simulated: rec.measured_from.is_none(),
            });
        }
        index
    }

    /// The share of the run with this fingerprint (in base steps, 0 to 1) that was done before
    /// this store resumed it from its checkpoint; 0 for a run computed from t = 0 or not here.
    pub fn resumed_share(&self, fingerprint: &str) -> f64 {
        self.resumed
            .lock()
            .ok()
            .and_then(|m| m.get(fingerprint).copied())
            .unwrap_or(0.0)
    }

    /// Runs a job on `threads` worker threads and stores its directory atomically. A failed
    /// simulation (instability, panic) is a record with status `failed`, not an error; errors
    /// are for the store itself (disk, permissions).
    ///
    /// The run is locked while it is computed ([`crate::lock::lock_run`]): when another process
    /// computes it, this waits, and takes that process's completed record instead of running
    /// it again ([`Store::done_elsewhere`] counts those).
    pub fn execute(&self, job: &Job, threads: usize) -> Result<Record> {
        let _claim = crate::lock::lock_run(&self.dir(&job.fingerprint))?;
        if let Some(rec) = self.record(&job.fingerprint)? {
            if rec.is_final() {
                self.elsewhere.fetch_add(1, Ordering::Relaxed);
                return Ok(rec);
            }
        }
        let digits = &job.fingerprint[..DIR_DIGITS.min(job.fingerprint.len())];
        let tmp = self.runs.join(format!(
            ".tmp-{digits}-{}-{}-{}",
            std::process::id(),
            TMP_COUNTER.fetch_add(1, Ordering::Relaxed),
            host_name()
        ));
        if tmp.exists() {
            fs::remove_dir_all(&tmp)?;
        }
        let params = serde_json::Value::Object(job.params.clone());
        let source = self.source_for(job);
        let from = source.as_ref().map_or(String::new(), |s| {
            format!(
                ", measured from the state of run {}",
                &s.fingerprint[..DIR_DIGITS.min(s.fingerprint.len())]
            )
        });
        self.log(&format!(
            "start {digits} on {} process {} with {threads} thread(s){from}: {params}",
            host_name(),
            std::process::id()
        ));
        let t0 = Instant::now();
        let outcome = match &source {
            Some(source) => self.measure_in(job, source, &tmp).or_else(|e| {
                // Nothing is lost: the run is simulated instead.
                log::warn!(
                    "run store: run {digits} could not be measured from {}'s kept state \
                     ({e:#}); simulating it",
                    source.dir.display()
                );
                self.log(&format!(
                    "measuring {digits} failed ({e:#}); simulating it instead"
                ));
                if tmp.exists() {
                    fs::remove_dir_all(&tmp)?;
                }
                self.execute_in(job, threads, &tmp)
            }),
            None => self.execute_in(job, threads, &tmp),
        };
        let wall = t0.elapsed().as_secs_f64();
        self.log(&match &outcome {
            Ok(r) if r.status == RunStatus::Completed && r.measured_from.is_some() => {
                format!("end {digits}: measured in {wall:.1} s")
            }
            Ok(r) if r.status == RunStatus::Completed => {
                format!("end {digits}: completed in {wall:.1} s")
            }
            Ok(r) => format!(
                "end {digits}: FAILED after {wall:.1} s: {}",
                r.error.as_deref().unwrap_or("").replace('\n', " ")
            ),
            Err(e) if hvi_run::interrupt::of(e).is_some() => {
                format!(
                    "end {digits}: stopped by a signal after {wall:.1} s (runs again when resumed)"
                )
            }
            Err(e) => {
                format!("end {digits}: store error after {wall:.1} s: {e:#}").replace('\n', " ")
            }
        });
        if outcome.is_err() {
            // A store error (a full disk, say) or an interrupt: nothing half-written stays.
            let _ = fs::remove_dir_all(&tmp);
        }
        outcome
    }

    /// The study's log ([`LOG_FILE`] beside the run store): one line per run started and
    /// ended, with the time (UTC), appended by every process that runs into this store.
    pub fn log_path(&self) -> PathBuf {
        self.runs
            .parent()
            .map_or_else(|| PathBuf::from(LOG_FILE), |p| p.join(LOG_FILE))
    }

    /// Appends `line` to the study's log, in one write (lines of processes sharing the store
    /// do not interleave). The log is a record for the reader: a run never fails for it.
    fn log(&self, line: &str) {
        use std::io::Write as _;
        let stamped = format!(
            "{} {line}\n",
            humantime::format_rfc3339_seconds(std::time::SystemTime::now())
        );
        if let Ok(mut f) = fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.log_path())
        {
            let _ = f.write_all(stamped.as_bytes());
        }
    }

    /// Runs `job` in the temporary directory `tmp` and moves it into place with its record.
    fn execute_in(&self, job: &Job, threads: usize, tmp: &Path) -> Result<Record> {
        let tmp = tmp.to_path_buf();
        fs::create_dir_all(&tmp)
            .write_context(&tmp, || format!("cannot create {}", tmp.display()))?;
        let t0 = Instant::now();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .build()
            .context("cannot start worker threads")?;
        // Pictures too (cloud_side.png feeds the snapshot matrices): about 1 % of a run.
        let every = self.checkpoint_every;
        let checkpoint = (every != hvi_run::checkpoint::Every::Off).then(|| {
            hvi_run::checkpoint::CheckpointOptions {
                path: self.checkpoint_path(&job.fingerprint),
                every,
            }
        });
        let opts = RunOptions {
            out_dir: tmp.clone(),
            progress: false,
            render: true,
            checkpoint,
            progress_file: true,
            ..RunOptions::default()
        };
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            pool.install(|| {
                run_scene(&job.scene, &opts).map(|o| (o.resumed_from_step, o.sim.derived.steps))
            })
        }));
        let error = self.error_of(job, &tmp, outcome)?;
        // Only a running run has progress to show.
        let _ = fs::remove_file(tmp.join(hvi_run::run::PROGRESS_FILE));
        let summary = read_summary(&tmp);
        let observables = summary
            .as_ref()
            .map(Summary::observables)
            .unwrap_or_default();
        let record = Record::of(
            job,
            error,
            observables,
            t0.elapsed().as_secs_f64(),
            threads.max(1),
        );
        self.seal_and_install(record, &tmp)
    }

    /// What a run's outcome leaves in its record: None when it completed, else its error or
    /// panic in words. A run resumed from its checkpoint is noted; a panic's checkpoint is
    /// removed (it may hold the cause); a run stopped by a signal keeps nothing and returns the
    /// stop as the error.
    fn error_of(
        &self,
        job: &Job,
        tmp: &Path,
        outcome: std::thread::Result<Result<(Option<u64>, u64)>>,
    ) -> Result<Option<Failure>> {
        if let Ok(Ok((Some(step), steps))) = &outcome {
            log::info!(
                "run store: run {} resumed from its checkpoint at base step {step}",
                &job.fingerprint[..DIR_DIGITS.min(job.fingerprint.len())]
            );
            if let Ok(mut m) = self.resumed.lock() {
                m.insert(
                    job.fingerprint.clone(),
                    (*step as f64 / (*steps).max(1) as f64).clamp(0.0, 1.0),
                );
            }
        }
        if outcome.is_err() {
            // A panic: its checkpoint may hold what caused it; the run starts afresh.
            let _ = hvi_run::checkpoint::remove(&self.checkpoint_path(&job.fingerprint));
        }
        if let Ok(Err(e)) = &outcome {
            if let Some(stop) = hvi_run::interrupt::of(e) {
                // Stopped by a signal: nothing of it is kept, and it is not a failure (the
                // study runs it again when resumed).
                let _ = fs::remove_dir_all(tmp);
                return Err(stop.into());
            }
        }
        Ok(match outcome {
            Ok(Ok(_)) => None,
            // The run wrote into the temporary directory; its message names the final one.
            Ok(Err(e)) => Some(Failure {
                message: format!("{e:#}").replace(
                    &tmp.display().to_string(),
                    &self.dir(&job.fingerprint).display().to_string(),
                ),
                reproducible: hvi_run::error::is_reproducible(&e),
            }),
            // A panic is a defect, not the scene's verdict: the run is tried again.
            Err(panic) => Some(Failure {
                message: format!(
                    "panic: {}",
                    panic
                        .downcast_ref::<String>()
                        .cloned()
                        .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_else(|| "(no message)".into())
                ),
                reproducible: false,
            }),
        })
    }

    /// Measures `job` from the kept state of `source` ([`crate::remeasured`]) in the temporary
    /// directory `tmp` and moves it into place with its record.
    fn measure_in(&self, job: &Job, source: &Source, tmp: &Path) -> Result<Record> {
        let t0 = Instant::now();
        let summary =
            crate::remeasured::measure_from(&source.dir, &source.fingerprint, &job.scene, tmp)?;
        let record = Record {
            measured_from: Some(source.fingerprint.clone()),
            ..Record::of(
                job,
                None,
                summary.observables(),
                t0.elapsed().as_secs_f64(),
                1,
            )
        };
        self.seal_and_install(record, tmp)
    }

    /// Seals `record`, writes it last into the run's temporary directory `tmp` and moves the
    /// directory into place.
    fn seal_and_install(&self, record: Record, tmp: &Path) -> Result<Record> {
        let record = record.sealed()?;
        write_atomic_bytes(
            &tmp.join("record.json"),
            serde_json::to_string_pretty(&record)?.as_bytes(),
        )?;
        sync_dir(tmp);
        self.install(tmp, &record.fingerprint)?;
        Ok(record)
    }

    /// Moves a finished temporary directory to its final name, replacing a failed run's.
    fn install(&self, tmp: &Path, fingerprint: &str) -> Result<()> {
        let dest = self.dir(fingerprint);
        if dest.exists() {
            match self.record(fingerprint) {
                // Another process finished the same run first: keep its result.
                Ok(Some(r)) if r.is_final() => {
                    fs::remove_dir_all(tmp)?;
                    return Ok(());
                }
                Ok(_) => {}
                Err(e) => return Err(e),
            }
            let old = self.runs.join(format!(
                ".old-{}-{}-{}-{}",
                &fingerprint[..DIR_DIGITS.min(fingerprint.len())],
                std::process::id(),
                TMP_COUNTER.fetch_add(1, Ordering::Relaxed),
                host_name()
            ));
            fs::rename(&dest, &old)
                .write_context(&old, || format!("cannot move {} aside", dest.display()))?;
            fs::rename(tmp, &dest).write_context(&dest, || {
                format!("cannot move {} into place", dest.display())
            })?;
            sync_dir(&self.runs);
            fs::remove_dir_all(&old)?;
        } else {
            fs::rename(tmp, &dest).write_context(&dest, || {
                format!("cannot move {} to {}", tmp.display(), dest.display())
            })?;
            sync_dir(&self.runs);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_progress_names_judge_only_this_hosts_processes() {
        let me = std::process::id();
        let here = InProgress::parse(PathBuf::from(format!(
            "runs/.tmp-0123456789abcdef-{me}-3-{}",
            host_name()
        )))
        .expect("parses");
        assert_eq!(here.digits, "0123456789abcdef");
        assert_eq!(here.pid, me);
        assert_eq!(here.alive, Some(true));
        // A host name with dashes, a process of another machine: left alone.
        let there = InProgress::parse(PathBuf::from(".tmp-0123456789abcdef-1-0-node-17.cluster"))
            .expect("parses");
        assert_eq!(there.host.as_deref(), Some("node-17.cluster"));
        assert_eq!(there.alive, None);
        // The old naming (no host) is this host's.
        let old =
            InProgress::parse(PathBuf::from(".old-0123456789abcdef-4000000000-0")).expect("parses");
        assert_eq!((old.host, old.alive), (None, Some(false)));
        assert!(InProgress::parse(PathBuf::from("0123456789abcdef")).is_none());
        assert!(InProgress::parse(PathBuf::from(".tmp-x-notapid-0")).is_none());
    }

    #[test]
    fn a_record_of_a_version_with_fewer_observables_keeps_its_checksum() {
        let rec = Record {
            format: STUDY_FORMAT_VERSION,
            fingerprint: "ab".repeat(32),
            study: "s".into(),
            tier: "quick".into(),
            params: serde_json::Map::new(),
            status: RunStatus::Completed,
            error: None,
            reproducible: false,
            observables: Observables::default(),
            wall_seconds: 1.0,
            threads: 1,
            engine_version: "0.6.0".into(),
            measured_from: None,
            checksum: None,
        };
        // As an earlier version wrote it: without an observable this version added, sealed
        // over what it wrote.
        let mut value = serde_json::to_value(&rec).expect("json");
        value["observables"]
            .as_object_mut()
            .expect("observables")
            .remove("length_ratio_side");
        let sum = stored_digest(&value.to_string()).expect("digest");
        value["checksum"] = serde_json::json!(sum);
        let text = value.to_string();
        assert_eq!(stored_digest(&text).expect("digest"), sum);
        // Read back by this version, the record differs from the file (its new observable is
        // null), so only the file's own digest can vouch for it.
        let back: Record = serde_json::from_str(&text).expect("record");
        assert_ne!(back.digest().expect("digest"), sum);
        // An edit is still caught.
        let edited = text.replace("\"wall_seconds\":1.0", "\"wall_seconds\":2.0");
        assert_ne!(edited, text);
        assert_ne!(stored_digest(&edited).expect("digest"), sum);
    }

    #[test]
    fn a_summary_reads_back_typed_with_its_observables() {
        use hvi_analysis::observable::Observable;
        let dir = std::env::temp_dir().join(format!("hvi-store-summary-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        let mut spec = hvi_engine::scene::SceneSpec::calibration(1500.0, 2e-6);
        spec.analysis.track_every = 0;
        let opts = RunOptions {
            out_dir: dir.clone(),
            ..RunOptions::default()
        };
        run_scene(&spec, &opts).expect("runs");
        let summary = read_summary(&dir).expect("typed summary");
        let json: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(dir.join("summary.json")).expect("file"))
                .expect("json");
        let o = summary.observables();
        assert_eq!(o.get(Observable::Particles), json["particles"].as_f64());
        assert_eq!(
            o.get(Observable::Fragmentation),
            json["cloud"]["fragmentation"].as_f64()
        );
        assert_eq!(
            o.get(Observable::FrontVelocityRatio),
            json["cloud"]["front_velocity_ratio"].as_f64()
        );
        let broken =
            json["bonds_broken"].as_f64().expect("n") / json["bonds_initial"].as_f64().expect("n");
        assert_eq!(o.get(Observable::BondsBrokenFraction), Some(broken));
        assert!(o.get(Observable::Tau).is_some());
        let _ = fs::remove_dir_all(&dir);
    }
}
