//! Figs. 7, 9, 10 from the calibration study's grid over (eps, kappa): the snapshot matrix and
//! its large-fragment runs (7), R = La/Lr (9) and va/v0 (10). The grid is run by
//! `hvi-study calibrate --no-refine`, whose maps and snapshots the report collects.

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use hvi_analysis::contour::Field;
use hvi_analysis::decide;
use hvi_analysis::observable::Observable;
use hvi_analysis::score::Target;
use hvi_engine::paper;
use hvi_run::plan::Plan;
use hvi_run::store::{read_summary, Record};

use super::Ctx;
use super::{axis, completed_runs, index_of, join_or, mean, plan_records, timing};
use crate::cli::CalibrateArgs;
use crate::reproduce::report::{fmt_num, short, Figure, StageTiming, Value, Verdict};
use crate::study::calibrate::calibrate;
use crate::study::figures::field_of;

/// Paper text of Fig. 7.
pub fn fig7_paper() -> String {
    let [a, b] = paper::FIG7_LARGE_FRAGMENT_POINTS;
    format!(
        "at rcut = {} \u{3c3}: \u{3ba} <= {} fragments almost completely (~{} mm fragments); \
         ({}, {}) and ({}, {}) keep a large central fragment",
        short(paper::BEST_RCUT_OVER_SIGMA),
        short(paper::FIG7_FINE_MAX_KAPPA_N_M),
        short(paper::FIG7_FINE_FRAGMENT_SIZE_M * 1e3),
        short(a.0),
        short(a.1),
        short(b.0),
        short(b.1)
    )
}

/// Fig. 7, not computed yet.
pub fn fig7_pending() -> Figure {
    Figure::pending(
        "7",
        "snapshot matrix over (\u{3b5}, \u{3ba}) at the analysis time",
        fig7_paper(),
    )
}

/// Paper text of Fig. 9.
pub fn fig9_paper() -> String {
    format!(
        "R plateau about {}, peak {} at ({}, {}); local maximum at the best fit ({}, {}); the experiment's R = {}",
        paper::FIG9_R_PLATEAU,
        paper::FIG9_R_PEAK,
        short(paper::FIG9_R_PEAK_AT.0),
        short(paper::FIG9_R_PEAK_AT.1),
        short(paper::BEST_EPS_J),
        short(paper::BEST_KAPPA_N_M),
        paper::CALIBRATION_SHOT_LENGTH_RATIO
    )
}

/// Fig. 9, not computed yet.
pub fn fig9_pending() -> Figure {
    Figure::pending("9", "R = La/Lr over (\u{3b5}, \u{3ba})", fig9_paper())
}

/// Paper text of Fig. 10.
pub fn fig10_paper() -> String {
    "va/v0 falls as \u{3b5} grows and varies little with \u{3ba}; the experiment's value is a red contour".into()
}

/// Fig. 10, not computed yet.
pub fn fig10_pending() -> Figure {
    Figure::pending("10", "va/v0 over (\u{3b5}, \u{3ba})", fig10_paper())
}

/// Figs. 7, 9, 10 from the calibration study's grid (`calibrate --no-refine`).
pub fn fig7_9_10(
    ctx: &Ctx,
    study_path: &Path,
    sref: &crate::reproduce::config::StudyRef,
    plan: &Plan,
) -> Result<(Vec<Figure>, StageTiming)> {
    let t0 = Instant::now();
    let dir = ctx.runs.join(&plan.study);
    let cached = completed_runs(plan, &dir).unwrap_or(0);
    let calibration = calibrate(&CalibrateArgs {
        study: ctx.study_args(study_path, sref, &dir),
        no_refine: true,
        max_iters: None,
    })?;
    // `calibrate` returns its result but not the grid's records: those are the store's.
    let records = plan_records(plan, &dir)?;
    let bound = largest_fragment_bound(&calibration.targets);
    let files = collect(ctx, &dir)?;
    let grid = Grid::of(plan, &records, &dir)?;
    let figures = vec![
        fig7_figure(&grid, bound, files.fig7),
        fig9_figure(&grid.length_ratio, files.fig9),
        fig10_figure(&grid.front_velocity, files.fig10),
    ];
    let t = timing("calibration", "7, 9, 10", plan, cached, &records, t0);
    Ok((figures, t))
}

