//! # hvi-study
//!
//! The `hvi-study` command's workflows, each joining running ([`hvi_run`]), analysis
//! ([`hvi_analysis`]) and pictures ([`hvi_plot`]): sweeps, calibration, the validity map, the
//! stability map, the accuracy benchmark and the reproduction of the paper. The binary parses
//! arguments ([`cli`]) and dispatches here.

pub mod accuracy;
pub mod cli;
pub mod commands;
pub mod reproduce;
pub mod study;
