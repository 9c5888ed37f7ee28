//! The screen of a calibration's runs (`calibrate.screen`, docs/calibration.md, "The
//! screen"): a run whose length ratio or va/v0 alone puts J above `calibrate.screen_above`
//! needs to be known as far from the targets, not computed to the end.
//!
//! Each run the calibration makes carries the scene keys of `hvi_run::screen`: at
//! `calibrate.screen_after_transits` times its shot's transit time D/v0 after first contact,
//! or `calibrate.screen_after_plate_transits` times the plate's t/v0 if later (a thick plate's
//! debris front slows for longer), it measures what free flight from then gives at the
//! analysis time, and outside the windows set here it goes on in free flight. A shot whose
//! plate is thicker than `calibrate.screen_max_t_over_d` is not screened. The windows
//! come from the shot's targets on `length_ratio` and `front_velocity_ratio` (the two
//! observables free flight from that time moved by at most 3.7 % over the shots measured,
//! docs/model-decisions.md): outside a window that one term exceeds the larger of 1 (the
//! target is missed) and the term that alone makes J = `screen_above`, with every window
//! widened by `screen_allowance` of the target's value for what free flight moves them. A
//! run inside every window goes on in full, bit for bit the run without a screen. A run the
//! store already holds without a screen is taken as it is (a screen never repeats a run).

use hvi_analysis::observable::Observable;
use hvi_analysis::score::{Target, TargetKind, Targets};
use hvi_engine::scene::SceneSpec;
use hvi_run::error::Result;
use hvi_store::plan::{fingerprint, run_dir_name, Plan};
use hvi_store::store::{Job, Store};

use crate::config::CalibrateConfig;

/// The screen's windows for one shot's runs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Windows {
    /// On the length ratio (the scene's reading).
    pub length_ratio: Option<[f64; 2]>,
    /// On va / v0.
    pub front_velocity_ratio: Option<[f64; 2]>,
}

impl Windows {
    fn any(&self) -> bool {
        self.length_ratio.is_some() || self.front_velocity_ratio.is_some()
    }
}

/// The screen of one shot's runs: when it looks and its windows.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ShotScreen {
    /// Time after first contact at which the shot's runs are screened, s: the later of
    /// `calibrate.screen_after_transits` times the shot's [`transit_s`] and
    /// `calibrate.screen_after_plate_transits` times its [`plate_transit_s`].
    pub after_s: f64,
    /// Its windows (none when its plate is too thick).
    pub windows: Windows,
    /// Its plate's t/D as simulated.
    pub t_over_d: f64,
}

/// The screen of a calibration: each shot's time and windows (none: off).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Screen {
    /// The time, in transit times D/v0 (`calibrate.screen_after_transits`).
    pub transits: f64,
    /// The time, in the plate's transit times t/v0 when later
    /// (`calibrate.screen_after_plate_transits`).
    pub plate_transits: f64,
    /// The thickest plate screened, t/D (`calibrate.screen_max_t_over_d`).
    pub max_t_over_d: f64,
    /// Per shot, in the calibration's order.
    pub shots: Vec<ShotScreen>,
}

impl Screen {
    /// No screen: every run in full (the ladder's check, a held-out shot's prediction).
    pub fn off() -> Screen {
        Screen::default()
    }

    /// The screen `cfg` asks for over the shots' `targets` (off with `calibrate.screen =
    /// false`).
    pub fn of(cfg: &CalibrateConfig, targets: &[Targets]) -> Screen {
        if !cfg.screen {
            return Screen::off();
        }
        let shots = targets.len();
        Screen {
            transits: cfg.screen_after_transits,
            plate_transits: cfg.screen_after_plate_transits,
            max_t_over_d: cfg.screen_max_t_over_d,
            shots: targets
                .iter()
                .map(|t| {
                    let t_over_d = t.shot.simulated_t_over_d();
                    ShotScreen {
                        after_s: (cfg.screen_after_transits * transit_s(t))
                            .max(cfg.screen_after_plate_transits * plate_transit_s(t)),
                        windows: if t_over_d > cfg.screen_max_t_over_d {
                            Windows::default()
                        } else {
                            windows_of(t, shots, cfg.screen_above, cfg.screen_allowance)
                        },
                        t_over_d,
                    }
                })
                .collect(),
        }
    }

    /// Whether shot `shot`'s plate is thicker than `calibrate.screen_max_t_over_d`, so that
    /// its runs go in full.
    pub fn too_thick(&self, shot: usize) -> bool {
        self.shots
            .get(shot)
            .is_some_and(|s| s.t_over_d > self.max_t_over_d)
    }

