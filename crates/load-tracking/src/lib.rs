//! # load-tracking: what the cable forces say about the load
//!
//! The CRS measures every cable force in its redirection pulleys (sec. 5.1). With the structure
//! matrix of the controller's model the forces give the wrench the platform carries,
//! A^T(x) f + w_e = 0 (eq. 2.31), so w_e = −A^T(x) f. From that:
//!
//! - [`payload`]: mass and centre of gravity of the cabin load from forces at rest in one or
//!   more poses, with their standard deviations (eq. 6.22–6.23 generalised to several poses);
//! - [`point_load`]: a moving point load (a walking subject) from the change of the xy torque
//!   against the unloaded state (eq. 5.9–5.10), with its uncertainty;
//! - [`setup`]: the cable offsets of the set-up (eq. 6.24) and the initial tension f_ini that
//!   keeps the forces closest to f_ref (eq. 3.41) along a planned path (eq. 3.42).
//!
//! Model layer (Model + Data, free functions); the tools that run it on the plant or the stack
//! live in `plant-experiments` (`load_experiment`) and `calibration-campaigns` (`commission`).

pub mod payload;
pub mod point_load;
pub mod setup;

use cdpr_model::kinematics::{self, KinematicsError};
use cdpr_model::{Data, Model, Pose, statics};
use nalgebra::Vector6;

/// Standard gravity, m/s² (the value the platform TOMLs' loads were computed with).
pub const G: f64 = 9.81;

/// The external wrench the platform carries at `pose` according to the measured cable forces
/// `f` and the model's geometry: w_e = −A^T(x) f (eq. 2.31, eq. 6.23). Allocation-free.
pub fn wrench_from_forces(
    model: &Model,
    data: &mut Data,
    pose: &Pose,
    f: &[f64],
) -> Result<Vector6<f64>, KinematicsError> {
    kinematics::inverse(model, data, pose)?;
    Ok(-statics::cable_wrench(data, f))
}
