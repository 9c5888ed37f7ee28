//! Numerical stability: property-based tests on random valid scenes (proptest). Whatever the
//! velocity, plate thickness, material and step, the engine either runs with momentum
//! conserved and the energy ledger within its guard, or stops with an `Unstable` diagnostic
//! naming the step and the reason; it never panics and never returns non-finite state as a
//! success. Scenes are small (6 particles across D, t/D from 0.1: one particle thick) and short (the
//! first microsecond of the impact).

use glam::DVec3;
use hvi_engine::potential::ContactForm;
use hvi_engine::scene::{Geometry, Resolution, SceneSpec, TimeStep};
use hvi_engine::sim::Simulation;
use hvi_engine::EngineError;
use proptest::prelude::*;

/// A scene from the sampled parameters (any of them may be out of the engine's range: then
/// `build` must refuse it with an error naming the key).
#[allow(clippy::too_many_arguments)]
fn scene(
    v0: f64,
    t_over_d: f64,
    eps: f64,
    kappa: f64,
    dt_factor: f64,
    seed: u64,
    wca: bool,
    across: f64,
) -> SceneSpec {
    let mut spec = SceneSpec::calibration(1.0, 1e-6);
    if let Geometry::SphereOnPlate {
        v0_m_s,
        t_over_d: t,
        width_over_d,
        ..
    } = &mut spec.scene
    {
        *v0_m_s = v0;
        *t = t_over_d;
        *width_over_d = 2.0;
    }
    spec.resolution = Resolution {
        particles: None,
        particles_across_d: Some(across),
    };
    spec.material.eps_j = Some(eps);
    spec.material.kappa_n_m = Some(kappa);
    spec.material.contact = if wca {
        ContactForm::Wca
    } else {
        ContactForm::Printed
    };
    spec.run.dt_factor = dt_factor;
    spec.run.seed = seed;
    spec.run.energy_every = 25;
    spec
}

/// Runs to the end; Ok(steps) or the engine's error.
fn run(spec: &SceneSpec) -> Result<Simulation, EngineError> {
    let setup = spec.build()?;
    let mut sim = Simulation::new(setup)?;
    let steps = sim.derived.steps;
    while sim.step < steps {
        sim.advance(spec.run.energy_every.min(steps - sim.step))?;
        let e = sim.energy();
        sim.check_energy(&e)?;
    }
    Ok(sim)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn random_scenes_run_conserving_or_stop_with_a_diagnostic(
        v0 in 1000.0..20000.0f64,
        t_over_d in 0.1..1.0f64,
        log_eps in -3.0..1.0f64,
        log_kappa in 5.0..8.0f64,
        dt_factor in 0.5..24.0f64,
        seed in 1u64..10_000,
        wca in any::<bool>(),
    ) {
        let spec = scene(v0, t_over_d, 10f64.powf(log_eps), 10f64.powf(log_kappa), dt_factor, seed, wca, 6.0);
        let outcome = std::panic::catch_unwind(|| run(&spec));
        let outcome = match outcome {
            Ok(o) => o,
            Err(_) => return Err(TestCaseError::fail(format!("panicked on {spec:?}"))),
        };
        match outcome {
            Ok(sim) => {
                // Success means finite state, momentum to round-off, ledger within its guard.
                prop_assert!(sim.particles.pos.iter().all(|x| x.is_finite()));
                prop_assert!(sim.particles.vel.iter().all(|v| v.is_finite()));
                let m: f64 = sim.particles.mass.iter().sum();
                let dp: DVec3 = sim.momentum() - sim.momentum_initial;
                prop_assert!(dp.length() <= 1e-10 * m * v0, "momentum moved by {:e}", dp.length() / (m * v0));
            }
            Err(EngineError::Unstable { reason, .. }) => {
                prop_assert!(!reason.is_empty());
            }
            Err(EngineError::InvalidValue { key, allowed, .. }) => {
                // Only a combination the engine documents as out of range.
                prop_assert!(!key.is_empty() && !allowed.is_empty());
            }
            Err(other) => return Err(TestCaseError::fail(format!("unexpected error {other} on {spec:?}"))),
        }
    }
}

