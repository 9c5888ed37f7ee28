//! File formats: atomic writes, extended XYZ (OVITO, ASE), LAMMPS data files.

use std::fs;
use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{Result, ResultExt, RunError};
pub use crate::files::{remove_stale_partials, write_atomic_bytes, write_atomic_with};
use hvi_engine::sim::Simulation;
use hvi_engine::state::{Body, Particles};

/// Writes serialisable rows as a CSV file (header from the field names), atomically.
pub fn write_csv_atomic<T: serde::Serialize>(
    path: &Path,
    rows: impl IntoIterator<Item = T>,
) -> Result<()> {
    write_atomic_with(path, |w| {
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
    let text = fs::read_to_string(path).read_context(path, || {
        format!("cannot read target file {}", path.display())
    })?;
    hvi_analysis::score::Targets::parse(&text, path)
        .map_err(RunError::library)
        .with_context(|| format!("in target file {}", path.display()))
}

/// Order of particles by id (id 0 first), so files list particles stably across re-sorts.
fn by_id(p: &Particles) -> Vec<u32> {
    p.index_of_id()
}

/// The file name of a run's multi-frame extended XYZ trajectory (`--dump-every`).
pub const TRAJECTORY_FILE: &str = "trajectory.extxyz";
/// The ParaView collection of a run's VTK frames (`--dump-every`).
pub const PVD_FILE: &str = "trajectory.pvd";
/// The directory of a run's VTK frames, `frame_NNNNN.vtu`.
pub const VTK_DIR: &str = "vtk";

/// Which files a run's dumps go to (`--dump-format`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DumpFormat {
    /// `trajectory.extxyz` only (OVITO, ASE).
    Extxyz,
    /// `trajectory.pvd` with `vtk/frame_NNNNN.vtu` only (ParaView, meshio).
    Vtk,
    /// Both.
    #[default]
    Both,
}

impl DumpFormat {
    /// Whether the extended XYZ trajectory is written.
    pub fn extxyz(self) -> bool {
        matches!(self, DumpFormat::Extxyz | DumpFormat::Both)
    }
    /// Whether the VTK frames are written.
    pub fn vtk(self) -> bool {
        matches!(self, DumpFormat::Vtk | DumpFormat::Both)
    }
}

/// The per-particle columns of a trajectory frame, as the `Properties` key names them.
/// `masses` and `momenta` are the names ASE maps onto `Atoms` (so `get_masses()` and
/// `get_velocities()` work); `velo` is OVITO's name for the velocity.
pub const TRAJECTORY_PROPERTIES: &str = "species:S:1:pos:R:3:velo:R:3:masses:R:1:momenta:R:3:id:I:1:body:I:1:fragment:I:1:broken_bonds:I:1";

/// A run's dumps: one multi-frame extended XYZ file (`trajectory.extxyz`), which OVITO reads
/// as a trajectory and `ase.io.read(path, index=":")` as a list of frames, and/or one VTK
/// unstructured grid per frame (`vtk/frame_NNNNN.vtu`, a vertex cell per particle) collected by
/// `trajectory.pvd` with each frame's time since first contact, for ParaView. Per particle, in
/// id order: position (m), velocity (m/s), mass (kg), id, body (0 impactor, 1 target), fragment
/// (its smallest particle id: particles joined by intact bonds share it) and broken bonds; the
/// extended XYZ adds species and momentum (kg m/s). Units are SI and written as they are: ASE
/// and OVITO take the numbers as given (ASE would call them Angstrom and amu; velocities from
/// momenta / masses come out in m/s). The extended XYZ is written to
/// `.trajectory.extxyz.partial` and each `.vtu` atomically; the trajectory and the `.pvd` are
/// moved into place when the run ends, so a file with its final name is always whole.
pub struct Trajectory {
    dir: std::path::PathBuf,
    partial: std::path::PathBuf,
    path: std::path::PathBuf,
    w: Option<BufWriter<fs::File>>,
    /// The VTK frames written so far: (tau, file relative to the run directory).
    vtk: Option<Vec<(f64, String)>>,
    frames: usize,
    /// Intact bonds of each particle (by id) when the trajectory started: a broken bond's slots
    /// are cleared at the next neighbour build, so the count broken is this minus the intact.
    initial_bonds: Vec<u8>,
}

/// Where a [`Trajectory`] stands ([`Trajectory::save_state`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrajectoryState {
    extxyz_bytes: Option<u64>,
    vtk: Option<Vec<(f64, String)>>,
    frames: usize,
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
    /// Starts the trajectory in `dir` in `format`; broken bonds count from the state of `sim`
    /// now (t = 0).
    pub fn create(dir: &Path, sim: &Simulation, format: DumpFormat) -> Result<Self> {
        let path = dir.join(TRAJECTORY_FILE);
        let partial = dir.join(format!(".{TRAJECTORY_FILE}.partial"));
        let w = match format.extxyz() {
            true => Some(BufWriter::new(
                fs::File::create(&partial)
                    .write_context(&partial, || format!("cannot create {}", partial.display()))?,
            )),
            false => None,
        };
        let vtk = match format.vtk() {
            true => {
                let vtk_dir = dir.join(VTK_DIR);
                fs::create_dir_all(&vtk_dir)
                    .write_context(&vtk_dir, || format!("cannot create {}", vtk_dir.display()))?;
                Some(Vec::new())
            }
            false => None,
        };
        Ok(Trajectory {
            dir: dir.to_path_buf(),
            partial,
            path,
            w,
            vtk,
            frames: 0,
            initial_bonds: intact_bonds_by_id(&sim.full_particles()),
        })
    }

    /// Appends the state at base step `step` as one frame.
    pub fn frame(&mut self, sim: &Simulation, step: u64) -> Result<()> {
        let full = sim.full_particles();
        let p: &Particles = &full;
        let fragment = hvi_engine::cloud::label_fragments(p);
        let order = by_id(p);
        let broken: Vec<u8> = order
            .iter()
            .map(|&i| {
                let i = i as usize;
                let intact = p.intact_partners_of(i).count() as u8;
                self.initial_bonds[p.id[i] as usize].saturating_sub(intact)
            })
            .collect();
        if let Some(w) = self.w.as_mut() {
            write_xyz_frame(w, sim, p, step, self.frames, &order, &fragment, &broken)
                .write_context(&self.partial, || {
                    format!("cannot write {}", self.partial.display())
                })?;
        }
        if let Some(vtk) = self.vtk.as_mut() {
            let name = format!("{VTK_DIR}/frame_{:05}.vtu", self.frames);
            let bytes = vtu_frame(sim, p, step, &order, &fragment, &broken)?;
            write_atomic_bytes(&self.dir.join(&name), &bytes)?;
            vtk.push((sim.tau_s(), name));
        }
        self.frames += 1;
        Ok(())
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Where the trajectory stands, for a checkpoint: the extended XYZ file is flushed and its
    /// length recorded, so that a resumed run cuts off what was written after the checkpoint.
    pub fn save_state(&mut self) -> Result<TrajectoryState> {
        let extxyz_bytes = match self.w.as_mut() {
            Some(w) => {
                w.flush().write_context(&self.partial, || {
                    format!("cannot write {}", self.partial.display())
                })?;
                Some(w.get_ref().metadata()?.len())
            }
            None => None,
        };
        Ok(TrajectoryState {
            extxyz_bytes,
            vtk: self.vtk.clone(),
            frames: self.frames,
            initial_bonds: self.initial_bonds.clone(),
        })
    }

    /// The trajectory of a resumed run in `dir`, as [`Self::save_state`] left it: the partial
    /// extended XYZ file cut back to its length then (an error when it is shorter or missing:
    /// the frames before the checkpoint are gone, and the run must start again). A finished
    /// run's `trajectory.extxyz` (a run extended to a later end) is continued in a copy.
    pub fn resume(dir: &Path, s: TrajectoryState) -> Result<Self> {
        let path = dir.join(TRAJECTORY_FILE);
        let partial = dir.join(format!(".{TRAJECTORY_FILE}.partial"));
        let w = match s.extxyz_bytes {
            Some(bytes) => {
                // A finished run's trajectory, extended to a later end: continued in a copy, so
                // that the finished file stays whole until the extension finishes.
                if !partial.exists() && path.is_file() {
                    fs::copy(&path, &partial).write_context(&partial, || {
                        format!("cannot copy {} to continue it", path.display())
                    })?;
                }
                let f = fs::OpenOptions::new()
                    .write(true)
                    .open(&partial)
                    .write_context(&partial, || format!("cannot reopen {}", partial.display()))?;
                let have = f.metadata()?.len();
                if have < bytes {
                    return Err(RunError::parse(format!(
                        "{} holds {have} bytes, fewer than the {bytes} of the checkpoint",
                        partial.display()
                    )));
                }
                f.set_len(bytes)?;
                let mut w = BufWriter::new(f);
                std::io::Seek::seek(&mut w, std::io::SeekFrom::End(0))?;
                Some(w)
            }
            None => None,
        };
        if let Some(vtk) = &s.vtk {
            if let Some((_, missing)) = vtk.iter().find(|(_, f)| !dir.join(f).is_file()) {
                return Err(RunError::parse(format!(
                    "the VTK frame {} is missing",
                    dir.join(missing).display()
                )));
            }
        }
        Ok(Trajectory {
            dir: dir.to_path_buf(),
            partial,
            path,
            w,
            vtk: s.vtk,
            frames: s.frames,
            initial_bonds: s.initial_bonds,
        })
    }

    /// Syncs the extended XYZ file and moves it into place as `trajectory.extxyz`; writes the
    /// `.pvd` collection of the VTK frames.
    pub fn finish(self) -> Result<()> {
        if let Some(mut w) = self.w {
            w.flush()?;
            w.get_ref().sync_all()?;
            fs::rename(&self.partial, &self.path).write_context(&self.path, || {
                format!("cannot move {} into place", self.path.display())
            })?;
        }
        if let Some(vtk) = &self.vtk {
            write_atomic_with(&self.dir.join(PVD_FILE), |w| {
                writeln!(w, "<?xml version=\"1.0\"?>")?;
                writeln!(
                    w,
                    "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">"
                )?;
                writeln!(w, "  <Collection>")?;
                for (tau, file) in vtk {
                    writeln!(
                        w,
                        "    <DataSet timestep=\"{tau:.9e}\" group=\"\" part=\"0\" file=\"{file}\"/>"
                    )?;
                }
                writeln!(w, "  </Collection>")?;
                writeln!(w, "</VTKFile>")?;
                Ok(())
            })?;
        }
        Ok(())
    }
}

/// One extended XYZ frame (see [`Trajectory`]), particles in `order` (by id).
#[allow(clippy::too_many_arguments)]
fn write_xyz_frame(
    w: &mut impl Write,
    sim: &Simulation,
    p: &Particles,
    step: u64,
    frame: usize,
    order: &[u32],
    fragment: &[u32],
    broken: &[u8],
) -> Result<()> {
    writeln!(w, "{}", p.len())?;
    writeln!(
        w,
        "Properties={TRAJECTORY_PROPERTIES} Time={:.9e} tau={:.9e} step={step} frame={frame} \
         units=\"SI: m, m/s, kg, kg m/s, s\" pbc=\"F F F\"",
        sim.time_s(),
        sim.tau_s(),
    )?;
    for (k, &i) in order.iter().enumerate() {
        let i = i as usize;
        let (x, v, m) = (p.pos[i], p.vel[i], p.mass[i]);
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
            broken[k]
        )?;
    }
    w.flush()?;
    Ok(())
}

