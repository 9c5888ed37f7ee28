//! `hvi-study reanalyse`: the debris cloud of a study's stored runs measured again from the
//! state each run kept (`state.bin`, [`hvi_run::state`]), with each run's own analysis settings
//! or with others (the quantile, the shadowgraph's pixel and optical depth, the witness plate's
//! standoff), running no simulation ([`hvi_engine::cloud::remeasure`]). The runs' files are
//! read, never written; the table goes into the study directory.

use std::path::{Path, PathBuf};

use hvi_engine::cloud::{remeasure, CloudResult};
use hvi_engine::scene::{Analysis, Width};
use hvi_run::bail;
use hvi_run::error::{Result, ResultExt, RunError};
use hvi_run::run::Summary;
use hvi_store::plan::{describe_values, Plan};
use hvi_store::store::{read_summary, Record, RunStatus, Store};
use hvi_store::table::{num, result_columns, ResultRow, Table};
use serde_json::Value;

/// The `[analysis]` keys a re-analysis may change ([`hvi_engine::scene::MEASUREMENT_KEYS`]);
/// the others (the front times, the track, the pictures) are fixed by what the run kept.
pub use hvi_engine::scene::MEASUREMENT_KEYS as CHANGEABLE_KEYS;

/// The analysis settings a re-analysis changes (`--set analysis.KEY=VALUE`); the rest stays
/// each run's own.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AnalysisChanges {
    /// `analysis.quantile`.
    pub quantile: Option<f64>,
    /// `analysis.width`.
    pub width: Option<Width>,
    /// `analysis.shadowgraph_pixel_m`, m.
    pub shadowgraph_pixel_m: Option<f64>,
    /// `analysis.shadowgraph_blur_m`, m.
    pub shadowgraph_blur_m: Option<f64>,
    /// `analysis.shadowgraph_grain_m`, m.
    pub shadowgraph_grain_m: Option<f64>,
    /// `analysis.shadowgraph_optical_depth`.
    pub shadowgraph_optical_depth: Option<f64>,
    /// `analysis.witness_standoff_m`, m.
    pub witness_standoff_m: Option<f64>,
}

impl AnalysisChanges {
    /// Parses `analysis.KEY=VALUE` overrides and checks each value's range (errors name the
    /// key and say what is allowed).
    pub fn parse(sets: &[String]) -> Result<Self> {
        let mut c = AnalysisChanges::default();
        for set in sets {
            let (key, value) = set.split_once('=').ok_or_else(|| {
                RunError::Input(format!(
                    "--set `{set}`: expected analysis.KEY=VALUE, e.g. analysis.quantile=0.99"
                ))
            })?;
            let key = key.trim();
            if key == "analysis.width" {
                c.width = Some(Width::parse(value.trim().trim_matches('"'))?);
                continue;
            }
            let slot = match key {
                "analysis.quantile" => &mut c.quantile,
                "analysis.shadowgraph_pixel_m" => &mut c.shadowgraph_pixel_m,
                "analysis.shadowgraph_blur_m" => &mut c.shadowgraph_blur_m,
                "analysis.shadowgraph_grain_m" => &mut c.shadowgraph_grain_m,
                "analysis.shadowgraph_optical_depth" => &mut c.shadowgraph_optical_depth,
                "analysis.witness_standoff_m" => &mut c.witness_standoff_m,
                "analysis.front_times_s" => bail!(
                    "--set `{set}`: the front times are those at which the runs kept their \
                     state; changing them needs new runs"
                ),
                _ if !hvi_engine::scene::keys::KEYS.iter().any(|k| k.name == key) => {
                    let hint = hvi_run::scene_file::suggest(key)
                        .filter(|k| CHANGEABLE_KEYS.contains(k))
                        .map_or(String::new(), |k| format!(" (did you mean `{k}`?)"));
                    bail!(
                        "--set `{set}`: unknown key `{key}`{hint}; a re-analysis can change {}",
                        CHANGEABLE_KEYS.join(", ")
                    )
                }
                _ => bail!(
                    "--set `{set}`: `{key}` cannot change in a re-analysis, which runs no \
                     simulation (allowed: {})",
                    CHANGEABLE_KEYS.join(", ")
                ),
            };
            let v: f64 = value.trim().parse().map_err(|_| {
                RunError::Input(format!("--set `{set}`: `{}` is not a number", value.trim()))
            })?;
            *slot = Some(v);
        }
        // The ranges do not depend on the run: check them once, before reading any.
        c.apply(&Analysis::default(), f64::MAX)?;
        Ok(c)
    }