/// The largest-fragment fraction above which a run keeps "a large central fragment": the
/// calibration shot's bound on the largest fragment (None when its targets have none).
fn largest_fragment_bound(targets: &[Target]) -> Option<f64> {
    targets
        .iter()
        .find(|t| t.observable == Observable::LargestFragmentMassFraction)
        .map(|t| t.value)
}

/// The report files of each figure, copied from the calibration study's directory.
struct Files {
    fig7: Vec<String>,
    fig9: Vec<String>,
    fig10: Vec<String>,
}

fn collect(ctx: &Ctx, dir: &Path) -> Result<Files> {
    let fig7 = ctx.collect_all(&[(dir.join("snapshots.png"), "fig07_snapshots.png")])?;
    let mut fig9 = ctx.collect_all(&[(dir.join("map_R.png"), "fig09_R.png")])?;
    let fig10 = ctx.collect_all(&[(dir.join("map_va.png"), "fig10_va.png")])?;
    fig9.extend(ctx.collect_all(&[(dir.join("results.csv"), "fig07_09_10_grid.csv")])?);
    Ok(Files { fig7, fig9, fig10 })
}

/// The (eps, kappa) field of an observable over the calibration grid.
fn calibration_field(plan: &Plan, records: &[Record], observable: Observable) -> Result<Field> {
    let ax = axis(plan, "material.eps_j")?;
    let ay = axis(plan, "material.kappa_n_m")?;
    // Other axes (rcut) at the paper's value where the grid has it.
    let slice = plan
        .runs
        .iter()
        .position(|r| {
            plan.axes.iter().zip(&r.values).all(|(a, v)| {
                a.key != "material.rcut_over_sigma"
                    || v.as_f64()
                        .is_some_and(|x| (x - paper::BEST_RCUT_OVER_SIGMA).abs() < 1e-12)
            })
        })
        .unwrap_or(0);
    field_of(plan, records, (ax, ay), slice, |r| {
        r.observables.get(observable)
    })
}

/// What the three figures read off the calibration grid.
struct Grid {
    largest: Field,
    fragmentation: Field,
    mean_diameter: Field,
    length_ratio: Field,
    front_velocity: Field,
    /// Grid runs.
    runs: usize,
    /// The first run's particle count that is known.
    particles: Option<f64>,
    /// The first run's particle diameter (its `summary.json`), m.
    sigma_m: Option<f64>,
}

impl Grid {
    fn of(plan: &Plan, records: &[Record], dir: &Path) -> Result<Grid> {
        let field = |o| calibration_field(plan, records, o);
        Ok(Grid {
            largest: field(Observable::LargestFragmentMassFraction)?,
            fragmentation: field(Observable::Fragmentation)?,
            mean_diameter: field(Observable::MeanFragmentDiameter)?,
            length_ratio: field(Observable::LengthRatio)?,
            front_velocity: field(Observable::FrontVelocityRatio)?,
            runs: records.len(),
            particles: records
                .iter()
                .find_map(|r| r.observables.get(Observable::Particles)),
            sigma_m: plan
                .runs
                .first()
                .and_then(|r| read_summary(&dir.join(&r.dir)).map(|s| s.sigma_m)),
        })
    }
}

/// A field's finite value at the grid point (eps, kappa).
fn value_at(field: &Field, (e, k): (f64, f64)) -> Option<f64> {
    let c = index_of(&field.x, e)?;
    let r = index_of(&field.y, k)?;
    Some(field.z[r][c]).filter(|v| v.is_finite())
}

