//! The calibration's problem: a point of the searched parameters becomes a run of each shot
//! through the store (at the shot's impact and the study's other settings), and the runs are
//! scored together against the shots' targets. The grid, the searches and the paper's point all
//! evaluate through it.

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::Path;

use hvi_analysis::observable::Observable;
use hvi_analysis::score::{combined_objective, Score, Targets, MISSING_TERM};
use hvi_run::bail;
use hvi_run::error::{Result, RunError};
use hvi_store::plan::{fingerprint, validated_scene, Plan};
use hvi_store::runner::Runner;
use hvi_store::spec::{json_to_override, round_sig, Study};
use hvi_store::store::{Job, Record, RunStatus, Store};
use serde_json::Value;

use crate::config::CalibrateConfig;
pub use crate::result::fmt_term;
use crate::result::EvalStage;
use crate::result::{shot_means, Evaluation};
use crate::screen::Screen;

/// The cost of a point outside the grid's box or with an invalid scene (no run is made).
pub const OUTSIDE_COST: f64 = 10.0 * MISSING_TERM;

/// The paper's best fit (Figs. 11-12): eps = 0.01 J, kappa = 4.56e6 N/m, rcut = 1.5 sigma.
pub const PAPER_BEST: [(&str, f64); 3] = [
    ("material.eps_j", hvi_engine::paper::BEST_EPS_J),
    ("material.kappa_n_m", hvi_engine::paper::BEST_KAPPA_N_M),
    (
        "material.rcut_over_sigma",
        hvi_engine::paper::BEST_RCUT_OVER_SIGMA,
    ),
];

/// The numeric value of a JSON axis value.
pub(super) fn as_num(v: &Value, key: &str) -> Result<f64> {
    v.as_f64().ok_or_else(|| {
        RunError::Input(format!(
            "axis `{key}`: value {v} is not a number (calibrate needs numbers)"
        ))
    })
}

/// The refinement's problem: parameters in transformed coordinates -> objective, each point a
/// run through the store.
pub struct Refinement<'a> {
    pub(super) study: &'a Study,
    /// The study's plan (the first shot's), which names the study and tier of every run.
    pub(super) plan: &'a Plan,
    pub(super) store: &'a Store,
    /// Each shot's targets, in order (the first is the plan's shot).
    pub(super) targets: &'a [Targets],
    /// Per shot, the fixed overrides: its plan's common ones (its impact among them) plus the
    /// non-refined axes at the best point.
    pub(super) fixed: Vec<Vec<String>>,
    /// Refined keys, whether each is in log10, and the box in transformed coordinates.
    pub(super) dims: Vec<Dim>,
    pub(super) threads: usize,
    /// Where batches of runs execute (here or as Slurm job arrays).
    pub(super) runner: &'a Runner,
    /// The study directory (the store's, and the Slurm submissions').
    pub(super) out: &'a Path,
    pub(super) progress: bool,
    pub(super) log: RefCell<Vec<Evaluation>>,
    pub(super) ran: RefCell<usize>,
    /// The screen of the runs it makes.
    pub(super) screen: &'a Screen,
}

