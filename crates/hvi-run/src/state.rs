//! The compact state a run keeps of its debris cloud, `state.bin`: every particle at the
//! analysis time and at the two front times ([`hvi_engine::cloud::KeptStates`]), so that
//! `hvi-study reanalyse` measures the cloud again, with other settings, without re-simulating
//! ([`hvi_engine::cloud::remeasure`]). Written atomically with the run's other files when
//! `analysis.keep_state` is on (the default).
//!
//! # Format, version 2
//!
//! Little-endian, in three parts: a header, one to three frames (the analysis time first,
//! then the front times that were sampled, in order), and the SHA-256 of all bytes before it.
//!
//! Header, 80 bytes (version 1, which this code still reads, is the first 72: one density for
//! both bodies):
//!
//! | offset | bytes | type | field |
//! |---|---|---|---|
//! | 0 | 8 | ASCII | magic `HVISTATE` |
//! | 8 | 4 | u32 | format version, 2 |
//! | 12 | 4 | u32 | frames F, 1 to 3 |
//! | 16 | 8 | u64 | particles N |
//! | 24 | 8 | f64 | z of the plate's original rear face, m |
//! | 32 | 8 | f64 | density of the plate, kg/m^3 |
//! | 40 | 8 | f64 | the impactor's mass, kg |
//! | 48 | 8 | f64 | impact velocity v0, m/s |
//! | 56 | 8 | f64 | particle mass of the impactor, kg |
//! | 64 | 8 | f64 | particle mass of the target, kg |
//! | 72 | 8 | f64 | density of the impactor, kg/m^3 |
//!
//! Each frame, 32 + 29 N bytes (arrays in particle-id order):
//!
//! | offset | bytes | type | field |
//! |---|---|---|---|
//! | 0 | 4 | u32 | kind: 0 the analysis time, 1 the first front time, 2 the second |
//! | 4 | 4 | u32 | reserved, 0 |
//! | 8 | 8 | u64 | base step |
//! | 16 | 8 | f64 | time, s |
//! | 24 | 8 | f64 | time since first contact tau, s |
//! | 32 | 12 N | 3 f32 each | positions x, y, z, m |
//! | 32 + 12 N | 12 N | 3 f32 each | velocities, m/s |
//! | 32 + 24 N | 4 N | u32 each | fragment label (the smallest id in the fragment) |
//! | 32 + 28 N | N | u8 each | bit 0: target (else impactor); bit 1: residual plate; bit 2: debris cloud |
//!
//! Then 32 bytes: SHA-256 of everything before them. A file is 80 + F (32 + 29 N) + 32 bytes:
//! 29 bytes per particle and frame, 0.87 MB for three frames of 1e4 particles, 23.5 MB for
//! three of the paper's 2.7e5.
//!
//! Decision: positions and velocities are stored as f32 (relative precision 2^-24, 6e-8: 6 nm
//! at 0.1 m, against particles 0.1 mm across; 0.4 mm/s at 7 km/s), which halves the file. The
//! cloud's membership and labels are stored as the run found them, so a re-analysis counts
//! the same particles and fragments with the same masses exactly; lengths, centroids and
//! velocities come back to f32 precision. Masses are one per body: every particle of a body
//! has its body's mass (eq. 20).

use std::fmt;
use std::path::Path;

use glam::DVec3;
use hvi_engine::cloud::{CloudState, KeptStates};
use hvi_engine::state::Body;
use sha2::{Digest, Sha256};

use crate::error::{Result, ResultExt, RunError};
use crate::files::write_atomic_bytes;

/// The state file's name in a run's directory.
pub const STATE_FILE: &str = "state.bin";
/// The first eight bytes of a state file.
pub const MAGIC: [u8; 8] = *b"HVISTATE";
/// The format version this code writes (it reads this one and version 1).
pub const FORMAT_VERSION: u32 = 2;
/// Header bytes.
pub const HEADER_BYTES: usize = 80;
/// Header bytes of version 1 (one density for both bodies).
const HEADER_BYTES_V1: usize = 72;
/// Bytes of a frame before its arrays.
pub const FRAME_HEADER_BYTES: usize = 32;
/// Bytes per particle and frame.
pub const BYTES_PER_PARTICLE: usize = 29;
/// Bytes of the trailing SHA-256.
pub const CHECKSUM_BYTES: usize = 32;

