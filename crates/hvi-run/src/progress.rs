//! How a library reports without printing: messages go through the `log` facade (the command's
//! logger prints them, those of target [`STDOUT`] on standard output, the rest on standard
//! error), and progress bars are drawn by the command through [`Bars`], installed once as the
//! logger is. Without bars (not a terminal, a library caller, a test) progress goes to the log
//! as lines.

use std::sync::OnceLock;

/// The log target whose messages the command prints on standard output: the paths a workflow
/// wrote and the tables a script reads. Every other message goes to standard error.
pub const STDOUT: &str = "hvi::stdout";

/// What a bar counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    /// A run's base steps.
    Steps,
    /// A batch's runs.
    Runs,
}

/// A progress bar as the command draws it.
pub trait Bar: Send + Sync {
    /// Sets the position and the message beside the bar.
    fn set(&self, position: u64, message: String);
    /// One more done, and the message beside the bar.
    fn inc(&self, message: String);
    /// A line said above the bar.
    fn line(&self, text: String);
    /// Removes the bar.
    fn finish(&self);
}

/// Makes bars: the command's, installed with [`set_bars`].
pub trait Bars: Send + Sync {
    /// A new bar over `total` of `unit`.
    fn bar(&self, total: u64, unit: Unit) -> Box<dyn Bar>;
}

static BARS: OnceLock<Box<dyn Bars>> = OnceLock::new();

/// Installs the command's bars; false when bars were installed before (the first stay).
pub fn set_bars(bars: Box<dyn Bars>) -> bool {
    BARS.set(bars).is_ok()
}

/// A new bar over `total` of `unit`, or none when the command installed no bars.
pub fn bar(total: u64, unit: Unit) -> Option<Box<dyn Bar>> {
    BARS.get().map(|b| b.bar(total, unit))
}
