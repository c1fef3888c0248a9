//! The work of one 1 ms cycle: check the reference pose, compute q_θ = φ(x) + φ_sg(x)
//! (eq. 2.3 + eq. 5.26) and the cable velocities q̇ = −A ẋ (eq. 2.54), fill the setpoint.
//! Allocation-free and lock-free; every rejection is a typed value.

use cdpr_model::config::{MotionLimits, Region};
use cdpr_model::dynamics::{Motion, RigidBody, inertial_wrench};
use cdpr_model::kinematics;
use cdpr_model::model::{Data, Model};
use cdpr_model::pose::{Pose, twist_from_coordinates};
use cdpr_model::statics;
use crs_ipc::{CONTRACT_VERSION, JointSetpoint, MAX_CABLES};
use nalgebra::Vector6;

/// Offset model added to the standard kinematics (the polynomial surrogate, eq. 5.23).
pub trait OffsetModel: Send {
    /// Writes φ_sg(x) (m) for each cable into `out`; false when it cannot.
    fn offsets(&self, x: &[f64; 6], out: &mut [f64]) -> bool;
    /// Largest |offset| the model can produce over its region, m (proven at fit time).
    fn bound_m(&self) -> f64;
}

impl OffsetModel for surrogate::Surrogate {
    #[inline]
    fn offsets(&self, x: &[f64; 6], out: &mut [f64]) -> bool {
        self.eval(x, out).is_ok()
    }
    fn bound_m(&self) -> f64 {
        self.report().certified_bound_mm * 1e-3
    }
}

/// One reference sample from the trajectory generator or the motion-cueing stream.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Reference {
    pub pose: Pose,
    /// Pose-coordinate velocity [ṙ; φ̇], m/s and rad/s.
    pub velocity: [f64; 6],
    /// Pose-coordinate acceleration, m/s² and rad/s².
    pub acceleration: [f64; 6],
}

/// Why a reference was refused (the loop then holds the last safe setpoint and latches).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum Rejection {
    #[error("reference is not finite")]
    NonFinite,
    #[error("reference pose outside the configured workspace region")]
    OutsideRegion,
    #[error("reference not wrench feasible (eq. 3.29 with w = w_e + w_in when dynamic): cable {} would need {force_n:.1} N", cable + 1)]
    NotWrenchFeasible { cable: usize, force_n: f64 },
    #[error("linear velocity {value:.3} m/s exceeds the limit")]
    LinearVelocity { value: f64 },
    #[error("angular velocity {value:.3} rad/s exceeds the limit")]
    AngularVelocity { value: f64 },
    #[error("linear acceleration {value:.3} m/s² exceeds the limit")]
    LinearAcceleration { value: f64 },
    #[error("angular acceleration {value:.3} rad/s² exceeds the limit")]
    AngularAcceleration { value: f64 },
    #[error("inverse kinematics failed at the reference pose")]
    Kinematics,
    #[error("surrogate offset unavailable or beyond its bound on cable {cable}")]
    Surrogate { cable: usize },
}

/// Why [`Cycle::set_surrogate`] refused a surrogate.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum SurrogateRejected {
    #[error("surrogate has {surrogate} cables, the platform {platform}")]
    CableCount { surrogate: usize, platform: usize },
    #[error(
        "surrogate offsets can reach {:.1} mm, above the {:.0} mm bound of eq. 5.27",
        bound_m * 1e3,
        DELTA_Q_LIMIT_M * 1e3
    )]
    Bound { bound_m: f64 },
}

/// Preallocated state of the cycle computation (Model/Data split).
pub struct Cycle {
    model: Model,
    data: Data,
    limits: MotionLimits,
    region: Region,
    surrogate: Option<Box<dyn OffsetModel>>,
    /// Largest offset accepted from the surrogate (≤ 100 mm, eq. 5.27).
    offset_limit_m: f64,
    /// Check eq. 3.29 with the closed-form forces every cycle (≈ 0.4 µs).
    check_feasibility: bool,
    /// Mass properties for the dynamic wrench w = w_e + w_in (eq. 5.13–5.16); `None` checks
    /// the static wrench w_e only.
    dynamics: Option<RigidBody>,
    /// Tolerance on the limits for rounding in the trajectory generator (1 + this).
    limit_tolerance: f64,
    forces: Vec<f64>,
    offsets: Vec<f64>,
}

/// ≤ 100 mm: the safety monitor's threshold (sec. 5.6, eq. 5.27).
pub use crs_limits::DELTA_Q_LIMIT_M;

impl Cycle {
    pub fn new(
        model: Model,
        limits: MotionLimits,
        region: Region,
        check_feasibility: bool,
    ) -> Self {
        let m = model.m();
        assert!(m <= MAX_CABLES, "more cables than the IPC payload carries");
        Self {
            data: Data::new(&model),
            model,
            limits,
            region,
            surrogate: None,
            offset_limit_m: DELTA_Q_LIMIT_M,
            check_feasibility,
            dynamics: None,
            limit_tolerance: 1e-6,
            forces: vec![0.0; m],
            offsets: vec![0.0; m],
        }
    }