const TARGET_BIT: u8 = 1;
const RESIDUAL_PLATE_BIT: u8 = 2;
const CLOUD_BIT: u8 = 4;

/// Which sample a frame holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameKind {
    /// The analysis time (the end of the run).
    End = 0,
    /// The first front time.
    Front1 = 1,
    /// The second front time.
    Front2 = 2,
}

impl fmt::Display for FrameKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            FrameKind::End => "the analysis time",
            FrameKind::Front1 => "the first front time",
            FrameKind::Front2 => "the second front time",
        })
    }
}

/// The size of a state file of `frames` frames of `n` particles, bytes (`None` on overflow).
pub fn file_bytes(n: u64, frames: u64) -> Option<u64> {
    file_bytes_of(HEADER_BYTES, n, frames)
}

/// [`file_bytes`] with a header of `header` bytes.
fn file_bytes_of(header: usize, n: u64, frames: u64) -> Option<u64> {
    let frame = (BYTES_PER_PARTICLE as u64)
        .checked_mul(n)?
        .checked_add(FRAME_HEADER_BYTES as u64)?;
    frame
        .checked_mul(frames)?
        .checked_add((header + CHECKSUM_BYTES) as u64)
}

/// Each body's particle mass (indexed by `Body as usize`; 0 for a body without particles).
/// An error when a body's particles differ in mass: the format keeps one mass per body.
fn masses_by_body(s: &CloudState) -> Result<[f64; 2]> {
    let mut m: [Option<f64>; 2] = [None, None];
    for (&b, &mass) in s.body.iter().zip(&s.mass) {
        match m[b as usize] {
            None => m[b as usize] = Some(mass),
            Some(x) if x.to_bits() == mass.to_bits() => {}
            Some(x) => {
                return Err(RunError::Invariant(format!(
                    "the {b:?}'s particles differ in mass ({x:e} and {mass:e} kg): state format \
                 {FORMAT_VERSION} keeps one mass per body"
                )))
            }
        }
    }
    Ok(m.map(|x| x.unwrap_or(0.0)))
}

/// The bytes of a state file holding `kept`.
pub fn encode(kept: &KeptStates) -> Result<Vec<u8>> {
    let end = &kept.end;
    let n = end.len();
    let frames: Vec<(FrameKind, &CloudState)> = std::iter::once((FrameKind::End, end))
        .chain(
            [FrameKind::Front1, FrameKind::Front2]
                .into_iter()
                .zip(&kept.front)
                .filter_map(|(k, s)| s.as_ref().map(|s| (k, s))),
        )
        .collect();
    let masses = masses_by_body(end)?;
    for (kind, s) in &frames {
        if s.len() != n || masses_by_body(s)? != masses {
            return Err(RunError::Invariant(format!(
                "the state at {kind} is of other particles than the one at the analysis time"
            )));
        }
    }
    let total = file_bytes(n as u64, frames.len() as u64)
        .and_then(|b| usize::try_from(b).ok())
        .ok_or_else(|| RunError::Input(format!("{n} particles are too many for a state file")))?;
    let mut b = Vec::with_capacity(total);
    b.extend_from_slice(&MAGIC);
    b.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    b.extend_from_slice(&(frames.len() as u32).to_le_bytes());
    b.extend_from_slice(&(n as u64).to_le_bytes());
    for x in [
        end.plate_rear_z_m,
        end.density_kg_m3,
        end.impactor_mass_kg,
        end.v0_m_s,
        masses[0],
        masses[1],
        end.impactor_density_kg_m3,
    ] {
        b.extend_from_slice(&x.to_le_bytes());
    }
    for (kind, s) in frames {
        b.extend_from_slice(&(kind as u32).to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes());
        b.extend_from_slice(&s.step.to_le_bytes());
        b.extend_from_slice(&s.time_s.to_le_bytes());
        b.extend_from_slice(&s.tau_s.to_le_bytes());
        for v in s.pos.iter().chain(&s.vel) {
            for x in v.to_array() {
                b.extend_from_slice(&(x as f32).to_le_bytes());
            }
        }
        for l in &s.labels {
            b.extend_from_slice(&l.to_le_bytes());
        }
        for i in 0..n {
            let bit = |on: bool, bit: u8| if on { bit } else { 0 };
            b.push(
                bit(s.body[i] == Body::Target, TARGET_BIT)
                    | bit(s.in_residual_plate[i], RESIDUAL_PLATE_BIT)
                    | bit(s.in_cloud[i], CLOUD_BIT),
            );
        }
    }
    let digest = Sha256::digest(&b);
    b.extend_from_slice(&digest);
    debug_assert_eq!(b.len(), total);
    Ok(b)
}

