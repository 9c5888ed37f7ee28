//! What the resolution makes of a scene: each plate's particle layers and its thickness as
//! simulated (a whole number of layers times r_eq), sigma, and the warnings when the lattice
//! cannot represent the scene asked for, or when a change of the geometry moved sigma at a
//! fixed particle count. Facts and warnings are data, each warning with a one-sentence message
//! that names the key and the numbers; nothing here prints (the command line does:
//! docs/running.md, "Resolution").
//!
//! ```
//! use hvi_scene::scene::{Geometry, ResolutionIssue, SceneSpec};
//!
//! // The calibration scene at 2000 particles with a plate of t/D = 0.05: one layer.
//! let mut spec = SceneSpec::calibration(2000.0, 1e-7);
//! if let Geometry::SphereOnPlate { t_over_d, .. } = &mut spec.scene {
//!     *t_over_d = 0.05;
//! }
//! let check = spec.build().expect("valid scene").resolution_check();
//! assert_eq!(check.plates[0].layers, 1);
//! let issues: Vec<_> = check.warnings().iter().map(|w| w.issue).collect();
//! assert_eq!(issues, [ResolutionIssue::TooFewLayers, ResolutionIssue::ThicknessOff]);
//! ```

use super::build::Setup;
use super::layout::layer_count;
use super::spec::{Geometry, Resolution, SceneSpec};
use crate::error::Result;
use crate::paper;

/// The fewest particle layers a plate may have without a warning.
///
/// A simple cubic plate of one layer has no bond through its thickness and its front and rear
/// faces are the same particles; in a plate of two, every particle is on a face. Three is the
/// thinnest plate with a layer between the face the sphere strikes and the face that spalls.
pub const MIN_PLATE_LAYERS: u32 = 3;

/// The relative difference between a plate's simulated thickness (layers x r_eq) and the asked
/// one above which the resolution draws a warning.
///
/// A plate is a whole number of layers, so its thickness is off by up to half a layer, which
/// stays within 10 % whatever the thickness asked once the plate is five lattice spacings thick
/// or more (t / r_eq >= 5). 10 % is half the smallest relative step between the validity map's
/// t/D rows (0.5 to 0.6, 20 %); rows that still become one plate are named by
/// [`merged_warnings`].
pub const THICKNESS_TOLERANCE: f64 = 0.10;

/// The relative change of sigma that a change of the geometry at the same resolution may make
/// without a warning.
///
/// At a fixed `resolution.particles` the particles fill the whole scene, so any change of its
/// volume moves sigma (as the cube root of the volume). 2 % of sigma is 6 % of the volume per
/// particle, less than the lattice's own rounding of `resolution.particles` at a few thousand
/// particles (the calibration scene lays out 1838 particles for 2000 asked, 4463 for 5000,
/// 10808 for 10000).
pub const SIGMA_CHANGE_TOLERANCE: f64 = 0.02;

/// One plate of a scene as the lattice lays it out.
#[derive(Debug, Clone, PartialEq)]
pub struct Plate {
    /// The key that asks for its thickness: `scene.t_over_d`, `scene.target_thickness_m` or
    /// `scene.flyer_thickness_m`.
    pub key: &'static str,
    /// What it is, as messages name it: `plate`, `target plate`, `flyer plate`.
    pub name: &'static str,
    /// The key's value as asked: t/D for `scene.t_over_d`, else the thickness in m.
    pub asked: f64,
    /// The same quantity as simulated (layers x r_eq, over D for `scene.t_over_d`).
    pub simulated: f64,
    /// The thickness asked, m.
    pub asked_m: f64,
    /// The thickness simulated, layers x r_eq, m.
    pub simulated_m: f64,
    /// Particle layers through the thickness: the asked thickness over r_eq, rounded (0 for a
    /// plate thinner than half a layer, which [`SceneSpec::build`] refuses).
    pub layers: u32,
}

impl Plate {
    /// The simulated thickness's relative difference from the asked one, (simulated - asked)
    /// / asked: positive when the plate is simulated thicker.
    pub fn relative_error(&self) -> f64 {
        self.simulated_m / self.asked_m - 1.0
    }

    /// Whether the key is a ratio to D (`scene.t_over_d`) rather than a thickness in m.
    fn over_d(&self) -> bool {
        self.key == "scene.t_over_d"
    }

    /// The plate's asked or simulated quantities as messages print them: `t/D 0.0787`,
    /// `t/D 0.0787 and 0.0893`, `1.6 mm`.
    fn shown(&self, values: impl Iterator<Item = f64>) -> String {
        if self.over_d() {
            format!("t/D {}", and_list(&distinct(values, num)))
        } else {
            format!("{} mm", and_list(&distinct(values.map(|v| v * 1e3), num)))
        }
    }
}

