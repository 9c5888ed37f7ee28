//! The `hvi-study` command: parses the command line ([`hvi_study::cli`]), runs the
//! subcommand ([`hvi_study::commands::dispatch`]) and turns an error into exit code 2 with
//! its message.

use std::process::ExitCode;

use clap::Parser;
use hvi_study::cli::Cli;

fn main() -> ExitCode {
    let cli = Cli::parse();
    match hvi_study::commands::dispatch(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