/// Reads little-endian fields from a byte slice whose length was checked beforehand.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> &'a [u8] {
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        s
    }
    fn array<const K: usize>(&mut self) -> [u8; K] {
        let mut a = [0u8; K];
        a.copy_from_slice(self.take(K));
        a
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.array())
    }
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.array())
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.array())
    }
    fn vectors(&mut self, n: usize) -> Vec<DVec3> {
        self.take(12 * n)
            .chunks_exact(12)
            .map(|c| {
                let f =
                    |k: usize| f64::from(f32::from_le_bytes([c[k], c[k + 1], c[k + 2], c[k + 3]]));
                DVec3::new(f(0), f(4), f(8))
            })
            .collect()
    }
}

/// The states held in the bytes of a state file. Errors say what is wrong (not a state file,
/// another version, truncated, corrupt); [`read_state`] adds the file's name.
pub fn decode(bytes: &[u8]) -> Result<KeptStates> {
    let layout = Layout::check(bytes)?;
    let mut c = Cursor {
        bytes,
        at: layout.constants_at,
    };
    let constants = Constants::read(&mut c, layout.version);
    let mut end = None;
    let mut front = [None, None];
    for k in 0..layout.frames {
        let kind = c.u32();
        let state = read_frame(&mut c, layout.particles, &constants)?;
        let slot = match (k, kind) {
            (0, 0) => &mut end,
            (k, 1 | 2) if k > 0 && front[kind as usize - 1].is_none() => {
                &mut front[kind as usize - 1]
            }
            _ => {
                return Err(RunError::parse(format!(
                    "corrupt: frame {k} is of kind {kind}"
                )))
            }
        };
        *slot = Some(state);
    }
    let end = end.ok_or_else(|| RunError::parse("corrupt: no frame at the analysis time"))?;
    Ok(KeptStates { end, front })
}

/// A state file's header, checked against its length and checksum.
struct Layout {
    version: u32,
    frames: u32,
    particles: usize,
    /// Where the run's constants start.
    constants_at: usize,
}

impl Layout {
    /// Reads and checks the header: the magic, a version this build reads, the frame and
    /// particle counts against the file's length, and the SHA-256 of its contents.
    fn check(bytes: &[u8]) -> Result<Layout> {
        let magic = bytes.len().min(MAGIC.len());
        if bytes[..magic] != MAGIC[..magic] {
            return Err(RunError::parse(
                "not an hvi state file (no `HVISTATE` at its start)",
            ));
        }
        let truncated = || {
            RunError::parse(format!(
                "truncated: {} bytes, shorter than the header",
                bytes.len()
            ))
        };
        if bytes.len() < 16 {
            return Err(truncated());
        }
        let mut c = Cursor { bytes, at: 8 };
        let version = c.u32();
        let header = match version {
            1 => HEADER_BYTES_V1,
            FORMAT_VERSION => HEADER_BYTES,
            _ => {
                return Err(RunError::parse(format!(
                    "state format version {version}; this hvi-study reads versions 1 to \
                     {FORMAT_VERSION}: rerun the run with it"
                )))
            }
        };
        let frames = c.u32();
        if bytes.len() < header {
            return Err(truncated());
        }
        if !(1..=3).contains(&frames) {
            return Err(RunError::parse(format!(
                "corrupt: {frames} frames (a state file has 1 to 3)"
            )));
        }
        let n64 = c.u64();
        let expected = file_bytes_of(header, n64, u64::from(frames))
            .filter(|_| n64 <= u64::from(u32::MAX))
            .ok_or_else(|| RunError::parse(format!("corrupt: {n64} particles")))?;
        if bytes.len() as u64 != expected {
            return Err(RunError::parse(format!(
                "truncated or corrupt: {} bytes, but {frames} frames of {n64} particles take \
                 {expected}",
                bytes.len()
            )));
        }
        let (body_bytes, checksum) = bytes.split_at(bytes.len() - CHECKSUM_BYTES);
        if Sha256::digest(body_bytes).as_slice() != checksum {
            return Err(RunError::parse(
                "corrupt: its SHA-256 does not match its contents",
            ));
        }
        Ok(Layout {
            version,
            frames,
            particles: n64 as usize,
            constants_at: c.at,
        })
    }
}

