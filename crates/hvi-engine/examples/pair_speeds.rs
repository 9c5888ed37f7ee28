//! Diagnostic for multi-rate stepping: how many particles hold the adaptive step down.
//!
//! Runs the calibration scene and at a few times measures, per particle, the stride its own
//! interacting pairs (listed pairs and bond partners) would allow under the adaptive step's
//! displacement bound (relative speed) and stiffness bound (its closest pair), and prints the
//! share of particles allowing less than 2, 4, 8, 16, 32 and 64 base steps, beside the global
//! stride the engine takes; then the same shares by the stiffness bound and the closing speed
//! (the rate at which a pair's distance falls) instead of the relative speed, and the
//! smallest stride allowed anywhere by each bound. reports/multirate and
//! reports/stride-rule are its results.
//!
//! `cargo run --release -p hvi-engine --example pair_speeds -- PARTICLES [TIMES_US...]`
use hvi_engine::paper;
use hvi_engine::scene::SceneSpec;
use hvi_engine::sim::Simulation;
use hvi_engine::state::{BONDS_PER_PARTICLE, INDEX_MASK, NO_BOND};

fn main() {
    // As `hvi-study` runs a scene; RAYON_NUM_THREADS sets the thread count.
    hvi_engine::threads::in_pool(run);
}

fn run() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("number"))
        .collect();
    let n = args.first().copied().unwrap_or(3e4);
    let mut times: Vec<f64> = args.iter().skip(1).map(|t| t * 1e-6).collect();
    if times.is_empty() {
        times = vec![0.5e-6, 1e-6, 2e-6, 4e-6, 8e-6, 16e-6, 24e-6, 31e-6];
    }
    let spec = SceneSpec::calibration(n, paper::ANALYSIS_TIME_S);
    let disp = spec.run.stride_displacement_over_sigma;
    let mut sim = Simulation::new(spec.build().expect("valid")).expect("starts");
    let disp_m = disp * sim.derived.sigma_m;
    let min_mass = sim
        .particles
        .mass
        .iter()
        .fold(f64::INFINITY, |a, &b| a.min(b));
    let bounds = [2u64, 4, 8, 16, 32, 64];
    println!(
        "{} particles, dt {:.3e} s; columns: tau us, steps, stride, share of particles allowing < {bounds:?} base steps (speed or stiffness), share by speed alone < same",
        sim.particles.len(),
        sim.dt
    );
    for &t in &times {
        while sim.tau_s() < t {
            sim.step_once().expect("stable");
        }
        let p = &sim.particles;
        let nl = sim.neighbour_list();
        let np = p.len();
        let mut below = [0usize; 6];
        let mut below_speed = [0usize; 6];
        let mut below_closing = [0usize; 6];
        let (mut min_speed, mut min_closing, mut min_stiff) =
            (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        for i in 0..np {
            let vi = p.vel[i];
            let pi = p.pos[i];
            let mut w2: f64 = 0.0;
            let mut c: f64 = 0.0;
            let mut r2min = f64::INFINITY;
            let mut visit = |j: usize| {
                let dv = vi - p.vel[j];
                let d = pi - p.pos[j];
                w2 = w2.max(dv.length_squared());
                // Closing speed: -(d . dv) / |d|.
                c = c.max(-d.dot(dv) / d.length());
                r2min = r2min.min(d.length_squared());
            };
            for &j in nl.of(i) {
                visit(j as usize);
            }
            for &s in &p.bonds[i * BONDS_PER_PARTICLE..(i + 1) * BONDS_PER_PARTICLE] {
                if s != NO_BOND {
                    visit((s & INDEX_MASK) as usize);
                }
            }
            let by_speed = disp_m / (w2.sqrt() * sim.dt);
            let k = sim.materials.stiffness_at(r2min);
            let by_stiff = hvi_engine::step::stiffness_step_s(min_mass, k) / sim.dt;
            let allowed = by_speed.min(by_stiff);
            let by_closing = disp_m / (c * sim.dt);
            min_speed = min_speed.min(by_speed);
            min_closing = min_closing.min(by_closing);
            min_stiff = min_stiff.min(by_stiff);
            for (b, &bound) in bounds.iter().enumerate() {
                below[b] += usize::from(allowed < bound as f64);
                below_speed[b] += usize::from(by_speed < bound as f64);
                below_closing[b] += usize::from(by_closing.min(by_stiff) < bound as f64);
            }
        }
        let share = |c: &[usize; 6]| {
            c.iter()
                .map(|&c| format!("{:.4}", c as f64 / np as f64))
                .collect::<Vec<_>>()
                .join(" ")
        };
        println!(
            "{:6.2} {:6} {:3}  {}  | {} | closing+stiff {} | min by speed {min_speed:.1} closing {min_closing:.1} stiffness {min_stiff:.1}",
            sim.tau_s() * 1e6,
            sim.steps_taken,
            sim.stride,
            share(&below),
            share(&below_speed),
            share(&below_closing)
        );
    }
}