impl Refinement<'_> {
    /// Parameter values (by key) of a point in the search's coordinates.
    pub(super) fn values(&self, x: &[f64]) -> BTreeMap<String, f64> {
        self.values_in(&self.dims, x)
    }

    /// Parameter values (by key) of a point in the coordinates of `dims`.
    pub(super) fn values_in(&self, dims: &[Dim], x: &[f64]) -> BTreeMap<String, f64> {
        dims.iter()
            .zip(x)
            .map(|(Dim { key: k, log, .. }, &u)| {
                let v = if *log { 10f64.powf(u) } else { u };
                (k.clone(), round_sig(v, 6))
            })
            .collect()
    }

    /// The combined score of observables per shot (`observable(s, o)`: shot s's value of o).
    pub(super) fn score(&self, observable: impl Fn(usize, Observable) -> Option<f64>) -> Score {
        combined_objective(self.targets, observable)
    }

    /// The runs of a parameter point (by key), one per shot in order, at `seed` (None: the
    /// scene's), each or why there is none (its scene is invalid).
    pub(super) fn jobs(
        &self,
        params: &BTreeMap<String, f64>,
        seed: Option<u64>,
    ) -> Result<Vec<std::result::Result<Job, String>>> {
        (0..self.fixed.len())
            .map(|shot| self.job(shot, params, seed))
            .collect()
    }

    /// Why a parameter point makes no valid scene for some shot (None: valid for all).
    pub(super) fn invalid(&self, params: &BTreeMap<String, f64>) -> Result<Option<String>> {
        Ok(self
            .jobs(params, None)?
            .into_iter()
            .find_map(std::result::Result::err))
    }

    /// The run of shot `shot` at a parameter point (by key), at `seed` (None: the scene's), or
    /// why there is none (its scene is invalid).
    fn job(
        &self,
        shot: usize,
        params: &BTreeMap<String, f64>,
        seed: Option<u64>,
    ) -> Result<std::result::Result<Job, String>> {
        let mut set = self.fixed[shot].clone();
        for (k, v) in params {
            set.push(format!("{k}={}", json_to_override(&serde_json::json!(v))?));
        }
        let mut job_params: serde_json::Map<String, Value> = params
            .iter()
            .map(|(k, v)| (k.clone(), serde_json::json!(v)))
            .collect();
        if let Some(seed) = seed {
            set.push(format!("run.seed={seed}"));
            job_params.insert("run.seed".into(), serde_json::json!(seed));
        }
        let scene = match validated_scene(self.study, &set) {
            Ok(s) => s,
            Err(e) => return Ok(Err(format!("invalid scene: {e:#}"))),
        };
        let job = Job {
            fingerprint: fingerprint(&scene, &self.plan.tier)?,
            scene,
            study: self.plan.study.clone(),
            tier: self.plan.tier.clone(),
            params: job_params,
        };
        Ok(Ok(self.screen.apply(shot, job, self.store)?))
    }

    /// Evaluates a parameter point (by key) at the scene's seed, running each shot's run the
    /// store lacks.
    pub(super) fn evaluate(
        &self,
        stage: EvalStage,
        params: &BTreeMap<String, f64>,
    ) -> Result<Evaluation> {
        let step = self
            .log
            .borrow()
            .iter()
            .filter(|e| e.stage == stage)
            .count();
        let mut jobs = Vec::new();
        for job in self.jobs(params, None)? {
            match job {
                Ok(job) => jobs.push(job),
                Err(why) => return Ok(outside(stage, step, params, why)),
            }
        }
        let mut records = Vec::new();
        let mut cached = true;
        for job in &jobs {
            let (record, hit) = self.record_of(stage, params, job)?;
            cached &= hit;
            records.push(record);
        }
        let completed = records.iter().all(|r| r.status == RunStatus::Completed);
        let score = self.score(|s, o| records[s].observables.get(o));
        let failed: Vec<String> = records
            .iter()
            .filter(|r| r.status != RunStatus::Completed)
            .map(|r| r.error.clone().unwrap_or_else(|| "(no message)".into()))
            .collect();
        let per_shot: Vec<_> = records.iter().map(|r| vec![r.observables]).collect();
        Ok(Evaluation {
            stage,
            step,
            params: params.clone(),
            objective: score.objective,
            score: Some(score),
            status: if completed {
                "completed".into()
            } else {
                format!("failed: {}", failed.join("; "))
            },
            cached,
            dir: Some(hvi_store::plan::run_dir_name(&jobs[0].fingerprint)),
            seeds: Vec::new(),
            seed_objectives: Vec::new(),
            means: shot_means(self.targets, &per_shot),
        })
    }

    /// A run's record from the store, or run (here or on Slurm); whether it was stored.
    fn record_of(
        &self,
        stage: EvalStage,
        params: &BTreeMap<String, f64>,
        job: &Job,
    ) -> Result<(Record, bool)> {
        if let Some(r) = self.store.record(&job.fingerprint)? {
            if r.status == RunStatus::Completed {
                return Ok((r, true));
            }
        }
        let record =
            match self.runner {
                Runner::Local(_) => self.store.execute(job, self.threads)?,
                Runner::Slurm(_) => {
                    let describe = |_: usize| fmt_params(params);
                    let report = self.runner.execute(
                        self.store,
                        self.out,
                        self.plan,
                        std::slice::from_ref(job),
                        &describe,
                        &stage.to_string(),
                    )?;
                    report.records.into_iter().next().ok_or_else(|| {
                        RunError::Input(format!("the run of {stage} has no record"))
                    })?
                }
            };
        // A run measured from another's kept state is no simulation.
        if record.measured_from.is_none() {
            *self.ran.borrow_mut() += 1;
        }
        Ok((record, false))
    }
}

/// A point that is not run: outside the box, or a scene the engine rejects (`status` says
/// which).
fn outside(
    stage: EvalStage,
    step: usize,
    params: &BTreeMap<String, f64>,
    status: String,
) -> Evaluation {
    Evaluation {
        stage,
        step,
        params: params.clone(),
        score: None,
        objective: OUTSIDE_COST,
        status,
        cached: false,
        dir: None,
        seeds: Vec::new(),
        seed_objectives: Vec::new(),
        means: BTreeMap::new(),
    }
}

/// Parameters as `key = value` pairs for the report and the log.
pub fn fmt_params(p: &BTreeMap<String, f64>) -> String {
    p.iter()
        .map(|(k, v)| format!("{}={v:.4e}", k.rsplit('.').next().unwrap_or(k)))
        .collect::<Vec<_>>()
        .join(", ")
}

pub(super) fn describe_eval(e: &Evaluation) -> String {
    let mut s = format!("{}  J = {:.4}", fmt_params(&e.params), e.objective);
    if let Some(score) = &e.score {
        for t in &score.terms {
            s.push_str(&format!(
                "\n      {:<18} observed {:>12}  term {} (weight {})",
                t.name,
                t.observed.map_or("n/a".to_string(), |v| format!("{v:.4e}")),
                fmt_term(t),
                t.weight
            ));
        }
    }
    s
}