/// What the resolution makes of a scene: its lattice spacing and sigma, and each plate's layers.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolutionCheck {
    /// The scene's resolution as given.
    pub resolution: Resolution,
    /// Lattice spacing r_eq, m.
    pub r_eq_m: f64,
    /// Particle diameter sigma, m.
    pub sigma_m: f64,
    /// Sphere diameter D, m (None for a flyer-plate scene).
    pub diameter_m: Option<f64>,
    /// Volume of both bodies, m^3: what `resolution.particles` divides into particles.
    pub volume_m3: f64,
    /// The plates: the sphere's target plate, or the flyer plate's target and flyer.
    pub plates: Vec<Plate>,
}

/// What is wrong with a plate at this resolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ResolutionIssue {
    /// Fewer particle layers than [`MIN_PLATE_LAYERS`].
    TooFewLayers,
    /// The simulated thickness differs from the asked one by more than
    /// [`THICKNESS_TOLERANCE`].
    ThicknessOff,
}

/// A warning about one plate of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolutionWarning {
    /// What is wrong.
    pub issue: ResolutionIssue,
    /// The plate, as laid out.
    pub plate: Plate,
    /// Lattice spacing r_eq, m.
    pub r_eq_m: f64,
    /// What cures it: each resolution key the scene may set (its own first) with the least
    /// value that does, e.g. (`resolution.particles`, 1.22e5).
    pub remedy: Vec<(&'static str, f64)>,
    /// The warning in one sentence, naming the key and the numbers.
    pub message: String,
}

/// A warning that concerns some of several scenes (the runs of a plan): each distinct warning
/// once, with the scenes it concerns.
#[derive(Debug, Clone, PartialEq)]
pub struct MergedWarning {
    /// The warning in one sentence, naming the key and the numbers.
    pub message: String,
    /// The scenes it concerns: indices into the checks given, ascending.
    pub scenes: Vec<usize>,
}

/// A geometry key whose value differs between two scenes.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyChange {
    /// The key, e.g. `scene.width_over_d`.
    pub key: &'static str,
    /// Its value in the first scene.
    pub before: String,
    /// Its value in the second.
    pub after: String,
}

/// Sigma moved by a change of the geometry at the same resolution ([`sigma_change`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SigmaChange {
    /// The geometry keys that moved it, in the order of the scene's keys.
    pub keys: Vec<KeyChange>,
    /// Sigma of the first scene, m.
    pub sigma_before_m: f64,
    /// Sigma of the second, m.
    pub sigma_after_m: f64,
    /// The resolution key both scenes give: `resolution.particles` or
    /// `resolution.particles_across_d`.
    pub resolution_key: &'static str,
    /// Its value.
    pub resolution_value: f64,
    /// The value of that key that keeps the second scene at the first one's sigma.
    pub keeping_value: f64,
    /// The warning in one sentence, naming the keys and both sigmas in mm.
    pub message: String,
}

impl Setup {
    /// What the resolution makes of this scene: the plates' layers, their simulated
    /// thickness, sigma; [`ResolutionCheck::warnings`] says what is wrong with them.
    pub fn resolution_check(&self) -> ResolutionCheck {
        ResolutionCheck::new(&self.spec.scene, &self.spec.resolution, self.derived.r_eq_m)
    }
}

impl SceneSpec {
    /// [`Setup::resolution_check`] without laying out the lattice: the same numbers from the
    /// geometry and the resolution alone, which it checks (the other keys are not checked).
    pub fn resolution_check(&self) -> Result<ResolutionCheck> {
        let r_eq = lattice_spacing_m(self)?;
        Ok(ResolutionCheck::new(&self.scene, &self.resolution, r_eq))
    }
}

/// The geometry checked and its lattice spacing r_eq at the scene's resolution, m.
fn lattice_spacing_m(spec: &SceneSpec) -> Result<f64> {
    spec.scene.validate()?;
    spec.resolution.lattice_spacing_m(&spec.scene)
}

impl ResolutionCheck {
    /// The plates of `geometry` at lattice spacing `r_eq_m` (`resolution` says how it was
    /// chosen, for the remedies).
    pub fn new(geometry: &Geometry, resolution: &Resolution, r_eq_m: f64) -> ResolutionCheck {
        let plate = |key, name, asked: f64, asked_m: f64, over: f64| {
            let layers = layer_count(asked_m, r_eq_m).max(0) as u32;
            let simulated_m = f64::from(layers) * r_eq_m;
            Plate {
                key,
                name,
                asked,
                simulated: simulated_m / over,
                asked_m,
                simulated_m,
                layers,
            }
        };
        let (diameter_m, plates) = match *geometry {
            Geometry::SphereOnPlate {
                diameter_m,
                t_over_d,
                ..
            } => (
                Some(diameter_m),
                vec![plate(
                    "scene.t_over_d",
                    "plate",
                    t_over_d,
                    t_over_d * diameter_m,
                    diameter_m,
                )],
            ),
            Geometry::FlyerPlate {
                flyer_thickness_m,
                target_thickness_m,
                ..
            } => (
                None,
                vec![
                    plate(
                        "scene.target_thickness_m",
                        "target plate",
                        target_thickness_m,
                        target_thickness_m,
                        1.0,
                    ),
                    plate(
                        "scene.flyer_thickness_m",
                        "flyer plate",
                        flyer_thickness_m,
                        flyer_thickness_m,
                        1.0,
                    ),
                ],
            ),
        };
        ResolutionCheck {
            resolution: resolution.clone(),
            r_eq_m,
            sigma_m: r_eq_m / paper::r_eq_over_sigma(),
            diameter_m,
            volume_m3: geometry.volume_m3(),
            plates,
        }
    }

