//! Fig. 5 (F against particle count, the paper's best fit on the calibration scene) and
//! Figs. 11-12 (the series' finest run: the best fit at the final resolution, scored against
//! the calibration shot).

use std::path::Path;
use std::time::Instant;

use hvi_analysis::decide;
use hvi_analysis::observable::{Observable, Observables};
use hvi_analysis::score::{objective, Score, Targets};
use hvi_engine::paper;
use hvi_plot::paper as plots;
use hvi_run::error::Result;
use hvi_run::output::write_atomic_with;
use hvi_store::plan::Plan;
use hvi_store::store::{read_summary, Record, RunStatus};

use super::shared::{execute, Ctx};
use crate::report::{fmt_num, short, Figure, StageTiming, Value, Verdict};

/// Paper text of Fig. 5.
pub fn fig5_paper() -> String {
    format!(
        "F converges from about {} particles (calibration runs at {}, final runs at {})",
        short(paper::CONVERGED_PARTICLES),
        short(paper::CALIBRATION_PARTICLES),
        short(paper::FINAL_PARTICLES)
    )
}

/// Fig. 5, not computed yet.
pub fn fig5_pending() -> Figure {
    Figure::pending(
        "5",
        "convergence of the fragmentation with particle count",
        fig5_paper(),
    )
}

/// Paper text of Figs. 11-12.
pub fn fig11_paper() -> String {
    format!(
        "best fit \u{3b5} = {} J, \u{3ba} = {} N/m, rcut = {} \u{3c3}: cloud at {} \u{b5}s (side view) and \
         3-D series at \u{3c4} = {} \u{b5}s; N = {}, \u{394}t = {} s, {} h on one processor",
        short(paper::BEST_EPS_J),
        short(paper::BEST_KAPPA_N_M),
        short(paper::BEST_RCUT_OVER_SIGMA),
        short(paper::ANALYSIS_TIME_S * 1e6),
        paper::FIG12_TIMES_S
            .iter()
            .map(|t| short(t * 1e6))
            .collect::<Vec<_>>()
            .join(", "),
        short(paper::FINAL_PARTICLES),
        short(paper::TIME_STEP_S),
        short(paper::PAPER_WALL_SECONDS / 3600.0)
    )
}

/// Figs. 11-12, not computed yet.
pub fn fig11_pending() -> Figure {
    Figure::pending(
        "11-12",
        "the best fit at the final resolution: side view and 3-D series",
        fig11_paper(),
    )
}

/// Fig. 5 (F against particle count) and Figs. 11-12 (its finest run, the best fit at the
/// final resolution). `targets` score the best-fit run against the calibration shot.
pub fn fig5_11_12(ctx: &Ctx, plan: &Plan, targets: &Targets) -> Result<(Vec<Figure>, StageTiming)> {
    let t0 = Instant::now();
    let run = execute(ctx, plan)?;
    let series = Series::of(&run.records);
    let numbers = Convergence::of(&series.fs);
    draw_fig5(ctx, plan, &series, &numbers)?;
    let f5 = fig5_figure(&series, &numbers);
    let mut f11 = fig11_pending();
    if let Some(&i) = series.order.last() {
        let run_dir = run.dir.join(&plan.runs[i].dir);
        f11.files = collect_fig11(ctx, &run_dir)?;
        fig11_numbers(&mut f11, &run.records[i], &run_dir, targets);
    }
    let t = run.timing("convergence", "5, 11, 12", plan, t0);
    Ok((vec![f5, f11], t))
}

/// The convergence series: run indices by particle count, and each run's count and F.
struct Series {
    order: Vec<usize>,
    ns: Vec<f64>,
    fs: Vec<f64>,
}

impl Series {
    fn of(records: &[Record]) -> Series {
        // The axis is sorted ascending by construction; sort anyway.
        let get = |i: usize, o: Observable| records[i].observables.get(o).unwrap_or(f64::NAN);
        let mut order: Vec<usize> = (0..records.len()).collect();
        order.sort_by(|&a, &b| {
            get(a, Observable::Particles).total_cmp(&get(b, Observable::Particles))
        });
        Series {
            ns: order
                .iter()
                .map(|&i| get(i, Observable::Particles))
                .collect(),
            fs: order
                .iter()
                .map(|&i| get(i, Observable::Fragmentation))
                .collect(),
            order,
        }
    }

