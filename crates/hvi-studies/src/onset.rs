//! The model's fragmentation onset per t/D, found by bisection in v0 through the run store,
//! and held against the experiments' relations (`hvi_analysis::onset`): `onset.csv`,
//! `onset.json` and the curves of the validity map's picture.
//!
//! The onset's definition (docs/model-decisions.md, "The fragmentation onset"): the impactor
//! has fragmented at a v0 when the mean over the seeds of its largest piece anywhere
//! (`impactor_intact_mass_fraction`) is below the threshold (default 0.8). Every t/D is
//! bisected at once, one batch of runs per step (each t/D's next v0 at every seed), so the
//! runs spread over the cores; each run is stored and reused like a map's.
//!
//! The study's optional `[validity.onset]`:
//!
//! ```toml
//! [validity.onset]
//! threshold = 0.8            # fragmented below this intact fraction
//! seeds = [1, 2]             # each v0 runs at every seed; the mean decides
//! v_min_m_s = 1500.0         # the range searched
//! v_max_m_s = 8000.0
//! tolerance_m_s = 100.0      # the bracket's width at which the search stops
//! relations = "../experiments_data/fragmentation-onset.toml"  # default: the shipped file
//! enabled = true
//! ```

use std::path::{Path, PathBuf};

use hvi_run::bail;
use hvi_run::error::{Result, RunError};
use serde::{Deserialize, Serialize};
use serde_json::json;

use hvi_analysis::contour::Point;
use hvi_analysis::observable::Observable;
use hvi_analysis::onset::{compare, range_verdict, Agreement, Bisection, Onset, Relations};
use hvi_run::output::write_atomic_with;
use hvi_store::exec::{execute, ExecOptions};
use hvi_store::plan::{fingerprint, validated_scene, Plan};
use hvi_store::spec::{json_to_override, Study};
use hvi_store::store::{Job, Record, RunStatus, Store};

/// The t/D key the onset is found over.
pub const T_OVER_D: &str = "scene.t_over_d";
/// The impact velocity key it bisects.
pub const V0: &str = "scene.v0_m_s";

fn default_threshold() -> f64 {
    0.8
}
fn default_seeds() -> Vec<u64> {
    vec![1, 2]
}
fn default_v_min() -> f64 {
    1500.0
}
fn default_v_max() -> f64 {
    8000.0
}
fn default_tolerance() -> f64 {
    100.0
}
fn default_true() -> bool {
    true
}

/// `[validity.onset]`.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct OnsetConfig {
    /// The impactor has fragmented below this intact mass fraction.
    #[serde(default = "default_threshold")]
    pub threshold: f64,
    /// The seeds each v0 runs at.
    #[serde(default = "default_seeds")]
    pub seeds: Vec<u64>,
    /// The lowest v0 searched, m/s.
    #[serde(default = "default_v_min")]
    pub v_min_m_s: f64,
    /// The highest v0 searched, m/s.
    #[serde(default = "default_v_max")]
    pub v_max_m_s: f64,
    /// The bracket's width at which the search stops, m/s.
    #[serde(default = "default_tolerance")]
    pub tolerance_m_s: f64,
    /// A relations file (relative to the study file); default the shipped one.
    #[serde(default)]
    pub relations: Option<PathBuf>,
    /// Whether the map finds the onset at all.
    #[serde(default = "default_true")]
    pub enabled: bool,
}

impl Default for OnsetConfig {
    fn default() -> Self {
        OnsetConfig {
            threshold: default_threshold(),
            seeds: default_seeds(),
            v_min_m_s: default_v_min(),
            v_max_m_s: default_v_max(),
            tolerance_m_s: default_tolerance(),
            relations: None,
            enabled: true,
        }
    }
}

impl OnsetConfig {
    /// Checks the values, naming the key and its allowed range.
    pub fn check(&self) -> Result<()> {
        if !(self.threshold > 0.0 && self.threshold < 1.0) {
            bail!(
                "study key `validity.onset.threshold`: {} (allowed: (0, 1), the impactor's \
                 intact mass fraction below which it counts as fragmented)",
                self.threshold
            );
        }
        if self.seeds.is_empty() {
            bail!("study key `validity.onset.seeds`: empty (allowed: one seed or more)");
        }
        Bisection::new(self.v_min_m_s, self.v_max_m_s, self.tolerance_m_s).map_err(|e| {
            RunError::Input(format!(
                "study keys `validity.onset.v_min_m_s`, `v_max_m_s`, `tolerance_m_s`: {e}"
            ))
        })?;
        Ok(())
    }