    /// The scene of shot `shot`'s run with the screen's keys, or None when the shot has no
    /// window, or the screen would come at or after the run's end or its free flight.
    fn screened(&self, shot: usize, scene: &SceneSpec) -> Option<SceneSpec> {
        let ShotScreen {
            after_s,
            windows: w,
            ..
        } = *self.shots.get(shot)?;
        let run = &scene.run;
        if !w.any()
            || run.end_time_s <= after_s
            || run.free_flight_after_s.is_some_and(|t| t <= after_s)
            || run.screen_after_s.is_some()
        {
            return None;
        }
        let mut scene = scene.clone();
        scene.run.screen_after_s = Some(after_s);
        scene.run.screen_length_ratio = w.length_ratio;
        scene.run.screen_front_velocity_ratio = w.front_velocity_ratio;
        Some(scene)
    }

    /// The run of `job` (shot `shot`'s) as the calibration makes it: the job as it is when
    /// the store holds it finished or it is not screened (no window, or the screen at or after
    /// its end or its free flight); else the job with the screen's keys (a run of its own in
    /// the store).
    pub fn apply(&self, shot: usize, job: Job, store: &Store) -> Result<Job> {
        let Some(scene) = self.screened(shot, &job.scene) else {
            return Ok(job);
        };
        if store.holds_finished(&job.fingerprint) {
            return Ok(job);
        }
        Ok(Job {
            fingerprint: fingerprint(&scene, &job.tier)?,
            scene,
            ..job
        })
    }

    /// Shot `shot`'s plan as the calibration runs it: each run as [`Self::apply`] makes it
    /// (against `store`, if the study directory has one), its overrides listing the screen's,
    /// so that the study directory's `plan.json` names the runs the calibration holds.
    pub fn apply_to_plan(&self, shot: usize, plan: &mut Plan, store: Option<&Store>) -> Result<()> {
        for run in &mut plan.runs {
            let Some(scene) = self.screened(shot, &run.scene) else {
                continue;
            };
            if store.is_some_and(|s| s.holds_finished(&run.fingerprint)) {
                continue;
            }
            let r = &scene.run;
            let window = |w: Option<[f64; 2]>| w.map(|[lo, hi]| format!("[{lo:?}, {hi:?}]"));
            if let Some(t) = r.screen_after_s {
                run.set.push(format!("run.screen_after_s={t:?}"));
            }
            if let Some(w) = window(r.screen_length_ratio) {
                run.set.push(format!("run.screen_length_ratio={w}"));
            }
            if let Some(w) = window(r.screen_front_velocity_ratio) {
                run.set.push(format!("run.screen_front_velocity_ratio={w}"));
            }
            run.fingerprint = fingerprint(&scene, &plan.tier)?;
            run.dir = run_dir_name(&run.fingerprint);
            run.scene = scene;
        }
        Ok(())
    }
}

/// A shot's transit time D/v0 as simulated, s: the time the impactor takes to travel its own
/// diameter, the scale the cloud forms on.
pub fn transit_s(targets: &Targets) -> f64 {
    targets.shot.impactor_diameter_m / targets.shot.simulated_v0_m_s()
}

/// A shot's plate transit time t/v0 as simulated, s: the time the impactor takes to travel
/// the plate's thickness. Behind a thick plate the debris front goes on slowing after the
/// impactor's transits have made the cloud (docs/model-decisions.md).
pub fn plate_transit_s(targets: &Targets) -> f64 {
    targets.shot.simulated_t_over_d() * transit_s(targets)
}

/// One shot's windows: on each observable the screen reads, the intersection of the windows
/// of the shot's targets on it (none when they leave nothing, or without such a target).
/// `shots` is the number of shots J is the mean over.
pub fn windows_of(targets: &Targets, shots: usize, above: f64, allowance: f64) -> Windows {
    let total: f64 = targets.targets.iter().map(|t| t.weight).sum();
    let on = |o: Observable| {
        let mut window: Option<[f64; 2]> = None;
        for t in targets
            .targets
            .iter()
            .filter(|t| t.observable == o && t.weight > 0.0)
        {
            // The term that alone makes J = above: w t / (S W) = above.
            let term = (above * shots as f64 * total / t.weight).max(1.0);
            let [lo, hi] = target_window(t, term, allowance);
            window = Some(match window {
                Some([a, b]) => [a.max(lo), b.min(hi)],
                None => [lo, hi],
            });
        }
        window.filter(|[lo, hi]| lo < hi)
    };
    Windows {
        length_ratio: on(Observable::LengthRatio),
        front_velocity_ratio: on(Observable::FrontVelocityRatio),
    }
}

