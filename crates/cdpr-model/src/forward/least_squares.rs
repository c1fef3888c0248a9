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
    let mut grad = gradient(model, data, &x, q_theta);
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
            // A step that leaves the valid region (IK error) counts as uphill: damp more.
            let cost_new = eval(model, data, &x_new, q_theta).unwrap_or(f64::INFINITY);
            // With inconsistent lengths the cost stays finite and its change drops below
            // round-off before the pose has converged; there the gradient decides.
            let grad_new = gradient(model, data, &x_new, q_theta);
            let at_roundoff = (cost_new - cost).abs() <= cost_roundoff(data, q_theta);
            if (cost_new < cost && !at_roundoff) || (at_roundoff && grad_new < grad) {
                x = x_new;
                let small = step.amax() < opts.step_tolerance;
                cost = cost_new;
                grad = grad_new;
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
    Err(FkError::NotConverged {
        iterations: opts.max_iterations,
        residual: (2.0 * cost).sqrt(),
    })
}

fn eval(model: &Model, data: &mut Data, x: &Pose, q_theta: &[f64]) -> Result<f64, FkError> {
    kinematics::inverse(model, data, x)?;
    Ok(0.5
        * data
            .q
            .iter()
            .zip(q_theta)
            .map(|(q, qt)| (q - qt).powi(2))
            .sum::<f64>())
}

/// Round-off level of the cost ½Σρ²: each ρ_i = q_i − q_θ,i carries an error of a few ulp of
/// q_i, so the cost is only known to ≈ Σ |ρ_i| · ulp(q_i).
fn cost_roundoff(data: &Data, q_theta: &[f64]) -> f64 {
    let mut s = 0.0;
    for (q, qt) in data.q.iter().zip(q_theta) {
        s += (q - qt).abs() * q.abs().max(qt.abs());
    }
    16.0 * f64::EPSILON * s
}

/// ‖Jᵀρ‖_∞ in pose coordinates at the state in `data` (inverse kinematics of `x` done).
fn gradient(model: &Model, data: &Data, x: &Pose, q_theta: &[f64]) -> f64 {
    let mut atr = Vector6::zeros();
    for i in 0..model.m() {
        atr += data.at[i] * (data.q[i] - q_theta[i]);
    }
    (twist_from_coordinates(x).transpose() * atr).amax()
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
    if gradient(model, data, &x, q_theta) > opts.gradient_acceptance {
        return Err(FkError::NotConverged {
            iterations,
            residual: residual_norm,
        });
    }
    Ok(FkSolution {
        pose: x,
        iterations,
        residual_norm,
    })
}
