//! The stages of the reproduction. Each runs its study through the study runner and its
//! store (finished runs are reused), draws or collects its figures into the report directory,
//! and turns the runs' numbers into [`Figure`](crate::report::Figure)s: the paper's result (from `hvi_engine::paper`),
//! ours, the deciding numbers ([`hvi_analysis::decide`]) and a verdict.
//!
//! Every stage reads the same way: run (or collect) the study, gather the fields it needs,
//! compute the deciding numbers (pure functions of plain values), draw, and build each
//! figure with its verdict.

mod fig13;
mod fig16_17;
mod fig3;
mod fig4;
mod fig5_11_12;
mod fig7_9_10;
mod shared;

pub use fig13::{fig13, fig13_paper, fig13_pending};
pub use fig16_17::{fig16_17, fig16_paper, fig16_pending, fig17_paper, fig17_pending};
pub use fig3::{fig3, fig3_paper, fig3_pending};
pub use fig4::{fig4, fig4_paper, fig4_pending};
pub use fig5_11_12::{fig11_paper, fig11_pending, fig5_11_12, fig5_paper, fig5_pending};
pub use fig7_9_10::{
    fig10_checks, fig10_figure, fig10_paper, fig10_pending, fig7_9_10, fig7_paper, fig7_pending,
    fig9_checks, fig9_figure, fig9_paper, fig9_pending, FIG10_CHECKS, FIG10_MAIN_CHECKS,
    FIG9_CHECKS, FIG9_MAIN_CHECKS,
};
pub use shared::{completed_runs, Ctx};
