//! `hvi-study bench`: engine throughput (particle-steps per second) on a scene at several
//! thread counts, with a check that every thread count gives bit-identical physics.

use std::fmt::Write as _;
use std::path::Path;

use hvi_engine::scene::SceneSpec;
use serde::Serialize;

use crate::error::{Result, ResultExt, RunError};
use crate::output::write_csv_atomic;
use crate::run::{run_scene, RunOptions};

/// One row of the benchmark table.
#[derive(Debug, Clone, Serialize)]
pub struct BenchRow {
    /// Worker threads.
    pub threads: usize,
    /// Particles.
    pub particles: usize,
    /// Steps taken.
    pub steps: u64,
    /// Wall time of the stepping loop and set-up, s.
    pub wall_seconds: f64,
    /// Particles times steps over the stepping wall time.
    pub particle_steps_per_second: f64,
    /// Throughput over that of the first thread count.
    pub speedup: f64,
    /// Bonds broken by the end.
    pub bonds_broken: u64,
    /// Relative energy-ledger drift at the end.
    pub energy_drift: f64,
    /// Seconds in contact forces, bonds, neighbour lists and integration.
    pub contact_s: f64,
    /// Seconds in the bond kernel.
    pub bonds_s: f64,
    /// Seconds in neighbour-list builds.
    pub neighbour_s: f64,
    /// Seconds in integration.
    pub integrate_s: f64,
}

/// Runs `spec` once per thread count; fails if the physics differs between thread counts.
pub fn bench(spec: &SceneSpec, threads: &[usize], out: &Path) -> Result<(Vec<BenchRow>, String)> {
    if threads.is_empty() || threads.contains(&0) {
        return Err(RunError::Input(format!("invalid value for `--threads`: {threads:?} (allowed: a list of integers >= 1, e.g. 1,2)")));
    }
    let mut rows: Vec<BenchRow> = Vec::new();
    let mut reference: Option<(u64, u64)> = None;
    for &t in threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .context("thread pool")?;
        let opts = RunOptions {
            out_dir: out.join(format!("threads_{t}")),
            progress: false,
            ..Default::default()
        };
        log::info!("bench: {t} thread(s)...");
        let outcome = pool.install(|| run_scene(spec, &opts))?;
        let s = &outcome.summary;
        let fingerprint = (s.energy.total_final_j.to_bits(), s.bonds_broken);
        match reference {
            None => reference = Some(fingerprint),
            Some(r) if r != fingerprint => {
                return Err(RunError::Invariant(format!(
                    "results differ between thread counts: final energy {} vs bits {:x}",
                    s.energy.total_final_j, r.0
                )));
            }
            Some(_) => {}
        }
        let base = rows
            .first()
            .map(|r| r.particle_steps_per_second)
            .unwrap_or(s.particle_steps_per_second);
        rows.push(BenchRow {
            threads: t,
            particles: s.particles,
            steps: s.steps,
            wall_seconds: s.wall_seconds,
            particle_steps_per_second: s.particle_steps_per_second,
            speedup: s.particle_steps_per_second / base,
            bonds_broken: s.bonds_broken,
            energy_drift: s.energy.relative_drift,
            contact_s: s.timing.contact_s,
            bonds_s: s.timing.bonds_s,
            neighbour_s: s.timing.neighbour_s,
            integrate_s: s.timing.integrate_s,
        });
    }
    let mut table = format!(
        "kernels: {} (hvi_engine::simd; HVI_ISA=baseline forces x86-64's baseline)\n",
        hvi_engine::simd::isa().name()
    );
    table.push_str(
        "threads  particles     steps   wall (s)  particle-steps/s  speedup  bonds broken  energy drift\n",
    );
    for r in &rows {
        let _ = writeln!(
            table,
            "{:>7}  {:>9}  {:>8}  {:>9.2}  {:>16.3e}  {:>7.2}  {:>12}  {:>12.2e}",
            r.threads,
            r.particles,
            r.steps,
            r.wall_seconds,
            r.particle_steps_per_second,
            r.speedup,
            r.bonds_broken,
            r.energy_drift
        );
    }
    let _ = writeln!(
        table,
        "identical physics at every thread count: yes (final energy and bonds broken bit-equal)"
    );
    write_csv_atomic(&out.join("bench.csv"), &rows)?;
    Ok((rows, table))
}
