//! Differential kinematics (sec. 2.5) and the differential pulley model (sec. 2.7).
//!
//! All pose Jacobians are taken with respect to the twist δx = [δr; ω] of eq. (2.44), as in
//! the spec; multiply from the right by [`crate::pose::twist_from_coordinates`] to get them with
//! respect to the pose coordinates (δr, δφ). Every function expects `data` to hold the inverse
//! kinematics of the pose (see [`super::inverse`]).

use crate::model::{Data, Model};
use crate::pose::{Pose, skew};
use nalgebra::{Matrix3, Matrix3x6, RowVector3, RowVector6};

/// ∂p_B,i/∂x = [I  −b̃_i] (eq. 2.48).
pub fn anchor_jacobian(data: &Data, i: usize) -> Matrix3x6<f64> {
    let mut j = Matrix3x6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    j.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-skew(&data.b_world[i])));
    j
}

/// Row i of ∂q/∂x = −A (eq. 2.52–2.54): −[u_i^T  (b_i × u_i)^T]. Holds for the pulley model
/// with u_i taken at the contact point (sec. 2.7: arc and free length differentials cancel).
pub fn length_jacobian_row(data: &Data, i: usize) -> RowVector6<f64> {
    -data.at[i].transpose()
}

/// ∂p_A,i/∂x of the pulley model (eq. 2.86): the out-of-plane part swivels the pulley,
/// n_M (b_a / b_xy) n_M^T J_pB with b_a = r_p (1 − cos β) the distance of p_A from the axis;
/// the in-plane part rolls the contact point along the circle, r_p t ∂β/∂x. Zero for the
/// standard model (a_i is fixed).
pub fn contact_point_jacobian(model: &Model, data: &Data, i: usize) -> Matrix3x6<f64> {
    let Some(pl) = &model.params().pulleys else {
        return Matrix3x6::zeros();
    };
    let r_p = pl.radius[i];
    if r_p == 0.0 {
        return Matrix3x6::zeros();
    }
    let az = pl.axis[i];
    let ux = data.pulley_ux[i];
    let n_m = ux.cross(&az);
    let beta = data.beta[i];
    let t = -data.u[i]; // direction from p_A to p_B
    let jpb = anchor_jacobian(data, i);
    let b_a = r_p * (1.0 - beta.cos());
    let swivel = n_m * (n_m.transpose() * jpb) * (b_a / data.pulley_bxy[i]);
    let roll = t * wrap_angle_jacobian(model, data, i) * r_p;
    swivel + roll
}

/// ∂β_i/∂x: δβ = −(n · δp_B) / q_f with n = −cos β u_Ax + sin β u_Az the in-plane normal of
/// the free cable (from the rolling geometry behind eq. 2.83–2.84). Zero for the standard model.
pub fn wrap_angle_jacobian(model: &Model, data: &Data, i: usize) -> RowVector6<f64> {
    let Some(pl) = &model.params().pulleys else {
        return RowVector6::zeros();
    };
    let (sb, cb) = data.beta[i].sin_cos();
    let n = data.pulley_ux[i] * (-cb) + pl.axis[i] * sb;
    -(n.transpose() * anchor_jacobian(data, i)) / data.q_free[i]
}

/// Jacobian of the wound arc length q_u = β r_p (eq. 2.85).
pub fn arc_length_jacobian(model: &Model, data: &Data, i: usize) -> RowVector6<f64> {
    let r_p = model
        .params()
        .pulleys
        .as_ref()
        .map_or(0.0, |pl| pl.radius[i]);
    wrap_angle_jacobian(model, data, i) * r_p
}

/// Jacobian of the free cable length q_f: ∂q/∂x − ∂q_u/∂x (eq. 2.28 differentiated).
pub fn free_length_jacobian(model: &Model, data: &Data, i: usize) -> RowVector6<f64> {
    length_jacobian_row(data, i) - arc_length_jacobian(model, data, i)
}

/// ∂l_i/∂x = J_pA − J_pB (eq. 2.87; for the standard model [−I  b̃_i], eq. 2.50).
pub fn cable_vector_jacobian(model: &Model, data: &Data, i: usize) -> Matrix3x6<f64> {
    contact_point_jacobian(model, data, i) - anchor_jacobian(data, i)
}

/// ∂u_i/∂x = (1/q_f)(I − u u^T) ∂l_i/∂x (eq. 2.62–2.64); for the standard model this is
/// (1/q)(u u^T − I)[I  −b̃_i] (eq. 2.65).
pub fn unit_vector_jacobian(model: &Model, data: &Data, i: usize) -> Matrix3x6<f64> {
    let u = data.u[i];
    let proj = Matrix3::identity() - u * u.transpose();
    proj * cable_vector_jacobian(model, data, i) / data.q_free[i]
}

/// ∂q_i/∂(a_i, b_i^(P)) = u_i^T [I  −R_0P] (eq. 4.5–4.6). Returns the two 1×3 blocks. Also
/// valid for the pulley model: moving a_i moves the whole pulley, so q depends on p_B − a_i
/// only and ∂q/∂a_i = −∂q/∂p_B = u_i^T.
pub fn length_parameter_jacobian(
    data: &Data,
    pose: &Pose,
    i: usize,
) -> (RowVector3<f64>, RowVector3<f64>) {
    let ut = data.u[i].transpose();
    (ut, -(ut * pose.rotation()))
}
