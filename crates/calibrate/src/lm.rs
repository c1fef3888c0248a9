//! Dense Levenberg–Marquardt (Moré 1978) on the normal equations with Marquardt's diagonal
//! scaling, for the nonlinear least-squares problems of eq. (4.10–4.16): the Gauss–Newton step
//! of eq. (4.11) with J^T J as the Hessian approximation (eq. 4.16), damped until it descends.
//!
//! Box constraints (a parameter's physical range) are kept by projection with an active set
//! (as in projected Levenberg–Marquardt / trust-region reflective solvers): a variable at a
//! bound whose gradient pushes it outwards is held for the step, the others take the damped
//! step of the reduced system, and the trial point is clipped into the box. Treating a step
//! outside the box as uphill instead (the earlier design) stalls a fit that starts at a bound
//! (a stored rope of 0 m whose gradient wants one cable negative) or that a bound stops: every
//! coupled step leaves the box, the damping grows until the step vanishes, and the fit reports
//! its start as the optimum.

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
    /// Range (lower, upper) of variable k (±∞ when unbounded); the start must lie inside.
    fn bounds(&self, _k: usize) -> (f64, f64) {
        (f64::NEG_INFINITY, f64::INFINITY)
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
    let bounds: Vec<(f64, f64)> = (0..n).map(|k| p.bounds(k)).collect();
    let bounded = bounds
        .iter()
        .any(|(lo, hi)| lo.is_finite() || hi.is_finite());
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
        // Active set: variables at a bound whose descent direction −g leaves the box.
        let active: Vec<bool> = (0..n)
            .map(|k| {
                let (lo, hi) = bounds[k];
                (z[k] <= lo && g[k] > 0.0) || (z[k] >= hi && g[k] < 0.0)
            })
            .collect();
        if bounded
            && (0..n)
                .filter(|k| !active[*k])
                .all(|k| g[k].abs() <= opts.gtol)
        {
            converged = true;
            break;
        }
        let mut accepted = false;
        for _ in 0..60 {
            let mut a = jtj.clone();
            let mut rhs = -&g;
            for k in 0..n {
                a[(k, k)] += mu * jtj[(k, k)].max(1e-30);
            }
            for k in (0..n).filter(|k| active[*k]) {
                a.row_mut(k).fill(0.0);
                a.column_mut(k).fill(0.0);
                a[(k, k)] = 1.0;
                rhs[k] = 0.0;
            }
            let step = match a.cholesky() {
                Some(c) => c.solve(&rhs),
                None => {
                    mu = (mu * 10.0).max(1e-12);
                    continue;
                }
            };
            let mut z_new = &z + &step;
            if bounded {
                for k in 0..n {
                    z_new[k] = z_new[k].clamp(bounds[k].0, bounds[k].1);
                }
            }
            let step = &z_new - &z;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// r = (z₀ + 1, z₁ − z₀ − 2) with z₀ ≥ 0, started at z = (0, 0) on the bound: the free
    /// optimum (−1, 1) lies outside, the bounded one is (0, 2). A solver that rejects every step
    /// leaving the box stalls at the start (each coupled step leaves it); the active set holds
    /// z₀ and moves z₁.
    struct Coupled;

    impl LsqProblem for Coupled {
        type Error = ();
        fn n_residuals(&self) -> usize {
            2
        }
        fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), ()> {
            if z[0] < 0.0 {
                return Err(());
            }
            r[0] = z[0] + 1.0;
            r[1] = z[1] - z[0] - 2.0;
            Ok(())
        }
        fn jacobian(&mut self, _z: &DVector<f64>, j: &mut DMatrix<f64>) -> Result<(), ()> {
            j[(0, 0)] = 1.0;
            j[(1, 0)] = -1.0;
            j[(1, 1)] = 1.0;
            Ok(())
        }
        fn bounds(&self, k: usize) -> (f64, f64) {
            if k == 0 {
                (0.0, f64::INFINITY)
            } else {
                (f64::NEG_INFINITY, f64::INFINITY)
            }
        }
    }

    #[test]
    fn a_fit_starting_on_a_bound_it_presses_does_not_stall() {
        let res = solve(
            &mut Coupled,
            DVector::from_vec(vec![0.0, 0.0]),
            &LmOptions::default(),
            &mut |_, _| {},
        )
        .unwrap();
        assert!(res.z[0] == 0.0, "{}", res.z);
        assert!((res.z[1] - 2.0).abs() < 1e-9, "{}", res.z);
        assert!((res.cost - 0.5).abs() < 1e-12, "{}", res.cost);
    }

    /// Without bounds the same problem reaches its free optimum.
    #[test]
    fn an_unbounded_fit_reaches_the_free_optimum() {
        struct Free;
        impl LsqProblem for Free {
            type Error = ();
            fn n_residuals(&self) -> usize {
                2
            }
            fn residual(&mut self, z: &DVector<f64>, r: &mut DVector<f64>) -> Result<(), ()> {
                r[0] = z[0] + 1.0;
                r[1] = z[1] - z[0] - 2.0;
                Ok(())
            }
            fn jacobian(&mut self, _z: &DVector<f64>, j: &mut DMatrix<f64>) -> Result<(), ()> {
                j[(0, 0)] = 1.0;
                j[(1, 0)] = -1.0;
                j[(1, 1)] = 1.0;
                Ok(())
            }
        }
        let res = solve(
            &mut Free,
            DVector::from_vec(vec![0.0, 0.0]),
            &LmOptions::default(),
            &mut |_, _| {},
        )
        .unwrap();
        assert!(
            (res.z[0] + 1.0).abs() < 1e-9 && (res.z[1] - 1.0).abs() < 1e-9,
            "{}",
            res.z
        );
    }
}
