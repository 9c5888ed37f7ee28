//! Studies: a study file expands into a validated plan of runs, the runs execute in parallel
//! through a store that keeps each result once (by fingerprint), and the results become a
//! table, scores and plots.
//!
//! study file (`spec`) -> plan (`plan`, `plan.json`) -> runs (`exec`, `store`,
//! `runs/<fingerprint>/`) -> table (`table`, `results.csv`, `results.json`).

pub mod calibrate;
pub mod cli;
pub mod collect;
pub mod contour;
pub mod exec;
pub mod figures;
pub mod plan;
pub mod plot;
pub mod score;
pub mod slurm;
pub mod snapshots;
pub mod spec;
pub mod stability;
pub mod store;
pub mod table;
pub mod validity;

use std::path::{Path, PathBuf};

use anyhow::Result;

use exec::{ExecOptions, ExecReport};
use plan::{describe_values, Plan};
use store::{Job, Record, Store};
use table::{results_table, Table};

/// A plan's run as a job for the store.
pub fn job_of(plan: &Plan, index: usize) -> Result<Job> {
    let run = plan.run(index)?;
    let params = plan
        .axes
        .iter()
        .zip(&run.values)
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
    let store = Store::open(dir)?;
    let jobs: Vec<Job> = (0..plan.runs.len())
        .map(|i| job_of(plan, i))
        .collect::<Result<_>>()?;
    let describe = |i: usize| describe_values(&plan.axes, &plan.runs[i].values);
    let report = exec::execute(&store, &jobs, &describe, opts)?;
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
