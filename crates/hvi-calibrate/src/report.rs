//! What a calibration writes: `calibration.json`, `calibration.md`, `evaluations.csv`,
//! `surrogate.csv`, the maps and the snapshot matrix, and the console's report.

use std::path::{Path, PathBuf};

use hvi_analysis::observable::Observable;
use hvi_analysis::score::objective;
use hvi_analysis::surrogate::REGION_NOISE_MULTIPLE;
use hvi_run::error::{Result, ResultExt};
use hvi_run::output::{write_atomic_bytes, write_atomic_with};
use hvi_store::plan::Plan;
use hvi_store::store::Record;

use crate::problem::describe_eval;
use crate::result::EvalStage;
use crate::result::{fmt_value, CalibrationResult, Evaluation, FloorPoint, Surface};
use hvi_studies::document::{Document, Section};

/// The maps and the snapshot matrix; a figure that cannot be drawn is reported, not fatal.
pub(super) fn draw_figures(
    out: &Path,
    plan: &Plan,
    records: &[Record],
    result: &CalibrationResult,
    log_axes: &[String],
    progress: bool,
) {
    match crate::maps::calibration_maps(out, plan, records, result, log_axes) {
        Ok(stems) if progress => {
            for s in stems {
                log::info!("plot: {} (and .svg)", s.with_extension("png").display());
            }
        }
        Ok(_) => {}
        Err(e) => log::info!("no maps drawn: {e:#}"),
    }
    match calibration_snapshots(out, plan, records, result) {
        Ok(path) if progress => log::info!("snapshots: {}", path.display()),
        Ok(_) => {}
        Err(e) => log::info!("no snapshot matrix: {e:#}"),
    }
}

/// The report's title: the study, the particle count of its runs and where it came from.
fn title(r: &CalibrationResult) -> String {
    let n = r.particles.map_or("?".into(), |n| format!("{n}"));
    match r.particles_asked {
        Some(asked) => format!(
            "Calibration of `{}` at {n} particles ({asked} asked: the lattice's nearest count; \
             the other settings of tier `{}`)",
            r.study, r.tier
        ),
        None => format!(
            "Calibration of `{}` at tier `{}` ({n} particles)",
            r.study, r.tier
        ),
    }
}

/// The verdict of a calibration in one line: converged, bounded (the answer is a one-sided
/// bound or "not identified" on some parameter) or not converged, and why.
fn verdict_line(r: &CalibrationResult) -> String {
    let state = match (r.method.as_str(), r.converged, r.bounded) {
        ("none", _, _) => "GRID ONLY",
        (_, true, _) => "CONVERGED",
        (_, false, true) => "BOUNDED",
        (_, false, false) => "NOT CONVERGED",
    };
    format!("{state} ({}): {}", r.method, r.termination)
}

/// The shots calibrated against, each with its impact; with several, each one's own J at the
/// best point.
fn shots(sec: &mut Section, r: &CalibrationResult) {
    let per_shot = r.best.score.as_ref().map(|s| per_shot_objectives(r, s));
    for (k, s) in r.shots.iter().enumerate() {
        let j = per_shot
            .as_ref()
            .filter(|p| p.len() > 1)
            .and_then(|p| p.get(k))
            .map_or(String::new(), |(_, j)| {
                format!("; its J at the best point {j:.4}")
            });
        sec.fact(
            "shot",
            format!("{}: {}{j} ({})", s.name(), s.impact, s.file.display()),
        );
    }
    if r.shots.len() > 1 {
        sec.note(
            "J is the mean of the shots' own J, each the weighted mean of its terms (every shot \
             counts alike); a term is named `<shot>:<target>`.",
        );
    }
}

/// Each shot's own J from a combined score.
fn per_shot_objectives(
    r: &CalibrationResult,
    score: &hvi_analysis::score::Score,
) -> Vec<(String, f64)> {
    let ids: Vec<String> = r.shots.iter().map(|s| s.id.clone()).collect();
    hvi_analysis::score::shot_objectives(&ids, score)
}

