//! The reproduction's record: per figure the paper's result, ours, the deciding numbers and a
//! verdict; the machine and the run times; the wall-time estimate. Written as `report.md`
//! (for people) and `reproduce.json` (for the next night's comparison, [`diff`]).

use std::fmt::Write as _;
use std::path::Path;

use hvi_run::error::{Result, ResultExt};
use serde::{Deserialize, Serialize};

pub use hvi_analysis::number::{fmt_duration, fmt_num, short};

use hvi_run::output::write_atomic_bytes;

/// How a figure compares with the paper.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// What the paper reports holds in our runs.
    Reproduced,
    /// Part of it holds.
    Partly,
    /// It does not hold (or could not be checked at all).
    Not,
    /// Not computed yet (the reproduction is still running, or stopped before it).
    Pending,
}

impl Verdict {
    /// The word the report uses.
    pub fn word(self) -> &'static str {
        match self {
            Verdict::Reproduced => "reproduced",
            Verdict::Partly => "partly",
            Verdict::Not => "not reproduced",
            Verdict::Pending => "pending",
        }
    }

    /// From how many of `total` checks hold: all, some, none.
    pub fn of_checks(held: usize, total: usize) -> Verdict {
        if total > 0 && held == total {
            Verdict::Reproduced
        } else if held > 0 {
            Verdict::Partly
        } else {
            Verdict::Not
        }
    }

    /// From a figure's claims: "not reproduced" when any check of its main claim fails
    /// (whatever the secondary checks say), "reproduced" when every check holds, "partly" when
    /// the main claim holds and a secondary check does not.
    pub fn of_claims(main: &[Check], secondary: &[Check]) -> Verdict {
        if !main.iter().all(|c| c.held) {
            Verdict::Not
        } else if secondary.iter().all(|c| c.held) {
            Verdict::Reproduced
        } else {
            Verdict::Partly
        }
    }
}

/// One check of a figure against the paper: whether it holds, and what was found, with its
/// numbers (worded for either outcome).
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// Whether it holds.
    pub held: bool,
    /// What was found, as the reason says it.
    pub found: String,
}

impl Check {
    /// A check and what was found.
    pub fn new(held: bool, found: impl Into<String>) -> Check {
        Check {
            held,
            found: found.into(),
        }
    }
}

/// A figure's verdict from its main and secondary checks ([`Verdict::of_claims`]) and the
/// reason that says each: `Main claim holds: ...; ... Secondary: ...; ...`.
pub fn judge(main: &[Check], secondary: &[Check]) -> (Verdict, String) {
    let say = |checks: &[Check]| {
        checks
            .iter()
            .map(|c| c.found.as_str())
            .collect::<Vec<_>>()
            .join("; ")
    };
    let mut reason = format!(
        "Main claim {}: {}.",
        if main.iter().all(|c| c.held) {
            "holds"
        } else {
            "fails"
        },
        say(main)
    );
    if !secondary.is_empty() {
        let _ = write!(reason, " Secondary: {}.", say(secondary));
    }
    (Verdict::of_claims(main, secondary), reason)
}

/// A deciding number's value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Value {
    /// A number.
    Number(f64),
    /// Yes or no.
    Flag(bool),
    /// Anything else, and "n/a" for a missing number.
    Text(String),
}

impl Value {
    /// A number, or "n/a" when it is missing or not finite.
    pub fn num(x: Option<f64>) -> Value {
        match x {
            Some(v) if v.is_finite() => Value::Number(v),
            _ => Value::Text("n/a".into()),
        }
    }

    /// As the report prints it.
    pub fn show(&self) -> String {
        match self {
            Value::Number(x) => fmt_num(*x),
            Value::Flag(b) => (if *b { "yes" } else { "no" }).into(),
            Value::Text(s) => s.clone(),
        }
    }
}

/// One deciding number.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Number {
    /// What it is (unique within its figure; the key of the nightly comparison).
    pub name: String,
    /// Its value.
    pub value: Value,
    /// How it was computed, or the paper's value beside it.
    pub note: String,
    /// A run time or throughput: shown, but not compared between nights (it differs between
    /// runs of the command).
    #[serde(default)]
    pub timing: bool,
}