    /// The relations: the study's file, or the shipped ones.
    pub fn relations(&self, study: &Study) -> Result<Relations> {
        match &self.relations {
            Some(p) => {
                let path = study.path.parent().unwrap_or(Path::new(".")).join(p);
                let text = std::fs::read_to_string(&path).map_err(|e| {
                    RunError::Input(format!(
                        "study key `validity.onset.relations`: cannot read {}: {e}",
                        path.display()
                    ))
                })?;
                Ok(Relations::parse(&text, &path.display().to_string())?)
            }
            None => Ok(Relations::shipped()?),
        }
    }
}

/// One t/D's onset: the model's, each relation's, and how they compare.
#[derive(Debug, Clone, Serialize)]
pub struct OnsetRow {
    /// t/D.
    pub t_over_d: f64,
    /// The model's onset.
    pub model: Onset,
    /// The v0s run, each with the seeds' mean intact fraction.
    pub runs: Vec<(f64, f64)>,
    /// Whether the outcome was monotone in v0 over the runs.
    pub monotone: bool,
    /// Per relation (in the file's order): its onset, m/s, and the comparison.
    pub experiments: Vec<(String, f64, Agreement)>,
    /// The lowest v0 at which the map's F = cut-off line crosses this t/D, m/s.
    pub cutoff_line_m_s: Option<f64>,
}

/// What the onset search found.
#[derive(Debug, Clone, Serialize)]
pub struct OnsetResult {
    /// The settings.
    pub config: OnsetConfig,
    /// One row per t/D, ascending.
    pub rows: Vec<OnsetRow>,
    /// The relations compared against.
    pub relations: Relations,
    /// (range, verdict) per t/D range: thin and thick plates, split at the relations'
    /// branch point.
    pub verdicts: Vec<(String, String)>,
    /// Runs made or reused.
    pub runs: usize,
}

/// The t/D values of a plan: its `scene.t_over_d` axis, else the scene's one value.
pub fn t_values(plan: &Plan) -> Result<Vec<f64>> {
    let mut t: Vec<f64> = match plan.axes.iter().find(|a| a.key == T_OVER_D) {
        Some(a) => a
            .values
            .iter()
            .map(|v| {
                v.as_f64()
                    .ok_or_else(|| RunError::Input(format!("axis `{T_OVER_D}` is not numeric")))
            })
            .collect::<Result<_>>()?,
        None => vec![plan
            .runs
            .first()
            .and_then(|r| r.scene.scene.t_over_d())
            .ok_or_else(|| {
                RunError::Input("the onset needs a sphere-on-plate scene (t/D)".to_string())
            })?],
    };
    t.sort_by(f64::total_cmp);
    t.dedup();
    Ok(t)
}

/// Finds the model's onset at every t/D of `plan` and compares it with the relations.
/// `boundary` is the map's F = cut-off line in (v0 m/s, t/D) for the `cutoff_line_m_s` column.
pub fn find_onsets(
    study: &Study,
    plan: &Plan,
    out: &Path,
    cfg: &OnsetConfig,
    exec: &ExecOptions,
    boundary: &[Vec<Point>],
) -> Result<OnsetResult> {
    cfg.check()?;
    let relations = cfg.relations(study)?;
    let ts = t_values(plan)?;
    let store = Store::open(out)?;
    let mut searches: Vec<Bisection> = ts
        .iter()
        .map(|_| Bisection::new(cfg.v_min_m_s, cfg.v_max_m_s, cfg.tolerance_m_s))
        .collect::<hvi_analysis::error::Result<_>>()?;
    let mut means: Vec<Vec<(f64, f64)>> = vec![Vec::new(); ts.len()];
    let mut runs = 0;
    loop {
        let step: Vec<(usize, f64)> = searches
            .iter()
            .enumerate()
            .filter_map(|(k, b)| b.next().map(|v| (k, v)))
            .collect();
        if step.is_empty() {
            break;
        }
        let jobs = step_jobs(study, plan, &ts, &step, &cfg.seeds)?;
        let describe = |i: usize| describe_job(&jobs[i]);
        let report = execute(&store, &jobs, &describe, exec)?;
        runs += jobs.len();
        for (s, &(k, v)) in step.iter().enumerate() {
            let records = &report.records[s * cfg.seeds.len()..(s + 1) * cfg.seeds.len()];
            let mean = intact_mean(records, ts[k], v)?;
            means[k].push((v, mean));
            searches[k].record(v, mean < cfg.threshold);
        }
    }
    let rows: Vec<OnsetRow> = ts
        .iter()
        .zip(searches.iter().zip(means))
        .map(|(&t, (b, runs))| row(t, b, runs, &relations, boundary))
        .collect::<Result<_>>()?;
    let verdicts = verdicts(&rows, relations.branch_point());
    Ok(OnsetResult {
        config: cfg.clone(),
        rows,
        relations,
        verdicts,
        runs,
    })
}

