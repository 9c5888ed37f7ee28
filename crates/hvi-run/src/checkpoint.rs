//! Checkpoints of a run in progress, so that a run killed at any moment (SIGKILL, a Slurm time
//! limit, preemption, a power cut after the file reached the disk) resumes from its last
//! checkpoint and ends bit-identical to a run never stopped: the same `energy.csv`, cloud
//! files, `state.bin`, trajectory and `summary.json` apart from its timings.
//!
//! A run ([`crate::run::run_scene`]) writes one between two steps, at a landing (the state
//! there is whole: the step, the energy sample, the cloud sample and any dump are done):
//! - every [`Every`] (`--checkpoint-every`: wall time such as `10m`, the default, or base
//!   steps such as `5000steps`; `off` for none);
//! - when Ctrl-C or SIGTERM stops it ([`crate::interrupt`]): Slurm's `--signal` sends SIGTERM
//!   before a time limit, so a task writes one before it is killed.
//!
//! A single run (`hvi-study run`) keeps it as `checkpoint.bin` in its output directory; a run of
//! a study store as `runs/.checkpoint-<digits>.bin` beside its run lock. The same command again
//! resumes from it; the run removes it once it has ended (completed or failed: both are
//! results).
//!
//! A checkpoint is used only for the run it was written by: its key is the SHA-256 of the
//! scene (every key), the output choices that shape what a run gathers (pictures, dumps) and
//! the program's version ([`key`]). One of another run is reported and replaced; a damaged one
//! (truncated, changed, of another format) is reported and the run starts from t = 0.
//!
//! # Format, version 1
//!
//! Little-endian: a 64-byte header, the payload, and the SHA-256 of all bytes before it.
//!
//! | offset | bytes | type | field |
//! |---|---|---|---|
//! | 0 | 8 | ASCII | magic `HVICKPT\0` |
//! | 8 | 4 | u32 | format version, 1 |
//! | 12 | 4 | u32 | reserved, 0 |
//! | 16 | 32 | bytes | the run's key ([`key`]) |
//! | 48 | 8 | u64 | base step of the state |
//! | 56 | 8 | u64 | payload bytes P |
//! | 64 | P | postcard | the payload: the simulation's [`hvi_engine::sim::SimState`] and what the run gathered |
//! | 64 + P | 32 | bytes | SHA-256 of everything before |
//!
//! The payload is serde's data model in `postcard`'s encoding: floats bit for bit, integers as
//! variable-length. It holds every particle's position, velocity and force in f64 and the
//! neighbour list, about 300 bytes per particle: 80 MB at the paper's 2.7e5 particles, written
//! in well under a second, once per interval.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

use serde::de::DeserializeOwned;
use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::error::{Result, ResultExt, RunError};
use crate::files::write_atomic_bytes;
pub use crate::files::CHECKPOINT_FILE;

/// The first eight bytes of a checkpoint.
pub const MAGIC: [u8; 8] = *b"HVICKPT\0";
/// The format version this code writes and reads.
pub const FORMAT_VERSION: u32 = 1;
/// Header bytes.
pub const HEADER_BYTES: usize = 64;
/// Bytes of the trailing SHA-256.
pub const CHECKSUM_BYTES: usize = 32;

/// How often a run writes a checkpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Every {
    /// Never (not even when a signal stops the run).
    Off,
    /// After this much wall time since the run started or its last checkpoint.
    Wall(Duration),
    /// At the first landing at or after each multiple of this many base steps.
    Steps(u64),
}

impl Default for Every {
    /// Every 10 minutes of wall time: a small fraction of a long run's time for the file, and
    /// at most 10 minutes lost to a kill.
    fn default() -> Self {
        Every::Wall(Duration::from_secs(600))
    }
}

