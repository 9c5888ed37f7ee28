//! The run observables: one typed definition of each number a study reads of a run (its
//! name in tables and target files, its symbol, unit and meaning), and the values of one run.
//!
//! The debris-cloud observables are computed once, in `hvi_engine::cloud` (docs/model.md
//! section 5); the run crate fills [`Observables`] from a run's summary. Tables, scores,
//! tolerances, plots and reports iterate over [`Observable::ALL`] instead of naming them again, so adding
//! an observable is one row of [`DEFINITIONS`] plus its computation.
//!
//! ```
//! use hvi_analysis::observable::{Observable, Observables};
//! let r = Observable::from_name("length_ratio").expect("known");
//! assert_eq!((r.symbol(), r.unit()), ("R", "1"));
//! let mut o = Observables::default();
//! o.set(r, Some(1.2));
//! assert_eq!(o.get(Observable::LengthRatio), Some(1.2));
//! assert_eq!(o.get(Observable::Fragmentation), None);
//! ```

use std::fmt;

use serde::de::{self, MapAccess, Visitor};
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// One observable of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Observable {
    /// Particles in the run.
    Particles,
    /// Fragmentation F = N_frag / N_part (eq. 21).
    Fragmentation,
    /// Particles in the debris cloud.
    NPart,
    /// Fragments in the debris cloud.
    NFrag,
    /// Axial length La.
    LengthAxial,
    /// Radial length Lr, as `analysis.width` reads it (side-on by default).
    LengthRadial,
    /// R = La / Lr, as `analysis.width` reads Lr.
    LengthRatio,
    /// Lr seen side-on (the projection a shadowgraph records).
    LengthRadialSide,
    /// R seen side-on.
    LengthRatioSide,
    /// Lr as a cylindrical radius (distance from the axis).
    LengthRadialCylindrical,
    /// R with the cylindrical Lr.
    LengthRatioCylindrical,
    /// Front velocity va.
    FrontVelocity,
    /// va / v0.
    FrontVelocityRatio,
    /// The cloud's largest fragment's mass over the impactor mass.
    LargestFragmentMassFraction,
    /// The impactor mass of the cloud fragment holding the most of it, over the impactor mass.
    ImpactorLargestFragmentMassFraction,
    /// The impactor's largest piece anywhere, over the impactor mass (1: intact).
    ImpactorIntactMassFraction,
    /// Largest fragment's volume-equivalent diameter.
    LargestFragmentDiameter,
    /// Mass-weighted mean fragment diameter.
    MeanFragmentDiameter,
    /// Time since first contact of the cloud measurement.
    Tau,
    /// Bonds broken over bonds at t = 0.
    BondsBrokenFraction,
    /// Relative drift of the energy ledger at the end.
    EnergyRelativeDrift,
    /// La of the shadowgraph's silhouette.
    LengthAxialSilhouette,
    /// Lr of the shadowgraph's silhouette.
    LengthRadialSilhouette,
    /// R of the shadowgraph's silhouette.
    LengthRatioSilhouette,
    /// va / v0 from the silhouette's front at the two image times.
    FrontVelocityRatioSilhouette,
    /// Craters on the witness plate.
    CraterCount,
    /// Median crater diameter on the witness plate.
    CraterDiameterMedian,
    /// Largest crater diameter on the witness plate.
    CraterDiameterMax,
    /// Largest crater within the impactor's radius of the axis.
    CentralCraterDiameter,
    /// 1 when the central crater is large (at least 5 times the median), else 0.
    LargeCentralCrater,
    /// 1 when the run's screen found it outside its window and it went on in free flight, 0
    /// when it went on in full; absent without a screen (`run.screen_after_s`).
    Screened,
}

/// What names and explains an observable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Definition {
    /// The observable.
    pub observable: Observable,
    /// Its name in tables, target files and `record.json` (snake case, unit suffix).
    pub name: &'static str,
    /// Its symbol in pictures and reports.
    pub symbol: &'static str,
    /// Its SI unit ("1" when dimensionless).
    pub unit: &'static str,
    /// One line of meaning.
    pub description: &'static str,
}

const fn def(
    observable: Observable,
    name: &'static str,
    symbol: &'static str,
    unit: &'static str,
    description: &'static str,
) -> Definition {
    Definition {
        observable,
        name,
        symbol,
        unit,
        description,
    }
}

