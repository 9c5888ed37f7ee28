//! The readings study's report: `report.md` (every reading side by side, then each with its
//! two maps, verdicts and deciding numbers), `fidelity.json` (the same for machines),
//! `readings.csv` (one row per reading) and the maps `<reading>_R.png` / `<reading>_va.png`.

use std::fmt::Write as _;
use std::path::Path;

use hvi_engine::paper;
use hvi_plot::contour::{contour_plot, ContourPlot, Marker};
use hvi_run::error::{Result, ResultExt};
use plotters::style::RGBColor;
use serde::Serialize;

use crate::result::{FidelityResult, Judged, SeedFields};
use hvi_reproduce::report::{cell, check_report_dir, fmt_num, numbers_table, Figure};
use hvi_reproduce::stages::{FIG10_CHECKS, FIG10_MAIN_CHECKS, FIG9_CHECKS, FIG9_MAIN_CHECKS};
use hvi_run::output::{write_atomic_bytes, write_csv_atomic};

/// All check names, Fig. 9's then Fig. 10's, in [`Judged::checks`] order, with whether each is
/// part of its figure's main claim.
fn check_names() -> Vec<(String, bool)> {
    let named = |fig: &str, names: &[&str], main: usize| {
        names
            .iter()
            .enumerate()
            .map(|(i, n)| (format!("Fig. {fig}: {n}"), i < main))
            .collect::<Vec<_>>()
    };
    let mut v = named("9", &FIG9_CHECKS, FIG9_MAIN_CHECKS);
    v.extend(named("10", &FIG10_CHECKS, FIG10_MAIN_CHECKS));
    v
}

#[derive(Serialize)]
struct ReadingRow<'a> {
    reading: &'a str,
    label: &'a str,
    source: String,
    seeds: String,
    runs: usize,
    fig9_verdict: &'static str,
    fig10_verdict: &'static str,
    main_checks_held: usize,
    checks_held: usize,
    checks: usize,
    r_plateau_mean: Option<f64>,
    r_plateau_relative_spread: Option<f64>,
    r_peak: Option<f64>,
    r_at_paper_fit: Option<f64>,
    va_rows_falling: String,
    va_spread_along_eps: Option<f64>,
    r_seed_spread: Option<f64>,
    va_seed_spread: Option<f64>,
}

/// A deciding number of a judged figure, by name.
fn number(f: &Figure, name: &str) -> Option<f64> {
    f.numbers
        .iter()
        .find(|n| n.name.starts_with(name))
        .and_then(|n| match n.value {
            hvi_reproduce::report::Value::Number(x) => Some(x),
            _ => None,
        })
}

fn text(f: &Figure, name: &str) -> String {
    f.numbers
        .iter()
        .find(|n| n.name.starts_with(name))
        .map_or("n/a".into(), |n| n.value.show())
}

fn row<'a>(j: &'a Judged, all: &[Judged]) -> ReadingRow<'a> {
    let readings: Vec<_> = all.iter().map(|j| j.reading.clone()).collect();
    let (main, held) = j.score();
    ReadingRow {
        reading: &j.reading.name,
        label: &j.reading.label,
        source: j.reading.source_text(&readings),
        seeds: j
            .seeds
            .iter()
            .map(|s| s.to_string())
            .collect::<Vec<_>>()
            .join(" "),
        runs: j.runs,
        fig9_verdict: j.fig9.verdict.word(),
        fig10_verdict: j.fig10.verdict.word(),
        main_checks_held: main,
        checks_held: held,
        checks: j.checks().len(),
        r_plateau_mean: number(&j.fig9, "R plateau: mean"),
        r_plateau_relative_spread: number(&j.fig9, "R plateau: (max - min) / mean"),
        r_peak: number(&j.fig9, "R peak"),
        r_at_paper_fit: number(&j.fig9, "R at the paper's fit"),
        va_rows_falling: text(&j.fig10, "\u{3ba} rows where va/v0 falls"),
        va_spread_along_eps: number(&j.fig10, "mean spread of va/v0 along \u{3b5}"),
        r_seed_spread: j.length_ratio.seed_spread(),
        va_seed_spread: j.front_velocity.seed_spread(),
    }
}