// ---------------------------------------------------------------------------------------------
// Fig. 7

/// A run at kappa <= the paper's fine-fragmentation bound.
struct FineRun {
    eps: f64,
    kappa: f64,
    largest: f64,
    fragmentation: f64,
}

/// Fig. 7's deciding numbers.
struct Fig7Numbers {
    /// Whether the grid has a row at kappa <= the fine bound.
    has_fine_rows: bool,
    /// Every run in those rows, row by row.
    fine_runs: Vec<FineRun>,
    /// Their largest fragment (a missing value counts as infinite).
    fine_max: f64,
    /// The largest fragment at each of the paper's two large-fragment points.
    large: Vec<((f64, f64), Option<f64>)>,
    /// The largest finite mean fragment diameter in those rows, m.
    fine_diameter: f64,
}

fn fig7_numbers(largest: &Field, fragmentation: &Field, mean_diameter: &Field) -> Fig7Numbers {
    let fine_rows: Vec<usize> = (0..largest.y.len())
        .filter(|&r| largest.y[r] <= paper::FIG7_FINE_MAX_KAPPA_N_M * (1.0 + 1e-9))
        .collect();
    let mut fine_runs = Vec::new();
    let mut fine_max = f64::NEG_INFINITY;
    for &r in &fine_rows {
        for (c, &eps) in largest.x.iter().enumerate() {
            let l = largest.z[r][c];
            fine_runs.push(FineRun {
                eps,
                kappa: largest.y[r],
                largest: l,
                fragmentation: fragmentation.z[r][c],
            });
            fine_max = fine_max.max(if l.is_finite() { l } else { f64::INFINITY });
        }
    }
    Fig7Numbers {
        has_fine_rows: !fine_rows.is_empty(),
        fine_runs,
        fine_max,
        large: paper::FIG7_LARGE_FRAGMENT_POINTS
            .iter()
            .map(|&p| (p, value_at(largest, p)))
            .collect(),
        fine_diameter: fine_rows
            .iter()
            .flat_map(|&r| mean_diameter.z[r].iter().copied())
            .filter(|d| d.is_finite())
            .fold(f64::NEG_INFINITY, f64::max),
    }
}

fn fig7_figure(grid: &Grid, bound: Option<f64>, files: Vec<String>) -> Figure {
    let mut f7 = fig7_pending();
    f7.files = files;
    match bound {
        None => {
            f7.reason = "the calibration targets have no largest-fragment bound to decide 'large central fragment'".into();
        }
        Some(bound) => {
            let n = fig7_numbers(&grid.largest, &grid.fragmentation, &grid.mean_diameter);
            fig7_decide(&mut f7, grid, &n, bound);
        }
    }
    if f7.verdict == Verdict::Pending {
        f7.verdict = Verdict::Not;
    }
    f7
}

