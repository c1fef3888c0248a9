//! Elastostatics (sec. 2.4, 2.6): cable force laws (eq. 2.33–2.36), the inverse elastostatic
//! model φ_el (eq. 2.37, 2.41) and the stiffness matrices K_G, K_C, K_wx, C_xw, J_xθ
//! (eq. 2.67–2.80). Functions expect `data` to hold the inverse kinematics of the pose.

use crate::kinematics::{self, KinematicsError, differential};
use crate::model::{Data, Model};
use crate::pose::{Pose, skew};
use crate::statics::{self, StaticsError};
use nalgebra::{DMatrix, Matrix3x6, Matrix6, Vector6};

/// Force of one cable and its partial derivatives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CableForce {
    /// Cable force f_i, N (positive = tension).
    pub f: f64,
    /// ∂f_i/∂q_i, N/m (eq. 2.71).
    pub df_dq: f64,
    /// ∂f_i/∂q_θ,i, N/m (eq. 2.72).
    pub df_dqt: f64,
}

/// A cable force law f_i(q_i, q_θ,i): the elasticity model of sec. 2.4. The control model uses
/// [`LinearElastic`]; the simulated plant supplies richer laws (powertrain compliance,
/// tension-dependent stiffness, hysteresis, sag) through the same interface.
pub trait CableLaw {
    /// Force of cable `i` at geometric length `q` and controlled length `q_theta`. May be
    /// negative (compression); the elastostatic solvers treat f < 0 as a slack cable.
    fn force(&self, i: usize, q: f64, q_theta: f64) -> CableForce;
    /// Controlled length q_θ that yields force `f` at geometric length `q` (inverse of
    /// [`CableLaw::force`], used by φ_el, eq. 2.37).
    fn controlled_length(&self, i: usize, q: f64, f: f64) -> f64;
}

/// Linear elastic cable of the spec: k_i = k_F,i / q_i (eq. 2.33), f_i = k_i (q_i − q_θ,i)
/// (eq. 2.35–2.36), i.e. f = k_F (1 − q_θ/q) with ∂f/∂q = k_F q_θ / q² (eq. 2.71) and
/// ∂f/∂q_θ = −k_F / q (eq. 2.72).
#[derive(Clone, Copy, Debug)]
pub struct LinearElastic<'a> {
    /// k_F,i per cable, N.
    pub k_f: &'a [f64],
}

impl CableLaw for LinearElastic<'_> {
    #[inline]
    fn force(&self, i: usize, q: f64, q_theta: f64) -> CableForce {
        let k = self.k_f[i] / q;
        CableForce {
            f: k * (q - q_theta),
            df_dq: self.k_f[i] * q_theta / (q * q),
            df_dqt: -k,
        }
    }

    #[inline]
    fn controlled_length(&self, i: usize, q: f64, f: f64) -> f64 {
        // eq. (2.37): q_θ = q − f / k with k = k_F / q.
        q - f * q / self.k_f[i]
    }
}

/// Springs of constant stiffness k_i (N/m) independent of length: f = k (q − q_θ). With k = 1
/// and no load the elastostatic forward kinematics is the least-squares forward kinematics
/// (remark at eq. 2.81).
#[derive(Clone, Copy, Debug)]
pub struct ConstantStiffness<'a> {
    pub k: &'a [f64],
}

impl CableLaw for ConstantStiffness<'_> {
    #[inline]
    fn force(&self, i: usize, q: f64, q_theta: f64) -> CableForce {
        CableForce {
            f: self.k[i] * (q - q_theta),
            df_dq: self.k[i],
            df_dqt: -self.k[i],
        }
    }

    #[inline]
    fn controlled_length(&self, i: usize, q: f64, f: f64) -> f64 {
        q - f / self.k[i]
    }
}

impl Model {
    /// The model's own cable law (eq. 2.33–2.36).
    pub fn linear_law(&self) -> LinearElastic<'_> {
        LinearElastic {
            k_f: &self.params().k_f,
        }
    }
}

/// Evaluates `law` for every cable at the controlled lengths `q_theta`, writing `data.f`,
/// `data.df_dq` and `data.df_dqt`. Slack cables (f < 0) carry no force and no stiffness.
pub fn cable_forces(data: &mut Data, law: &impl CableLaw, q_theta: &[f64]) {
    for i in 0..data.m() {
        let cf = law.force(i, data.q[i], q_theta[i]);
        if cf.f > 0.0 {
            data.f[i] = cf.f;
            data.df_dq[i] = cf.df_dq;
            data.df_dqt[i] = cf.df_dqt;
        } else {
            data.f[i] = 0.0;
            data.df_dq[i] = 0.0;
            data.df_dqt[i] = 0.0;
        }
    }
}

/// Inverse elastostatic model q_θ = φ_el(x, f) = q(x) − K^{-1} f (eq. 2.37) with the model's
/// linear law, written to `q_theta`. Allocation-free.
pub fn inverse(
    model: &Model,
    data: &mut Data,
    pose: &Pose,
    f: &[f64],
    q_theta: &mut [f64],
) -> Result<(), KinematicsError> {
    inverse_with_law(model, data, &model.linear_law(), pose, f, q_theta)
}

/// [`inverse`] with an arbitrary cable law.
pub fn inverse_with_law(
    model: &Model,
    data: &mut Data,
    law: &impl CableLaw,
    pose: &Pose,
    f: &[f64],
    q_theta: &mut [f64],
) -> Result<(), KinematicsError> {
    kinematics::inverse(model, data, pose)?;
    for i in 0..model.m() {
        q_theta[i] = law.controlled_length(i, data.q[i], f[i]);
    }
    Ok(())
}

