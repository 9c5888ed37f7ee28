//! `hvi-study run --lammps DIR`: the exported scene runs in LAMMPS as `lmp -in DIR/in.lmp`,
//! unedited and from another directory, and agrees with hvi's run of the same scene (total
//! energy with the broken-bond ledger within 1e-4, bonds broken within 2 % or 2: the
//! tolerances of `bench/lammps/compare.sh --check`). Without LAMMPS the comparison skips with
//! a message, and fails under CI=true (`.ci/run` installs Debian's `lammps`).

use std::path::Path;
use std::process::Command;

mod common;
use common::{bin, repo, scratch};

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
        .expect("json")
}

#[test]
fn an_exported_scene_runs_in_lammps_unedited_and_agrees_with_hvi() {
    let dir = scratch("hvi-lammps", "export");
    let (out, lmp_dir) = (dir.join("hvi"), dir.join("lammps"));
    // The impact's first 150 steps at 2000 particles: bonds break, as in the CI smoke.
    let o = bin()
        .arg("run")
        .arg(repo().join("studies/scenes/default.toml"))
        .args([
            "--set",
            "resolution.particles=2000",
            "--set",
            "run.max_stride=1",
            "--set",
            "run.end_time_s=4.6e-7",
            "--set",
            "run.energy_every=25",
            "--threads",
            "1",
            "--quiet",
        ])
        .arg("--out")
        .arg(&out)
        .arg("--lammps")
        .arg(&lmp_dir)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = summary(&out);
    for f in ["data.lmp", "bond.table", "model.lmp", "in.lmp"] {
        assert!(lmp_dir.join(f).is_file(), "{f}");
    }
    // Every coefficient of the scene is in the script, at full precision.
    let input = std::fs::read_to_string(lmp_dir.join("in.lmp")).expect("in.lmp");
    let d = &s["derived"];
    for (var, key) in [
        ("sigma", "sigma_m"),
        ("r_eq", "r_eq_m"),
        ("eps", "eps_j"),
        ("kappa", "kappa_n_m"),
        ("rcut", "rcut_m"),
        ("dt", "dt_s"),
    ] {
        let line = input
            .lines()
            .find(|l| l.split_whitespace().nth(1) == Some(var))
            .unwrap_or_else(|| panic!("no variable {var} in {input}"));
        let v: f64 = line
            .split_whitespace()
            .nth(3)
            .expect("value")
            .parse()
            .expect("number");
        assert_eq!(v, d[key].as_f64().expect(key), "{var}");
    }
    assert!(
        input.contains(&format!("steps         index {}", s["steps"])),
        "{input}"
    );

    let Some(lmp) = ["lmp", "lmp_serial"].into_iter().find(|c| {
        Command::new(c)
            .arg("-h")
            .output()
            .is_ok_and(|o| o.status.success())
    }) else {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true but no LAMMPS (lmp) to run the export (.ci/run installs Debian's lammps)"
        );
        eprintln!("SKIP: no LAMMPS here: the exported scene was not run");
        return;
    };
    // Unedited, from another directory.
    let o = Command::new(lmp)
        .current_dir(&dir)
        .arg("-in")
        .arg(lmp_dir.join("in.lmp"))
        .args(["-screen", "none", "-log"])
        .arg(dir.join("log.lammps"))
        .output()
        .expect("lmp runs");
    let log = std::fs::read_to_string(dir.join("log.lammps")).unwrap_or_default();
    assert!(o.status.success(), "{log}");
    let fin: std::collections::HashMap<&str, f64> = log
        .lines()
        .find_map(|l| l.strip_prefix("HVI_FINAL "))
        .expect("HVI_FINAL line")
        .split_whitespace()
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k, v.parse().expect("number")))
        .collect();
    assert_eq!(fin["step"], s["steps"].as_f64().expect("steps"));
    let e = &s["energy"];
    let (hvi_total, lmp_total) = (e["total_final_j"].as_f64().expect("total"), fin["econs"]);
    assert!(
        (hvi_total - lmp_total).abs() <= 1e-4 * hvi_total.abs(),
        "total energy: hvi {hvi_total}, LAMMPS {lmp_total}"
    );
    let (hvi_broken, lmp_broken) = (s["bonds_broken"].as_f64().expect("broken"), fin["broken"]);
    assert!(
        hvi_broken > 0.0,
        "no bond broke: the comparison would be empty"
    );
    assert!(
        (hvi_broken - lmp_broken).abs() <= (0.02 * hvi_broken).max(2.0),
        "bonds broken: hvi {hvi_broken}, LAMMPS {lmp_broken}"
    );
}

#[test]
fn an_export_into_the_run_directory_survives_the_next_run() {
    let dir = scratch("hvi-lammps", "keep");
    let out = dir.join("run");
    let go = || {
        bin()
            .arg("run")
            .arg(repo().join("studies/scenes/default.toml"))
            .args([
                "--set",
                "resolution.particles=300",
                "--set",
                "run.end_time_s=1e-8",
                "--threads",
                "1",
                "--quiet",
            ])
            .arg("--out")
            .arg(&out)
            .arg("--lammps")
            .arg(out.join("lammps"))
            .output()
            .expect("runs")
    };
    assert!(go().status.success());
    assert!(go().status.success());
    assert!(out.join("lammps/in.lmp").is_file());
}
