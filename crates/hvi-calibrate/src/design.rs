//! The grid stage's design: which of the study grid's points a calibration runs before its
//! search (`calibrate.initial_design`, docs/calibration.md "Stages").
//!
//! `grid` runs every point. `corners` runs, over the searched axes, the box's corners and the
//! grid point nearest its centre (in the search's coordinates: log10 on a log axis), at every
//! value of the axes not searched: 5 of the shipped study's 12 points. The rest of the grid
//! stays the lattice the box extends on; an extension runs the lattice's points near the
//! answer that no run has scored yet, so the points a corner design skipped near the answer are
//! run then.

use hvi_store::plan::Plan;

use crate::config::InitialDesign;
use crate::problem::Dim;
use crate::result::DesignUse;

/// The positions in `plan.runs` of the design's points, in plan order.
pub fn design_runs(plan: &Plan, dims: &[Dim], design: InitialDesign) -> Vec<usize> {
    if design == InitialDesign::Grid {
        return (0..plan.runs.len()).collect();
    }
    // Per searched axis: its position among the plan's axes and its low, high and centre
    // value indices.
    let picks: Vec<(usize, [usize; 3])> = dims
        .iter()
        .filter_map(|d| {
            let k = plan.axes.iter().position(|a| a.key == d.key)?;
            let coords: Vec<f64> = plan.axes[k]
                .values
                .iter()
                .map(|v| {
                    v.as_f64()
                        .map_or(f64::NAN, |x| if d.log { x.log10() } else { x })
                })
                .collect();
            Some((k, corner_and_centre(&coords)?))
        })
        .collect();
    (0..plan.runs.len())
        .filter(|&i| {
            let at = &plan.runs[i].coords;
            let corner = picks
                .iter()
                .all(|&(k, [lo, hi, _])| at[k] == lo || at[k] == hi);
            let centre = picks.iter().all(|&(k, [.., c])| at[k] == c);
            corner || centre
        })
        .collect()
}

/// The indices of the lowest, the highest and the centre value of one axis's coordinates (the
/// centre: nearest the middle of the two, the lower on a tie). None when a coordinate is not
/// a number.
fn corner_and_centre(coords: &[f64]) -> Option<[usize; 3]> {
    if coords.is_empty() || coords.iter().any(|c| !c.is_finite()) {
        return None;
    }
    let by = |pick: fn(f64, f64) -> bool| {
        (0..coords.len()).fold(0, |b, i| if pick(coords[i], coords[b]) { i } else { b })
    };
    let lo = by(|a, b| a < b);
    let hi = by(|a, b| a > b);
    let mid = 0.5 * (coords[lo] + coords[hi]);
    // Distances compared with a tolerance: factor-2 steps on a log axis tie exactly only in
    // exact arithmetic.
    let tol = 1e-9 * (coords[hi] - coords[lo]).abs().max(1e-300);
    let centre = (0..coords.len()).fold(lo, |b, i| {
        let (di, db) = ((coords[i] - mid).abs(), (coords[b] - mid).abs());
        if di < db - tol || (di <= db + tol && coords[i] < coords[b]) {
            i
        } else {
            b
        }
    });
    Some([lo, hi, centre])
}

/// The plan restricted to the runs at `runs` (positions in `plan.runs`): what the grid stage
/// runs, scores and draws. Each run keeps its own index and directory.
pub fn design_plan(plan: &Plan, runs: &[usize]) -> Plan {
    Plan {
        runs: runs.iter().map(|&i| plan.runs[i].clone()).collect(),
        ..plan.clone()
    }
}

/// Each shot's plan restricted to the design's points (the same grid points of every shot's
/// grid, chosen on the first's), and the design as the result records it.
pub fn design_plans(
    plans: &[&Plan],
    dims: &[Dim],
    design: InitialDesign,
) -> (Vec<Plan>, DesignUse) {
    let runs = design_runs(plans[0], dims, design);
    let used = DesignUse {
        name: design.name().into(),
        points: runs.len(),
        grid_points: plans[0].runs.len(),
    };
    (plans.iter().map(|p| design_plan(p, &runs)).collect(), used)
}

/// The position in `plan.runs` of the run whose index in the study's plan is `index` (a
/// design plan holds a subset of the study's runs, each with its own index).
pub fn position(plan: &Plan, index: usize) -> hvi_run::error::Result<usize> {
    plan.runs
        .iter()
        .position(|r| r.index == index)
        .ok_or_else(|| {
            hvi_run::error::RunError::Input(format!(
                "run {index} of the study's grid is not among the grid stage's runs"
            ))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_is_nearest_the_middle_lower_on_a_tie() {
        let log = |v: &[f64]| v.iter().map(|x: &f64| x.log10()).collect::<Vec<_>>();
        // eps: 0.01, 0.1, 1 -> the middle value.
        assert_eq!(corner_and_centre(&log(&[0.01, 0.1, 1.0])), Some([0, 2, 1]));
        // kappa in factor-2 steps: 2.28e6 and 4.56e6 tie in log10; the lower.
        assert_eq!(
            corner_and_centre(&log(&[1.14e6, 2.28e6, 4.56e6, 9.12e6])),
            Some([0, 3, 1])
        );
        // Unsorted values, linear: 1.3, 1.8, 1.5 -> 1.5 is at index 2.
        assert_eq!(corner_and_centre(&[1.3, 1.8, 1.5]), Some([0, 1, 2]));
        // Two values: the centre is a corner.
        assert_eq!(corner_and_centre(&[1.0, 2.0]), Some([0, 1, 0]));
        assert_eq!(corner_and_centre(&[1.0]), Some([0, 0, 0]));
        assert_eq!(corner_and_centre(&[]), None);
        assert_eq!(corner_and_centre(&[1.0, f64::NAN]), None);
    }

    /// The shipped calibration study's grid (eps 3 values x kappa 4 x rcut 1): the four
    /// corners and (0.1 J, 2.28e6 N/m); `grid` keeps all 12.
    #[test]
    fn corners_of_the_shipped_grid() {
        let study =
            hvi_store::spec::Study::load(std::path::Path::new("../../studies/calibration.toml"))
                .expect("the shipped study");
        let plan = hvi_store::plan::build_plan(&study, &hvi_store::plan::PlanRequest::default())
            .expect("plan");
        let cfg = crate::CalibrateConfig::of(&study).expect("[calibrate]");
        let (_, dims) = crate::problem::refined_axes(&plan, &cfg).expect("axes");
        assert_eq!(design_runs(&plan, &dims, InitialDesign::Grid).len(), 12);
        let picked: Vec<(f64, f64)> = design_runs(&plan, &dims, InitialDesign::Corners)
            .iter()
            .map(|&i| {
                let v = &plan.runs[i].values;
                (v[0].as_f64().expect("eps"), v[1].as_f64().expect("kappa"))
            })
            .collect();
        assert_eq!(
            picked,
            vec![
                (0.01, 1.14e6),
                (0.01, 9.12e6),
                (0.1, 2.28e6),
                (1.0, 1.14e6),
                (1.0, 9.12e6)
            ]
        );
        let sub = design_plan(&plan, &design_runs(&plan, &dims, InitialDesign::Corners));
        assert_eq!(sub.runs.len(), 5);
        assert_eq!(
            sub.runs[2].index, 5,
            "a run keeps its index in the study's plan"
        );
        assert_eq!(position(&sub, 5).expect("run 5"), 2);
        assert!(position(&sub, 4).is_err());
    }
}