/// The held-out shot's prediction against its measurement.
fn held_out(sec: &mut Section, h: &crate::result::HeldOut) {
    sec.fact("shot", format!("{}: {}", h.shot.name(), h.shot.impact));
    for line in h.lines() {
        sec.fact("prediction", line);
    }
    sec.fact(
        "J",
        format!(
            "{:.4} against its own targets at the calibrated point, over seeds {:?}",
            h.evaluation.objective, h.evaluation.seeds
        ),
    )
    .note(
        "Left out of the calibration (`--hold-out`) and run at its answer: how well the \
         calibration predicts a shot it did not see. A target is met when its term is at most 1.",
    );
}

/// What the targets determine of each searched parameter, one fact each.
fn identified(sec: &mut Section, r: &CalibrationResult) {
    if r.identified.is_empty() {
        return;
    }
    for (key, id) in &r.identified {
        sec.fact("determined", id.describe(key));
    }
    sec.note(
        "An interval is the model's confidence region inside the box. A bound is the answer \
         where every target is met on the side of the box the answer touches: the targets \
         bound the parameter from the other side only, and the side is no optimum. \
         docs/calibration.md, \"What the targets determine\".",
    );
}

/// The calibration's report, composed once: the verdict, the calibrated point with its
/// interval and the paper's, the boxes searched, every target, the gaps and the cost. The
/// console prints its text, calibration.md is its Markdown.
pub fn report(r: &CalibrationResult) -> Document {
    let mut doc = Document {
        title: title(r),
        preamble: "Written by `hvi-study calibrate` from calibration.json (regenerate it with the \
                   command; do not edit)."
            .into(),
        verdict: verdict_line(r),
        sections: Vec::new(),
    };
    shots(doc.section("Shots"), r);
    calibrated_point(doc.section("The calibrated point"), r);
    identified(doc.section("What the targets determine"), r);
    if let Some(surface) = &r.surface {
        valley(
            doc.section("The valley's floor (the model's)"),
            surface,
            r.noise,
        );
    }
    boxes(doc.section("The boxes searched"), r);
    targets(doc.section("Every target at the best point"), r);
    if let Some(h) = &r.held_out {
        held_out(doc.section("The held-out shot"), h);
    }
    let gaps = doc.section("Not scored");
    for g in &r.gaps {
        gaps.fact(
            "not scored (gap)",
            format!("{}: {} (a gap in experiments_data)", g.name, g.source),
        );
    }
    doc.section("Cost")
        .fact("runs", cost_line(r))
        .note("Every evaluation is in evaluations.csv.");
    doc
}

/// The runs simulated and where they went: `108 simulated by this invocation, 88 of them after
/// the grid (the grid at the search's seeds, the extended boxes' grid points, 1 search
/// batch(es)); 27 points evaluated after the grid; wall time 46.5 s`.
fn cost_line(r: &CalibrationResult) -> String {
    let mut batches: Vec<EvalStage> = r
        .refinement
        .iter()
        .map(|e| e.stage)
        .filter(|s| s.is_search())
        .collect();
    batches.dedup();
    let mut after = Vec::new();
    if r.refinement.iter().any(|e| e.stage == EvalStage::GridSeeds) {
        after.push("the grid at the search's seeds".to_string());
    }
    if r.refinement.iter().any(|e| e.stage.is_extension()) {
        after.push("the extended boxes' grid points".to_string());
    }
    match (r.method.as_str(), batches.len()) {
        ("ego", n) => after.push(format!("{n} search batch(es)")),
        ("nelder-mead", _) => after.push("the Nelder-Mead steps".to_string()),
        _ => {}
    }
    let after = if after.is_empty() {
        String::new()
    } else {
        format!(" ({})", after.join(", "))
    };
    // Scored points left at one seed where others ran at several
    // (calibrate.seeds_within_decades).
    let most = r
        .refinement
        .iter()
        .map(|e| e.seeds.len())
        .max()
        .unwrap_or(0);
    let one = r
        .refinement
        .iter()
        .filter(|e| most > 1 && e.seeds.len() == 1 && e.score.is_some())
        .count();
    let screened = if one > 0 {
        format!(
            " ({one} of them at one seed, more than calibrate.seeds_within_decades decades \
             above the lowest J when they ran)"
        )
    } else {
        String::new()
    };
    let design = match &r.initial_design {
        Some(d) if d.points < d.grid_points => format!(
            "; the grid stage ran the {} design, {} of the grid's {} points",
            d.name, d.points, d.grid_points
        ),
        _ => String::new(),
    };
    format!(
        "{} simulated by this invocation, {} of them after the grid{after}; {} points evaluated \
         after the grid{screened}{design}; wall time {:.1} s",
        r.runs_made,
        r.refinement_runs,
        r.refinement.len(),
        r.wall_seconds
    )
}

