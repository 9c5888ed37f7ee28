//! `hvi-study reproduce`: every figure of Watson & Steinhauser (2017) regenerated through the
//! study runner and its store, and a report that puts the paper's result beside ours.

pub mod decide;
pub mod sizing;
