//! # hvi-study
//!
//! The `hvi-study` command's workflows, each joining running ([`hvi_run`]), analysis
//! ([`hvi_analysis`]) and pictures ([`hvi_plot`]): sweeps, calibration, the validity map, the
//! stability map, the accuracy benchmark and the reproduction of the paper. The binary parses
//! arguments ([`cli`]) and dispatches here ([`commands::dispatch`]).
//!
//! ```
//! use clap::Parser;
//! use hvi_study::cli::{Cli, Command};
//! let cli = Cli::try_parse_from(["hvi-study", "sweep", "studies/calibration.toml", "--tier", "quick"])
//!     .expect("valid flags");
//! assert!(matches!(cli.command, Command::Sweep(ref a) if a.selection.tier.as_deref() == Some("quick")));
//! // Bad flags are refused before anything runs.
//! assert!(Cli::try_parse_from(["hvi-study", "sweep"]).is_err());
//! ```

pub mod cli;
pub mod commands;
pub mod terminal;