/// The best point against the paper's fit, its confidence region, where the runs meet every
/// target, the model's prior and the noise.
fn calibrated_point(sec: &mut Section, r: &CalibrationResult) {
    let num = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.4e}"));
    let rows = r
        .best
        .params
        .iter()
        .map(|(k, v)| {
            let interval = r.region.as_ref().and_then(|g| g.intervals.get(k));
            let at_edge = r.region.as_ref().and_then(|g| g.at_boundary.get(k));
            vec![
                format!("`{k}`"),
                format!("{v:.4e}"),
                num(interval.map(|i| i.0)),
                num(interval.map(|i| i.1)),
                at_edge.map_or("n/a".into(), |&b| if b { "yes" } else { "no" }.into()),
                num(r.paper.params.get(k).copied()),
                r.ratio_to_paper
                    .get(k)
                    .map_or("n/a".to_string(), |q| format!("{q:.3}")),
            ]
        })
        .collect();
    sec.table(
        &[
            "parameter",
            "best",
            "interval (low)",
            "interval (high)",
            "interval at the box's edge",
            "the paper's fit",
            "best / paper",
        ],
        rows,
    );
    if let Some(g) = &r.region {
        sec.note(format!(
            "The interval is the confidence region of the minimum: every point the surrogate \
             predicts within {} noise standard errors of its lowest prediction (J < {:.4}), and \
             every point run whose seed-mean J is below that; the predicted part covers {:.1} % \
             of the searched box.{}",
            hvi_analysis::surrogate::REGION_NOISE_MULTIPLE,
            g.threshold,
            100.0 * g.share_of_box,
            if g.at_boundary.values().any(|&b| b) {
                " It reaches the box's edge on at least one axis: the parameter may lie outside \
                 what was searched."
            } else {
                ""
            }
        ));
    }
    sec.fact("best", describe_eval(&r.best));
    if let Some(m) = &r.targets_met {
        sec.fact("targets met", m.describe()).note(
            "Where the runs meet every target: each term within its tolerance at the seed mean, \
             no model. The interval above is the model's, around one minimum; this span is how \
             far along the valley the points looked at meet the targets.",
        );
    }
    if let Some(p) = &r.prior {
        sec.fact(
            "modelled as",
            format!(
                "log10 J as {} (docs/calibration.md, \"The resolution ladder\")",
                p.describe()
            ),
        );
    }
    if let Some(noise) = r.noise {
        sec.fact(
            "noise",
            format!(
                "{noise:.4} in log10 J ({})",
                r.noise_source
                    .as_deref()
                    .unwrap_or("a seed mean's standard error, at least calibrate.noise_floor")
            ),
        );
    }
}

/// Rows of the valley's floor a report shows: all of up to `most`, else `most` evenly spaced
/// with the lowest among them.
fn floor_rows(floor: &[FloorPoint], most: usize) -> Vec<usize> {
    if floor.len() <= most {
        return (0..floor.len()).collect();
    }
    let lowest = (0..floor.len())
        .min_by(|&a, &b| {
            floor[a]
                .log10_objective
                .total_cmp(&floor[b].log10_objective)
        })
        .unwrap_or(0);
    let mut rows: Vec<usize> = (0..most)
        .map(|k| k * (floor.len() - 1) / (most - 1))
        .chain([lowest])
        .collect();
    rows.sort_unstable();
    rows.dedup();
    rows
}

