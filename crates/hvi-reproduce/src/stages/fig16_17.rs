//! Figs. 16 and 17 from the validity-map study over (v0, t/D): F's shape, the validity
//! boundary at the paper's cut-off and whether the valid cells are free of a large central
//! fragment, the cut-off's justification (16); the valid and invalid regions of the snapshot
//! matrix (17).
//! The map is run and drawn by `hvi-study validity-map`; the report collects its files.

use std::path::Path;
use std::time::Instant;

use hvi_analysis::contour::Field;
use hvi_analysis::decide;
use hvi_analysis::observable::Observable;
use hvi_analysis::score::Target;
use hvi_engine::paper;
use hvi_run::error::Result;
use hvi_store::plan::Plan;

use super::shared::{axis, completed_runs, plan_records, timing, Ctx};
use super::shared::{keeps_large_fragment, largest_fragment_bound};
use crate::report::{fmt_num, judge, short, Check, Figure, StageTiming, Value, Verdict};
use hvi_studies::figures::field_of;
use hvi_studies::validity::{validity_map, ValidityMap, ValidityOptions};

/// Paper text of Fig. 16.
pub fn fig16_paper() -> String {
    format!(
        "F rises monotonically with v0; a local maximum in t/D; the contour F = {} is the validity cut-off, \
         chosen so that the cells above it keep no large central fragment (section 3.3)",
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

/// Figs. 16 and 17 from the validity-map study; `targets` are the calibration shot's, whose
/// largest-fragment bound decides what a large central fragment is.
pub fn fig16_17(
    ctx: &Ctx,
    study_path: &Path,
    sref: &crate::config::StudyRef,
    plan: &Plan,
    targets: &[Target],
) -> Result<(Vec<Figure>, StageTiming)> {
    let t0 = Instant::now();
    let dir = ctx.runs.join(&plan.study);
    let cached = completed_runs(plan, &dir).unwrap_or(0);
    let cutoff = paper::VALIDITY_FRAGMENTATION_CUTOFF;
    let map = validity_map(&ValidityOptions {
        study: ctx.study_options(study_path, sref, &dir),
        cutoff: Some(cutoff),
        // The paper's Figs. 16 and 17 are the map; the onset against experiments is the
        // validity-map study's own (reports/validity-vs-experiment).
        onset: false,
        onset_threshold: None,
    })?;
    // `validity_map` returns its map but not the runs' records: those are the store's.
    let records = plan_records(plan, &dir)?;
    let mut f16 = fig16_pending();
    let mut f17 = fig17_pending();
    (f16.files, f17.files) = collect(ctx, &dir, &map)?;
    let ax = axis(plan, "scene.v0_m_s")?;
    let ay = axis(plan, "scene.t_over_d")?;
    let map_of = |o| field_of(plan, &records, (ax, ay), 0, |r| r.observables.get(o));
    let field = map_of(Observable::Fragmentation)?;
    let largest = map_of(Observable::LargestFragmentMassFraction)?;
    let bound = largest_fragment_bound(targets);
    fig16_decide(
        &mut f16,
        &FragmentationMap::of(&field, cutoff),
        &LargeFragments::of(&field, &largest, cutoff, bound),
        cutoff,
    );
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

/// One valid cell (F >= the cut-off) of the validity map that keeps a large central fragment.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LargeFragmentCell {
    v0_m_s: f64,
    t_over_d: f64,
    fragmentation: f64,
    /// Of the impactor mass.
    largest: f64,
}

/// Whether the valid cells keep no large central fragment: the paper chose F = 0.3 so that
/// they do not (section 3.3: "particular attention was given to the size of the large central
/// fragment when choosing the cutoff value").
struct LargeFragments {
    /// The large-fragment bound ([`largest_fragment_bound`]; None: the targets have none).
    bound: Option<f64>,
    /// Cells with F >= the cut-off.
    valid: usize,
    /// Those of them with a large central fragment, largest first.
    cells: Vec<LargeFragmentCell>,
}

impl LargeFragments {
    /// From F and the largest fragment over the same (v0, t/D) grid.
    fn of(fragmentation: &Field, largest: &Field, cutoff: f64, bound: Option<f64>) -> Self {
        let mut valid = 0;
        let mut cells = Vec::new();
        for (r, row) in fragmentation.z.iter().enumerate() {
            for (c, &f) in row.iter().enumerate() {
                if !(f.is_finite() && f >= cutoff) {
                    continue;
                }
                valid += 1;
                let l = largest.z[r][c];
                if bound.is_some_and(|b| keeps_large_fragment(l, b)) {
                    cells.push(LargeFragmentCell {
                        v0_m_s: fragmentation.x[c],
                        t_over_d: fragmentation.y[r],
                        fragmentation: f,
                        largest: l,
                    });
                }
            }
        }
        cells.sort_by(|a, b| b.largest.total_cmp(&a.largest));
        LargeFragments {
            bound,
            valid,
            cells,
        }
    }

    /// The check: no valid cell keeps a large central fragment.
    fn check(&self, cutoff: f64) -> Check {
        let (n, valid) = (self.cells.len(), self.valid);
        match (self.bound, self.cells.first()) {
            (None, _) => Check::new(
                false,
                "the cut-off's justification cannot be checked: the calibration targets have no largest-fragment bound",
            ),
            (Some(b), None) => Check::new(
                true,
                format!(
                    "no valid cell keeps a large central fragment (largest fragment <= {b} of the impactor mass in all {valid} cells with F >= {cutoff})"
                ),
            ),
            (Some(b), Some(worst)) => Check::new(
                false,
                format!(
                    "the cut-off's justification fails: {n} of {valid} valid cells (F >= {cutoff}) keep a large central fragment (largest fragment > {b} of the impactor mass), the largest at {}",
                    worst.show()
                ),
            ),
        }
    }
}

impl LargeFragmentCell {
    /// `8000 m/s, t/D 0.05: F = 0.3190, largest fragment 0.5540`.
    fn show(&self) -> String {
        format!(
            "{:.0} m/s, t/D {}: F = {}, largest fragment {}",
            self.v0_m_s,
            short(self.t_over_d),
            fmt_num(self.fragmentation),
            fmt_num(self.largest)
        )
    }
}

fn fig16_decide(f16: &mut Figure, m: &FragmentationMap, large: &LargeFragments, cutoff: f64) {
    fig16_numbers(f16, m, large, cutoff);
    let (monotone_rows, n_rows, interior, n_cols) = (m.monotone_rows, m.rows, m.interior, m.cols);
    let monotone = monotone_rows == n_rows && n_rows > 0;
    let main = [
        Check::new(
            monotone,
            if monotone {
                format!("F is monotone in v0 at every t/D ({monotone_rows} of {n_rows})")
            } else {
                format!(
                    "F is monotone in v0 at {monotone_rows} of {n_rows} t/D (largest fall {})",
                    fmt_num(m.worst_drop)
                )
            },
        ),
        Check::new(
            2 * interior > n_cols,
            format!(
                "an interior t/D maximum at {}{interior} of {n_cols} v0",
                if 2 * interior > n_cols { "" } else { "only " }
            ),
        ),
        Check::new(
            m.lo < cutoff && m.hi >= cutoff,
            format!(
                "the F = {cutoff} contour {} the map (F {} - {})",
                if m.lo < cutoff && m.hi >= cutoff {
                    "crosses"
                } else {
                    "does not cross"
                },
                fmt_num(m.lo),
                fmt_num(m.hi)
            ),
        ),
    ];
    (f16.verdict, f16.reason) = judge(&main, &[large.check(cutoff)]);
    f16.ours = format!(
        "F from {} to {}; monotone in v0 at {monotone_rows} of {n_rows} t/D; interior t/D maximum at {interior} of {n_cols} v0; {} of {} valid cells keep a large central fragment",
        fmt_num(m.lo),
        fmt_num(m.hi),
        large.cells.len(),
        large.valid
    );
}

fn fig16_numbers(f16: &mut Figure, m: &FragmentationMap, large: &LargeFragments, cutoff: f64) {
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
    f16.number(
        "bound for a large central fragment",
        Value::num(large.bound),
        "of the impactor mass (experiments_data: the calibration shot's no_large_fragment target, as in Fig. 7)",
    );
    f16.number(
        "valid cells with a large central fragment",
        Value::Text(format!("{} of {}", large.cells.len(), large.valid)),
        format!("largest fragment above the bound in a cell with F >= {cutoff}; paper: none (section 3.3)"),
    );
    f16.number(
        "those cells, largest fragment first",
        Value::Text(if large.cells.is_empty() {
            "none".into()
        } else {
            large
                .cells
                .iter()
                .map(LargeFragmentCell::show)
                .collect::<Vec<_>>()
                .join("; ")
        }),
        "largest fragment as a fraction of the impactor mass",
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

    #[test]
    fn a_valid_cell_with_a_55_percent_fragment_fails_the_cutoff_s_justification() {
        // F rises with v0 at both t/D, with a t/D maximum at neither (2 rows); the paper
        // tier's (8 km/s, t/D 0.05) cell is the middle one of the first row: F = 0.32 with a
        // 55 % largest fragment.
        let f = field(vec![vec![0.1, 0.32, 0.5], vec![0.2, 0.4, 0.6]]);
        let largest = field(vec![vec![0.9, 0.55, 0.02], vec![0.8, 0.03, 0.01]]);
        let m = FragmentationMap::of(&f, 0.3);
        let large = LargeFragments::of(&f, &largest, 0.3, Some(0.05));
        assert_eq!((large.valid, large.cells.len()), (4, 1));
        assert_eq!(
            large.cells[0],
            LargeFragmentCell {
                v0_m_s: 2.0,
                t_over_d: 0.1,
                fragmentation: 0.32,
                largest: 0.55
            }
        );
        let check = large.check(0.3);
        assert!(!check.held);
        assert!(
            check.found.contains("1 of 4 valid cells"),
            "{}",
            check.found
        );
        assert!(check
            .found
            .contains("2 m/s, t/D 0.1: F = 0.3200, largest fragment 0.5500"));
        // The invalid cells' large fragments (0.9, 0.8) do not count; at the bound is not large.
        let clean = field(vec![vec![0.9, 0.05, 0.02], vec![0.8, 0.03, 0.01]]);
        assert!(
            LargeFragments::of(&f, &clean, 0.3, Some(0.05))
                .check(0.3)
                .held
        );
        // No bound: the check cannot hold.
        assert!(!LargeFragments::of(&f, &clean, 0.3, None).check(0.3).held);
        // The main claim holds but for the interior maximum; with it held the large fragment
        // caps the verdict at "partly".
        let mut f16 = fig16_pending();
        let mut shaped = FragmentationMap::of(&f, 0.3);
        shaped.interior = shaped.cols;
        fig16_decide(&mut f16, &shaped, &large, 0.3);
        assert_eq!(f16.verdict, Verdict::Partly, "{}", f16.reason);
        assert!(f16.reason.contains("justification fails"), "{}", f16.reason);
        let mut f16 = fig16_pending();
        fig16_decide(&mut f16, &m, &large, 0.3);
        assert_eq!(
            f16.verdict,
            Verdict::Not,
            "no interior maximum: {}",
            f16.reason
        );
        let mut f16 = fig16_pending();
        fig16_decide(
            &mut f16,
            &shaped,
            &LargeFragments::of(&f, &clean, 0.3, Some(0.05)),
            0.3,
        );
        assert_eq!(f16.verdict, Verdict::Reproduced, "{}", f16.reason);
    }
}
