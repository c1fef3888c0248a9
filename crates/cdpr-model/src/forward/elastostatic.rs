//! Elastostatic forward kinematics (x, f) = ν_el(q_θ, w_e) (eq. 2.42): the pose where the
//! residual wrench ρ(x) = A^T(x) f(x, q_θ) + w_e (eq. 2.43) vanishes, by Levenberg–Marquardt
//! with the analytic Jacobian ∂ρ/∂x = K_G − K_C (eq. 2.74, 2.76) in pose coordinates.
//! Slack cables (f < 0) carry no force (see [`crate::elastostatics::cable_forces`]).

use super::{FkError, FkOptions, FkSolution, check_input};
use crate::elastostatics::{self, CableLaw, Stiffness};
use crate::kinematics;
use crate::model::{Data, Model};
use crate::pose::{Pose, twist_from_coordinates};
use crate::statics;
use nalgebra::Vector6;

/// ν_el with the model's own linear cable law and wrench. On success `data.f` holds the cable
/// forces at the returned pose. Allocation-free.
pub fn elastostatic(
    model: &Model,
    data: &mut Data,
    q_theta: &[f64],
    guess: &Pose,
    opts: &FkOptions,
) -> Result<FkSolution, FkError> {
    elastostatic_with_law(
        model,
        data,
        &model.linear_law(),
        &model.params().w_e,
        q_theta,
        guess,
        opts,
    )
}

/// ν_el with an arbitrary cable law and external wrench (used by the simulated plant).
pub fn elastostatic_with_law(
    model: &Model,
    data: &mut Data,
    law: &impl CableLaw,
    w_e: &Vector6<f64>,
    q_theta: &[f64],
    guess: &Pose,
    opts: &FkOptions,
) -> Result<FkSolution, FkError> {
    check_input(model.m(), q_theta, guess)?;
    let mut x = *guess;
    let mut rho = eval(model, data, law, w_e, q_theta, &x)?;
    let mut cost = 0.5 * rho.norm_squared();
    let mut mu = opts.initial_damping;
    for it in 1..=opts.max_iterations {
        if data.f.iter().all(|f| *f == 0.0) {
            return Err(FkError::AllSlack);
        }
        if rho.amax() <= opts.wrench_tolerance * scale(data, w_e) {
            return Ok(FkSolution {
                pose: x,
                iterations: it - 1,
                residual_norm: rho.norm(),
            });
        }
        let j = Stiffness::at(model, data).k_wx * twist_from_coordinates(&x);
        let jtj = j.transpose() * j;
        let jtr = j.transpose() * rho;
        loop {
            let mut lhs = jtj;
            for k in 0..6 {
                lhs[(k, k)] += mu * jtj[(k, k)].max(1e-12);
            }
            let step = lhs
                .cholesky()
                .ok_or(FkError::Singular { iteration: it })?
                .solve(&(-jtr));
            let x_new = x.add_increment(&step);
            let accepted = match eval(model, data, law, w_e, q_theta, &x_new) {
                Ok(r) if 0.5 * r.norm_squared() <= cost => Some(r),
                _ => None,
            };
            if let Some(r) = accepted {
                x = x_new;
                rho = r;
                cost = 0.5 * rho.norm_squared();
                mu = (mu / 5.0).max(1e-15);
                if step.amax() < opts.step_tolerance {
                    return accept(model, data, law, w_e, q_theta, x, it, opts);
                }
                break;
            }
            mu *= 4.0;
            if mu > 1e12 {
                return accept(model, data, law, w_e, q_theta, x, it, opts);
            }
        }
    }
    accept(model, data, law, w_e, q_theta, x, opts.max_iterations, opts)
}

fn scale(data: &Data, w_e: &Vector6<f64>) -> f64 {
    data.f.iter().sum::<f64>() + w_e.amax() + 1.0
}

fn eval(
    model: &Model,
    data: &mut Data,
    law: &impl CableLaw,
    w_e: &Vector6<f64>,
    q_theta: &[f64],
    x: &Pose,
) -> Result<Vector6<f64>, FkError> {
    kinematics::inverse(model, data, x)?;
    elastostatics::cable_forces(data, law, q_theta);
    Ok(statics::cable_wrench(data, &data.f) + w_e)
}

#[allow(clippy::too_many_arguments)]
fn accept(
    model: &Model,
    data: &mut Data,
    law: &impl CableLaw,
    w_e: &Vector6<f64>,
    q_theta: &[f64],
    x: Pose,
    iterations: usize,
    opts: &FkOptions,
) -> Result<FkSolution, FkError> {
    let rho = eval(model, data, law, w_e, q_theta, &x)?;
    if data.f.iter().all(|f| *f == 0.0) {
        return Err(FkError::AllSlack);
    }
    if rho.amax() > opts.wrench_acceptance * scale(data, w_e) {
        return Err(FkError::NotConverged {
            iterations,
            residual: rho.norm(),
        });
    }
    Ok(FkSolution {
        pose: x,
        iterations,
        residual_norm: rho.norm(),
    })
}
