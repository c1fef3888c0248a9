//! Least-squares forward kinematics ν(q_θ) = argmin ½‖q(x) − q_θ‖² (eq. 2.11) by
//! Levenberg–Marquardt on the linearisation ρ(x0 + Δx) = ρ(x0) + J_qx Δx (eq. 2.12–2.15) with
//! J_qx = −A (eq. 2.54) in pose coordinates (J_qx · diag(I, J_P)).

use super::{FkError, FkOptions, FkSolution, check_input, from_lm};
use crate::kinematics;
use crate::levenberg_marquardt::{self as lm, Accepted, Flow};
use crate::model::{Data, Model};
use crate::pose::{Pose, twist_from_coordinates};
use nalgebra::{Matrix6, U6, Vector6};

/// Solves ν(q_θ) from `guess`. Allocation-free; leaves the inverse kinematics of the solution
/// in `data`.
pub fn least_squares(
    model: &Model,
    data: &mut Data,
    q_theta: &[f64],
    guess: &Pose,
    opts: &FkOptions,
) -> Result<FkSolution, FkError> {
    check_input(model.m(), q_theta, guess)?;
    let mut problem = LengthResidual {
        model,
        data,
        q_theta,
        opts,
        grad: 0.0,
        last_grad: 0.0,
        last_roundoff: 0.0,
    };
    let out = lm::solve(&mut problem, *guess, &opts.lm_settings(3.0)).map_err(from_lm)?;
    match out.stop {
        lm::Stop::MaxIterations => Err(FkError::NotConverged {
            iterations: out.iterations,
            residual: (2.0 * out.cost).sqrt(),
        }),
        _ => finish(model, data, out.point, q_theta, out.iterations, opts),
    }
}

/// ρ = q(x) − q_θ with the state of the last evaluated point (the gradient and the cost's
/// round-off there, for the acceptance rule).
struct LengthResidual<'a> {
    model: &'a Model,
    data: &'a mut Data,
    q_theta: &'a [f64],
    opts: &'a FkOptions,
    /// ‖Jᵀρ‖_∞ at the current point.
    grad: f64,
    last_grad: f64,
    last_roundoff: f64,
}

impl lm::Problem<U6> for LengthResidual<'_> {
    type Point = Pose;
    type Error = FkError;

    fn dim(&self) -> U6 {
        U6
    }

    fn cost(&mut self, x: &Pose) -> Result<f64, FkError> {
        let cost = eval(self.model, self.data, x, self.q_theta)?;
        self.last_grad = gradient(self.model, self.data, x, self.q_theta);
        self.last_roundoff = cost_roundoff(self.data, self.q_theta);
        Ok(cost)
    }

    fn begin(&mut self, _x: &Pose, _cost: &mut f64) -> Result<Flow, FkError> {
        // The current point was the last one evaluated.
        self.grad = self.last_grad;
        Ok(Flow::Continue)
    }

    fn normal_equations(
        &mut self,
        x: &Pose,
        jtj: &mut Matrix6<f64>,
        g: &mut Vector6<f64>,
    ) -> Result<(), FkError> {
        // J = −A T, JᵀJ = Tᵀ(AᵀA)T, Jᵀρ = −Tᵀ Σ v_i ρ_i.
        let t = twist_from_coordinates(x);
        let mut ata = Matrix6::zeros();
        let mut atr = Vector6::zeros();
        for i in 0..self.model.m() {
            let v = self.data.at[i];
            ata += v * v.transpose();
            atr += v * (self.data.q[i] - self.q_theta[i]);
        }
        *jtj = t.transpose() * ata * t;
        *g = -(t.transpose() * atr);
        Ok(())
    }

    fn retract(&self, x: &Pose, step: &Vector6<f64>) -> Pose {
        x.add_increment(step)
    }

    fn accepts(&mut self, cost: f64, cost_new: f64) -> bool {
        // With inconsistent lengths the cost stays finite and its change drops below
        // round-off before the pose has converged; there the gradient decides.
        let at_roundoff = (cost_new - cost).abs() <= self.last_roundoff;
        (cost_new < cost && !at_roundoff) || (at_roundoff && self.last_grad < self.grad)
    }

    fn accepted(&mut self, s: &Accepted<'_, Pose, U6>) -> bool {
        self.grad = self.last_grad;
        s.step.amax() < self.opts.step_tolerance || s.cost_after == 0.0
    }
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