/// A refined axis and the grid's box on it, in the coordinates the search moves in.
#[derive(Debug, Clone, PartialEq)]
pub struct Dim {
    /// The axis's scene key.
    pub key: String,
    /// Refined in log10 of the value (else in the value).
    pub log: bool,
    /// The box's lowest coordinate.
    pub lo: f64,
    /// The box's highest coordinate.
    pub hi: f64,
}

impl Dim {
    /// The axis `key` over the box [lo, hi] in its coordinates (log10 when `log`).
    pub fn new(key: &str, log: bool, lo: f64, hi: f64) -> Self {
        Dim {
            key: key.to_string(),
            log,
            lo,
            hi,
        }
    }
}

/// The axes the refinement moves (`calibrate.refine`, default every axis with more than one
/// value) and their coordinates.
pub fn refined_axes(plan: &Plan, cfg: &CalibrateConfig) -> Result<(Vec<String>, Vec<Dim>)> {
    let refine_keys: Vec<String> = match &cfg.refine {
        Some(k) => k.clone(),
        None => plan
            .axes
            .iter()
            .filter(|a| a.values.len() > 1)
            .map(|a| a.key.clone())
            .collect(),
    };
    let mut dims = Vec::new();
    for k in &refine_keys {
        let axis = plan.axes.iter().find(|a| &a.key == k).ok_or_else(|| {
            RunError::Input(format!(
                "study key `calibrate.refine`: `{k}` is not an axis"
            ))
        })?;
        let log = cfg.log_axes.contains(k);
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for v in &axis.values {
            let x = as_num(v, k)?;
            if log && x <= 0.0 {
                bail!("axis `{k}` is refined in log10 but has the value {x} <= 0");
            }
            let u = if log { x.log10() } else { x };
            lo = lo.min(u);
            hi = hi.max(u);
        }
        dims.push(Dim {
            key: k.clone(),
            log,
            lo,
            hi,
        });
    }
    Ok((refine_keys, dims))
}

/// What the stages after the grid share: where runs go and how they are scored.
pub struct Stage<'a> {
    /// The study.
    pub study: &'a Study,
    /// The study's plan (the first shot's).
    pub plan: &'a Plan,
    /// Each shot's plan: the study's grid at its impact.
    pub plans: &'a [&'a Plan],
    /// The run store.
    pub store: &'a Store,
    /// Each shot's targets.
    pub targets: &'a [Targets],
    /// Threads for the runs.
    pub threads: usize,
    /// Where the runs execute (here, or Slurm).
    pub runner: &'a Runner,
    /// The study directory.
    pub out: &'a Path,
    /// Progress on the log.
    pub progress: bool,
    /// The screen of the runs it makes ([`Screen::off`]: every run in full).
    pub screen: &'a Screen,
}

impl<'a> Stage<'a> {
    /// A problem over `dims` with the other scene keys at `fixed` (per shot).
    pub fn problem(&self, fixed: Vec<Vec<String>>, dims: Vec<Dim>) -> Refinement<'a> {
        Refinement {
            study: self.study,
            plan: self.plan,
            store: self.store,
            targets: self.targets,
            fixed,
            dims,
            threads: self.threads,
            runner: self.runner,
            out: self.out,
            progress: self.progress,
            log: RefCell::new(Vec::new()),
            ran: RefCell::new(0),
            screen: self.screen,
        }
    }
}

/// Per shot, its plan's common overrides plus every axis at the best run's value, except the
/// axes `moved` names (those the stage sets itself).
pub fn fixed_overrides(
    plans: &[&Plan],
    best_values: &[Value],
    moved: impl Fn(&String) -> bool,
) -> Result<Vec<Vec<String>>> {
    plans
        .iter()
        .map(|plan| {
            let mut fixed = plan.set.clone();
            for (a, v) in plan.axes.iter().zip(best_values) {
                if !moved(&a.key) {
                    fixed.push(format!("{}={}", a.key, json_to_override(v)?));
                }
            }
            Ok(fixed)
        })
        .collect()
}

/// The best scored point over the best grid point and the refinement.
pub(super) fn best_of(best_grid: &Evaluation, refinement: &[Evaluation]) -> Evaluation {
    std::iter::once(best_grid)
        .chain(refinement)
        .filter(|e| e.score.is_some() && e.objective.is_finite())
        .min_by(|a, b| a.objective.total_cmp(&b.objective))
        .cloned()
        .unwrap_or_else(|| best_grid.clone())
}

/// Particles of a run, read from its record in the study directory.
pub(super) fn particles_of(out: &Path, e: &Evaluation) -> Option<f64> {
    e.dir
        .as_ref()
        .and_then(|d| {
            std::fs::read_to_string(out.join(d).join("record.json"))
                .ok()
                .and_then(|t| serde_json::from_str::<Record>(&t).ok())
        })
        .and_then(|r| r.observables.get(Observable::Particles))
}
