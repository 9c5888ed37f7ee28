//! Figs. 16 and 17 from the validity-map study over (v0, t/D): F's shape and the validity
//! boundary at the paper's cut-off (16), and the valid and invalid regions of the snapshot
//! matrix (17).
//! The map is run and drawn by `hvi-study validity-map`; the report collects its files.

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use hvi_analysis::contour::Field;
use hvi_analysis::decide;
use hvi_analysis::observable::Observable;
use hvi_engine::paper;
use hvi_run::plan::Plan;

use super::{axis, completed_runs, plan_records, timing, Ctx};
use crate::cli::ValidityArgs;
use crate::reproduce::report::{fmt_num, Figure, StageTiming, Value, Verdict};
use crate::study::figures::field_of;
use crate::study::validity::{validity_map, ValidityMap};

/// Paper text of Fig. 16.
pub fn fig16_paper() -> String {
    format!(
        "F rises monotonically with v0; a local maximum in t/D; the contour F = {} is the validity cut-off",
        paper::VALIDITY_FRAGMENTATION_CUTOFF
    )
}

/// Fig. 16, not computed yet.
pub fn fig16_pending() -> Figure {
    Figure::pending(
        "16",
        "F over (v0, t/D) and the validity boundary",
        fig16_paper(),
    )
}

/// Paper text of Fig. 17.
pub fn fig17_paper() -> String {
    format!(
        "snapshots over (t/D, v0): the valid region (F >= {}) red, the invalid one blue",
        paper::VALIDITY_FRAGMENTATION_CUTOFF
    )
}

/// Fig. 17, not computed yet.
pub fn fig17_pending() -> Figure {
    Figure::pending(
        "17",
        "snapshot matrix over (v0, t/D), valid red, invalid blue",
        fig17_paper(),
    )
}

/// Figs. 16 and 17 from the validity-map study.
pub fn fig16_17(
    ctx: &Ctx,
    study_path: &Path,
    sref: &crate::reproduce::config::StudyRef,
    plan: &Plan,
) -> Result<(Vec<Figure>, StageTiming)> {
    let t0 = Instant::now();
    let dir = ctx.runs.join(&plan.study);
    let cached = completed_runs(plan, &dir).unwrap_or(0);
    let cutoff = paper::VALIDITY_FRAGMENTATION_CUTOFF;
    let map = validity_map(&ValidityArgs {
        study: ctx.study_args(study_path, sref, &dir),
        cutoff: Some(cutoff),
    })?;
    // `validity_map` returns its map but not the runs' records: those are the store's.
    let records = plan_records(plan, &dir)?;
    let mut f16 = fig16_pending();
    let mut f17 = fig17_pending();
    (f16.files, f17.files) = collect(ctx, &dir, &map)?;
    let ax = axis(plan, "scene.v0_m_s")?;
    let ay = axis(plan, "scene.t_over_d")?;
    let field = field_of(plan, &records, (ax, ay), 0, |r| {
        r.observables.get(Observable::Fragmentation)
    })?;
    fig16_decide(&mut f16, &FragmentationMap::of(&field, cutoff), cutoff);
    fig17_decide(&mut f17, &Regions::of(&field, cutoff), cutoff);
    let t = timing("validity-map", "16, 17", plan, cached, &records, t0);
    Ok((vec![f16, f17], t))
}

/// The files of Figs. 16 and 17, copied from the validity-map study's directory.
fn collect(ctx: &Ctx, dir: &Path, map: &ValidityMap) -> Result<(Vec<String>, Vec<String>)> {
    let f16 = ctx.collect_all(&[
        (map.plot.with_extension("png"), "fig16_fragmentation.png"),
        (dir.join("validity_boundary.csv"), "fig16_boundary.csv"),
        (dir.join("results.csv"), "fig16_17_grid.csv"),
    ])?;
    let f17 = ctx.collect_all(&[(dir.join("snapshots.png"), "fig17_snapshots.png")])?;
    Ok((f16, f17))
}

// ---------------------------------------------------------------------------------------------
// Fig. 16

