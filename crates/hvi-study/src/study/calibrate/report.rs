//! What a calibration writes: `calibration.json`, `calibration.md`, `evaluations.csv`,
//! `surrogate.csv`, the maps and the snapshot matrix, and the console's report.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use hvi_analysis::observable::Observable;
use hvi_analysis::score::objective;
use hvi_run::output::{write_atomic, write_atomic_bytes};
use hvi_run::plan::Plan;
use hvi_run::store::Record;

use super::problem::describe_eval;
use super::result::{CalibrationResult, Evaluation, Surface};

/// The maps and the snapshot matrix; a figure that cannot be drawn is reported, not fatal.
pub(super) fn draw_figures(
    out: &Path,
    plan: &Plan,
    records: &[Record],
    result: &CalibrationResult,
    log_axes: &[String],
    progress: bool,
) {
    match crate::study::figures::calibration_maps(out, plan, records, result, log_axes) {
        Ok(stems) if progress => {
            for s in stems {
                eprintln!("plot: {} (and .svg)", s.with_extension("png").display());
            }
        }
        Ok(_) => {}
        Err(e) => eprintln!("no maps drawn: {e:#}"),
    }
    match calibration_snapshots(out, plan, records, result) {
        Ok(path) if progress => eprintln!("snapshots: {}", path.display()),
        Ok(_) => {}
        Err(e) => eprintln!("no snapshot matrix: {e:#}"),
    }
}

/// The verdict of a calibration in one line: converged or not, and why.
pub(super) fn verdict_line(r: &CalibrationResult) -> String {
    let state = match (r.method.as_str(), r.converged) {
        ("none", _) => "GRID ONLY",
        (_, true) => "CONVERGED",
        (_, false) => "NOT CONVERGED",
    };
    format!("{state} ({}): {}", r.method, r.termination)
}

/// The confidence region as one line per parameter: `key in [lo, hi]` (with a note where it
/// reaches the searched box's edge).
pub(super) fn interval_lines(r: &CalibrationResult) -> Vec<String> {
    let Some(region) = &r.region else {
        return Vec::new();
    };
    region
        .intervals
        .iter()
        .map(|(k, (lo, hi))| {
            let edge = if region.at_boundary.get(k).copied().unwrap_or(false) {
                " (reaches the searched box's edge: the interval may be wider)"
            } else {
                ""
            };
            format!(
                "{k} in [{lo:.4e}, {hi:.4e}], best {:.4e}{edge}",
                r.best.params.get(k).copied().unwrap_or(f64::NAN)
            )
        })
        .collect()
}

/// The human-readable report: the verdict, best point with its interval, every term, the
/// paper's point, the gaps, runs and wall time.
pub fn report_text(r: &CalibrationResult) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "calibration of `{}` at tier `{}` ({} particles): {}\n",
        r.study,
        r.tier,
        r.particles.map_or("?".into(), |n| format!("{n}")),
        verdict_line(r),
    ));
    for (k, b) in r.boxes.iter().enumerate() {
        s.push_str(&format!(
            "  box {k}:       {}: {}\n",
            super::result::fmt_bounds(&b.bounds),
            b.termination
        ));
    }
    for e in &r.edges {
        s.push_str(&format!(
            "  edge:        {}{}\n",
            e.describe(),
            e.limit
                .as_ref()
                .map_or(String::new(), |l| format!(" ({l})"))
        ));
    }
    if let Some(p) = &r.prior {
        s.push_str(&format!("  modelled as: {}\n", p.describe()));
    }
    s.push_str(&format!("  best:        {}\n", describe_eval(&r.best)));
    for line in interval_lines(r) {
        s.push_str(&format!("  interval:    {line}\n"));
    }
    if let Some(m) = &r.targets_met {
        s.push_str(&format!("  targets met: {}\n", m.describe()));
    }
    if let Some(noise) = r.noise {
        s.push_str(&format!(
            "  noise:       {noise:.4} in log10 J ({})\n",
            r.noise_source
                .as_deref()
                .unwrap_or("a seed mean's standard error, or the floor")
        ));
    }
    for sp in &r.best_spread {
        s.push_str(&format!(
            "  at the best point: {} = {:.4} +- {:.4} (sd over {} seed(s))\n",
            sp.target, sp.mean, sp.sd, sp.seeds
        ));
    }
    s.push_str(&format!("  best grid:   {}\n", describe_eval(&r.best_grid)));
    s.push_str(&format!("  paper's fit: {}\n", describe_eval(&r.paper)));
    for (k, v) in &r.ratio_to_paper {
        s.push_str(&format!("  best / paper for {k}: {v:.3}\n"));
    }
    for g in &r.gaps {
        s.push_str(&format!("  not scored (gap): {}: {}\n", g.name, g.source));
    }
    s.push_str(&format!(
        "  runs: {} simulated now ({} in the search), wall time {:.1} s\n",
        r.runs_made, r.refinement_runs, r.wall_seconds
    ));
    s
}

