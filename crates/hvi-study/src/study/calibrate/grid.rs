//! The calibration's first stage: every run of the study's grid, through the store, scored
//! against the targets; `results.csv/json` gain the objective and its terms.

use std::path::Path;

use anyhow::{anyhow, Result};
use hvi_analysis::score::{objective, Score, Targets};
use hvi_run::plan::{describe_values, Plan};
use hvi_run::runner::Runner;
use hvi_run::store::{Job, Record, RunStatus, Store};
use hvi_run::study::job;
use hvi_run::table::{results_table, Table};
use serde_json::Value;

use super::problem::describe_eval;
use super::result::{observed_means, Evaluation};
use crate::study::sweep::print_failures;

/// Scores every row of a results table and adds `objective` and `score_<name>` columns.
pub fn score_table(table: &mut Table, records: &[Record], targets: &Targets) -> Vec<Score> {
    let scores: Vec<Score> = records
        .iter()
        .map(|r| objective(&targets.targets, |name| r.observables.get(name)))
        .collect();
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
    for (k, t) in targets.targets.iter().enumerate() {
        table.push_column(
            &format!("score_{}", t.name),
            scores.iter().map(|s| num(s.terms[k].term)).collect(),
        );
    }
    scores
}

/// The grid stage's outcome.
pub(super) struct Grid {
    /// Runs simulated by this invocation.
    pub(super) ran: usize,
    /// Every grid run as an evaluation, in plan order.
    pub(super) evaluations: Vec<Evaluation>,
    /// The runs' records, in plan order.
    pub(super) records: Vec<Record>,
    /// The run with the lowest objective.
    pub(super) best: usize,
}

/// Stage 1: the grid, run (or reused) through the store and scored; results.csv/json gain the
/// objective and the terms.
pub(super) fn grid_stage(
    plan: &Plan,
    out: &Path,
    runner: &Runner,
    targets: &Targets,
    progress: bool,
) -> Result<Grid> {
    let stored = stored_before(plan, out)?;
    let store = runner.store(out)?;
    let jobs: Vec<Job> = (0..plan.runs.len())
        .map(|i| job(plan, i))
        .collect::<hvi_run::error::Result<_>>()?;
    let describe = |i: usize| describe_values(&plan.axes, &plan.runs[i].values);
    let report = runner.execute(&store, out, plan, &jobs, &describe, "grid")?;
    let mut table = results_table(
        plan,
        &report.records.iter().cloned().map(Some).collect::<Vec<_>>(),
    );
    if progress {
        eprintln!("grid: {}", report.line());
    }
    print_failures(&report.records);
    let scores = score_table(&mut table, &report.records, targets);
    table.write(out, "results")?;
    let evaluations = grid_evaluations(plan, &report.records, &scores, &stored);
    let best = (0..evaluations.len())
        .filter(|&i| evaluations[i].objective.is_finite())
        .min_by(|&a, &b| {
            evaluations[a]
                .objective
                .total_cmp(&evaluations[b].objective)
        })
        .ok_or_else(|| anyhow!("no grid run has a score"))?;
    if progress {
        eprintln!(
            "best grid point (run {best}): {}",
            describe_eval(&evaluations[best])
        );
    }
    Ok(Grid {
        ran: report.ran,
        evaluations,
        records: report.records,
        best,
    })
}

/// Whether each run of the plan was finished in the store before this invocation.
pub(super) fn stored_before(plan: &Plan, out: &Path) -> Result<Vec<bool>> {
    let Ok(store) = Store::existing(out) else {
        return Ok(vec![false; plan.runs.len()]);
    };
    plan.runs
        .iter()
        .map(|r| {
            // A damaged record counts as not stored (the sweep repairs and re-runs it).
            Ok(matches!(store.record(&r.fingerprint),
                Ok(Some(rec)) if rec.status == RunStatus::Completed))
        })
        .collect()
}

/// The grid runs as evaluations: their numeric axis values, scores and status (`cached`: the
/// run was in the store before this invocation).
pub(super) fn grid_evaluations(
    plan: &Plan,
    records: &[Record],
    scores: &[Score],
    stored: &[bool],
) -> Vec<Evaluation> {
    plan.runs
        .iter()
        .zip(records)
        .zip(scores)
        .zip(stored)
        .map(|(((run, rec), score), &cached)| {
            let params = plan
                .axes
                .iter()
                .zip(&run.values)
                .filter_map(|(a, v)| v.as_f64().map(|x| (a.key.clone(), x)))
                .collect();
            Evaluation {
                stage: "grid".into(),
                step: run.index,
                params,
                objective: score.objective,
                score: Some(score.clone()),
                status: match rec.status {
                    RunStatus::Completed => "completed".into(),
                    RunStatus::Failed => "failed".into(),
                },
                cached,
                dir: Some(run.dir.clone()),
                seeds: Vec::new(),
                seed_objectives: Vec::new(),
                means: observed_means(std::slice::from_ref(&rec.observables)),
            }
        })
        .collect()
}
