//! Rigid-body dynamics of the platform for the dynamic wrench (sec. 5.4, eq. 5.13–5.16):
//! w = w_e + w_in, where w_in is the d'Alembert (inertial) wrench of the accelerated platform,
//! taken about the platform's reference point and in world coordinates like w_e and the
//! structure matrix A^T (eq. 2.30). The cables must then hold A^T f + w = 0 instead of the
//! static A^T f + w_e = 0.
//!
//! With c = R c_P the vector from the reference point to the centre of gravity, the COG
//! acceleration is a_c = a + α × c + ω × (ω × c), and (Newton–Euler about the moving point)
//!
//!   w_in = −[ m a_c ;  c × m a_c + I_w α + ω × (I_w ω) ],   I_w = R I_c R^T,
//!
//! with I_c the inertia about the COG in platform coordinates (eq. 5.13–5.14 give it for the
//! helicopter's stator and cabin). Gravity is not part of w_in: it is in w_e (eq. 5.12).

use crate::pose::Pose;
use nalgebra::{Matrix3, Vector3, Vector6};

/// Standard gravity, m/s² (the spec's 7500 N ↔ 764.5 kg of eq. 5.12 uses it).
pub const GRAVITY_M_PER_S2: f64 = 9.81;

/// Mass properties of one rigid body (the cabin, a payload, or their sum).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidBody {
    /// Mass m, kg.
    pub mass_kg: f64,
    /// Centre of gravity c_P in platform coordinates, m.
    pub cog_m: Vector3<f64>,
    /// Inertia tensor about the centre of gravity in platform coordinates, kg·m².
    pub inertia_kg_m2: Matrix3<f64>,
}

/// Why mass properties are not physical.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum BodyError {
    #[error("mass must be a finite number > 0, got {0} kg")]
    Mass(f64),
    #[error("centre of gravity must be finite")]
    Cog,
    #[error(
        "inertia must be finite, symmetric and positive definite with principal moments obeying the triangle inequality"
    )]
    Inertia,
}

impl RigidBody {
    /// Validates mass, COG and inertia (symmetric, positive definite, I₁ + I₂ ≥ I₃ for every
    /// permutation of the principal moments: a real mass distribution).
    pub fn new(
        mass_kg: f64,
        cog_m: Vector3<f64>,
        inertia_kg_m2: Matrix3<f64>,
    ) -> Result<Self, BodyError> {
        if !(mass_kg.is_finite() && mass_kg > 0.0) {
            return Err(BodyError::Mass(mass_kg));
        }
        if !cog_m.iter().all(|v| v.is_finite()) {
            return Err(BodyError::Cog);
        }
        let i = inertia_kg_m2;
        if !i.iter().all(|v| v.is_finite())
            || (i - i.transpose()).abs().max() > 1e-9 * (1.0 + i.abs().max())
        {
            return Err(BodyError::Inertia);
        }
        let ev = i.symmetric_eigenvalues();
        let (a, b, c) = (ev[0], ev[1], ev[2]);
        let tol = 1e-9 * (a.abs() + b.abs() + c.abs());
        if a <= 0.0 || b <= 0.0 || c <= 0.0 || a + b < c - tol || a + c < b - tol || b + c < a - tol
        {
            return Err(BodyError::Inertia);
        }
        Ok(Self {
            mass_kg,
            cog_m,
            inertia_kg_m2,
        })
    }

    /// The rigid union of two bodies: masses add, the COG is the mass-weighted mean, the
    /// inertias move to the common COG by the parallel-axis theorem (Steiner):
    /// I = Σ I_k + m_k (|d_k|² E − d_k d_kᵀ), d_k = c_k − c.
    pub fn combined(&self, other: &RigidBody) -> RigidBody {
        let m = self.mass_kg + other.mass_kg;
        let c = (self.cog_m * self.mass_kg + other.cog_m * other.mass_kg) / m;
        let steiner = |b: &RigidBody| {
            let d = b.cog_m - c;
            b.inertia_kg_m2
                + (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * b.mass_kg
        };
        RigidBody {
            mass_kg: m,
            cog_m: c,
            inertia_kg_m2: steiner(self) + steiner(other),
        }
    }

    /// The static wrench of the body's weight about the reference point at orientation
    /// `pose` (world frame): [0, 0, −m g; c × (0, 0, −m g)], the part of w_e it explains.
    pub fn weight_wrench(&self, pose: &Pose) -> Vector6<f64> {
        let f = Vector3::new(0.0, 0.0, -self.mass_kg * GRAVITY_M_PER_S2);
        let c = pose.rotation() * self.cog_m;
        let t = c.cross(&f);
        Vector6::new(f.x, f.y, f.z, t.x, t.y, t.z)
    }
}

/// The platform's motion at one instant, world frame: reference-point acceleration a (m/s²),
/// angular velocity ω (rad/s) and angular acceleration α (rad/s²).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Motion {
    pub acceleration: Vector3<f64>,
    pub angular_velocity: Vector3<f64>,
    pub angular_acceleration: Vector3<f64>,
}