/// calibration.md: what a reader needs from calibration.json, in prose and tables.
pub fn report_md(r: &CalibrationResult) -> String {
    let mut s = format!(
        "# Calibration of `{}` at tier `{}`\n\nWritten by `hvi-study calibrate` from calibration.json (regenerate it with the command; do not edit). {} particles.\n\n**{}**\n\n",
        r.study,
        r.tier,
        r.particles.map_or("?".into(), |n| format!("{n}")),
        verdict_line(r)
    );
    s.push_str("## The calibrated point\n\n| parameter | best | interval (low) | interval (high) | the paper's fit | best / paper |\n|---|---|---|---|---|---|\n");
    for (k, v) in &r.best.params {
        let (lo, hi) = r
            .region
            .as_ref()
            .and_then(|g| g.intervals.get(k))
            .map_or(("n/a".to_string(), "n/a".to_string()), |(a, b)| {
                (format!("{a:.4e}"), format!("{b:.4e}"))
            });
        s.push_str(&format!(
            "| `{k}` | {v:.4e} | {lo} | {hi} | {} | {} |\n",
            r.paper
                .params
                .get(k)
                .map_or("n/a".to_string(), |p| format!("{p:.4e}")),
            r.ratio_to_paper
                .get(k)
                .map_or("n/a".to_string(), |q| format!("{q:.3}"))
        ));
    }
    if let Some(g) = &r.region {
        s.push_str(&format!(
            "\nThe interval is the confidence region of the minimum: every point the surrogate predicts within {} noise standard errors of its lowest prediction (J < {:.4}); it covers {:.1} % of the searched box.{}\n",
            hvi_analysis::surrogate::REGION_NOISE_MULTIPLE,
            g.threshold,
            100.0 * g.share_of_box,
            if g.at_boundary.values().any(|&b| b) {
                " It reaches the box's edge on at least one axis: the parameter may lie outside what was searched."
            } else {
                ""
            }
        ));
    }
    if let Some(m) = &r.targets_met {
        s.push_str(&format!(
            "\nWhere the runs meet every target (each term within its tolerance at the seed mean, no model): {}. The interval above is the model's, around one minimum; this span is how far along the valley the points looked at meet the targets.\n",
            m.describe()
        ));
    }
    if !r.boxes.is_empty() {
        s.push_str("\n## The boxes searched\n\n| box | bounds | the search there | sides the answer touched |\n|---|---|---|---|\n");
        for (k, b) in r.boxes.iter().enumerate() {
            let edges = if b.edges.is_empty() {
                "none: the answer is inside".to_string()
            } else {
                b.edges
                    .iter()
                    .map(|e| {
                        format!(
                            "{}{}",
                            e.describe(),
                            e.limit
                                .as_ref()
                                .map_or(String::new(), |l| format!(" ({l})"))
                        )
                    })
                    .collect::<Vec<_>>()
                    .join("; ")
            };
            s.push_str(&format!(
                "| {k} | {} | {} | {edges} |\n",
                super::result::fmt_bounds(&b.bounds),
                b.termination
            ));
        }
        if let Some(limit) = &r.limit {
            s.push_str(&format!("\nNot an optimum inside the box: {limit}.\n"));
        }
    }
    s.push_str("\n## Every target at the best point\n\n| target | observed (seed mean) | sd over seeds | term | weight |\n|---|---|---|---|---|\n");
    if let Some(score) = &r.best.score {
        for t in &score.terms {
            let sp = r.best_spread.iter().find(|x| x.target == t.name);
            s.push_str(&format!(
                "| {} | {} | {} | {:.4} | {} |\n",
                t.name,
                t.observed.map_or("n/a".into(), |v| format!("{v:.4}")),
                sp.map_or("n/a".into(), |x| format!("{:.4} ({} seeds)", x.sd, x.seeds)),
                t.term,
                t.weight
            ));
        }
    }
    s.push_str(&format!(
        "\nObjective J = {:.4} at the best point, {:.4} at the best grid point, {:.4} at the paper's fit.\n",
        r.best.objective, r.best_grid.objective, r.paper.objective
    ));
    if let Some(p) = &r.prior {
        s.push_str(&format!(
            "The search modelled log10 J as {} (docs/calibration.md, \"The resolution ladder\").\n",
            p.describe()
        ));
    }
    if let Some(noise) = r.noise {
        s.push_str(&format!(
            "The noise the search worked with: {noise:.4} in log10 J ({}).\n",
            r.noise_source
                .as_deref()
                .unwrap_or("a seed mean's standard error, at least calibrate.noise_floor")
        ));
    }
    for g in &r.gaps {
        s.push_str(&format!(
            "\nNot scored (a gap in experiments_data): {}: {}\n",
            g.name, g.source
        ));
    }
    s.push_str(&format!(
        "\n## Cost\n\n{} runs simulated by this invocation ({} in the search after the grid); {} points evaluated after the grid; wall time {:.1} s. Every evaluation is in evaluations.csv.\n",
        r.runs_made,
        r.refinement_runs,
        r.refinement.len(),
        r.wall_seconds
    ));
    s
}