/// Every observable, in table order (a plain table: the one place an observable is named).
pub const DEFINITIONS: [Definition; 31] = {
    use Observable::*;
    [
        def(Particles, "particles", "N", "1", "particles in the run"),
        def(
            Fragmentation,
            "fragmentation",
            "F",
            "1",
            "fragmentation N_frag / N_part (eq. 21)",
        ),
        def(
            NPart,
            "n_part",
            "N_part",
            "1",
            "particles in the debris cloud",
        ),
        def(
            NFrag,
            "n_frag",
            "N_frag",
            "1",
            "fragments in the debris cloud",
        ),
        def(
            LengthAxial,
            "length_axial_m",
            "La",
            "m",
            "axial length of the cloud",
        ),
        def(
            LengthRadial,
            "length_radial_m",
            "Lr",
            "m",
            "full width of the cloud as `analysis.width` reads it (default side-on)",
        ),
        def(
            LengthRatio,
            "length_ratio",
            "R",
            "1",
            "length ratio La / Lr",
        ),
        def(
            LengthRadialSide,
            "length_radial_side_m",
            "Lr (side)",
            "m",
            "full width of the cloud seen side-on (quantile of |x| and |y|)",
        ),
        def(
            LengthRatioSide,
            "length_ratio_side",
            "R (side)",
            "1",
            "length ratio La / Lr with Lr seen side-on",
        ),
        def(
            LengthRadialCylindrical,
            "length_radial_cylindrical_m",
            "Lr (cylindrical)",
            "m",
            "full width of the cloud as twice the quantile of the distance from the axis",
        ),
        def(
            LengthRatioCylindrical,
            "length_ratio_cylindrical",
            "R (cylindrical)",
            "1",
            "length ratio La / Lr with Lr a cylindrical radius",
        ),
        def(
            FrontVelocity,
            "front_velocity_m_s",
            "va",
            "m/s",
            "front velocity, lab frame",
        ),
        def(
            FrontVelocityRatio,
            "front_velocity_ratio",
            "va/v0",
            "1",
            "front velocity over v0",
        ),
        def(
            LargestFragmentMassFraction,
            "largest_fragment_mass_fraction",
            "largest fragment",
            "1",
            "the cloud's largest fragment's mass (impactor or plate material) over the impactor's",
        ),
        def(
            ImpactorLargestFragmentMassFraction,
            "impactor_largest_fragment_mass_fraction",
            "largest impactor piece",
            "1",
            "the impactor mass of the cloud fragment holding the most of it, over the impactor's",
        ),
        def(
            ImpactorIntactMassFraction,
            "impactor_intact_mass_fraction",
            "impactor intact",
            "1",
            "the impactor's largest piece anywhere (cloud, crater or in front of the plate), over \
             its mass: 1 for an intact impactor; the fragmentation onset is read from it",
        ),
        def(
            LargestFragmentDiameter,
            "largest_fragment_diameter_m",
            "d_max",
            "m",
            "largest fragment's volume-equivalent diameter",
        ),
        def(
            MeanFragmentDiameter,
            "mean_fragment_diameter_m",
            "d_mean",
            "m",
            "mass-weighted mean volume-equivalent fragment diameter",
        ),
        def(
            Tau,
            "tau_s",
            "tau",
            "s",
            "time since first contact of the cloud measurement",
        ),
        def(
            BondsBrokenFraction,
            "bonds_broken_fraction",
            "broken",
            "1",
            "bonds broken over bonds at t = 0",
        ),
        def(
            EnergyRelativeDrift,
            "energy_relative_drift",
            "drift",
            "1",
            "relative drift of the energy ledger at the end",
        ),
        def(
            LengthAxialSilhouette,
            "length_axial_silhouette_m",
            "La (silhouette)",
            "m",
            "axial length of the shadowgraph's silhouette",
        ),
        def(
            LengthRadialSilhouette,
            "length_radial_silhouette_m",
            "Lr (silhouette)",
            "m",
            "full width of the shadowgraph's silhouette",
        ),
        def(
            LengthRatioSilhouette,
            "length_ratio_silhouette",
            "R (silhouette)",
            "1",
            "La / Lr of the shadowgraph's silhouette",
        ),
        def(
            FrontVelocityRatioSilhouette,
            "front_velocity_ratio_silhouette",
            "va/v0 (silhouette)",
            "1",
            "front velocity of the silhouette between the two image times, over v0",
        ),
        def(
            CraterCount,
            "crater_count",
            "craters",
            "1",
            "craters on the witness plate",
        ),
        def(
            CraterDiameterMedian,
            "crater_diameter_median_m",
            "median crater",
            "m",
            "median crater diameter on the witness plate",
        ),
        def(
            CraterDiameterMax,
            "crater_diameter_max_m",
            "largest crater",
            "m",
            "largest crater diameter on the witness plate",
        ),
        def(
            CentralCraterDiameter,
            "central_crater_diameter_m",
            "central crater",
            "m",
            "largest crater within the impactor's radius of the axis",
        ),
        def(
            LargeCentralCrater,
            "large_central_crater",
            "large central crater",
            "1",
            "1 if the central crater is at least 5 times the median, else 0",
        ),
        def(
            Screened,
            "screened",
            "screened",
            "1",
            "1 if the run's screen (`run.screen_after_s`) sent it on in free flight, 0 if it \
             went on in full; absent without a screen (a seed mean between)",
        ),
    ]
};

impl Observable {
    /// Every observable, in table order.
    pub const ALL: [Observable; DEFINITIONS.len()] = {
        let mut all = [Observable::Particles; DEFINITIONS.len()];
        let mut i = 0;
        while i < all.len() {
            all[i] = DEFINITIONS[i].observable;
            i += 1;
        }
        all
    };

