//! A study's plan executed into its store: the jobs of a plan, their execution, and the
//! results table.
//!
//! study file (`spec`) -> plan (`plan`, `plan.json`) -> runs (`exec`, `store`,
//! `runs/<fingerprint>/`) -> table (`table`, `results.csv`, `results.json`).

use std::path::{Path, PathBuf};

use hvi_run::error::Result;

use crate::exec::{ExecOptions, ExecReport};
use crate::plan::{describe_values, Plan};
use crate::store::{Job, Record, Store};
use crate::table::{results_table, Table};

/// A plan's run as a job for the store.
pub fn job(plan: &Plan, index: usize) -> Result<Job> {
    let run = plan.run(index)?;
    let params = plan
        .axes
        .iter()
        .zip(&run.values)
        // A batch plan's run without a key has `null` there (see `runner::batch_plan`).
        .filter(|(_, v)| !v.is_null())
        .map(|(a, v)| (a.key.clone(), v.clone()))
        .collect();
    Ok(Job {
        fingerprint: run.fingerprint.clone(),
        scene: run.scene.clone(),
        study: plan.study.clone(),
        tier: plan.tier.clone(),
        params,
    })
}

/// Executes every run of a plan whose `plan.json` lives in `dir`, and writes the results
/// table there. Returns the table and what the execution did.
pub fn execute_plan(plan: &Plan, dir: &Path, opts: &ExecOptions) -> Result<(Table, ExecReport)> {
    let store = Store::open(dir)?.with_checkpoint_every(opts.checkpoint_every);
    let jobs: Vec<Job> = (0..plan.runs.len())
        .map(|i| job(plan, i))
        .collect::<Result<_>>()?;
    let describe = |i: usize| describe_values(&plan.axes, &plan.runs[i].values);
    let report = crate::exec::execute(&store, &jobs, &describe, opts)?;
    let records: Vec<Option<Record>> = report.records.iter().cloned().map(Some).collect();
    let table = results_table(plan, &records);
    table.write(dir, "results")?;
    Ok((table, report))
}

/// The default output directory of a study at a tier: `runs/studies/<study>/<tier>` (with
/// `-n<particles>` appended when `--particles` overrides the tier's resolution).
pub fn default_out_dir(study: &str, tier: &str, particles: Option<f64>) -> PathBuf {
    let leaf = match particles {
        Some(n) => format!("{tier}-n{n}"),
        None => tier.to_string(),
    };
    Path::new("runs").join("studies").join(study).join(leaf)
}
