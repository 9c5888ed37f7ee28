//! The `hvi-study` command: parses the command line ([`hvi_study::cli`]), runs the
//! subcommand ([`hvi_study::commands::dispatch`]) and turns an error into its message and its
//! exit code ([`hvi_run::error::exit_code`]).

use std::process::ExitCode;

use clap::Parser;
use hvi_study::cli::Cli;

fn main() -> ExitCode {
    // Output piped into a reader that stops early (`hvi-study keys | head`) ends the process
    // quietly, as it ends `ls | head`, instead of a panic on the failed write: Rust ignores
    // SIGPIPE by default, so a closed pipe becomes a write error that `println!` panics on.
    #[cfg(unix)]
    // SAFETY: setting a signal's disposition to the default at the start of main, before any
    // other thread exists, has no memory-safety conditions.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    hvi_study::terminal::install();
    let cli = Cli::parse();
    if let Err(e) = hvi_run::interrupt::install() {
        eprintln!("warning: Ctrl-C and SIGTERM will end the process at once: {e}");
    }
    match hvi_study::commands::dispatch(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if let Some(stop) = hvi_run::interrupt::of(&*e) {
                eprintln!(
                    "{stop}: the runs in progress stopped at a checkpoint (unless \
                     --checkpoint-every off) and left no partial result; finished runs are \
                     kept: run the same command again to resume (nothing finished runs again, \
                     a checkpointed run continues where it stopped)"
                );
            } else {
                eprintln!("error: {e:#}");
            }
            // docs/running.md, "Exit codes"; the mapping and its tests are hvi-run's.
            ExitCode::from(hvi_run::error::exit_code(&*e))
        }
    }
}
