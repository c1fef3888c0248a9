//! The simulated plant's second formulation: the static equilibrium of a cable robot as the
//! MINIMUM OF ITS POTENTIAL ENERGY, computed from scalar cable lengths alone.
//!
//! Why it exists: sim-plant is the "ground truth" the stack is measured
//! against, but it solves its equilibrium with the controller's own kinematics, statics and
//! forward-kinematics code (cdpr-model). An error in those shared equations would appear in
//! controller and plant alike and no test could see it. This crate shares no code with
//! cdpr-model (it depends on glam only; `crates/crs/tests/layering.rs` pins that) and
//! shares as little of the *formulation* as possible:
//!
//! * The model library balances forces: A^T(x) f + w_e = 0 (eq. 2.43) with the structure matrix
//!   built from unit vectors u_i and the moment arms b_i × u_i (eq. 2.30), solved by
//!   Levenberg–Marquardt with the analytic stiffness K_G − K_C (eq. 2.74–2.76).
//! * Here the pose minimises U(x) = Σ_i E_i(q_i(x)) + V(x): the strain energy of each elastic
//!   cable (the integral of its force law over its length, eq. 2.33–2.36) plus the potential of
//!   the load. Only the cable LENGTHS q_i(x) are computed — with a pulley model derived here
//!   from the tangent condition in the pulley plane, not from eq. 2.19's angle formula — and
//!   every force direction and moment arm comes out of numerical differentiation of U. A wrong
//!   unit vector, moment arm, sign or pulley term in the model library therefore disagrees with
//!   this minimum (the stationarity condition ∂U/∂x = 0 IS the force balance, by the principle
//!   of virtual work).
//! * Rotations are unit quaternions with world-frame rotation-vector increments (the model uses
//!   XYZ angles and their Jacobian, eq. 2.44–2.46); the minimiser is a damped Newton method on
//!   a finite-difference Hessian of U, with its own 6 × 6 Cholesky.
//!
//! Only conservative loads have a potential: gravity of a mass at a centre of gravity (its
//! torque turns with the platform) and a constant force. A constant world-frame torque does not
//! (its work depends on the path of the rotation), so [`Robot::new`] refuses one.
//!
//! Units: SI (m, rad, N, kg). Poses at the boundary are `[x, y, z, φx, φy, φz]` with
//! R = R_x(φx) R_y(φy) R_z(φz) (the convention of the spec's eq. 2.2), so results compare with
//! the plant's directly.

mod energy;
mod geometry;
mod linalg;
/// The 6 × 6 Cholesky solve of the Newton step (bench-plant's minimiser uses it too).
pub use linalg::cholesky_solve;
mod minimize;
mod robot;

pub use energy::{cable_energy, cable_force};
pub use geometry::{PoseQ, cable_length};
pub use minimize::{Equilibrium, Options, equilibrium};
pub use robot::{Cable, Load, OracleError, Pulley, Robot};
