//! # hvi-engine
//!
//! The discrete element model of hypervelocity impact of Watson and Steinhauser
//! (Materials 2017, 10, 379): bodies as simple cubic lattices of particles, nearest-neighbour
//! springs that break for good past `rcut`, a Lennard-Jones contact repulsion between every
//! pair closer than r_eq, geometric sizing so results do not depend on the particle count, and
//! velocity Verlet. This crate steps a scene in time (`sim`, `neighbour`, `threads`) and
//! measures its debris cloud (`cloud`); the scene, its laws and the state arrays are
//! hvi-scene's, re-exported here under the same names. The crate knows nothing of files, plots
//! or command lines.
//!
//! ```
//! use hvi_engine::scene::{Analysis, Geometry, Material, Resolution, RunSettings, SceneSpec};
//! use hvi_engine::sim::Simulation;
//!
//! let spec = SceneSpec {
//!     scene: Geometry::SphereOnPlate {
//!         diameter_m: 9.53e-3, t_over_d: 0.425, width_over_d: 3.0,
//!         v0_m_s: 6700.0, density_kg_m3: 2700.0, standoff_m: 0.0,
//!     },
//!     resolution: Resolution { particles: Some(2000.0), particles_across_d: None },
//!     material: Material::default(),
//!     impactor: Default::default(),
//!     run: RunSettings { end_time_s: 1e-7, ..RunSettings::default() },
//!     analysis: Analysis::default(),
//! };
//! let setup = spec.build().expect("valid scene");
//! let mut sim = Simulation::new(setup).expect("stable start");
//! sim.advance(50).expect("stable");
//! let e = sim.energy();
//! let drift = (e.total_j() - sim.energy_initial.total_j()) / sim.energy_initial.total_j();
//! assert!(drift.abs() < 1e-3);
//! ```

pub mod cloud;
pub mod neighbour;
pub mod sim;
pub mod simd;
pub mod threads;

// The scene, its laws and the state arrays are hvi-scene's; re-exported so that a user of the
// engine names every part of the model through one crate.
pub use hvi_scene::{
    error, paper, potential, rng, scene, shadowgraph, state, step, symmetry, witness,
};

pub use error::{EngineError, Result};