    /// `analysis` with the changes, checked against a run ending at `end_time_s`.
    pub fn apply(&self, analysis: &Analysis, end_time_s: f64) -> Result<Analysis> {
        let mut a = analysis.clone();
        let pairs = [
            (&mut a.quantile, self.quantile),
            (&mut a.shadowgraph_pixel_m, self.shadowgraph_pixel_m),
            (&mut a.shadowgraph_blur_m, self.shadowgraph_blur_m),
            (&mut a.shadowgraph_grain_m, self.shadowgraph_grain_m),
            (
                &mut a.shadowgraph_optical_depth,
                self.shadowgraph_optical_depth,
            ),
            (&mut a.witness_standoff_m, self.witness_standoff_m),
        ];
        for (field, change) in pairs {
            if let Some(v) = change {
                *field = v;
            }
        }
        if let Some(w) = self.width {
            a.width = w;
        }
        a.validate(end_time_s)?;
        Ok(a)
    }
}

/// One run measured again.
#[derive(Debug, Clone)]
pub struct Reanalysis {
    /// The run's summary with its `cloud` measured again; everything else (the scene too) as
    /// the run wrote it.
    pub summary: Summary,
    /// The new measurement, with every fragment and crater.
    pub cloud: CloudResult,
    /// The settings it was measured with.
    pub analysis: Analysis,
}

/// Measures the cloud of the run in `dir` again from its `state.bin`, with the run's analysis
/// settings changed by `changes`; `Ok(None)` when the run kept no state. Errors (an unreadable
/// summary or state file) name the file.
pub fn reanalyse_run(dir: &Path, changes: &AnalysisChanges) -> Result<Option<Reanalysis>> {
    let Some((mut summary, kept)) = hvi_store::remeasured::read_kept(dir)? else {
        return Ok(None);
    };
    let analysis = changes
        .apply(&summary.scene.analysis, summary.scene.run.end_time_s)
        .with_context(|| format!("the run in {}", dir.display()))?;
    let cloud = remeasure(&kept, &analysis);
    summary.cloud = Some(cloud.report.clone());
    Ok(Some(Reanalysis {
        summary,
        cloud,
        analysis,
    }))
}

/// How one run of the store fared.
#[derive(Debug, Clone)]
pub enum Outcome {
    /// Measured again.
    Reanalysed(Box<Reanalysis>),
    /// Completed, but it kept no state (`keep_state_off`: its scene said
    /// `analysis.keep_state = false`).
    NoState {
        /// Whether its scene turned keeping the state off.
        keep_state_off: bool,
    },
    /// Completed, but its state (or summary) could not be read: the error names the file.
    BadState(String),
    /// Failed: nothing to measure.
    Failed,
    /// A plan run without a result in the store.
    Missing,
}

impl Outcome {
    /// The word in the table's `status` column.
    pub fn status(&self) -> &'static str {
        match self {
            Outcome::Reanalysed(_) => "completed",
            Outcome::NoState { .. } => "no_state",
            Outcome::BadState(_) => "bad_state",
            Outcome::Failed => "failed",
            Outcome::Missing => "missing",
        }
    }
}

/// One run of the study: where it is in the plan and the store, and how it fared.
#[derive(Debug, Clone)]
pub struct RunEntry {
    /// Its index in the plan (`None` for a store run the plan does not list, such as a
    /// calibration's refinement).
    pub index: Option<usize>,
    /// Its axis values, one per plan axis.
    pub values: Vec<Value>,
    /// Its fingerprint.
    pub fingerprint: String,
    /// Its directory, relative to the study directory.
    pub dir: String,
    /// Its record, when it has one.
    pub record: Option<Record>,
    /// What the re-analysis made of it.
    pub outcome: Outcome,
}

/// The re-analysis of a study directory.
#[derive(Debug, Clone)]
pub struct StudyReanalysis {
    /// The study directory.
    pub study_dir: PathBuf,
    /// The plan.
    pub plan: Plan,
    /// Every run: the plan's in plan order, then the store's others by directory.
    pub runs: Vec<RunEntry>,
}