    /// Installs the surrogate offset model; refuses one whose proven bound can exceed the
    /// 100 mm safety threshold (eq. 5.27) or that was fitted for another number of cables.
    pub fn set_surrogate(
        &mut self,
        s: Box<dyn OffsetModel>,
        n_cables: usize,
    ) -> Result<(), SurrogateRejected> {
        if n_cables != self.model.m() {
            return Err(SurrogateRejected::CableCount {
                surrogate: n_cables,
                platform: self.model.m(),
            });
        }
        let b = s.bound_m();
        if !(b.is_finite() && b < DELTA_Q_LIMIT_M) {
            return Err(SurrogateRejected::Bound { bound_m: b });
        }
        self.surrogate = Some(s);
        Ok(())
    }

    pub fn has_surrogate(&self) -> bool {
        self.surrogate.is_some()
    }

    /// Checks (and distributes forces for) the dynamic wrench w = w_e + w_in of the reference
    /// (eq. 5.13–5.16) instead of the static w_e: `Some(body)` with the platform's mass
    /// properties, `None` for the static check.
    pub fn set_dynamics(&mut self, body: Option<RigidBody>) {
        self.dynamics = body;
    }

    /// The mass properties of the dynamic check, if on.
    pub fn dynamics(&self) -> Option<&RigidBody> {
        self.dynamics.as_ref()
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Checks `r` and writes the setpoint (everything but sequence and timestamp).
    pub fn compute(&mut self, r: &Reference, out: &mut JointSetpoint) -> Result<(), Rejection> {
        let pose = r.pose;
        if !pose.is_finite()
            || !r
                .velocity
                .iter()
                .chain(&r.acceleration)
                .all(|v| v.is_finite())
        {
            return Err(Rejection::NonFinite);
        }
        if !self.region.contains(&pose) {
            return Err(Rejection::OutsideRegion);
        }
        // Velocity and acceleration limits (table 5.1) on the twist [ṙ; ω], ω = J_P φ̇.
        let t = twist_from_coordinates(&pose);
        let v = t * Vector6::from_column_slice(&r.velocity);
        let a = t * Vector6::from_column_slice(&r.acceleration);
        let tol = 1.0 + self.limit_tolerance;
        let (vl, vw) = (v.fixed_rows::<3>(0).norm(), v.fixed_rows::<3>(3).norm());
        if vl > self.limits.linear_velocity_max * tol {
            return Err(Rejection::LinearVelocity { value: vl });
        }
        if vw > self.limits.angular_velocity_max * tol {
            return Err(Rejection::AngularVelocity { value: vw });
        }
        let (al, aw) = (a.fixed_rows::<3>(0).norm(), a.fixed_rows::<3>(3).norm());
        if al > self.limits.linear_acceleration_max * tol {
            return Err(Rejection::LinearAcceleration { value: al });
        }
        if aw > self.limits.angular_acceleration_max * tol {
            return Err(Rejection::AngularAcceleration { value: aw });
        }
        // q = φ(x), eq. (2.3)-(2.8).
        kinematics::inverse(&self.model, &mut self.data, &pose)
            .map_err(|_| Rejection::Kinematics)?;
        if self.check_feasibility {
            let p = self.model.params();
            // w = w_e + w_in (eq. 5.13–5.16): the cables must also accelerate the platform.
            // α = J_P φ̈ drops the J̇_P φ̇ term (≤ |φ̇|² sin φ: < 1 % of the limits here).
            let w = match &self.dynamics {
                None => p.w_e,
                Some(body) => {
                    let motion = Motion {
                        acceleration: a.fixed_rows::<3>(0).into_owned(),
                        angular_velocity: v.fixed_rows::<3>(3).into_owned(),
                        angular_acceleration: a.fixed_rows::<3>(3).into_owned(),
                    };
                    p.w_e + inertial_wrench(body, &pose, &motion)
                }
            };
            let fd =
                statics::force_distribution(&self.data, &w, p.f_min, p.f_max, &mut self.forces)
                    .map_err(|_| Rejection::Kinematics)?;
            if !fd.feasible {
                let (cable, force_n) = if fd.f_lo < p.f_min {
                    (fd.cable_lo, fd.f_lo)
                } else {
                    (fd.cable_hi, fd.f_hi)
                };
                return Err(Rejection::NotWrenchFeasible { cable, force_n });
            }
        }
        // φ_sg(x), eq. (5.23)-(5.27): zero without a surrogate.
        let m = self.model.m();
        match &self.surrogate {
            Some(s) => {
                if !s.offsets(&pose.to_array(), &mut self.offsets) {
                    return Err(Rejection::Surrogate { cable: 0 });
                }
                if let Some(c) = self
                    .offsets
                    .iter()
                    .position(|o| o.is_nan() || o.abs() >= self.offset_limit_m)
                {
                    return Err(Rejection::Surrogate { cable: c });
                }
            }
            None => self.offsets.iter_mut().for_each(|o| *o = 0.0),
        }
        out.version = CONTRACT_VERSION;
        out.cable_count = m as u32;
        out.pose = pose.to_array();
        out.pose_velocity = r.velocity;
        for i in 0..MAX_CABLES {
            if i < m {
                out.cable_length_m[i] = self.data.q[i] + self.offsets[i];
                out.surrogate_offset_m[i] = self.offsets[i];
                // q̇ = −A ẋ (eq. 2.54), with the twist ẋ = [ṙ; ω].
                out.cable_velocity_m_per_s[i] = -self.data.at[i].dot(&v);
            } else {
                out.cable_length_m[i] = 0.0;
                out.surrogate_offset_m[i] = 0.0;
                out.cable_velocity_m_per_s[i] = 0.0;
            }
        }
        Ok(())
    }
}
