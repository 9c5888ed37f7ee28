//! # hvi-run
//!
//! One run, from a scene file to its outputs: scene files with `--set` overrides
//! ([`scene_file`]), the run and its files ([`run`], [`output`]), the cloud's kept state for
//! re-analysis ([`state`]), checkpoints of a run in progress and the continuation a later end
//! time extends from ([`checkpoint`]), the LAMMPS export ([`lammps`]) and the engine benchmark
//! ([`mod@bench`]). Studies of many runs and the store that keeps them are the `hvi-store`
//! crate's. Every function returns [`error::Result`]: its [`error::RunError`] says what went
//! wrong, and [`error::exit_code`] the exit code a command ends with.
//!
//! ```
//! use hvi_run::run::{run_scene, RunOptions};
//! use hvi_run::scene_file::parse_scene;
//! let text = r#"
//! [scene]
//! kind = "sphere_on_plate"
//! diameter_m = 9.53e-3
//! t_over_d = 0.425
//! v0_m_s = 6700.0
//! [resolution]
//! particles = 800
//! [material]
//! eps_j = 0.01
//! kappa_n_m = 4.56e6
//! [run]
//! end_time_s = 1e-6
//! "#;
//! // `--set` overrides apply on top of the file, and a wrong key is named.
//! let spec = parse_scene(text, &["scene.v0_m_s=5000".into()]).expect("a valid scene");
//! assert_eq!(spec.scene.v0_m_s(), 5000.0);
//! assert!(parse_scene(text, &["scene.v0_ms=5000".into()]).is_err());
//! let out = std::env::temp_dir().join(format!("hvi-run-doc-{}", std::process::id()));
//! let outcome = run_scene(&spec, &RunOptions { out_dir: out.clone(), ..RunOptions::default() })
//!     .expect("runs");
//! assert!(out.join("summary.json").exists() && outcome.summary.steps > 0);
//! # std::fs::remove_dir_all(&out).ok();
//! ```

pub mod bench;
pub mod checkpoint;
pub mod error;
pub mod files;
pub mod interrupt;
pub mod lammps;
pub mod output;
pub mod progress;
pub mod run;
pub mod scene_file;
pub mod screen;
pub mod start;
pub mod state;

pub use progress::STDOUT;
