//! Steps a sphere-on-plate scene and prints throughput: `cargo run --release -p hvi-engine
//! --example steps -- PARTICLES STEPS DT_FACTOR`.
use hvi_engine::paper;
use hvi_engine::scene::{Geometry, Material, Resolution, RunSettings, SceneSpec};
use hvi_engine::sim::Simulation;

fn main() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("number"))
        .collect();
    let (n, steps, f) = (
        args.first().copied().unwrap_or(1e4),
        args.get(1).copied().unwrap_or(2000.0),
        args.get(2).copied().unwrap_or(1.0),
    );
    let spec = SceneSpec {
        scene: Geometry::SphereOnPlate {
            diameter_m: paper::IMPACTOR_DIAMETER_M,
            t_over_d: paper::CALIBRATION_T_OVER_D,
            width_over_d: paper::DEFAULT_WIDTH_OVER_D,
            v0_m_s: paper::CALIBRATION_V0_M_S,
            density_kg_m3: paper::ALUMINIUM_DENSITY_KG_M3,
            standoff_m: 0.0,
        },
        resolution: Resolution {
            particles: Some(n),
            particles_across_d: None,
        },
        material: Material::default(),
        run: RunSettings {
            dt_factor: f,
            ..RunSettings::default()
        },
        analysis: Default::default(),
    };
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
