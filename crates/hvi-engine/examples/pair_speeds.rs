//! Diagnostic for multi-rate stepping: how many particles hold the adaptive step down.
//!
//! Runs the calibration scene and at a few times measures, per particle, the stride its own
//! interacting pairs (listed pairs and bond partners) would allow under the adaptive step's
//! displacement bound (relative speed) and stiffness bound (its closest pair), and prints the
//! share of particles allowing less than 2, 4, 8, 16, 32 and 64 base steps, beside the global
//! stride the engine takes; then the same shares by the relative speed alone and by the
//! closing speed (the rate at which a pair's distance falls) with the stiffness bound, and the
//! smallest stride allowed anywhere by each bound. reports/multirate and
//! reports/stride-rule are its results.
//!
//! `cargo run --release -p hvi-engine --example pair_speeds -- PARTICLES [TIMES_US...]`
use hvi_engine::paper;
use hvi_engine::scene::SceneSpec;
use hvi_engine::sim::Simulation;
use hvi_engine::state::{BONDS_PER_PARTICLE, INDEX_MASK, NO_BOND};

/// The strides (base steps) the shares are counted below.
const BOUNDS: [u64; 6] = [2, 4, 8, 16, 32, 64];

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
    let mut sim = Simulation::new(spec.build().expect("valid")).expect("starts");
    let disp_m = spec.run.stride_displacement_over_sigma * sim.derived.sigma_m;
    println!(
        "{} particles, dt {:.3e} s; columns: tau us, steps, stride taken, share of particles \
         allowing < {BOUNDS:?} base steps by relative speed or stiffness | by relative speed \
         alone | by closing speed or stiffness | the smallest stride allowed by each bound",
        sim.particles.len(),
        sim.dt
    );
    for &t in &times {
        while sim.tau_s() < t {
            sim.step_once().expect("stable");
        }
        let tally = Tally::of(&sim, disp_m);
        println!(
            "{:6.2} {:6} {:3}  {}",
            sim.tau_s() * 1e6,
            sim.steps_taken,
            sim.stride,
            tally.line(sim.particles.len())
        );
    }
}

/// The strides particle `i`'s own pairs allow, base steps: by their largest relative speed,
/// by their largest closing speed (each moving at most `disp_m` per step), and by the
/// stiffness bound at its closest pair.
struct Allowed {
    by_speed: f64,
    by_closing: f64,
    by_stiffness: f64,
}

impl Allowed {
    fn of(sim: &Simulation, i: usize, disp_m: f64, min_mass: f64) -> Self {
        let p = &sim.particles;
        let (pi, vi) = (p.pos[i], p.vel[i]);
        let (mut w2, mut closing, mut r2min): (f64, f64, f64) = (0.0, 0.0, f64::INFINITY);
        let slots = &p.bonds[i * BONDS_PER_PARTICLE..(i + 1) * BONDS_PER_PARTICLE];
        let bonded = slots
            .iter()
            .filter(|&&s| s != NO_BOND)
            .map(|&s| (s & INDEX_MASK) as usize);
        for j in sim
            .neighbour_list()
            .of(i)
            .iter()
            .map(|&j| j as usize)
            .chain(bonded)
        {
            let (d, dv) = (pi - p.pos[j], vi - p.vel[j]);
            w2 = w2.max(dv.length_squared());
            closing = closing.max(-d.dot(dv) / d.length());
            r2min = r2min.min(d.length_squared());
        }
        let k = sim.materials.stiffness_at(r2min);
        Allowed {
            by_speed: disp_m / (w2.sqrt() * sim.dt),
            by_closing: disp_m / (closing * sim.dt),
            by_stiffness: hvi_engine::step::stiffness_step_s(min_mass, k) / sim.dt,
        }
    }
}

/// Counts of particles allowing less than each of [`BOUNDS`], and the smallest strides.
#[derive(Default)]
struct Tally {
    below: [usize; 6],
    below_speed: [usize; 6],
    below_closing: [usize; 6],
    min_speed: f64,
    min_closing: f64,
    min_stiffness: f64,
}

impl Tally {
    fn of(sim: &Simulation, disp_m: f64) -> Self {
        let min_mass = sim
            .particles
            .mass
            .iter()
            .fold(f64::INFINITY, |a, &b| a.min(b));
        let mut t = Tally {
            min_speed: f64::INFINITY,
            min_closing: f64::INFINITY,
            min_stiffness: f64::INFINITY,
            ..Default::default()
        };
        for i in 0..sim.particles.len() {
            let a = Allowed::of(sim, i, disp_m, min_mass);
            t.min_speed = t.min_speed.min(a.by_speed);
            t.min_closing = t.min_closing.min(a.by_closing);
            t.min_stiffness = t.min_stiffness.min(a.by_stiffness);
            for (b, &bound) in BOUNDS.iter().enumerate() {
                let bound = bound as f64;
                t.below[b] += usize::from(a.by_speed.min(a.by_stiffness) < bound);
                t.below_speed[b] += usize::from(a.by_speed < bound);
                t.below_closing[b] += usize::from(a.by_closing.min(a.by_stiffness) < bound);
            }
        }
        t
    }

    /// The shares of `n` particles and the smallest strides, as one line.
    fn line(&self, n: usize) -> String {
        let share = |c: &[usize; 6]| {
            c.iter()
                .map(|&c| format!("{:.4}", c as f64 / n as f64))
                .collect::<Vec<_>>()
                .join(" ")
        };
        format!(
            "{}  | {} | {} | smallest by speed {:.1}, closing {:.1}, stiffness {:.1}",
            share(&self.below),
            share(&self.below_speed),
            share(&self.below_closing),
            self.min_speed,
            self.min_closing,
            self.min_stiffness
        )
    }
}
