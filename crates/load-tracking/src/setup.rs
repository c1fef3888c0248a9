//! The set-up: cable offsets from the initial forces (eq. 6.24) and the initial tension that
//! keeps the forces closest to f_ref along a planned path (eq. 3.42).
//!
//! A kinematic controller commands q(s) = φ(x(s)) + q_off, where the offsets q_off are fixed
//! at the set-up pose x_0 by the initial tension f_ini: q_off = φ_el(x_0, f_ini) − φ(x_0) =
//! −K^{-1} f_ini (eq. 2.37, 6.24). Along the path the forces f(s, f_ini) then follow from the
//! elastostatic forward kinematics (eq. 2.44). Eq. 3.42 chooses f_ini to minimise
//! Σ_s ‖f_ref(s) − f(s, f_ini)‖² with f_ref from eq. 3.41. f_ini must itself balance the
//! load at x_0, so it moves only in the kernel of A^T(x_0) (eq. 2.40): f_ini = f_p + H λ,
//! λ ∈ R^{m−6}; the forces depend on λ almost linearly, and a few steps of the stack's one
//! Levenberg–Marquardt (nearly Gauss–Newton) with a finite-difference Jacobian solve it.

use cdpr_model::forward::{self, FkError, FkOptions};
use cdpr_model::kinematics::{self, KinematicsError};
use cdpr_model::levenberg_marquardt as lm;
use cdpr_model::statics::{self, StaticsError};
use cdpr_model::{Data, Model, Pose, elastostatics};
use nalgebra::{DMatrix, DVector, Dyn};

/// Cable offsets q_off = φ_el(x_0, f) − φ(x_0) = −K^{-1} f (eq. 6.24), m.
pub fn cable_offsets(
    model: &Model,
    data: &mut Data,
    pose: &Pose,
    f: &[f64],
) -> Result<Vec<f64>, KinematicsError> {
    let m = model.m();
    let mut q_theta = vec![0.0; m];
    elastostatics::inverse(model, data, pose, f, &mut q_theta)?;
    Ok((0..m).map(|i| q_theta[i] - data.q[i]).collect())
}

/// Why the initial tension could not be chosen.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SetupError {
    #[error("set-up pose: {0}")]
    Kinematics(#[from] KinematicsError),
    #[error("set-up pose: {0}")]
    Statics(#[from] StaticsError),
    #[error("path sample {sample}: forward kinematics: {err}")]
    Forward { sample: usize, err: FkError },
    #[error("the path is empty")]
    EmptyPath,
    #[error("the solver for f_ini: singular normal equations (iteration {iteration})")]
    Singular { iteration: usize },
    #[error("the solver for f_ini: a cost or gradient is not finite (iteration {iteration})")]
    NonFinite { iteration: usize },
    #[error("f_ini(λ) is not wrench feasible at the set-up pose: cable {cable} at {force:.0} N")]
    Infeasible { cable: usize, force: f64 },
}

/// The result of eq. 3.42.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct InitialTension {
    /// The chosen f_ini at the set-up pose, N.
    pub f_ini: Vec<f64>,
    /// Its offsets q_off (eq. 6.24), m.
    pub q_off: Vec<f64>,
    /// RMS of f_ref − f along the path with the chosen f_ini and with the start value, N.
    pub rms_chosen_n: f64,
    pub rms_start_n: f64,
    /// Smallest and largest cable force along the path with the chosen f_ini, N.
    pub f_min_n: f64,
    pub f_max_n: f64,
    pub iterations: usize,
}