/// One VTK XML unstructured grid (`.vtu`, binary in base64 as vtkio writes it): a vertex cell
/// per particle, in `order` (by id), with the point data `velocity` (m/s), `mass` (kg), `id`,
/// `body`, `fragment` and `broken_bonds`, and the step and times in the title.
fn vtu_frame(
    sim: &Simulation,
    p: &Particles,
    step: u64,
    order: &[u32],
    fragment: &[u32],
    broken: &[u8],
) -> Result<Vec<u8>> {
    use vtkio::model::{
        Attribute, Attributes, ByteOrder, CellType, Cells, DataSet, UnstructuredGridPiece, Version,
        VertexNumbers, Vtk,
    };
    let n = order.len();
    let mut points = Vec::with_capacity(3 * n);
    let mut velocity = Vec::with_capacity(3 * n);
    for &i in order {
        let (x, v) = (p.pos[i as usize], p.vel[i as usize]);
        points.extend_from_slice(&[x.x, x.y, x.z]);
        velocity.extend_from_slice(&[v.x, v.y, v.z]);
    }
    let pick =
        |f: &dyn Fn(usize) -> u32| -> Vec<u32> { order.iter().map(|&i| f(i as usize)).collect() };
    let mass: Vec<f64> = order.iter().map(|&i| p.mass[i as usize]).collect();
    let point = vec![
        Attribute::vectors("velocity").with_data(velocity),
        Attribute::scalars("mass", 1).with_data(mass),
        Attribute::scalars("id", 1).with_data(pick(&|i| p.id[i])),
        Attribute::scalars("body", 1).with_data(pick(&|i| p.body[i] as u32)),
        Attribute::scalars("fragment", 1).with_data(pick(&|i| fragment[i])),
        Attribute::scalars("broken_bonds", 1)
            .with_data(broken.iter().map(|&b| b as u32).collect::<Vec<u32>>()),
    ];
    let vtk = Vtk {
        version: Version::new((1, 0)),
        title: format!(
            "hvi-study {} step={step} time_s={:.9e} tau_s={:.9e} (SI units)",
            env!("CARGO_PKG_VERSION"),
            sim.time_s(),
            sim.tau_s()
        ),
        byte_order: ByteOrder::LittleEndian,
        file_path: None,
        data: DataSet::inline(UnstructuredGridPiece {
            points: points.into(),
            cells: Cells {
                cell_verts: VertexNumbers::XML {
                    connectivity: (0..n as u64).collect(),
                    offsets: (1..=n as u64).collect(),
                },
                types: vec![CellType::Vertex; n],
            },
            data: Attributes {
                point,
                cell: Vec::new(),
            },
        }),
    };
    let mut bytes = Vec::new();
    vtk.write_xml(&mut bytes)
        .map_err(|e| RunError::Library(Box::new(e)))
        .context("VTK frame")?;
    Ok(bytes)
}

