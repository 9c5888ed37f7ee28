//! The analysis settings (`[analysis]`): which debris-cloud observables a run measures, and
//! when. The observables themselves are defined in `crate::cloud`; their defaults (quantile,
//! front times) live here with the settings that use them.

use serde::{Deserialize, Serialize};

use crate::error::{check_range, EngineError, Result};
use crate::paper;

/// Default quantile of the front and of the radial extent (MODEL.md section 5: "for instance
/// 99.5 %").
pub const DEFAULT_QUANTILE: f64 = 0.995;
/// Default times since first contact at which the front is located for va, s (MODEL.md
/// section 5: "for instance 28 and 32 us", like the experiment's X-ray pair).
pub const DEFAULT_FRONT_TIMES_S: [f64; 2] = [28e-6, 32e-6];

/// What a run measures of the debris cloud, and when. The observables themselves are defined in
/// [`crate::cloud`] (MODEL.md section 5); these keys only choose the quantile, the times and
/// how often. Only what is asked for is computed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Analysis {
    /// Measure the cloud at the end of the run (the analysis time): fragments, N_part, N_frag,
    /// F, La, Lr, R, fragment sizes, and the front velocity va from the two front times.
    pub cloud: bool,
    /// Quantile of the cloud particles' axial and radial positions that defines the front and
    /// the radial extent (so that a few stray particles do not decide La and Lr), in [0.5, 1];
    /// 1 is the plain maximum (always reported as well).
    pub quantile: f64,
    /// The two times since first contact at which the front is located for va, s, with
    /// 0 <= t1 < t2 <= `run.end_time_s`. When not given: the experiment's 28 and 32 us if the
    /// run reaches 32 us, else 7/8 of the end time and the end time
    /// ([`Analysis::front_times_s`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub front_times_s: Option<[f64; 2]>,
    /// Steps between samples of the cloud track (front, La, Lr over time; one fragment
    /// labelling each, about the cost of one step); 0 turns the track off.
    pub track_every: u64,
    /// Times since first contact of the rendered 3-D series (`hvi-study run --render`, Fig. 12),
    /// s; times beyond the end of the run are skipped.
    pub render_times_s: Vec<f64>,
}

impl Default for Analysis {
    fn default() -> Self {
        Analysis {
            cloud: true,
            quantile: DEFAULT_QUANTILE,
            front_times_s: None,
            track_every: 100,
            render_times_s: paper::FIG12_TIMES_S.to_vec(),
        }
    }
}

impl Analysis {
    /// The two front times for va, s since first contact, for a run that ends at `end_time_s`:
    /// the given ones, or the experiment's (28, 32) us when the run reaches 32 us, or else
    /// (7/8 T, T) with T the end time (the same ratio, so a short run still measures a speed).
    pub fn front_times_s(&self, end_time_s: f64) -> [f64; 2] {
        match self.front_times_s {
            Some(t) => t,
            None => {
                let [t1, t2] = DEFAULT_FRONT_TIMES_S;
                if end_time_s >= t2 {
                    [t1, t2]
                } else {
                    [t1 / t2 * end_time_s, end_time_s]
                }
            }
        }
    }

    /// Checks every value against its allowed range, naming the key.
    pub fn validate(&self, end_time_s: f64) -> Result<()> {
        check_range("analysis.quantile", self.quantile, 0.5, false, 1.0, false)?;
        if let Some([t1, t2]) = self.front_times_s {
            let ok = t1.is_finite() && t2.is_finite() && 0.0 <= t1 && t1 < t2 && t2 <= end_time_s;
            if !ok {
                return Err(EngineError::invalid(
                    "analysis.front_times_s",
                    format!("[{t1:e}, {t2:e}]"),
                    format!(
                        "two times since first contact in s with 0 <= t1 < t2 <= run.end_time_s                          = {end_time_s:e}"
                    ),
                ));
            }
        }
        for &t in &self.render_times_s {
            if !(t.is_finite() && t >= 0.0) {
                return Err(EngineError::invalid(
                    "analysis.render_times_s",
                    t,
                    "times since first contact in s, each finite and >= 0",
                ));
            }
        }
        Ok(())
    }
}
