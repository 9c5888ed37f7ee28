//! The registry of scene keys: every key a scene file or `--set` accepts, with what it means,
//! its allowed values and its default. It is the one definition behind `hvi-study keys`, the
//! keys table of docs/running.md (generated from it; a test compares), the did-you-mean of an
//! unknown key, and the interval checks of the scene's validation ([`check`]), so the ranges
//! an error names are the ranges the docs print.

use crate::error::{check_range, EngineError, Result};
use crate::step::MAX_STRIDE_DISPLACEMENT_OVER_SIGMA;

/// What values a key allows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Allowed {
    /// A finite number in an interval (checked by [`check`]).
    Interval {
        /// Lower bound.
        lo: f64,
        /// Whether the lower bound is excluded.
        lo_open: bool,
        /// Upper bound (infinity: unbounded).
        hi: f64,
        /// Whether the upper bound is excluded.
        hi_open: bool,
    },
    /// Anything else, described in words (choices, booleans, lists, ranges that depend on
    /// other keys); checked where the scene is built.
    Text(&'static str),
}

impl Allowed {
    /// The allowed values in words: `(0, 1e5]`, `a number > 0`, or the text.
    pub fn describe(&self) -> String {
        match *self {
            Allowed::Interval {
                lo,
                lo_open,
                hi,
                hi_open,
            } => crate::error::describe_interval(lo, lo_open, hi, hi_open),
            Allowed::Text(t) => t.to_string(),
        }
    }
}

/// One scene key.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Key {
    /// `section.name`.
    pub name: &'static str,
    /// One line of meaning (Markdown).
    pub meaning: &'static str,
    /// Its allowed values.
    pub allowed: Allowed,
    /// Its default, in words (Markdown).
    pub default: &'static str,
}

impl Key {
    /// The unit, from the name's suffix (`_m_s` m/s, `_kg_m3` kg/m^3, `_n_m` N/m, `_pa` Pa,
    /// `_j` J, `_s` s, `_m` m); `-` for a ratio, a count or a choice.
    pub fn unit(&self) -> &'static str {
        let field = self.name.rsplit('.').next().unwrap_or(self.name);
        for (suffix, unit) in [
            ("_m_s", "m/s"),
            ("_kg_m3", "kg/m^3"),
            ("_n_m", "N/m"),
            ("_pa", "Pa"),
            ("_j", "J"),
            ("_s", "s"),
            ("_m", "m"),
        ] {
            if field.ends_with(suffix) {
                return unit;
            }
        }
        "-"
    }
}

const fn interval(lo: f64, lo_open: bool, hi: f64, hi_open: bool) -> Allowed {
    Allowed::Interval {
        lo,
        lo_open,
        hi,
        hi_open,
    }
}

/// A number > 0.
const POSITIVE: Allowed = interval(0.0, true, f64::INFINITY, true);

/// The sections of a scene, in the order of docs/running.md: each key is `section.name`.
pub const SECTIONS: [&str; 6] = [
    "scene",
    "resolution",
    "material",
    "impactor",
    "run",
    "analysis",
];

