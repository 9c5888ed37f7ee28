//! File formats: atomic writes, extended XYZ (OVITO, ASE), LAMMPS data files.

use std::fs;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};
use hvi_engine::sim::Simulation;
use hvi_engine::state::{Body, Particles};

/// Writes a file atomically: into a temporary sibling, flushed and synced, then renamed over
/// the target. A reader sees the old file or the new one, never a torn one.
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let dir = path.parent().unwrap_or_else(|| Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp.{}", std::process::id()));
    {
        let file =
            fs::File::create(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
        let mut w = BufWriter::new(file);
        write(&mut w)?;
        w.flush()?;
        w.get_ref().sync_all()?;
    }
    fs::rename(&tmp, path).with_context(|| format!("cannot move {} into place", path.display()))?;
    Ok(())
}

/// Writes bytes atomically.
pub fn write_atomic_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| {
        w.write_all(bytes)?;
        Ok(())
    })
}

/// Writes serialisable rows as a CSV file (header from the field names), atomically.
pub fn write_csv_atomic<T: serde::Serialize>(
    path: &Path,
    rows: impl IntoIterator<Item = T>,
) -> Result<()> {
    write_atomic(path, |w| {
        let mut csv = csv::Writer::from_writer(w);
        for r in rows {
            csv.serialize(r)?;
        }
        csv.flush()?;
        Ok(())
    })
}

/// Reads a target file (`experiments_data/*.toml`, parsed by [`hvi_analysis::score::Targets`]).
pub fn load_targets(path: &Path) -> Result<hvi_analysis::score::Targets> {
    let text = fs::read_to_string(path)
        .with_context(|| format!("cannot read target file {}", path.display()))?;
    hvi_analysis::score::Targets::parse(&text, path)
        .with_context(|| format!("in target file {}", path.display()))
}

/// Order of particles by id (id 0 first), so files list particles stably across re-sorts.
fn by_id(p: &Particles) -> Vec<u32> {
    p.index_of_id()
}

/// The file name of a run's multi-frame extended XYZ trajectory (`--dump-every`).
pub const TRAJECTORY_FILE: &str = "trajectory.extxyz";

/// The per-particle columns of a trajectory frame, as the `Properties` key names them.
/// `masses` and `momenta` are the names ASE maps onto `Atoms` (so `get_masses()` and
/// `get_velocities()` work); `velo` is OVITO's name for the velocity.
pub const TRAJECTORY_PROPERTIES: &str = "species:S:1:pos:R:3:velo:R:3:masses:R:1:momenta:R:3:id:I:1:body:I:1:fragment:I:1:broken_bonds:I:1";

/// A run's dumps as one multi-frame extended XYZ file (`trajectory.extxyz`), which OVITO reads
/// as a trajectory and `ase.io.read(path, index=":")` as a list of frames. Per particle, in id
/// order: species, position (m), velocity (m/s), mass (kg), momentum (kg m/s), id, body
/// (0 impactor, 1 target), fragment (its smallest particle id: particles joined by intact bonds
/// share it) and broken bonds. Units are SI and written as they are: ASE and OVITO take the
/// numbers as given (ASE would call them Angstrom and amu; velocities from momenta / masses come
/// out in m/s). Frames are written to `.trajectory.extxyz.partial` and the file is moved into
/// place when the run ends, so a file named `trajectory.extxyz` is always whole.
pub struct Trajectory {
    partial: std::path::PathBuf,
    path: std::path::PathBuf,
    w: BufWriter<fs::File>,
    frames: usize,
    /// Intact bonds of each particle (by id) when the trajectory started: a broken bond's slots
    /// are cleared at the next neighbour build, so the count broken is this minus the intact.
    initial_bonds: Vec<u8>,
}

/// Intact bonds of each particle, by id.
fn intact_bonds_by_id(p: &Particles) -> Vec<u8> {
    let mut n = vec![0u8; p.len()];
    for i in 0..p.len() {
        n[p.id[i] as usize] = p.intact_partners_of(i).count() as u8;
    }
    n
}

impl Trajectory {
    /// Starts the trajectory in `dir`; broken bonds count from the state of `sim` now (t = 0).
    pub fn create(dir: &Path, sim: &Simulation) -> Result<Self> {
        let path = dir.join(TRAJECTORY_FILE);
        let partial = dir.join(format!(".{TRAJECTORY_FILE}.partial"));
        let file = fs::File::create(&partial)
            .with_context(|| format!("cannot create {}", partial.display()))?;
        Ok(Trajectory {
            partial,
            path,
            w: BufWriter::new(file),
            frames: 0,
            initial_bonds: intact_bonds_by_id(&sim.particles),
        })
    }

