//! Pose sensitivity to parameter errors (sec. 3.3, eq. 3.25–3.28): a controller that believes
//! the parameters p̂ commands q_θ = φ_el(x, f) for a pose x and forces f; the real robot with
//! parameters p̂ + Δp settles elsewhere. To first order (eq. 3.27–3.28)
//!
//! Δx = C_xw (J_wab Δp_ab + J_wkF Δk_F + Δw_e),
//!
//! with J_wab = ∂(A^T f)/∂p_ab and J_wkF = A^T ∂f/∂k_F taken at the commanded lengths. This
//! module builds the 6 × n_p matrix J_xp = ∂x/∂p for the frame anchors a_i, the platform
//! anchors b_i and the cable stiffness k_F,i, and summarises it as the RMS pose error for
//! independent parameter errors of given standard deviations — the error map a designer reads
//! to decide how well the geometry must be measured.
//!
//! J_wab is a central difference of the wrench balance at the fixed pose and fixed q_θ (the
//! wrench is smooth in the anchors; the step is 1 µm), J_wkF is analytic (f = k_F (1 − q_θ/q)
//! for the linear law, so ∂f_i/∂k_F,i = f_i / k_F,i). The tests check J_xp against the full
//! elastostatic forward kinematics of a perturbed robot (eq. 2.42), an independent path.

use cdpr_model::elastostatics::{self, ElastostaticsError, Stiffness};
use cdpr_model::kinematics;
use cdpr_model::kinematics::KinematicsError;
use cdpr_model::model::ModelError;
use cdpr_model::model::{Data, Model};
use cdpr_model::pose::Pose;
use cdpr_model::statics;
use cdpr_model::statics::StaticsError;
use nalgebra::{DMatrix, Vector3, Vector6};

/// Why a sensitivity could not be computed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SensitivityError {
    #[error(transparent)]
    Elastostatics(#[from] ElastostaticsError),
    #[error(transparent)]
    Kinematics(#[from] KinematicsError),
    #[error(transparent)]
    Statics(#[from] StaticsError),
    #[error("a shifted anchor makes an invalid model: {0}")]
    Model(#[from] ModelError),
}

/// One identified quantity of the control model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Parameter {
    /// Frame-side exit point a_i, coordinate `axis` (0 = x, 1 = y, 2 = z), m.
    FrameAnchor { cable: usize, axis: usize },
    /// Platform anchor b_i (platform frame), coordinate `axis`, m.
    PlatformAnchor { cable: usize, axis: usize },
    /// Specific stiffness k_F,i, N.
    Stiffness { cable: usize },
}

impl Parameter {
    /// Name as used in platform TOML and calibration reports (`a_3.z`, `b_0.x`, `k_f_5`).
    pub fn name(&self) -> String {
        const AX: [char; 3] = ['x', 'y', 'z'];
        match *self {
            Parameter::FrameAnchor { cable, axis } => format!("a_{cable}.{}", AX[axis]),
            Parameter::PlatformAnchor { cable, axis } => format!("b_{cable}.{}", AX[axis]),
            Parameter::Stiffness { cable } => format!("k_f_{cable}"),
        }
    }
}

/// ∂x/∂p at one pose (eq. 3.28). Rows: translation (m) then rotation (rad, small-angle
/// rotation vector); one column per [`Parameter`].
#[derive(Clone, Debug)]
pub struct ParameterSensitivity {
    pub params: Vec<Parameter>,
    pub j_xp: DMatrix<f64>,
    /// The commanded forces f at the pose, N.
    pub forces: Vec<f64>,
}

/// Standard deviations of independent parameter errors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParameterErrors {
    /// σ of every frame-anchor coordinate, m.
    pub frame_anchor_m: f64,
    /// σ of every platform-anchor coordinate, m.
    pub platform_anchor_m: f64,
    /// σ of k_F,i relative to k_F,i (0.05 = 5 %).
    pub stiffness_rel: f64,
}

/// The expected pose error for [`ParameterErrors`] at one pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseErrorEstimate {
    /// √E‖Δr‖², m.
    pub rms_position_m: f64,
    /// √E‖Δφ‖², rad.
    pub rms_rotation_rad: f64,
    /// Column with the largest position gain ‖∂r/∂p_j‖·σ_j, and that contribution, m.
    pub dominant: Option<(Parameter, f64)>,
}

impl ParameterSensitivity {
    /// σ of parameter `j` under `e`, in its own unit (m, or N for k_F).
    pub fn sigma(&self, j: usize, e: &ParameterErrors, model: &Model) -> f64 {
        match self.params[j] {
            Parameter::FrameAnchor { .. } => e.frame_anchor_m,
            Parameter::PlatformAnchor { .. } => e.platform_anchor_m,
            Parameter::Stiffness { cable } => e.stiffness_rel * model.params().k_f[cable],
        }
    }

    /// ‖∂r/∂p_j‖ σ_j and ‖∂φ/∂p_j‖ σ_j: what parameter `j` alone contributes, m and rad.
    pub fn contribution(&self, j: usize, e: &ParameterErrors, model: &Model) -> (f64, f64) {
        let s = self.sigma(j, e, model);
        let col = self.j_xp.column(j);
        (
            Vector3::new(col[0], col[1], col[2]).norm() * s,
            Vector3::new(col[3], col[4], col[5]).norm() * s,
        )
    }

