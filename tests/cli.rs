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
    assert!(csv.starts_with(
        "time_s,tau_s,kinetic_j,contact_j,bond_j,broken_j,absorbed_j,total_j,bonds_broken"
    ));
    assert!(csv.lines().count() > 3);
    let trajectory = std::fs::read_to_string(out.join("trajectory.extxyz")).expect("trajectory");
    let mut lines = trajectory.lines();
    let n: usize = lines.next().expect("count").trim().parse().expect("count");
    assert!(lines.next().expect("comment").contains(
        "Properties=species:S:1:pos:R:3:velo:R:3:masses:R:1:momenta:R:3:id:I:1:body:I:1:fragment:I:1:broken_bonds:I:1"
    ));
    let frames = trajectory
        .lines()
        .filter(|l| l.starts_with("Properties="))
        .count();
    assert!(frames >= 2, "expected several frames, got {frames}");
    assert_eq!(trajectory.lines().count(), frames * (n + 2));
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
        (&["--set", "run.symmetry=half"], "run.symmetry"),
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

/// `hvi-study accuracy` end to end on a tiny scene: candidates at two seeds, the reference
/// step at two, their means, the pooled seed scatter and the noise floor it sets, every run in
/// `accuracy-runs.csv`, and a second invocation that reuses every stored run.
#[test]
fn accuracy_compares_seed_means_and_resumes_from_the_store() {
    let dir = scratch("accuracy");
    let (report, store) = (dir.join("report"), dir.join("store"));
    let accuracy = |extra: &[&str]| {
        let mut cmd = bin();
        cmd.arg("accuracy")
            .arg(repo().join("studies/scenes/default.toml"))
            .args([
                "--set",
                "resolution.particles=1500",
                "--set",
                "run.end_time_s=4e-6",
                "--variant",
                "dt4:run.dt_factor=4;run.max_stride=1",
                "--noise-seeds",
                "0",
                "--threads",
                "1",
                "--out",
            ])
            .arg(&report)
            .arg("--store")
            .arg(&store)
            .args(extra);
        cmd.output().expect("runs")
    };
    let o = accuracy(&["--seeds", "2"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    // `--seeds 2` raises the noise-floor seeds from 0 to 1: four runs in all.
    let runs = std::fs::read_to_string(report.join("accuracy-runs.csv")).expect("runs csv");
    assert_eq!(runs.lines().count(), 1 + 4, "{runs}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report.join("accuracy.json")).expect("json"))
            .expect("parses");
    assert_eq!(json["seeds"], 2);
    assert_eq!(json["reference_runs"], 2);
    // One dof from the reference step's pair, one from the candidate's.
    assert_eq!(json["scatter_dof"], 2);
    let run_rows = json["runs"].as_array().expect("runs");
    let value = |variant: &str, seed: u64, key: &str| {
        run_rows
            .iter()
            .find(|r| r["variant"] == variant && r["seed"] == seed)
            .and_then(|r| r[key].as_f64())
            .unwrap_or_else(|| panic!("{variant} seed {seed} {key}"))
    };
    let row = json["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["variant"] == "dt4")
        .expect("dt4 row");
    assert_eq!(row["seeds"], 2);
    let key = "length_ratio";
    let (c1, c2) = (value("dt4", 1, key), value("dt4", 2, key));
    let (r1, r2) = (value("reference", 1, key), value("seed2", 1, key));
    assert_ne!(c1, c2, "the two seeds of a candidate must differ");
    let cand = row[key].as_f64().expect("R");
    assert!((cand - 0.5 * (c1 + c2)).abs() <= 1e-12 * cand.abs());
    let reference = 0.5 * (r1 + r2);
    let err = row["err_length_ratio"].as_f64().expect("err");
    assert!((err - ((cand - reference) / reference).abs()).abs() < 1e-12);
    // Pooled scatter: each pair {a, b} adds (a - b)^2 / 2 to the sum of squares, one dof.
    let s = (((c1 - c2).powi(2) + (r1 - r2).powi(2)) / 2.0 / 2.0).sqrt() / reference;
    let scatter = json["seed_scatter"][0][1].as_f64().expect("scatter");
    assert!((scatter - s).abs() < 1e-12, "{scatter} vs {s}");
    // Noise floor for 2 seeds against 2 reference runs: 2 s sqrt(1/2 + 1/2).
    let floor = json["noise_floor"][0][1].as_f64().expect("floor");
    assert!((floor - 2.0 * s).abs() < 1e-12, "{floor} vs {}", 2.0 * s);
    let md = std::fs::read_to_string(report.join("accuracy.md")).expect("md");
    assert!(md.contains("2 SE, 2 seed(s) against 2"), "{md}");
    assert!(report.join("pareto.png").exists());
    // A second invocation runs nothing.
    let o = accuracy(&["--seeds", "2"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert_eq!(stderr.matches("(stored)").count(), 4, "{stderr}");
    // Bad counts name the flag and the range, and lose nothing stored.
    for bad in ["0", "10"] {
        let o = accuracy(&["--seeds", bad]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains("--seeds") && stderr.contains("allowed 1 to 9"),
            "{stderr}"
        );
    }
    let o = accuracy(&["--seeds", "2"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(stderr.matches("(stored)").count(), 4, "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A quarter-symmetry run shows the user the full scene: the summary's counts, the cloud,
/// the trajectory's particles and the LAMMPS data are of the four copies.
#[test]
fn a_quarter_run_writes_the_full_scene() {
    let out = scratch("quarter");
    let data = out.join("init.data");
    let o = run(
        &out,
        &[
            "--set",
            "run.symmetry=quarter",
            "--set",
            "run.end_time_s=4e-6",
            "--dump-every",
            "100000",
            "--dump-format",
            "extxyz",
            "--lammps-data",
            data.to_str().expect("utf8"),
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("simulated"));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("json");
    let n = summary["particles"].as_u64().expect("particles");
    let simulated = summary["particles_simulated"].as_u64().expect("simulated");
    assert_eq!(n, 4 * simulated);
    assert_eq!(summary["scene"]["run"]["symmetry"], "quarter");
    assert!(summary["cloud"]["n_part"].as_u64().expect("cloud") > 0);
    let xyz = std::fs::read_to_string(out.join("trajectory.extxyz")).expect("xyz");
    assert_eq!(xyz.lines().next().expect("count").trim(), n.to_string());
    let lammps = std::fs::read_to_string(&data).expect("data");
    assert!(lammps.contains(&format!("{n} atoms")), "{}", &lammps[..300]);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn run_into_an_earlier_run_clears_its_files_and_refuses_other_directories() {
    let out = scratch("again");
    let o = run(&out, &["--render", "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("cloud_side.png").exists());
    // Again without --render: the old pictures go, so none sits beside the new tables.
    let o = run(&out, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("held an earlier run: removed its"),
        "{stderr}"
    );
    assert!(stderr.contains("cloud_side.png"), "{stderr}");
    assert!(!out.join("cloud_side.png").exists());
    assert!(out.join("summary.json").exists());

    // A foreign file, a study directory, a store's run: refused, nothing removed.
    std::fs::write(out.join("notes.txt"), "mine").expect("file");
    let o = run(&out, &[]);
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("a file that a run does not write (notes.txt)"),
        "{stderr}"
    );
    assert!(out.join("summary.json").exists(), "nothing removed");
    for marker in ["plan.json", "record.json"] {
        let dir = scratch(&format!("marker-{marker}"));
        std::fs::create_dir_all(&dir).expect("dir");
        std::fs::write(dir.join(marker), "{}").expect("marker");
        let o = run(&dir, &[]);
        assert!(!o.status.success());
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(
            stderr.contains(marker) && stderr.contains("refusing"),
            "{stderr}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// The summary without what depends on the machine's speed (wall times, rates, timings).
fn physics(out: &Path) -> serde_json::Value {
    let mut s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("json");
    let o = s.as_object_mut().expect("object");
    for key in ["wall_seconds", "particle_steps_per_second", "timing"] {
        assert!(o.remove(key).is_some(), "summary lacks {key}");
    }
    s
}

#[test]
fn output_flags_never_change_the_trajectory() {
    // Render times inside the run and dumps at an odd interval: the adaptive step lands on the
    // scene's render times whether or not frames are captured, and takes dumps where it is.
    let scene = [
        "--set",
        "run.end_time_s=6e-6",
        "--set",
        "analysis.render_times_s=[0.0, 3.3e-6, 5.1e-6]",
        "--threads",
        "1",
        "--quiet",
    ];
    let plain = scratch("plain");
    let o = run(&plain, &scene);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let reference = physics(&plain);
    let energy = std::fs::read_to_string(plain.join("energy.csv")).expect("energy.csv");
    assert!(reference["steps"].as_u64().expect("steps") > 100);
    assert!(reference["stride_limits"].is_object() || reference["stride_limits"].is_array());
    let flagged = scratch("flagged");
    let data = flagged.join("init.data");
    let flags: [&[&str]; 3] = [
        &["--render"],
        &["--dump-every", "77"],
        &["--render", "--dump-every", "333", "--lammps-data"],
    ];
    for extra in flags {
        let _ = std::fs::remove_dir_all(&flagged);
        let mut args: Vec<&str> = scene.to_vec();
        args.extend_from_slice(extra);
        if extra.contains(&"--lammps-data") {
            args.push(data.to_str().expect("utf8"));
        }
        let o = run(&flagged, &args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_eq!(physics(&flagged), reference, "with {extra:?}");
        assert_eq!(
            std::fs::read_to_string(flagged.join("energy.csv")).expect("energy.csv"),
            energy,
            "with {extra:?}"
        );
        if extra.contains(&"--dump-every") {
            let trajectory =
                std::fs::read_to_string(flagged.join("trajectory.extxyz")).expect("trajectory");
            let frames = trajectory
                .lines()
                .filter(|l| l.starts_with("Properties="))
                .count();
            assert!(frames >= 2, "with {extra:?}: {frames} frames");
        }
    }
    let _ = std::fs::remove_dir_all(&plain);
    let _ = std::fs::remove_dir_all(&flagged);
}

/// Runs a Python snippet with `python3`; None (after saying why) where Python or the module is
/// missing, which fails under CI (`.ci/run` installs them).
fn python(module: &str, code: &str) -> Option<Output> {
    let probe = Command::new("python3")
        .args(["-c", &format!("import {module}")])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        assert!(
            std::env::var_os("CI").is_none(),
            "python3 with `{module}` is missing under CI (.ci/run installs it)"
        );
        eprintln!("skipped: python3 with `{module}` is missing (pip install {module})");
        return None;
    }
    Some(
        Command::new("python3")
            .args(["-c", code])
            .output()
            .expect("python3 runs"),
    )
}

#[test]
fn the_trajectory_opens_in_ase_with_every_frame_velocities_masses_and_fragments() {
    let out = scratch("ase");
    let o = run(
        &out,
        &[
            "--set",
            "run.end_time_s=3e-6",
            "--dump-every",
            "200",
            "--threads",
            "2",
            "--quiet",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("json");
    let particles = summary["particles"].as_u64().expect("particles");
    let broken = summary["bonds_broken"].as_u64().expect("broken");
    let impactor = summary["derived"]["mass_impactor_kg"].as_f64().expect("m");
    let base_steps = summary["base_steps"].as_u64().expect("base steps");
    // Frames at step 0, at the first step at or after each multiple of 200, and at the end.
    let path = out.join("trajectory.extxyz");
    let code = format!(
        r#"
import ase.io, numpy as np
frames = ase.io.read(r"{path}", index=":")
last = frames[-1]
v = last.get_velocities()
rel = np.abs(v - last.arrays["velo"]).max() / np.abs(last.arrays["velo"]).max()
m = last.get_masses()
print(len(frames), len(last), rel, m[last.arrays["body"] == 0][0],
      int(last.arrays["broken_bonds"].sum()), len(set(last.arrays["fragment"])),
      int(last.info["step"]), sorted(last.arrays["id"])[-1])
"#,
        path = path.display()
    );
    let Some(o) = python("ase", &code) else {
        return;
    };
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    let got: Vec<&str> = text.split_whitespace().collect();
    assert_eq!(got.len(), 8, "{text}");
    let frames: u64 = got[0].parse().expect("frames");
    assert!(
        frames > base_steps / 200,
        "{frames} frames for {base_steps} steps"
    );
    assert_eq!(got[1].parse::<u64>().expect("n"), particles);
    let rel: f64 = got[2].parse().expect("rel");
    assert!(
        rel < 1e-8,
        "ASE's velocities (momenta / masses) differ by {rel}"
    );
    let m: f64 = got[3].parse().expect("mass");
    assert!((m - impactor).abs() <= 1e-9 * impactor, "{m} vs {impactor}");
    // Each broken bond counts at both of its particles.
    assert_eq!(got[4].parse::<u64>().expect("broken"), 2 * broken);
    let fragments: u64 = got[5].parse().expect("fragments");
    assert!(fragments > 1 && fragments < particles, "{fragments}");
    assert_eq!(got[6].parse::<u64>().expect("step"), base_steps);
    assert_eq!(got[7].parse::<u64>().expect("id"), particles - 1);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn vtk_frames_open_in_meshio_and_a_later_run_clears_them() {
    let out = scratch("vtk");
    let args = [
        "--set",
        "run.end_time_s=3e-6",
        "--dump-every",
        "200",
        "--threads",
        "2",
        "--quiet",
    ];
    let o = run(&out, &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("json");
    let particles = summary["particles"].as_u64().expect("particles");
    let broken = summary["bonds_broken"].as_u64().expect("broken");
    let pvd = std::fs::read_to_string(out.join("trajectory.pvd")).expect("pvd");
    let files: Vec<&str> = pvd
        .lines()
        .filter_map(|l| l.split("file=\"").nth(1))
        .filter_map(|f| f.split('"').next())
        .collect();
    assert!(files.len() >= 2, "{pvd}");
    for f in &files {
        assert!(out.join(f).is_file(), "{f} listed in the .pvd is missing");
    }
    // Every frame read by meshio: one vertex cell per particle, the point data, and the last
    // frame's positions and velocities those of the extended XYZ trajectory's last frame.
    let code = format!(
        r#"
import meshio, numpy as np, re
pvd = open(r"{dir}/trajectory.pvd").read()
steps = [float(t) for t in re.findall(r'timestep="([^"]+)"', pvd)]
files = re.findall(r'file="([^"]+)"', pvd)
assert steps == sorted(steps), steps
for f in files:
    m = meshio.read(r"{dir}/" + f)
    assert [c.type for c in m.cells] == ["vertex"], m.cells
    assert len(m.cells[0].data) == len(m.points)
last = meshio.read(r"{dir}/" + files[-1])
xyz = open(r"{dir}/trajectory.extxyz").read().splitlines()
n = int(xyz[0])
rows = np.array([[float(v) for v in l.split()[1:7]] for l in xyz[-n:]])
print(len(files), len(last.points), int(last.point_data["broken_bonds"].sum()),
      np.abs(last.points - rows[:, 0:3]).max(), np.abs(last.point_data["velocity"] - rows[:, 3:6]).max(),
      int(last.point_data["id"].max()), sorted(last.point_data.keys()))
"#,
        dir = out.display()
    );
    if let Some(o) = python("meshio", &code) {
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let text = String::from_utf8_lossy(&o.stdout);
        let got: Vec<&str> = text.split_whitespace().collect();
        assert!(got.len() >= 7, "{text}");
        assert_eq!(got[0].parse::<usize>().expect("frames"), files.len());
        assert_eq!(got[1].parse::<u64>().expect("n"), particles);
        assert_eq!(got[2].parse::<u64>().expect("broken"), 2 * broken);
        // The extended XYZ writes 13 significant digits for positions, 10 for velocities.
        assert!(got[3].parse::<f64>().expect("dx") < 1e-13, "{text}");
        assert!(got[4].parse::<f64>().expect("dv") < 1e-5, "{text}");
        assert_eq!(got[5].parse::<u64>().expect("id"), particles - 1);
        for name in ["velocity", "mass", "body", "fragment", "broken_bonds"] {
            assert!(
                text.contains(&format!("'{name}'")),
                "{name} missing: {text}"
            );
        }
    }
    // The same directory again, extended XYZ only: the earlier run's VTK files go.
    let mut again: Vec<&str> = args.to_vec();
    again.extend_from_slice(&["--dump-format", "extxyz"]);
    let o = run(&out, &again);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("trajectory.extxyz").is_file());
    assert!(!out.join("trajectory.pvd").exists() && !out.join("vtk").exists());
    // VTK only: no extended XYZ.
    let mut vtk_only: Vec<&str> = args.to_vec();
    vtk_only.extend_from_slice(&["--dump-format", "vtk"]);
    let o = run(&out, &vtk_only);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!out.join("trajectory.extxyz").exists());
    assert!(out.join("trajectory.pvd").is_file() && out.join("vtk/frame_00000.vtu").is_file());
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn keys_lists_the_registry_the_docs_print_and_suspicious_values_warn() {
    let o = bin().args(["keys", "--markdown"]).output().expect("runs");
    assert!(o.status.success());
    let table = String::from_utf8_lossy(&o.stdout).into_owned();
    let docs = std::fs::read_to_string(repo().join("docs/running.md")).expect("docs");
    assert!(
        docs.contains(&table),
        "docs/running.md's keys table is not `hvi-study keys --markdown`: regenerate it"
    );
    assert!(table.lines().count() > 45, "{table}");
    let o = bin()
        .args(["keys", "analysis.quantile"])
        .output()
        .expect("runs");
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("analysis.quantile") && text.contains("[0.5, 1]"),
        "{text}"
    );
    assert!(!text.contains("scene.v0_m_s"), "{text}");
    // In a terminal, links read as words and a path, not Markdown.
    assert!(!text.contains("]("), "{text}");
    assert!(text.contains("(docs/model-decisions.md#"), "{text}");
    // An error words a range as keys does: "a number > 0", not "(0e0, inf)"; and a value
    // that is not allowed draws its error, not a warning about what it would do.
    let out = scratch("range-words");
    let o = run(&out, &["--set", "run.end_time_s=-1", "--quiet"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("invalid value for `run.end_time_s`: -1 (allowed: a number > 0)"),
        "{err}"
    );
    assert!(!err.contains("warning"), "{err}");
    let o = bin()
        .args(["keys", "run.end_time_s"])
        .output()
        .expect("runs");
    assert!(String::from_utf8_lossy(&o.stdout).contains("a number > 0"));
    // `plan` runs nothing: the flags of running are not its flags.
    for flag in [
        ["--threads", "2"],
        ["--jobs", "2"],
        ["--checkpoint-every", "off"],
    ] {
        let o = bin()
            .arg("plan")
            .arg(repo().join("studies/calibration.toml"))
            .args(flag)
            .output()
            .expect("runs");
        assert_eq!(o.status.code(), Some(2), "{flag:?}");
        assert!(
            String::from_utf8_lossy(&o.stderr)
                .contains(&format!("unexpected argument '{}'", flag[0])),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
    }

    // km/s typed as m/s: allowed, but it warns; so does a run too short for a cloud.
    let out = scratch("warn");
    let o = run(
        &out,
        &[
            "--set",
            "scene.v0_m_s=6.7",
            "--set",
            "run.end_time_s=1e-7",
            "--quiet",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("warning: scene.v0_m_s = 6.7 m/s is below 100 m/s"),
        "{err}"
    );
    assert!(
        err.contains("warning: run.end_time_s = 1.000e-7 s is shorter than"),
        "{err}"
    );
    // A study file given to `run`.
    let o = bin()
        .arg("run")
        .arg(repo().join("studies/calibration.toml"))
        .arg("--out")
        .arg(&out)
        .output()
        .expect("runs");
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("hvi-study sweep FILE"));
    let _ = std::fs::remove_dir_all(&out);
}

/// Issue 53: a resolution that cannot represent the scene says so, with the numbers. By hand
/// (docs/running.md, "Resolution"): the calibration scene at 2000 particles with t/D = 0.05
/// has r_eq = 0.0787 D = 0.75 mm, so the 0.4765 mm plate is 1 layer, simulated t/D 0.0787
/// (57 % thicker); the plate's volume fell from 4.35 D^3 to 0.974 D^3, so sigma fell from
/// 1.1 mm to 0.668 mm. default.toml's 10000 particles on a plate of W = 6 D: sigma 0.643 mm
/// -> 0.989 mm. The quick validity map's t/D 0.05 and 0.1 (10 particles across D) are one
/// plate of 1 layer; its plan says so once, naming their 16 runs.
#[test]
fn a_plate_the_resolution_cannot_represent_is_named_with_its_numbers() {
    let out = scratch("resolution");
    let scene = |file: &str, sets: &[&str]| {
        let mut cmd = bin();
        cmd.arg("run")
            .arg(repo().join("studies/scenes").join(file))
            .arg("--out")
            .arg(&out)
            .args(["--quiet", "--fresh"]);
        for s in sets {
            cmd.args(["--set", s]);
        }
        let o = cmd.output().expect("runs");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let at = ["resolution.particles=2000", "run.end_time_s=1e-7"];
    let err = scene("calibration.toml", &[at[0], at[1], "scene.t_over_d=0.05"]);
    for line in [
        "warning: scene.t_over_d = 0.05 gives a plate of 1 particle layer (r_eq 0.75 mm; \
         simulated t/D 0.0787), fewer than the minimum of 3: resolution.particles >= 1.22e5 \
         (or resolution.particles_across_d >= 50) gives it 3\n",
        "warning: scene.t_over_d = 0.05 is simulated as t/D 0.0787: 0.75 mm thick, not \
         0.477 mm (1 layer of r_eq 0.75 mm), 57 % thicker than asked, beyond the 10 % \
         tolerance: resolution.particles >= 9.74e5 (or resolution.particles_across_d >= 100) \
         keeps it within 10 %\n",
        "warning: scene.t_over_d = 0.05 (was 0.425) changes sigma from 1.1 mm to 0.668 mm at \
         resolution.particles = 2000",
    ] {
        assert!(err.contains(line), "{line}\nnot in\n{err}");
    }
    // The scene file's own plate at the same count: 3 layers, 8.5 % thin, the same sigma.
    let err = scene("calibration.toml", &at);
    for word in ["layer", "tolerance", "sigma"] {
        assert!(!err.contains(word), "{err}");
    }

    let err = scene(
        "default.toml",
        &["scene.width_over_d=6", "run.end_time_s=1e-7"],
    );
    assert!(
        err.contains(
            "warning: scene.width_over_d = 6 (was 3) changes sigma from 0.643 mm to 0.989 mm \
             at resolution.particles = 10000 (the particles fill the whole scene's volume): \
             resolution.particles = 36400 keeps sigma at 0.643 mm\n"
        ),
        "{err}"
    );

    let o = bin()
        .arg("plan")
        .arg(repo().join("studies/validity-map.toml"))
        .arg("--out")
        .arg(out.join("plan"))
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    let line = "warning: scene.t_over_d = 0.05 and 0.1 give the same plate of 1 particle layer \
                (r_eq 0.953 mm; simulated t/D 0.1), fewer than the minimum of 3: \
                resolution.particles_across_d >= 50 gives it 3 (16 of 56 runs: \
                scene.t_over_d = 0.05, 0.1)\n";
    assert!(err.contains(line), "{err}");
    assert_eq!(err.matches("0.05 and 0.1").count(), 1, "once: {err}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn completions_man_pages_and_help_say_what_each_command_takes() {
    let o = bin().args(["completions", "bash"]).output().expect("runs");
    assert!(o.status.success());
    let script = String::from_utf8_lossy(&o.stdout);
    assert!(
        script.contains("hvi-study") && script.contains("validity-map"),
        "{script}"
    );
    let dir = scratch("man");
    let o = bin()
        .args(["man", "--out"])
        .arg(&dir)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for page in [
        "hvi-study.1",
        "hvi-study-run.1",
        "hvi-study-keys.1",
        "hvi-study-sweep.1",
    ] {
        let text = std::fs::read_to_string(dir.join(page)).expect(page);
        assert!(
            text.starts_with(".ie") || text.contains(".TH"),
            "{page}: {text}"
        );
    }
    let help = |cmd: &str| {
        let o = bin().args([cmd, "--help"]).output().expect("runs");
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    // Commands that run nothing take no --threads or --jobs.
    for cmd in ["status", "collect"] {
        let h = help(cmd);
        assert!(
            !h.contains("--threads") && !h.contains("--jobs"),
            "{cmd}: {h}"
        );
        assert!(h.contains("--tier"), "{cmd}: {h}");
    }
    assert!(help("sweep").contains("--jobs"));
    assert!(help("validity-map").contains("studies/validity-map.toml"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn output_into_a_pipe_closed_early_ends_quietly() {
    // `hvi-study keys | head`: the reader goes away before the list is written. The process
    // ends as `ls | head` does (SIGPIPE), without a panic or a backtrace.
    use std::io::Read;
    for _ in 0..5 {
        let mut child = bin()
            .arg("keys")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("starts");
        drop(child.stdout.take()); // the reader closes at once
        let status = child.wait().expect("ends");
        let mut err = String::new();
        child
            .stderr
            .take()
            .expect("stderr")
            .read_to_string(&mut err)
            .expect("stderr");
        assert!(!err.contains("panicked"), "{err}");
        assert_ne!(status.code(), Some(101), "{err}");
    }
}

/// A binary built on a cluster's login node must run on its compute nodes: the workspace's
/// build settings ask for no particular processor (reports/benchmark-portable measures what
/// the native opt-in gains).
#[test]
fn builds_are_portable_by_default() {
    let path = repo().join(".cargo/config.toml");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return; // no build settings at all: portable
    };
    let config: toml::Value = toml::from_str(&text).expect("config.toml parses");
    let flags = |v: Option<&toml::Value>| -> Vec<String> {
        match v {
            Some(toml::Value::Array(a)) => a
                .iter()
                .filter_map(|f| f.as_str().map(String::from))
                .collect(),
            Some(toml::Value::String(s)) => s.split_whitespace().map(String::from).collect(),
            _ => Vec::new(),
        }
    };
    let mut all = flags(config.get("build").and_then(|b| b.get("rustflags")));
    if let Some(targets) = config.get("target").and_then(|t| t.as_table()) {
        for t in targets.values() {
            all.extend(flags(t.get("rustflags")));
        }
    }
    assert!(
        !all.iter()
            .any(|f| f.contains("target-cpu") || f.contains("target-feature")),
        "{}: {all:?}",
        path.display()
    );
}