    /// Its definition.
    pub fn definition(self) -> &'static Definition {
        &DEFINITIONS[self as usize]
    }

    /// Its name in tables and files.
    pub fn name(self) -> &'static str {
        self.definition().name
    }

    /// Its symbol.
    pub fn symbol(self) -> &'static str {
        self.definition().symbol
    }

    /// Its SI unit.
    pub fn unit(self) -> &'static str {
        self.definition().unit
    }

    /// Whether the observable is a count (particles, fragments, craters) or a yes/no as 0 or 1:
    /// a whole number, which tables write without a decimal point.
    pub fn is_whole(self) -> bool {
        matches!(
            self,
            Observable::Particles
                | Observable::NPart
                | Observable::NFrag
                | Observable::CraterCount
                | Observable::LargeCentralCrater
        )
    }

    /// One line of meaning.
    pub fn description(self) -> &'static str {
        self.definition().description
    }

    /// The observable of that name, if any.
    pub fn from_name(name: &str) -> Option<Observable> {
        DEFINITIONS
            .iter()
            .find(|d| d.name == name)
            .map(|d| d.observable)
    }

    /// Every name, in table order.
    pub fn names() -> impl Iterator<Item = &'static str> {
        DEFINITIONS.iter().map(|d| d.name)
    }

    /// The observable of that name, or an error naming `key` and the allowed names.
    pub fn parse_named(key: &str, name: &str) -> Result<Observable, String> {
        Observable::from_name(name).ok_or_else(|| {
            format!(
                "{key}: unknown observable `{name}` (allowed: {:?})",
                Observable::names().collect::<Vec<_>>()
            )
        })
    }
}

impl fmt::Display for Observable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for Observable {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Observable {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        Observable::from_name(&name).ok_or_else(|| {
            de::Error::custom(format!(
                "unknown observable `{name}` (allowed: {:?})",
                Observable::names().collect::<Vec<_>>()
            ))
        })
    }
}

/// The observables of one run; `None` where the run did not measure it (a failed run, no
/// cloud). Serialised as an object of every name in table order (`null` when missing).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Observables {
    values: [Option<f64>; DEFINITIONS.len()],
}

impl Observables {
    /// The value of one observable.
    pub fn get(&self, o: Observable) -> Option<f64> {
        self.values[o as usize]
    }

    /// The value of the observable of that name (`None` for an unknown name).
    pub fn by_name(&self, name: &str) -> Option<f64> {
        Observable::from_name(name).and_then(|o| self.get(o))
    }

    /// Sets one observable.
    pub fn set(&mut self, o: Observable, value: Option<f64>) {
        self.values[o as usize] = value;
    }

    /// Every observable with its value, in table order.
    pub fn iter(&self) -> impl Iterator<Item = (Observable, Option<f64>)> + '_ {
        Observable::ALL.iter().map(|&o| (o, self.get(o)))
    }
}

impl Serialize for Observables {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(DEFINITIONS.len()))?;
        for (o, v) in self.iter() {
            map.serialize_entry(o.name(), &v)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for Observables {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct ObservablesVisitor;
        impl<'de> Visitor<'de> for ObservablesVisitor {
            type Value = Observables;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("an object of observables")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Observables, A::Error> {
                let mut o = Observables::default();
                // Unknown names (an observable a later version dropped) are skipped.
                while let Some(name) = map.next_key::<String>()? {
                    let value: Option<f64> = map.next_value()?;
                    if let Some(k) = Observable::from_name(&name) {
                        o.set(k, value);
                    }
                }
                Ok(o)
            }
        }
        d.deserialize_map(ObservablesVisitor)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn definitions_are_in_enum_order_with_unique_names() {
        for (i, d) in DEFINITIONS.iter().enumerate() {
            assert_eq!(d.observable as usize, i, "{}", d.name);
            assert_eq!(Observable::from_name(d.name), Some(d.observable));
        }
        let mut names: Vec<_> = Observable::names().collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), DEFINITIONS.len());
    }

    #[test]
    fn observables_round_trip_through_json_with_nulls() {
        let mut o = Observables::default();
        o.set(Observable::Fragmentation, Some(0.5));
        o.set(Observable::EnergyRelativeDrift, Some(-1e-6));
        let text = serde_json::to_string(&o).expect("serialises");
        assert!(
            text.starts_with(r#"{"particles":null,"fragmentation":0.5,"#),
            "{text}"
        );
        let back: Observables = serde_json::from_str(&text).expect("parses");
        assert_eq!(back, o);
        let partial: Observables =
            serde_json::from_str(r#"{"length_ratio": 1.3, "dropped_name": 2}"#).expect("parses");
        assert_eq!(partial.get(Observable::LengthRatio), Some(1.3));
        assert_eq!(partial.get(Observable::Particles), None);
    }

    #[test]
    fn unknown_names_are_refused_with_the_allowed_list() {
        let e = Observable::parse_named("targets.r.observable", "ratio").expect_err("unknown");
        assert!(
            e.contains("targets.r.observable") && e.contains("length_ratio"),
            "{e}"
        );
        assert!(serde_json::from_str::<Observable>(r#""ratio""#).is_err());
    }
}
