//! Where a scene's particles and steps go after the impact, the measurement behind the verdicts
//! on two skip options (docs/model-decisions.md, sleeping and per-fragment free flight): every
//! 2 us it prints the steps and builds taken since the last line, the stride, the residual
//! plate's share of the particles and how fast its bonded neighbours move against each other,
//! the share of particles in debris fragments that have separated (no contact with another
//! fragment, receding from every listed one) and of those the lone particles, and per kind of
//! pair (both in the residual plate, both separated debris, any other) the largest relative
//! speed of the pairs the adaptive step's speed bound covers (listed pairs and bond partners).
//!
//! `cargo run --release -p hvi-engine --example plate_and_debris -- [PARTICLES] [T_OVER_D]`
//! (the calibration scene, 3e4 particles and its t/D by default).
use hvi_engine::cloud::{find_cloud, quantile, CloudReference};
use hvi_engine::paper;
use hvi_engine::scene::{Geometry, SceneSpec};
use hvi_engine::sim::Simulation;

/// Seconds between lines.
const EVERY_S: f64 = 2e-6;

fn main() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("a number"))
        .collect();
    let n = args.first().copied().unwrap_or(3e4);
    let mut spec = SceneSpec::calibration(n, paper::ANALYSIS_TIME_S);
    if let (Some(&t), Geometry::SphereOnPlate { t_over_d, .. }) = (args.get(1), &mut spec.scene) {
        *t_over_d = t;
    }
    let mut sim = Simulation::new(spec.build().expect("a valid scene")).expect("starts");
    let reference = CloudReference::of(&sim);
    let v0 = sim.derived.v0_m_s;
    println!(
        "{} particles; speeds over v0; pair kinds: plate-plate / separated debris / other",
        sim.particles.len()
    );
    println!(
        "tau_us steps builds stride | plate share, bond speed p50 p90, bonds < 0.005 v0 | \
         separated share (lone) | largest pair speed plate / separated / other"
    );
    let (mut steps0, mut builds0) = (0, 0);
    let mut next = EVERY_S;
    while sim.tau_s() < paper::ANALYSIS_TIME_S {
        sim.step_once().expect("stable");
        if sim.tau_s() < next {
            continue;
        }
        next += EVERY_S;
        let l = Look::of(&sim, &reference);
        let mut bond_speed = l.plate_bond_speeds.clone();
        let slow = bond_speed.iter().filter(|&&w| w < 0.005 * v0).count();
        let np = sim.particles.len() as f64;
        println!(
            "{:5.1} {:5} {:4} {:3} | {:.3} {:.4} {:.4} {:.4} | {:.3} ({:.3}) | {:.3} / {:.3} / {:.3}",
            sim.tau_s() * 1e6,
            sim.steps_taken - steps0,
            sim.neighbour_builds() - builds0,
            sim.stride,
            l.plate as f64 / np,
            quantile(&mut bond_speed, 0.5).unwrap_or(0.0) / v0,
            quantile(&mut bond_speed, 0.9).unwrap_or(0.0) / v0,
            slow as f64 / l.plate_bond_speeds.len().max(1) as f64,
            l.separated as f64 / np,
            l.lone as f64 / np,
            l.fastest[0] / v0,
            l.fastest[1] / v0,
            l.fastest[2] / v0,
        );
        steps0 = sim.steps_taken;
        builds0 = sim.neighbour_builds();
    }
}

/// One look at the scene.
struct Look {
    plate: usize,
    separated: usize,
    lone: usize,
    plate_bond_speeds: Vec<f64>,
    /// Largest relative speed of listed or bonded pairs: plate-plate, separated, other.
    fastest: [f64; 3],
}

impl Look {
    fn of(sim: &Simulation, reference: &CloudReference) -> Look {
        let p = &sim.particles;
        let n = p.len();
        // The residual plate as the cloud's measurement defines it, and the fragments held by
        // a contact or a neighbour closing in as the ballistic cut-off judges them.
        let members = find_cloud(p, reference);
        let labels = &members.labels;
        let in_plate = |i: usize| members.in_residual_plate[i];
        let held_label = sim.fragments_held(labels);
        let held = |i: usize| in_plate(i) || held_label[labels[i] as usize];
        let mut size = vec![0usize; n];
        for &l in labels {
            size[l as usize] += 1;
        }
        let nl = sim.neighbour_list();
        let kind = |i: usize, j: usize| {
            if in_plate(i) && in_plate(j) {
                0
            } else if !held(i) && !held(j) {
                1
            } else {
                2
            }
        };
        let mut fastest = [0.0f64; 3];
        let mut plate_bond_speeds = Vec::new();
        for i in 0..n {
            for j in nl
                .of(i)
                .iter()
                .map(|&j| j as usize)
                .chain(p.intact_partners_of(i))
            {
                let w = (p.vel[i] - p.vel[j]).length();
                let k = kind(i, j);
                fastest[k] = fastest[k].max(w);
            }
        }
        for (i, j) in p.intact_bond_pairs() {
            if in_plate(i) {
                plate_bond_speeds.push((p.vel[i] - p.vel[j]).length());
            }
        }
        let separated: Vec<usize> = (0..n).filter(|&i| !held(i)).collect();
        Look {
            plate: (0..n).filter(|&i| in_plate(i)).count(),
            lone: separated
                .iter()
                .filter(|&&i| size[labels[i] as usize] == 1)
                .count(),
            separated: separated.len(),
            plate_bond_speeds,
            fastest,
        }
    }
}
