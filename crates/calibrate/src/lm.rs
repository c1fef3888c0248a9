//! Dense Levenberg–Marquardt (Moré 1978) on the normal equations with Marquardt's diagonal
//! scaling, for the nonlinear least-squares problems of eq. (4.10–4.16): the Gauss–Newton step
//! of eq. (4.11) with J^T J as the Hessian approximation (eq. 4.16), damped until it descends.

use nalgebra::{DMatrix, DVector};

/// A least-squares problem in the (preconditioned) variables z.
pub trait LsqProblem {
    /// Why the residual or Jacobian cannot be evaluated at some z.
    type Error;
    fn n_residuals(&self) -> usize;
    /// Residual at z; `Err` marks z as outside the model's valid region (treated as uphill).
    fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), Self::Error>;
    /// Jacobian ∂r/∂z at z (the residual at z was the last one evaluated).
    fn jacobian(&mut self, z: &DVector<f64>, j: &mut DMatrix<f64>) -> Result<(), Self::Error>;
    /// Called at the start of every iteration (e.g. to update IRLS weights); returns true if
    /// the objective changed (the cost is then re-evaluated).
    fn start_iteration(&mut self, _z: &DVector<f64>) -> bool {
        false
    }
}

/// Stopping rules.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct LmOptions {
    pub max_iterations: usize,
    /// Stop when the relative cost reduction of an accepted step is below this.
    pub ftol: f64,
    /// Stop when ‖δz‖ ≤ xtol (‖z‖ + xtol).
    pub xtol: f64,
    /// Stop when ‖J^T r‖_∞ ≤ gtol.
    pub gtol: f64,
    pub initial_damping: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            ftol: 1e-15,
            xtol: 1e-15,
            gtol: 1e-300,
            initial_damping: 1e-4,
        }
    }
}

/// Result of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct LmResult {
    pub z: DVector<f64>,
    /// ½‖r‖² at z.
    pub cost: f64,
    pub residual: DVector<f64>,
    pub iterations: usize,
    pub evaluations: usize,
    /// Cost after every accepted iteration (first entry: the start).
    pub history: Vec<f64>,
    pub converged: bool,
}

/// Why a run failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LmError<E> {
    /// The start point itself is outside the model's valid region.
    #[error("residual at the start point: {0}")]
    AtStart(E),
    /// The residual could not be re-evaluated at an accepted point (the problem changed it,
    /// e.g. new IRLS weights).
    #[error("residual at an accepted point: {0}")]
    AtAccepted(E),
    /// The Jacobian could not be evaluated at an accepted point.
    #[error("Jacobian: {0}")]
    Jacobian(E),
}

/// Runs Levenberg–Marquardt from `z0`. `on_iteration(iteration, cost)` reports progress.
pub fn solve<P: LsqProblem>(
    p: &mut P,
    z0: DVector<f64>,
    opts: &LmOptions,
    on_iteration: &mut dyn FnMut(usize, f64),
) -> Result<LmResult, LmError<P::Error>> {
    let n = z0.len();
    let nr = p.n_residuals();
    let mut z = z0;
    let mut r = DVector::zeros(nr);
    p.residual(&z, &mut r).map_err(LmError::AtStart)?;
    let mut cost = 0.5 * r.norm_squared();
    let mut history = vec![cost];
    let mut j = DMatrix::zeros(nr, n);
    let mut mu = opts.initial_damping;
    let mut evaluations = 1;
    let mut r_new = DVector::zeros(nr);
    let mut converged = false;
    let mut iterations = 0;
    for it in 1..=opts.max_iterations {
        iterations = it;
        if p.start_iteration(&z) {
            p.residual(&z, &mut r).map_err(LmError::AtAccepted)?;
            cost = 0.5 * r.norm_squared();
        }
        if cost == 0.0 {
            converged = true;
            break;
        }
        j.fill(0.0);
        p.residual(&z, &mut r).map_err(LmError::AtAccepted)?;
        p.jacobian(&z, &mut j).map_err(LmError::Jacobian)?;
        // gemm (matrixmultiply) is much faster than tr_mul's column dots for tall J.
        let jtj = j.transpose() * &j;
        let g = j.tr_mul(&r);
        if g.amax() <= opts.gtol {
            converged = true;
            break;
        }
        let mut accepted = false;
        for _ in 0..60 {
            let mut a = jtj.clone();
            for k in 0..n {
                a[(k, k)] += mu * jtj[(k, k)].max(1e-30);
            }
            let step = match a.cholesky() {
                Some(c) => c.solve(&(-&g)),
                None => {
                    mu = (mu * 10.0).max(1e-12);
                    continue;
                }
            };
            let z_new = &z + &step;
            evaluations += 1;
            let ok = p.residual(&z_new, &mut r_new).is_ok();
            let cost_new = if ok {
                0.5 * r_new.norm_squared()
            } else {
                f64::INFINITY
            };
            if cost_new <= cost {
                let small_step = step.norm() <= opts.xtol * (z.norm() + opts.xtol);
                let small_gain = cost - cost_new <= opts.ftol * cost;
                z = z_new;
                std::mem::swap(&mut r, &mut r_new);
                cost = cost_new;
                mu = (mu / 3.0).max(1e-15);
                accepted = true;
                history.push(cost);
                on_iteration(it, cost);
                if small_step || small_gain {
                    converged = true;
                }
                break;
            }
            mu *= 4.0;
            if mu > 1e16 {
                break;
            }
        }
        if !accepted {
            // No descent direction left: a stationary point to working precision.
            converged = true;
            break;
        }
        if converged {
            break;
        }
    }
    p.residual(&z, &mut r).map_err(LmError::AtAccepted)?;
    cost = 0.5 * r.norm_squared();
    Ok(LmResult {
        z,
        cost,
        residual: r,
        iterations,
        evaluations,
        history,
        converged,
    })
}