/// The state as a LAMMPS data file (`units si`, `atom_style bond`): atoms (id = hvi id + 1,
/// molecule = body + 1, type 1 impactor / 2 target), velocities and intact bonds.
///
/// Refused for a scene whose impactor has its own law (`[impactor]` eps, kappa or rcut): the
/// export writes one bond law and one contact law (a density of its own is kept, by the
/// per-type masses).
pub fn write_lammps_data(path: &Path, sim: &Simulation) -> Result<()> {
    if !sim.materials.is_one() {
        return Err(RunError::Input(
            "the LAMMPS export writes one bond and one contact law for both bodies, and this \
             scene's impactor has its own ([impactor] eps, kappa or rcut): export a scene of \
             one material (a different impactor.density_kg_m3 alone is kept)"
                .into(),
        ));
    }
    let full = sim.full_particles();
    let p: &Particles = &full;
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
    write_atomic_with(path, |w| {
        lammps_header(w, sim, p.len(), bonds.len())?;
        writeln!(w, "{:.12e} {:.12e} xlo xhi", lo.x - margin, hi.x + margin)?;
        writeln!(w, "{:.12e} {:.12e} ylo yhi", lo.y - margin, hi.y + margin)?;
        writeln!(w, "{:.12e} {:.12e} zlo zhi", lo.z - margin, hi.z + margin)?;
        writeln!(w)?;
        writeln!(w, "Masses")?;
        writeln!(w)?;
        writeln!(w, "1 {:.12e}", d.mass_impactor_kg)?;
        writeln!(w, "2 {:.12e}", d.mass_target_kg)?;
        writeln!(w)?;
        lammps_atoms(w, p, &order)?;
        writeln!(w)?;
        writeln!(w, "Bonds")?;
        writeln!(w)?;
        for (k, (a, b)) in bonds.iter().enumerate() {
            writeln!(w, "{} 1 {} {}", k + 1, a, b)?;
        }
        Ok(())
    })
}