    /// The largest finite particle count (0 when there is none).
    fn n_max(&self) -> f64 {
        self.ns
            .iter()
            .copied()
            .filter(|n| n.is_finite())
            .fold(0.0, f64::max)
    }
}

/// Fig. 5's deciding numbers from F along the series.
struct Convergence {
    /// Relative change of F from each count to the next.
    changes: Vec<f64>,
    /// The index from which every step changes F by less than the tolerance.
    from: Option<usize>,
}

impl Convergence {
    fn of(fs: &[f64]) -> Convergence {
        Convergence {
            changes: decide::relative_changes(fs),
            from: decide::converged_from(fs, decide::CONVERGENCE_TOLERANCE),
        }
    }
}

/// `fig05_convergence.png` and `fig05_convergence.csv`.
fn draw_fig5(ctx: &Ctx, plan: &Plan, s: &Series, c: &Convergence) -> Result<()> {
    plots::convergence(
        &ctx.out.join("fig05_convergence.png"),
        &s.ns.iter().copied().zip(s.fs.iter().copied()).collect::<Vec<_>>(),
        c.from.map(|k| s.ns[k]),
        paper::CONVERGED_PARTICLES,
        decide::CONVERGENCE_TOLERANCE,
        &format!("Fig. 5: fragmentation of the debris cloud against particle count (tier `{}`)", plan.tier),
        &format!(
            "calibration scene, \u{3b5} = {} J, \u{3ba} = {} N/m, rcut = {} \u{3c3}, cloud at the end of the run; geometric sizing at every count",
            short(paper::BEST_EPS_J),
            short(paper::BEST_KAPPA_N_M),
            short(paper::BEST_RCUT_OVER_SIGMA)
        ),
    )?;
    write_atomic_with(&ctx.out.join("fig05_convergence.csv"), |w| {
        writeln!(w, "particles,fragmentation,relative_change_to_next")?;
        for (k, (n, f)) in s.ns.iter().zip(&s.fs).enumerate() {
            let change = c.changes.get(k).map_or(String::new(), |c| c.to_string());
            writeln!(w, "{n},{f},{change}")?;
        }
        Ok(())
    })?;
    Ok(())
}

fn fig5_figure(s: &Series, c: &Convergence) -> Figure {
    let mut f5 = fig5_pending();
    f5.files = vec![
        "fig05_convergence.png".into(),
        "fig05_convergence.csv".into(),
    ];
    for (n, x) in s.ns.iter().zip(&s.fs) {
        f5.number(format!("F at N = {n}"), Value::num(Some(*x)), "");
    }
    for (k, change) in c.changes.iter().enumerate() {
        f5.number(
            format!("change of F, N = {} -> {}", s.ns[k], s.ns[k + 1]),
            Value::num(Some(*change)),
            "relative",
        );
    }
    let conv_n = c.from.map(|k| s.ns[k]);
    f5.number(
        "converged from N",
        conv_n.map_or(Value::Text("not within this series".into()), Value::Number),
        format!(
            "the first count after which every step changes F by < {} %; paper: about {}",
            100.0 * decide::CONVERGENCE_TOLERANCE,
            short(paper::CONVERGED_PARTICLES)
        ),
    );
    let n_max = s.n_max();
    f5.ours = match conv_n {
        Some(n) => format!(
            "F changes by < {} % per step from N = {n} on",
            100.0 * decide::CONVERGENCE_TOLERANCE
        ),
        None => format!(
            "F still changes by {} at the last step (N up to {n_max})",
            c.changes
                .last()
                .map_or("n/a".into(), |c| format!("{:.1} %", 100.0 * c))
        ),
    };
    (f5.verdict, f5.reason) = fig5_verdict(&s.fs, &c.changes, conv_n, n_max);
    f5
}