/// The search's final model along its valley: at each value of the second key the first
/// key's best value and the predicted J, and how far along the floor J stays within the noise
/// of its lowest (where the targets cannot tell the points apart).
fn valley(sec: &mut Section, s: &Surface, noise: Option<f64>) {
    let floor = s.floor();
    let Some(lowest) = floor
        .iter()
        .map(|p| p.log10_objective)
        .min_by(f64::total_cmp)
    else {
        return;
    };
    let threshold = noise.map(|n| lowest + REGION_NOISE_MULTIPLE * n);
    let within = |p: &FloorPoint| threshold.is_some_and(|t| p.log10_objective <= t);
    let (x, y) = (&s.keys.0, &s.keys.1);
    let rows = floor_rows(&floor, 9)
        .into_iter()
        .map(|k| {
            let p = &floor[k];
            vec![
                format!("`{y}` = {}", fmt_value(p.along)),
                fmt_value(p.at),
                format!("{:.4}", 10f64.powf(p.log10_objective)),
                if threshold.is_none() {
                    "n/a".into()
                } else if within(p) {
                    "yes".into()
                } else {
                    "no".into()
                },
            ]
        })
        .collect();
    sec.table(
        &[
            "along the valley",
            &format!("`{x}` at the floor"),
            "predicted J",
            "within the noise of the lowest",
        ],
        rows,
    );
    let flat: Vec<&FloorPoint> = floor.iter().filter(|p| within(p)).collect();
    let span = |v: &dyn Fn(&FloorPoint) -> f64| {
        let lo = flat.iter().map(|p| v(p)).fold(f64::INFINITY, f64::min);
        let hi = flat.iter().map(|p| v(p)).fold(f64::NEG_INFINITY, f64::max);
        format!("[{}, {}]", fmt_value(lo), fmt_value(hi))
    };
    if let (Some(t), false) = (threshold, flat.is_empty()) {
        sec.fact(
            "flat along",
            format!(
                "{} of {} rows of the floor within {REGION_NOISE_MULTIPLE} noise standard \
                 errors of its lowest (J < {:.4}): `{y}` in {}, `{x}` in {} there",
                flat.len(),
                floor.len(),
                10f64.powf(t),
                span(&|p| p.along),
                span(&|p| p.at),
            ),
        );
    }
    sec.note(format!(
        "The model's lowest J at each `{y}` of its grid (surrogate.csv). Where the floor stays \
         within the noise, the targets cannot tell its points apart: there the calibration \
         fixes `{x}` for a given `{y}`, not the two together."
    ));
}

/// Every box searched, the sides the answer touched, and the limit where one stopped it.
fn boxes(sec: &mut Section, r: &CalibrationResult) {
    if r.boxes.is_empty() {
        return;
    }
    let rows = r
        .boxes
        .iter()
        .enumerate()
        .map(|(k, b)| {
            let edges = if b.edges.is_empty() {
                "none: the answer is inside".to_string()
            } else {
                b.edges
                    .iter()
                    .map(|e| {
                        let limit = e.limit.as_ref();
                        format!(
                            "{}{}",
                            e.describe(),
                            limit.map_or(String::new(), |l| format!(" ({l})"))
                        )
                    })
                    .collect::<Vec<_>>()
                    .join("; ")
            };
            vec![
                format!("box {k}"),
                crate::result::fmt_bounds(&b.bounds),
                b.termination.clone(),
                edges,
            ]
        })
        .collect();
    sec.table(
        &[
            "box",
            "bounds",
            "the search there",
            "sides the answer touched",
        ],
        rows,
    );
    if let Some(limit) = &r.limit {
        if r.bounded {
            sec.fact("limit", format!("A bound, not an optimum: {limit}"));
        } else {
            sec.fact("limit", format!("Not an optimum inside the box: {limit}"));
        }
    }
}

/// Every target's term at the best point with its seed spread, and J at the best point, the
/// best grid point and the paper's fit (each over the same seeds).
fn targets(sec: &mut Section, r: &CalibrationResult) {
    let rows = r
        .best
        .score
        .iter()
        .flat_map(|score| &score.terms)
        .map(|t| {
            let sp = r.best_spread.iter().find(|x| x.target == t.name);
            vec![
                t.name.clone(),
                t.observed.map_or("n/a".into(), |v| format!("{v:.4}")),
                sp.map_or("n/a".into(), |x| format!("{:.4} ({} seeds)", x.sd, x.seeds)),
                crate::problem::fmt_term(t),
                t.weight.to_string(),
            ]
        })
        .collect();
    sec.table(
        &[
            "target",
            "observed (seed mean)",
            "sd over seeds",
            "term",
            "weight",
        ],
        rows,
    )
    .fact(
        "objective",
        format!(
            "J = {:.4} at the best point, {:.4} at the best grid point, {:.4} at the paper's fit",
            r.best.objective, r.best_grid.objective, r.paper.objective
        ),
    )
    .fact("best grid", describe_eval(&r.best_grid))
    .fact("paper's fit", describe_eval(&r.paper));
}

