//! Times the steps of the debris cloud, where neighbour builds and the contact kernel cost
//! most: runs the calibration scene to `WARM_US` microseconds after first contact, then takes
//! `STEPS` more steps and prints the time per phase, the neighbour list's shape and a checksum
//! of the state (equal checksums: bit-identical physics).
//!
//! `cargo run --release -p hvi-engine --example cloud_steps -- PARTICLES WARM_US STEPS [SKIN]`
use hvi_engine::paper;
use hvi_engine::scene::SceneSpec;
use hvi_engine::sim::Simulation;

fn main() {
    // As `hvi-study` runs a scene; RAYON_NUM_THREADS sets the thread count.
    hvi_engine::threads::in_pool(run);
}

fn run() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("number"))
        .collect();
    let n = args.first().copied().unwrap_or(5e4);
    let warm_s = args.get(1).copied().unwrap_or(16.0) * 1e-6;
    let steps = args.get(2).copied().unwrap_or(500.0) as u64;
    let mut spec = SceneSpec::calibration(n, paper::ANALYSIS_TIME_S);
    if let Some(&skin) = args.get(3) {
        spec.run.skin_over_sigma = skin;
    }
    let mut sim = Simulation::new(spec.build().expect("valid")).expect("starts");
    let t = std::time::Instant::now();
    while sim.tau_s() < warm_s {
        sim.step_once().expect("stable");
    }
    let warm = t.elapsed().as_secs_f64();
    let (timing0, builds0, steps0) = (sim.timing, sim.neighbour_builds(), sim.steps_taken);
    let t = std::time::Instant::now();
    for _ in 0..steps {
        sim.step_once().expect("stable");
    }
    let el = t.elapsed().as_secs_f64();
    let nl = sim.neighbour_list();
    let np = sim.particles.len();
    let listed = nl.neighbours.len();
    let r_eq2 = sim.materials.target.r_eq2();
    let in_contact = (0..np)
        .map(|i| {
            nl.of(i)
                .iter()
                .filter(|&&j| {
                    (sim.particles.pos[i] - sim.particles.pos[j as usize]).length_squared() < r_eq2
                })
                .count()
        })
        .sum::<usize>();
    let sum: f64 = sim
        .particles
        .pos
        .iter()
        .zip(&sim.particles.vel)
        .map(|(x, v)| x.x + 2.0 * x.y + 3.0 * x.z + 1e-9 * (v.x + v.y + v.z))
        .sum();
    let d = |a: std::time::Duration, b: std::time::Duration| (a - b).as_secs_f64();
    println!(
        "{np} particles, warm-up {warm:.1} s to {:.2} us; {} steps in {el:.2} s ({:.3e} particle-steps/s), \
         stride {}, {} builds\n  contact {:.3} s, bonds {:.3} s, neighbour {:.3} s, integrate {:.3} s\n  \
         list {:.2} per particle, {:.1} % of listed pairs in contact\n  checksum {sum:.17e}",
        sim.tau_s() * 1e6,
        sim.steps_taken - steps0,
        np as f64 * steps as f64 / el,
        sim.stride,
        sim.neighbour_builds() - builds0,
        d(sim.timing.contact, timing0.contact),
        d(sim.timing.bonds, timing0.bonds),
        d(sim.timing.neighbour, timing0.neighbour),
        d(sim.timing.integrate, timing0.integrate),
        listed as f64 / np as f64,
        100.0 * in_contact as f64 / listed.max(1) as f64,
    );
}
