//! # hvi-study
//!
//! Everything around the engine: scene files, runs and their output files, and (later)
//! studies, scoring and plots. The `hvi-study` binary is a thin layer over this library.

pub mod accuracy;
pub mod bench;
pub mod output;
pub mod render;
pub mod reproduce;
pub mod run;
pub mod scene_file;
pub mod study;
