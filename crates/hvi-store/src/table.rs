//! The results table of a study: one row per run with its parameters, status, observables
//! and scores, written as `results.csv` and `results.json` (an array of objects whose keys
//! are the CSV's columns, in the same order).

use std::path::Path;

use hvi_run::error::Result;
use serde_json::Value;

use crate::plan::Plan;
use crate::spec::Axis;
use crate::store::{Record, RunStatus};
use hvi_analysis::observable::{Observable, Observables};
use hvi_run::files::write_atomic_with;

/// A table: named columns, rows of JSON values (null where there is nothing).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    /// Column names.
    pub columns: Vec<String>,
    /// Rows, each as long as `columns`.
    pub rows: Vec<Vec<Value>>,
}

impl Table {
    /// The column's index.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }

    /// Adds a column with one value per row.
    pub fn push_column(&mut self, name: &str, values: Vec<Value>) {
        debug_assert_eq!(values.len(), self.rows.len());
        self.columns.push(name.to_string());
        for (row, v) in self.rows.iter_mut().zip(values) {
            row.push(v);
        }
    }

    /// Writes `<stem>.csv` and `<stem>.json` into `dir`, atomically.
    pub fn write(&self, dir: &Path, stem: &str) -> Result<()> {
        write_atomic_with(&dir.join(format!("{stem}.csv")), |w| {
            let mut csv = csv::Writer::from_writer(w);
            csv.write_record(&self.columns)?;
            for row in &self.rows {
                csv.write_record(row.iter().map(cell))?;
            }
            csv.flush()?;
            Ok(())
        })?;
        write_atomic_with(&dir.join(format!("{stem}.json")), |w| {
            writeln!(w, "[")?;
            for (i, row) in self.rows.iter().enumerate() {
                let fields: Vec<String> = self
                    .columns
                    .iter()
                    .zip(row)
                    .map(|(c, v)| format!("{}: {}", Value::String(c.clone()), v))
                    .collect();
                let sep = if i + 1 < self.rows.len() { "," } else { "" };
                writeln!(w, "  {{{}}}{sep}", fields.join(", "))?;
            }
            writeln!(w, "]")?;
            Ok(())
        })
    }
}

/// A JSON value as a CSV cell: numbers and strings as they are, null as empty.
fn cell(v: &Value) -> String {
    match v {
        Value::Null => String::new(),
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// A number as a JSON value: null when absent or not finite.
pub fn num(x: Option<f64>) -> Value {
    x.filter(|v| v.is_finite())
        .map_or(Value::Null, |v| serde_json::json!(v))
}

/// An observable's value as a JSON value: a count or a yes/no as a whole number (so that
/// `1838`, not `1838.0`, reaches a CSV reader and pandas reads an integer column), any other
/// as [`num`].
pub fn observable_cell(o: Observable, x: Option<f64>) -> Value {
    match x {
        Some(v) if o.is_whole() && v.fract() == 0.0 && v.abs() < 9.0e15 => {
            serde_json::json!(v as i64)
        }
        _ => num(x),
    }
}

/// The columns of a results table over `axes`: `index`, one per axis, `status`,
/// `fingerprint`, `dir`, one per observable, `wall_seconds`, `measured_from` (the fingerprint
/// of the run whose kept state a run was measured from, empty for a simulated run), `error`.
pub fn result_columns(axes: &[Axis]) -> Vec<String> {
    let mut columns = vec!["index".to_string()];
    columns.extend(axes.iter().map(|a| a.key.clone()));
    columns.extend(["status", "fingerprint", "dir"].map(String::from));
    columns.extend(Observable::names().map(String::from));
    columns.extend(["wall_seconds", "measured_from", "error"].map(String::from));
    columns
}

/// One run's row of a results table ([`result_columns`]).
#[derive(Debug, Clone, Copy)]
pub struct ResultRow<'a> {
    /// Its index in the plan (`None` for a run of the store the plan does not list).
    pub index: Option<usize>,
    /// Its axis values, one per axis.
    pub values: &'a [Value],
    /// `completed`, `failed`, `missing` or another word for how it stands.
    pub status: &'a str,
    /// Its fingerprint.
    pub fingerprint: &'a str,
    /// Its directory, relative to the study directory.
    pub dir: &'a str,
    /// Its observables (`None`: every observable empty).
    pub observables: Option<&'a Observables>,
    /// Its wall time, s.
    pub wall_seconds: Option<f64>,
    /// The fingerprint of the run it was measured from, when it was not simulated.
    pub measured_from: Option<&'a str>,
    /// Its error.
    pub error: Option<&'a str>,
}

impl ResultRow<'_> {
    /// The row's cells, in the order of [`result_columns`].
    pub fn cells(&self) -> Vec<Value> {
        let mut row = vec![self.index.map_or(Value::Null, |i| serde_json::json!(i))];
        row.extend(self.values.iter().cloned());
        row.push(Value::String(self.status.into()));
        row.push(Value::String(self.fingerprint.into()));
        row.push(Value::String(self.dir.into()));
        for o in Observable::ALL {
            row.push(observable_cell(
                o,
                self.observables.and_then(|obs| obs.get(o)),
            ));
        }
        row.push(num(self.wall_seconds));
        row.push(
            self.measured_from
                .map_or(Value::Null, |f| Value::String(f.into())),
        );
        row.push(self.error.map_or(Value::Null, |e| Value::String(e.into())));
        row
    }
}

/// The table of a plan's runs with their records (a missing record gives status `missing`).
pub fn results_table(plan: &Plan, records: &[Option<Record>]) -> Table {
    let rows = plan
        .runs
        .iter()
        .zip(records)
        .map(|(run, rec)| {
            let status = match rec {
                Some(r) if r.status == RunStatus::Completed => "completed",
                Some(_) => "failed",
                None => "missing",
            };
            ResultRow {
                index: Some(run.index),
                values: &run.values,
                status,
                fingerprint: &run.fingerprint,
                dir: &run.dir,
                observables: rec.as_ref().map(|r| &r.observables),
                wall_seconds: rec.as_ref().map(|r| r.wall_seconds),
                measured_from: rec.as_ref().and_then(|r| r.measured_from.as_deref()),
                error: rec.as_ref().and_then(|r| r.error.as_deref()),
            }
            .cells()
        })
        .collect();
    Table {
        columns: result_columns(&plan.axes),
        rows,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_csv_and_json_with_the_same_columns() {
        let mut t = Table {
            columns: vec!["a".into(), "b".into()],
            rows: vec![
                vec![serde_json::json!(1.5), Value::Null],
                vec![serde_json::json!("x,y"), serde_json::json!(2)],
            ],
        };
        t.push_column("c", vec![serde_json::json!(true), Value::Null]);
        let dir = std::env::temp_dir().join(format!("hvi-table-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        t.write(&dir, "results").expect("writes");
        let csv = std::fs::read_to_string(dir.join("results.csv")).expect("csv");
        assert_eq!(csv, "a,b,c\n1.5,,true\n\"x,y\",2,\n");
        let json: Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).expect("json"))
                .expect("valid json");
        assert_eq!(json[1]["a"], "x,y");
        assert_eq!(json[0]["c"], true);
    }
}