/// The runs of one bisection step: each (t/D index, v0) at every seed, in that order.
fn step_jobs(
    study: &Study,
    plan: &Plan,
    ts: &[f64],
    step: &[(usize, f64)],
    seeds: &[u64],
) -> Result<Vec<Job>> {
    let mut jobs = Vec::new();
    for &(k, v) in step {
        for &seed in seeds {
            let mut set = plan.set.clone();
            let mut params = serde_json::Map::new();
            for (key, value) in [
                (T_OVER_D, json!(ts[k])),
                (V0, json!(v)),
                ("run.seed", json!(seed)),
            ] {
                set.push(format!("{key}={}", json_to_override(&value)?));
                params.insert(key.into(), value);
            }
            let scene = validated_scene(study, &set)?;
            jobs.push(Job {
                fingerprint: fingerprint(&scene, &plan.tier)?,
                scene,
                study: plan.study.clone(),
                tier: plan.tier.clone(),
                params,
            });
        }
    }
    Ok(jobs)
}

fn describe_job(job: &Job) -> String {
    let p = &job.params;
    format!(
        "onset t/D {} v0 {} seed {}",
        p.get(T_OVER_D).map_or(String::new(), ToString::to_string),
        p.get(V0).map_or(String::new(), ToString::to_string),
        p.get("run.seed").map_or(String::new(), ToString::to_string)
    )
}

/// The seeds' mean intact fraction at (t, v); an error naming the run when one failed.
fn intact_mean(records: &[Record], t: f64, v: f64) -> Result<f64> {
    let mut sum = 0.0;
    for r in records {
        let value = match r.status {
            RunStatus::Completed => r.observables.get(Observable::ImpactorIntactMassFraction),
            _ => None,
        };
        let Some(x) = value else {
            bail!(
                "the onset's run at t/D {t}, v0 {v} m/s has no `{}` ({}): {}",
                Observable::ImpactorIntactMassFraction,
                hvi_store::plan::run_dir_name(&r.fingerprint),
                r.error.clone().unwrap_or_else(|| {
                    "it was stored before this observable existed; run with a fresh \
                     output directory"
                        .into()
                })
            );
        };
        sum += x;
    }
    Ok(sum / records.len() as f64)
}

fn row(
    t: f64,
    b: &Bisection,
    runs: Vec<(f64, f64)>,
    relations: &Relations,
    boundary: &[Vec<Point>],
) -> Result<OnsetRow> {
    let model = b
        .onset()
        .ok_or_else(|| RunError::Input(format!("the onset search at t/D {t} did not finish")))?;
    let experiments = relations
        .relations
        .iter()
        .map(|r| {
            let v = r.onset_m_s(t);
            (r.id.clone(), v, compare(&model, v))
        })
        .collect();
    Ok(OnsetRow {
        t_over_d: t,
        model,
        runs,
        monotone: b.monotone(),
        experiments,
        cutoff_line_m_s: crossing_v0(boundary, t),
    })
}

/// The lowest v0 at which a polyline in (v0, t/D) crosses `t`.
pub fn crossing_v0(lines: &[Vec<Point>], t: f64) -> Option<f64> {
    lines
        .iter()
        .flat_map(|l| l.windows(2))
        .filter_map(|w| {
            let ((x0, y0), (x1, y1)) = (w[0], w[1]);
            let between = (y0 - t) * (y1 - t) <= 0.0 && y0 != y1;
            between.then(|| x0 + (t - y0) / (y1 - y0) * (x1 - x0))
        })
        .min_by(f64::total_cmp)
}