/// The run's constants every frame shares.
struct Constants {
    plate_rear_z_m: f64,
    density_kg_m3: f64,
    impactor_density_kg_m3: f64,
    impactor_mass_kg: f64,
    v0_m_s: f64,
    /// A particle's mass by body (impactor, target).
    masses: [f64; 2],
}

impl Constants {
    fn read(c: &mut Cursor, version: u32) -> Constants {
        let plate_rear_z_m = c.f64();
        let density_kg_m3 = c.f64();
        let impactor_mass_kg = c.f64();
        let v0_m_s = c.f64();
        let masses = [c.f64(), c.f64()];
        // Version 1 had one density for both bodies.
        let impactor_density_kg_m3 = if version == 1 { density_kg_m3 } else { c.f64() };
        Constants {
            plate_rear_z_m,
            density_kg_m3,
            impactor_density_kg_m3,
            impactor_mass_kg,
            v0_m_s,
            masses,
        }
    }
}

/// One frame after its kind: its step and times, positions, velocities, fragment labels and
/// each particle's flags.
fn read_frame(c: &mut Cursor, n: usize, k: &Constants) -> Result<CloudState> {
    let _reserved = c.u32();
    let step = c.u64();
    let time_s = c.f64();
    let tau_s = c.f64();
    let pos = c.vectors(n);
    let vel = c.vectors(n);
    let labels: Vec<u32> = c
        .take(4 * n)
        .chunks_exact(4)
        .map(|x| u32::from_le_bytes([x[0], x[1], x[2], x[3]]))
        .collect();
    if let Some(l) = labels.iter().find(|&&l| l as usize >= n) {
        return Err(RunError::parse(format!(
            "corrupt: fragment label {l} of {n} particles"
        )));
    }
    let flags = c.take(n);
    let body: Vec<Body> = flags
        .iter()
        .map(|f| {
            if f & TARGET_BIT != 0 {
                Body::Target
            } else {
                Body::Impactor
            }
        })
        .collect();
    Ok(CloudState {
        step,
        time_s,
        tau_s,
        plate_rear_z_m: k.plate_rear_z_m,
        density_kg_m3: k.density_kg_m3,
        impactor_density_kg_m3: k.impactor_density_kg_m3,
        impactor_mass_kg: k.impactor_mass_kg,
        v0_m_s: k.v0_m_s,
        pos,
        vel,
        mass: body.iter().map(|&b| k.masses[b as usize]).collect(),
        body,
        labels,
        in_residual_plate: flags.iter().map(|f| f & RESIDUAL_PLATE_BIT != 0).collect(),
        in_cloud: flags.iter().map(|f| f & CLOUD_BIT != 0).collect(),
    })
}

/// Writes `kept` as `path`, atomically.
pub fn write_state(path: &Path, kept: &KeptStates) -> Result<()> {
    let bytes = encode(kept).with_context(|| format!("state file {}", path.display()))?;
    write_atomic_bytes(path, &bytes)
}