    /// E‖Δx‖² = Σ_j ‖J_xp[:, j]‖² σ_j² for independent zero-mean errors.
    pub fn pose_error(&self, model: &Model, e: &ParameterErrors) -> PoseErrorEstimate {
        let (mut sr, mut sphi) = (0.0, 0.0);
        let mut dominant: Option<(Parameter, f64)> = None;
        for j in 0..self.params.len() {
            let (gr, gphi) = self.contribution(j, e, model);
            sr += gr * gr;
            sphi += gphi * gphi;
            if dominant.is_none_or(|(_, g)| gr > g) {
                dominant = Some((self.params[j], gr));
            }
        }
        PoseErrorEstimate {
            rms_position_m: sr.sqrt(),
            rms_rotation_rad: sphi.sqrt(),
            dominant,
        }
    }

    /// Δx = J_xp Δp for a parameter error vector in the order of `params`.
    pub fn predict(&self, dp: &[f64]) -> Vector6<f64> {
        let v = &self.j_xp * nalgebra::DVector::from_column_slice(dp);
        Vector6::from_column_slice(v.as_slice())
    }
}

/// Every parameter the sensitivity covers, in the order of the columns of J_xp.
pub fn parameters(model: &Model) -> Vec<Parameter> {
    let m = model.m();
    let mut v = Vec::with_capacity(7 * m);
    for cable in 0..m {
        for axis in 0..3 {
            v.push(Parameter::FrameAnchor { cable, axis });
        }
    }
    for cable in 0..m {
        for axis in 0..3 {
            v.push(Parameter::PlatformAnchor { cable, axis });
        }
    }
    for cable in 0..m {
        v.push(Parameter::Stiffness { cable });
    }
    v
}

/// The controller's forces at `x`: the closed-form force distribution of eq. (3.41).
pub fn commanded_forces(model: &Model, x: &Pose) -> Result<Vec<f64>, SensitivityError> {
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, x)?;
    let p = model.params();
    let mut f = vec![0.0; model.m()];
    statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f)?;
    Ok(f)
}

/// Residual wrench A^T f + w_e of `model` at pose `x` with controlled lengths `q_theta`.
fn wrench(
    model: &Model,
    data: &mut Data,
    x: &Pose,
    q_theta: &[f64],
) -> Result<Vector6<f64>, SensitivityError> {
    kinematics::inverse(model, data, x)?;
    elastostatics::cable_forces(data, &model.linear_law(), q_theta);
    Ok(statics::residual_wrench(data, &data.f, &model.params().w_e))
}

/// J_xp of eq. (3.28) at pose `x` where the controller (believing `model`) commands forces `f`.
/// Allocates (a design-time analysis, not for the hard loop).
pub fn parameter_sensitivity(
    model: &Model,
    x: &Pose,
    f: &[f64],
) -> Result<ParameterSensitivity, SensitivityError> {
    let m = model.m();
    let mut data = Data::new(model);
    let mut q_theta = vec![0.0; m];
    elastostatics::inverse(model, &mut data, x, f, &mut q_theta)?;
    elastostatics::cable_forces(&mut data, &model.linear_law(), &q_theta);
    let lu = Stiffness::at(model, &data).k_wx.lu();
    let params = parameters(model);
    let mut j_wp = DMatrix::zeros(6, params.len());
    const H: f64 = 1e-6;
    for (j, par) in params.iter().enumerate() {
        let col: Vector6<f64> = match *par {
            Parameter::Stiffness { cable } => {
                // J_wkF (eq. 3.27): A^T ∂f/∂k_F with ∂f_i/∂k_F,i = f_i / k_F,i.
                data.at[cable] * (data.f[cable] / model.params().k_f[cable])
            }
            Parameter::FrameAnchor { cable, axis } | Parameter::PlatformAnchor { cable, axis } => {
                let frame = matches!(par, Parameter::FrameAnchor { .. });
                let shifted = |h: f64| {
                    model.with_params(|p| {
                        if frame {
                            p.a[cable][axis] += h;
                        } else {
                            p.b[cable][axis] += h;
                        }
                    })
                };
                let (mp, mm) = (shifted(H)?, shifted(-H)?);
                let mut d = Data::new(&mp);
                let wp = wrench(&mp, &mut d, x, &q_theta)?;
                let wm = wrench(&mm, &mut d, x, &q_theta)?;
                (wp - wm) / (2.0 * H)
            }
        };
        j_wp.set_column(j, &col);
    }
    // w(x + Δx, p + Δp) = 0 with ∂w/∂x = K_wx (elastostatics::Stiffness) gives
    // Δx = −K_wx⁻¹ J_wp Δp, i.e. C_xw J_wp of eq. (3.28) in the spec's sign convention.
    let mut j_xp = DMatrix::zeros(6, params.len());
    for j in 0..params.len() {
        let rhs: Vector6<f64> = -j_wp.fixed_view::<6, 1>(0, j).into_owned();
        let col = lu
            .solve(&rhs)
            .ok_or(ElastostaticsError::SingularStiffness)?;
        j_xp.set_column(j, &col);
    }
    Ok(ParameterSensitivity {
        params,
        j_xp,
        forces: f.to_vec(),
    })
}