/// The verdict per t/D range: thin plates below the branch point, thick at or above it (one
/// range over all t/D without a branch point).
fn verdicts(rows: &[OnsetRow], split: Option<f64>) -> Vec<(String, String)> {
    let of = |keep: &dyn Fn(f64) -> bool| -> Vec<Agreement> {
        rows.iter()
            .filter(|r| keep(r.t_over_d))
            .flat_map(|r| r.experiments.iter().map(|e| e.2))
            .collect()
    };
    match split {
        Some(s) => vec![
            (
                format!("t/D < {s:.3} (thin plates)"),
                range_verdict(&of(&|t| t < s)),
            ),
            (
                format!("t/D >= {s:.3} (thick plates)"),
                range_verdict(&of(&|t| t >= s)),
            ),
        ],
        None => vec![("every t/D".into(), range_verdict(&of(&|_| true)))],
    }
}

/// Writes `onset.csv` (one row per t/D) and `onset.json` (rows, settings, relations with
/// their sources, verdicts) into `out`.
pub fn write_onset(out: &Path, r: &OnsetResult) -> Result<()> {
    write_atomic_with(&out.join("onset.csv"), |w| {
        write!(
            w,
            "t_over_d,onset_model_m_s,onset_model_lo_m_s,onset_model_hi_m_s,onset_model_kind,seeds,runs,monotone"
        )?;
        for rel in &r.relations.relations {
            write!(
                w,
                ",onset_{0}_m_s,ratio_model_{0},agreement_{0}",
                rel.id.replace('-', "_")
            )?;
        }
        writeln!(w, ",cutoff_line_m_s")?;
        for row in &r.rows {
            let (lo, hi, kind) = match row.model {
                Onset::Between { lo, hi } => (Some(lo), Some(hi), "between"),
                Onset::Below { v } => (None, Some(v), "below"),
                Onset::Above { v } => (Some(v), None, "above"),
            };
            let opt = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x}"));
            write!(
                w,
                "{},{},{},{},{kind},{},{},{}",
                row.t_over_d,
                opt(row.model.estimate_m_s()),
                opt(lo),
                opt(hi),
                r.config.seeds.len(),
                row.runs.len() * r.config.seeds.len(),
                row.monotone
            )?;
            for (_, v, a) in &row.experiments {
                let ratio = row.model.estimate_m_s().map(|m| m / v);
                write!(w, ",{v},{},{}", opt(ratio), a.name())?;
            }
            writeln!(w, ",{}", opt(row.cutoff_line_m_s))?;
        }
        Ok(())
    })?;
    let doc = json!({
        "definition": format!(
            "the impactor has fragmented when the mean over the seeds of `{}` is below {}",
            Observable::ImpactorIntactMassFraction, r.config.threshold
        ),
        "config": r.config,
        "rows": r.rows,
        "relations": r.relations,
        "verdicts": r.verdicts.iter().map(|(k, v)| json!({"range": k, "verdict": v})).collect::<Vec<_>>(),
        "runs": r.runs,
    });
    let text = serde_json::to_string_pretty(&doc)?;
    hvi_run::files::write_atomic_bytes(&out.join("onset.json"), format!("{text}\n").as_bytes())?;
    Ok(())
}

/// The onset table in words, one line per t/D, for the console.
pub fn describe(r: &OnsetResult) -> String {
    let mut s = format!(
        "fragmentation onset (impactor intact fraction < {}, {} seed(s), bisection to {} m/s):\n",
        r.config.threshold,
        r.config.seeds.len(),
        r.config.tolerance_m_s
    );
    for row in &r.rows {
        s.push_str(&format!(
            "  t/D {:<6} model {}",
            row.t_over_d,
            row.model.describe()
        ));
        for ((id, v, a), rel) in row.experiments.iter().zip(&r.relations.relations) {
            let _ = id;
            s.push_str(&format!(
                "; {} {:.2} km/s ({})",
                rel.name,
                v / 1e3,
                a.name()
            ));
        }
        if !row.monotone {
            s.push_str("; not monotone in v0");
        }
        s.push('\n');
    }
    for (range, verdict) in &r.verdicts {
        s.push_str(&format!("  {range}: {verdict}\n"));
    }
    s
}