/// One figure (or a pair shown together) of the reproduction.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Figure {
    /// The paper's figure number(s): `3`, `11-12`.
    pub id: String,
    /// What it shows.
    pub title: String,
    /// What the paper reports (from `hvi_engine::paper`).
    pub paper: String,
    /// What we find, in one or two sentences.
    pub ours: String,
    /// The numbers that decide the verdict.
    pub numbers: Vec<Number>,
    /// The verdict.
    pub verdict: Verdict,
    /// Why.
    pub reason: String,
    /// The figure files, relative to the report.
    pub files: Vec<String>,
}

impl Figure {
    /// A figure not computed yet.
    pub fn pending(id: &str, title: &str, paper: String) -> Figure {
        Figure {
            id: id.into(),
            title: title.into(),
            paper,
            ours: "not computed yet".into(),
            numbers: Vec::new(),
            verdict: Verdict::Pending,
            reason: "its stage has not finished".into(),
            files: Vec::new(),
        }
    }

    /// Adds a deciding number.
    pub fn number(&mut self, name: impl Into<String>, value: Value, note: impl Into<String>) {
        self.numbers.push(Number {
            name: name.into(),
            value,
            note: note.into(),
            timing: false,
        });
    }

    /// Adds a run time or throughput (not compared between nights).
    pub fn timing(&mut self, name: impl Into<String>, value: Value, note: impl Into<String>) {
        self.numbers.push(Number {
            name: name.into(),
            value,
            note: note.into(),
            timing: true,
        });
    }
}

/// What one stage of the reproduction did and how long it took.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StageTiming {
    /// The stage (`sizing`, `calibration`, ...).
    pub stage: String,
    /// The figures it makes.
    pub figures: String,
    /// Runs in its plan.
    pub runs: usize,
    /// Simulated now.
    pub ran: usize,
    /// Found in the store.
    pub cached: usize,
    /// Failed runs.
    pub failed: usize,
    /// Wall time, s.
    pub wall_seconds: f64,
}

/// The machine the reproduction ran on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Machine {
    /// CPU model (`/proc/cpuinfo`).
    pub cpu: String,
    /// Logical CPUs available to the process.
    pub cores: usize,
    /// Operating system and architecture.
    pub os: String,
}

impl Machine {
    /// This machine.
    pub fn detect() -> Machine {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|t| {
                t.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_string())
            })
            .unwrap_or_else(|| "unknown".into());
        Machine {
            cpu,
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            os: format!("{} {}", std::env::consts::OS, std::env::consts::ARCH),
        }
    }
}

/// One stage's share of a tier's cost.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EstimateRow {
    /// The stage.
    pub stage: String,
    /// The figures it makes.
    pub figures: String,
    /// Runs.
    pub runs: usize,
    /// Smallest and largest run, particles.
    pub particles: (usize, usize),
    /// Sum over runs of particles x steps.
    pub particle_steps: f64,
    /// particle_steps / throughput, s.
    pub seconds: f64,
}

/// The expected wall time of a tier from its runs' particle-steps.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Estimate {
    /// The tier.
    pub tier: String,
    /// Per stage.
    pub rows: Vec<EstimateRow>,
    /// The throughput assumed, particle-steps/s.
    pub particle_steps_per_second: f64,
    /// On this many cores.
    pub cores: usize,
    /// Where the throughput comes from.
    pub source: String,
}

impl Estimate {
    /// Total particle-steps.
    pub fn particle_steps(&self) -> f64 {
        self.rows.iter().map(|r| r.particle_steps).sum()
    }

    /// Total seconds.
    pub fn seconds(&self) -> f64 {
        self.rows.iter().map(|r| r.seconds).sum()
    }
}

