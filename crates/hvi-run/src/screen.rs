//! The screen (`run.screen_after_s`): at a set time after first contact, what free flight
//! from then would give at the analysis time, measured on a copy of the state; when a
//! measurement lies outside its window (`run.screen_length_ratio`,
//! `run.screen_front_velocity_ratio`) the run itself goes on in free flight from then, as
//! `run.free_flight_after_s` at the same time would, instead of computing the rest.
//!
//! Free flight from 8 us after contact moves R and va/v0 by at most 0.5 % on the calibration
//! scene at 2.7e5 particles (docs/model-decisions.md, "Time to an answer"); the fragment sizes
//! it moves far more, so a screen reads only these two. A study sets the windows where a run
//! outside them is far from its targets whatever its fragments (`hvi-study calibrate`,
//! docs/calibration.md, "The screen"): such a run needs to be known as far, not computed to
//! the end. A run inside every window goes on exactly as without a screen.

use hvi_engine::cloud::{first_step_at_or_after, label_fragments, CloudObserver};
use hvi_engine::scene::{Derived, RunSettings};
use hvi_engine::sim::Simulation;
use serde::{Deserialize, Serialize};

/// What the screen measured (`summary.json`'s `screen`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScreenReport {
    /// When it looked: the time since first contact, s.
    pub tau_s: f64,
    /// The length ratio (the scene's reading) free flight from then gives at the analysis
    /// time; null without a cloud.
    pub length_ratio: Option<f64>,
    /// va / v0 likewise.
    pub front_velocity_ratio: Option<f64>,
    /// Whether a measurement lay outside its window, so that the run went on in free flight.
    pub free_flight: bool,
}

/// The base step at which the screen looks, if the scene asks for one: the first energy
/// sample (`run.energy_every`) at or after `run.screen_after_s` since first contact. The run
/// lands there anyway, so a run the screen lets go on is the run without a screen, bit for
/// bit. (A screen due after the last sample does not look.)
pub fn screen_step(run: &RunSettings, d: &Derived) -> Option<u64> {
    run.screen_after_s.map(|t| {
        let s = first_step_at_or_after(d, t);
        s.div_ceil(run.energy_every) * run.energy_every
    })
}

/// Screens the run now: measures free flight from now to the end on a copy of `sim` (with a
/// copy of the run's `observer`, so the front samples already taken count), and when a
/// measurement lies outside its window starts free flight in `sim` itself.
pub fn screen(
    sim: &mut Simulation,
    run: &RunSettings,
    observer: Option<&CloudObserver>,
) -> ScreenReport {
    let labels = label_fragments(&sim.particles);
    let (length_ratio, front_velocity_ratio) = probe(sim, &labels, observer);
    let outside = |w: Option<[f64; 2]>, x: Option<f64>| match (w, x) {
        (Some([lo, hi]), Some(x)) => !(lo..=hi).contains(&x),
        _ => false,
    };
    let free_flight = outside(run.screen_length_ratio, length_ratio)
        || outside(run.screen_front_velocity_ratio, front_velocity_ratio);
    if free_flight {
        sim.start_coasting(&labels);
    }
    ScreenReport {
        tau_s: sim.tau_s(),
        length_ratio,
        front_velocity_ratio,
        free_flight,
    }
}

/// R and va/v0 at the end of the run if its fragments (`labels`) flew freely from now on: a
/// copy of the state coasted to each front time still to come and to the end.
fn probe(
    sim: &Simulation,
    labels: &[u32],
    observer: Option<&CloudObserver>,
) -> (Option<f64>, Option<f64>) {
    let Some(mut observer) = observer.cloned() else {
        return (None, None);
    };
    let mut copy = sim.clone();
    copy.start_coasting(labels);
    let end = copy.derived.steps;
    while copy.step < end {
        let next = observer.next_front(copy.step).map_or(end, |f| f.min(end));
        // In free flight a step is rigid motion: it cannot fail.
        if copy.step_until(next).is_err() {
            return (None, None);
        }
        observer.observe(&copy);
    }
    match observer.finish(&copy) {
        Some(c) => (
            c.report.measurement.length_ratio,
            c.report.front_velocity_ratio,
        ),
        None => (None, None),
    }
}

#[cfg(test)]
mod tests {
    use crate::run::{run_scene, RunOptions, RunOutcome};
    use hvi_engine::scene::SceneSpec;

    /// A run the screen lets go on is the run without a screen, bit for bit; one it sends on
    /// in free flight is the run with `run.free_flight_after_s` at the screen's step, bit for
    /// bit; and what the screen measured is what that free flight gives at the end.
    #[test]
    fn a_screen_goes_on_in_full_or_in_free_flight_and_measures_the_free_flight() {
        let base = std::env::temp_dir().join(format!("hvi-screen-{}", std::process::id()));
        let spec = SceneSpec::calibration(1000.0, 4e-6);
        let opts = |dir: &str| RunOptions {
            out_dir: base.join(dir),
            ..RunOptions::default()
        };
        let plain = run_scene(&spec, &opts("plain")).expect("runs");
        // R of a run's cloud at the end.
        let r_of = |o: &RunOutcome| {
            o.summary
                .cloud
                .as_ref()
                .and_then(|c| c.measurement.length_ratio)
                .expect("a cloud with R")
        };
        let r_full = r_of(&plain);
        let screened = |window: [f64; 2], dir: &str| {
            let mut s = spec.clone();
            s.run.screen_after_s = Some(1.5e-6);
            s.run.screen_length_ratio = Some(window);
            run_scene(&s, &opts(dir)).expect("runs")
        };
        let inside = screened([0.0, 100.0], "inside");
        let report = inside.summary.screen.expect("the screen looked");
        assert!(!report.free_flight);
        assert_eq!(
            inside.energy, plain.energy,
            "inside the window: the run without a screen"
        );
        assert_eq!(inside.summary.cloud, plain.summary.cloud);
        assert_eq!(inside.summary.ballistic_cutoff_tau_s, None);
        // The screen looks at the first energy sample at or after its time.
        let every = spec.run.energy_every as f64 * plain.summary.dt_s;
        assert!(
            (1.5e-6..1.5e-6 + every).contains(&report.tau_s),
            "{}",
            report.tau_s
        );

        let r = report.length_ratio.expect("a cloud");
        let outside = screened([r + 1.0, r + 2.0], "outside");
        let out = outside.summary.screen.expect("the screen looked");
        assert!(out.free_flight);
        assert_eq!(out.length_ratio, report.length_ratio, "the same probe");
        let tau = outside
            .summary
            .ballistic_cutoff_tau_s
            .expect("free flight began");
        assert_eq!(tau, out.tau_s);
        let mut coast = spec.clone();
        coast.run.free_flight_after_s = Some(out.tau_s - 0.5 * plain.summary.dt_s);
        let coasted = run_scene(&coast, &opts("coasted")).expect("runs");
        assert_eq!(coasted.summary.ballistic_cutoff_tau_s, Some(tau));
        assert_eq!(
            outside.energy, coasted.energy,
            "outside: free flight from the screen on"
        );
        let r_ff = r_of(&outside);
        assert_eq!(r_ff, r_of(&coasted));
        // The probe coasted in fewer steps than the run: the same R to round-off.
        assert!((r - r_ff).abs() <= 1e-12 * r, "probe {r}, run {r_ff}");
        assert_ne!(r_ff, r_full, "free flight from 1.5 us is not the full run");
        assert!(outside.summary.steps < plain.summary.steps);
        let _ = std::fs::remove_dir_all(&base);
    }
}
