//! # stack-reports: what the stack's runs report
//!
//! - [`run_plots`]: the plots and index.html of every `crs sim` run.
//! - [`sim_observer`]: what `crs sim` runs next to the stack: the console and the run's plots.
//! - [`figures`]: the docs' headline figures regenerated into one JSON file (`crs figures`).
//! - [`surrogate_report`]: report.md/json and tracking.svg of a surrogate evaluation.
//! - [`commission_report`]: what `crs commission` prints of a commissioning.

pub mod commission_report;
pub mod figures;
pub mod run_plots;
pub mod sim_observer;
pub mod surrogate_report;
