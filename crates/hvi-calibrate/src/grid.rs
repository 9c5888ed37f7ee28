//! The calibration's first stage: the runs of the study's grid that its initial design picks
//! ([`crate::design`]), through the store, scored against the targets; `results.csv/json`
//! gain the objective and its terms.

use std::path::Path;

use hvi_analysis::score::{
    combined_objective, combined_targets, objective, Score, Target, Targets,
};
use hvi_run::error::{Result, RunError};
use hvi_store::plan::{describe_values, Plan};
use hvi_store::runner::Runner;
use hvi_store::store::{Job, Record, RunStatus, Store};
use hvi_store::study::job;
use hvi_store::table::{results_table, Table};
use serde_json::Value;

use crate::problem::describe_eval;
use crate::result::EvalStage;
use crate::result::{shot_means, Evaluation};
use crate::CalibrateConfig;
use hvi_store::spec::Study;
use hvi_studies::sweep::print_failures;

/// Scores every row of a results table and adds `objective` and `score_<name>` columns.
pub fn score_table(table: &mut Table, records: &[Record], targets: &Targets) -> Vec<Score> {
    let scores: Vec<Score> = records
        .iter()
        .map(|r| objective(&targets.targets, |name| r.observables.get(name)))
        .collect();
    push_score_columns(table, &scores, &targets.targets);
    scores
}

/// Adds `objective` and a `score_<name>` column per target (in the order of the scores'
/// terms) to a results table.
fn push_score_columns(table: &mut Table, scores: &[Score], targets: &[Target]) {
    let num = |x: f64| {
        if x.is_finite() {
            serde_json::json!(x)
        } else {
            Value::Null
        }
    };
    table.push_column(
        "objective",
        scores.iter().map(|s| num(s.objective)).collect(),
    );
    for (k, t) in targets.iter().enumerate() {
        table.push_column(
            &format!("score_{}", t.name),
            scores.iter().map(|s| num(s.terms[k].term)).collect(),
        );
    }
}

/// The grid stage's outcome.
pub(super) struct Grid {
    /// Runs simulated by this invocation.
    pub(super) ran: usize,
    /// Every grid point as an evaluation, in plan order.
    pub(super) evaluations: Vec<Evaluation>,
    /// The first shot's runs' records, in plan order (what the maps draw).
    pub(super) records: Vec<Record>,
    /// Per grid point, every shot's record, in shot order.
    pub(super) shot_records: Vec<Vec<Record>>,
    /// The point with the lowest objective.
    pub(super) best: usize,
}

/// Stage 1: the grid of every shot (`plans`, the design's points of the study's grid at each
/// shot's impact, the first the study's own), run (or reused) through the store and scored together per grid point;
/// `results.csv/json` (the first shot's runs) and, with several shots, `results-<shot>.csv/json`
/// gain the objective and the terms.
pub(super) fn grid_stage(
    plans: &[&Plan],
    out: &Path,
    runner: &Runner,
    targets: &[Targets],
    progress: bool,
) -> Result<Grid> {
    let plan = plans[0];
    let stored: Vec<Vec<bool>> = plans
        .iter()
        .map(|p| stored_before(p, out))
        .collect::<Result<_>>()?;
    let store = runner.store(out)?;
    let mut jobs: Vec<Job> = Vec::new();
    for p in plans {
        for i in 0..p.runs.len() {
            jobs.push(job(p, i)?);
        }
    }
    let n = plan.runs.len();
    let describe = |i: usize| {
        let shot = &targets[(i / n).min(targets.len() - 1)].shot.id;
        let values = describe_values(&plan.axes, &plan.runs[i % n].values);
        if plans.len() > 1 {
            format!("{shot}: {values}")
        } else {
            values
        }
    };
    let report = runner.execute(&store, out, plan, &jobs, &describe, "grid")?;
    if progress {
        log::info!("grid: {}", report.line());
    }
    print_failures(&report.records);
    let by_shot: Vec<Vec<Record>> = report.records.chunks(n).map(<[Record]>::to_vec).collect();
    let scores: Vec<Score> = (0..n)
        .map(|i| combined_objective(targets, |s, o| by_shot[s][i].observables.get(o)))
        .collect();
    let flat = combined_targets(targets);
    for (s, (p, records)) in plans.iter().zip(&by_shot).enumerate() {
        let mut table = results_table(p, &records.iter().cloned().map(Some).collect::<Vec<_>>());
        push_score_columns(&mut table, &scores, &flat);
        let name = if s == 0 {
            "results".to_string()
        } else {
            format!("results-{}", targets[s].shot.id)
        };
        table.write(out, &name)?;
    }
    let shot_records: Vec<Vec<Record>> = (0..n)
        .map(|i| by_shot.iter().map(|r| r[i].clone()).collect())
        .collect();
    let cached: Vec<bool> = (0..n).map(|i| stored.iter().all(|s| s[i])).collect();
    let evaluations = grid_evaluations(plan, &shot_records, &scores, &cached, targets);
    let best = (0..evaluations.len())
        .filter(|&i| evaluations[i].objective.is_finite())
        .min_by(|&a, &b| {
            evaluations[a]
                .objective
                .total_cmp(&evaluations[b].objective)
        })
        .ok_or_else(|| RunError::Input("no grid run has a score".to_string()))?;
    if progress {
        log::info!(
            "best grid point (run {best}): {}",
            describe_eval(&evaluations[best])
        );
    }
    Ok(Grid {
        ran: report.ran,
        evaluations,
        records: by_shot[0].clone(),
        shot_records,
        best,
    })
}