/// Chooses f_ini at `x0` for `path` (poses of the planned trajectory) by eq. 3.42, starting
/// from eq. 3.41's f_ref at x0.
pub fn initial_tension(
    model: &Model,
    x0: &Pose,
    path: &[Pose],
) -> Result<InitialTension, SetupError> {
    if path.is_empty() {
        return Err(SetupError::EmptyPath);
    }
    let p = model.params();
    let m = model.m();
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, x0)?;
    let mut f_p = vec![0.0; m];
    statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f_p)?;
    let h = statics::nullspace_basis(&data);
    // f_ref(s) of eq. 3.41 along the path.
    let mut f_ref = Vec::with_capacity(path.len());
    for x in path {
        kinematics::inverse(model, &mut data, x)?;
        let mut f = vec![0.0; m];
        statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f)?;
        f_ref.push(f);
    }
    let ref_vec = DVector::from_iterator(m * path.len(), f_ref.iter().flatten().copied());
    let mut problem = Tension {
        model,
        x0,
        path,
        f_p: DVector::from_column_slice(&f_p),
        h,
        ref_vec,
        data,
        f_now: DVector::zeros(0),
    };
    let k = problem.h.ncols();
    let start = problem.forces(&DVector::zeros(k))?;
    let rms_start = problem.rms(&start);
    let settings = lm::Settings {
        // The forces depend on λ almost linearly: a few steps; ‖δλ‖ < 1 N ends it.
        max_iterations: 8,
        max_trials: 10,
        // Nearly Gauss–Newton, damped only where the FK fails or the cost rises.
        initial_damping: 1e-9,
        decrease: 10.0,
        min_damping: 1e-12,
        increase: 10.0,
        max_damping: 1e6,
        damping: lm::Damping::Marquardt { floor: 1e-12 },
        on_singular: lm::OnSingular::IncreaseDamping,
        gradient_tolerance: None,
    };
    let outcome = match lm::solve(&mut problem, DVector::zeros(k), &settings) {
        Ok(o) => o,
        Err(lm::LmError::Start(e) | lm::LmError::Problem { source: e, .. }) => return Err(e),
        Err(lm::LmError::Singular { iteration }) => {
            return Err(SetupError::Singular { iteration });
        }
        Err(lm::LmError::NonFiniteStart) => return Err(SetupError::NonFinite { iteration: 0 }),
        Err(lm::LmError::NonFiniteGradient { iteration }) => {
            return Err(SetupError::NonFinite { iteration });
        }
    };
    let lambda = outcome.point;
    let f_now = problem.forces(&lambda)?;
    let rms_chosen = problem.rms(&f_now);
    let mut data = problem.data;
    let f_ini = &problem.f_p + &problem.h * &lambda;
    if let Some((cable, force)) = f_ini
        .iter()
        .enumerate()
        .find(|(_, f)| **f < p.f_min || **f > p.f_max)
        .map(|(i, f)| (i, *f))
    {
        return Err(SetupError::Infeasible { cable, force });
    }
    let q_off = cable_offsets(model, &mut data, x0, f_ini.as_slice())?;
    Ok(InitialTension {
        f_ini: f_ini.iter().copied().collect(),
        q_off,
        rms_chosen_n: rms_chosen,
        rms_start_n: rms_start,
        f_min_n: f_now.min(),
        f_max_n: f_now.max(),
        iterations: outcome.iterations,
    })
}

/// Eq. 3.42 as a least-squares problem in λ (f_ini = f_p + H λ): r(λ) = f(λ) − f_ref over the
/// path, J = ∂f/∂λ by finite differences.
struct Tension<'a> {
    model: &'a Model,
    x0: &'a Pose,
    path: &'a [Pose],
    f_p: DVector<f64>,
    h: DMatrix<f64>,
    ref_vec: DVector<f64>,
    data: Data,
    /// The forces at the last point whose cost was evaluated (the solver's current point when
    /// it asks for the normal equations).
    f_now: DVector<f64>,
}

impl Tension<'_> {
    /// The cable forces along the path for λ: the offsets f_ini implies at x_0 (eq. 6.24),
    /// then the elastostatic forward kinematics at each path pose (eq. 2.44).
    fn forces(&mut self, lambda: &DVector<f64>) -> Result<DVector<f64>, SetupError> {
        let m = self.model.m();
        let f_ini = &self.f_p + &self.h * lambda;
        let q_off = cable_offsets(self.model, &mut self.data, self.x0, f_ini.as_slice())?;
        let mut out = DVector::zeros(m * self.path.len());
        let mut q_theta = vec![0.0; m];
        let opts = FkOptions::default();
        for (s, x) in self.path.iter().enumerate() {
            kinematics::inverse(self.model, &mut self.data, x)?;
            for i in 0..m {
                q_theta[i] = self.data.q[i] + q_off[i];
            }
            forward::elastostatic(self.model, &mut self.data, &q_theta, x, &opts)
                .map_err(|err| SetupError::Forward { sample: s, err })?;
            out.rows_mut(s * m, m).copy_from_slice(&self.data.f);
        }
        Ok(out)
    }

    /// RMS of f_ref − f over the path, N.
    fn rms(&self, f: &DVector<f64>) -> f64 {
        ((&self.ref_vec - f).norm_squared() / f.len() as f64).sqrt()
    }
}

