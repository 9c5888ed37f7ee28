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
use plotters::prelude::*;
use serde::Serialize;

use crate::cli::{StabilityArgs, StudyArgs};
use hvi_plot::render::{fonts, write_png, FAMILY};
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
        map_plot(
            &args.out.join(format!("{stem}.png")),
            &format!("{} \u{2014} {}", plan.study, study.description),
            &plan.tier_description,
            (&x_name, &x_labels),
            (&y_name, &y_labels),
            &slice_cells,
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

/// Colour of a stable cell by its drift: green (1e-7 or less) to orange (the ledger bound).
fn drift_color(d: f64) -> RGBColor {
    let lo = -7.0;
    let hi = hvi_engine::sim::LEDGER_DRIFT_BOUND.log10();
    let t = ((d.max(1e-300).log10() - lo) / (hi - lo)).clamp(0.0, 1.0);
    let (a, b) = ([120.0, 200.0, 120.0], [245.0, 160.0, 40.0]);
    let c = |k: usize| (a[k] + (b[k] - a[k]) * t) as u8;
    RGBColor(c(0), c(1), c(2))
}

fn map_plot(
    path: &Path,
    title: &str,
    subtitle: &str,
    x: (&str, &[String]),
    y: (&str, &[String]),
    cells: &[Cell],
) -> Result<()> {
    fonts()?;
    let (w, h) = (1300u32, 900u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        let (nx, ny) = (x.1.len(), y.1.len());
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FAMILY, 22))
            .margin(20)
            .x_label_area_size(60)
            .y_label_area_size(90)
            .build_cartesian_2d(0.0..nx as f64, 0.0..ny as f64)?;
        let xl = x.1.to_vec();
        let yl = y.1.to_vec();
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(nx * 2 + 1)
            .y_labels(ny * 2 + 1)
            .x_desc(x.0)
            .y_desc(y.0)
            .label_style((FAMILY, 16))
            .axis_desc_style((FAMILY, 18))
            .x_label_formatter(&|v| {
                let k = (v - 0.5).round();
                if (v - 0.5 - k).abs() < 1e-6 && k >= 0.0 {
                    xl.get(k as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .y_label_formatter(&|v| {
                let k = (v - 0.5).round();
                if (v - 0.5 - k).abs() < 1e-6 && k >= 0.0 {
                    yl.get(k as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .draw()?;
        for c in cells {
            let (x0, y0) = (c.at.0 as f64, c.at.1 as f64);
            let fill = if c.status == "stable" {
                c.max_drift.map_or(RGBColor(200, 200, 200), drift_color)
            } else {
                RGBColor(210, 40, 40)
            };
            chart.draw_series(std::iter::once(Rectangle::new(
                [(x0 + 0.03, y0 + 0.03), (x0 + 0.97, y0 + 0.97)],
                fill.filled(),
            )))?;
            let line1 = if c.status == "stable" {
                c.max_drift.map_or("-".into(), |d| format!("{d:.0e}"))
            } else {
                "stopped".into()
            };
            let line2 = c
                .dt_over_bound
                .map_or(String::new(), |f| format!("dt {f:.2}"));
            for (k, text) in [line1, line2].into_iter().enumerate() {
                chart.draw_series(std::iter::once(Text::new(
                    text,
                    (x0 + 0.12, y0 + 0.68 - 0.3 * k as f64),
                    (FAMILY, 14).into_font().color(&BLACK),
                )))?;
            }
        }
        root.draw(&Text::new(
            format!(
                "{subtitle}. Cell: largest ledger drift, step / stability bound; red = stopped."
            ),
            (20, h as i32 - 22),
            (FAMILY, 14).into_font().color(&RGBColor(60, 60, 60)),
        ))?;
        root.present()?;
    }
    write_png(path, &rgb, w, h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drift_colours_run_green_to_orange() {
        assert_eq!(drift_color(1e-9), RGBColor(120, 200, 120));
        assert_eq!(drift_color(1.0), RGBColor(245, 160, 40));
        let mid = drift_color(1e-5);
        assert!(mid.0 > 120 && mid.0 < 245);
    }
}