/// Reads the state file `path`; `Ok(None)` when there is none. Errors name the file.
pub fn read_state(path: &Path) -> Result<Option<KeptStates>> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(RunError::read(path, e)),
    };
    decode(&bytes)
        .map(Some)
        .with_context(|| format!("state file {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three frames of five particles with every flag combination and awkward numbers.
    fn kept() -> KeptStates {
        let frame = |step: u64, shift: f64| CloudState {
            step,
            time_s: step as f64 * 1e-9,
            tau_s: step as f64 * 1e-9 - 3e-7,
            plate_rear_z_m: 4.05e-3,
            density_kg_m3: 2700.0,
            impactor_density_kg_m3: 7850.0,
            impactor_mass_kg: 1.3e-3,
            v0_m_s: 6700.0,
            pos: (0..5)
                .map(|k| DVec3::new(k as f64 * 1e-4, -0.5e-3, 0.01 + shift + k as f64 * 1e-3))
                .collect(),
            vel: (0..5)
                .map(|k| DVec3::new(10.0 * k as f64, -3.0, 6700.0 - k as f64))
                .collect(),
            mass: vec![2e-9, 2e-9, 3e-9, 3e-9, 3e-9],
            body: vec![
                Body::Impactor,
                Body::Impactor,
                Body::Target,
                Body::Target,
                Body::Target,
            ],
            labels: vec![0, 0, 2, 3, 3],
            in_residual_plate: vec![false, false, true, false, false],
            in_cloud: vec![true, true, false, true, false],
        };
        KeptStates {
            end: frame(300, 0.0),
            front: [Some(frame(100, -0.01)), None],
        }
    }

    #[test]
    fn round_trips_to_f32_precision_with_the_documented_size() {
        let k = kept();
        let bytes = encode(&k).expect("encodes");
        assert_eq!(bytes.len() as u64, file_bytes(5, 2).expect("size"));
        assert_eq!(bytes.len(), 80 + 2 * (32 + 29 * 5) + 32);
        let back = decode(&bytes).expect("decodes");
        assert!(back.front[1].is_none());
        for (a, b) in [
            (&k.end, &back.end),
            (
                k.front[0].as_ref().expect("front"),
                back.front[0].as_ref().expect("front"),
            ),
        ] {
            assert_eq!((a.step, a.time_s, a.tau_s), (b.step, b.time_s, b.tau_s));
            assert_eq!((a.plate_rear_z_m, a.v0_m_s), (b.plate_rear_z_m, b.v0_m_s));
            assert_eq!(
                (a.density_kg_m3, a.impactor_density_kg_m3),
                (b.density_kg_m3, b.impactor_density_kg_m3)
            );
            assert_eq!(a.mass, b.mass);
            assert_eq!(a.body, b.body);
            assert_eq!(a.labels, b.labels);
            assert_eq!(a.in_residual_plate, b.in_residual_plate);
            assert_eq!(a.in_cloud, b.in_cloud);
            for (x, y) in a.pos.iter().zip(&b.pos).chain(a.vel.iter().zip(&b.vel)) {
                assert!(
                    (*x - *y).abs().max_element() <= 6e-8 * x.abs().max_element(),
                    "{x} {y}"
                );
            }
        }
    }

    /// A version-1 file (one density, a 72-byte header) still reads, with the impactor of
    /// the plate's density.
    #[test]
    fn version_1_files_read_with_one_density() {
        let bytes = encode(&kept()).expect("encodes");
        let body = &bytes[..bytes.len() - CHECKSUM_BYTES];
        let mut v1: Vec<u8> = [&body[..72], &body[80..]].concat();
        v1[8..12].copy_from_slice(&1u32.to_le_bytes());
        let sum = Sha256::digest(&v1);
        v1.extend_from_slice(&sum);
        let back = decode(&v1).expect("version 1 decodes");
        assert_eq!(back.end.density_kg_m3, 2700.0);
        assert_eq!(back.end.impactor_density_kg_m3, 2700.0);
        assert_eq!(back.end.mass, kept().end.mass);
    }

    #[test]
    fn damaged_files_are_refused_with_a_reason() {
        let bytes = encode(&kept()).expect("encodes");
        let err = |b: &[u8]| format!("{:#}", decode(b).expect_err("refused"));
        assert!(err(&bytes[..bytes.len() - 1]).contains("truncated"));
        assert!(err(&bytes[..40]).contains("truncated"));
        assert!(err(b"PNG and more bytes").contains("not an hvi state file"));
        let mut flipped = bytes.clone();
        flipped[200] ^= 1;
        assert!(err(&flipped).contains("SHA-256"));
        let mut newer = bytes.clone();
        newer[8] = 3;
        assert!(err(&newer).contains("version 3"));
        let mut huge = bytes;
        huge[16..24].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(err(&huge).contains("corrupt"));
        // A missing file is no state, not an error; an unreadable one names the file.
        let dir = std::env::temp_dir().join(format!("hvi-state-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        assert!(read_state(&dir.join("none.bin"))
            .expect("no file")
            .is_none());
        let bad = dir.join(STATE_FILE);
        std::fs::write(&bad, b"HVISTATE").expect("write");
        let e = format!("{:#}", read_state(&bad).expect_err("refused"));
        assert!(e.contains(&bad.display().to_string()), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
