//! Least-squares forward kinematics ν(q_θ) = argmin ½‖q(x) − q_θ‖² (eq. 2.11) by
//! Levenberg–Marquardt on the linearisation ρ(x0 + Δx) = ρ(x0) + J_qx Δx (eq. 2.12–2.15) with
//! J_qx = −A (eq. 2.54) in pose coordinates (J_qx · diag(I, J_P)).

use super::{FkError, FkOptions, FkSolution, check_input};
use crate::kinematics;
use crate::model::{Data, Model};
use crate::pose::{Pose, twist_from_coordinates};
use nalgebra::{Matrix6, Vector6};

/// Solves ν(q_θ) from `guess`. Allocation-free; leaves the inverse kinematics of the solution
/// in `data`.
pub fn least_squares(
    model: &Model,
    data: &mut Data,
    q_theta: &[f64],
    guess: &Pose,
    opts: &FkOptions,
) -> Result<FkSolution, FkError> {
    let m = model.m();
    check_input(m, q_theta, guess)?;
    let mut x = *guess;
    let mut cost = eval(model, data, &x, q_theta)?;
    let mut mu = opts.initial_damping;
    for it in 1..=opts.max_iterations {
        // Normal equations in pose coordinates: J = −A T, JᵀJ = Tᵀ(AᵀA)T, Jᵀρ = −Tᵀ Σ v_i ρ_i.
        let t = twist_from_coordinates(&x);
        let mut ata = Matrix6::zeros();
        let mut atr = Vector6::zeros();
        for i in 0..m {
            let v = data.at[i];
            ata += v * v.transpose();
            atr += v * (data.q[i] - q_theta[i]);
        }
        let jtj = t.transpose() * ata * t;
        let jtr = -(t.transpose() * atr);
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
            let cost_new = match eval(model, data, &x_new, q_theta) {
                Ok(c) => c,
                Err(_) => f64::INFINITY, // step left the valid region: damp more
            };
            if cost_new <= cost {
                x = x_new;
                let small = step.amax() < opts.step_tolerance;
                cost = cost_new;
                mu = (mu / 3.0).max(1e-15);
                if small || cost == 0.0 {
                    return finish(model, data, x, q_theta, it, opts);
                }
                break;
            }
            mu *= 4.0;
            if mu > 1e12 {
                // No descent possible any more: a stationary point (or stuck).
                eval(model, data, &x, q_theta)?;
                return finish(model, data, x, q_theta, it, opts);
            }
        }
    }
    Err(FkError::NotConverged { iterations: opts.max_iterations, residual: (2.0 * cost).sqrt() })
}

fn eval(model: &Model, data: &mut Data, x: &Pose, q_theta: &[f64]) -> Result<f64, FkError> {
    kinematics::inverse(model, data, x)?;
    Ok(0.5 * data.q.iter().zip(q_theta).map(|(q, qt)| (q - qt).powi(2)).sum::<f64>())
}

fn finish(
    model: &Model,
    data: &mut Data,
    x: Pose,
    q_theta: &[f64],
    iterations: usize,
    opts: &FkOptions,
) -> Result<FkSolution, FkError> {
    let cost = eval(model, data, &x, q_theta)?;
    let residual_norm = (2.0 * cost).sqrt();
    // Gradient at the solution decides: a stationary point of eq. (2.11) is accepted.
    let t = twist_from_coordinates(&x);
    let mut atr = Vector6::zeros();
    for i in 0..model.m() {
        atr += data.at[i] * (data.q[i] - q_theta[i]);
    }
    let gradient = (t.transpose() * atr).amax();
    if gradient > opts.gradient_acceptance {
        return Err(FkError::NotConverged { iterations, residual: residual_norm });
    }
    Ok(FkSolution { pose: x, iterations, residual_norm })
}