/// Fig. 7's numbers, verdict and text against the large-fragment `bound`.
fn fig7_decide(f7: &mut Figure, grid: &Grid, n: &Fig7Numbers, bound: f64) {
    for run in &n.fine_runs {
        f7.number(
            format!(
                "largest fragment at ({}, {})",
                short(run.eps),
                short(run.kappa)
            ),
            Value::num(Some(run.largest)),
            format!("of the impactor mass; F = {}", fmt_num(run.fragmentation)),
        );
    }
    let fine_ok = n.has_fine_rows && n.fine_max < bound;
    for (p, l) in &n.large {
        f7.number(
            format!("largest fragment at ({}, {})", short(p.0), short(p.1)),
            Value::num(*l),
            "paper: a large central fragment",
        );
    }
    let large_ok = n.large.iter().all(|(_, l)| l.is_some_and(|l| l >= bound));
    f7.number(
        "bound for a large central fragment",
        Value::Number(bound),
        "of the impactor mass (experiments_data: the calibration shot's no_large_fragment target)",
    );
    f7.number(
        format!(
            "largest mean fragment diameter at \u{3ba} <= {} (mm)",
            short(paper::FIG7_FINE_MAX_KAPPA_N_M)
        ),
        Value::num(Some(n.fine_diameter * 1e3)),
        format!(
            "paper: ~{} mm fragments",
            paper::FIG7_FINE_FRAGMENT_SIZE_M * 1e3
        ),
    );
    f7.number(
        "particle diameter \u{3c3} (mm)",
        Value::num(grid.sigma_m.map(|s| s * 1e3)),
        "the smallest fragment this tier can show",
    );
    let checks = [fine_ok, large_ok];
    f7.verdict = Verdict::of_checks(checks.iter().filter(|c| **c).count(), checks.len());
    f7.reason = fig7_reason(fine_ok, large_ok, n.fine_max, bound, grid.sigma_m);
    f7.ours = format!(
        "{} grid runs at {} particles; largest fragment {}-{} of the impactor mass",
        grid.runs,
        grid.particles.map_or("?".into(), |n| n.to_string()),
        grid.largest.range().map_or("n/a".into(), |r| fmt_num(r.0)),
        grid.largest.range().map_or("n/a".into(), |r| fmt_num(r.1)),
    );
}

fn fig7_reason(
    fine_ok: bool,
    large_ok: bool,
    fine_max: f64,
    bound: f64,
    sigma_m: Option<f64>,
) -> String {
    let fine = short(paper::FIG7_FINE_MAX_KAPPA_N_M);
    let mut why = vec![if fine_ok {
        format!("every run at \u{3ba} <= {fine} fragments almost completely (largest fragment < {bound})")
    } else {
        format!("not every run at \u{3ba} <= {fine} fragments almost completely (largest fragment up to {})", fmt_num(fine_max))
    }];
    why.push(if large_ok {
        "both of the paper's large-fragment runs keep one".to_string()
    } else {
        "the paper's large-fragment runs do not both keep one".to_string()
    });
    if sigma_m.is_some_and(|s| s > paper::FIG7_FINE_FRAGMENT_SIZE_M) {
        why.push(format!(
            "fragments of ~{} mm are below this tier's particle diameter",
            paper::FIG7_FINE_FRAGMENT_SIZE_M * 1e3
        ));
    }
    why.join("; ")
}

// ---------------------------------------------------------------------------------------------
// Fig. 9

/// Fig. 9's deciding numbers over the R = La/Lr field.
struct RatioMap {
    /// The median over the grid.
    plateau: Option<f64>,
    /// Where the maximum is, (eps, kappa).
    peak_at: Option<(f64, f64)>,
    /// The maximum.
    peak: Option<f64>,
    /// R at the paper's best fit.
    at_fit: Option<f64>,
    /// R at the paper's peak.
    at_paper_peak: Option<f64>,
    /// Whether the paper's best fit is larger than its grid neighbours.
    fit_is_local_max: Option<bool>,
}

impl RatioMap {
    fn of(rr: &Field) -> RatioMap {
        let all_r: Vec<f64> = rr.z.iter().flatten().copied().collect();
        let peak_at = decide::argmax(&all_r).map(|i| (rr.x[i % rr.x.len()], rr.y[i / rr.x.len()]));
        let fit_is_local_max = match (
            index_of(&rr.x, paper::BEST_EPS_J),
            index_of(&rr.y, paper::BEST_KAPPA_N_M),
        ) {
            (Some(c), Some(r)) => decide::is_local_maximum(&rr.z, r, c),
            _ => None,
        };
        RatioMap {
            plateau: decide::median(&all_r),
            peak_at,
            peak: peak_at.and_then(|p| value_at(rr, p)),
            at_fit: value_at(rr, (paper::BEST_EPS_J, paper::BEST_KAPPA_N_M)),
            at_paper_peak: value_at(rr, paper::FIG9_R_PEAK_AT),
            fit_is_local_max,
        }
    }

