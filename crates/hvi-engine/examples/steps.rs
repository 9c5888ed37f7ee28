//! Steps a sphere-on-plate scene and prints throughput: `cargo run --release -p hvi-engine
//! --example steps -- PARTICLES STEPS DT_FACTOR`.
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
    let (n, steps, f) = (
        args.first().copied().unwrap_or(1e4),
        args.get(1).copied().unwrap_or(2000.0),
        args.get(2).copied().unwrap_or(1.0),
    );
    let mut spec = SceneSpec::calibration(n, paper::ANALYSIS_TIME_S);
    spec.run.dt_factor = f;
    let mut sim = Simulation::new(spec.build().expect("valid")).expect("starts");
    let t = std::time::Instant::now();
    sim.advance(steps as u64).expect("stable");
    let el = t.elapsed().as_secs_f64();
    println!(
        "{} particles, {} steps: {:.3e} particle-steps/s, {} builds, timing {:?}",
        sim.particles.len(),
        steps,
        sim.particles.len() as f64 * steps / el,
        sim.neighbour_builds(),
        sim.timing
    );
}
