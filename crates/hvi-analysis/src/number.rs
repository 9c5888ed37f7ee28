//! How numbers (and durations) are rounded and printed in tables, plot labels, reports and
//! progress lines.
//!
//! ```
//! use hvi_analysis::number::{fmt_duration, fmt_num, round_sig, short};
//! assert_eq!(round_sig(4.5612e6, 3), 4.56e6);
//! assert_eq!(short(4.56e6), "4.56e6");
//! assert_eq!(fmt_num(0.123456), "0.1235");
//! assert_eq!(fmt_duration(210.0), "3.5 min");
//! ```

/// `x` rounded to `digits` significant digits.
pub fn round_sig(x: f64, digits: i32) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let e = x.abs().log10().floor() as i32;
    let scale = 10f64.powi(digits - 1 - e);
    (x * scale).round() / scale
}

/// A parameter value in its shortest form, to six significant digits: `0.01`, `1`,
/// `4.56e6`, `2.5e5`, `16.1`.
pub fn short(x: f64) -> String {
    let x = round_sig(x, 6);
    let a = x.abs();
    if a != 0.0 && !(1e-2..1e4).contains(&a) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// A number as the report prints it: whole numbers below 1e6 as they are, else four
/// significant digits, in exponent form outside [1e-3, 1e5).
pub fn fmt_num(x: f64) -> String {
    if !x.is_finite() {
        return "n/a".into();
    }
    let a = x.abs();
    if x.fract() == 0.0 && a < 1e6 {
        format!("{x:.0}")
    } else if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{x:.3e}")
    } else if a == 0.0 {
        "0".into()
    } else {
        let digits = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{x:.digits$}")
    }
}

/// A duration for people: `42 s`, `3.5 min`, `7.2 h`, `2.9 days`.
pub fn fmt_duration(s: f64) -> String {
    if !s.is_finite() {
        "n/a".into()
    } else if s < 120.0 {
        format!("{s:.0} s")
    } else if s < 2.0 * 3600.0 {
        format!("{:.1} min", s / 60.0)
    } else if s < 48.0 * 3600.0 {
        format!("{:.1} h", s / 3600.0)
    } else {
        format!("{:.1} days", s / 86400.0)
    }
}
