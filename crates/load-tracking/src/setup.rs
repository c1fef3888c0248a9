//! The set-up: cable offsets from the initial forces (eq. 6.24) and the initial tension that
//! keeps the forces closest to f_ref along a planned path (eq. 3.42).
//!
//! A kinematic controller commands q(s) = φ(x(s)) + q_off, where the offsets q_off are fixed
//! at the set-up pose x_0 by the initial tension f_ini: q_off = φ_el(x_0, f_ini) − φ(x_0) =
//! −K^{-1} f_ini (eq. 2.37, 6.24). Along the path the forces f(s, f_ini) then follow from the
//! elastostatic forward kinematics (eq. 2.44). Eq. 3.42 chooses f_ini to minimise
//! Σ_s ‖f_ref(s) − f(s, f_ini)‖² with f_ref from eq. 3.41. f_ini must itself balance the
//! load at x_0, so it moves only in the kernel of A^T(x_0) (eq. 2.40): f_ini = f_p + H λ,
//! λ ∈ R^{m−6}; the forces depend on λ almost linearly, and a few Gauss–Newton steps with a
//! finite-difference Jacobian solve it.

use cdpr_model::forward::{self, FkError, FkOptions};
use cdpr_model::kinematics::{self, KinematicsError};
use cdpr_model::statics::{self, StaticsError};
use cdpr_model::{Data, Model, Pose, elastostatics};
use nalgebra::{DMatrix, DVector};

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
    let forces = |lambda: &DVector<f64>, data: &mut Data| -> Result<DVector<f64>, SetupError> {
        let f_ini = DVector::from_column_slice(&f_p) + &h * lambda;
        let q_off = cable_offsets(model, data, x0, f_ini.as_slice())?;
        let mut out = DVector::zeros(m * path.len());
        let mut q_theta = vec![0.0; m];
        let opts = FkOptions::default();
        for (s, x) in path.iter().enumerate() {
            kinematics::inverse(model, data, x)?;
            for i in 0..m {
                q_theta[i] = data.q[i] + q_off[i];
            }
            forward::elastostatic(model, data, &q_theta, x, &opts)
                .map_err(|err| SetupError::Forward { sample: s, err })?;
            out.rows_mut(s * m, m).copy_from_slice(&data.f);
        }
        Ok(out)
    };
    let k = h.ncols();
    let mut lambda = DVector::zeros(k);
    let f_start = forces(&lambda, &mut data)?;
    let rms = |f: &DVector<f64>| ((&ref_vec - f).norm_squared() / f.len() as f64).sqrt();
    let rms_start = rms(&f_start);
    let mut f_now = f_start;
    let mut iterations = 0;
    for it in 0..8 {
        iterations = it + 1;
        // Finite-difference Jacobian ∂f/∂λ (10 N steps: the law is linear in f, the geometry
        // barely moves).
        let mut jac = DMatrix::zeros(f_now.len(), k);
        for c in 0..k {
            let mut l2 = lambda.clone();
            l2[c] += 10.0;
            let f2 = forces(&l2, &mut data)?;
            jac.set_column(c, &((&f2 - &f_now) / 10.0));
        }
        let step = (jac.transpose() * &jac)
            .try_inverse()
            .map(|inv| inv * (jac.transpose() * (&ref_vec - &f_now)))
            .unwrap_or_else(|| DVector::zeros(k));
        // Damped: halve until the cost drops (the FK may fail far out: treat as uphill).
        let mut t = 1.0;
        let mut accepted = false;
        while t > 1e-3 {
            let cand = &lambda + &step * t;
            if let Ok(f) = forces(&cand, &mut data)
                && rms(&f) < rms(&f_now)
            {
                lambda = cand;
                f_now = f;
                accepted = true;
                break;
            }
            t *= 0.5;
        }
        if !accepted || step.norm() * t < 1.0 {
            break;
        }
    }
    let f_ini = DVector::from_column_slice(&f_p) + &h * &lambda;
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
        rms_chosen_n: rms(&f_now),
        rms_start_n: rms_start,
        f_min_n: f_now.min(),
        f_max_n: f_now.max(),
        iterations,
    })
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