/// The study directory's plan: `dir/plan.json`, or `dir` itself when it is a plan file.
fn plan_of(dir: &Path) -> Result<(Plan, PathBuf)> {
    let (path, study_dir) = if dir.is_dir() {
        (dir.join("plan.json"), dir.to_path_buf())
    } else {
        let parent = dir
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or_else(|| Path::new("."));
        (dir.to_path_buf(), parent.to_path_buf())
    };
    if !path.is_file() {
        bail!(
            "{} is not a study directory: it has no plan.json (give the --out of a sweep)",
            dir.display()
        );
    }
    Ok((Plan::load(&path)?, study_dir))
}

/// Measures every completed run of the study in `study_dir` again (see [`reanalyse_run`]).
/// A run without state, or with a state that cannot be read, is an entry saying so, not an
/// error.
pub fn reanalyse_study(study_dir: &Path, changes: &AnalysisChanges) -> Result<StudyReanalysis> {
    let (plan, study_dir) = plan_of(study_dir)?;
    let store = Store::existing(&study_dir)?;
    let mut runs: Vec<RunEntry> = Vec::new();
    for run in &plan.runs {
        runs.push(RunEntry {
            index: Some(run.index),
            values: run.values.clone(),
            fingerprint: run.fingerprint.clone(),
            dir: run.dir.clone(),
            record: store.record(&run.fingerprint)?,
            outcome: Outcome::Missing,
        });
    }
    for dir in store.run_dirs()? {
        let name = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let rel = format!("runs/{name}");
        if runs.iter().any(|r| r.dir == rel) {
            continue;
        }
        let path = dir.join("record.json");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let rec: Record = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a run record", path.display()))?;
        let record = store.record(&rec.fingerprint)?;
        runs.push(RunEntry {
            index: None,
            values: plan
                .axes
                .iter()
                .map(|a| rec.params.get(&a.key).cloned().unwrap_or(Value::Null))
                .collect(),
            fingerprint: rec.fingerprint.clone(),
            dir: rel,
            record,
            outcome: Outcome::Missing,
        });
    }
    for entry in &mut runs {
        entry.outcome = match &entry.record {
            None => Outcome::Missing,
            Some(r) if r.status != RunStatus::Completed => Outcome::Failed,
            Some(_) => {
                let dir = study_dir.join(&entry.dir);
                match reanalyse_run(&dir, changes) {
                    Ok(Some(r)) => Outcome::Reanalysed(Box::new(r)),
                    Ok(None) => Outcome::NoState {
                        keep_state_off: read_summary(&dir)
                            .is_some_and(|s| !s.scene.analysis.keep_state),
                    },
                    Err(e) => Outcome::BadState(format!("{e:#}")),
                }
            }
        };
    }
    Ok(StudyReanalysis {
        study_dir,
        plan,
        runs,
    })
}

/// The settings columns the re-analysis table adds after the results columns.
pub const SETTINGS_COLUMNS: [&str; 7] = [
    "analysis_quantile",
    "analysis_width",
    "analysis_shadowgraph_pixel_m",
    "analysis_shadowgraph_blur_m",
    "analysis_shadowgraph_grain_m",
    "analysis_shadowgraph_optical_depth",
    "analysis_witness_standoff_m",
];

impl StudyReanalysis {
    /// The table: `results.csv`'s columns (the observables measured again; the run's own
    /// where the cloud does not enter, e.g. the energy drift), then the settings each run was
    /// measured with ([`SETTINGS_COLUMNS`]).
    pub fn table(&self) -> Table {
        let mut columns = result_columns(&self.plan.axes);
        columns.extend(SETTINGS_COLUMNS.map(String::from));
        let rows = self
            .runs
            .iter()
            .map(|e| {
                let re = match &e.outcome {
                    Outcome::Reanalysed(r) => Some(r),
                    _ => None,
                };
                let observables = re.map(|r| r.summary.observables());
                let error = match &e.outcome {
                    Outcome::NoState { .. } => {
                        Some("no state: rerun it with a current version".into())
                    }
                    Outcome::BadState(msg) => Some(msg.clone()),
                    _ => e.record.as_ref().and_then(|r| r.error.clone()),
                };
                let mut cells = ResultRow {
                    index: e.index,
                    values: &e.values,
                    status: e.outcome.status(),
                    fingerprint: &e.fingerprint,
                    dir: &e.dir,
                    observables: observables.as_ref(),
                    wall_seconds: e.record.as_ref().map(|r| r.wall_seconds),
                    measured_from: e.record.as_ref().and_then(|r| r.measured_from.as_deref()),
                    error: error.as_deref(),
                }
                .cells();
                let a = re.map(|r| &r.analysis);
                cells.extend([
                    num(a.map(|a| a.quantile)),
                    a.map_or(Value::Null, |a| Value::from(a.width.name())),
                    num(a.map(|a| a.shadowgraph_pixel_m)),
                    num(a.map(|a| a.shadowgraph_blur_m)),
                    num(a.map(|a| a.shadowgraph_grain_m)),
                    num(a.map(|a| a.shadowgraph_optical_depth)),
                    num(a.map(|a| a.witness_standoff_m)),
                ]);
                cells
            })
            .collect();
        Table { columns, rows }
    }

