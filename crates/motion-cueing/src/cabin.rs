//! What a rider in the cabin feels, from the cabin's pose coordinates and their first two time
//! derivatives: the specific force at the head and the angular velocity, in cabin axes (the
//! rider faces the cabin's +x axis, +z up), the same quantities a vehicle's IMU records.
//!
//!   ω = J_P(φ) φ̇,   α = J_P φ̈ + J̇_P φ̇             (eq. 2.45–2.46)
//!   a_h = r̈ + α × r_h + ω × (ω × r_h),  r_h = R h   (h: head in cabin coordinates)
//!   f = Rᵀ (a_h − g),  ω_cabin = Rᵀ ω,  g = [0, 0, −g]
//!
//! with R = R_x R_y R_z (eq. 2.2). J̇_P φ̇ follows from J_P = [e_x, R_x e_y, R_x R_y e_z]:
//! d(R_x e_y)/dt = φ̇_x e_x × R_x e_y and d(R_x R_y e_z)/dt = (φ̇_x e_x + φ̇_y R_x e_y) × R_x R_y e_z.

use cdpr_model::Pose;
use cdpr_model::dynamics::GRAVITY_M_PER_S2;
use cdpr_model::pose::{rot_x, rot_y};
use nalgebra::Vector3;

/// Specific force (m/s²) at the head and angular velocity (rad/s), cabin axes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Felt {
    pub specific_force: Vector3<f64>,
    pub angular_velocity: Vector3<f64>,
}

/// What the rider with the head at `head` (cabin coordinates, m) feels at `pose` moving with
/// pose-coordinate velocity `vel` and acceleration `acc` ([ṙ; φ̇], [r̈; φ̈]).
pub fn felt(pose: &Pose, vel: &[f64; 6], acc: &[f64; 6], head: &Vector3<f64>) -> Felt {
    let r = pose.rotation();
    let jp = pose.angle_jacobian();
    let phi_dot = Vector3::new(vel[3], vel[4], vel[5]);
    let phi_ddot = Vector3::new(acc[3], acc[4], acc[5]);
    let omega = jp * phi_dot;
    let rx = rot_x(pose.phi.x);
    let ey = rx * Vector3::y();
    let ez = rx * rot_y(pose.phi.y) * Vector3::z();
    let jdot_phidot = phi_dot.y * (phi_dot.x * Vector3::x()).cross(&ey)
        + phi_dot.z * (phi_dot.x * Vector3::x() + phi_dot.y * ey).cross(&ez);
    let alpha = jp * phi_ddot + jdot_phidot;
    let rh = r * head;
    let a =
        Vector3::new(acc[0], acc[1], acc[2]) + alpha.cross(&rh) + omega.cross(&omega.cross(&rh));
    let g = Vector3::new(0.0, 0.0, -GRAVITY_M_PER_S2);
    Felt {
        specific_force: r.transpose() * (a - g),
        angular_velocity: r.transpose() * omega,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn at_rest_level_the_rider_feels_gravity_and_a_pitch_down_feels_like_braking() {
        let h = Vector3::new(0.0, 0.0, 0.5);
        let z = [0.0; 6];
        let f = felt(
            &Pose::new(Vector3::new(0.0, 0.0, 2.0), Vector3::zeros()),
            &z,
            &z,
            &h,
        );
        assert!((f.specific_force - Vector3::new(0.0, 0.0, GRAVITY_M_PER_S2)).norm() < 1e-12);
        // Pitched nose-down by θ (φ_y > 0): gravity pulls the rider forward, f_x = −g sin θ,
        // as a braking car's deceleration does.
        let th = 3f64.to_radians();
        let f = felt(
            &Pose::new(Vector3::zeros(), Vector3::new(0.0, th, 0.0)),
            &z,
            &z,
            &h,
        );
        assert!((f.specific_force.x + GRAVITY_M_PER_S2 * th.sin()).abs() < 1e-12);
        // Rolled by φ_x > 0: f_y = g sin φ, as a left turn's centripetal acceleration.
        let f = felt(
            &Pose::new(Vector3::zeros(), Vector3::new(th, 0.0, 0.0)),
            &z,
            &z,
            &h,
        );
        assert!((f.specific_force.y - GRAVITY_M_PER_S2 * th.sin()).abs() < 1e-12);
    }

    #[test]
    fn angular_terms_match_finite_differences_of_the_head_position() {
        // A pose trajectory; the head's world acceleration from second differences of its
        // position must equal a_h, and Rᵀ ω the body rate from the rotation's derivative.
        let h = Vector3::new(0.2, -0.1, 0.6);
        let traj = |t: f64| {
            Pose::new(
                Vector3::new(0.3 * t.sin(), 0.1 * t * t, 2.0),
                Vector3::new(0.05 * (2.0 * t).sin(), 0.04 * t.cos(), 0.06 * t),
            )
        };
        let deriv = |t: f64| -> ([f64; 6], [f64; 6]) {
            let v = [
                0.3 * t.cos(),
                0.2 * t,
                0.0,
                0.1 * (2.0 * t).cos(),
                -0.04 * t.sin(),
                0.06,
            ];
            let a = [
                -0.3 * t.sin(),
                0.2,
                0.0,
                -0.2 * (2.0 * t).sin(),
                -0.04 * t.cos(),
                0.0,
            ];
            (v, a)
        };
        let t = 0.7;
        let eps = 1e-4;
        let head = |t: f64| {
            let p = traj(t);
            p.r + p.rotation() * h
        };
        let a_fd = (head(t + eps) - 2.0 * head(t) + head(t - eps)) / (eps * eps);
        let (v, a) = deriv(t);
        let p = traj(t);
        let f = felt(&p, &v, &a, &h);
        let g = Vector3::new(0.0, 0.0, -GRAVITY_M_PER_S2);
        let f_fd = p.rotation().transpose() * (a_fd - g);
        assert!(
            (f.specific_force - f_fd).norm() < 1e-5,
            "{} vs {}",
            f.specific_force,
            f_fd
        );
        // Body rate: skew(ω_b) = Rᵀ Ṙ.
        let rd = (traj(t + eps).rotation() - traj(t - eps).rotation()) / (2.0 * eps);
        let s = p.rotation().transpose() * rd;
        let wb = Vector3::new(s[(2, 1)], s[(0, 2)], s[(1, 0)]);
        assert!((f.angular_velocity - wb).norm() < 1e-7);
    }
}