#[derive(Serialize)]
struct JsonReading<'a> {
    #[serde(flatten)]
    row: ReadingRow<'a>,
    checks_detail: Vec<(String, bool, String)>,
    per_seed: Vec<(u64, &'static str, &'static str)>,
    fig9: &'a Figure,
    fig10: &'a Figure,
    length_ratio_mean: &'a hvi_analysis::contour::Field,
    front_velocity_ratio_mean: &'a hvi_analysis::contour::Field,
}

#[derive(Serialize)]
struct JsonReport<'a> {
    config: String,
    tier: &'a str,
    particles: Option<f64>,
    seeds: &'a [u64],
    closest: Option<&'a str>,
    claims_no_reading_reproduces: Vec<String>,
    wall_seconds: f64,
    ran: usize,
    readings: Vec<JsonReading<'a>>,
}

/// The checks that hold in no reading.
fn unreproduced(res: &FidelityResult) -> Vec<String> {
    check_names()
        .into_iter()
        .enumerate()
        .filter(|(i, _)| res.readings.iter().all(|j| !j.checks()[*i].held))
        .map(|(_, (n, main))| format!("{n}{}", if main { " (main claim)" } else { "" }))
        .collect()
}

/// Writes the whole report into `out`.
pub fn write_report(res: &FidelityResult, out: &Path) -> Result<()> {
    check_report_dir(out, "fidelity.json", "fidelity")?;
    for j in &res.readings {
        draw_maps(res, j, out)?;
    }
    let rows: Vec<ReadingRow> = res.readings.iter().map(|j| row(j, &res.readings)).collect();
    write_csv_atomic(&out.join("readings.csv"), rows)?;
    let names = check_names();
    let json = JsonReport {
        config: res.config.path.display().to_string(),
        tier: &res.tier,
        particles: res.particles,
        seeds: &res.seeds,
        closest: res.closest().map(|j| j.reading.name.as_str()),
        claims_no_reading_reproduces: unreproduced(res),
        wall_seconds: res.wall_seconds,
        ran: res.ran,
        readings: res
            .readings
            .iter()
            .map(|j| JsonReading {
                row: row(j, &res.readings),
                checks_detail: names
                    .iter()
                    .zip(j.checks())
                    .map(|((n, _), c)| (n.clone(), c.held, c.found.clone()))
                    .collect(),
                per_seed: j
                    .per_seed
                    .iter()
                    .map(|(s, a, b)| (*s, a.word(), b.word()))
                    .collect(),
                fig9: &j.fig9,
                fig10: &j.fig10,
                length_ratio_mean: &j.length_ratio.mean,
                front_velocity_ratio_mean: &j.front_velocity.mean,
            })
            .collect(),
    };
    let text = serde_json::to_string_pretty(&json).context("fidelity.json")?;
    write_atomic_bytes(&out.join("fidelity.json"), text.as_bytes())?;
    write_atomic_bytes(&out.join("report.md"), markdown(res).as_bytes())?;
    Ok(())
}

/// The maps' markers: the paper's fit, and on the R map the paper's peak.
fn markers(with_peak: bool) -> Vec<Marker> {
    let mut m = vec![Marker {
        at: (paper::BEST_EPS_J, paper::BEST_KAPPA_N_M),
        label: "paper's fit (0.01, 4.56e6)".into(),
        color: RGBColor(255, 255, 255),
        cross: false,
    }];
    if with_peak {
        m.push(Marker {
            at: paper::FIG9_R_PEAK_AT,
            label: format!("paper's peak R = {}", paper::FIG9_R_PEAK),
            color: RGBColor(230, 0, 0),
            cross: true,
        });
    }
    m
}

