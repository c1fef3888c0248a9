//! The target the polynomial surrogate is fitted to (sec. 5.6, eq. 5.23–5.26): the joint-space
//! offset that turns the standard kinematics into the elastostatic force control,
//!
//! ```text
//! q_off(x) = φ_el(x, f_ref(x)) − φ(x)      (eq. 2.37 minus eq. 2.3)
//! f_ref(x) = f_m − A^{+T}(w_e + A^T f_m)   (eq. 3.41)
//! ```
//!
//! so that q_θ = φ(x) + φ_sg(x) ≈ φ_el(x, f_ref(x)) drives an elastic plant to the pose x with
//! the reference force distribution. With the linear law (eq. 2.33, 2.36) the offset is
//! −f_ref,i q_i / k_F per cable: tens of mm on the CRS, inside the 100 mm bound (eq. 5.27).

use crate::config::Region;
use crate::kinematics::KinematicsError;
use crate::statics::{self, ForceDistribution, StaticsError};
use crate::{Data, Model, Pose, elastostatics, kinematics};

/// Why q_off(x) or f_ref(x) could not be evaluated at a pose.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum OffsetTargetError {
    #[error("inverse kinematics: {0}")]
    Kinematics(#[from] KinematicsError),
    #[error("force distribution (eq. 3.41): {0}")]
    Statics(#[from] StaticsError),
}

/// Evaluates q_off(x) and f_ref(x) for one model. Preallocated; `offset` does not allocate.
pub struct OffsetTarget {
    model: Model,
    data: Data,
    f_ref: Vec<f64>,
    q_theta: Vec<f64>,
}

impl OffsetTarget {
    pub fn new(model: &Model) -> Self {
        let m = model.m();
        Self {
            model: model.clone(),
            data: Data::new(model),
            f_ref: vec![0.0; m],
            q_theta: vec![0.0; m],
        }
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    /// f_ref(x) (eq. 3.41) with its feasibility verdict (eq. 3.29).
    pub fn reference_forces(
        &mut self,
        pose: &Pose,
    ) -> Result<(&[f64], ForceDistribution), OffsetTargetError> {
        kinematics::inverse(&self.model, &mut self.data, pose)?;
        let p = self.model.params();
        let fd =
            statics::force_distribution(&self.data, &p.w_e, p.f_min, p.f_max, &mut self.f_ref)?;
        Ok((&self.f_ref, fd))
    }

    /// q_off(x) = φ_el(x, f_ref(x)) − φ(x), m per cable, into `out` (length m).
    pub fn offset(
        &mut self,
        pose: &Pose,
        out: &mut [f64],
    ) -> Result<ForceDistribution, OffsetTargetError> {
        let (_, fd) = self.reference_forces(pose)?;
        let f = std::mem::take(&mut self.f_ref);
        let r = elastostatics::inverse(&self.model, &mut self.data, pose, &f, &mut self.q_theta);
        self.f_ref = f;
        r?;
        for i in 0..self.model.m() {
            // data.q holds φ(x) from the same call (eq. 2.3).
            out[i] = self.q_theta[i] - self.data.q[i];
        }
        Ok(fd)
    }
}

/// The platform's operating region as the surrogate's box [x, y, z, φx, φy, φz] (m, rad).
pub fn region_box(region: &Region) -> ([f64; 6], [f64; 6]) {
    let lo = region.position.min;
    let hi = region.position.max;
    (
        [
            lo.x,
            lo.y,
            lo.z,
            region.rotation_min.x,
            region.rotation_min.y,
            region.rotation_min.z,
        ],
        [
            hi.x,
            hi.y,
            hi.z,
            region.rotation_max.x,
            region.rotation_max.y,
            region.rotation_max.z,
        ],
    )
}
