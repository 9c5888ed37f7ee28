//! Geometric sizing (Fig. 4): colliding plates give the same energy curves at any particle
//! count with sizing, and not without. Uses the reproduction's scene and deciding numbers
//! (`hvi_reproduce::sizing`, `hvi_analysis::decide`), so it lives at the workspace level;
//! the engine's own physics tests are in `crates/hvi-engine/tests/physics.rs`.

use hvi_analysis::decide::{curve_deviation, EnergySample};
use hvi_engine::sim::Simulation;
use hvi_reproduce::sizing;

/// Kinetic and potential (contact + bond) energy against time since contact, stepping the
/// engine directly on the scene `hvi-study reproduce` uses for Fig. 4.
fn flyer_curves(particles: f64, sizing: bool) -> Vec<EnergySample> {
    let spec = sizing::plates_scene(particles, sizing);
    let mut sim = Simulation::new(spec.build().expect("valid")).expect("starts");
    let mut out = Vec::new();
    while sim.step < sim.derived.steps {
        let e = sim.energy();
        out.push(EnergySample {
            tau_s: sim.tau_s(),
            kinetic_j: e.kinetic_j,
            potential_j: e.contact_j + e.bond_j,
        });
        let n = sizing::SAMPLE_EVERY.min(sim.derived.steps - sim.step);
        sim.advance(n).expect("stable");
    }
    out
}

/// Fig. 4: with sizing, energy curves of colliding plates at 500, 5000 and 50000 particles
/// agree within `SIZED_MAX_DEVIATION` of the initial kinetic energy (measured: 7-8 %); without
/// sizing they differ by more than `UNSIZED_MIN_DEVIATION` (measured: about 45 %).
#[test]
fn sizing_makes_colliding_plates_independent_of_particle_count() {
    let counts = [500.0, 5000.0, 50000.0];
    let sized: Vec<_> = counts.iter().map(|&n| flyer_curves(n, true)).collect();
    let unscaled: Vec<_> = counts.iter().map(|&n| flyer_curves(n, false)).collect();
    for k in 0..2 {
        let d = curve_deviation(&sized[k], &sized[2]);
        assert!(
            d < sizing::SIZED_MAX_DEVIATION,
            "with sizing, N = {} differs from N = 5e4 by {d:.3}",
            counts[k]
        );
        let u = curve_deviation(&unscaled[k], &unscaled[2]);
        assert!(
            u > sizing::UNSIZED_MIN_DEVIATION,
            "without sizing, N = {} differs from N = 5e4 by only {u:.3}",
            counts[k]
        );
    }
}
