//! Inverse kinematics of the standard model (sec. 2.2) and of the pulley model (sec. 2.3), and
//! their differentials (sec. 2.5, 2.7). Both fill the same [`Data`] fields, so statics,
//! elastostatics and the solvers work with either model unchanged (sec. 2.7: the structure
//! matrix of the pulley model uses the contact point p_A instead of a).

pub mod differential;
pub mod pulley;
pub mod standard;

use crate::model::{Data, Model};
use crate::pose::Pose;
use nalgebra::Vector6;

/// Why the inverse kinematics has no valid solution at a pose.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum KinematicsError {
    #[error("the pose is not finite")]
    NonFinitePose,
    #[error("cable {cable}: platform anchor coincides with the frame anchor (zero cable length)")]
    DegenerateCable { cable: usize },
    #[error(
        "cable {cable}: platform anchor lies on the pulley swivel axis (pulley plane undefined)"
    )]
    OnSwivelAxis { cable: usize },
    #[error("cable {cable}: platform anchor lies inside the pulley circle")]
    InsidePulley { cable: usize },
}

/// Inverse kinematics q = φ(x) (eq. 2.3) or q = φ_pl(x) (eq. 2.16), depending on the model.
/// Fills `q`, `q_free`, `beta`, `l`, `u`, `b_world`, `p_exit` and the structure-matrix columns
/// `at` of `data`. Allocation-free.
pub fn inverse(model: &Model, data: &mut Data, pose: &Pose) -> Result<(), KinematicsError> {
    if !pose.is_finite() {
        return Err(KinematicsError::NonFinitePose);
    }
    let p = model.params();
    let rot = pose.rotation();
    match &p.pulleys {
        None => {
            for i in 0..model.m() {
                // eq. (2.6): b_i = R_0P b_i^(P); p_B,i = r + b_i.
                let bw = rot * p.b[i];
                data.b_world[i] = bw;
                standard::cable(data, i, &p.a[i], &(pose.r + bw))?;
                set_column(data, i);
            }
        }
        Some(pl) => {
            for i in 0..model.m() {
                let bw = rot * p.b[i];
                data.b_world[i] = bw;
                pulley::cable(data, i, &p.a[i], &(pose.r + bw), pl.radius[i], &pl.axis[i])?;
                set_column(data, i);
            }
        }
    }
    Ok(())
}

/// eq. (2.30): column v_i = [u_i; b_i × u_i] of A^T.
#[inline(always)]
fn set_column(data: &mut Data, i: usize) {
    let u = data.u[i];
    let c = data.b_world[i].cross(&u);
    data.at[i] = Vector6::new(u.x, u.y, u.z, c.x, c.y, c.z);
}

/// Convenience: cable lengths of a pose into `out` (length m).
pub fn lengths(
    model: &Model,
    data: &mut Data,
    pose: &Pose,
    out: &mut [f64],
) -> Result<(), KinematicsError> {
    inverse(model, data, pose)?;
    out.copy_from_slice(&data.q);
    Ok(())
}
