//! What the command prints, and the only place that prints: the libraries' messages (the `log`
//! facade; target [`hvi_run::STDOUT`] on standard output, the rest on standard error, each
//! message as it is: the words carry their own "warning:" or "note:") and their progress bars
//! ([`hvi_run::progress`], drawn with indicatif on a terminal).

use std::io::IsTerminal;
use std::time::Duration;

use hvi_run::progress::{Bar, Bars, Unit};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// The command's logger.
struct Terminal;

impl log::Log for Terminal {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.level() <= log::Level::Info
    }

    fn log(&self, record: &log::Record) {
        if self.enabled(record.metadata()) {
            if record.target() == hvi_run::STDOUT {
                println!("{}", record.args());
            } else {
                eprintln!("{}", record.args());
            }
        }
    }

    fn flush(&self) {}
}

static TERMINAL: Terminal = Terminal;

/// Progress bars on standard error.
struct Indicatif;

impl Bars for Indicatif {
    fn bar(&self, total: u64, unit: Unit) -> Box<dyn Bar> {
        let b = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
        let template = match unit {
            Unit::Steps => "{bar:30} {pos}/{len} steps  {msg}  ETA {eta}",
            Unit::Runs => "{bar:30} {pos}/{len} runs  {msg}  elapsed {elapsed}  ETA {eta}",
        };
        b.set_style(
            ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        if unit == Unit::Runs {
            b.enable_steady_tick(Duration::from_millis(500));
        }
        Box::new(Drawn(b))
    }
}

/// One bar on the terminal.
struct Drawn(ProgressBar);

impl Bar for Drawn {
    fn set(&self, position: u64, message: String) {
        self.0.set_position(position);
        self.0.set_message(message);
    }

    fn inc(&self, message: String) {
        self.0.inc(1);
        self.0.set_message(message);
    }

    fn line(&self, text: String) {
        self.0.println(text);
    }

    fn finish(&self) {
        self.0.finish_and_clear();
    }
}

/// Installs the logger, and the progress bars when standard error is a terminal (elsewhere
/// progress comes as lines).
pub fn install() {
    if log::set_logger(&TERMINAL).is_ok() {
        log::set_max_level(log::LevelFilter::Info);
    }
    if std::io::stderr().is_terminal() {
        hvi_run::progress::set_bars(Box::new(Indicatif));
    }
}