/// Fig. 16's deciding numbers over the F field (columns v0, rows t/D).
struct FragmentationMap {
    /// t/D rows where F never falls with rising v0 (beyond the tolerance).
    monotone_rows: usize,
    /// The largest fall of F with rising v0 over all rows.
    worst_drop: f64,
    /// Per t/D row, where F reaches the cut-off (`t/D 0.1: 4500 m/s`).
    crossings: Vec<String>,
    /// v0 columns whose largest F is at an interior t/D.
    interior: usize,
    /// Per v0 column, the t/D of its largest F (`5000: 0.3`).
    argmax: Vec<String>,
    /// F's finite range.
    lo: f64,
    hi: f64,
    rows: usize,
    cols: usize,
}

impl FragmentationMap {
    fn of(field: &Field, cutoff: f64) -> FragmentationMap {
        let mut monotone_rows = 0;
        let mut worst_drop: f64 = 0.0;
        let mut crossings = Vec::new();
        for (r, row) in field.z.iter().enumerate() {
            if decide::non_decreasing(row, decide::MONOTONE_TOLERANCE) == Some(true) {
                monotone_rows += 1;
            }
            worst_drop = worst_drop.max(decide::largest_drop(row).unwrap_or(0.0));
            crossings.push(format!(
                "t/D {}: {}",
                field.y[r],
                crossing(&field.x, row, cutoff)
            ));
        }
        let mut interior = 0;
        let mut argmax = Vec::new();
        for c in 0..field.x.len() {
            let col: Vec<f64> = field.z.iter().map(|row| row[c]).collect();
            if decide::interior_maximum(&col) == Some(true) {
                interior += 1;
            }
            argmax.push(format!(
                "{:.0}: {}",
                field.x[c],
                decide::argmax(&col).map_or("n/a".into(), |i| format!("{}", field.y[i]))
            ));
        }
        let (lo, hi) = field.range().unwrap_or((f64::NAN, f64::NAN));
        FragmentationMap {
            monotone_rows,
            worst_drop,
            crossings,
            interior,
            argmax,
            lo,
            hi,
            rows: field.y.len(),
            cols: field.x.len(),
        }
    }
}

/// Where a row of F over `v0` first rises through `cutoff`, as the report says it.
fn crossing(v0: &[f64], row: &[f64], cutoff: f64) -> String {
    let first_valid = row
        .iter()
        .find(|v| v.is_finite())
        .is_some_and(|&v| v >= cutoff);
    match decide::upward_crossing(v0, row, cutoff) {
        Some(v) => format!("{:.0} m/s", v),
        None if first_valid => "valid everywhere".into(),
        None => "below everywhere".into(),
    }
}

fn fig16_decide(f16: &mut Figure, m: &FragmentationMap, cutoff: f64) {
    let (monotone_rows, n_rows, interior, n_cols) = (m.monotone_rows, m.rows, m.interior, m.cols);
    f16.number(
        "t/D rows where F is monotone in v0",
        Value::Text(format!("{monotone_rows} of {n_rows}")),
        format!(
            "never falling by more than {} below an earlier value",
            decide::MONOTONE_TOLERANCE
        ),
    );
    f16.number(
        "largest fall of F with rising v0",
        Value::Number(m.worst_drop),
        "over all t/D rows",
    );
    f16.number(
        "v0 columns with an interior t/D maximum of F",
        Value::Text(format!("{interior} of {n_cols}")),
        "the largest F neither at the thinnest nor at the thickest plate",
    );
    f16.number(
        "t/D of the largest F, per v0 (m/s)",
        Value::Text(m.argmax.join("; ")),
        "paper: a local maximum in t/D",
    );
    f16.number(
        "F range",
        Value::Text(format!("{} - {}", fmt_num(m.lo), fmt_num(m.hi))),
        "",
    );
    f16.number(
        format!("v0 where F reaches {cutoff}, per t/D"),
        Value::Text(m.crossings.join("; ")),
        "linear between runs; the validity boundary",
    );
    let checks = [
        (
            monotone_rows == n_rows && n_rows > 0,
            "F is monotone in v0 at every t/D".to_string(),
            format!("F is monotone in v0 at {monotone_rows} of {n_rows} t/D"),
        ),
        (
            2 * interior > n_cols,
            format!("an interior t/D maximum at {interior} of {n_cols} v0"),
            format!("an interior t/D maximum at only {interior} of {n_cols} v0"),
        ),
        (
            m.lo < cutoff && m.hi >= cutoff,
            format!("the F = {cutoff} contour crosses the map"),
            format!("the F = {cutoff} contour does not cross the map"),
        ),
    ];
    let held = checks.iter().filter(|c| c.0).count();
    f16.verdict = Verdict::of_checks(held, checks.len());
    f16.reason = checks
        .iter()
        .map(|c| if c.0 { c.1.clone() } else { c.2.clone() })
        .collect::<Vec<_>>()
        .join("; ");
    f16.ours = format!(
        "F from {} to {}; monotone in v0 at {monotone_rows} of {n_rows} t/D; interior t/D maximum at {interior} of {n_cols} v0",
        fmt_num(m.lo),
        fmt_num(m.hi)
    );
}

