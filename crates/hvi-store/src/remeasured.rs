//! A run measured from another run's kept state instead of simulated.
//!
//! The settings of [`hvi_engine::scene::MEASUREMENT_KEYS`] (the quantile, the width, the camera,
//! the witness plate) only say how the debris cloud is measured from the states a run keeps
//! (`state.bin`, [`hvi_run::state`]). A run whose scene differs from a completed run's only in
//! them (and in `analysis.keep_state`) simulates exactly what that run simulated, so the store
//! ([`crate::store`]) measures it from that run's state ([`hvi_engine::cloud::remeasure`], the
//! functions a run measures with): about a second instead of the simulation.
//!
//! The measured run's directory holds what a simulated one holds:
//!
//! - anew: `summary.json` (the source's, with this run's scene, the cloud measured again and
//!   `measured_from`, the source's fingerprint), the cloud's tables and the pictures that show
//!   the measurement ([`hvi_run::run::MEASURED_FILES`]), drawn from the state at the analysis
//!   time;
//! - taken over from the source (hard links where the filesystem allows, else copies): the
//!   energy, the series pictures, the trajectory, the kept state (unless this run's scene
//!   turns `keep_state` off) and the cloud's track, `cloud_track.csv` and `.png`, when it reads
//!   the same (the same quantile and width). A track read otherwise was measured during the
//!   simulation and cannot be measured again from three kept instants: the measured run has
//!   none.
//!
//! Counts, fragments and masses come back exactly; lengths, ratios and crater sizes to the f32
//! precision of the kept positions (1e-6 relative), va to 1e-5 relative in a 4 us run
//! (docs/studies.md, "Runs measured from a kept state").

use std::fs;
use std::path::Path;

use hvi_engine::cloud::{remeasure, KeptStates};
use hvi_engine::scene::SceneSpec;
use hvi_plot::render::{Frame, SceneInfo};

use hvi_run::error::{Result, ResultExt, RunError};
use hvi_run::files::write_atomic_bytes;
use hvi_run::run::{read_summary, render_measured, write_cloud_tables, Summary, MEASURED_FILES};
use hvi_run::state::{read_state, STATE_FILE};

/// A completed run's summary and kept states, read from its directory; `Ok(None)` when it kept
/// no state. Errors (an unreadable summary or state, or a state of another particle count) name
/// the file.
pub fn read_kept(dir: &Path) -> Result<Option<(Summary, KeptStates)>> {
    let summary_path = dir.join("summary.json");
    let summary = read_summary(dir).ok_or_else(|| {
        RunError::parse(format!(
            "{}: no summary.json this version reads",
            summary_path.display()
        ))
    })?;
    let path = dir.join(STATE_FILE);
    let Some(kept) = read_state(&path)? else {
        return Ok(None);
    };
    if kept.end.len() != summary.particles {
        return Err(RunError::parse(format!(
            "state file {}: {} particles, but the run's summary.json has {}",
            path.display(),
            kept.end.len(),
            summary.particles
        )));
    }
    Ok(Some((summary, kept)))
}

/// Measures the run of `scene` from the kept state of the completed run in `source` (with
/// fingerprint `source_fingerprint`) into the directory `out`, as the module's doc says; its
/// summary. The caller has checked that the two scenes simulate the same thing
/// ([`crate::plan::simulation_key`]).
pub fn measure_from(
    source: &Path,
    source_fingerprint: &str,
    scene: &SceneSpec,
    out: &Path,
) -> Result<Summary> {
    let (mut summary, kept) = read_kept(source)?
        .ok_or_else(|| RunError::Store(format!("{} kept no state to measure", source.display())))?;
    let analysis = &scene.analysis;
    analysis.validate(scene.run.end_time_s)?;
    let cloud = remeasure(&kept, analysis);
    let same_track = summary.scene.analysis.same_track_reading(analysis);
    fs::create_dir_all(out).write_context(out, || format!("cannot create {}", out.display()))?;
    take_over(source, out, &|name: &str| {
        let measured = MEASURED_FILES.contains(&name);
        let track = name == "cloud_track.csv" || name == "cloud_track.png";
        let state = name == STATE_FILE;
        !(name.starts_with('.')
            || name == "record.json"
            || name == "summary.json"
            || measured
            || (track && !same_track)
            || (state && !analysis.keep_state))
    })?;
    write_cloud_tables(out, &cloud)?;
    let info = SceneInfo::new(scene, &summary.derived, summary.particles);
    render_measured(out, &info, &Frame::of_state(&kept.end), Some(&cloud))?;
    summary.cloud = Some(cloud.report);
    summary.scene = scene.clone();
    summary.measured_from = Some(source_fingerprint.to_string());
    write_atomic_bytes(
        &out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    Ok(summary)
}

/// Links (or, where the filesystem cannot, copies) every file of `from` whose name `keep`
/// accepts into `to`, directories (a run's VTK frames) recursively.
fn take_over(from: &Path, to: &Path, keep: &dyn Fn(&str) -> bool) -> Result<()> {
    let entries =
        fs::read_dir(from).read_context(from, || format!("cannot list {}", from.display()))?;
    for entry in entries {
        let entry = entry.map_err(|e| RunError::read(from, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if !keep(&name) {
            continue;
        }
        let (src, dest) = (entry.path(), to.join(&name));
        if src.is_dir() {
            fs::create_dir_all(&dest)
                .write_context(&dest, || format!("cannot create {}", dest.display()))?;
            take_over(&src, &dest, &|n: &str| !n.starts_with('.'))?;
        } else if fs::hard_link(&src, &dest).is_err() {
            fs::copy(&src, &dest).write_context(&dest, || {
                format!("cannot copy {} to {}", src.display(), dest.display())
            })?;
        }
    }
    Ok(())
}
