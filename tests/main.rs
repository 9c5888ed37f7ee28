//! hvi-study's integration tests, one test binary (docs/testing.md): every file here is a
//! module of it, sharing [`common`]'s helpers (the repository root, the built `hvi-study`
//! binary, scratch directories).

mod common;

mod architecture;
mod checkpoint;
mod cli;
mod cloud;
mod fidelity;
mod fuzz;
mod lammps;
mod reanalyse;
mod reproduce;
mod sizing;
mod slurm;
mod stability;
mod study;