impl lm::Problem<Dyn> for Tension<'_> {
    type Point = DVector<f64>;
    type Error = SetupError;

    fn dim(&self) -> Dyn {
        Dyn(self.h.ncols())
    }

    /// A λ whose forward kinematics fails somewhere on the path counts as uphill.
    fn cost(&mut self, lambda: &DVector<f64>) -> Result<f64, SetupError> {
        self.f_now = self.forces(lambda)?;
        Ok(0.5 * (&self.f_now - &self.ref_vec).norm_squared())
    }

    fn normal_equations(
        &mut self,
        lambda: &DVector<f64>,
        jtj: &mut DMatrix<f64>,
        g: &mut DVector<f64>,
    ) -> Result<(), SetupError> {
        // Forward differences with 10 N steps: the law is linear in f, the geometry barely
        // moves.
        // `forces` needs `self` mutably; the current point's forces are set aside meanwhile.
        let f0 = std::mem::take(&mut self.f_now);
        let mut jac = DMatrix::zeros(f0.len(), lambda.len());
        for c in 0..lambda.len() {
            let mut l2 = lambda.clone();
            l2[c] += 10.0;
            let f2 = self.forces(&l2)?;
            jac.set_column(c, &((f2 - &f0) / 10.0));
        }
        self.f_now = f0;
        jtj.copy_from(&(jac.transpose() * &jac));
        g.copy_from(&(jac.transpose() * (&self.f_now - &self.ref_vec)));
        Ok(())
    }

    fn retract(&self, lambda: &DVector<f64>, step: &DVector<f64>) -> DVector<f64> {
        lambda + step
    }

    /// Only a strict decrease replaces the point.
    fn accepts(&mut self, cost: f64, cost_new: f64) -> bool {
        cost_new < cost
    }

    fn accepted(&mut self, step: &lm::Accepted<'_, DVector<f64>, Dyn>) -> bool {
        step.step.norm() < 1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdpr_model::config::load_platform;
    use nalgebra::Vector3;

    fn heli() -> cdpr_model::config::Platform {
        load_platform(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../config/helicopter.toml"
        ))
        .unwrap()
    }

    /// q_off = −f q / k_F (eq. 6.24): the spec's 3678 N on a ~10 m cable with k_F = 2000 kN
    /// is about −19 mm.
    #[test]
    fn offsets_are_the_elongation() {
        let p = heli();
        let mut data = Data::new(&p.model);
        let f = vec![4000.0; 8];
        let q_off = cable_offsets(&p.model, &mut data, &p.home, &f).unwrap();
        for i in 0..8 {
            let expect = -f[i] * data.q[i] / p.model.params().k_f[i];
            assert!(
                (q_off[i] - expect).abs() < 1e-12,
                "{i}: {} vs {expect}",
                q_off[i]
            );
        }
    }

    /// Along a path away from the set-up pose the chosen f_ini tracks f_ref at least as well
    /// as eq. 3.41's f_ref at the set-up pose does, and it still balances the load there.
    #[test]
    fn the_chosen_tension_is_no_worse_and_balances_the_load() {
        let p = heli();
        let path: Vec<Pose> = (0..12)
            .map(|k| {
                let a = k as f64 / 12.0 * std::f64::consts::TAU;
                Pose::new(
                    p.home.r + Vector3::new(0.5 * a.cos(), 0.5 * a.sin(), 0.1 * a.sin()),
                    Vector3::zeros(),
                )
            })
            .collect();
        let r = initial_tension(&p.model, &p.home, &path).unwrap();
        assert!(r.rms_chosen_n <= r.rms_start_n + 1e-6, "{r:?}");
        let mut data = Data::new(&p.model);
        kinematics::inverse(&p.model, &mut data, &p.home).unwrap();
        let res = statics::residual_wrench(&data, &r.f_ini, &p.model.params().w_e);
        assert!(res.norm() < 1e-6, "f_ini does not balance the load: {res}");
        assert!(matches!(
            initial_tension(&p.model, &p.home, &[]),
            Err(SetupError::EmptyPath)
        ));
    }
}