/// calibration.json and evaluations.csv (every evaluation: grid, refinement, paper).
pub(super) fn write_outputs(out: &Path, r: &CalibrationResult, grid: &[Evaluation]) -> Result<()> {
    write_atomic_bytes(
        &out.join("calibration.json"),
        serde_json::to_string_pretty(r)?.as_bytes(),
    )?;
    write_atomic_bytes(&out.join("calibration.md"), report_md(r).as_bytes())?;
    let keys: Vec<String> = {
        let mut k: Vec<String> = grid
            .iter()
            .chain(&r.refinement)
            .flat_map(|e| e.params.keys().cloned())
            .collect();
        k.sort();
        k.dedup();
        k
    };
    let names: Vec<String> = r.targets.iter().map(|t| t.name.clone()).collect();
    write_atomic(&out.join("evaluations.csv"), |w| {
        let mut csv = csv::Writer::from_writer(w);
        let mut header = vec!["stage".to_string(), "step".into()];
        header.extend(keys.iter().cloned());
        header.push("objective".into());
        header.extend(names.iter().map(|n| format!("score_{n}")));
        header.extend(["seeds", "status", "cached", "dir"].map(String::from));
        csv.write_record(&header)?;
        for e in grid
            .iter()
            .chain(&r.refinement)
            .chain(std::iter::once(&r.paper))
        {
            let mut row = vec![e.stage.clone(), e.step.to_string()];
            row.extend(
                keys.iter()
                    .map(|k| e.params.get(k).map_or(String::new(), |v| v.to_string())),
            );
            // A point not run (outside the box, invalid scene, failed) has no objective.
            row.push(if e.score.is_some() && e.objective.is_finite() {
                e.objective.to_string()
            } else {
                String::new()
            });
            for k in 0..names.len() {
                row.push(
                    e.score
                        .as_ref()
                        .map_or(String::new(), |s| s.terms[k].term.to_string()),
                );
            }
            row.push(
                e.seeds
                    .iter()
                    .map(|x| x.to_string())
                    .collect::<Vec<_>>()
                    .join(" "),
            );
            row.push(e.status.clone());
            row.push(e.cached.to_string());
            row.push(e.dir.clone().unwrap_or_default());
            csv.write_record(&row)?;
        }
        csv.flush()?;
        Ok(())
    })?;
    if let Some(surface) = &r.surface {
        write_surface(out, surface)?;
    }
    Ok(())
}

/// `surrogate.csv`: the search's final model over two axes (x, y, predicted log10 J).
pub(super) fn write_surface(out: &Path, s: &Surface) -> Result<()> {
    write_atomic(&out.join("surrogate.csv"), |w| {
        let mut csv = csv::Writer::from_writer(w);
        csv.write_record([
            s.keys.0.as_str(),
            s.keys.1.as_str(),
            "predicted_log10_objective",
        ])?;
        for (row, &y) in s.field.z.iter().zip(&s.field.y) {
            for (&z, &x) in row.iter().zip(&s.field.x) {
                csv.write_record([x.to_string(), y.to_string(), z.to_string()])?;
            }
        }
        csv.flush()?;
        Ok(())
    })
}

