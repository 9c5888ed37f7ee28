//! Quarter symmetry (`run.symmetry = "quarter"`): the quarter with its mirror images is the
//! full scene. Checked against a full run of the same lattice started exactly symmetric (no
//! thermal velocities): the same trajectories, ledger and broken bonds to round-off through
//! the impact; and on its own: momentum, the ledger bound, the rebuild rule across the planes,
//! bit-identical results at one and two threads. Small scenes, release-optimised.

use std::collections::HashMap;

use glam::DVec3;
use hvi_engine::scene::{Geometry, Resolution, SceneSpec};
use hvi_engine::sim::Simulation;
use hvi_engine::symmetry::Symmetry;

/// The calibration scene at 10 particles across D: a plate of 30 x 30 sites (even, so the
/// full and the quarter lattices are the same), to `end_time_s`.
fn scene(symmetry: Symmetry, thermal: f64, end_time_s: f64) -> SceneSpec {
    let mut spec = SceneSpec::calibration(1.0, end_time_s);
    spec.resolution = Resolution {
        particles: None,
        particles_across_d: Some(10.0),
    };
    if let Geometry::SphereOnPlate { width_over_d, .. } = &mut spec.scene {
        *width_over_d = 3.0;
    }
    spec.run.symmetry = symmetry;
    spec.run.thermal_ratio = thermal;
    spec
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool")
}

/// Positions keyed by the initial site (rounded to a tenth of the spacing).
fn site_key(x: DVec3, r_eq: f64) -> [i64; 3] {
    let q = x / (0.1 * r_eq);
    [q.x.round() as i64, q.y.round() as i64, q.z.round() as i64]
}

#[test]
fn quarter_with_its_images_is_the_full_scene() {
    let end = 1.5e-6;
    let mut full_spec = scene(Symmetry::Full, 0.0, end);
    full_spec.run.max_stride = 1;
    let mut quarter_spec = scene(Symmetry::Quarter, 0.0, end);
    quarter_spec.run.max_stride = 1;
    let mut full = Simulation::new(full_spec.build().expect("full")).expect("starts");
    let mut quarter = Simulation::new(quarter_spec.build().expect("quarter")).expect("starts");
    assert_eq!(quarter.symmetry, Symmetry::Quarter);
    assert_eq!(4 * quarter.particles.len(), full.particles.len());
    assert_eq!(quarter.full_particle_count(), full.particles.len());
    assert_eq!(quarter.bonds_initial, full.bonds_initial);
    let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(f64::MIN_POSITIVE);
    assert!(
        rel(
            quarter.energy_initial.total_j(),
            full.energy_initial.total_j()
        ) < 1e-12
    );

    // Which full particle each quarter particle is (by id), from the initial positions.
    let r_eq = full.derived.r_eq_m;
    let full_by_site: HashMap<[i64; 3], u32> = full
        .particles
        .pos
        .iter()
        .zip(&full.particles.id)
        .map(|(&x, &id)| (site_key(x, r_eq), id))
        .collect();
    let twin: HashMap<u32, u32> = quarter
        .particles
        .pos
        .iter()
        .zip(&quarter.particles.id)
        .map(|(&x, &id)| (id, full_by_site[&site_key(x, r_eq)]))
        .collect();

    let steps = full.derived.steps;
    full.advance(steps).expect("full stable");
    quarter.advance(steps).expect("quarter stable");
    assert!(
        full.bonds_broken > full.bonds_initial / 50,
        "the impact breaks bonds"
    );
    assert_eq!(quarter.bonds_broken, full.bonds_broken);
    let (ef, eq) = (full.energy(), quarter.energy());
    assert!(rel(eq.total_j(), ef.total_j()) < 1e-9, "{eq:?} vs {ef:?}");
    assert!(rel(eq.kinetic_j, ef.kinetic_j) < 1e-9);
    assert!(rel(eq.broken_j, ef.broken_j) < 1e-12);
    let full_index = full.particles.index_of_id();
    let mut worst: f64 = 0.0;
    for (i, &id) in quarter.particles.id.iter().enumerate() {
        let j = full_index[twin[&id] as usize] as usize;
        worst = worst.max((quarter.particles.pos[i] - full.particles.pos[j]).length());
    }
    assert!(
        worst < 1e-6 * r_eq,
        "largest position difference {worst:.3e} m"
    );
    // The full scene as the quarter shows it: same particle count, same intact bonds.
    let unfolded = quarter.full_particles();
    assert_eq!(unfolded.len(), full.particles.len());
    assert_eq!(
        unfolded.intact_bonds() as u64,
        full.bonds_initial - full.bonds_broken
    );
    assert_eq!(quarter.momentum().x, 0.0);
    assert!(rel(quarter.momentum().z, full.momentum().z) < 1e-12);
}

#[test]
fn quarter_keeps_momentum_ledger_and_lists_every_contact_across_the_planes() {
    let spec = scene(Symmetry::Quarter, 1e-3, 3e-6);
    let mut sim = Simulation::new(spec.build().expect("valid")).expect("starts");
    let p0 = sim.momentum_initial;
    let e0 = sim.energy_initial.total_j();
    let r_eq = sim.derived.r_eq_m;
    let mut worst: f64 = 0.0;
    while sim.step < sim.derived.steps {
        sim.advance(20.min(sim.derived.steps - sim.step))
            .expect("stable");
        let missing = sim.neighbour_list().missing_pairs(&sim.particles, r_eq);
        assert_eq!(missing, 0, "a contact missed at step {}", sim.step);
        let e = sim.energy();
        worst = worst.max(((e.total_j() - e0) / e0).abs());
    }
    assert!(
        worst < hvi_engine::sim::LEDGER_DRIFT_BOUND,
        "ledger drift {worst:.3e}"
    );
    let dp = (sim.momentum() - p0).length() / p0.length();
    assert!(dp < 1e-12, "momentum changed by {dp:.3e}");
    assert!(sim.bonds_broken > 0);
}

#[test]
fn quarter_is_bit_identical_at_one_and_two_threads() {
    let spec = scene(Symmetry::Quarter, 1e-3, 1.5e-6);
    let run = |threads: usize| {
        pool(threads).install(|| {
            let mut sim = Simulation::new(spec.build().expect("valid")).expect("starts");
            sim.advance(sim.derived.steps).expect("stable");
            let e = sim.energy();
            (
                sim.particles.pos.clone(),
                e.total_j().to_bits(),
                sim.bonds_broken,
            )
        })
    };
    assert!(run(1) == run(2));
}
