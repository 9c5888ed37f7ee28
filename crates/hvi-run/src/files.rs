//! The ground floor of hvi-run, imported by the modules above it and importing none of them
//! but [`crate::error`]: atomic file writes, canonical JSON and the format and engine versions
//! that fingerprints record, the host's name, and the names of a run's files that more than
//! one module reads.

use std::fs;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::OnceLock;

use crate::error::{Result, ResultExt};

/// Version of the plan and run-record formats, and of what the fingerprint covers. Bump it
/// when either changes meaning, so old results are not mistaken for new ones.
pub const STUDY_FORMAT_VERSION: u32 = 1;

/// The engine version a fingerprint records: the workspace version. Results that a code change
/// alters need a version bump to invalidate cached runs (a decision: a hash of the source
/// would invalidate every run on every commit).
pub const ENGINE_VERSION: &str = env!("CARGO_PKG_VERSION");

/// How many hex digits of the fingerprint name a run's directory.
pub const DIR_DIGITS: usize = 16;

/// A single run's checkpoint file, in its output directory.
pub const CHECKPOINT_FILE: &str = "checkpoint.bin";

/// A single run's continuation state, in its output directory: what a later end time takes
/// up from (`crate::run::RunOptions::continuation`).
pub const CONTINUATION_FILE: &str = "continuation.bin";

/// Serialises a JSON value with object keys sorted and no whitespace: the same value always
/// gives the same bytes (serde_json writes floats in their shortest round-trip form).
pub fn canonical_json(v: &serde_json::Value) -> String {
    fn write(v: &serde_json::Value, out: &mut String) {
        match v {
            serde_json::Value::Object(m) => {
                let mut keys: Vec<&String> = m.keys().collect();
                keys.sort();
                out.push('{');
                for (i, k) in keys.iter().enumerate() {
                    if i > 0 {
                        out.push(',');
                    }
                    out.push_str(&serde_json::Value::String((*k).clone()).to_string());
                    out.push(':');
                    write(&m[*k], out);
                }
                out.push('}');
            }
            serde_json::Value::Array(a) => {
                out.push('[');
                for (i, x) in a.iter().enumerate() {
                    if i > 0 {
                        out.push(',');
                    }
                    write(x, out);
                }
                out.push(']');
            }
            other => out.push_str(&other.to_string()),
        }
    }
    let mut s = String::new();
    write(v, &mut s);
    s
}

/// Writes a file atomically: into a temporary sibling, flushed and synced, then renamed over
/// the target. A reader sees the old file or the new one, never a torn one. An I/O error is a
/// [`crate::error::RunError::Write`] of `path`, anything else `write` returns is said under "cannot write
/// PATH".
pub fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> Result<()>,
) -> Result<()> {
    let dir = path.parent().unwrap_or_else(|| Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp.{}", std::process::id()));
    let written = (|| -> Result<()> {
        let file = fs::File::create(&tmp)?;
        let mut w = BufWriter::new(file);
        write(&mut w)?;
        w.flush()?;
        w.get_ref().sync_all()?;
        Ok(())
    })();
    if let Err(e) = written {
        // A full disk, say: no partial file stays, and the error names the file.
        let _ = fs::remove_file(&tmp);
        return Err(e.writing(path, format!("cannot write {}", path.display())));
    }
    fs::rename(&tmp, path).write_context(path, || {
        format!("cannot move {} into place", path.display())
    })?;
    Ok(())
}

/// Removes the temporary files [`write_atomic_with`] left in `dir` when a process was killed during
/// a write (`.<name>.tmp.<pid>` of another process than this one), where the caller knows no
/// other process writes (a resumed run's own directory, a checkpoint under its run lock).
/// `only` restricts it to the temporaries of one file name. Returns how many.
pub fn remove_stale_partials(dir: &Path, only: Option<&str>) -> Result<usize> {
    let own = format!(".tmp.{}", std::process::id());
    let mut n = 0;
    let Ok(entries) = fs::read_dir(dir) else {
        return Ok(0);
    };
    for e in entries.filter_map(|e| e.ok()) {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some((target, pid)) = name.strip_prefix('.').and_then(|r| r.rsplit_once(".tmp."))
        else {
            continue;
        };
        let ours = only.is_none_or(|o| o == target);
        if ours && pid.parse::<u32>().is_ok() && !name.ends_with(&own) && e.path().is_file() {
            let path = e.path();
            fs::remove_file(&path)
                .write_context(&path, || format!("cannot remove {}", path.display()))?;
            n += 1;
        }
    }
    Ok(n)
}

/// Writes bytes atomically.
pub fn write_atomic_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |w| {
        w.write_all(bytes)?;
        Ok(())
    })
}

/// This machine's name as it appears in in-progress directory names (characters other than
/// letters, digits, `.`, `-` and `_` become `_`).
pub fn host_name() -> &'static str {
    static HOST: OnceLock<String> = OnceLock::new();
    HOST.get_or_init(|| {
        let raw = ["/proc/sys/kernel/hostname", "/etc/hostname"]
            .iter()
            .find_map(|p| fs::read_to_string(p).ok())
            .or_else(|| std::env::var("HOSTNAME").ok())
            .unwrap_or_default();
        let name: String = raw
            .trim()
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        if name.is_empty() {
            "unknown".into()
        } else {
            name
        }
    })
}