/// calibration.json and evaluations.csv (every evaluation: grid, refinement, paper).
pub(super) fn write_outputs(out: &Path, r: &CalibrationResult, grid: &[Evaluation]) -> Result<()> {
    write_atomic_bytes(
        &out.join("calibration.json"),
        serde_json::to_string_pretty(r)?.as_bytes(),
    )?;
    write_atomic_bytes(&out.join("calibration.md"), report(r).markdown().as_bytes())?;
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
    write_atomic_with(&out.join("evaluations.csv"), |w| {
        let mut csv = csv::Writer::from_writer(w);
        let mut header = vec!["stage".to_string(), "step".into()];
        header.extend(keys.iter().cloned());
        header.push("objective".into());
        header.extend(names.iter().map(|n| format!("score_{n}")));
        header.extend(["seeds", "status", "cached", "screened", "dir"].map(String::from));
        csv.write_record(&header)?;
        for e in grid
            .iter()
            .chain(&r.refinement)
            .chain(std::iter::once(&r.paper))
        {
            let mut row = vec![e.stage.to_string(), e.step.to_string()];
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
            // The share of its runs the screen sent on in free flight (empty: no screen).
            row.push(
                e.mean(Observable::Screened)
                    .map_or(String::new(), |x| x.to_string()),
            );
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
    write_atomic_with(&out.join("surrogate.csv"), |w| {
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
    })?;
    Ok(())
}

/// The snapshot matrix of the grid (Fig. 7): each run's side view at the end, captioned with
/// F and R and the objective; the best grid point framed red.
pub(super) fn calibration_snapshots(
    out: &Path,
    plan: &Plan,
    records: &[Record],
    result: &CalibrationResult,
) -> Result<PathBuf> {
    let axes = hvi_studies::figures::map_axes(plan)?;
    let slice = crate::design::position(plan, result.best_grid.step)?;
    let (cols, rows, tiles) = hvi_studies::figures::plan_tiles(plan, out, axes, slice, |i| {
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
            footer: &hvi_studies::figures::conditions(plan, records),
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
    write_atomic_with(&root.join("index.csv"), |w| {
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
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvi_analysis::contour::Field;

    /// A valley along the diagonal x = y whose floor rises 0.05 in log10 J per unit of y.
    fn diagonal_valley() -> Surface {
        let axis: Vec<f64> = (1..=5).map(f64::from).collect();
        let z = axis
            .iter()
            .map(|&y| {
                axis.iter()
                    .map(|&x| -2.0 + 0.05 * (y - 1.0) + 0.3 * (x - y).powi(2))
                    .collect()
            })
            .collect();
        Surface {
            keys: ("eps".into(), "kappa".into()),
            field: Field::new(axis.clone(), axis, z).expect("field"),
        }
    }

    #[test]
    fn the_floor_follows_the_valley_and_says_how_far_it_is_flat() {
        let s = diagonal_valley();
        let floor = s.floor();
        assert_eq!(floor.len(), 5);
        for p in &floor {
            assert_eq!(p.at, p.along, "{p:?}");
        }
        let mut doc = Document::default();
        // Noise 0.05: within 2 x 0.05 of the lowest are the floor's rows y = 1, 2, 3.
        valley(doc.section("valley"), &s, Some(0.05));
        let text = doc.text();
        assert!(
            text.contains("3 of 5 rows of the floor within 2 noise standard errors"),
            "{text}"
        );
        assert!(
            text.contains("`kappa` in [1, 3], `eps` in [1, 3]"),
            "{text}"
        );
        // Without a noise estimate the table stands, with no claim of flatness.
        let mut doc = Document::default();
        valley(doc.section("valley"), &s, None);
        let text = doc.text();
        assert!(!text.contains("rows of the floor within"), "{text}");
        assert!(text.contains("n/a"), "{text}");
    }

    #[test]
    fn a_long_floor_shows_nine_rows_with_its_lowest() {
        let floor: Vec<FloorPoint> = (0..33)
            .map(|k| FloorPoint {
                along: k as f64,
                at: 0.0,
                log10_objective: (k as f64 - 17.0).abs(),
            })
            .collect();
        let rows = floor_rows(&floor, 9);
        assert_eq!(rows.first(), Some(&0));
        assert_eq!(rows.last(), Some(&32));
        assert!(rows.contains(&17), "{rows:?}");
        assert!(rows.len() <= 10, "{rows:?}");
    }
}
