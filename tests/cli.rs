//! End-to-end tests of `hvi-study run`: the files it writes, and a clear error for each kind
//! of bad input (naming the key and the allowed range, exit code 2, never a panic).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_hvi-study"))
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hvi-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn run(out: &Path, extra: &[&str]) -> Output {
    let mut cmd = bin();
    cmd.arg("run")
        .arg(repo().join("studies/scenes/default.toml"))
        .arg("--out")
        .arg(out)
        .args([
            "--set",
            "resolution.particles=2000",
            "--set",
            "run.end_time_s=1e-6",
        ])
        .args(extra);
    cmd.output().expect("runs")
}

#[test]
fn run_writes_summary_energy_dumps_and_lammps_data() {
    let out = scratch("files");
    let data = out.join("init.data");
    let o = run(
        &out,
        &[
            "--dump-every",
            "1000",
            "--lammps-data",
            data.to_str().expect("utf8"),
            "--threads",
            "2",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stderr = String::from_utf8_lossy(&o.stderr);
    for needle in [
        "sigma =",
        "sigma_ref =",
        "gamma =",
        "lambda =",
        "dt =",
        "Contact",
        "Neigh",
        "particle-steps/s",
    ] {
        assert!(
            stderr.contains(needle),
            "progress output lacks `{needle}`:\n{stderr}"
        );
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("json");
    for key in [
        "particles",
        "bonds_initial",
        "bonds_broken",
        "steps",
        "dt_s",
        "sigma_m",
        "wall_seconds",
        "particle_steps_per_second",
    ] {
        assert!(summary[key].is_number(), "summary lacks {key}");
    }
    for key in [
        "kinetic_j",
        "contact_j",
        "bond_j",
        "broken_j",
        "total_initial_j",
        "total_final_j",
        "relative_drift",
    ] {
        assert!(
            summary["energy"][key].is_number(),
            "summary.energy lacks {key}"
        );
    }
    assert_eq!(
        summary["momentum"]["initial_kg_m_s"]
            .as_array()
            .map(Vec::len),
        Some(3)
    );
    assert_eq!(
        summary["momentum"]["final_kg_m_s"].as_array().map(Vec::len),
        Some(3)
    );
    assert_eq!(summary["status"], "completed");
    assert_eq!(summary["scene"]["resolution"]["particles"], 2000.0);
    let csv = std::fs::read_to_string(out.join("energy.csv")).expect("energy.csv");
    assert!(
        csv.starts_with("time_s,tau_s,kinetic_j,contact_j,bond_j,broken_j,total_j,bonds_broken")
    );
    assert!(csv.lines().count() > 3);
    let dumps: Vec<_> = std::fs::read_dir(&out)
        .expect("dir")
        .filter_map(|e| e.ok())
        .filter(|e| e.path().extension().is_some_and(|x| x == "xyz"))
        .collect();
    assert!(dumps.len() >= 2, "expected XYZ snapshots");
    let xyz = std::fs::read_to_string(dumps[0].path()).expect("xyz");
    let mut lines = xyz.lines();
    let n: usize = lines.next().expect("count").trim().parse().expect("count");
    assert!(lines
        .next()
        .expect("comment")
        .contains("Properties=species:S:1:id:I:1:body:I:1:pos:R:3:velo:R:3"));
    assert_eq!(lines.count(), n);
    let lammps = std::fs::read_to_string(&data).expect("lammps data");
    assert!(lammps.contains(&format!("{n} atoms")));
    for section in ["Masses", "Atoms # bond", "Velocities", "Bonds"] {
        assert!(lammps.contains(section), "LAMMPS data lacks {section}");
    }
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn bad_inputs_name_the_key_and_the_allowed_range() {
    let cases: &[(&[&str], &str)] = &[
        (
            &["--set", "material.rcut_over_sigma=1.1"],
            "material.rcut_over_sigma",
        ),
        (&["--set", "scene.diameter_m=-0.01"], "scene.diameter_m"),
        (&["--set", "scene.diameter_m=0"], "scene.diameter_m"),
        (&["--set", "scene.v0_m_s=0"], "scene.v0_m_s"),
        (&["--set", "scene.v0_m_s=-6700"], "scene.v0_m_s"),
        (
            &["--set", "resolution.particles=-5"],
            "resolution.particles",
        ),
        (&["--set", "resolution.particles=0"], "resolution.particles"),
        (&["--set", "scene.t_over_d=nan"], "scene.t_over_d"),
        (&["--set", "material.eps_j=inf"], "material.eps_j"),
        (&["--set", "material.kappa_n_m=0"], "material.kappa_n_m"),
        (&["--set", "scene.width_over_d=0.5"], "scene.width_over_d"),
        (&["--set", "scene.speed=1"], "speed"),
        (&["--set", "physics.eps=1"], "physics"),
        (&["--set", "scene.t_over_d=0.001"], "one particle thick"),
        (&["--set", "scene.standoff_m=-0.002"], "overlap"),
        (&["--set", "run.dt_s=1e-6"], "run.dt_s"),
        (&["--set", "run.dt_factor=5000"], "run.dt_factor"),
        (
            &["--set", "run.frame_block_over_sigma=1"],
            "run.frame_block_over_sigma",
        ),
        (&["--set", "run.end_time_s=-1"], "run.end_time_s"),
        (&["--set", "run.thermal_ratio=-0.1"], "run.thermal_ratio"),
        (&["--set", "run.max_stride=0"], "run.max_stride"),
        (&["--set", "run.max_stride=65"], "run.max_stride"),
        (
            &["--set", "run.stride_displacement_over_sigma=0.2"],
            "run.stride_displacement_over_sigma",
        ),
        (&["--set", "run.dt_s=fast"], "dt_s"),
        (&["--set", "material.contact=cubic"], "contact"),
        (&["--threads", "0"], "--threads"),
        (&["--dump-every", "0"], "--dump-every"),
    ];
    for (args, needle) in cases {
        let out = scratch("bad");
        let o = run(&out, args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(
            o.status.code(),
            Some(2),
            "{args:?} should fail with exit code 2:\n{stderr}"
        );
        assert!(!stderr.contains("panicked"), "{args:?} panicked:\n{stderr}");
        assert!(
            stderr.contains(needle),
            "{args:?}: error does not mention `{needle}`:\n{stderr}"
        );
        let _ = std::fs::remove_dir_all(&out);
    }
    // Range errors say what is allowed.
    let out = scratch("range");
    let o = run(&out, &["--set", "material.rcut_over_sigma=1.0"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("allowed"), "{stderr}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn unstable_run_stops_and_still_writes_what_it_had() {
    let out = scratch("unstable");
    let o = run(&out, &["--set", "run.min_distance_over_sigma=0.99"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("instability"), "{stderr}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("json");
    assert_eq!(summary["status"], "unstable");
    assert!(summary["error"]
        .as_str()
        .expect("error")
        .contains("sigma apart"));
    assert!(out.join("energy.csv").exists());
    let _ = std::fs::remove_dir_all(&out);
}
