//! The reproduction's history: one JSON record per `reproduce` run, appended to a JSON Lines
//! file (`history.jsonl` in the report directory, or `--history FILE` shared by several).
//!
//! A record holds what a reviewer asks of a night: the commit, the versions, the tier, the
//! date, the machine, the wall time of each stage, and every figure's verdict and deciding
//! numbers (timings left out: they differ between nights). The file is rewritten atomically
//! under an advisory lock, so two reproductions appending at once both land and a killed one
//! leaves the file whole. A line that does not parse (a hand edit, a foreign tool) is reported
//! and skipped when reading, and kept verbatim when appending: nothing is lost silently.
//! docs/reproduction.md describes the file.

use std::fs::OpenOptions;
use std::path::{Path, PathBuf};

use crate::report::{Machine, Reproduction, Value, Verdict};
use hvi_run::error::{Result, ResultExt};
use hvi_run::files::write_atomic_bytes;
use serde::{Deserialize, Serialize};

/// The history's file name in a report directory.
pub const HISTORY_FILE: &str = "history.jsonl";

/// One `reproduce` run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// The commit the binary ran from (`HVI_COMMIT`, else `git rev-parse` where the command
    /// ran, `-dirty` with uncommitted changes; `unknown` outside a repository).
    pub commit: String,
    /// The engine's version (`hvi-engine`).
    pub engine_version: String,
    /// The workspace's version (`hvi-study`).
    pub workspace_version: String,
    /// The tier.
    pub tier: String,
    /// When the run finished, UTC, RFC 3339.
    pub date: String,
    /// The machine.
    pub machine: Machine,
    /// Wall time of the whole run, s.
    pub wall_seconds: f64,
    /// Whether every stage finished.
    pub complete: bool,
    /// Each stage's wall time and runs.
    pub stages: Vec<StageRecord>,
    /// Each figure's verdict and deciding numbers.
    pub figures: Vec<FigureRecord>,
}

/// One stage of a recorded run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageRecord {
    /// The stage.
    pub stage: String,
    /// Wall time, s.
    pub wall_seconds: f64,
    /// Runs simulated.
    pub ran: usize,
    /// Runs found in the store.
    pub cached: usize,
}

/// One figure of a recorded run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FigureRecord {
    /// The paper's figure number(s).
    pub id: String,
    /// The verdict.
    pub verdict: Verdict,
    /// The deciding numbers (name, value), timings left out.
    pub numbers: Vec<(String, Value)>,
}

impl Record {
    /// The record of a finished reproduction, at `date` from `commit`.
    pub fn of(rep: &Reproduction, commit: String, date: String) -> Record {
        Record {
            commit,
            engine_version: hvi_run::files::ENGINE_VERSION.into(),
            workspace_version: rep.version.clone(),
            tier: rep.tier.clone(),
            date,
            machine: rep.machine.clone(),
            wall_seconds: rep.wall_seconds,
            complete: rep.complete,
            stages: rep
                .stages
                .iter()
                .map(|s| StageRecord {
                    stage: s.stage.clone(),
                    wall_seconds: s.wall_seconds,
                    ran: s.ran,
                    cached: s.cached,
                })
                .collect(),
            figures: rep
                .figures
                .iter()
                .map(|f| FigureRecord {
                    id: f.id.clone(),
                    verdict: f.verdict,
                    numbers: f
                        .numbers
                        .iter()
                        .filter(|n| !n.timing)
                        .map(|n| (n.name.clone(), n.value.clone()))
                        .collect(),
                })
                .collect(),
        }
    }

    /// A figure's record.
    pub fn figure(&self, id: &str) -> Option<&FigureRecord> {
        self.figures.iter().find(|f| f.id == id)
    }
}

impl FigureRecord {
    /// A deciding number's value.
    pub fn number(&self, name: &str) -> Option<&Value> {
        self.numbers.iter().find(|n| n.0 == name).map(|n| &n.1)
    }
}

/// A history file as read: its records in order and the lines that did not parse.
#[derive(Debug, Clone, Default)]
pub struct History {
    /// The file.
    pub path: PathBuf,
    /// Every record that parsed, in the file's order.
    pub records: Vec<Record>,
    /// Lines that did not parse: (line number from 1, why).
    pub damaged: Vec<(usize, String)>,
}