/// Inverse elastostatic model with wrench and internal tension state,
/// q_θ = φ_el(x, w_e, λ) = q(x) − K^{-1}(−A^{+T} w_e + H λ) (eq. 2.41), H from
/// [`statics::nullspace_basis`]. Returns the forces used. Analysis helper; allocates.
pub fn inverse_wrench_lambda(
    model: &Model,
    data: &mut Data,
    pose: &Pose,
    w_e: &Vector6<f64>,
    lambda: &[f64],
    q_theta: &mut [f64],
) -> Result<Vec<f64>, ElastostaticsError> {
    kinematics::inverse(model, data, pose)?;
    let m = model.m();
    let h = statics::nullspace_basis(data);
    if lambda.len() != h.ncols() {
        return Err(ElastostaticsError::LambdaLength {
            expected: h.ncols(),
            got: lambda.len(),
        });
    }
    let mut f_ext = vec![0.0; m];
    let mut scratch = vec![0.0; m];
    statics::split_internal_external(data, w_e, &vec![0.0; m], &mut f_ext, &mut scratch)?;
    let lam = nalgebra::DVector::from_column_slice(lambda);
    let f_int = &h * lam;
    let f: Vec<f64> = (0..m).map(|i| f_ext[i] + f_int[i]).collect();
    inverse(model, data, pose, &f, q_theta)?;
    Ok(f)
}

/// Errors of the elastostatic analysis helpers.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ElastostaticsError {
    #[error(transparent)]
    Kinematics(#[from] KinematicsError),
    #[error(transparent)]
    Statics(#[from] StaticsError),
    #[error("λ must have m − 6 = {expected} entries, got {got}")]
    LambdaLength { expected: usize, got: usize },
    #[error("the stiffness matrix is singular at this pose")]
    SingularStiffness,
}

/// ∂v_i/∂x for v_i = [u_i; b_i × u_i] (eq. 2.68), using ∂u/∂x (eq. 2.65, pulley: 2.87) and
/// ∂(b×u)/∂x = b̃ ∂u/∂x − ũ ∂b/∂x with ∂b/∂x = [0  −b̃] (eq. 2.47, 2.70).
fn column_jacobian(model: &Model, data: &Data, i: usize) -> (Matrix3x6<f64>, Matrix3x6<f64>) {
    let du = differential::unit_vector_jacobian(model, data, i);
    let b = data.b_world[i];
    let mut db = Matrix3x6::zeros();
    db.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew(&b)));
    let dbu = skew(&b) * du - skew(&data.u[i]) * db;
    (du, dbu)
}

/// Geometric stiffness K_G = Σ f_i ∂v_i/∂x (eq. 2.67) with the forces in `data.f`.
pub fn geometric_stiffness(model: &Model, data: &Data) -> Matrix6<f64> {
    let mut kg = Matrix6::zeros();
    for i in 0..model.m() {
        let fi = data.f[i];
        if fi == 0.0 {
            continue;
        }
        let (du, dbu) = column_jacobian(model, data, i);
        let mut top = kg.fixed_view_mut::<3, 6>(0, 0);
        top += du * fi;
        let mut bottom = kg.fixed_view_mut::<3, 6>(3, 0);
        bottom += dbu * fi;
    }
    kg
}

/// Cable stiffness K_C = A^T K A (eq. 2.75) with K = diag(∂f/∂q) from `data.df_dq`
/// (eq. 2.73; for the linear law ≈ diag(k)).
pub fn cable_stiffness(data: &Data) -> Matrix6<f64> {
    let mut kc = Matrix6::zeros();
    for (v, k) in data.at.iter().zip(&data.df_dq) {
        kc += v * v.transpose() * *k;
    }
    kc
}

/// The stiffness matrices of sec. 2.6 at the state in `data` (inverse kinematics and
/// [`cable_forces`] done).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stiffness {
    /// Geometric stiffness K_G (eq. 2.67).
    pub k_g: Matrix6<f64>,
    /// Cable stiffness K_C = A^T K A (eq. 2.75).
    pub k_c: Matrix6<f64>,
    /// K_wx = K_G − K_C, the Jacobian of the residual wrench A^T f + w_e with respect to the
    /// twist at fixed q_θ (eq. 2.74, 2.76: ∂w_e/∂x = −K_wx). −K_wx is the positive-definite
    /// stiffness an engineer measures (N/m, N·m/rad).
    pub k_wx: Matrix6<f64>,
}

impl Stiffness {
    pub fn at(model: &Model, data: &Data) -> Self {
        let k_g = geometric_stiffness(model, data);
        let k_c = cable_stiffness(data);
        Self {
            k_g,
            k_c,
            k_wx: k_g - k_c,
        }
    }

    /// C_xw = K_wx^{-1} (eq. 2.77), so δx = −C_xw δw_e (eq. 2.78).
    pub fn compliance(&self) -> Option<Matrix6<f64>> {
        self.k_wx.try_inverse()
    }
}

/// J_xθ = (K_G − K_C)^{-1} A^T K_θ (eq. 2.79–2.80), 6×m, with K_θ = −diag(∂f/∂q_θ) (= K for
/// the linear law), so δx = J_xθ δq_θ at constant wrench. Allocates (m is a run-time size).
pub fn pose_sensitivity(model: &Model, data: &Data) -> Result<DMatrix<f64>, ElastostaticsError> {
    let s = Stiffness::at(model, data);
    let lu = s.k_wx.lu();
    let mut j = DMatrix::zeros(6, model.m());
    for i in 0..model.m() {
        let col = lu
            .solve(&(data.at[i] * (-data.df_dqt[i])))
            .ok_or(ElastostaticsError::SingularStiffness)?;
        j.set_column(i, &col);
    }
    Ok(j)
}
