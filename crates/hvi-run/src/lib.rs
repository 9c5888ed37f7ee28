//! # hvi-run
//!
//! Runs scenes and studies and keeps their results: scene files with `--set` overrides
//! ([`scene_file`]), one run and its files ([`run`], [`output`]), the cloud's kept state for
//! re-analysis ([`state`]), study files and their validated plans ([`spec`], [`plan`]), the
//! run store that keeps each result once ([`store`]), parallel execution ([`exec`]), results
//! tables ([`table`]), Slurm job arrays ([`slurm`]) and the engine benchmark ([`mod@bench`]).

pub mod bench;
pub mod exec;
pub mod output;
pub mod plan;
pub mod run;
pub mod scene_file;
pub mod slurm;
pub mod spec;
pub mod state;
pub mod store;
pub mod study;
pub mod table;
