//! The study workflows: plan, sweep and run-unit ([`sweep`]), `calibrate`, `collect` and `status`,
//! the calibration maps ([`figures`]), `validity-map`, `stability` and `reanalyse`.

pub mod accuracy;
pub mod collect;
pub mod document;
pub mod figures;
pub mod onset;
pub mod options;
pub mod reanalyse;
pub mod stability;
pub mod sweep;
pub mod validity;