fn draw_maps(res: &FidelityResult, j: &Judged, out: &Path) -> Result<()> {
    let seeds = res
        .seeds
        .iter()
        .map(|s| s.to_string())
        .collect::<Vec<_>>()
        .join(", ");
    let conditions = format!(
        "reading `{}`; tier `{}`, {} particles, mean of seeds {seeds}",
        j.reading.name,
        res.tier,
        res.particles.map_or("?".into(), |n| format!("{n:.0}"))
    );
    let plot = |f: &SeedFields, title: String, value: &str, peak: bool| ContourPlot {
        title,
        subtitle: conditions.clone(),
        x_label: "eps (J) (log scale)".into(),
        y_label: "kappa (N/m) (log scale)".into(),
        x_log: true,
        y_log: true,
        field: f.mean.clone(),
        value_label: value.into(),
        levels: 6,
        highlight: None,
        extra_points: Vec::new(),
        samples: None,
        region: None,
        curves: Vec::new(),
        bulk_colours: false,
        markers: markers(peak),
    };
    contour_plot(
        &out.join(format!("{}_R", j.reading.name)),
        &plot(
            &j.length_ratio,
            format!("R = La/Lr (Fig. 9): {}", j.fig9.verdict.word()),
            &format!("R ({})", j.reading.length_ratio.name()),
            true,
        ),
    )?;
    Ok(contour_plot(
        &out.join(format!("{}_va", j.reading.name)),
        &plot(
            &j.front_velocity,
            format!("va/v0 (Fig. 10): {}", j.fig10.verdict.word()),
            &format!("va/v0 ({})", j.reading.front_velocity.name()),
            false,
        ),
    )?)
}

fn opt(x: Option<f64>) -> String {
    x.map_or("n/a".into(), fmt_num)
}

fn markdown(res: &FidelityResult) -> String {
    let mut s = String::new();
    let readings: Vec<_> = res.readings.iter().map(|j| j.reading.clone()).collect();
    let _ = writeln!(
        s,
        "# Readings study: Figs. 9 and 10 under each reading of the paper\n"
    );
    let _ = writeln!(
        s,
        "Generated by `hvi-study fidelity --config {}` (never edited by hand). The calibration \
         grid (`{}`, tier `{}`, {} particles) at seeds {:?} (a reading may name its own), under each reading; every map is \
         judged on the seed mean by the checks of the reproduction's Figs. 9 and 10 \
         (docs/reproduction.md#verdict-rules). {} runs simulated by this invocation, {} in all; \
         wall time {}.\n",
        res.config.path.display(),
        res.config.study.display(),
        res.tier,
        res.particles.map_or("?".into(), |n| format!("{n:.0}")),
        res.seeds,
        res.ran,
        res.readings
            .iter()
            .filter(|j| matches!(j.reading.source, crate::config::Source::Runs { .. }))
            .map(|j| j.runs)
            .sum::<usize>(),
        hvi_reproduce::report::fmt_duration(res.wall_seconds)
    );
    if !res.config.description.is_empty() {
        let _ = writeln!(s, "{}\n", res.config.description.trim());
    }
    summary_table(&mut s, res, &readings);
    checks_table(&mut s, res);
    for j in &res.readings {
        reading_section(&mut s, j, &readings);
    }
    s
}