/// The snapshot matrix of the grid (Fig. 7): each run's side view at the end, captioned with
/// F and R and the objective; the best grid point framed red.
pub(super) fn calibration_snapshots(
    out: &Path,
    plan: &Plan,
    records: &[Record],
    result: &CalibrationResult,
) -> Result<PathBuf> {
    let axes = crate::study::figures::map_axes(plan)?;
    let slice = result.best_grid.step;
    let (cols, rows, tiles) = crate::study::figures::plan_tiles(plan, out, axes, slice, |i| {
        let r = &records[i];
        let f = |x: Option<f64>| x.map_or("n/a".to_string(), |v| format!("{v:.2}"));
        let j = objective(&result.targets, |n| r.observables.get(n)).objective;
        (
            (i == slice).then_some(plotters::style::RED),
            format!(
                "F = {}, R = {}, J = {j:.2}",
                f(r.observables.get(Observable::Fragmentation)),
                f(r.observables.get(Observable::LengthRatio))
            ),
        )
    })?;
    let path = out.join("snapshots.png");
    let title = format!(
        "Debris clouds over ({}, {}) (Fig. 7); red frame: the best grid point",
        plan.axes[axes.0].label, plan.axes[axes.1].label
    );
    hvi_plot::snapshots::snapshot_matrix(
        &path,
        hvi_plot::snapshots::MatrixText {
            title: &title,
            columns: &cols,
            rows: &rows,
            footer: &crate::study::figures::conditions(plan, records),
        },
        &tiles,
    )?;
    Ok(path)
}

/// The files of one calibration (as opposed to the grid's, which every calibration of the
/// study shares).
const CALIBRATION_FILES: [&str; 6] = [
    "calibration.json",
    "calibration.md",
    "evaluations.csv",
    "surrogate.csv",
    "map_objective.png",
    "map_objective.svg",
];

/// Keeps this calibration's files under `calibrations/<label>/` of the study directory (so
/// that calibrations with other methods, seeds, settings or boxes sit side by side and never
/// overwrite each other; the study directory's own copies are the last calibration's), and
/// rewrites `calibrations/index.csv`, one row per kept calibration. Returns the directory.
pub(super) fn archive(out: &Path, r: &CalibrationResult) -> Result<PathBuf> {
    let root = out.join("calibrations");
    let dir = root.join(&r.label);
    let tmp = root.join(format!(".tmp-{}-{}", r.label, std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp)?;
    }
    std::fs::create_dir_all(&tmp)?;
    for name in CALIBRATION_FILES {
        let from = out.join(name);
        if from.exists() {
            std::fs::copy(&from, tmp.join(name)).with_context(|| {
                format!("cannot copy {} into {}", from.display(), tmp.display())
            })?;
        }
    }
    if dir.exists() {
        std::fs::remove_dir_all(&dir)
            .with_context(|| format!("cannot replace {}", dir.display()))?;
    }
    std::fs::rename(&tmp, &dir)
        .with_context(|| format!("cannot move {} to {}", tmp.display(), dir.display()))?;
    write_index(&root)?;
    Ok(dir)
}

/// `calibrations/index.csv`: every kept calibration (from its calibration.json), by label.
fn write_index(root: &Path) -> Result<()> {
    let mut rows: Vec<CalibrationResult> = Vec::new();
    for entry in std::fs::read_dir(root)? {
        let path = entry?.path().join("calibration.json");
        if let Ok(text) = std::fs::read_to_string(&path) {
            if let Ok(r) = serde_json::from_str::<CalibrationResult>(&text) {
                rows.push(r);
            }
        }
    }
    rows.sort_by(|a, b| a.label.cmp(&b.label));
    let keys: Vec<String> = {
        let mut k: Vec<String> = rows
            .iter()
            .flat_map(|r| r.best.params.keys().cloned())
            .collect();
        k.sort();
        k.dedup();
        k
    };
    write_atomic(&root.join("index.csv"), |w| {
        let mut csv = csv::Writer::from_writer(w);
        let mut header: Vec<String> = ["label", "method", "seeds", "converged", "boxes"]
            .map(String::from)
            .to_vec();
        header.extend(keys.iter().map(|k| format!("best {k}")));
        header.extend(["objective", "paper_objective", "edges", "particles"].map(String::from));
        csv.write_record(&header)?;
        for r in &rows {
            let mut row = vec![
                r.label.clone(),
                r.method.clone(),
                if r.best.seeds.is_empty() {
                    "scene".to_string()
                } else {
                    r.best
                        .seeds
                        .iter()
                        .map(u64::to_string)
                        .collect::<Vec<_>>()
                        .join(" ")
                },
                r.converged.to_string(),
                r.boxes.len().to_string(),
            ];
            row.extend(keys.iter().map(|k| {
                r.best
                    .params
                    .get(k)
                    .map_or(String::new(), |v| v.to_string())
            }));
            row.push(r.best.objective.to_string());
            row.push(r.paper.objective.to_string());
            row.push(
                r.edges
                    .iter()
                    .map(|e| format!("{} {}", e.key, e.side.name()))
                    .collect::<Vec<_>>()
                    .join("; "),
            );
            row.push(r.particles.map_or(String::new(), |n| n.to_string()));
            csv.write_record(&row)?;
        }
        csv.flush()?;
        Ok(())
    })
}
