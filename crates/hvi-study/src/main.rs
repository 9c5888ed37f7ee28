//! The `hvi-study` command: parses the command line ([`hvi_study::cli`]), runs the
//! subcommand ([`hvi_study::commands::dispatch`]) and turns an error into its message and its
//! exit code ([`hvi_run::error::exit_code`]).

use std::process::ExitCode;

use clap::Parser;
use hvi_study::cli::Cli;

/// Prints the libraries' progress lines and warnings (the `log` facade) on stderr, each
/// message as it is: the words carry their own "warning:" or "note:".
struct Stderr;

impl log::Log for Stderr {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.level() <= log::Level::Info
    }

    fn log(&self, record: &log::Record) {
        if self.enabled(record.metadata()) {
            eprintln!("{}", record.args());
        }
    }

    fn flush(&self) {}
}

static STDERR: Stderr = Stderr;

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
    if log::set_logger(&STDERR).is_ok() {
        log::set_max_level(log::LevelFilter::Info);
    }
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
            ExitCode::from(exit_code(&e))
        }
    }
}

/// The exit code of a command that failed with `e` (docs/running.md, "Exit codes"), from the
/// first cause in its chain that decides one: 128 + N after signal N, 74 when an output
/// cannot be written (a full disk, an unwritable directory), 69 when Slurm or another
/// external program refused or failed, 2 for anything else (a bad input, a refusal).
fn exit_code(e: &anyhow::Error) -> u8 {
    hvi_run::error::exit_code(&**e)
}

#[cfg(test)]
mod tests {
    use super::exit_code;
    use hvi_run::error::{Interrupted, RunError};
    use std::path::Path;

    #[test]
    fn exit_codes_come_from_the_cause_under_the_contexts() {
        let full = std::io::Error::new(std::io::ErrorKind::StorageFull, "No space left on device");
        let write = RunError::write(Path::new("out/runs/x/record.json"), full).context("run 3");
        assert_eq!(exit_code(&anyhow::Error::from(write).context("sweep")), 74);
        let sbatch = RunError::External("sbatch not found".into());
        assert_eq!(exit_code(&anyhow::Error::from(sbatch)), 69);
        let stop = anyhow::Error::from(RunError::from(Interrupted(15))).context("stage fig5");
        assert_eq!(exit_code(&stop), 143);
        let input = RunError::Input("invalid value for `--poll`: 0".into());
        assert_eq!(exit_code(&anyhow::Error::from(input)), 2);
        assert_eq!(
            exit_code(&anyhow::anyhow!("invalid value for `--seeds`")),
            2
        );
    }
}