/// The inertial (d'Alembert) wrench w_in of `body` at `pose` in `motion` (module docs; eq.
/// 5.13–5.16: T_M = I_z α is its yaw row at rest). Allocation-free, a few dozen flops: it runs
/// in the 1 ms loop.
#[inline]
pub fn inertial_wrench(body: &RigidBody, pose: &Pose, motion: &Motion) -> Vector6<f64> {
    let r = pose.rotation();
    let c = r * body.cog_m;
    let (w, al) = (motion.angular_velocity, motion.angular_acceleration);
    let a_c = motion.acceleration + al.cross(&c) + w.cross(&w.cross(&c));
    let f = a_c * body.mass_kg;
    let i_w = r * body.inertia_kg_m2 * r.transpose();
    let t = c.cross(&f) + i_w * al + w.cross(&(i_w * w));
    Vector6::new(-f.x, -f.y, -f.z, -t.x, -t.y, -t.z)
}

/// The linear map (a, α) ↦ w_in at `pose` with ω = 0 (the spatial inertia about the
/// reference point, negated): w_in = −M(x) [a; α] + (ω terms). Used to bound the inertial
/// wrench over all accelerations within limits (motion-core's feasible planner limits).
pub fn spatial_inertia(body: &RigidBody, pose: &Pose) -> nalgebra::Matrix6<f64> {
    let r = pose.rotation();
    let c = r * body.cog_m;
    let cx = crate::pose::skew(&c);
    let m = body.mass_kg;
    let i_w = r * body.inertia_kg_m2 * r.transpose();
    let mut s = nalgebra::Matrix6::zeros();
    // force = m (a + α × c) = m a − m c̃ α
    s.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(Matrix3::identity() * m));
    s.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-cx * m));
    // torque = c × force + I_w α = m c̃ a − m c̃ c̃ α + I_w α
    s.fixed_view_mut::<3, 3>(3, 0).copy_from(&(cx * m));
    s.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(i_w - cx * cx * m));
    s
}

/// How far the accelerations may go so that the closed-form forces (eq. 3.41) of the dynamic
/// wrench stay within [f_min, f_max] over a set of poses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccelerationScale {
    /// Largest s ≥ 0 (∞ when no pose bounds it) such that every pose stays feasible for every linear acceleration
    /// |a| ≤ s·a_max, angular acceleration |α| ≤ s·α_max and angular velocity |ω| ≤ ω_max.
    pub scale: f64,
    /// The pose and cable that bound it (index into the poses given).
    pub pose_index: usize,
    pub cable: usize,
}

/// Why no acceleration is feasible.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ScaleError {
    #[error("pose {pose_index}: inverse kinematics or the structure matrix failed")]
    Singular { pose_index: usize },
    #[error(
        "pose {pose_index}: cable {} leaves [f_min, f_max] already at rest (static wrench) or at the largest angular velocity",
        cable + 1
    )]
    NotFeasibleAtRest { pose_index: usize, cable: usize },
}