/// Every scene key, section by section, in the order of docs/running.md.
pub const KEYS: &[Key] = &[
    Key {
        name: "scene.kind",
        meaning: "the geometry",
        allowed: Allowed::Text("`sphere_on_plate` or `flyer_plate`"),
        default: "(required)",
    },
    Key {
        name: "scene.diameter_m",
        meaning: "sphere diameter D",
        allowed: POSITIVE,
        default: "(required for `sphere_on_plate`)",
    },
    Key {
        name: "scene.t_over_d",
        meaning: "plate thickness over D",
        allowed: POSITIVE,
        default: "(required for `sphere_on_plate`)",
    },
    Key {
        name: "scene.width_over_d",
        meaning: "plate side over D",
        allowed: interval(1.0, false, 1e3, false),
        default: "3",
    },
    Key {
        name: "scene.v0_m_s",
        meaning: "impact velocity (a value below 100 m/s draws a warning: km/s typed as m/s?)",
        allowed: interval(0.0, true, 1e5, false),
        default: "(required)",
    },
    Key {
        name: "scene.density_kg_m3",
        meaning: "density of the plate, and of the impactor unless `impactor.density_kg_m3`",
        allowed: POSITIVE,
        default: "2700",
    },
    Key {
        name: "scene.standoff_m",
        meaning: "extra gap at t = 0 (first contact at `standoff / v0`)",
        allowed: Allowed::Text("a finite number"),
        default: "0",
    },
    Key {
        name: "scene.flyer_thickness_m",
        meaning: "flyer-plate geometry: the flyer's thickness",
        allowed: POSITIVE,
        default: "(required for `flyer_plate`)",
    },
    Key {
        name: "scene.target_thickness_m",
        meaning: "flyer-plate geometry: the target's thickness",
        allowed: POSITIVE,
        default: "(required for `flyer_plate`)",
    },
    Key {
        name: "scene.width_m",
        meaning: "flyer-plate geometry: the plates' side",
        allowed: POSITIVE,
        default: "(required for `flyer_plate`)",
    },
    Key {
        name: "resolution.particles",
        meaning: "target total particle count",
        allowed: interval(8.0, false, 5e8, false),
        default: "one of the two",
    },
    Key {
        name: "resolution.particles_across_d",
        meaning: "lattice sites across D (sphere on plate only), instead of `particles`",
        allowed: interval(2.0, false, 2000.0, false),
        default: "one of the two",
    },
    Key {
        name: "material.contact",
        meaning: "the contact law: `printed` (eq. 3 as printed, prefactor eps) or `wca` (4 eps)",
        allowed: Allowed::Text("`printed` or `wca`"),
        default: "`printed`",
    },
    Key {
        name: "material.eps_j",
        meaning: "eps at the reference sigma (the paper's fit: 0.01)",
        allowed: POSITIVE,
        default: "required, unless gamma and lambda are given",
    },
    Key {
        name: "material.kappa_n_m",
        meaning: "kappa at the reference sigma (the paper's fit: 4.56e6)",
        allowed: POSITIVE,
        default: "required, unless gamma and lambda are given",
    },
    Key {
        name: "material.gamma_pa",
        meaning: "or the size-invariant gamma = eps/sigma^3 (not mixed with eps, kappa)",
        allowed: POSITIVE,
        default: "",
    },
    Key {
        name: "material.lambda_pa",
        meaning: "or the size-invariant lambda = kappa/sigma (not mixed with eps, kappa)",
        allowed: POSITIVE,
        default: "",
    },
    Key {
        name: "material.rcut_over_sigma",
        meaning: "bond break distance / sigma",
        allowed: Allowed::Text("(2^(1/6), 10]"),
        default: "1.5",
    },
    Key {
        name: "material.sizing",
        meaning: "geometric sizing on/off (off only to show Fig. 4's failure)",
        allowed: Allowed::Text("`true` or `false`"),
        default: "true",
    },
    Key {
        name: "material.sizing_rule",
        meaning: "how eps scales with sigma under sizing: `eq12` (eps ~ sigma^3) or `eqs5_6` \
                  (eps ~ sigma, as eqs. 5/6 print it; kept for the readings study, \
                  [fidelity.md](fidelity.md)); kappa ~ sigma in both, and with `eqs5_6` give \
                  eps and kappa, not gamma and lambda",
        allowed: Allowed::Text("`eq12` or `eqs5_6`"),
        default: "`eq12`",
    },
    Key {
        name: "impactor.density_kg_m3",
        meaning: "the impactor's density where it differs from the plate's \
                  (`scene.density_kg_m3`), e.g. 7850 for a steel sphere",
        allowed: POSITIVE,
        default: "the plate's",
    },
    Key {
        name: "impactor.eps_j",
        meaning: "the impactor's eps at the reference sigma; the contact between the bodies \
                  takes sqrt(eps_impactor eps_plate)",
        allowed: POSITIVE,
        default: "the plate's",
    },
    Key {
        name: "impactor.kappa_n_m",
        meaning: "the impactor's kappa at the reference sigma",
        allowed: POSITIVE,
        default: "the plate's",
    },
    Key {
        name: "impactor.gamma_pa",
        meaning: "or the impactor's gamma = eps/sigma^3 (not with `impactor.eps_j`)",
        allowed: POSITIVE,
        default: "the plate's",
    },
    Key {
        name: "impactor.lambda_pa",
        meaning: "or the impactor's lambda = kappa/sigma (not with `impactor.kappa_n_m`)",
        allowed: POSITIVE,
        default: "the plate's",
    },
    Key {
        name: "impactor.rcut_over_sigma",
        meaning: "the impactor's bond break distance / sigma",
        allowed: Allowed::Text("(2^(1/6), 10]"),
        default: "the plate's",
    },
    Key {
        name: "run.end_time_s",
        meaning: "simulated time after first contact (too short for the sphere to get through \
                  the plate draws a warning: no cloud forms)",
        allowed: POSITIVE,
        default: "32e-6",
    },
    Key {
        name: "run.dt_s",
        meaning: "the base step, or `auto`",
        allowed: Allowed::Text("`auto` or a number > 0"),
        default: "`auto`",
    },
    Key {
        name: "run.dt_factor",
        meaning: "multiplier of the paper's step (1 = the paper's 1e-10 s at sigma_ref) for \
                  the base step, the step of the impact; capped at half the stability bound",
        allowed: interval(0.0, true, 1e3, false),
        default: "6",
    },
    Key {
        name: "run.max_stride",
        meaning: "adaptive step: the largest multiple of the base step a step may take (1 = a \
                  fixed step); the criterion is in \
                  [model-decisions.md](model-decisions.md#adaptive-step)",
        allowed: Allowed::Text("a whole number from 1 to 64"),
        default: "16",
    },
    Key {
        name: "run.stride_displacement_over_sigma",
        meaning: "adaptive step: listed pairs close in by at most this fraction of sigma per \
                  step (0.05 is the stability bound's; above it this is an accuracy knob, the \
                  stiffness bound still holds)",
        allowed: interval(0.0, true, MAX_STRIDE_DISPLACEMENT_OVER_SIGMA, false),
        default: "0.05",
    },
    Key {
        name: "run.dt_over_bound",
        meaning: "stress tests only: the step as this multiple of the stability bound; \
                  replaces `dt_s` and `dt_factor` (the stability map's step axis)",
        allowed: interval(0.0, true, 8.0, false),
        default: "unset",
    },
    Key {
        name: "run.seed",
        meaning: "seed of the thermal velocities",
        allowed: Allowed::Text("a whole number >= 0"),
        default: "1",
    },
    Key {
        name: "run.thermal_ratio",
        meaning: "thermal velocity s.d. per component / v0",
        allowed: interval(0.0, false, 0.1, false),
        default: "1e-3",
    },
    Key {
        name: "run.skin_over_sigma",
        meaning: "neighbour-list skin / sigma (the default is the largest whose list radius \
                  stays below the lattice's second neighbours at sqrt 2 r_eq)",
        allowed: interval(0.0, true, 2.0, false),
        default: "0.45",
    },
    Key {
        name: "run.frame_block_over_sigma",
        meaning: "side of the blocks whose mean velocity is the frame of the neighbour-list \
                  rebuild rule, / sigma; 0 = classic rule (rebuild when any particle moved half \
                  the skin); exact for any value",
        allowed: Allowed::Text("0 or a number in [2, 1000]"),
        default: "8",
    },
    Key {
        name: "run.energy_every",
        meaning: "base steps between energy-ledger samples (an adaptive step lands on each)",
        allowed: Allowed::Text("a whole number >= 1"),
        default: "200",
    },
    Key {
        name: "run.max_energy_drift",
        meaning: "blow-up guard on the ledger (relative drift)",
        allowed: POSITIVE,
        default: "0.05",
    },
    Key {
        name: "run.min_distance_over_sigma",
        meaning: "blow-up guard on pair distance",
        allowed: interval(0.0, false, 1.0, true),
        default: "0.35",
    },
    Key {
        name: "run.ballistic_cutoff",
        meaning: "free flight once the debris stops interacting: fragments move rigidly with \
                  their centre-of-mass velocity (experimental: on the default scene the gate \
                  never opens within 32 us)",
        allowed: Allowed::Text("`true` or `false`"),
        default: "false",
    },
    Key {
        name: "run.cutoff_min_tau_s",
        meaning: "the cut-off's gate: not before this time",
        allowed: interval(0.0, false, f64::INFINITY, true),
        default: "8e-6",
    },
    Key {
        name: "run.cutoff_quiet_s",
        meaning: "the gate: the window over which the broken-bond count must stay quiet",
        allowed: POSITIVE,
        default: "2e-6",
    },
    Key {
        name: "run.cutoff_break_fraction",
        meaning: "the gate: the most the broken-bond count may grow over the quiet window, as \
                  a fraction (and no two fragments touch or close in)",
        allowed: interval(0.0, false, 1.0, false),
        default: "1e-3",
    },
    Key {
        name: "run.free_flight_after_s",
        meaning: "free flight from this time after first contact on, whatever the cut-off's \
                  gate: the fragments as they are then move rigidly with their \
                  centre-of-mass velocities to the end (its cost in accuracy: \
                  docs/model-decisions.md)",
        allowed: Allowed::Text("a number > 0 and below run.end_time_s, or unset"),
        default: "unset",
    },
    Key {
        name: "run.screen_after_s",
        meaning: "the screen: at the first energy sample at or after this time after first \
                  contact the run measures, on a copy, what free flight from then would give \
                  at the analysis time; outside a window below it goes on in free flight \
                  (skips the rest of the physics); `hvi-study calibrate` sets it \
                  (docs/calibration.md, \"The screen\")",
        allowed: Allowed::Text("a number > 0 and below run.end_time_s, with a window; or unset"),
        default: "unset",
    },
    Key {
        name: "run.screen_length_ratio",
        meaning: "the screen's window on the length ratio (the scene's reading)",
        allowed: Allowed::Text("[low, high], finite, low < high; or unset"),
        default: "unset",
    },
    Key {
        name: "run.screen_front_velocity_ratio",
        meaning: "the screen's window on va / v0",
        allowed: Allowed::Text("[low, high], finite, low < high; or unset"),
        default: "unset",
    },
    Key {
        name: "run.absorbing_band_over_d",
        meaning: "width over D of a band inside the plate's lateral edge that damps outgoing \
                  stress waves (a sponge layer; sphere on plate only, less than half the \
                  plate's side; its energy is booked in the ledger as `absorbed_j`)",
        allowed: interval(0.0, false, 10.0, false),
        default: "0 (no band)",
    },
    Key {
        name: "run.symmetry",
        meaning: "`quarter` simulates the quarter x > 0, y > 0 of a normal impact on a square \
                  plate with mirror images across both planes (a quarter of the particles; \
                  the plate's side rounds to an even number of lattice sites); outputs and \
                  measurements are of the full scene (its error against the full scene: \
                  [model decisions](model-decisions.md#quarter-symmetry))",
        allowed: Allowed::Text("`full` or `quarter`"),
        default: "full",
    },
    Key {
        name: "analysis.cloud",
        meaning: "measure the cloud at the end of the run (fragments, F, La, Lr, R, va, sizes)",
        allowed: Allowed::Text("`true` or `false`"),
        default: "true",
    },
    Key {
        name: "analysis.quantile",
        meaning: "quantile of the cloud particles' z and of their width (`analysis.width`) that \
                  defines the front and the width (why 0.9: [model \
                  decisions](model-decisions.md#the-readings-of-the-paper-behind-figs-9-and-10))",
        allowed: interval(0.5, false, 1.0, false),
        default: "0.9",
    },
    Key {
        name: "analysis.width",
        meaning: "how the cloud's width Lr (and R = La / Lr) is read: `side`, as a side-view \
                  shadowgraph records it (the quantile of |x| and |y|), or `cylindrical`, the \
                  quantile of the distance from the axis; both are reported, this one is \
                  `length_ratio` (why side: [model \
                  decisions](model-decisions.md#the-width-of-the-cloud-cylindrical-or-side-on))",
        allowed: Allowed::Text("`side` or `cylindrical`"),
        default: "side",
    },
    Key {
        name: "analysis.front_times_s",
        meaning: "the two times since first contact at which the front is located for va",
        allowed: Allowed::Text("`[t1, t2]` with 0 <= t1 < t2 <= `run.end_time_s`"),
        default: "(28, 32) us; (7/8 T, T) for a run ending at T < 32 us",
    },
    Key {
        name: "analysis.track_every",
        meaning: "base steps between samples of `cloud_track.csv` (each costs one fragment \
                  labelling, about one step); 0 = no track",
        allowed: Allowed::Text("a whole number >= 0"),
        default: "100",
    },
    Key {
        name: "analysis.render_times_s",
        meaning: "times of the `--render` series (the adaptive step lands on each, rendered or \
                  not); those beyond the run are skipped",
        allowed: Allowed::Text("a list of numbers"),
        default: "[0, 9.1e-6, 16.1e-6, 32e-6]",
    },
    Key {
        name: "analysis.shadowgraph_pixel_m",
        meaning: "pixel size of the synthetic shadowgraph",
        allowed: interval(0.0, true, 0.01, false),
        default: "5e-4",
    },
    Key {
        name: "analysis.shadowgraph_blur_m",
        meaning: "its Gaussian blur (standard deviation)",
        allowed: interval(0.0, false, 0.05, false),
        default: "2e-3",
    },
    Key {
        name: "analysis.shadowgraph_grain_m",
        meaning: "grain diameter of the debris its optical depth refers to",
        allowed: interval(0.0, true, 0.01, false),
        default: "1e-5",
    },
    Key {
        name: "analysis.shadowgraph_optical_depth",
        meaning: "optical depth at which a shadowgraph pixel is dark",
        allowed: interval(0.0, true, 100.0, false),
        default: "1 (transmission 1/e)",
    },
    Key {
        name: "analysis.witness_standoff_m",
        meaning: "distance of the synthetic witness plate behind the target's rear face",
        allowed: interval(0.0, true, 10.0, false),
        default: "0.1",
    },
    Key {
        name: "analysis.keep_state",
        meaning: "write `state.bin`, so the cloud can be measured again with other settings \
                  (`hvi-study reanalyse`)",
        allowed: Allowed::Text("`true` or `false`"),
        default: "true",
    },
];