/// The whole reproduction.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Reproduction {
    /// The tier.
    pub tier: String,
    /// The tier's description.
    pub tier_description: String,
    /// The config file.
    pub config: String,
    /// hvi-study version.
    pub version: String,
    /// The machine.
    pub machine: Machine,
    /// Whether every stage has finished.
    pub complete: bool,
    /// The figures in the paper's order.
    pub figures: Vec<Figure>,
    /// What each stage did.
    pub stages: Vec<StageTiming>,
    /// Wall time so far, s.
    pub wall_seconds: f64,
    /// Wall-time estimates: this tier's, and the config's estimate tier's.
    pub estimates: Vec<Estimate>,
    /// Notes on the model decisions every figure depends on.
    pub notes: Vec<String>,
    /// What changed since the previous report (`--previous`), one line each.
    pub changes: Option<Vec<String>>,
}

/// Text as one Markdown table cell (pipes escaped, on one line).
pub fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// Checks a report directory before anything runs, and creates it: a new or empty directory,
/// or an earlier report of `command` (it holds `marker`, e.g. `reproduce.json`); it must be
/// writable.
pub fn check_report_dir(out: &Path, marker: &str, command: &str) -> Result<()> {
    if out.exists() {
        if !out.is_dir() {
            hvi_run::bail!(
                "invalid value for `--out`: {} is a file (allowed: a directory)",
                out.display()
            );
        }
        let empty = std::fs::read_dir(out)
            .with_context(|| format!("cannot read --out {}", out.display()))?
            .next()
            .is_none();
        if !empty && !out.join(marker).exists() {
            hvi_run::bail!(
                "refusing to write into --out {}: it is not empty and holds no {marker} \
                 (not a report of `hvi-study {command}`); choose a new or empty directory",
                out.display()
            );
        }
    }
    std::fs::create_dir_all(out)
        .with_context(|| format!("cannot create --out {}", out.display()))?;
    let probe = out.join(format!(".write-test-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .with_context(|| format!("cannot write into --out {}", out.display()))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// A figure's deciding numbers as a Markdown table (nothing when it has none).
pub fn numbers_table(s: &mut String, numbers: &[Number]) {
    if numbers.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "| deciding number | value | how / paper |\n|---|---|---|"
    );
    for n in numbers {
        let _ = writeln!(
            s,
            "| {} | {} | {} |",
            cell(&n.name),
            cell(&n.value.show()),
            cell(&n.note)
        );
    }
    s.push('\n');
}

impl Reproduction {
    /// The report as Markdown: the header and notes, the summary table, the changes since the
    /// previous report, the machine and run times, the estimates, then one section per figure.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        self.header(&mut s);
        self.summary(&mut s);
        if let Some(changes) = &self.changes {
            changes_section(&mut s, changes);
        }
        self.run_times(&mut s);
        for e in &self.estimates {
            estimate_section(&mut s, e);
        }
        for f in &self.figures {
            figure_section(&mut s, f);
        }
        s
    }

    fn header(&self, s: &mut String) {
        let _ = writeln!(
            s,
            "# Reproduction of Watson & Steinhauser (2017), tier `{}`\n",
            self.tier
        );
        let _ = writeln!(
            s,
            "Written by `hvi-study reproduce --tier {}` (hvi-study {}, config `{}`). Regenerate it \
             with the command; do not edit it. The paper's numbers come from \
             `crates/hvi-scene/src/paper.rs`; every number of ours is computed by the command from \
             the runs.{}\n",
            self.tier,
            self.version,
            self.config,
            if self.complete {
                ""
            } else {
                " **Incomplete: some stages have not finished (verdict `pending`).**"
            }
        );
        if !self.tier_description.is_empty() {
            let _ = writeln!(s, "Tier `{}`: {}\n", self.tier, self.tier_description);
        }
        for n in &self.notes {
            let _ = writeln!(s, "- {n}");
        }
        if !self.notes.is_empty() {
            s.push('\n');
        }
    }

    /// One row per figure: the paper, ours, the verdict and why.
    fn summary(&self, s: &mut String) {
        let _ = writeln!(s, "## Summary\n");
        let _ = writeln!(s, "| Fig. | paper | ours | verdict |\n|---|---|---|---|");
        for f in &self.figures {
            let _ = writeln!(
                s,
                "| [{}](#fig-{}) | {} | {} | **{}**: {} |",
                f.id,
                f.id,
                cell(&f.paper),
                cell(&f.ours),
                f.verdict.word(),
                cell(&f.reason)
            );
        }
        s.push('\n');
    }

    /// The machine and what each stage ran, took from the store and took in wall time.
    fn run_times(&self, s: &mut String) {
        let _ = writeln!(s, "## Machine and run times\n");
        let _ = writeln!(
            s,
            "{} ({} logical CPUs available), {}. Run times differ between runs of the command; \
             everything else in this report is reproducible (the engine is bit-identical at any \
             thread count, and runs come from the store by fingerprint).\n",
            self.machine.cpu, self.machine.cores, self.machine.os
        );
        let _ = writeln!(
            s,
            "| stage | figures | runs | simulated now | from the store | failed | wall time |\n|---|---|---|---|---|---|---|"
        );
        for t in &self.stages {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} |",
                t.stage,
                t.figures,
                t.runs,
                t.ran,
                t.cached,
                t.failed,
                fmt_duration(t.wall_seconds)
            );
        }
        let _ = writeln!(
            s,
            "\nTotal wall time: {}.\n",
            fmt_duration(self.wall_seconds)
        );
    }
    /// Writes `report.md` and `reproduce.json` into `dir`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        write_atomic_bytes(&dir.join("report.md"), self.markdown().as_bytes())?;
        write_atomic_bytes(
            &dir.join("reproduce.json"),
            serde_json::to_string_pretty(self)?.as_bytes(),
        )?;
        Ok(())
    }

    /// Reads a `reproduce.json`.
    pub fn load(path: &Path) -> Result<Reproduction> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        serde_json::from_str(&text)
            .with_context(|| format!("{} is not a reproduce.json", path.display()))
    }
}