/// The largest acceleration scale that keeps every pose of `poses` wrench feasible with the
/// dynamic wrench w = w_e + w_in (eq. 3.29, 3.41, 5.13–5.16), worst case over the ball of
/// accelerations: the closed form is affine in w, f = f(w_e) − A^{+T} w_in, and w_in is linear
/// in (a, α) (−M(x)[a; α], [`spatial_inertia`]) plus the ω terms, so per cable i with
/// g_i = row i of A^{+T} M(x):
///   |Δf_i| ≤ s (‖g_i,a‖ a_max + ‖g_i,α‖ α_max) + ‖row_i A^{+T}‖ ω_max² (m |c| (1 + |c|) + (λ_max − λ_min)/2).
/// Exact for the loop's check at each given pose (not between them: the loop still checks
/// every reference). Poses whose static margin (eq. 3.41 with w_e alone) is below
/// `min_static_margin_n` are left out: near the border of the static wrench-feasible set no
/// acceleration at all is feasible, so including them would allow none anywhere; the loop
/// refuses an acceleration there that does not fit. Allocates (call it at configure time).
pub fn feasible_acceleration_scale(
    model: &crate::Model,
    body: &RigidBody,
    poses: &[Pose],
    min_static_margin_n: f64,
    a_max: f64,
    alpha_max: f64,
    omega_max: f64,
) -> Result<AccelerationScale, ScaleError> {
    let p = model.params();
    let mut data = crate::Data::new(model);
    let mut f0 = vec![0.0; model.m()];
    let ev = body.inertia_kg_m2.symmetric_eigenvalues();
    let lam_spread = 0.5 * (ev.max() - ev.min());
    let mut best = AccelerationScale {
        scale: f64::INFINITY,
        pose_index: 0,
        cable: 0,
    };
    for (k, pose) in poses.iter().enumerate() {
        crate::kinematics::inverse(model, &mut data, pose)
            .map_err(|_| ScaleError::Singular { pose_index: k })?;
        let fd = crate::statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f0)
            .map_err(|_| ScaleError::Singular { pose_index: k })?;
        if fd.margin < min_static_margin_n {
            continue;
        }
        let chol = crate::statics::gram(&data)
            .cholesky()
            .ok_or(ScaleError::Singular { pose_index: k })?;
        let inv = chol.inverse();
        let s_x = spatial_inertia(body, pose);
        let c = body.cog_m.norm();
        // ‖ω × (I ω)‖ = ‖ω × (I − λ̄E) ω‖ ≤ ω² (λ_max − λ_min)/2, λ̄ the mid eigenvalue range;
        // ‖m ω × (ω × c)‖ ≤ m ω² |c|, its torque c × (·) adds |c| times that.
        let omega_w = omega_max * omega_max * (body.mass_kg * c * (1.0 + c) + lam_spread);
        for (i, at) in data.at.iter().enumerate() {
            // row i of A^{+T} = a_iᵀ (AᵀA)⁻¹
            let row = at.transpose() * inv;
            let g = row * s_x;
            let reach =
                g.fixed_columns::<3>(0).norm() * a_max + g.fixed_columns::<3>(3).norm() * alpha_max;
            let slack = (f0[i] - p.f_min).min(p.f_max - f0[i]) - row.norm() * omega_w;
            if slack < 0.0 {
                return Err(ScaleError::NotFeasibleAtRest {
                    pose_index: k,
                    cable: i,
                });
            }
            if reach > 0.0 && slack / reach < best.scale {
                best = AccelerationScale {
                    scale: slack / reach,
                    pose_index: k,
                    cable: i,
                };
            }
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn heli() -> RigidBody {
        // eq. 5.12–5.14: 7500 N, COG 0.08 m towards −x, I_st + I_hc.
        RigidBody::new(
            7500.0 / GRAVITY_M_PER_S2,
            Vector3::new(-0.08, 0.0, 0.0),
            Matrix3::from_diagonal(&Vector3::new(90.8 + 117.0, 87.0 + 121.0, 4.7 + 62.5)),
        )
        .unwrap()
    }

    #[test]
    fn yaw_acceleration_of_the_cabin_needs_the_torque_of_eq_5_16() {
        // eq. 5.14–5.16: I_hc,z α_max = 62.5 kg m² × 300°/s² = 327 N m (the cabin alone, at
        // its COG on the yaw axis).
        let cabin = RigidBody::new(
            700.0,
            Vector3::zeros(),
            Matrix3::from_diagonal(&Vector3::new(117.0, 121.0, 62.5)),
        )
        .unwrap();
        let m = Motion {
            angular_acceleration: Vector3::new(0.0, 0.0, 300f64.to_radians()),
            ..Motion::default()
        };
        let w = inertial_wrench(&cabin, &Pose::default(), &m);
        assert!((w[5] + 327.2).abs() < 0.1, "{w}");
        assert!(w.fixed_rows::<5>(0).norm() < 1e-9);
    }

    #[test]
    fn inertial_wrench_is_the_rate_of_momentum_by_finite_differences() {
        // Integrate a rigid motion and compare −d/dt of linear momentum and of angular momentum
        // about the (moving) reference point with w_in (Newton–Euler about a moving point:
        // τ_P = dL_P/dt + v_P × m v_c).
        let b = RigidBody::new(
            500.0,
            Vector3::new(0.1, -0.2, 0.3),
            Matrix3::new(120.0, 5.0, -3.0, 5.0, 100.0, 2.0, -3.0, 2.0, 60.0),
        )
        .unwrap();
        let pose = |t: f64| {
            Pose::new(
                Vector3::new(0.3 * t * t, -0.1 * t, 0.2 * (t * 2.0).sin()),
                Vector3::new(0.1 * (t * 1.5).sin(), 0.05 * t, -0.08 * t * t),
            )
        };
        let t = 0.4;
        let h = 1e-4;
        // Linear momentum p = m v_c, angular momentum about P: L_P = c × m v_c + I_w ω.
        let state = |t: f64| {
            let (p0, p1) = (pose(t - 1e-6), pose(t + 1e-6));
            let v = (p1.r - p0.r) / 2e-6;
            let r0 = p0.rotation();
            let r1 = p1.rotation();
            let rd = (r1 - r0) / 2e-6;
            let rr = pose(t).rotation();
            let wx = rd * rr.transpose();
            let w = Vector3::new(wx[(2, 1)], wx[(0, 2)], wx[(1, 0)]);
            let c = rr * b.cog_m;
            let vc = v + w.cross(&c);
            let i_w = rr * b.inertia_kg_m2 * rr.transpose();
            (v, w, vc * b.mass_kg, c.cross(&(vc * b.mass_kg)) + i_w * w)
        };
        let (v, w, _, _) = state(t);
        let (_, w0, p0, l0) = state(t - h);
        let (_, w1, p1, l1) = state(t + h);
        let f = (p1 - p0) / (2.0 * h);
        let tau = (l1 - l0) / (2.0 * h) + v.cross(&(state(t).2));
        let a = (state(t + h).0 - state(t - h).0) / (2.0 * h);
        let m = Motion {
            acceleration: a,
            angular_velocity: w,
            angular_acceleration: (w1 - w0) / (2.0 * h),
        };
        let w_in = inertial_wrench(&b, &pose(t), &m);
        for k in 0..3 {
            assert!(
                (w_in[k] + f[k]).abs() < 1e-3 * (1.0 + f[k].abs()),
                "force {k}: {w_in} vs {f}"
            );
            assert!(
                (w_in[3 + k] + tau[k]).abs() < 1e-3 * (1.0 + tau[k].abs()),
                "torque {k}: {w_in} vs {tau}"
            );
        }
        // The spatial inertia is the ω-free part.
        let m0 = Motion {
            angular_velocity: Vector3::zeros(),
            ..m
        };
        let lin = -spatial_inertia(&b, &pose(t))
            * Vector6::new(
                a.x,
                a.y,
                a.z,
                m.angular_acceleration.x,
                m.angular_acceleration.y,
                m.angular_acceleration.z,
            );
        assert!((lin - inertial_wrench(&b, &pose(t), &m0)).norm() < 1e-9);
    }

    #[test]
    fn combining_bodies_keeps_mass_cog_and_moves_inertia_by_steiner() {
        let a = RigidBody::new(
            100.0,
            Vector3::new(1.0, 0.0, 0.0),
            Matrix3::identity() * 10.0,
        )
        .unwrap();
        let b = RigidBody::new(
            100.0,
            Vector3::new(-1.0, 0.0, 0.0),
            Matrix3::identity() * 10.0,
        )
        .unwrap();
        let s = a.combined(&b);
        assert_eq!(s.mass_kg, 200.0);
        assert!(s.cog_m.norm() < 1e-12);
        // Two point masses 1 m off the axis: +2 × 100 kg m² about y and z, nothing about x.
        assert!(
            (s.inertia_kg_m2 - Matrix3::from_diagonal(&Vector3::new(20.0, 220.0, 220.0))).norm()
                < 1e-9
        );
        assert!(
            RigidBody::new(
                1.0,
                Vector3::zeros(),
                Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 3.0))
            )
            .is_err()
        );
        assert!(RigidBody::new(-1.0, Vector3::zeros(), Matrix3::identity()).is_err());
        // The helicopter's weight wrench is eq. 5.12's.
        let w = heli().weight_wrench(&Pose::default());
        assert!(
            (w - Vector6::new(0.0, 0.0, -7500.0, 0.0, -600.0, 0.0)).norm() < 1e-9,
            "{w}"
        );
    }
}
