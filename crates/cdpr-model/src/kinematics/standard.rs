//! Standard inverse kinematics φ(x, a, b), eq. (2.3)–(2.8).

use super::KinematicsError;
use crate::model::Data;
use nalgebra::Vector3;

/// One cable of the standard model: l_i = a_i − r − b_i (eq. 2.5), q_i = ‖l_i‖ (eq. 2.7),
/// u_i = l_i / q_i (eq. 2.8).
#[inline]
pub(crate) fn cable(
    data: &mut Data,
    i: usize,
    a: &Vector3<f64>,
    pb: &Vector3<f64>,
) -> Result<(), KinematicsError> {
    let l = a - pb;
    let q = l.norm();
    if q <= 0.0 {
        return Err(KinematicsError::DegenerateCable { cable: i });
    }
    // β = 0, p_exit = a and the pulley fields are constant for the standard model and set by
    // `Data::new`; only the pose-dependent quantities are written here.
    data.l[i] = l;
    data.q[i] = q;
    data.q_free[i] = q;
    data.u[i] = l / q;
    Ok(())
}
