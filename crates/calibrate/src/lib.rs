//! # calibrate: identification of the control model from measured data
//!
//! Closes the loop between measured data (docs/data-format.md) and the control model of
//! motion-core (spec ch. 4, 6). Which physical effects the residuals support, the spec's steps
//! end to end and the report are `calibrate-diagnosis`, on top of this crate.
//!
//! | job | module | equations |
//! |---|---|---|
//! | samples from a data set, held-out splits | [`observation`] | ch. 6.1 |
//! | parameter set, preconditioning scales | [`params`] | 4.42, 6.14 |
//! | joint-space and elastostatic residuals, analytic Jacobians | [`residual`] | 4.5–4.10, 4.38–4.41 |
//! | Levenberg–Marquardt | [`lm`] | 4.10–4.16 |
//! | identification, identifiability, ridge/lasso, offsets from data | [`identify`] | 4.18–4.23, 4.32, 4.42, 3.14 |
//! | validation through the forward kinematics | [`validate`] | 3.3–3.8, 2.42 |

#![allow(clippy::needless_range_loop)]

pub mod identify;
pub mod lm;
pub mod observation;
pub mod params;
pub mod residual;
pub mod validate;

pub use identify::{Fit, FitError, FitSpec, fit};
pub use observation::{Observation, from_dataset, split};
pub use params::{CalModel, ParamId};
pub use residual::{Kind, Weights};