// ---------------------------------------------------------------------------------------------
// Fig. 17

/// Fig. 17's deciding numbers: the valid and invalid runs and how each t/D row splits.
struct Regions {
    /// Runs with F >= the cut-off.
    valid: usize,
    /// Runs with a finite F below it.
    invalid: usize,
    /// t/D rows that, with rising v0, never go from valid back to invalid.
    split_once: usize,
    rows: usize,
}

impl Regions {
    fn of(field: &Field, cutoff: f64) -> Regions {
        let finite = || field.z.iter().flatten().filter(|v| v.is_finite());
        Regions {
            valid: finite().filter(|v| **v >= cutoff).count(),
            invalid: finite().filter(|v| **v < cutoff).count(),
            split_once: field
                .z
                .iter()
                .filter(|row| {
                    let flags: Vec<bool> = row
                        .iter()
                        .filter(|v| v.is_finite())
                        .map(|v| *v >= cutoff)
                        .collect();
                    flags.windows(2).all(|w| !w[0] || w[1])
                })
                .count(),
            rows: field.y.len(),
        }
    }
}

fn fig17_decide(f17: &mut Figure, m: &Regions, cutoff: f64) {
    let (valid, invalid, consistent, n_rows) = (m.valid, m.invalid, m.split_once, m.rows);
    f17.number(
        "valid runs (red)",
        Value::Number(valid as f64),
        format!("F >= {cutoff}"),
    );
    f17.number(
        "invalid runs (blue)",
        Value::Number(invalid as f64),
        format!("F < {cutoff}"),
    );
    f17.number(
        "t/D rows split once (invalid below one v0, valid above)",
        Value::Text(format!("{consistent} of {n_rows}")),
        "",
    );
    let both = valid > 0 && invalid > 0;
    let split = consistent == n_rows && n_rows > 0;
    f17.verdict = Verdict::of_checks(both as usize + split as usize, 2);
    f17.reason = format!(
        "{}; {}",
        if both {
            "both regions appear"
        } else if valid > 0 {
            "only the valid region appears"
        } else {
            "only the invalid region appears"
        },
        if split {
            "every t/D row changes from invalid to valid once as v0 rises".to_string()
        } else {
            format!(
                "{consistent} of {n_rows} t/D rows change from invalid to valid once as v0 rises"
            )
        }
    );
    f17.ours = format!("{valid} runs valid, {invalid} invalid");
}

#[cfg(test)]
mod tests {
    use super::*;

    /// F over v0 = (1, 2, 3) (columns) and t/D = (0.1, 0.2) (rows).
    fn field(z: Vec<Vec<f64>>) -> Field {
        Field::new(vec![1.0, 2.0, 3.0], vec![0.1, 0.2], z).expect("field")
    }

    #[test]
    fn regions_count_runs_and_rows_that_split_once() {
        let f = field(vec![vec![0.1, 0.2, 0.5], vec![0.4, 0.1, f64::NAN]]);
        let r = Regions::of(&f, 0.3);
        assert_eq!((r.valid, r.invalid, r.split_once, r.rows), (2, 3, 1, 2));
    }

    #[test]
    fn crossings_say_where_f_reaches_the_cutoff() {
        assert_eq!(crossing(&[1.0, 2.0], &[0.1, 0.5], 0.3), "2 m/s");
        assert_eq!(crossing(&[1.0, 2.0], &[0.4, 0.5], 0.3), "valid everywhere");
        assert_eq!(crossing(&[1.0, 2.0], &[0.1, 0.2], 0.3), "below everywhere");
        let m = FragmentationMap::of(&field(vec![vec![0.1, 0.2, 0.5], vec![0.2, 0.1, 0.4]]), 0.3);
        assert_eq!((m.monotone_rows, m.rows, m.cols), (1, 2, 3));
        assert!((m.worst_drop - 0.1).abs() < 1e-12, "{}", m.worst_drop);
    }
}
