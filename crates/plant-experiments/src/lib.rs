//! # plant-experiments: experiments on the simulated plant alone
//!
//! Measurements taken on the plant model (crate `sim-plant`) without running the stack's
//! processes:
//!
//! - [`plant_check`]: a plant TOML checked and settled at home (`crs plant check`).
//! - [`plant_record`]: a measurement campaign on the plant written as a data set.
//! - [`reachable_on_plant`]: the kinematic controller's reachable workspace measured on the plant.
//! - [`load_experiment`]: the seed's walking-subject load tracking (sec. 5.3) on the plant.
//! - [`surrogate_evaluation`]: the surrogate fit of a platform and its evaluation on the plant.

pub mod load_experiment;
pub mod plant_check;
pub mod plant_record;
pub mod reachable_on_plant;
pub mod surrogate_evaluation;