/// The data file's title line (the model's sized values) and its counts.
fn lammps_header(
    w: &mut dyn std::io::Write,
    sim: &Simulation,
    atoms: usize,
    bonds: usize,
) -> std::io::Result<()> {
    let d = &sim.derived;
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
    writeln!(w, "{atoms} atoms")?;
    writeln!(w, "{bonds} bonds")?;
    writeln!(w, "2 atom types")?;
    writeln!(w, "1 bond types")?;
    writeln!(w, "6 extra bond per atom")?;
    writeln!(w, "12 extra special per atom")?;
    writeln!(w)
}

/// The Atoms (id, molecule = type = body) and Velocities sections, in id order.
fn lammps_atoms(w: &mut dyn std::io::Write, p: &Particles, order: &[u32]) -> std::io::Result<()> {
    writeln!(w, "Atoms # bond")?;
    writeln!(w)?;
    for &i in order {
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
    for &i in order {
        let i = i as usize;
        let v = p.vel[i];
        writeln!(w, "{} {:.15e} {:.15e} {:.15e}", p.id[i] + 1, v.x, v.y, v.z)?;
    }
    Ok(())
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

/// Whether `path` is a run's VTK directory: files `frame_NNNNN.vtu` (and temporary files) only.
fn is_vtk_dir(path: &Path) -> bool {
    std::fs::read_dir(path).is_ok_and(|entries| {
        entries.filter_map(|e| e.ok()).all(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            e.file_type().is_ok_and(|t| t.is_file())
                && ((name.starts_with("frame_") && name.ends_with(".vtu"))
                    || (name.starts_with('.') && name.contains(".tmp.")))
        })
    })
}

/// Whether `name` is a file a run writes (see [`RUN_FILES`]).
fn is_run_file(name: &str) -> bool {
    RUN_FILES.contains(&name)
        || name == TRAJECTORY_FILE
        || (name.starts_with("dump_") && name.ends_with(".xyz")) // earlier versions' dumps
        || name == format!(".{TRAJECTORY_FILE}.partial")
        || name == PVD_FILE
        || name == crate::files::CHECKPOINT_FILE
        || name == crate::files::CONTINUATION_FILE
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
        return Err(RunError::Input(format!(
            "invalid value for `--out`: {} is a file (allowed: a directory)",
            dir.display()
        )));
    }
    for (marker, what) in [
        ("plan.json", "a study directory (it has plan.json)"),
        ("runs", "a study directory (it has runs/)"),
        ("record.json", "a run of a study store (it has record.json)"),
    ] {
        if dir.join(marker).exists() {
            return Err(RunError::Input(format!(
                "refusing to run into --out {}: it is {what}, and a single run's files would \
                 mix with it; choose a new or empty directory",
                dir.display()
            )));
        }
    }
    let mut ours = Vec::new();
    let mut foreign = Vec::new();
    let entries = std::fs::read_dir(dir)
        .read_context(dir, || format!("cannot read --out {}", dir.display()))?;
    for e in entries {
        let e = e.read_context(dir, || format!("cannot read --out {}", dir.display()))?;
        let name = e.file_name();
        if keep.contains(&name.as_os_str()) {
            continue;
        }
        let text = name.to_string_lossy().into_owned();
        let file = is_run_file(&text) && e.file_type().is_ok_and(|t| t.is_file());
        if file || (text == VTK_DIR && is_vtk_dir(&e.path())) {
            ours.push(text);
        } else {
            foreign.push(text);
        }
    }
    if !foreign.is_empty() {
        foreign.sort();
        return Err(RunError::Input(format!(
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
        )));
    }
    ours.sort();
    for name in &ours {
        let path = dir.join(name);
        let removed = if path.is_dir() {
            std::fs::remove_dir_all(&path)
        } else {
            std::fs::remove_file(&path)
        };
        removed.write_context(&path, || {
            format!(
                "cannot remove the earlier run's {}",
                dir.join(name).display()
            )
        })?;
    }
    Ok(ours)
}
