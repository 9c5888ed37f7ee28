//! Advisory locks (`flock` through `std::fs::File::lock`), so that two processes never do the
//! same work in one study directory:
//!
//! - the **study lock** `<study>/.study.lock`, taken by the process that writes the study's
//!   `plan.json` and held until it exits: a second `sweep`, `calibrate`, ... of the same
//!   directory waits for the first (and then reuses its runs) instead of planning over it;
//! - a **run lock** `runs/.lock-<digits>`, held while a run is computed: a second process (a
//!   Slurm task, another sweep) waits for it and then takes its record instead of running it
//!   again.
//!
//! Where the filesystem does not support locks (some network filesystems) the locks are skipped
//! with one warning, and the store's own rule holds: a run appears complete or not at all (an
//! atomic rename), and a run finished twice keeps the first result.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

use hvi_run::error::{Result, ResultExt};

/// The study locks this process holds (kept until it exits).
static HELD: Mutex<Vec<(PathBuf, File)>> = Mutex::new(Vec::new());

/// Whether the "locks unsupported" warning was printed.
static WARNED: AtomicBool = AtomicBool::new(false);

fn unsupported(path: &Path, e: &std::io::Error) {
    if !WARNED.swap(true, Ordering::Relaxed) {
        log::warn!(
            "warning: cannot lock {} ({e}); going on without advisory locks: the run store's \
             atomic renames still keep every result whole, but two processes may compute the \
             same run",
            path.display()
        );
    }
}

fn open(path: &Path) -> Result<File> {
    OpenOptions::new()
        .create(true)
        .truncate(false)
        .read(true)
        .write(true)
        .open(path)
        .write_context(path, || {
            format!("cannot open the lock file {}", path.display())
        })
}

/// Who holds a lock, as its holder wrote it ("pid 123 on host, hvi-study sweep").
fn holder(file: &mut File) -> String {
    let mut s = String::new();
    let _ = file.seek(SeekFrom::Start(0));
    let _ = file.read_to_string(&mut s);
    let s = s.trim();
    if s.is_empty() {
        "another process".into()
    } else {
        s.to_string()
    }
}

/// Writes this process into a lock file it holds.
fn stamp(file: &mut File) {
    let args: Vec<String> = std::env::args().take(3).collect();
    let _ = file.set_len(0);
    let _ = file.seek(SeekFrom::Start(0));
    let _ = writeln!(
        file,
        "pid {} on {}: {}",
        std::process::id(),
        hvi_run::files::host_name(),
        args.join(" ")
    );
    let _ = file.flush();
}

/// Locks `path` exclusively, waiting (and saying so, with `waiting(holder)`) when another
/// process holds it. `None` when the filesystem cannot lock (warned once).
fn acquire(path: &Path, waiting: &dyn Fn(&str) -> String) -> Result<Option<File>> {
    let mut file = open(path)?;
    match file.try_lock() {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => {
            log::info!("{}", waiting(&holder(&mut file)));
            if let Err(e) = file.lock() {
                unsupported(path, &e);
                return Ok(None);
            }
        }
        Err(TryLockError::Error(e)) => {
            unsupported(path, &e);
            return Ok(None);
        }
    }
    stamp(&mut file);
    Ok(Some(file))
}

/// Takes the study lock of `dir` for the rest of this process (a no-op when it holds it
/// already); waits, saying who holds it, when another process does.
pub fn hold_study(dir: &Path) -> Result<()> {
    let key = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    let mut held = HELD.lock().unwrap_or_else(|p| p.into_inner());
    if held.iter().any(|(d, _)| *d == key) {
        return Ok(());
    }
    let path = dir.join(".study.lock");
    let waiting = |who: &str| {
        format!(
            "{}: another hvi-study ({who}) is working in this study directory; waiting for it \
             to finish (its finished runs are then reused, nothing is done twice)",
            dir.display()
        )
    };
    if let Some(file) = acquire(&path, &waiting)? {
        held.push((key, file));
    }
    Ok(())
}

/// A run lock, released when dropped.
#[derive(Debug)]
pub struct RunLock {
    _file: Option<File>,
}

/// Takes the lock of the run whose directory is `run_dir` (the file `.lock-<name>` beside it),
/// waiting, and saying so, when another process computes that run.
pub fn lock_run(run_dir: &Path) -> Result<RunLock> {
    let name = run_dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let parent = run_dir.parent().unwrap_or_else(|| Path::new("."));
    let path = parent.join(format!(".lock-{name}"));
    let waiting = |who: &str| {
        format!(
            "run {}: computed by another process ({who}); waiting for its result",
            run_dir.display()
        )
    };
    Ok(RunLock {
        _file: acquire(&path, &waiting)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_lock_excludes_a_second_holder_until_dropped() {
        let dir = std::env::temp_dir().join(format!("hvi-lock-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("dir");
        let run = dir.join("0123456789abcdef");
        let first = lock_run(&run).expect("locks");
        // Another open file description of the same file cannot take it meanwhile.
        let other = open(&dir.join(".lock-0123456789abcdef")).expect("opens");
        assert!(matches!(other.try_lock(), Err(TryLockError::WouldBlock)));
        drop(first);
        assert!(other.try_lock().is_ok(), "released on drop");
        // The study lock is held once per process and directory.
        hold_study(&dir).expect("study lock");
        hold_study(&dir).expect("again: a no-op");
        let again = open(&dir.join(".study.lock")).expect("opens");
        assert!(matches!(again.try_lock(), Err(TryLockError::WouldBlock)));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
