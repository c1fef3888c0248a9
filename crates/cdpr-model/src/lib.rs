//! # cdpr-model: the CDPR model library
//!
//! Models of the spec's chapter 2 (and the workspace of chapter 3) for spatial cable robots
//! with m ≥ 7 cables and n = 6 DOF, with their differential counterparts:
//!
//! | job | module | equations |
//! |---|---|---|
//! | pose, rotation, J_P | [`pose`] | 2.2, 2.44–2.46 |
//! | standard / pulley inverse kinematics | [`kinematics`] | 2.3–2.8, 2.16–2.29 |
//! | differential kinematics | [`kinematics::differential`] | 2.47–2.65, 2.83–2.87, 4.5–4.6 |
//! | statics, force distribution | [`statics`] | 2.30–2.31, 2.38–2.40, 3.41, 5.11 |
//! | elastostatics, stiffness | [`elastostatics`] | 2.33–2.41, 2.66–2.80 |
//! | forward kinematics ν, ν_el | [`forward`] | 2.9–2.15, 2.42–2.43, 2.81 |
//! | Levenberg–Marquardt for small dense least squares (every solver above and calibration's) | [`levenberg_marquardt`] | 2.12–2.15, 4.11, 4.16 |
//! | wrench-feasible workspace, reachable workspace W_R | [`workspace`] | 3.29, 3.33–3.35 |
//! | exact wrench feasibility (LP) | [`feasibility`] | 3.29, 2.38–2.40 |
//! | rigid-body dynamics, inertial wrench w_in | [`dynamics`] | 5.13–5.16, 5.21 |
//! | operator TOML | [`config`] | tables 5.1, eq. 5.8, 5.12, 5.17, 6.1, 6.20 |
//!
//! This crate knows nothing of IPC, real time, CAN or command lines: the daemon (`motion-core`),
//! the plant, calibration and the CLI build on it; the design analyses (planar robots, parameter
//! sensitivity, the cabin truss) are `cdpr-analysis`.
//!
//! Model/Data split: [`Model`] is immutable and validated; [`Data`] is preallocated per
//! thread, and every hot-path function (inverse kinematics, force distribution, forward
//! kinematics) writes into it without allocating.

// Per-cable loops index several parallel arrays (q, q_θ, f, columns of A^T) by the cable
// number, as the equations do; iterator zips of four slices would hide that.
#![allow(clippy::needless_range_loop)]

pub mod config;
pub mod config_writer;
pub mod dynamics;
pub mod elastostatics;
pub mod feasibility;
pub mod forward;
pub mod kinematics;
pub mod levenberg_marquardt;
pub mod model;
pub mod offset_target;
pub mod pose;
pub mod statics;
pub mod workspace;

pub use model::{Data, MAX_CABLES, MIN_CABLES, Model, ModelError, ModelParams, Pulleys};
pub use pose::Pose;
