//! `hvi-study stability`: the stress matrix. Each slice is an ordinary two-axis study
//! (`studies/stability/*.toml`: v0 x t/D, v0 x step, eps x kappa), run through the study store
//! (parallel, cached, resumable); for every cell the map records whether the run completed,
//! its largest energy-ledger drift, its step against the stability bound, and the first sign of
//! trouble the engine reported (`EngineError::Unstable`: the step, the time and what was seen).
//!
//! Writes into the report directory: `<slice>.png` (a cell per run: green to orange by the
//! drift, red where the run stopped), `stability.csv` (every cell) and `stability.md` (per
//! slice: cells, stopped runs, the largest drift, the verdict against the ledger bound).

use hvi_analysis::observable::Observable;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::Serialize;

use crate::cli::{StabilityArgs, StudyArgs};
use hvi_plot::stability_map::{stability_map, MapCell, StabilityMap};
use hvi_run::output::{write_atomic_bytes, write_csv_atomic};
use hvi_run::store::{read_summary, RunStatus, Store};
use hvi_run::study::execute_plan;

/// One cell of the stress matrix.
#[derive(Debug, Clone, Serialize)]
pub struct Cell {
    /// The slice (study name).
    pub slice: String,
    /// First axis key and value.
    pub x_key: String,
    /// First axis value.
    pub x: String,
    /// Second axis key.
    pub y_key: String,
    /// Second axis value.
    pub y: String,
    /// `stable` (completed) or `stopped`.
    pub status: String,
    /// Largest |relative ledger drift| over the run.
    pub max_drift: Option<f64>,
    /// Time step, s.
    pub dt_s: Option<f64>,
    /// Step over the stability bound.
    pub dt_over_bound: Option<f64>,
    /// Bonds broken over bonds at t = 0.
    pub broken_fraction: Option<f64>,
    /// The engine's diagnostic when the run stopped.
    pub trouble: String,
    /// Grid position (column, row).
    #[serde(skip)]
    pub at: (usize, usize),
}

fn default_slices() -> Result<Vec<PathBuf>> {
    let dir = Path::new("studies/stability");
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| {
            format!(
                "cannot list {} (run from the repository root or name the slice files)",
                dir.display()
            )
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("no slice files in {}", dir.display());
    }
    Ok(files)
}