/// Where `t`'s term is at most `term`, widened by `allowance` of the target's value on each
/// side (an `at_most` target has no low side: its low end is the lowest finite number).
fn target_window(t: &Target, term: f64, allowance: f64) -> [f64; 2] {
    let reach = term.sqrt();
    let pad = allowance * t.value.abs();
    match t.kind {
        TargetKind::Value => {
            let h = t.tolerance * reach;
            [t.value - h - pad, t.value + h + pad]
        }
        TargetKind::AtMost => [f64::MIN, t.value + t.tolerance * reach + pad],
        TargetKind::LogValue => {
            let f = t.tolerance.powf(reach);
            [t.value / f - pad, t.value * f + pad]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvi_analysis::score::term;

    fn target(name: &str, o: Observable, kind: TargetKind, value: f64, tol: f64) -> Target {
        Target {
            name: name.into(),
            observable: o,
            kind,
            value,
            tolerance: tol,
            weight: 1.0,
            source: String::new(),
        }
    }

    fn shot(targets: Vec<Target>) -> Targets {
        let text = "[shot]\nid = \"s\"\ndescription = \"d\"\nsource = \"s\"\nimpactor_diameter_m = 0.01\nimpactor_material = \"aluminium\"\nplate_material = \"aluminium\"\nv0_m_s = 6500.0\nt_over_d = 0.4\n\n[[targets]]\nname = \"x\"\nobservable = \"length_ratio\"\nkind = \"value\"\nvalue = 1.0\ntolerance = 0.1\nweight = 1.0\nsource = \"s\"\n";
        let mut t = Targets::parse(text, std::path::Path::new("s.toml")).expect("in the test");
        t.targets = targets;
        t
    }

    /// At a window's edge the screened term alone makes J exactly the threshold; inside it,
    /// less. So a screened run (outside) is above the threshold whatever its other terms.
    #[test]
    fn a_window_edge_is_where_one_term_alone_reaches_the_threshold() {
        let r = target("r", Observable::LengthRatio, TargetKind::Value, 1.55, 0.1);
        let frag = target(
            "f",
            Observable::MeanFragmentDiameter,
            TargetKind::LogValue,
            1e-3,
            3.0,
        );
        let large = target(
            "l",
            Observable::LargestFragmentMassFraction,
            TargetKind::AtMost,
            0.05,
            0.05,
        );
        let t = shot(vec![r.clone(), large, frag]);
        let w = windows_of(&t, 1, 1.0, 0.0);
        let [lo, hi] = w.length_ratio.expect("in the test");
        assert!(w.front_velocity_ratio.is_none(), "no target on va/v0");
        for edge in [lo, hi] {
            let j = term(&r, Some(edge)) / 3.0;
            assert!((j - 1.0).abs() < 1e-9, "J at the edge {edge}: {j}");
        }
        // Widened by 2 % of 1.55 on each side.
        let padded = windows_of(&t, 1, 1.0, 0.02)
            .length_ratio
            .expect("in the test");
        assert!((lo - padded[0] - 0.031).abs() < 1e-12 && (padded[1] - hi - 0.031).abs() < 1e-12);
        // Two shots: J is their mean, so one term must be twice as large.
        let [lo2, _] = windows_of(&t, 2, 1.0, 0.0)
            .length_ratio
            .expect("in the test");
        assert!((term(&r, Some(lo2)) / 3.0 / 2.0 - 1.0).abs() < 1e-9);
    }

    /// Each shot is screened at the configured number of its own transit times D/v0 (as
    /// simulated), so a slower or larger impactor is screened later.
    #[test]
    fn each_shot_is_screened_at_its_own_transit_times() {
        let r = target("r", Observable::LengthRatio, TargetKind::Value, 1.55, 0.1);
        let fast = shot(vec![r.clone()]);
        let mut slow = shot(vec![r]);
        slow.shot.v0_m_s = 3250.0;
        slow.shot.impactor_diameter_m = 0.02;
        let cfg: CalibrateConfig = serde_json::from_value(serde_json::json!({
            "screen_after_transits": 4.0,
            "screen_after_plate_transits": 0.0
        }))
        .expect("in the test");
        let screen = Screen::of(&cfg, &[fast, slow]);
        let times: Vec<f64> = screen.shots.iter().map(|s| s.after_s).collect();
        // 4 x 10 mm / 6500 m/s, and 4 x 20 mm / 3250 m/s: four times as long.
        assert!((times[0] - 4.0 * 0.01 / 6500.0).abs() < 1e-18, "{times:?}");
        assert!((times[1] - 4.0 * times[0]).abs() < 1e-18, "{times:?}");
        assert!(screen
            .shots
            .iter()
            .all(|s| s.windows.length_ratio.is_some()));
    }

    /// Behind a thick plate the screen waits for the plate's transits when they come later:
    /// at the defaults a plate of t/D = 0.2 is screened at 5.6 D/v0, one of 0.6 at 13.3 t/v0
    /// (7.98 D/v0), and the calibration shot's 0.425 at 13.3 x 0.425 = 5.65 D/v0.
    #[test]
    fn a_thick_plate_is_screened_at_its_plate_transits() {
        let r = target("r", Observable::LengthRatio, TargetKind::Value, 1.55, 0.1);
        let at = |t_over_d: f64| {
            let mut s = shot(vec![r.clone()]);
            s.shot.t_over_d = t_over_d;
            let cfg: CalibrateConfig =
                serde_json::from_value(serde_json::json!({})).expect("in the test");
            Screen::of(&cfg, &[s]).shots[0].after_s / (0.01 / 6500.0)
        };
        for (t_over_d, transits) in [(0.2, 5.6), (0.425, 13.3 * 0.425), (0.6, 13.3 * 0.6)] {
            let got = at(t_over_d);
            assert!((got - transits).abs() < 1e-9, "t/D {t_over_d}: {got} D/v0");
        }
    }

    /// A plate thicker than `calibrate.screen_max_t_over_d` (0.6 by default) gets no window,
    /// so its runs go in full; at the limit it is screened, and `inf` screens every plate.
    #[test]
    fn a_plate_thicker_than_the_limit_is_not_screened() {
        let r = target("r", Observable::LengthRatio, TargetKind::Value, 1.55, 0.1);
        // The limit as configured (None: the default).
        let screen = |t_over_d: f64, limit: Option<f64>| {
            let mut s = shot(vec![r.clone()]);
            s.shot.t_over_d = t_over_d;
            let mut cfg: CalibrateConfig =
                serde_json::from_value(serde_json::json!({})).expect("in the test");
            if let Some(limit) = limit {
                cfg.screen_max_t_over_d = limit;
            }
            Screen::of(&cfg, &[s])
        };
        let at_limit = screen(0.6, None);
        assert!(at_limit.shots[0].windows.any() && !at_limit.too_thick(0));
        let thick = screen(1.0, None);
        assert!(thick.too_thick(0), "{thick:?}");
        assert_eq!(thick.shots[0].windows, Windows::default());
        let unlimited = screen(1.0, Some(f64::INFINITY));
        assert!(unlimited.shots[0].windows.any() && !unlimited.too_thick(0));
    }

    /// A window never screens a run that meets its target: below a threshold of one term,
    /// the edge is where the target's own term is 1.
    #[test]
    fn a_screened_run_always_misses_its_target() {
        let r = target("r", Observable::LengthRatio, TargetKind::Value, 1.55, 0.1);
        let t = shot(vec![r.clone()]);
        let [lo, hi] = windows_of(&t, 1, 0.01, 0.0)
            .length_ratio
            .expect("in the test");
        assert!((term(&r, Some(lo)) - 1.0).abs() < 1e-9 && (term(&r, Some(hi)) - 1.0).abs() < 1e-9);
    }

    /// Kinds: a log target's window is a factor each way; an upper bound has no low side;
    /// two targets on one observable intersect.
    #[test]
    fn windows_follow_the_target_kinds_and_intersect() {
        let va = target(
            "va",
            Observable::FrontVelocityRatio,
            TargetKind::LogValue,
            0.9,
            1.1,
        );
        let w = windows_of(&shot(vec![va.clone()]), 1, 4.0, 0.0);
        let [lo, hi] = w.front_velocity_ratio.expect("in the test");
        assert!((lo - 0.9 / 1.21).abs() < 1e-12 && (hi - 0.9 * 1.21).abs() < 1e-12);
        let most = target("m", Observable::LengthRatio, TargetKind::AtMost, 1.6, 0.1);
        let value = target("v", Observable::LengthRatio, TargetKind::Value, 1.4, 0.1);
        let w = windows_of(&shot(vec![most.clone()]), 1, 1.0, 0.0);
        assert_eq!(w.length_ratio.expect("in the test")[0], f64::MIN);
        let both = windows_of(&shot(vec![most, value]), 1, 0.5, 0.0);
        // Each term's edge at 1 tolerance (0.5 x 2 targets / 1 = 1): [1.3, 1.5] and up to 1.7.
        let [lo, hi] = both.length_ratio.expect("in the test");
        assert!((lo - 1.3).abs() < 1e-12 && (hi - 1.5).abs() < 1e-12);
        let fragments_only = target(
            "f",
            Observable::MeanFragmentDiameter,
            TargetKind::Value,
            1e-3,
            1e-3,
        );
        assert!(!windows_of(&shot(vec![fragments_only]), 1, 1.0, 0.0).any());
    }
}
