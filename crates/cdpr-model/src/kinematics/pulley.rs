//! Pulley inverse kinematics φ_pl(x, a, b, r_p, u_Az), eq. (2.16)–(2.29).
//!
//! Geometry in the pulley plane (spanned by u_Ax and the swivel axis u_Az, fig. 2.8): the cable
//! runs into the pulley at a_i along +u_Az, tangent to the pulley circle with centre
//! p_M = a_i + r_p u_Ax, wraps by β and leaves at the contact point p_A towards p_B. With
//! b_xy, b_z the in-plane coordinates of p_B − a_i (eq. 2.21):
//!   b_M = sqrt((b_xy − r_p)² + b_z²)                       (eq. 2.20)
//!   β   = atan2(b_xy − r_p, b_z) + acos(q_f / b_M)          (eq. 2.19)
//!   q_f = sqrt(b_M² − r_p²)                                 (eq. 2.22)
//!   p_A = a + r_p((1 − cos β) u_Ax + sin β u_Az)            (eq. 2.23–2.27, Rodrigues)
//!   q   = q_f + β r_p                                       (eq. 2.17, 2.28–2.29)
//! The spec writes the first term of β as acos(b_z / b_M), which equals the atan2 form only
//! for b_xy ≥ r_p; atan2 keeps the sign when p_B passes between axis and pulley centre.
//! The free length and unit vector are taken from l = p_A − p_B itself, so r_p = 0 gives
//! p_A = a and the standard model bit for bit (eq. 2.1).

use super::KinematicsError;
use crate::model::Data;
use nalgebra::Vector3;

#[inline]
pub(crate) fn cable(
    data: &mut Data,
    i: usize,
    a: &Vector3<f64>,
    pb: &Vector3<f64>,
    r_p: f64,
    axis: &Vector3<f64>,
) -> Result<(), KinematicsError> {
    let d = pb - a;
    let b_z = d.dot(axis);
    let d_perp = d - axis * b_z;
    let b_xy = d_perp.norm(); // eq. (2.21)
    let u_x = if b_xy > 1e-12 {
        d_perp / b_xy
    } else if r_p == 0.0 {
        // Pulley plane undefined but irrelevant without a pulley: any normal to the axis.
        any_normal(axis)
    } else {
        return Err(KinematicsError::OnSwivelAxis { cable: i });
    };
    let b_m2 = (b_xy - r_p).powi(2) + b_z * b_z; // eq. (2.20), squared
    let tangent2 = b_m2 - r_p * r_p; // q_f², eq. (2.22)
    if tangent2 <= 0.0 {
        return Err(KinematicsError::InsidePulley { cable: i });
    }
    let q_tan = tangent2.sqrt();
    let beta = (b_xy - r_p).atan2(b_z) + r_p.atan2(q_tan); // eq. (2.19)
    let (sb, cb) = beta.sin_cos();
    let p_a = a + (u_x * (1.0 - cb) + axis * sb) * r_p; // eq. (2.27)
    let l = p_a - pb; // eq. (2.26)
    let q_f = l.norm();
    if q_f <= 0.0 {
        return Err(KinematicsError::DegenerateCable { cable: i });
    }
    data.l[i] = l;
    data.q_free[i] = q_f;
    data.beta[i] = beta;
    data.q[i] = q_f + beta * r_p; // eq. (2.17)
    data.u[i] = l / q_f;
    data.p_exit[i] = p_a;
    data.pulley_ux[i] = u_x;
    data.pulley_bxy[i] = b_xy;
    Ok(())
}

fn any_normal(axis: &Vector3<f64>) -> Vector3<f64> {
    let t = if axis.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let n = t - axis * t.dot(axis);
    n / n.norm()
}