    /// What is wrong with the plates at this resolution, each plate's fewest layers first,
    /// then its thickness.
    pub fn warnings(&self) -> Vec<ResolutionWarning> {
        let mut out = Vec::new();
        for p in &self.plates {
            if p.layers < MIN_PLATE_LAYERS {
                let remedy = self.remedy(p, f64::from(MIN_PLATE_LAYERS) - 0.5);
                out.push(self.warning(ResolutionIssue::TooFewLayers, p, remedy));
            }
        }
        for p in &self.plates {
            if p.relative_error().abs() > THICKNESS_TOLERANCE {
                let remedy = self.remedy(p, 0.5 / THICKNESS_TOLERANCE);
                out.push(self.warning(ResolutionIssue::ThicknessOff, p, remedy));
            }
        }
        out
    }

    fn warning(
        &self,
        issue: ResolutionIssue,
        plate: &Plate,
        remedy: Vec<(&'static str, f64)>,
    ) -> ResolutionWarning {
        let mut w = ResolutionWarning {
            issue,
            plate: plate.clone(),
            r_eq_m: self.r_eq_m,
            remedy,
            message: String::new(),
        };
        w.message = match issue {
            ResolutionIssue::TooFewLayers => layers_message(&[&w]),
            ResolutionIssue::ThicknessOff => thickness_message(&w),
        };
        w
    }

    /// The least value of each resolution key the scene may set that puts at least
    /// `per_layer` lattice spacings into the plate's thickness (a plate of t / r_eq >= n -
    /// 1/2 rounds to n layers or more): `resolution.particles` = V (per_layer / t)^3,
    /// `resolution.particles_across_d` = per_layer D / t. The scene's own key comes first.
    fn remedy(&self, plate: &Plate, per_layer: f64) -> Vec<(&'static str, f64)> {
        let r_eq_needed = plate.asked_m / per_layer;
        let particles = (
            "resolution.particles",
            ceil3(self.volume_m3 / r_eq_needed.powi(3)),
        );
        let across = self
            .diameter_m
            .map(|d| ("resolution.particles_across_d", ceil3(d / r_eq_needed)));
        match (self.resolution.particles_across_d.is_some(), across) {
            (true, Some(a)) => vec![a],
            (false, Some(a)) => vec![particles, a],
            (_, None) => vec![particles],
        }
    }
}

/// The sentence of a plate with too few layers, for one scene or for several with the same
/// key and layer count: `scene.t_over_d = 0.05 and 0.1 give the same plate of 1 particle
/// layer (...)`.
fn layers_message(ws: &[&ResolutionWarning]) -> String {
    let p = &ws[0].plate;
    let asked = distinct(ws.iter().map(|w| w.plate.asked), |x| format!("{x}"));
    let r_eq = distinct(ws.iter().map(|w| w.r_eq_m * 1e3), num);
    // One plate when every scene has the same lattice (and so the same simulated plate).
    let one_plate = ws.iter().all(|w| w.r_eq_m == ws[0].r_eq_m);
    let verb = match (asked.len(), one_plate) {
        (1, true) => format!("gives a {}", p.name),
        (1, false) => format!("gives {}s", p.name),
        (_, true) => format!("give the same {}", p.name),
        (_, false) => format!("give {}s", p.name),
    };
    let layers = p.layers;
    format!(
        "{} = {} {verb} of {layers} particle layer{} (r_eq {} mm; simulated {}), fewer than \
         the minimum of {MIN_PLATE_LAYERS}: {} gives {} {MIN_PLATE_LAYERS}",
        p.key,
        and_list(&asked),
        plural(layers),
        and_list(&r_eq),
        p.shown(ws.iter().map(|w| w.plate.simulated)),
        remedy_text(ws.iter().map(|w| &w.remedy)),
        if one_plate { "it" } else { "each" },
    )
}

/// The sentence of a plate simulated thicker or thinner than asked beyond the tolerance.
fn thickness_message(w: &ResolutionWarning) -> String {
    let p = &w.plate;
    let as_what = if p.over_d() {
        format!("as {}: ", p.shown(std::iter::once(p.simulated)))
    } else {
        String::new()
    };
    let e = p.relative_error();
    format!(
        "{} = {} is simulated {as_what}{} mm thick, not {} mm ({} layer{} of r_eq {} mm), \
         {:.0} % {} than asked, beyond the {:.0} % tolerance: {} keeps it within {:.0} %",
        p.key,
        p.asked,
        num(p.simulated_m * 1e3),
        num(p.asked_m * 1e3),
        p.layers,
        plural(p.layers),
        num(w.r_eq_m * 1e3),
        100.0 * e.abs(),
        if e > 0.0 { "thicker" } else { "thinner" },
        100.0 * THICKNESS_TOLERANCE,
        remedy_text(std::iter::once(&w.remedy)),
        100.0 * THICKNESS_TOLERANCE,
    )
}

/// The sentence of distinct asked thicknesses that are one plate at this resolution.
fn same_plate_message(plates: &[(&Plate, f64)]) -> String {
    let (p, r_eq) = plates[0];
    let asked = distinct(plates.iter().map(|(q, _)| q.asked), |x| format!("{x}"));
    format!(
        "{} = {} give the same {} of {} particle layers (r_eq {} mm; simulated {}): their runs \
         differ only in the label; a finer resolution tells them apart",
        p.key,
        and_list(&asked),
        p.name,
        p.layers,
        num(r_eq * 1e3),
        p.shown(std::iter::once(p.simulated)),
    )
}

/// Each distinct warning of several scenes once, with the scenes it concerns: plates with too
/// few layers merged by key and layer count (so that two labels of one plate read as one
/// warning), thicknesses off by their message, then distinct asked thicknesses that are the
/// same plate of enough layers (the same key, layers and r_eq), which no single scene shows.
pub fn merged_warnings(checks: &[ResolutionCheck]) -> Vec<MergedWarning> {
    let per_scene: Vec<Vec<ResolutionWarning>> = checks.iter().map(|c| c.warnings()).collect();
    let all = || {
        per_scene
            .iter()
            .enumerate()
            .flat_map(|(i, ws)| ws.iter().map(move |w| (i, w)))
    };
    let mut out = Vec::new();
    // Too few layers, by (key, layers).
    let few = group_by(
        all().filter(|(_, w)| w.issue == ResolutionIssue::TooFewLayers),
        |w| (w.plate.key, w.plate.layers),
    );
    for (_, members) in few {
        let ws: Vec<&ResolutionWarning> = members.iter().map(|(_, w)| *w).collect();
        out.push(MergedWarning {
            message: layers_message(&ws),
            scenes: scenes_of(&members),
        });
    }
    // Thickness off, by message.
    let off = group_by(
        all().filter(|(_, w)| w.issue == ResolutionIssue::ThicknessOff),
        |w| w.message.clone(),
    );
    for (message, members) in off {
        out.push(MergedWarning {
            message,
            scenes: scenes_of(&members),
        });
    }
    // One plate under several labels, among plates with enough layers.
    let plates = checks.iter().enumerate().flat_map(|(i, c)| {
        c.plates
            .iter()
            .filter(|p| p.layers >= MIN_PLATE_LAYERS)
            .map(move |p| (i, (p, c.r_eq_m)))
    });
    for (_, members) in group_by(plates, |(p, r_eq)| (p.key, p.layers, r_eq.to_bits())) {
        let plates: Vec<(&Plate, f64)> = members.iter().map(|(_, m)| *m).collect();
        let first = plates[0].0.asked;
        if plates.iter().any(|(p, _)| p.asked != first) {
            out.push(MergedWarning {
                message: same_plate_message(&plates),
                scenes: scenes_of(&members),
            });
        }
    }
    out
}

/// Whether a change of the geometry from `before` to `after`, at the same resolution, moved
/// sigma by more than [`SIGMA_CHANGE_TOLERANCE`]: then the change, with both sigmas and the
/// geometry keys that did it. None when the two scenes' resolutions differ (sigma then moved
/// by the resolution asked) or sigma stayed within the tolerance. An error when either scene's
/// geometry or resolution is invalid.
///
/// At a fixed `resolution.particles` every key that changes the scene's volume moves sigma
/// (the plate's width and thickness, the sphere's diameter, the flyer plate's thicknesses and
/// width); at a fixed `resolution.particles_across_d`, only the sphere's diameter.
pub fn sigma_change(before: &SceneSpec, after: &SceneSpec) -> Result<Option<SigmaChange>> {
    if before.resolution != after.resolution {
        return Ok(None);
    }
    let (r_before, r_after) = (lattice_spacing_m(before)?, lattice_spacing_m(after)?);
    let ratio = r_after / r_before;
    if (ratio - 1.0).abs() <= SIGMA_CHANGE_TOLERANCE {
        return Ok(None);
    }
    let res = &after.resolution;
    let (resolution_key, resolution_value, keeping_value) =
        match (res.particles, res.particles_across_d) {
            (Some(n), _) => ("resolution.particles", n, n * ratio.powi(3)),
            (None, Some(k)) => ("resolution.particles_across_d", k, k * ratio),
            (None, None) => return Ok(None),
        };
    let keys = changed_keys(&before.scene, &after.scene, res);
    let sigma_before_m = r_before / paper::r_eq_over_sigma();
    let sigma_after_m = r_after / paper::r_eq_over_sigma();
    let why = match resolution_key {
        "resolution.particles" => "the particles fill the whole scene's volume",
        _ => "sigma follows the sphere's diameter",
    };
    let changes: Vec<String> = keys
        .iter()
        .map(|k| format!("{} = {} (was {})", k.key, k.after, k.before))
        .collect();
    let message = format!(
        "{} {} sigma from {} mm to {} mm at {resolution_key} = {resolution_value} ({why}): \
         {resolution_key} = {} keeps sigma at {} mm",
        and_list(&changes),
        if keys.len() == 1 { "changes" } else { "change" },
        num(sigma_before_m * 1e3),
        num(sigma_after_m * 1e3),
        num(keeping_value),
        num(sigma_before_m * 1e3),
    );
    Ok(Some(SigmaChange {
        keys,
        sigma_before_m,
        sigma_after_m,
        resolution_key,
        resolution_value,
        keeping_value,
        message,
    }))
}

/// The geometry keys that set sigma at this resolution, with their values.
fn sigma_keys(g: &Geometry, res: &Resolution) -> Vec<(&'static str, f64)> {
    match *g {
        Geometry::SphereOnPlate { diameter_m, .. } if res.particles.is_none() => {
            vec![("scene.diameter_m", diameter_m)]
        }
        Geometry::SphereOnPlate {
            diameter_m,
            t_over_d,
            width_over_d,
            ..
        } => vec![
            ("scene.diameter_m", diameter_m),
            ("scene.t_over_d", t_over_d),
            ("scene.width_over_d", width_over_d),
        ],
        Geometry::FlyerPlate {
            flyer_thickness_m,
            target_thickness_m,
            width_m,
            ..
        } => vec![
            ("scene.flyer_thickness_m", flyer_thickness_m),
            ("scene.target_thickness_m", target_thickness_m),
            ("scene.width_m", width_m),
        ],
    }
}

/// The keys that set sigma whose values differ between two geometries (the kind, when the
/// geometries are of two kinds).
fn changed_keys(before: &Geometry, after: &Geometry, res: &Resolution) -> Vec<KeyChange> {
    let kind = |g: &Geometry| match g {
        Geometry::SphereOnPlate { .. } => "sphere_on_plate",
        Geometry::FlyerPlate { .. } => "flyer_plate",
    };
    if kind(before) != kind(after) {
        return vec![KeyChange {
            key: "scene.kind",
            before: kind(before).into(),
            after: kind(after).into(),
        }];
    }
    sigma_keys(before, res)
        .into_iter()
        .zip(sigma_keys(after, res))
        .filter(|((_, b), (_, a))| a != b)
        .map(|((key, b), (_, a))| KeyChange {
            key,
            before: format!("{b}"),
            after: format!("{a}"),
        })
        .collect()
}

/// Groups `(scene, item)` pairs by `key`, the groups in the order of their first member.
fn group_by<T, K: PartialEq>(
    items: impl Iterator<Item = (usize, T)>,
    key: impl Fn(&T) -> K,
) -> Vec<(K, Vec<(usize, T)>)> {
    let mut groups: Vec<(K, Vec<(usize, T)>)> = Vec::new();
    for (i, item) in items {
        let k = key(&item);
        match groups.iter_mut().find(|(g, _)| *g == k) {
            Some((_, members)) => members.push((i, item)),
            None => groups.push((k, vec![(i, item)])),
        }
    }
    groups
}

/// The scenes of a group, ascending and once each.
fn scenes_of<T>(members: &[(usize, T)]) -> Vec<usize> {
    let mut s: Vec<usize> = members.iter().map(|(i, _)| *i).collect();
    s.sort_unstable();
    s.dedup();
    s
}

/// The remedies of several warnings as one: for each key, the largest value any needs, as
/// `resolution.particles >= 1.22e5 (or resolution.particles_across_d >= 50)`.
fn remedy_text<'a>(remedies: impl Iterator<Item = &'a Vec<(&'static str, f64)>>) -> String {
    let mut most: Vec<(&'static str, f64)> = Vec::new();
    for r in remedies {
        for &(key, value) in r {
            match most.iter_mut().find(|(k, _)| *k == key) {
                Some((_, v)) => *v = v.max(value),
                None => most.push((key, value)),
            }
        }
    }
    let mut parts = most.iter().map(|(k, v)| format!("{k} >= {}", num(*v)));
    let first = parts.next().unwrap_or_default();
    match parts.collect::<Vec<_>>() {
        rest if rest.is_empty() => first,
        rest => format!("{first} (or {})", rest.join(" or ")),
    }
}

/// The values' texts, ascending by value, each text once.
fn distinct(values: impl Iterator<Item = f64>, text: impl Fn(f64) -> String) -> Vec<String> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    let mut out: Vec<String> = Vec::new();
    for x in v {
        let t = text(x);
        if !out.contains(&t) {
            out.push(t);
        }
    }
    out
}

/// `a`, `a and b`, `a, b and c`.
fn and_list(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} and {last}", init.join(", ")),
    }
}

