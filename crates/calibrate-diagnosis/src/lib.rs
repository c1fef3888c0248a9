//! # calibrate-diagnosis: residual diagnosis and model extension
//!
//! On top of calibrate's identification (samples, parameters, residuals, fit, validation):
//! which physical effects the residuals support, the spec's steps end to end, how repeatable
//! the result is and the report of it.
//!
//! | job | module | equations |
//! |---|---|---|
//! | candidate effects, signature tests, selection | [`effects`] | 2.1, Fig. 1.4 |
//! | the spec's steps end to end | [`pipeline`] | ch. 6.2–6.5 |
//! | a per-cable effect's size (RMS ±1σ) against a truth | [`magnitude`] | |
//! | multi-start, second run, bootstrap of the chosen effects | [`repeatability`] | 6.8, 6.10 |
//! | structure the final model leaves in the held-out residuals | [`structure`] | |
//! | Markdown / JSON / SVG report, platform TOML | [`report`] | |

#![allow(clippy::needless_range_loop)]

pub mod effects;
pub mod magnitude;
pub mod pipeline;
pub mod repeatability;
pub mod repeatability_figures;
pub mod report;
pub mod structure;
