//! # hvi-scene
//!
//! A scene of the model of Watson and Steinhauser (Materials 2017, 10, 379), everything short of
//! stepping it: what a scene file says and its key registry ([`scene`]), validated, sized and
//! laid out as particles and bonds ([`state`]) with their laws ([`potential`]), the paper's
//! numbers ([`paper`]), the time step's bound ([`step`]), quarter symmetry ([`symmetry`]),
//! counter-based noise ([`rng`]), and the side-on camera and witness plate a cloud is measured
//! with ([`shadowgraph`], [`witness`]). `hvi-engine` steps it and measures the cloud, and
//! re-exports these modules under the same names.
//!
//! ```
//! use hvi_scene::scene::{Analysis, Geometry, Material, Resolution, RunSettings, SceneSpec};
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
//! assert!(setup.particles.len() > 1500);
//! ```

pub mod error;
pub mod paper;
pub mod potential;
pub mod rng;
pub mod scene;
pub mod shadowgraph;
pub mod state;
pub mod step;
pub mod symmetry;
pub mod witness;

pub use error::{EngineError, Result};
