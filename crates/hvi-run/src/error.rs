//! hvi-run's one error type, [`RunError`], and the exit code a failed command ends with
//! ([`exit_code`]).
//!
//! The ground floor with [`crate::files`]: it imports no module of the crate (the
//! [`Interrupted`] error lives here, and [`crate::interrupt`] re-exports it).
//!
//! An error is a chain, as `anyhow`'s are: a [`RunError::Context`] says what was being done
//! and its `source()` is the error below it; a read or write error's source is the system's
//! reason. `{}` prints an error's own message, `{:#}` the whole chain joined by `: ` (as
//! `anyhow` prints it, and as `anyhow` prints an `anyhow::Error` made from a `RunError`):
//! `run 3: cannot write runs/.tmp-…/record.json: No space left on device (os error 28)`.

use std::error::Error as StdError;
use std::fmt;
use std::path::{Path, PathBuf};

/// A library error with its own chain (`anyhow::Error` converts into it with `.into()`).
pub type BoxError = Box<dyn StdError + Send + Sync + 'static>;

/// Everything that can go wrong in hvi-run, each naming what to fix.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A scene value outside its range, or a run the engine stopped (the engine's error).
    #[error(transparent)]
    Engine(#[from] hvi_engine::error::EngineError),
    /// An analysis refused its input or failed (a targets file, a surrogate fit).
    #[error(transparent)]
    Analysis(#[from] hvi_analysis::error::AnalysisError),
    /// A picture that could not be drawn or written.
    #[error(transparent)]
    Plot(#[from] hvi_plot::error::PlotError),
    /// Wrong input: a scene or study file's key, an option, a value; the message names the
    /// field and what is allowed.
    #[error("{0}")]
    Input(String),
    /// An input file or directory that cannot be read (missing, no permission).
    #[error(fmt = fmt_io)]
    Read {
        /// The file or directory.
        path: PathBuf,
        /// What could not be done, naming the path ("cannot read scene file …").
        message: String,
        /// The system's reason.
        #[source]
        source: std::io::Error,
    },
    /// An output that cannot be written (a full disk, an unwritable directory): exit code 74.
    #[error(fmt = fmt_io)]
    Write {
        /// The file or directory.
        path: PathBuf,
        /// What could not be done, naming the path ("cannot write …", "cannot create …").
        message: String,
        /// The system's reason.
        #[source]
        source: std::io::Error,
    },
    /// A file whose content is malformed (a plan, a run record, a submission record, a state
    /// file, a checkpoint): the message says what is wrong and, where it is known here, the
    /// file (otherwise a [`RunError::Context`] around it names it).
    #[error(fmt = fmt_parse)]
    Parse {
        /// What is wrong.
        message: String,
        /// The parser's own error, if it has one.
        #[source]
        source: Option<BoxError>,
    },
    /// The store refuses (another study's plan, another fingerprint, a damaged run in a store
    /// opened for reading, ...).
    #[error("{0}")]
    Store(String),
    /// Results that break what hvi-run checks of them (physics that differs between thread
    /// counts).
    #[error("{0}")]
    Invariant(String),
    /// The scheduler (Slurm) or an external program refused or failed: exit code 69.
    #[error("{0}")]
    External(String),
    /// A signal asked the work to stop: exit code 128 + the signal's number.
    #[error(transparent)]
    Interrupted(#[from] Interrupted),
    /// A system error where a [`RunError::Context`] around it, or the caller, names the file
    /// (inside [`crate::files::write_atomic_with`], a directory listing).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// An error of a library hvi-run calls, with its own chain: a picture hvi-plot could not
    /// draw or save, a target file hvi-analysis refused, JSON or TOML that does not parse, a
    /// thread pool that does not start.
    #[error(transparent)]
    Library(BoxError),
    /// A lower error with what was being done when it happened.
    #[error(fmt = fmt_context)]
    Context {
        /// What was being done.
        context: String,
        /// The error.
        #[source]
        source: Box<RunError>,
    },
}

/// Result type of hvi-run.
pub type Result<T> = std::result::Result<T, RunError>;

/// `message`, and under `{:#}` the chain below it (`: cause` for each, as `anyhow` prints it).
fn fmt_chain(
    message: &str,
    source: Option<&(dyn StdError + 'static)>,
    f: &mut fmt::Formatter<'_>,
) -> fmt::Result {
    match source {
        Some(source) => hvi_analysis::error::fmt_chain(message, source, f),
        None => f.write_str(message),
    }
}

fn fmt_io(
    _path: &Path,
    message: &str,
    source: &std::io::Error,
    f: &mut fmt::Formatter<'_>,
) -> fmt::Result {
    fmt_chain(message, Some(source), f)
}

fn fmt_parse(message: &str, source: &Option<BoxError>, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    fmt_chain(
        message,
        source.as_deref().map(|s| s as &(dyn StdError + 'static)),
        f,
    )
}

fn fmt_context(context: &str, source: &RunError, f: &mut fmt::Formatter<'_>) -> fmt::Result {
    fmt_chain(context, Some(source), f)
}

impl RunError {
    /// [`RunError::Read`] with the message "cannot read PATH".
    pub fn read(path: &Path, source: std::io::Error) -> RunError {
        RunError::Read {
            message: format!("cannot read {}", path.display()),
            path: path.to_path_buf(),
            source,
        }
    }

    /// [`RunError::Write`] with the message "cannot write PATH".
    pub fn write(path: &Path, source: std::io::Error) -> RunError {
        RunError::Write {
            message: format!("cannot write {}", path.display()),
            path: path.to_path_buf(),
            source,
        }
    }

    /// [`RunError::Parse`] without a parser's error.
    pub fn parse(message: impl Into<String>) -> RunError {
        RunError::Parse {
            message: message.into(),
            source: None,
        }
    }

    /// A library's error (an `anyhow::Error` of hvi-plot or hvi-analysis, say) as
    /// [`RunError::Library`]; a `RunError` boxed as one comes back as itself.
    pub fn library(e: impl Into<BoxError>) -> RunError {
        match e.into().downcast::<RunError>() {
            Ok(r) => *r,
            Err(e) => RunError::Library(e),
        }
    }

    /// This error, an I/O error, as a [`RunError::Read`] of `path` with `message` (naming the
    /// path); another with `message` said above it.
    pub fn reading(self, path: &Path, message: impl Into<String>) -> RunError {
        match self {
            RunError::Io(source) => RunError::Read {
                path: path.to_path_buf(),
                message: message.into(),
                source,
            },
            other => other.context(message),
        }
    }

    /// This error, an I/O error, as a [`RunError::Write`] of `path` with `message` (naming the
    /// path); another with `message` said above it.
    pub fn writing(self, path: &Path, message: impl Into<String>) -> RunError {
        match self {
            RunError::Io(source) => RunError::Write {
                path: path.to_path_buf(),
                message: message.into(),
                source,
            },
            other => other.context(message),
        }
    }

    /// This error with `context` said above it.
    pub fn context(self, context: impl Into<String>) -> RunError {
        RunError::Context {
            context: context.into(),
            source: Box::new(self),
        }
    }

    /// The errors of this chain that are `RunError`s, this one first.
    pub fn chain(&self) -> impl Iterator<Item = &RunError> {
        run_errors(self)
    }
}

/// JSON that does not parse or serialise; an I/O error under it stays one ([`RunError::Io`]).
impl From<serde_json::Error> for RunError {
    fn from(e: serde_json::Error) -> RunError {
        if e.is_io() {
            RunError::Io(e.into())
        } else {
            RunError::Library(Box::new(e))
        }
    }
}

/// A CSV writer's or reader's error; an I/O error under it stays one ([`RunError::Io`]).
impl From<csv::Error> for RunError {
    fn from(e: csv::Error) -> RunError {
        if !e.is_io_error() {
            return RunError::Library(Box::new(e));
        }
        match e.into_kind() {
            csv::ErrorKind::Io(io) => RunError::Io(io),
            other => RunError::Library(format!("{other:?}").into()),
        }
    }
}

/// TOML that does not parse.
impl From<toml::de::Error> for RunError {
    fn from(e: toml::de::Error) -> RunError {
        RunError::Library(Box::new(e))
    }
}

/// A value that cannot be written as TOML.
impl From<toml::ser::Error> for RunError {
    fn from(e: toml::ser::Error) -> RunError {
        RunError::Library(Box::new(e))
    }
}

/// A checkpoint payload that does not encode or decode.
impl From<postcard::Error> for RunError {
    fn from(e: postcard::Error) -> RunError {
        RunError::Library(Box::new(e))
    }
}

/// A number in a table that does not parse.
impl From<std::num::ParseFloatError> for RunError {
    fn from(e: std::num::ParseFloatError) -> RunError {
        RunError::Library(Box::new(e))
    }
}

/// An integer in a table that does not parse.
impl From<std::num::ParseIntError> for RunError {
    fn from(e: std::num::ParseIntError) -> RunError {
        RunError::Library(Box::new(e))
    }
}

/// A formatter that failed (writing into a `String` does not).
impl From<std::fmt::Error> for RunError {
    fn from(e: std::fmt::Error) -> RunError {
        RunError::Library(Box::new(e))
    }
}

/// `.context(...)` and `.with_context(|| ...)` on an `Option`: `None` becomes a
/// [`RunError::Input`] with that message (the message names what is missing and what is
/// allowed), as `anyhow::Context` makes an error of `None`.
pub trait OptionExt<T> {
    /// `None` as an error with `message`.
    fn context(self, message: impl Into<String>) -> Result<T>;
    /// `None` as an error with the message `f` makes (made only on `None`).
    fn with_context<C: Into<String>>(self, f: impl FnOnce() -> C) -> Result<T>;
}

impl<T> OptionExt<T> for Option<T> {
    fn context(self, message: impl Into<String>) -> Result<T> {
        self.ok_or_else(|| RunError::Input(message.into()))
    }

    fn with_context<C: Into<String>>(self, f: impl FnOnce() -> C) -> Result<T> {
        self.ok_or_else(|| RunError::Input(f().into()))
    }
}

/// `return Err(RunError::Input(format!(...)))`: a refusal whose message names the field and
/// what is allowed (as `anyhow::bail!` reads, with a typed error).
#[macro_export]
macro_rules! bail {
    ($($t:tt)*) => {
        return Err($crate::error::RunError::Input(format!($($t)*)))
    };
}

/// A worker pool that does not start.
impl From<rayon::ThreadPoolBuildError> for RunError {
    fn from(e: rayon::ThreadPoolBuildError) -> RunError {
        RunError::Library(Box::new(e))
    }
}

/// `.context(...)` and `.with_context(|| ...)` on results whose error becomes a [`RunError`],
/// as `anyhow::Context` gives them (the context is said above the error:
/// [`RunError::Context`]), and `.read_context` / `.write_context`, which make an I/O error a
/// [`RunError::Read`] or [`RunError::Write`] of a path.
pub trait ResultExt<T> {
    /// The error with `context` above it.
    fn context(self, context: impl Into<String>) -> Result<T>;
    /// The error with the context `f` makes above it (made only on an error).
    fn with_context<C: Into<String>>(self, f: impl FnOnce() -> C) -> Result<T>;
    /// An I/O error as a [`RunError::Read`] of `path` with the `message` that names it
    /// ("cannot read …"); another error with that message above it ([`RunError::reading`]).
    fn read_context(self, path: &Path, message: impl FnOnce() -> String) -> Result<T>;
    /// An I/O error as a [`RunError::Write`] of `path` with the `message` that names it
    /// ("cannot create …"); another error with that message above it ([`RunError::writing`]).
    fn write_context(self, path: &Path, message: impl FnOnce() -> String) -> Result<T>;
}

impl<T, E: Into<RunError>> ResultExt<T> for std::result::Result<T, E> {
    fn context(self, context: impl Into<String>) -> Result<T> {
        self.map_err(|e| e.into().context(context))
    }

    fn with_context<C: Into<String>>(self, f: impl FnOnce() -> C) -> Result<T> {
        self.map_err(|e| e.into().context(f()))
    }

    fn read_context(self, path: &Path, message: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|e| e.into().reading(path, message()))
    }

    fn write_context(self, path: &Path, message: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|e| e.into().writing(path, message()))
    }
}

/// SIGINT's number.
pub const SIGINT: i32 = 2;
/// SIGTERM's number.
pub const SIGTERM: i32 = 15;

/// The error a run or a study returns when a signal stopped it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Interrupted(pub i32);

impl Interrupted {
    /// The signal's name.
    pub fn name(&self) -> &'static str {
        match self.0 {
            SIGINT => "SIGINT (Ctrl-C)",
            SIGTERM => "SIGTERM",
            _ => "a signal",
        }
    }
    /// The exit code: 128 + the signal's number.
    pub fn exit_code(&self) -> u8 {
        (128 + self.0).clamp(0, 255) as u8
    }
}

impl fmt::Display for Interrupted {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "interrupted by {}", self.name())
    }
}

impl StdError for Interrupted {}

/// The `RunError`s in an error's chain (walking `source()`), outermost first: the error
/// itself if it is one, and every one below it (also where a [`RunError::Context`] holds it
/// boxed, and under an `anyhow::Error`'s contexts).
pub fn run_errors<'a>(e: &'a (dyn StdError + 'static)) -> impl Iterator<Item = &'a RunError> {
    std::iter::successors(Some(e), |&e| e.source()).filter_map(as_run_error)
}

/// `e` as a `RunError`, if it is one (also boxed, as a [`RunError::Context`]'s `source()`
/// gives the error below it).
pub fn as_run_error<'a>(e: &'a (dyn StdError + 'static)) -> Option<&'a RunError> {
    e.downcast_ref::<RunError>()
        .or_else(|| e.downcast_ref::<Box<RunError>>().map(|b| &**b))
}

/// Whether `e` is a failure that running the same scene again repeats: the first engine error
/// in its chain, when that one is reproducible ([`hvi_engine::error::EngineError::is_reproducible`]).
/// A store keeps such a failure as the run's result rather than running it again.
pub fn is_reproducible(e: &(dyn StdError + 'static)) -> bool {
    std::iter::successors(Some(e), |&e| e.source())
        .find_map(|c| match as_run_error(c) {
            Some(RunError::Engine(engine)) => Some(engine.is_reproducible()),
            _ => c
                .downcast_ref::<hvi_engine::error::EngineError>()
                .map(hvi_engine::error::EngineError::is_reproducible),
        })
        .unwrap_or(false)
}

/// Exit code of a bad input or any other error: 2.
pub const EXIT_ERROR: u8 = 2;
/// Exit code of a scheduler or external program that refused or failed (EX_UNAVAILABLE): 69.
pub const EXIT_UNAVAILABLE: u8 = 69;
/// Exit code of an output that cannot be written (EX_IOERR): 74.
pub const EXIT_IO: u8 = 74;

/// The exit code a command that failed with `e` ends with, from the first cause in its chain
/// that decides one: a signal 128 + its number ([`Interrupted::exit_code`]), an output that
/// cannot be written ([`RunError::Write`], or an I/O error that only a write gives: a full
/// disk, a read-only filesystem) [`EXIT_IO`], the scheduler or an external program
/// ([`RunError::External`]) [`EXIT_UNAVAILABLE`], anything else (a bad input, a refusal)
/// [`EXIT_ERROR`]. docs/running.md lists them.
pub fn exit_code(e: &(dyn StdError + 'static)) -> u8 {
    for cause in std::iter::successors(Some(e), |&e| e.source()) {
        if let Some(stop) = cause.downcast_ref::<Interrupted>() {
            return stop.exit_code();
        }
        let run = as_run_error(cause);
        match run {
            Some(RunError::Interrupted(stop)) => return stop.exit_code(),
            Some(RunError::Write { .. }) => return EXIT_IO,
            Some(RunError::Plot(hvi_plot::error::PlotError::Write { .. })) => return EXIT_IO,
            Some(RunError::External(_)) => return EXIT_UNAVAILABLE,
            _ => {}
        }
        let io = match run {
            Some(RunError::Io(io)) => Some(io),
            _ => cause.downcast_ref::<std::io::Error>(),
        };
        if io.is_some_and(|io| {
            matches!(
                io.kind(),
                std::io::ErrorKind::StorageFull | std::io::ErrorKind::ReadOnlyFilesystem
            )
        }) {
            return EXIT_IO;
        }
    }
    EXIT_ERROR
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::ErrorKind;

    fn full_disk() -> std::io::Error {
        std::io::Error::new(ErrorKind::StorageFull, "No space left on device")
    }

    #[test]
    fn only_the_engines_verdict_on_the_scene_is_reproducible() {
        use hvi_engine::error::EngineError;
        let unstable = RunError::from(EngineError::Unstable {
            step: 42,
            time_s: 1e-7,
            reason: "two particles 0.338 sigma apart".into(),
        })
        .context("run stopped early; what it had is in x");
        assert!(is_reproducible(&unstable));
        let rejected = RunError::from(EngineError::invalid("material.eps_j", -1, "> 0"));
        assert!(is_reproducible(&rejected));
        let foreign = RunError::from(EngineError::StateMismatch("another scene".into()))
            .context("resuming from the checkpoint");
        assert!(!is_reproducible(&foreign));
        let disk = RunError::write(Path::new("x/record.json"), full_disk()).context("run 3");
        assert!(!is_reproducible(&disk));
        assert!(!is_reproducible(&RunError::Input("bad".into())));
    }

    #[test]
    fn a_chain_prints_as_anyhow_printed_it() {
        let e = RunError::write(Path::new("x/record.json"), full_disk())
            .context("run 3")
            .context("sweep");
        let want = "sweep: run 3: cannot write x/record.json: No space left on device";
        assert_eq!(format!("{e:#}"), want);
        assert_eq!(format!("{e}"), "sweep");
        // The same through anyhow, its own contexts above it.
        let any = anyhow::Error::from(e);
        assert_eq!(format!("{any:#}"), want);
        assert_eq!(
            format!("{:#}", any.context("study")),
            format!("study: {want}")
        );
        // Exactly what anyhow printed for the same chain built with anyhow.
        let old = anyhow::Error::from(full_disk())
            .context("cannot write x/record.json")
            .context("run 3")
            .context("sweep");
        assert_eq!(format!("{old:#}"), want);
        // A parse error with its parser's error, a library's chain.
        let json = || serde_json::from_str::<u32>("{").expect_err("not a number");
        let p = RunError::Parse {
            message: "p.json is not a plan.json".into(),
            source: Some(Box::new(json())),
        };
        let old = anyhow::Error::from(json()).context("p.json is not a plan.json");
        assert_eq!(format!("{p:#}"), format!("{old:#}"));
        assert!(format!("{p:#}").contains("expected u32"), "{p:#}");
        let lib = RunError::library(anyhow::anyhow!("PNG data").context("cannot draw"))
            .context("rendering fragments.png");
        assert_eq!(
            format!("{:#}", anyhow::Error::from(lib)),
            "rendering fragments.png: cannot draw: PNG data"
        );
        // A RunError that went through a box comes back as itself.
        let back = RunError::library(RunError::External("sbatch failed".into()));
        assert!(matches!(back, RunError::External(_)));
    }

    #[test]
    fn a_picture_or_an_analysis_that_failed_keeps_its_chain_and_exit_code() {
        let denied = std::io::Error::new(ErrorKind::PermissionDenied, "Permission denied");
        let plot = hvi_plot::error::PlotError::Write {
            path: "map.png".into(),
            context: "cannot create map.png".into(),
            source: denied,
        };
        let e = RunError::from(plot).context("the calibration's maps");
        assert_eq!(
            format!("{e:#}"),
            "the calibration's maps: cannot create map.png: Permission denied"
        );
        assert_eq!(exit_code(&e), EXIT_IO);
        let bad = hvi_analysis::error::AnalysisError::Input("targets[0]: weight -1".into());
        let e = RunError::from(bad);
        assert_eq!(format!("{e:#}"), "targets[0]: weight -1");
        assert_eq!(exit_code(&e), EXIT_ERROR);
    }

    #[test]
    fn the_exit_code_is_found_below_contexts() {
        let write = RunError::write(Path::new("out/runs/a/record.json"), full_disk())
            .context("run 3")
            .context("execution");
        assert_eq!(exit_code(&write), EXIT_IO);
        let any = anyhow::Error::from(write).context("sweep");
        assert_eq!(exit_code(&*any), EXIT_IO);
        // A full disk under a bare I/O error, an anyhow chain, or a library's error.
        let io = RunError::Io(full_disk()).context("cannot move x into place");
        assert_eq!(exit_code(&io), EXIT_IO);
        let lib = RunError::library(anyhow::Error::from(full_disk()).context("cannot write p"));
        assert_eq!(exit_code(&lib.context("rendering p")), EXIT_IO);
        // A file that cannot be read is an input error, even with PermissionDenied.
        let read = RunError::read(
            Path::new("s.toml"),
            std::io::Error::from(ErrorKind::PermissionDenied),
        );
        assert_eq!(exit_code(&read), EXIT_ERROR);
        let slurm = RunError::External("sbatch failed (exit status: 1): no".into())
            .context("nothing submitted");
        assert_eq!(
            exit_code(&*anyhow::Error::from(slurm).context("submit")),
            69
        );
        let stop = RunError::from(Interrupted(15)).context("run 2");
        assert_eq!(exit_code(&stop), 143);
        assert_eq!(exit_code(&*anyhow::Error::from(Interrupted(2))), 130);
        assert_eq!(exit_code(&RunError::Input("bad --poll".into())), EXIT_ERROR);
        assert_eq!(exit_code(&*anyhow::anyhow!("hvi-study's own")), EXIT_ERROR);
        // The RunErrors of a chain, through the boxes.
        let kinds: Vec<bool> = RunError::External("x".into())
            .context("a")
            .chain()
            .map(|e| matches!(e, RunError::External(_)))
            .collect();
        assert_eq!(kinds, [false, true]);
    }
}