    /// One line per run that was not measured again although it completed, saying why.
    pub fn problems(&self) -> Vec<String> {
        self.runs
            .iter()
            .filter_map(|e| {
                let what = describe_values(&self.plan.axes, &e.values);
                match &e.outcome {
                    Outcome::NoState { keep_state_off } => {
                        let off = *keep_state_off;
                        Some(format!(
                            "run {} ({what}) has no state: rerun it with a current version \
                             (remove its directory and run the study again: the store reuses \
                             it as it is){}",
                            e.dir,
                            if off {
                                "; its scene has analysis.keep_state = false"
                            } else {
                                ""
                            }
                        ))
                    }
                    Outcome::BadState(msg) => Some(format!("run {} ({what}): {msg}", e.dir)),
                    _ => None,
                }
            })
            .collect()
    }

    /// (measured again, without state, with a bad state, failed, missing).
    pub fn counts(&self) -> (usize, usize, usize, usize, usize) {
        let mut c = (0, 0, 0, 0, 0);
        for e in &self.runs {
            match e.outcome {
                Outcome::Reanalysed(_) => c.0 += 1,
                Outcome::NoState { .. } => c.1 += 1,
                Outcome::BadState(_) => c.2 += 1,
                Outcome::Failed => c.3 += 1,
                Outcome::Missing => c.4 += 1,
            }
        }
        c
    }
}

/// What `reanalyse` measures again and where the table goes.
#[derive(Debug, Clone)]
pub struct ReanalyseOptions {
    /// The study directory (the --out of a sweep: plan.json and runs/), or its plan.json.
    pub study_dir: PathBuf,
    /// Another analysis setting, `analysis.KEY=VALUE` (empty: each run's own).
    pub sets: Vec<String>,
    /// The table's name in the study directory: NAME.csv and NAME.json.
    pub table: String,
    /// No progress output (runs that cannot be measured are still listed).
    pub quiet: bool,
}

/// `hvi-study reanalyse`: writes `<table>.csv` / `<table>.json` into the study directory and
/// prints the CSV's path. Runs without state are listed on stderr and skipped; when a state
/// file cannot be read the table is still written and the command then fails, naming it.
pub fn reanalyse(args: &ReanalyseOptions) -> Result<()> {
    let stem = args.table.as_str();
    if stem.is_empty() || stem.contains(['/', '\\']) || stem.starts_with('.') || stem == "results" {
        bail!(
            "invalid value for `--table`: `{stem}` (allowed: a file name without directory, \
             not `results`)"
        );
    }
    let changes = AnalysisChanges::parse(&args.sets)?;
    let done = reanalyse_study(&args.study_dir, &changes)?;
    let study_dir = &done.study_dir;
    done.table().write(study_dir, stem)?;
    let problems = done.problems();
    for p in &problems {
        log::info!("{p}");
    }
    let (ok, no_state, bad, failed, missing) = done.counts();
    if !args.quiet {
        log::info!(
            "reanalysed {ok} of {} completed runs ({no_state} without state, {bad} with an \
             unreadable state); {failed} failed and {missing} missing runs have nothing to \
             measure",
            ok + no_state + bad
        );
    }
    log::info!(target: hvi_run::STDOUT, "{}", study_dir.join(format!("{stem}.csv")).display());
    if bad > 0 {
        bail!(
            "{bad} run(s) could not be measured again (status `bad_state` in {stem}.csv): {}",
            done.runs
                .iter()
                .find_map(|e| match &e.outcome {
                    Outcome::BadState(m) => Some(m.as_str()),
                    _ => None,
                })
                .unwrap_or_default()
        );
    }
    Ok(())
}