/// Whether each run of the plan was finished in the store before this invocation.
fn stored_before(plan: &Plan, out: &Path) -> Result<Vec<bool>> {
    let Ok(store) = Store::existing(out) else {
        return Ok(vec![false; plan.runs.len()]);
    };
    Ok(plan
        .runs
        .iter()
        .map(|r| store.holds_finished(&r.fingerprint))
        .collect())
}

/// The grid points as evaluations: their numeric axis values, scores and status (`cached`:
/// every shot's run was in the store before this invocation).
pub(super) fn grid_evaluations(
    plan: &Plan,
    records: &[Vec<Record>],
    scores: &[Score],
    stored: &[bool],
    targets: &[Targets],
) -> Vec<Evaluation> {
    plan.runs
        .iter()
        .zip(records)
        .zip(scores)
        .zip(stored)
        .map(|(((run, recs), score), &cached)| {
            let params = plan
                .axes
                .iter()
                .zip(&run.values)
                .filter_map(|(a, v)| v.as_f64().map(|x| (a.key.clone(), x)))
                .collect();
            let completed = recs.iter().all(|r| r.status == RunStatus::Completed);
            let per_shot: Vec<_> = recs.iter().map(|r| vec![r.observables]).collect();
            Evaluation {
                stage: EvalStage::Grid,
                step: run.index,
                params,
                objective: score.objective,
                score: Some(score.clone()),
                status: if completed { "completed" } else { "failed" }.into(),
                cached,
                dir: Some(run.dir.clone()),
                seeds: Vec::new(),
                seed_objectives: Vec::new(),
                means: shot_means(targets, &per_shot),
            }
        })
        .collect()
}

/// A calibration's grid scored from the store: results.csv/json with the objective and the
/// terms (none for a run without a result; a failed run scores as it does locally).
pub fn collect_calibration(
    plan: &Plan,
    dir: &Path,
    mut table: Table,
    filled: &[Record],
    missing: &[usize],
    quiet: bool,
) -> Result<()> {
    let study = Study::load(&plan.study_file)?;
    let cfg = CalibrateConfig::of(&study)?;
    let targets = cfg.load_targets(&study)?;
    score_table(&mut table, filled, &targets);
    let scored: Vec<usize> = (0..table.columns.len())
        .filter(|&c| table.columns[c] == "objective" || table.columns[c].starts_with("score_"))
        .collect();
    for &i in missing {
        for &c in &scored {
            table.rows[i][c] = Value::Null;
        }
    }
    table.write(dir, "results")?;
    if !quiet {
        log::info!(
            "the grid scored; the refinement runs new simulations one after another: \
             `hvi-study calibrate` does it (locally, or inside one Slurm job), reusing \
             these runs"
        );
    }
    log::info!(target: hvi_run::STDOUT, "{}", dir.join("results.csv").display());
    Ok(())
}
