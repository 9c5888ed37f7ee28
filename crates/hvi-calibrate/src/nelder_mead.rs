//! The search by Nelder-Mead (`calibrate.method = "nelder-mead"`): argmin's simplex from the
//! best grid point, one run at a time. Termination is whichever comes first: `max_iters`
//! iterations, or the standard deviation of the objective over the simplex below
//! `sd_tolerance` (argmin's criterion). A point outside the box, or one whose scene the engine
//! rejects, costs [`OUTSIDE_COST`] without a run.

use argmin::core::{CostFunction, Executor, State, TerminationReason, TerminationStatus};
use argmin::solver::neldermead::NelderMead;
use hvi_run::error::{Result, RunError};
use hvi_store::plan::Plan;

use crate::config::CalibrateConfig;
use crate::problem::{fmt_params, Dim, Refinement, OUTSIDE_COST};
use crate::result::EvalStage;
use crate::result::Evaluation;

/// Argmin's executor owns its problem; this lends it the refinement.
pub(super) struct Lend<'r, 'a>(&'r Refinement<'a>);

impl CostFunction for Lend<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Self::Param) -> std::result::Result<f64, argmin::core::Error> {
        let this = self.0;
        this.cost_of(x).map_err(argmin::core::Error::from)
    }
}

impl Refinement<'_> {
    fn cost_of(&self, x: &[f64]) -> Result<f64> {
        let params = self.values(x);
        let inside = self
            .dims
            .iter()
            .zip(x)
            .all(|(Dim { lo, hi, .. }, &u)| u >= lo - 1e-9 && u <= hi + 1e-9);
        let e = if inside {
            self.evaluate(EvalStage::Refine, &params)?
        } else {
            let step = self
                .log
                .borrow()
                .iter()
                .filter(|e| e.stage == EvalStage::Refine)
                .count();
            Evaluation {
                stage: EvalStage::Refine,
                step,
                params: params.clone(),
                score: None,
                objective: OUTSIDE_COST,
                status: "outside the grid's box: not run".into(),
                cached: false,
                dir: None,
                seeds: Vec::new(),
                seed_objectives: Vec::new(),
                means: Default::default(),
            }
        };
        if self.progress {
            log::info!(
                "refine {:>2}: {}  J = {:.4}{}",
                e.step,
                fmt_params(&e.params),
                e.objective,
                if e.cached {
                    " (cached)".to_string()
                } else if e.status != "completed" {
                    format!(" ({})", e.status)
                } else {
                    String::new()
                }
            );
        }
        let j = e.objective;
        self.log.borrow_mut().push(e);
        Ok(j)
    }
}

/// Why Nelder-Mead stopped, in words, and whether its own stopping rule (the simplex's sd
/// tolerance) ended it, read from the solver's state.
pub(super) struct Refined {
    /// The solver's termination and its iteration count, in words.
    pub termination: String,
    /// The solver converged (argmin's `TerminationReason::SolverConverged`).
    pub converged: bool,
}

/// Stage 2: Nelder-Mead from the best grid point (unless skipped). Returns why it stopped;
/// the evaluations stay in the problem's log.
pub(super) fn refine_stage(
    problem: &Refinement,
    cfg: &CalibrateConfig,
    max_iters: Option<u64>,
    best_grid: &Evaluation,
    refine_keys: &[String],
) -> Result<Refined> {
    let dims = &problem.dims;
    let max_iters = max_iters.unwrap_or(cfg.max_iters);
    if dims.is_empty() || max_iters == 0 {
        let why = if dims.is_empty() {
            "skipped: no axis to refine"
        } else {
            "skipped (max_iters = 0)"
        };
        return Ok(Refined {
            termination: why.to_string(),
            converged: false,
        });
    }
    let simplex = start_simplex(problem.plan, dims, best_grid);
    if problem.progress {
        log::info!(
            "refinement: Nelder-Mead over {} (log10 for {:?}), at most {max_iters} iterations, sd tolerance {}",
            refine_keys.join(", "),
            dims.iter().filter(|d| d.log).map(|d| d.key.as_str()).collect::<Vec<_>>(),
            cfg.sd_tolerance
        );
    }
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(cfg.sd_tolerance)
        .map_err(|e| RunError::Input(format!("{e}")))?;
    let res = Executor::new(Lend(problem), solver)
        .configure(|s| s.max_iters(max_iters))
        .run()
        .map_err(|e| RunError::Input(format!("refinement: {e:#}")))?;
    let st = res.state();
    Ok(Refined {
        termination: format!(
            "{} after {} iterations",
            st.get_termination_status(),
            st.get_iter()
        ),
        converged: matches!(
            st.get_termination_status(),
            TerminationStatus::Terminated(TerminationReason::SolverConverged)
        ),
    })
}

/// The start simplex: the best grid point and one step along each refined axis (half the
/// grid's spacing on that axis, towards the inside of the box).
pub(super) fn start_simplex(plan: &Plan, dims: &[Dim], best_grid: &Evaluation) -> Vec<Vec<f64>> {
    let x0: Vec<f64> = dims
        .iter()
        .map(|Dim { key: k, log, .. }| {
            let x = best_grid.params.get(k).copied().unwrap_or(f64::NAN);
            if *log {
                x.log10()
            } else {
                x
            }
        })
        .collect();
    let mut simplex = vec![x0.clone()];
    for (d, Dim { key: k, lo, hi, .. }) in dims.iter().enumerate() {
        let n = plan
            .axes
            .iter()
            .find(|a| &a.key == k)
            .map_or(2, |a| a.values.len());
        let step = 0.5 * (hi - lo) / (n.max(2) - 1) as f64;
        let mut v = x0.clone();
        v[d] = if x0[d] + step <= *hi + 1e-12 {
            x0[d] + step
        } else {
            x0[d] - step
        };
        simplex.push(v);
    }
    simplex
}