fn plural(n: u32) -> &'static str {
    if n == 1 {
        ""
    } else {
        "s"
    }
}

/// `x` to three significant digits, in exponent form outside [1e-3, 1e5): `0.75`, `0.0787`,
/// `36400`, `1.22e5`.
fn num(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let e = x.abs().log10().floor() as i32;
    let scale = 10f64.powi(2 - e);
    let r = (x * scale).round() / scale;
    if (1e-3..1e5).contains(&r.abs()) {
        format!("{r}")
    } else {
        format!("{r:e}")
    }
}

/// `x` rounded up to three significant digits (a least value stays enough when printed).
fn ceil3(x: f64) -> f64 {
    if x <= 0.0 || !x.is_finite() {
        return x;
    }
    let e = x.log10().floor() as i32;
    let scale = 10f64.powi(2 - e);
    // Forgive the last bits of a value that is a round number.
    (x * scale * (1.0 - 1e-12)).ceil() / scale
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneSpec;

    /// The calibration scene (D = 9.53 mm, W = 3 D) at `particles` with the plate's t/D and
    /// width set.
    fn calibration(particles: f64, t: f64, w: f64) -> SceneSpec {
        let mut spec = SceneSpec::calibration(particles, 1e-7);
        if let Geometry::SphereOnPlate {
            t_over_d,
            width_over_d,
            ..
        } = &mut spec.scene
        {
            *t_over_d = t;
            *width_over_d = w;
        }
        spec
    }

    fn close(a: f64, b: f64, rel: f64) -> bool {
        (a / b - 1.0).abs() < rel
    }

    /// By hand: V = (pi/6 + 3^2 x 0.05) D^3 = 0.97360 D^3; r_eq = (V / 2000)^(1/3) =
    /// 0.078667 D = 0.74970 mm; t = 0.4765 mm is 0.636 r_eq: 1 layer, simulated t/D 0.078667,
    /// 57.3 % thicker. Three layers need t / r_eq >= 2.5: N >= V (2.5 / 0.05 D)^3 = 1.217e5,
    /// or 50 across D; within 10 % needs t / r_eq >= 5: N >= 9.736e5, or 100 across D.
    #[test]
    fn t_over_d_0_05_at_2000_particles_is_one_layer() {
        let setup = calibration(2000.0, 0.05, 3.0).build().expect("valid scene");
        let check = setup.resolution_check();
        let d = paper::IMPACTOR_DIAMETER_M;
        assert!(close(check.r_eq_m, 0.078667 * d, 1e-4), "{}", check.r_eq_m);
        let p = &check.plates[0];
        assert_eq!((p.key, p.layers, p.asked), ("scene.t_over_d", 1, 0.05));
        assert!(close(p.simulated, 0.078667, 1e-4), "{}", p.simulated);
        assert!(
            close(p.relative_error(), 0.5733, 1e-3),
            "{}",
            p.relative_error()
        );
        // The layout agrees: the plate's rear face lies one r_eq behind its front.
        assert_eq!(setup.derived.plate_rear_z_m, check.r_eq_m);

        let w = check.warnings();
        assert_eq!(w.len(), 2, "{w:#?}");
        assert_eq!(w[0].issue, ResolutionIssue::TooFewLayers);
        assert_eq!(
            w[0].remedy,
            [
                ("resolution.particles", 1.22e5),
                ("resolution.particles_across_d", 50.0)
            ]
        );
        assert_eq!(
            w[0].message,
            "scene.t_over_d = 0.05 gives a plate of 1 particle layer (r_eq 0.75 mm; simulated \
             t/D 0.0787), fewer than the minimum of 3: resolution.particles >= 1.22e5 (or \
             resolution.particles_across_d >= 50) gives it 3"
        );
        assert_eq!(w[1].issue, ResolutionIssue::ThicknessOff);
        assert_eq!(
            w[1].remedy,
            [
                ("resolution.particles", 9.74e5),
                ("resolution.particles_across_d", 100.0)
            ]
        );
        assert_eq!(
            w[1].message,
            "scene.t_over_d = 0.05 is simulated as t/D 0.0787: 0.75 mm thick, not 0.477 mm \
             (1 layer of r_eq 0.75 mm), 57 % thicker than asked, beyond the 10 % tolerance: \
             resolution.particles >= 9.74e5 (or resolution.particles_across_d >= 100) keeps it \
             within 10 %"
        );
        // Without the lattice: the same numbers.
        assert_eq!(
            calibration(2000.0, 0.05, 3.0)
                .resolution_check()
                .expect("valid"),
            check
        );
    }

    /// Quarter symmetry halves the plate laterally and keeps every layer: the target's
    /// distinct heights in the quarter's layout are the layers the check counts.
    #[test]
    fn the_quarter_layout_has_the_layers_the_check_counts() {
        for t in [0.05, 0.2, 0.425] {
            let mut spec = calibration(2000.0, t, 3.0);
            spec.run.symmetry = crate::symmetry::Symmetry::Quarter;
            let setup = spec.build().expect("valid scene");
            let p = &setup.particles;
            let mut z: Vec<u64> = (0..p.len())
                .filter(|&k| p.body[k] == crate::state::Body::Target)
                .map(|k| p.pos[k].z.to_bits())
                .collect();
            z.sort_unstable();
            z.dedup();
            let check = setup.resolution_check();
            assert_eq!(z.len() as u32, check.plates[0].layers, "t/D {t}");
            assert_eq!(check, spec.resolution_check().expect("valid"));
        }
    }

    /// By hand: the calibration plate (t/D 0.425) at 2000 particles: V = 4.3486 D^3, r_eq =
    /// 0.12959 D, t / r_eq = 3.28: 3 layers, simulated t/D 0.3888, 8.5 % thinner: no warning.
    /// At 500: r_eq = 0.20572 D, t / r_eq = 2.07: 2 layers, simulated 0.411 (3.2 % thinner).
    #[test]
    fn the_calibration_plate_has_three_layers_at_2000_and_two_at_500() {
        let at = |n: f64| {
            calibration(n, 0.425, 3.0)
                .resolution_check()
                .expect("valid")
        };
        let c = at(2000.0);
        assert_eq!(c.plates[0].layers, 3);
        assert!(
            close(c.plates[0].simulated, 0.38877, 1e-3),
            "{:?}",
            c.plates
        );
        assert!(c.warnings().is_empty(), "{:#?}", c.warnings());
        let c = at(500.0);
        assert_eq!(c.plates[0].layers, 2);
        let w = c.warnings();
        assert_eq!(w.len(), 1, "{w:#?}");
        assert_eq!(w[0].issue, ResolutionIssue::TooFewLayers);
    }

    /// The quick validity map's rows at 10 particles across D: r_eq = D / 10, so t/D 0.05
    /// (0.5 r_eq, rounded up) and 0.1 are both one layer of r_eq, simulated t/D 0.1; 0.2 is
    /// two; 0.3 is three and exact. Merged over the rows: one warning for the two labels of
    /// one plate, one for t/D 0.2, and t/D 0.05's thickness (100 % thicker).
    #[test]
    fn the_quick_validity_maps_thin_rows_merge_into_one_plate() {
        let rows = [0.05, 0.1, 0.2, 0.3];
        let checks: Vec<ResolutionCheck> = rows
            .iter()
            .flat_map(|&t| {
                let mut spec = calibration(2000.0, t, 2.0);
                spec.resolution = Resolution {
                    particles: None,
                    particles_across_d: Some(10.0),
                };
                // Two v0 values per row: the merged warnings name both scenes.
                vec![spec.resolution_check().expect("valid"); 2]
            })
            .collect();
        let layers: Vec<u32> = checks.iter().map(|c| c.plates[0].layers).collect();
        assert_eq!(layers, [1, 1, 1, 1, 2, 2, 3, 3]);
        let merged = merged_warnings(&checks);
        assert_eq!(merged.len(), 3, "{merged:#?}");
        assert_eq!(
            merged[0].message,
            "scene.t_over_d = 0.05 and 0.1 give the same plate of 1 particle layer (r_eq \
             0.953 mm; simulated t/D 0.1), fewer than the minimum of 3: \
             resolution.particles_across_d >= 50 gives it 3"
        );
        assert_eq!(merged[0].scenes, [0, 1, 2, 3]);
        assert!(
            merged[1].message.starts_with(
                "scene.t_over_d = 0.2 gives a plate of 2 particle layers (r_eq 0.953 mm; \
                 simulated t/D 0.2)"
            ),
            "{}",
            merged[1].message
        );
        assert_eq!(merged[1].scenes, [4, 5]);
        assert!(
            merged[2]
                .message
                .starts_with("scene.t_over_d = 0.05 is simulated as t/D 0.1: 0.953 mm thick"),
            "{}",
            merged[2].message
        );
        assert!(merged[2].message.contains("100 % thicker"));
        assert_eq!(merged[2].scenes, [0, 1]);
    }

    /// At 2000 particles t/D 0.05 and 0.1 are two one-layer plates of different r_eq
    /// (0.75 mm; and for 0.1: V = 1.4236 D^3, r_eq = 0.089298 D = 0.851 mm): "plates", each
    /// r_eq and simulated t/D named, the remedy the larger of the two.
    #[test]
    fn one_layer_plates_of_two_lattices_are_named_apart() {
        let checks: Vec<ResolutionCheck> = [0.05, 0.1]
            .iter()
            .map(|&t| calibration(2000.0, t, 3.0).resolution_check().expect("ok"))
            .collect();
        let merged = merged_warnings(&checks);
        assert_eq!(
            merged[0].message,
            "scene.t_over_d = 0.05 and 0.1 give plates of 1 particle layer (r_eq 0.75 and \
             0.851 mm; simulated t/D 0.0787 and 0.0893), fewer than the minimum of 3: \
             resolution.particles >= 1.22e5 (or resolution.particles_across_d >= 50) gives \
             each 3"
        );
        assert_eq!(merged[0].scenes, [0, 1]);
    }

    /// Two labels of one plate of enough layers: at 10 across D, t/D 0.5 and 0.54 are both 5
    /// layers (0.54 is 7.4 % thinner: within the tolerance, so no single scene warns).
    #[test]
    fn two_labels_of_one_thick_plate_are_named() {
        let checks: Vec<ResolutionCheck> = [0.5, 0.54]
            .iter()
            .map(|&t| {
                let mut spec = calibration(2000.0, t, 2.0);
                spec.resolution = Resolution {
                    particles: None,
                    particles_across_d: Some(10.0),
                };
                spec.resolution_check().expect("valid")
            })
            .collect();
        assert!(checks.iter().all(|c| c.warnings().is_empty()));
        let merged = merged_warnings(&checks);
        assert_eq!(merged.len(), 1, "{merged:#?}");
        assert_eq!(
            merged[0].message,
            "scene.t_over_d = 0.5 and 0.54 give the same plate of 5 particle layers (r_eq \
             0.953 mm; simulated t/D 0.5): their runs differ only in the label; a finer \
             resolution tells them apart"
        );
    }

    /// By hand: default.toml's 10000 particles at W = 3 D: V = 4.3486 D^3, sigma = (V /
    /// 1e4)^(1/3) / 2^(1/6) = 0.067496 D = 0.64324 mm; at W = 6 D: V = (pi/6 + 36 x 0.425)
    /// D^3 = 15.824 D^3, sigma = 0.10382 D = 0.98936 mm. Keeping 0.643 mm takes 1e4 x 15.824
    /// / 4.3486 = 36388 particles.
    #[test]
    fn a_wider_plate_at_the_same_particle_count_coarsens_sigma() {
        let before = calibration(1e4, 0.425, 3.0);
        let after = calibration(1e4, 0.425, 6.0);
        let c = sigma_change(&before, &after)
            .expect("valid")
            .expect("sigma moved");
        assert!(
            close(c.sigma_before_m, 0.64324e-3, 1e-4),
            "{}",
            c.sigma_before_m
        );
        assert!(
            close(c.sigma_after_m, 0.98936e-3, 1e-4),
            "{}",
            c.sigma_after_m
        );
        assert!(close(c.keeping_value, 36388.0, 1e-4), "{}", c.keeping_value);
        assert_eq!(c.keys.len(), 1);
        assert_eq!(
            c.message,
            "scene.width_over_d = 6 (was 3) changes sigma from 0.643 mm to 0.989 mm at \
             resolution.particles = 10000 (the particles fill the whole scene's volume): \
             resolution.particles = 36400 keeps sigma at 0.643 mm"
        );
        // The same scene, a change within 2 % (t/D 0.425 -> 0.42: V 1 % smaller, sigma 0.35 %), or
        // another resolution: nothing.
        assert_eq!(sigma_change(&before, &before), Ok(None));
        assert_eq!(
            sigma_change(&before, &calibration(1e4, 0.42, 3.0)),
            Ok(None)
        );
        assert_eq!(
            sigma_change(&before, &calibration(2e4, 0.425, 6.0)),
            Ok(None)
        );
        // At a fixed count across D the width does not move sigma.
        let across = |w: f64| {
            let mut s = calibration(1e4, 0.425, w);
            s.resolution = Resolution {
                particles: None,
                particles_across_d: Some(10.0),
            };
            s
        };
        assert_eq!(sigma_change(&across(3.0), &across(6.0)), Ok(None));
    }

    /// Flyer plates: both plates are checked, each by its own key. By hand: flyer_plate.toml
    /// (1 mm on 2 mm, 4 mm square, V = 4.8e-8 m^3) at 500 particles: r_eq = 0.45789 mm; the
    /// flyer is 2.18 r_eq: 2 layers (0.916 mm, 8.4 % thinner), the target 4.37: 4 layers.
    #[test]
    fn a_flyer_plates_two_plates_are_checked() {
        let spec = SceneSpec {
            scene: Geometry::FlyerPlate {
                flyer_thickness_m: 1e-3,
                target_thickness_m: 2e-3,
                width_m: 4e-3,
                v0_m_s: 1000.0,
                density_kg_m3: 2700.0,
                standoff_m: 0.0,
            },
            ..SceneSpec::calibration(500.0, 1e-7)
        };
        let c = spec.build().expect("valid").resolution_check();
        assert!(close(c.r_eq_m, 0.45789e-3, 1e-4), "{}", c.r_eq_m);
        let layers: Vec<(&str, u32)> = c.plates.iter().map(|p| (p.key, p.layers)).collect();
        assert_eq!(
            layers,
            [
                ("scene.target_thickness_m", 4),
                ("scene.flyer_thickness_m", 2)
            ]
        );
        let w = c.warnings();
        assert_eq!(w.len(), 1, "{w:#?}");
        assert_eq!(
            w[0].message,
            "scene.flyer_thickness_m = 0.001 gives a flyer plate of 2 particle layers (r_eq \
             0.458 mm; simulated 0.916 mm), fewer than the minimum of 3: resolution.particles \
             >= 750 gives it 3"
        );
    }

    #[test]
    fn numbers_print_to_three_significant_digits() {
        assert_eq!(num(0.74970), "0.75");
        assert_eq!(num(0.0786671), "0.0787");
        assert_eq!(num(36389.0), "36400");
        assert_eq!(num(121_700.0), "1.22e5");
        assert_eq!(ceil3(121_700.0), 122_000.0);
        assert_eq!(ceil3(50.0), 50.0);
        assert_eq!(ceil3(50.000_001), 50.1);
    }
}