    /// The four checks against the paper, each with its description.
    fn checks(&self) -> [(bool, String); 4] {
        let tol = decide::LENGTH_RATIO_TOLERANCE;
        let near = |x: Option<f64>, y: f64| x.is_some_and(|x| (x - y).abs() <= tol);
        let peak_here = self.peak_at.is_some_and(|p| {
            (p.0 - paper::FIG9_R_PEAK_AT.0).abs() <= 1e-9 * p.0.abs()
                && (p.1 - paper::FIG9_R_PEAK_AT.1).abs() <= 1e-9 * p.1.abs()
        });
        [
            (
                near(self.plateau, paper::FIG9_R_PLATEAU),
                format!("plateau within {tol} of {}", paper::FIG9_R_PLATEAU),
            ),
            (
                near(self.peak, paper::FIG9_R_PEAK),
                format!("peak within {tol} of {}", paper::FIG9_R_PEAK),
            ),
            (peak_here, "peak at the paper's point".to_string()),
            (
                self.fit_is_local_max == Some(true),
                "local maximum at the paper's fit".to_string(),
            ),
        ]
    }
}

/// `(eps, kappa)` as the report prints a grid point.
fn point(p: (f64, f64)) -> String {
    format!("({}, {})", short(p.0), short(p.1))
}

fn fig9_figure(rr: &Field, files: Vec<String>) -> Figure {
    let mut f9 = fig9_pending();
    f9.files = files;
    let m = RatioMap::of(rr);
    f9.number(
        "R plateau (median over the grid)",
        Value::num(m.plateau),
        format!("paper: about {}", paper::FIG9_R_PLATEAU),
    );
    f9.number(
        "R peak (maximum over the grid)",
        Value::num(m.peak),
        format!("paper: {}", paper::FIG9_R_PEAK),
    );
    f9.number(
        "where the peak is (\u{3b5}, \u{3ba})",
        m.peak_at
            .map_or(Value::Text("n/a".into()), |p| Value::Text(point(p))),
        format!("paper: {}", point(paper::FIG9_R_PEAK_AT)),
    );
    f9.number(
        format!("R at the paper's peak {}", point(paper::FIG9_R_PEAK_AT)),
        Value::num(m.at_paper_peak),
        format!("paper: {}", paper::FIG9_R_PEAK),
    );
    f9.number(
        format!(
            "R at the paper's fit {}",
            point((paper::BEST_EPS_J, paper::BEST_KAPPA_N_M))
        ),
        Value::num(m.at_fit),
        format!("the experiment: {}", paper::CALIBRATION_SHOT_LENGTH_RATIO),
    );
    f9.number(
        "the paper's fit is a local maximum of R",
        m.fit_is_local_max
            .map_or(Value::Text("n/a".into()), Value::Flag),
        "larger than its grid neighbours in \u{3b5} and \u{3ba}",
    );
    let checks = m.checks();
    let held: Vec<&str> = checks
        .iter()
        .filter(|c| c.0)
        .map(|c| c.1.as_str())
        .collect();
    let missed: Vec<&str> = checks
        .iter()
        .filter(|c| !c.0)
        .map(|c| c.1.as_str())
        .collect();
    f9.verdict = Verdict::of_checks(held.len(), checks.len());
    f9.reason = format!(
        "holds: {}; does not: {}",
        join_or(&held, ", ", "none"),
        join_or(&missed, ", ", "none")
    );
    f9.ours = format!(
        "plateau {}, peak {} at {}; R = {} at the paper's fit",
        m.plateau.map_or("n/a".into(), fmt_num),
        m.peak.map_or("n/a".into(), fmt_num),
        m.peak_at.map_or("n/a".into(), point),
        m.at_fit.map_or("n/a".into(), fmt_num)
    );
    f9
}

// ---------------------------------------------------------------------------------------------
// Fig. 10

