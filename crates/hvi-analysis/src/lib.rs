//! # hvi-analysis
//!
//! Pure functions from run observables to the numbers a study decides on: the typed
//! observables ([`observable`]), the objective against experiments ([`score`]), contours on a
//! grid ([`contour`]), the reproduction's deciding numbers ([`decide`]) and the calibration's
//! surrogate search ([`surrogate`]). Nothing here reads or writes a file or parses a command
//! line.

pub mod contour;
pub mod decide;
pub mod error;
pub mod number;
pub mod observable;
pub mod onset;
pub mod score;
pub mod shot;
pub mod surrogate;
