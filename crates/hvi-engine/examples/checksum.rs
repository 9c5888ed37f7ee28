//! Runs the README's default scene (`studies/scenes/default.toml`: the calibration scene at 1e4
//! particles, 32 us after first contact) to the end with a [`CloudObserver`], landing on every
//! energy sample, cloud sample and render time (`analysis.render_times_s`) as `hvi-study run`
//! does, so that its steps, bonds and cloud are those of the run's `summary.json`, and prints
//! with full precision (`{:?}`) the steps, bonds broken, the final energy ledger, a checksum of
//! positions and velocities and the cloud measurement.
//!
//! A refactoring that must not change any number is checked by running this before and after
//! and comparing the output, which must be identical (it prints no timings):
//!
//! `cargo run --release -p hvi-engine --example checksum > after.txt`
use hvi_engine::cloud::{step_at_tau, CloudObserver};
use hvi_engine::potential::ContactForm;
use hvi_engine::scene::{
    Analysis, Geometry, Material, Resolution, RunSettings, SceneSpec, SizingRule, TimeStep,
};
use hvi_engine::sim::Simulation;

/// `studies/scenes/default.toml`, key for key (every other key at its default).
fn default_scene() -> SceneSpec {
    SceneSpec {
        scene: Geometry::SphereOnPlate {
            diameter_m: 9.53e-3,
            t_over_d: 0.425,
            width_over_d: 3.0,
            v0_m_s: 6700.0,
            density_kg_m3: 2700.0,
            standoff_m: 0.0,
        },
        resolution: Resolution {
            particles: Some(10000.0),
            particles_across_d: None,
        },
        impactor: Default::default(),
        material: Material {
            contact: ContactForm::Printed,
            eps_j: Some(0.01),
            kappa_n_m: Some(4.56e6),
            gamma_pa: None,
            lambda_pa: None,
            rcut_over_sigma: 1.5,
            sizing: true,
            sizing_rule: SizingRule::Eq12,
        },
        run: RunSettings {
            end_time_s: 32e-6,
            dt_s: TimeStep::Auto,
            seed: 1,
            ..RunSettings::default()
        },
        analysis: Analysis::default(),
    }
}

fn main() {
    let spec = default_scene();
    let setup = spec.build().expect("valid scene");
    let d = setup.derived;
    println!("derived {d:?}");
    println!("particles {}", setup.particles.len());
    let mut sim = Simulation::new(setup).expect("stable start");
    let mut observer = CloudObserver::new(&sim, &spec.analysis, spec.run.end_time_s);
    observer.observe(&sim);
    let energy_every = spec.run.energy_every;
    // The run lands on the scene's render times whether or not it renders (they are the
    // scene's, so pictures never change the trajectory).
    let render_steps: Vec<u64> = spec
        .analysis
        .render_times_s
        .iter()
        .map(|&t| step_at_tau(&d, t))
        .collect();
    let next_multiple = |s: u64, every: u64| (s / every + 1).saturating_mul(every);
    let mut max_drift: f64 = 0.0;
    let mut ledger_sum = 0.0;
    while sim.step < d.steps {
        let s = sim.step;
        let mut next = d.steps.min(next_multiple(s, energy_every));
        if let Some(due) = observer.next_due(s) {
            next = next.min(due);
        }
        if let Some(&r) = render_steps.iter().filter(|&&r| r > s).min() {
            next = next.min(r);
        }
        sim.step_until(next).expect("stable");
        let s = sim.step;
        if s.checked_rem(energy_every) == Some(0) || s == d.steps {
            let e = sim.energy();
            ledger_sum += e.total_j();
            max_drift = max_drift.max(sim.check_energy(&e).expect("ledger").abs());
        }
        observer.observe(&sim);
    }
    let e = sim.energy();
    let checksum: f64 = sim
        .particles
        .pos
        .iter()
        .zip(&sim.particles.vel)
        .map(|(x, v)| x.x + 2.0 * x.y + 3.0 * x.z + 1e-9 * (v.x + v.y + v.z))
        .sum();
    println!(
        "base steps {:?}, steps taken {:?}, largest stride {:?}, stride limits {:?}",
        sim.step, sim.steps_taken, sim.largest_stride, sim.stride_limits
    );
    println!("neighbour builds {:?}", sim.neighbour_builds());
    println!(
        "bonds initial {:?}, broken {:?}",
        sim.bonds_initial, sim.bonds_broken
    );
    println!("energy initial {:?}", sim.energy_initial);
    println!("energy final {e:?}");
    println!("max drift {max_drift:?}, ledger sum {ledger_sum:?}");
    println!("momentum {:?}", sim.momentum());
    println!("checksum {checksum:?}");
    println!("track rows {:?}", observer.track.len());
    println!("track last {:?}", observer.track.last());
    println!("front {:?}", observer.front);
    let cloud = observer.finish(&sim).expect("cloud measured");
    println!("cloud {:?}", cloud.report);
    println!("fragments {:?}", cloud.fragments.len());
}