/// The defaults are stable with margin where the paper works: at the corners of the paper's
/// grids (eps 0.01..1, kappa 1.14e6..9.12e6, v0 3..10 km/s, t/D 0.05..0.6) the automatic step
/// is at most half the stability bound, and a run *at* the bound completes with the ledger
/// within the project's bound.
#[test]
fn defaults_have_margin_at_the_paper_grid_corners() {
    let default_dt = hvi_engine::scene::RunSettings::default().dt_factor;
    for (v0, t_over_d, eps, kappa) in [
        (10000.0, 0.6, 0.01, 9.12e6),
        (10000.0, 0.05, 1.0, 1.14e6),
        (3000.0, 0.425, 1.0, 9.12e6),
        (10000.0, 0.425, 1.0, 9.12e6),
        (6700.0, 0.425, 0.01, 4.56e6),
    ] {
        let case = format!("v0 {v0} t/D {t_over_d} eps {eps} kappa {kappa}");
        // Thin plates need more particles across D to be one particle thick.
        let across = if t_over_d < 0.1 { 20.0 } else { 8.0 };
        let mut spec = scene(v0, t_over_d, eps, kappa, default_dt, 1, false, across);
        let d = spec.build().expect("valid").derived;
        assert!(
            d.dt_s <= 0.5 * d.dt_max_s * (1.0 + 1e-12),
            "{case}: auto step above half the bound"
        );
        spec.run.dt_s = TimeStep::Fixed(d.dt_max_s);
        let mut sim = run(&spec).unwrap_or_else(|e| panic!("{case} at the bound: {e}"));
        let e = sim.energy();
        let drift = (e.total_j() - sim.energy_initial.total_j()) / sim.energy_initial.total_j();
        assert!(
            drift.abs() < hvi_engine::sim::LEDGER_DRIFT_BOUND,
            "{case} at the bound: drift {drift:e}"
        );
    }
}

/// `hvi-study stability` on a 2 x 2 slice: the maps, table and summary are written, a step at
/// four times the bound is stopped with the engine's diagnostic naming the final run
/// directory, and a step at half the bound is stable.
#[test]
fn stability_command_maps_stable_and_stopped_cells() {
    let dir = std::env::temp_dir().join(format!("hvi-stability-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let scenes = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../studies/scenes");
    let slice = dir.join("slice.toml");
    std::fs::write(
        &slice,
        format!(
            r#"[study]
name = "tiny-step"
description = "test slice"
scene = "{}"
set = ["resolution.particles_across_d=6", "scene.width_over_d=2", "run.end_time_s=1e-6", "analysis.track_every=0"]

[[axes]]
key = "scene.v0_m_s"
values = [3000, 10000]

[[axes]]
key = "run.dt_over_bound"
values = [0.5, 4.0]

[tiers.quick]
description = "tiny"
set = []
"#,
            scenes.join("validity-map.toml").display()
        ),
    )
    .expect("write slice");
    let out = dir.join("report");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_hvi-study"))
        .args(["stability", "--quiet", "--out"])
        .arg(&out)
        .arg("--store")
        .arg(dir.join("runs"))
        .arg(&slice)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("slice.png").exists());
    let md = std::fs::read_to_string(out.join("stability.md")).expect("md");
    assert!(md.contains("cells: 4; stable: 2; stopped: 2"), "{md}");
    let csv = std::fs::read_to_string(out.join("stability.csv")).expect("csv");
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 4);
    for r in rows {
        if r.contains(",4,") || r.contains(",4.0,") {
            assert!(
                r.contains("stopped") && r.contains("numerical instability"),
                "{r}"
            );
            assert!(!r.contains(".tmp-"), "names a temporary directory: {r}");
        } else {
            assert!(r.contains("stable"), "{r}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