/// The key named `name` (`section.name`).
pub fn find(name: &str) -> Option<&'static Key> {
    KEYS.iter().find(|k| k.name == name)
}

/// Checks `value` against the registry's interval for `name`, naming the key and the allowed
/// range on failure.
pub fn check(name: &str, value: f64) -> Result<f64> {
    match find(name).map(|k| k.allowed) {
        Some(Allowed::Interval {
            lo,
            lo_open,
            hi,
            hi_open,
        }) => check_range(name, value, lo, lo_open, hi, hi_open),
        _ => Err(EngineError::invalid(
            name,
            value,
            "a key with an interval in the key registry (an internal error: please report it)",
        )),
    }
}

/// The keys table as Markdown: key, unit, allowed values, default, meaning.
pub fn markdown() -> String {
    markdown_of(KEYS.iter())
}

/// The table of `keys` as Markdown, in the columns of [`markdown`].
pub fn markdown_of<'a>(keys: impl IntoIterator<Item = &'a Key>) -> String {
    let mut s =
        String::from("| key | unit | allowed | default | meaning |\n|---|---|---|---|---|\n");
    for k in keys {
        s.push_str(&format!(
            "| `{}` | {} | {} | {} | {} |\n",
            k.name,
            k.unit(),
            k.allowed.describe(),
            k.default,
            k.meaning
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::step::MAX_STRIDE;

    #[test]
    fn names_are_unique_and_sectioned() {
        for (i, k) in KEYS.iter().enumerate() {
            assert!(
                KEYS[..i].iter().all(|o| o.name != k.name),
                "{} twice",
                k.name
            );
            let section = k.name.split('.').next().expect("section");
            assert!(SECTIONS.contains(&section), "{}", k.name);
        }
    }

    #[test]
    fn intervals_check_their_bounds() {
        assert!(check("scene.v0_m_s", 1e5).is_ok());
        assert!(check("scene.v0_m_s", 0.0).is_err());
        assert!(check("scene.v0_m_s", 1.00001e5).is_err());
        assert!(check("analysis.quantile", 0.5).is_ok());
        assert!(check("run.min_distance_over_sigma", 1.0).is_err());
        assert!(check("scene.kind", 1.0).is_err(), "not an interval key");
        assert_eq!(find("scene.v0_m_s").expect("key").unit(), "m/s");
        assert_eq!(find("material.kappa_n_m").expect("key").unit(), "N/m");
        assert_eq!(find("run.thermal_ratio").expect("key").unit(), "-");
        assert_eq!(
            find("scene.v0_m_s").expect("key").allowed.describe(),
            "(0, 1e5]"
        );
        assert_eq!(
            find("scene.diameter_m").expect("key").allowed.describe(),
            "a number > 0"
        );
        // Texts that name a constant of the engine say its value.
        let stride = find("run.max_stride").expect("key").allowed.describe();
        assert!(stride.ends_with(&format!("to {MAX_STRIDE}")), "{stride}");
    }
}