/// What changed since the previous report, one line each, or that nothing did.
fn changes_section(s: &mut String, changes: &[String]) {
    let _ = writeln!(s, "## What changed since the previous report\n");
    if changes.is_empty() {
        let _ = writeln!(
            s,
            "Nothing: every verdict and deciding number is as in the previous report.\n"
        );
    } else {
        for c in changes {
            let _ = writeln!(s, "- {c}");
        }
        s.push('\n');
    }
}

/// A tier's expected wall time per stage, from its runs' particles x base steps.
fn estimate_section(s: &mut String, e: &Estimate) {
    let _ = writeln!(
        s,
        "## Expected wall time of the `{}` tier on {} cores\n",
        e.tier, e.cores
    );
    let _ = writeln!(
        s,
        "From every planned run's particle count and number of base steps (the scene's own \
         base step, as the engine chooses it; the adaptive step takes fewer, longer steps) \
         at {} particles x base steps per second ({}).\n",
        fmt_num(e.particle_steps_per_second),
        e.source
    );
    let _ = writeln!(
        s,
        "| stage | figures | runs | particles | particles x base steps | expected |\n|---|---|---|---|---|---|"
    );
    for r in &e.rows {
        let particles = if r.particles.0 == r.particles.1 {
            r.particles.0.to_string()
        } else {
            format!("{}-{}", r.particles.0, r.particles.1)
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {particles} | {} | {} |",
            r.stage,
            r.figures,
            r.runs,
            fmt_num(r.particle_steps),
            fmt_duration(r.seconds)
        );
    }
    let _ = writeln!(
        s,
        "| total | | {} | | {} | **{}** |\n",
        e.rows.iter().map(|r| r.runs).sum::<usize>(),
        fmt_num(e.particle_steps()),
        fmt_duration(e.seconds())
    );
}