fn summary_table(s: &mut String, res: &FidelityResult, readings: &[crate::config::Reading]) {
    let _ = writeln!(s, "## Side by side\n");
    let _ = writeln!(
        s,
        "| reading | what | seeds | Fig. 9 | Fig. 10 | main checks held | checks held | R apart from the peak: mean, (max - min) / mean | R peak (where) | R at the paper's fit | κ rows where va/v0 falls | seed spread R / va/v0 |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    let n_main = FIG9_MAIN_CHECKS + FIG10_MAIN_CHECKS;
    for j in &res.readings {
        let r = row(j, &res.readings);
        let _ = writeln!(
            s,
            "| [`{name}`](#{name}) | {label} | {seeds} | {v9} | {v10} | {main} of {n_main} | {held} of {all} | {pm}, {ps} | {peak} {at} | {fit} | {rows} | {sr} / {sv} |",
            name = j.reading.name,
            label = cell(&j.reading.label),
            seeds = r.seeds,
            v9 = j.fig9.verdict.word(),
            v10 = j.fig10.verdict.word(),
            main = r.main_checks_held,
            held = r.checks_held,
            all = r.checks,
            pm = opt(r.r_plateau_mean),
            ps = opt(r.r_plateau_relative_spread),
            peak = opt(r.r_peak),
            at = text(&j.fig9, "where the peak is"),
            fit = opt(r.r_at_paper_fit),
            rows = r.va_rows_falling,
            sr = opt(r.r_seed_spread),
            sv = opt(r.va_seed_spread),
        );
    }
    let _ = writeln!(
        s,
        "\nSeed spread: the mean over grid points of max - min across the seeds (n/a with one \
         seed); a difference between readings smaller than it is noise.\n"
    );
    if let Some(b) = res.closest() {
        let (main, held) = b.score();
        let _ = writeln!(
            s,
            "**Closest to the paper:** `{}` ({}; {main} of {n_main} main-claim checks, {held} of {} checks). \
             Ranked by main-claim checks held, then all checks held; a tie keeps the earlier reading.\n",
            b.reading.name,
            b.reading.source_text(readings),
            b.checks().len()
        );
    }
    let none = unreproduced(res);
    let _ = writeln!(s, "**Claims no reading reproduces:**");
    if none.is_empty() {
        let _ = writeln!(s, " none.\n");
    } else {
        let _ = writeln!(s);
        for c in none {
            let _ = writeln!(s, "- {c}");
        }
        let _ = writeln!(s);
    }
}

fn checks_table(s: &mut String, res: &FidelityResult) {
    let _ = writeln!(s, "## Every check, every reading\n");
    let mut head = "| check |".to_string();
    let mut rule = "|---|".to_string();
    for j in &res.readings {
        let _ = write!(head, " `{}` |", j.reading.name);
        rule.push_str("---|");
    }
    let _ = writeln!(s, "{head}\n{rule}");
    for (i, (name, main)) in check_names().into_iter().enumerate() {
        let _ = write!(s, "| {name}{} |", if main { " (main)" } else { "" });
        for j in &res.readings {
            let _ = write!(s, " {} |", if j.checks()[i].held { "yes" } else { "no" });
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(s);
}

fn reading_section(s: &mut String, j: &Judged, readings: &[crate::config::Reading]) {
    let name = &j.reading.name;
    let _ = writeln!(
        s,
        "<a id=\"{name}\"></a>\n\n## `{name}`: {}\n",
        j.reading.label
    );
    let _ = writeln!(
        s,
        "Source: {}. Runs: {} (grid points x seeds {:?}) in `{}`.\n",
        j.reading.source_text(readings),
        j.runs,
        j.seeds,
        j.runs_dir.display()
    );
    let _ = writeln!(s, "![R map]({name}_R.png) ![va/v0 map]({name}_va.png)\n");
    let seeds = j
        .per_seed
        .iter()
        .map(|(seed, a, b)| format!("seed {seed}: Fig. 9 {}, Fig. 10 {}", a.word(), b.word()))
        .collect::<Vec<_>>()
        .join("; ");
    let agree = j
        .per_seed
        .iter()
        .all(|(_, a, b)| *a == j.fig9.verdict && *b == j.fig10.verdict);
    let _ = writeln!(
        s,
        "Each seed alone: {seeds} ({}).\n",
        if agree {
            "every seed agrees with the mean"
        } else {
            "the seeds disagree: the verdict is within the noise"
        }
    );
    for f in [&j.fig9, &j.fig10] {
        let _ = writeln!(s, "**Fig. {}: {}.** {}\n", f.id, f.verdict.word(), f.reason);
        numbers_table(s, &f.numbers);
    }
}