/// Converged within a factor of the paper's count; or converging (shrinking steps); or not.
fn fig5_verdict(fs: &[f64], changes: &[f64], conv_n: Option<f64>, n_max: f64) -> (Verdict, String) {
    let factor = decide::CONVERGENCE_COUNT_FACTOR;
    match conv_n {
        _ if fs.iter().any(|x| !x.is_finite()) => (
            Verdict::Not,
            "a run of the series failed or measured no cloud".into(),
        ),
        Some(n)
            if n >= paper::CONVERGED_PARTICLES / factor
                && n <= paper::CONVERGED_PARTICLES * factor =>
        {
            (
                Verdict::Reproduced,
                format!("converged from {n}, within a factor {factor} of the paper's count"),
            )
        }
        Some(n) => (
            Verdict::Partly,
            format!(
                "F converges, but from {n}, not about {}",
                short(paper::CONVERGED_PARTICLES)
            ),
        ),
        None => {
            let (first, last) = (changes.first().copied(), changes.last().copied());
            let shrinking = matches!((first, last), (Some(a), Some(b)) if b < a);
            let why = if n_max < paper::CONVERGED_PARTICLES / factor {
                format!(
                    "; this tier's largest count, {n_max}, is far below the paper's {}",
                    short(paper::CONVERGED_PARTICLES)
                )
            } else {
                String::new()
            };
            if shrinking {
                (
                    Verdict::Partly,
                    format!(
                        "F's steps shrink with N but stay above {} %{why}",
                        100.0 * decide::CONVERGENCE_TOLERANCE
                    ),
                )
            } else {
                (Verdict::Not, format!("F does not settle{why}"))
            }
        }
    }
}

/// The finest run's side view and 3-D series, copied into the report.
fn collect_fig11(ctx: &Ctx, run_dir: &Path) -> Result<Vec<String>> {
    ctx.collect_all(&[
        (run_dir.join("cloud_side.png"), "fig11_side.png"),
        (run_dir.join("cloud_series.png"), "fig12_series.png"),
    ])
}

/// Figs. 11-12's numbers and verdict from the finest run: its record, the step numbers of its
/// `summary.json`, and its score against the calibration shot.
fn fig11_numbers(f11: &mut Figure, rec: &Record, run_dir: &Path, targets: &Targets) {
    let summary = read_summary(run_dir);
    let o = &rec.observables;
    let n = o.get(Observable::Particles).unwrap_or(f64::NAN);
    f11.number(
        "particles",
        Value::num(Some(n)),
        format!("paper: {}", short(paper::FINAL_PARTICLES)),
    );
    f11.number(
        "time step (s)",
        Value::num(summary.as_ref().map(|s| s.dt_s)),
        format!(
            "the paper's {} s at \u{3c3}_ref, scaled with \u{3c3} (or as set)",
            short(paper::TIME_STEP_S)
        ),
    );
    f11.number(
        "steps",
        Value::num(summary.as_ref().map(|s| s.steps as f64)),
        "",
    );
    f11.number(
        "analysis time \u{3c4} (\u{b5}s)",
        Value::num(o.get(Observable::Tau).map(|t| t * 1e6)),
        format!("paper: {}", paper::ANALYSIS_TIME_S * 1e6),
    );
    observable_numbers(f11, o);
    let score = objective(&targets.targets, |name| o.get(name));
    f11.number(
        "objective J against the calibration shot",
        Value::num(Some(score.objective)),
        "<= 1: every target within tolerance (experiments_data/README.md)",
    );
    for t in &score.terms {
        f11.number(
            format!("term {}", t.name),
            Value::num(Some(t.term)),
            format!("weight {}", t.weight),
        );
    }
    f11.timing(
        "run time (s)",
        Value::num(Some(rec.wall_seconds)),
        format!("on {} thread(s)", rec.threads),
    );
    f11.timing(
        "particle-steps/s",
        Value::num(
            summary
                .as_ref()
                .map(|s| s.particle_steps_per_second)
                .filter(|v| v.is_finite()),
        ),
        format!(
            "the paper's run: {} on one processor",
            fmt_num(paper_particle_steps_per_second())
        ),
    );
    f11.ours = fig11_ours(n, o, &score);
    (f11.verdict, f11.reason) = fig11_verdict(rec, n, &score);
}