impl History {
    /// Reads a history (a missing file is an empty history).
    pub fn load(path: &Path) -> Result<History> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
            Err(e) => {
                return Err(e)
                    .with_context(|| format!("cannot read the history {}", path.display()))
            }
        };
        Ok(History::parse(path, &text))
    }

    fn parse(path: &Path, text: &str) -> History {
        let mut h = History {
            path: path.to_path_buf(),
            ..History::default()
        };
        for (k, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            match serde_json::from_str::<Record>(line) {
                Ok(r) => h.records.push(r),
                Err(e) => h.damaged.push((k + 1, e.to_string())),
            }
        }
        h
    }

    /// The records of one tier, in order (a shared history may hold several).
    pub fn of_tier<'a>(&'a self, tier: &'a str) -> impl Iterator<Item = &'a Record> + 'a {
        self.records.iter().filter(move |r| r.tier == tier)
    }

    /// Appends `record` to the history at `path` (created when missing) and returns the
    /// history as it now is. The file is rewritten atomically under an exclusive lock on
    /// `.<name>.lock` beside it; damaged lines stay as they were.
    pub fn append(path: &Path, record: &Record) -> Result<History> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
        }
        let lock_path = lock_path(path);
        let lock = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&lock_path)
            .with_context(|| format!("cannot open {}", lock_path.display()))?;
        // Where the filesystem has no locks, the atomic rewrite still leaves a whole file.
        let locked = lock.lock().is_ok();
        let mut text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
            Err(e) => {
                return Err(e)
                    .with_context(|| format!("cannot read the history {}", path.display()))
            }
        };
        if !text.is_empty() && !text.ends_with('\n') {
            text.push('\n');
        }
        text.push_str(&serde_json::to_string(record)?);
        text.push('\n');
        write_atomic_bytes(path, text.as_bytes())?;
        if locked {
            let _ = lock.unlock();
        }
        Ok(History::parse(path, &text))
    }
}

/// The lock beside a history: `.<name>.lock` (hidden, and ignored by the repository).
fn lock_path(path: &Path) -> PathBuf {
    let mut name = std::ffi::OsString::from(".");
    name.push(path.file_name().unwrap_or_default());
    name.push(".lock");
    path.with_file_name(name)
}

/// The commit the command runs from: `HVI_COMMIT` when set (a CI job that builds elsewhere),
/// else `git rev-parse --short=12 HEAD` in the current directory with `-dirty` when tracked
/// files differ from it, else `unknown`.
pub fn current_commit() -> String {
    if let Ok(c) = std::env::var("HVI_COMMIT") {
        if !c.trim().is_empty() {
            return c.trim().to_string();
        }
    }
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .stderr(std::process::Stdio::null())
            .output()
            .ok()
    };
    let Some(head) = git(&["rev-parse", "--short=12", "HEAD"])
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .filter(|s| !s.is_empty())
    else {
        return "unknown".into();
    };
    let dirty = git(&["diff", "--quiet", "HEAD", "--"]).is_some_and(|o| o.status.code() == Some(1));
    if dirty {
        format!("{head}-dirty")
    } else {
        head
    }
}

/// Now, UTC, RFC 3339 to the second.
pub fn now_utc() -> String {
    humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(commit: &str, x: f64, verdict: Verdict) -> Record {
        Record {
            commit: commit.into(),
            engine_version: "0.6.0".into(),
            workspace_version: "0.6.0".into(),
            tier: "quick".into(),
            date: "2026-12-04T00:00:00Z".into(),
            machine: Machine {
                cpu: "test".into(),
                cores: 2,
                os: "linux".into(),
            },
            wall_seconds: 1.0,
            complete: true,
            stages: vec![],
            figures: vec![FigureRecord {
                id: "9".into(),
                verdict,
                numbers: vec![("R".into(), Value::Number(x))],
            }],
        }
    }

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hvi-history-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("dir");
        d
    }

    #[test]
    fn records_append_in_order_and_a_damaged_line_is_reported_and_kept() {
        let dir = scratch("append");
        let path = dir.join("sub").join(HISTORY_FILE);
        let h = History::append(&path, &record("a", 1.0, Verdict::Reproduced)).expect("one");
        assert_eq!(h.records.len(), 1);
        // A hand edit breaks a line (and leaves no newline at the end).
        let mut text = std::fs::read_to_string(&path).expect("read");
        text.push_str("{\"commit\": \"truncated");
        std::fs::write(&path, &text).expect("write");
        let h = History::append(&path, &record("b", 2.0, Verdict::Partly)).expect("two");
        assert_eq!(
            h.records
                .iter()
                .map(|r| r.commit.as_str())
                .collect::<Vec<_>>(),
            ["a", "b"]
        );
        assert_eq!(h.damaged.len(), 1);
        assert_eq!(h.damaged[0].0, 2);
        let again = History::load(&path).expect("load");
        assert_eq!(again.records, h.records);
        assert!(std::fs::read_to_string(&path)
            .expect("read")
            .contains("{\"commit\": \"truncated\n"));
        assert_eq!(
            again.records[1].figure("9").and_then(|f| f.number("R")),
            Some(&Value::Number(2.0))
        );
    }

    #[test]
    fn a_missing_history_is_empty_and_tiers_are_kept_apart() {
        let dir = scratch("tiers");
        let path = dir.join(HISTORY_FILE);
        assert!(History::load(&path).expect("load").records.is_empty());
        History::append(&path, &record("a", 1.0, Verdict::Reproduced)).expect("a");
        let mut paper = record("b", 1.0, Verdict::Reproduced);
        paper.tier = "paper".into();
        let h = History::append(&path, &paper).expect("b");
        assert_eq!(h.of_tier("quick").count(), 1);
        assert_eq!(h.of_tier("paper").count(), 1);
    }

    #[test]
    fn the_date_is_utc_to_the_second() {
        let d = now_utc();
        assert_eq!(d.len(), 20, "{d}");
        assert!(d.ends_with('Z') && d.as_bytes()[10] == b'T', "{d}");
    }
}