    /// Appends the state at base step `step` as one frame.
    pub fn frame(&mut self, sim: &Simulation, step: u64) -> Result<()> {
        let p = &sim.particles;
        let fragment = hvi_engine::cloud::label_fragments(p);
        let w = &mut self.w;
        writeln!(w, "{}", p.len())?;
        writeln!(
            w,
            "Properties={TRAJECTORY_PROPERTIES} Time={:.9e} tau={:.9e} step={step} frame={} \
             units=\"SI: m, m/s, kg, kg m/s, s\" pbc=\"F F F\"",
            sim.time_s(),
            sim.tau_s(),
            self.frames,
        )?;
        for i in by_id(p) {
            let i = i as usize;
            let (x, v, m) = (p.pos[i], p.vel[i], p.mass[i]);
            let intact = p.intact_partners_of(i).count() as u8;
            let broken = self.initial_bonds[p.id[i] as usize].saturating_sub(intact);
            writeln!(
                w,
                "Al {:.12e} {:.12e} {:.12e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {} {} {} {}",
                x.x,
                x.y,
                x.z,
                v.x,
                v.y,
                v.z,
                m,
                m * v.x,
                m * v.y,
                m * v.z,
                p.id[i],
                p.body[i] as u8,
                fragment[i],
                broken
            )?;
        }
        w.flush()
            .with_context(|| format!("cannot write {}", self.partial.display()))?;
        self.frames += 1;
        Ok(())
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Syncs the file and moves it into place as `trajectory.extxyz`.
    pub fn finish(mut self) -> Result<()> {
        self.w.flush()?;
        self.w.get_ref().sync_all()?;
        fs::rename(&self.partial, &self.path)
            .with_context(|| format!("cannot move {} into place", self.path.display()))?;
        Ok(())
    }
}

/// The state as a LAMMPS data file (`units si`, `atom_style bond`): atoms (id = hvi id + 1,
/// molecule = body + 1, type 1 impactor / 2 target), velocities and intact bonds.
pub fn write_lammps_data(path: &Path, sim: &Simulation) -> Result<()> {
    let p = &sim.particles;
    let d = &sim.derived;
    let order = by_id(p);
    let mut bonds: Vec<(u32, u32)> = p
        .intact_bond_pairs()
        .map(|(i, j)| {
            let (a, b) = (p.id[i].min(p.id[j]), p.id[i].max(p.id[j]));
            (a + 1, b + 1)
        })
        .collect();
    bonds.sort_unstable();
    let (mut lo, mut hi) = (p.pos[0], p.pos[0]);
    for x in &p.pos {
        lo = lo.min(*x);
        hi = hi.max(*x);
    }
    let margin = 2.0 * d.r_eq_m;
    write_atomic(path, |w| {
        writeln!(
            w,
            "LAMMPS data file written by hvi-study {}: sigma = {:.9e} m, eps = {:.9e} J, kappa = {:.9e} N/m, rcut = {:.9e} m, dt = {:.9e} s",
            env!("CARGO_PKG_VERSION"),
            d.sigma_m,
            d.eps_j,
            d.kappa_n_m,
            d.rcut_m,
            d.dt_s
        )?;
        writeln!(w)?;
        writeln!(w, "{} atoms", p.len())?;
        writeln!(w, "{} bonds", bonds.len())?;
        writeln!(w, "2 atom types")?;
        writeln!(w, "1 bond types")?;
        writeln!(w, "6 extra bond per atom")?;
        writeln!(w, "12 extra special per atom")?;
        writeln!(w)?;
        writeln!(w, "{:.12e} {:.12e} xlo xhi", lo.x - margin, hi.x + margin)?;
        writeln!(w, "{:.12e} {:.12e} ylo yhi", lo.y - margin, hi.y + margin)?;
        writeln!(w, "{:.12e} {:.12e} zlo zhi", lo.z - margin, hi.z + margin)?;
        writeln!(w)?;
        writeln!(w, "Masses")?;
        writeln!(w)?;
        writeln!(w, "1 {:.12e}", d.mass_impactor_kg)?;
        writeln!(w, "2 {:.12e}", d.mass_target_kg)?;
        writeln!(w)?;
        writeln!(w, "Atoms # bond")?;
        writeln!(w)?;
        for &i in &order {
            let i = i as usize;
            let t = if p.body[i] == Body::Impactor { 1 } else { 2 };
            let x = p.pos[i];
            writeln!(
                w,
                "{} {} {} {:.15e} {:.15e} {:.15e}",
                p.id[i] + 1,
                t,
                t,
                x.x,
                x.y,
                x.z
            )?;
        }
        writeln!(w)?;
        writeln!(w, "Velocities")?;
        writeln!(w)?;
        for &i in &order {
            let i = i as usize;
            let v = p.vel[i];
            writeln!(w, "{} {:.15e} {:.15e} {:.15e}", p.id[i] + 1, v.x, v.y, v.z)?;
        }
        writeln!(w)?;
        writeln!(w, "Bonds")?;
        writeln!(w)?;
        for (k, (a, b)) in bonds.iter().enumerate() {
            writeln!(w, "{} 1 {} {}", k + 1, a, b)?;
        }
        Ok(())
    })
}

/// The files `hvi-study run` writes into its output directory (besides `trajectory.extxyz` and
/// temporary `.NAME.tmp.PID` files).
pub const RUN_FILES: [&str; 11] = [
    "summary.json",
    "energy.csv",
    "cloud_track.csv",
    "fragments.csv",
    "craters.csv",
    "state.bin",
    "cloud_side.png",
    "cloud_series.png",
    "fragments.png",
    "shadowgraph.png",
    "cloud_track.png",
];

/// Whether `name` is a file a run writes (see [`RUN_FILES`]).
fn is_run_file(name: &str) -> bool {
    RUN_FILES.contains(&name)
        || name == TRAJECTORY_FILE
        || (name.starts_with("dump_") && name.ends_with(".xyz")) // earlier versions' dumps
        || name == format!(".{TRAJECTORY_FILE}.partial")
        || (name.starts_with('.') && name.contains(".tmp."))
}

/// Makes `dir` ready for a new run: a missing or empty directory is fine; one that holds an
/// earlier run has that run's files removed (returned, so the caller can say so), so that no
/// old picture sits beside new tables. Refuses a study directory (`plan.json` or `runs/`), a
/// run of a study store (`record.json`) and a directory with files a run does not write
/// (other than the names in `keep`), naming them; nothing is removed then.
pub fn clear_run_dir(dir: &Path, keep: &[&std::ffi::OsStr]) -> Result<Vec<String>> {
    if !dir.exists() {
        return Ok(Vec::new());
    }
    if !dir.is_dir() {
        anyhow::bail!(
            "invalid value for `--out`: {} is a file (allowed: a directory)",
            dir.display()
        );
    }
    for (marker, what) in [
        ("plan.json", "a study directory (it has plan.json)"),
        ("runs", "a study directory (it has runs/)"),
        ("record.json", "a run of a study store (it has record.json)"),
    ] {
        if dir.join(marker).exists() {
            anyhow::bail!(
                "refusing to run into --out {}: it is {what}, and a single run's files would \
                 mix with it; choose a new or empty directory",
                dir.display()
            );
        }
    }
    let mut ours = Vec::new();
    let mut foreign = Vec::new();
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("cannot read --out {}", dir.display()))?;
    for e in entries {
        let e = e.with_context(|| format!("cannot read --out {}", dir.display()))?;
        let name = e.file_name();
        if keep.contains(&name.as_os_str()) {
            continue;
        }
        let text = name.to_string_lossy().into_owned();
        if is_run_file(&text) && e.file_type().is_ok_and(|t| t.is_file()) {
            ours.push(text);
        } else {
            foreign.push(text);
        }
    }
    if !foreign.is_empty() {
        foreign.sort();
        anyhow::bail!(
            "refusing to run into --out {}: it holds {} that a run does not write ({}{}); choose \
             a new or empty directory, or remove them",
            dir.display(),
            if foreign.len() == 1 {
                "a file"
            } else {
                "files"
            },
            foreign
                .iter()
                .take(3)
                .cloned()
                .collect::<Vec<_>>()
                .join(", "),
            if foreign.len() > 3 { ", ..." } else { "" }
        );
    }
    ours.sort();
    for name in &ours {
        std::fs::remove_file(dir.join(name)).with_context(|| {
            format!(
                "cannot remove the earlier run's {}",
                dir.join(name).display()
            )
        })?;
    }
    Ok(ours)
}