impl FromStr for Every {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let t = s.trim();
        let bad = || {
            format!(
                "invalid value for `--checkpoint-every`: {s} (allowed: `off`, a wall time such \
                 as 90s, 10m or 2h, or a number of base steps such as 5000steps)"
            )
        };
        if t == "off" {
            return Ok(Every::Off);
        }
        if let Some(n) = t.strip_suffix("steps") {
            return match n.trim().parse::<u64>() {
                Ok(n) if n >= 1 => Ok(Every::Steps(n)),
                _ => Err(bad()),
            };
        }
        let (number, unit) = t.split_at(t.len().saturating_sub(1));
        let scale = match unit {
            "s" => 1.0,
            "m" => 60.0,
            "h" => 3600.0,
            _ => return Err(bad()),
        };
        match number.trim().parse::<f64>() {
            Ok(x) if x.is_finite() && x > 0.0 && x * scale < 1e9 => {
                Ok(Every::Wall(Duration::from_secs_f64(x * scale)))
            }
            _ => Err(bad()),
        }
    }
}

impl fmt::Display for Every {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Every::Off => write!(f, "off"),
            Every::Steps(n) => write!(f, "{n}steps"),
            Every::Wall(d) => write!(f, "{}s", d.as_secs_f64()),
        }
    }
}

/// Where a run keeps its checkpoint and how often it writes one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CheckpointOptions {
    /// The checkpoint file.
    pub path: PathBuf,
    /// The interval.
    pub every: Every,
}

/// The key of a run: the SHA-256 of the canonical JSON of what its checkpoint depends on.
pub fn key(what: &serde_json::Value) -> [u8; 32] {
    let text = crate::files::canonical_json(&serde_json::json!({
        "checkpoint_format": FORMAT_VERSION,
        "version": crate::files::ENGINE_VERSION,
        "run": what,
    }));
    Sha256::digest(text.as_bytes()).into()
}

/// What a checkpoint file holds for a run with a given key.
#[derive(Debug)]
pub enum Found<T> {
    /// No file.
    Nothing,
    /// The run's checkpoint: its base step and payload.
    Resume {
        /// The base step it was written at.
        step: u64,
        /// What the run saved.
        payload: T,
    },
    /// A whole checkpoint of another run (another scene, version or output choices).
    OtherRun,
    /// A damaged file (the reason).
    Damaged(String),
}

/// Writes a checkpoint of the run with `key` at base step `step` (atomically: a kill during
/// the write leaves the previous checkpoint).
pub fn write<T: Serialize>(path: &Path, key: &[u8; 32], step: u64, payload: &T) -> Result<()> {
    let body = postcard::to_stdvec(payload)
        .with_context(|| format!("cannot encode the checkpoint {}", path.display()))?;
    let mut bytes = Vec::with_capacity(HEADER_BYTES + body.len() + CHECKSUM_BYTES);
    bytes.extend_from_slice(&MAGIC);
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(&0u32.to_le_bytes());
    bytes.extend_from_slice(key);
    bytes.extend_from_slice(&step.to_le_bytes());
    bytes.extend_from_slice(&(body.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&body);
    let digest = Sha256::digest(&bytes);
    bytes.extend_from_slice(&digest);
    write_atomic_bytes(path, &bytes)
}

/// The header of the checkpoint at `path`, if it is one of this format: (key, base step).
/// Cheap (64 bytes read); the content is checked only by [`read`].
pub fn header_of(path: &Path) -> Option<([u8; 32], u64)> {
    use std::io::Read;
    let mut head = [0u8; HEADER_BYTES];
    std::fs::File::open(path).ok()?.read_exact(&mut head).ok()?;
    if head[..8] != MAGIC || head[8..12] != FORMAT_VERSION.to_le_bytes() {
        return None;
    }
    let key = head[16..48].try_into().ok()?;
    let step = u64::from_le_bytes(head[48..56].try_into().ok()?);
    Some((key, step))
}

/// The header's key, if `path` is a checkpoint of this format ([`header_of`]).
pub fn key_of(path: &Path) -> Option<[u8; 32]> {
    header_of(path).map(|h| h.0)
}

/// Reads the checkpoint at `path` for the run with `key`: checked whole (length, checksum,
/// format) before its payload is decoded.
pub fn read<T: DeserializeOwned>(path: &Path, key: &[u8; 32]) -> Result<Found<T>> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Found::Nothing),
        Err(e) => return Err(RunError::read(path, e)),
    };
    if bytes.len() < HEADER_BYTES + CHECKSUM_BYTES || bytes[..8] != MAGIC {
        return Ok(Found::Damaged(
            "it is not a checkpoint (too short or no magic)".into(),
        ));
    }
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
    let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().expect("8 bytes"));
    if u32_at(8) != FORMAT_VERSION {
        return Ok(Found::Damaged(format!(
            "format version {} (this hvi-study reads {FORMAT_VERSION})",
            u32_at(8)
        )));
    }
    let payload_bytes = u64_at(56);
    if payload_bytes != (bytes.len() - HEADER_BYTES - CHECKSUM_BYTES) as u64 {
        return Ok(Found::Damaged(format!(
            "{} bytes where its header promises {}",
            bytes.len(),
            payload_bytes as u128 + (HEADER_BYTES + CHECKSUM_BYTES) as u128
        )));
    }
    let end = bytes.len() - CHECKSUM_BYTES;
    if Sha256::digest(&bytes[..end])[..] != bytes[end..] {
        return Ok(Found::Damaged(
            "its checksum does not match its content".into(),
        ));
    }
    if bytes[16..48] != key[..] {
        return Ok(Found::OtherRun);
    }
    match postcard::from_bytes(&bytes[HEADER_BYTES..end]) {
        Ok(payload) => Ok(Found::Resume {
            step: u64_at(48),
            payload,
        }),
        Err(e) => Ok(Found::Damaged(format!("its payload does not decode ({e})"))),
    }
}

