//! Steps a sphere-on-plate scene and prints throughput: `cargo run --release -p hvi-engine
//! --example steps -- PARTICLES STEPS DT_FACTOR`.
use hvi_engine::paper;
use hvi_engine::scene::SceneSpec;
use hvi_engine::sim::Simulation;

fn main() {
    // Inside a pool, as `hvi-study` runs: the stepping thread is one of the workers, so the
    // kernels' parallel loops do not wake a pool from outside at every call (which costs a
    // tenth of a small scene's time on one thread), and the other workers spin between the
    // loops (`hvi_engine::threads`). RAYON_NUM_THREADS sets the count.
    rayon::ThreadPoolBuilder::new()
        .build()
        .expect("a thread pool")
        .install(|| hvi_engine::threads::with_awake_workers(run));
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
