//! # calibrate: identification, residual diagnosis and model extension
//!
//! Closes the loop between measured data (docs/data-format.md) and the control model of
//! motion-core (spec ch. 4, 6):
//!
//! | job | module | equations |
//! |---|---|---|
//! | samples from a data set, held-out splits | [`observation`] | ch. 6.1 |
//! | parameter set, preconditioning scales | [`params`] | 4.42, 6.14 |
//! | joint-space and elastostatic residuals, analytic Jacobians | [`residual`] | 4.5–4.10, 4.38–4.41 |
//! | Levenberg–Marquardt | [`lm`] | 4.10–4.16 |
//! | identification, identifiability, ridge/lasso | [`identify`] | 4.18–4.23, 4.32, 4.42 |
//! | validation through the forward kinematics | [`validate`] | 3.3–3.8, 2.42 |
//! | candidate effects, signature tests, selection | [`effects`] | 2.1, Fig. 1.4 |
//! | the spec's steps end to end | [`pipeline`] | ch. 6.2–6.5 |
//! | a per-cable effect's size (RMS ±1σ) against a truth | [`magnitude`] | |
//! | multi-start, second run, bootstrap of the chosen effects | [`repeatability`] | 6.8, 6.10 |
//! | structure the final model leaves in the held-out residuals | [`structure`] | |
//! | Markdown / JSON / SVG report, platform TOML | [`report`] | |

#![allow(clippy::needless_range_loop)]

pub mod effects;
pub mod identify;
pub mod lm;
pub mod magnitude;
pub mod observation;
pub mod params;
pub mod pipeline;
pub mod repeatability;
pub mod repeatability_figures;
pub mod report;
pub mod residual;
pub mod structure;
pub mod validate;

pub use identify::{Fit, FitError, FitSpec, fit};
pub use observation::{Observation, from_dataset, split};
pub use params::{CalModel, ParamId};
pub use residual::{Kind, Weights};