/// Fig. 10's deciding numbers over the va/v0 field.
struct VelocityMap {
    /// kappa rows where va/v0 does not rise with eps.
    falling_rows: usize,
    /// kappa rows.
    rows: usize,
    /// Mean over kappa rows of max - min along eps.
    spread_eps: Option<f64>,
    /// Mean over eps columns of max - min along kappa.
    spread_kappa: Option<f64>,
}

impl VelocityMap {
    fn of(va: &Field) -> VelocityMap {
        VelocityMap {
            falling_rows: va
                .z
                .iter()
                .filter(|row| decide::non_increasing(row, decide::MONOTONE_TOLERANCE) == Some(true))
                .count(),
            rows: va.y.len(),
            spread_eps: mean(va.z.iter().filter_map(|row| decide::spread(row))),
            spread_kappa: mean((0..va.x.len()).filter_map(|c| {
                let col: Vec<f64> = va.z.iter().map(|row| row[c]).collect();
                decide::spread(&col)
            })),
        }
    }
}

fn fig10_figure(va: &Field, files: Vec<String>) -> Figure {
    let mut f10 = fig10_pending();
    f10.files = files;
    let m = VelocityMap::of(va);
    let (falls, rows) = (m.falling_rows, m.rows);
    f10.number(
        "\u{3ba} rows where va/v0 falls as \u{3b5} grows",
        Value::Text(format!("{falls} of {rows}")),
        format!("never rising by more than {}", decide::MONOTONE_TOLERANCE),
    );
    f10.number(
        "mean spread of va/v0 along \u{3b5}",
        Value::num(m.spread_eps),
        "max - min at fixed \u{3ba}, averaged",
    );
    f10.number(
        "mean spread of va/v0 along \u{3ba}",
        Value::num(m.spread_kappa),
        "max - min at fixed \u{3b5}, averaged",
    );
    f10.number(
        "the experiment's va/v0",
        Value::Text("not available".into()),
        "a documented gap in experiments_data (the paper draws it as a red contour without stating it)",
    );
    let all_fall = falls == rows && rows > 0;
    let kappa_small = matches!((m.spread_eps, m.spread_kappa), (Some(a), Some(b)) if b < a);
    f10.verdict = Verdict::of_checks(all_fall as usize + kappa_small as usize, 2);
    f10.reason = format!(
        "{}; {}; the experiment's contour cannot be drawn (gap)",
        if all_fall {
            "va/v0 falls with \u{3b5} at every \u{3ba}".to_string()
        } else {
            format!("va/v0 falls with \u{3b5} at {falls} of {rows} \u{3ba}")
        },
        if kappa_small {
            "it varies less with \u{3ba} than with \u{3b5}"
        } else {
            "it varies as much or more with \u{3ba} than with \u{3b5}"
        }
    );
    f10.ours = format!(
        "va/v0 between {} and {} over the grid",
        va.range().map_or("n/a".into(), |r| fmt_num(r.0)),
        va.range().map_or("n/a".into(), |r| fmt_num(r.1))
    );
    f10
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratio_map_finds_the_peak_and_the_fit_s_local_maximum() {
        let (e, k) = (paper::BEST_EPS_J, paper::BEST_KAPPA_N_M);
        let rr = Field::new(
            vec![e / 2.0, e, 2.0 * e],
            vec![k / 2.0, k, 2.0 * k],
            vec![
                vec![1.0, 1.1, 1.0],
                vec![1.1, 1.3, 1.2],
                vec![1.0, 1.1, f64::NAN],
            ],
        )
        .expect("field");
        let m = RatioMap::of(&rr);
        assert_eq!(m.peak_at, Some((e, k)));
        assert_eq!((m.peak, m.at_fit), (Some(1.3), Some(1.3)));
        assert_eq!(m.plateau, Some(1.1));
        assert_eq!(m.fit_is_local_max, Some(true));
        assert!(m.checks()[3].0, "local maximum at the paper's fit");
        assert_eq!(value_at(&rr, (2.0 * e, 2.0 * k)), None, "NaN is no value");
    }
}
