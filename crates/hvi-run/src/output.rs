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

/// Extended XYZ snapshot: species, id, body (0 impactor, 1 target), position (m), velocity
/// (m/s), in id order. OVITO and ASE read it; units are SI, not Angstrom.
pub fn write_xyz(path: &Path, sim: &Simulation) -> Result<()> {
    let p = &sim.particles;
    write_atomic(path, |w| {
        writeln!(w, "{}", p.len())?;
        writeln!(
            w,
            "Properties=species:S:1:id:I:1:body:I:1:pos:R:3:velo:R:3 Time={:.9e} tau={:.9e} units=SI pbc=\"F F F\"",
            sim.time_s(),
            sim.tau_s()
        )?;
        for i in by_id(p) {
            let i = i as usize;
            let (x, v) = (p.pos[i], p.vel[i]);
            writeln!(
                w,
                "Al {} {} {:.12e} {:.12e} {:.12e} {:.9e} {:.9e} {:.9e}",
                p.id[i], p.body[i] as u8, x.x, x.y, x.z, v.x, v.y, v.z
            )?;
        }
        Ok(())
    })
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

/// The files `hvi-study run` writes into its output directory (besides `dump_*.xyz` and
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
        || (name.starts_with("dump_") && name.ends_with(".xyz"))
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
