//! # hvi-store
//!
//! Studies of many runs and the store that keeps each result once: study files and their
//! validated plans ([`spec`], [`plan`]), the resolution warnings of a scene or a plan
//! ([`resolution`]), the run store ([`store`]), which measures a run from another's kept state
//! where only the measurement differs ([`remeasured`]), the locks that keep two processes from
//! doing the same work ([`lock`]), parallel execution ([`exec`]) or as Slurm batches
//! ([`runner`], [`slurm`]), a study's results tables ([`table`], [`study`]). One run is
//! [`hvi_run`]'s; errors are its [`hvi_run::error::RunError`], so a command reports a store's
//! failure and a run's alike.
//!
//! ```
//! use hvi_store::spec::Study;
//! // The paper's calibration study: a grid over (eps, kappa, rcut) at named tiers.
//! let study = Study::load(std::path::Path::new("../../studies/calibration.toml")).expect("valid");
//! assert_eq!(study.axes.len(), 3);
//! assert!(study.tiers.contains_key("quick"));
//! // A wrong key is refused with its name.
//! let bad = Study::parse("[study]\nname = \"x\"\nscnee = \"s.toml\"\n", "x.toml".as_ref());
//! assert!(bad.is_err());
//! ```

pub mod exec;
pub mod lock;
pub mod plan;
pub mod remeasured;
pub mod resolution;
pub mod runner;
pub mod slurm;
pub mod spec;
pub mod store;
pub mod study;
pub mod table;