/// A figure's section: its pictures, its data files, the paper, ours, the verdict and the
/// deciding numbers.
fn figure_section(s: &mut String, f: &Figure) {
    let _ = writeln!(s, "<a id=\"fig-{}\"></a>\n", f.id);
    let figs = if f.id.contains('-') { "Figs." } else { "Fig." };
    let _ = writeln!(s, "## {figs} {}: {}\n", f.id, f.title);
    for file in f.files.iter().filter(|p| p.ends_with(".png")) {
        let _ = writeln!(s, "![Fig. {}: {file}]({file})\n", f.id);
    }
    let others: Vec<&String> = f.files.iter().filter(|p| !p.ends_with(".png")).collect();
    if !others.is_empty() {
        let _ = writeln!(
            s,
            "Data: {}\n",
            others
                .iter()
                .map(|p| format!("[`{p}`]({p})"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let _ = writeln!(s, "- **Paper:** {}", f.paper);
    let _ = writeln!(s, "- **Ours:** {}", f.ours);
    let _ = writeln!(s, "- **Verdict: {}.** {}\n", f.verdict.word(), f.reason);
    numbers_table(s, &f.numbers);
}

/// Whether two values are the same, numbers to 1e-12 relative (a number read back from JSON
/// may differ from the one written in its last bit).
fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => (x - y).abs() <= 1e-12 * x.abs().max(y.abs()),
        _ => a == b,
    }
}

/// What changed from `previous` to `current`: verdicts and deciding numbers, one line each
/// (run times are not compared). Empty when nothing changed.
pub fn diff(previous: &Reproduction, current: &Reproduction) -> Vec<String> {
    let mut out = Vec::new();
    if previous.tier != current.tier {
        out.push(format!(
            "the previous report is of tier `{}`, this one of `{}`",
            previous.tier, current.tier
        ));
    }
    for f in &current.figures {
        let Some(p) = previous.figures.iter().find(|p| p.id == f.id) else {
            out.push(format!("Fig. {}: new (verdict {})", f.id, f.verdict.word()));
            continue;
        };
        if p.verdict != f.verdict {
            out.push(format!(
                "Fig. {}: verdict {} -> **{}** ({})",
                f.id,
                p.verdict.word(),
                f.verdict.word(),
                f.reason
            ));
        }
        for n in f.numbers.iter().filter(|n| !n.timing) {
            match p.numbers.iter().find(|m| m.name == n.name) {
                None => out.push(format!(
                    "Fig. {}: {} = {} (new)",
                    f.id,
                    n.name,
                    n.value.show()
                )),
                Some(m) if !same(&m.value, &n.value) => {
                    let rel = match (&m.value, &n.value) {
                        (Value::Number(a), Value::Number(b)) if *a != 0.0 => {
                            format!(" ({:+.2} %)", 100.0 * (b - a) / a.abs())
                        }
                        _ => String::new(),
                    };
                    out.push(format!(
                        "Fig. {}: {}: {} -> {}{rel}",
                        f.id,
                        n.name,
                        m.value.show(),
                        n.value.show()
                    ))
                }
                Some(_) => {}
            }
        }
        for m in p.numbers.iter().filter(|m| !m.timing) {
            if !f.numbers.iter().any(|n| n.name == m.name) {
                out.push(format!("Fig. {}: {} no longer reported", f.id, m.name));
            }
        }
    }
    for p in &previous.figures {
        if !current.figures.iter().any(|f| f.id == p.id) {
            out.push(format!("Fig. {}: no longer reported", p.id));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn repro(f: Vec<Figure>) -> Reproduction {
        Reproduction {
            tier: "quick".into(),
            tier_description: String::new(),
            config: "studies/reproduce.toml".into(),
            version: "0".into(),
            machine: Machine {
                cpu: "cpu".into(),
                cores: 2,
                os: "linux".into(),
            },
            complete: true,
            figures: f,
            stages: Vec::new(),
            wall_seconds: 1.0,
            estimates: Vec::new(),
            notes: Vec::new(),
            changes: None,
        }
    }

    fn fig(verdict: Verdict, x: f64) -> Figure {
        let mut f = Figure::pending("5", "F", "paper".into());
        f.verdict = verdict;
        f.number("F at 2000", Value::Number(x), "");
        f.number("converged", Value::Flag(false), "");
        f.timing("wall time", Value::Number(x * 100.0), "");
        f
    }

    #[test]
    fn numbers_format_and_verdicts_combine() {
        assert_eq!(fmt_num(1.5432), "1.543");
        assert_eq!(fmt_num(0.3), "0.3000");
        assert_eq!(fmt_num(2.5e5), "250000");
        assert_eq!(fmt_num(2.4e7), "2.400e7");
        assert_eq!(fmt_num(2.5e-5), "2.500e-5");
        assert_eq!(fmt_num(12.0), "12");
        assert_eq!(fmt_num(50430.0), "50430");
        assert_eq!(fmt_num(12.5), "12.50");
        assert_eq!(short(16.099999999999998), "16.1");
        assert_eq!(short(4.56e6), "4.56e6");
        assert_eq!(short(0.01), "0.01");
        assert_eq!(fmt_num(0.0), "0");
        assert_eq!(fmt_num(f64::NAN), "n/a");
        assert_eq!(Value::num(Some(f64::INFINITY)).show(), "n/a");
        assert_eq!(Verdict::of_checks(2, 2), Verdict::Reproduced);
        assert_eq!(Verdict::of_checks(1, 2), Verdict::Partly);
        assert_eq!(Verdict::of_checks(0, 2), Verdict::Not);
        assert_eq!(fmt_duration(30.0), "30 s");
        assert_eq!(fmt_duration(7200.0), "2.0 h");
        assert_eq!(fmt_duration(3.0 * 86400.0), "3.0 days");
    }

    #[test]
    fn a_failed_main_claim_is_not_reproduced_whatever_the_secondary_checks_say() {
        let yes = || Check::new(true, "it varies little");
        let no = || Check::new(false, "it rises");
        assert_eq!(Verdict::of_claims(&[yes()], &[yes()]), Verdict::Reproduced);
        assert_eq!(Verdict::of_claims(&[yes()], &[no()]), Verdict::Partly);
        assert_eq!(Verdict::of_claims(&[yes()], &[]), Verdict::Reproduced);
        // Fig. 10's case: the trend fails, the secondary check holds.
        assert_eq!(Verdict::of_claims(&[no()], &[yes()]), Verdict::Not);
        assert_eq!(Verdict::of_claims(&[yes(), no()], &[]), Verdict::Not);
        let (v, reason) = judge(&[no()], &[yes()]);
        assert_eq!(v, Verdict::Not);
        assert_eq!(
            reason,
            "Main claim fails: it rises. Secondary: it varies little."
        );
        let (v, reason) = judge(&[yes(), yes()], &[]);
        assert_eq!(v, Verdict::Reproduced);
        assert_eq!(
            reason,
            "Main claim holds: it varies little; it varies little."
        );
    }

    #[test]
    fn diff_reports_verdicts_and_numbers_only() {
        let a = repro(vec![fig(Verdict::Partly, 0.40)]);
        let mut b = repro(vec![fig(Verdict::Partly, 0.40)]);
        b.wall_seconds = 99.0;
        assert!(diff(&a, &b).is_empty());
        let c = repro(vec![fig(Verdict::Reproduced, 0.44)]);
        let d = diff(&a, &c);
        assert_eq!(d.len(), 2, "{d:?}");
        assert!(d[0].contains("partly -> **reproduced**"), "{d:?}");
        assert!(d[1].contains("0.4000 -> 0.4400 (+10.00 %)"), "{d:?}");
        // A last-bit difference is no change.
        let e = repro(vec![fig(Verdict::Partly, 0.40 * (1.0 + 1e-15))]);
        assert!(diff(&a, &e).is_empty());
        // JSON round trip keeps the values comparable.
        let json = serde_json::to_string(&c).expect("json");
        let back: Reproduction = serde_json::from_str(&json).expect("back");
        assert!(diff(&c, &back).is_empty());
        assert!(c.markdown().contains("**reproduced**"));
    }
}
