//! What the oracle is told about a robot: cables (frame exit, platform anchor, optional
//! pulley, specific stiffness) and a conservative load.

use glam::DVec3;

/// A pulley at the frame exit point: the rope arrives travelling along `axis` and wraps over
/// a circle of `radius` lying in the plane of the axis and the platform anchor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pulley {
    /// Pulley radius, m (> 0; use no pulley for a point exit).
    pub radius: f64,
    /// Swivel axis, world frame (normalised by [`Robot::new`]).
    pub axis: DVec3,
}

/// One elastic cable.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cable {
    /// Frame exit point a_i, world frame, m.
    pub frame_exit: DVec3,
    /// Platform anchor b_i, platform frame, m.
    pub anchor: DVec3,
    pub pulley: Option<Pulley>,
    /// Specific stiffness k_F = EA, N: the cable of unstretched (controlled) length q_θ pulls
    /// with f = k_F (q − q_θ)/q at length q (eq. 2.33–2.36), nothing when q ≤ q_θ.
    pub k_f: f64,
}

/// A load with a potential: `mass` at `center_of_gravity` (platform frame) under `gravity`
/// along −z, plus a constant world-frame `force`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Load {
    pub mass: f64,
    pub center_of_gravity: DVec3,
    pub gravity: f64,
    pub force: DVec3,
}

/// Why the oracle cannot answer.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum OracleError {
    #[error("cable {cable}: {field} is not finite or out of range")]
    BadInput { cable: usize, field: &'static str },
    #[error("load: {0} is not finite")]
    BadLoad(&'static str),
    #[error(
        "the load has a constant torque of {0:.3} N·m: a constant world torque has no potential, \
         the energy formulation cannot represent it"
    )]
    TorqueNotConservative(f64),
    #[error("expected {expected} controlled lengths, got {got}")]
    WrongLength { expected: usize, got: usize },
    #[error("cable {cable}: the anchor lies inside its pulley or on the swivel axis")]
    PulleyGeometry { cable: usize },
    #[error("every cable is slack at the minimum: the platform has no equilibrium")]
    AllSlack,
    #[error("no minimum after {iterations} Newton steps (last step {last_step:.3e})")]
    NotConverged { iterations: usize, last_step: f64 },
}

/// The robot the oracle solves. Immutable after [`Robot::new`].
#[derive(Clone, Debug, PartialEq)]
pub struct Robot {
    pub(crate) cables: Vec<Cable>,
    pub(crate) load: Load,
}

impl Robot {
    /// Checks and stores the robot. `constant_torque` is the norm of any constant world-frame
    /// torque the caller's load carries: non-zero is refused (see the crate docs).
    pub fn new(cables: Vec<Cable>, load: Load, constant_torque: f64) -> Result<Self, OracleError> {
        let mut cables = cables;
        for (i, c) in cables.iter_mut().enumerate() {
            let bad = |field| OracleError::BadInput { cable: i, field };
            if !c.frame_exit.is_finite() {
                return Err(bad("frame_exit"));
            }
            if !c.anchor.is_finite() {
                return Err(bad("anchor"));
            }
            if !(c.k_f.is_finite() && c.k_f > 0.0) {
                return Err(bad("k_f"));
            }
            if let Some(p) = &mut c.pulley {
                let n = p.axis.length();
                if !(p.radius.is_finite() && p.radius > 0.0) {
                    return Err(bad("pulley radius"));
                }
                if !(n.is_finite() && n > 0.0) {
                    return Err(bad("pulley axis"));
                }
                p.axis /= n;
            }
        }
        if !(load.mass.is_finite() && load.mass >= 0.0) {
            return Err(OracleError::BadLoad("mass"));
        }
        if !load.center_of_gravity.is_finite() {
            return Err(OracleError::BadLoad("center_of_gravity"));
        }
        if !load.gravity.is_finite() {
            return Err(OracleError::BadLoad("gravity"));
        }
        if !load.force.is_finite() {
            return Err(OracleError::BadLoad("force"));
        }
        if !constant_torque.is_finite() {
            return Err(OracleError::BadLoad("torque"));
        }
        if constant_torque != 0.0 {
            return Err(OracleError::TorqueNotConservative(constant_torque));
        }
        Ok(Self { cables, load })
    }

    pub fn cables(&self) -> &[Cable] {
        &self.cables
    }

    pub fn load(&self) -> &Load {
        &self.load
    }

    pub fn m(&self) -> usize {
        self.cables.len()
    }
}