/// The best-fit run's cloud beside the experiment's (or the witness plate's) evidence.
fn observable_numbers(f11: &mut Figure, o: &Observables) {
    for (name, x, note) in [
        (
            "R = La/Lr",
            o.get(Observable::LengthRatio),
            format!("the experiment: {}", paper::CALIBRATION_SHOT_LENGTH_RATIO),
        ),
        ("F", o.get(Observable::Fragmentation), String::new()),
        (
            "va/v0",
            o.get(Observable::FrontVelocityRatio),
            "the experiment's: a documented gap".to_string(),
        ),
        (
            "largest fragment / impactor mass",
            o.get(Observable::LargestFragmentMassFraction),
            "the witness plate: no large central fragment".to_string(),
        ),
        (
            "mean fragment diameter (mm)",
            o.get(Observable::MeanFragmentDiameter).map(|d| d * 1e3),
            "the witness plate: ~1 mm craters".to_string(),
        ),
    ] {
        f11.number(name, Value::num(x), note);
    }
}

/// The paper's final run's throughput: N x (tau / dt) particle-steps in its stated wall time.
fn paper_particle_steps_per_second() -> f64 {
    paper::FINAL_PARTICLES * (paper::ANALYSIS_TIME_S / paper::TIME_STEP_S)
        / paper::PAPER_WALL_SECONDS
}

fn fig11_ours(n: f64, o: &Observables, score: &Score) -> String {
    format!(
        "N = {n}, R = {}, F = {}, va/v0 = {}, largest fragment {} of the impactor, J = {}",
        o.get(Observable::LengthRatio).map_or("n/a".into(), fmt_num),
        o.get(Observable::Fragmentation)
            .map_or("n/a".into(), fmt_num),
        o.get(Observable::FrontVelocityRatio)
            .map_or("n/a".into(), fmt_num),
        o.get(Observable::LargestFragmentMassFraction)
            .map_or("n/a".into(), |x| format!("{:.1} %", 100.0 * x)),
        fmt_num(score.objective)
    )
}

/// Reproduced when the run completed at the paper's count and meets every target.
fn fig11_verdict(rec: &Record, n: f64, score: &Score) -> (Verdict, String) {
    if rec.status != RunStatus::Completed {
        return (
            Verdict::Not,
            format!("the run failed: {}", rec.error.as_deref().unwrap_or("")),
        );
    }
    let at_paper_n = (n / paper::FINAL_PARTICLES - 1.0).abs() < 0.02;
    let met = score.objective <= 1.0;
    let mut why = Vec::new();
    if !at_paper_n {
        why.push(format!(
            "{n} particles, not the paper's {}",
            short(paper::FINAL_PARTICLES)
        ));
    }
    if !met {
        let worst = score
            .terms
            .iter()
            .filter(|t| t.term > 1.0)
            .map(|t| t.name.clone())
            .collect::<Vec<_>>()
            .join(", ");
        why.push(format!(
            "the calibration shot's targets are missed (J = {}: {worst})",
            fmt_num(score.objective)
        ));
    }
    if why.is_empty() {
        (
            Verdict::Reproduced,
            "at the paper's resolution the best fit meets every target of the calibration shot"
                .into(),
        )
    } else {
        (Verdict::Partly, format!("drawn, but {}", why.join("; ")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fig5_verdict_from_the_convergence_count() {
        let n = paper::CONVERGED_PARTICLES;
        let fs = [0.5, 0.6, 0.61];
        assert_eq!(fig5_verdict(&fs, &[], Some(n), n).0, Verdict::Reproduced);
        assert_eq!(fig5_verdict(&fs, &[], Some(10.0 * n), n).0, Verdict::Partly);
        // Not converged: shrinking steps are partly, growing ones are not.
        assert_eq!(fig5_verdict(&fs, &[0.2, 0.1], None, n).0, Verdict::Partly);
        assert_eq!(fig5_verdict(&fs, &[0.1, 0.2], None, n).0, Verdict::Not);
        // A failed run decides before anything else.
        let failed = [0.5, f64::NAN];
        assert_eq!(fig5_verdict(&failed, &[], Some(n), n).0, Verdict::Not);
    }
}