/// Removes a checkpoint (a missing one is fine).
pub fn remove(path: &Path) -> Result<()> {
    match std::fs::remove_file(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e).write_context(path, || format!("cannot remove {}", path.display())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intervals_parse_and_bad_ones_name_the_flag() {
        assert_eq!("off".parse(), Ok(Every::Off));
        assert_eq!("90s".parse(), Ok(Every::Wall(Duration::from_secs(90))));
        assert_eq!("10m".parse(), Ok(Every::Wall(Duration::from_secs(600))));
        assert_eq!("0.5h".parse(), Ok(Every::Wall(Duration::from_secs(1800))));
        assert_eq!("5000steps".parse(), Ok(Every::Steps(5000)));
        for bad in [
            "", "10", "0s", "-1m", "0steps", "xsteps", "10d", "nanm", "1e12h",
        ] {
            let e = bad.parse::<Every>().expect_err(bad);
            assert!(
                e.contains("`--checkpoint-every`") && e.contains("allowed"),
                "{e}"
            );
        }
        for ok in ["off", "90s", "5000steps"] {
            let every: Every = ok.parse().expect("parses");
            assert_eq!(every.to_string().parse::<Every>(), Ok(every));
        }
    }

    #[test]
    fn a_checkpoint_reads_back_only_whole_and_for_its_own_run() {
        let dir = std::env::temp_dir().join(format!("hvi-ckpt-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp");
        let path = dir.join(CHECKPOINT_FILE);
        let k = key(&serde_json::json!({"scene": 1}));
        let other = key(&serde_json::json!({"scene": 2}));
        assert_ne!(k, other);
        assert!(matches!(read::<Vec<f64>>(&path, &k), Ok(Found::Nothing)));
        let payload = vec![0.1, f64::NAN, -0.0, 1e-300];
        write(&path, &k, 42, &payload).expect("writes");
        assert_eq!(key_of(&path), Some(k));
        assert_eq!(header_of(&path), Some((k, 42)));
        match read::<Vec<f64>>(&path, &k).expect("reads") {
            Found::Resume { step, payload: p } => {
                assert_eq!(step, 42);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&p), bits(&payload));
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            read::<Vec<f64>>(&path, &other),
            Ok(Found::OtherRun)
        ));
        let whole = std::fs::read(&path).expect("bytes");
        let mut flipped = whole.clone();
        flipped[HEADER_BYTES + 3] ^= 1;
        std::fs::write(&path, &flipped).expect("write");
        assert!(matches!(read::<Vec<f64>>(&path, &k), Ok(Found::Damaged(_))));
        std::fs::write(&path, &whole[..whole.len() - 5]).expect("write");
        assert!(matches!(read::<Vec<f64>>(&path, &k), Ok(Found::Damaged(_))));
        remove(&path).expect("removes");
        remove(&path).expect("a missing one is fine");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