fn value_text(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::Number(n) => n.as_f64().map_or(n.to_string(), |f| {
            format!("{}", hvi_run::spec::round_sig(f, 4))
        }),
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// Runs every slice and writes the maps, the table and the summary. Returns the cells.
pub fn stability(args: &StabilityArgs) -> Result<Vec<Cell>> {
    let slices = if args.studies.is_empty() {
        default_slices()?
    } else {
        args.studies.clone()
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut cells: Vec<Cell> = Vec::new();
    let mut md = String::from("# Stability map\n\n");
    let _ = writeln!(
        md,
        "Each slice is a two-axis study; each cell one run. *stable*: the run reached its end with every guard quiet (no non-finite value, no pair closer than run.min_distance_over_sigma, ledger within run.max_energy_drift); *stopped*: the engine's diagnostic is quoted. The ledger bound this project states is {:.0e}.\n",
        hvi_engine::sim::LEDGER_DRIFT_BOUND
    );
    for file in &slices {
        let stem = file
            .file_stem()
            .map_or("slice".into(), |s| s.to_string_lossy().into_owned());
        let study_args = StudyArgs {
            study: file.clone(),
            tier: args.tier.clone(),
            particles: None,
            sets: Vec::new(),
            out: Some(args.store.join(&stem)),
            threads: args.threads,
            jobs: None,
            quiet: args.quiet,
        };
        let (study, plan, out) = study_args.plan()?;
        if plan.axes.len() != 2 {
            bail!(
                "{}: a stability slice needs exactly 2 axes (has {})",
                file.display(),
                plan.axes.len()
            );
        }
        if !args.quiet {
            eprintln!(
                "stability: slice `{}` ({} runs, tier {})",
                plan.study,
                plan.runs.len(),
                plan.tier
            );
        }
        let (_, report) = execute_plan(&plan, &out, &study_args.exec_options())?;
        let store = Store::open(&out)?;
        let mut slice_cells = Vec::new();
        for (run, rec) in plan.runs.iter().zip(&report.records) {
            let summary = read_summary(&store.dir(&run.fingerprint));
            let num = |pointer: &str| summary.as_ref()?.pointer(pointer)?.as_f64();
            let dt = num("/dt_s");
            let bound = num("/derived/dt_max_s");
            slice_cells.push(Cell {
                slice: plan.study.clone(),
                x_key: plan.axes[0].key.clone(),
                x: value_text(&run.values[0]),
                y_key: plan.axes[1].key.clone(),
                y: value_text(&run.values[1]),
                status: if rec.status == RunStatus::Completed {
                    "stable"
                } else {
                    "stopped"
                }
                .into(),
                max_drift: num("/energy/max_abs_relative_drift"),
                dt_s: dt,
                dt_over_bound: dt.zip(bound).map(|(a, b)| a / b),
                broken_fraction: rec.observables.get(Observable::BondsBrokenFraction),
                trouble: rec.error.clone().unwrap_or_default(),
                at: (run.coords[0], run.coords[1]),
            });
        }
        let x_labels: Vec<String> = plan.axes[0].values.iter().map(value_text).collect();
        let y_labels: Vec<String> = plan.axes[1].values.iter().map(value_text).collect();
        let x_name = plan.axes[0].label.clone();
        let y_name = plan.axes[1].label.clone();
        let map_cells: Vec<MapCell> = slice_cells
            .iter()
            .map(|c| MapCell {
                at: c.at,
                stopped: c.status != "stable",
                max_drift: c.max_drift,
                dt_over_bound: c.dt_over_bound,
            })
            .collect();
        stability_map(
            &args.out.join(format!("{stem}.png")),
            &StabilityMap {
                title: &format!("{} \u{2014} {}", plan.study, study.description),
                subtitle: &plan.tier_description,
                x: (&x_name, &x_labels),
                y: (&y_name, &y_labels),
                cells: &map_cells,
                drift_bound: hvi_engine::sim::LEDGER_DRIFT_BOUND,
            },
        )?;
        let stopped: Vec<&Cell> = slice_cells
            .iter()
            .filter(|c| c.status != "stable")
            .collect();
        let worst = slice_cells
            .iter()
            .filter_map(|c| c.max_drift.map(|d| (d, c)))
            .max_by(|a, b| a.0.total_cmp(&b.0));
        let _ = writeln!(md, "## {} ({})\n", plan.study, study.description);
        let _ = writeln!(
            md,
            "Tier `{}`: {}. Map: `{stem}.png`.\n",
            plan.tier, plan.tier_description
        );
        let _ = writeln!(
            md,
            "- cells: {}; stable: {}; stopped: {}",
            slice_cells.len(),
            slice_cells.len() - stopped.len(),
            stopped.len()
        );
        if let Some((d, c)) = worst {
            let _ = writeln!(
                md,
                "- largest ledger drift: {d:.2e} at {} = {}, {} = {}{}",
                c.x_key,
                c.x,
                c.y_key,
                c.y,
                c.dt_over_bound
                    .map_or(String::new(), |f| format!(" (step {f:.2} of the bound)"))
            );
        }
        let within = slice_cells
            .iter()
            .filter(|c| {
                c.status == "stable"
                    && c.max_drift
                        .is_some_and(|d| d < hvi_engine::sim::LEDGER_DRIFT_BOUND)
            })
            .count();
        let _ = writeln!(
            md,
            "- within the ledger bound {:.0e}: {} of {}",
            hvi_engine::sim::LEDGER_DRIFT_BOUND,
            within,
            slice_cells.len()
        );
        for c in &stopped {
            let _ = writeln!(
                md,
                "- stopped at {} = {}, {} = {}: {}",
                c.x_key, c.x, c.y_key, c.y, c.trouble
            );
        }
        md.push('\n');
        cells.extend(slice_cells);
    }
    write_csv_atomic(&args.out.join("stability.csv"), &cells)?;
    write_atomic_bytes(&args.out.join("stability.md"), md.as_bytes())?;
    Ok(cells)
}
