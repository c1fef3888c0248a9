//! Levenberg–Marquardt for the nonlinear least-squares problems of eq. (4.10–4.16) in the
//! form identification poses them: a residual vector, its Jacobian and a box. The iteration is
//! the model library's ([`cdpr_model::levenberg_marquardt`]: the Gauss–Newton step of
//! eq. (4.11) with JᵀJ as the Hessian approximation, eq. 4.16, damped with Marquardt's scaling
//! until it descends); this module adds the box and the stopping rules of [`LmOptions`].
//!
//! Box constraints (a parameter's physical range) are kept by projection with an active set
//! (as in projected Levenberg–Marquardt / trust-region reflective solvers): a variable at a
//! bound whose gradient pushes it outwards is held for the step, the others take the damped
//! step of the reduced system, and the trial point is clipped into the box. Treating a step
//! outside the box as uphill instead stalls a fit that starts at a bound (a stored rope of
//! 0 m whose gradient wants one cable negative) or that a bound stops: every coupled step
//! leaves the box, the damping grows until the step vanishes, and the fit reports its start as
//! the optimum.

use cdpr_model::levenberg_marquardt as lm;
use nalgebra::{DMatrix, DVector, Dyn};

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
    /// The cost at the start point or the gradient at an accepted point is not finite.
    #[error("the cost or the gradient is not finite (iteration {iteration})")]
    NonFinite { iteration: usize },
}

/// Runs Levenberg–Marquardt from `z0` (the model library's
/// [`cdpr_model::levenberg_marquardt`], with Marquardt's scaling, the box held by the active
/// set and the residual-vector problem's own stopping rules). `on_iteration(iteration, cost)`
/// reports progress.
pub fn solve<P: LsqProblem>(
    p: &mut P,
    z0: DVector<f64>,
    opts: &LmOptions,
    on_iteration: &mut dyn FnMut(usize, f64),
) -> Result<LmResult, LmError<P::Error>> {
    let n = z0.len();
    let nr = p.n_residuals();
    let bounds: Vec<(f64, f64)> = (0..n).map(|k| p.bounds(k)).collect();
    let bounded = bounds
        .iter()
        .any(|(lo, hi)| lo.is_finite() || hi.is_finite());
    let mut adapter = Residuals {
        p,
        opts,
        bounds,
        bounded,
        r: DVector::zeros(nr),
        j: DMatrix::zeros(nr, n),
        history: Vec::new(),
        on_iteration,
    };
    let settings = lm::Settings {
        max_iterations: opts.max_iterations,
        max_trials: 60,
        initial_damping: opts.initial_damping,
        decrease: 3.0,
        min_damping: 1e-15,
        increase: 4.0,
        max_damping: 1e16,
        damping: lm::Damping::Marquardt { floor: 1e-30 },
        on_singular: lm::OnSingular::IncreaseDamping,
        gradient_tolerance: Some(opts.gtol),
    };
    let out = lm::solve(&mut adapter, z0, &settings).map_err(|e| match e {
        lm::LmError::Start(LmError::AtAccepted(e)) => LmError::AtStart(e),
        lm::LmError::Start(e) | lm::LmError::Problem { source: e, .. } => e,
        lm::LmError::NonFiniteStart => LmError::NonFinite { iteration: 0 },
        lm::LmError::NonFiniteGradient { iteration } | lm::LmError::Singular { iteration } => {
            LmError::NonFinite { iteration }
        }
    })?;
    let Residuals {
        p, mut r, history, ..
    } = adapter;
    p.residual(&out.point, &mut r)
        .map_err(LmError::AtAccepted)?;
    let cost = 0.5 * r.norm_squared();
    // A stop by the start-of-iteration test (zero cost) counts the iteration it stopped in.
    let iterations = match out.stop {
        lm::Stop::Satisfied => out.iterations + 1,
        _ => out.iterations,
    };
    Ok(LmResult {
        z: out.point,
        cost,
        residual: r,
        iterations,
        evaluations: out.evaluations,
        history,
        converged: out.stop != lm::Stop::MaxIterations,
    })
}

/// An [`LsqProblem`] as the solver's problem: JᵀJ from the residual Jacobian, the box by
/// projection and an active set (a variable at a bound whose descent direction −g leaves the
/// box is held for the step).
struct Residuals<'a, P: LsqProblem> {
    p: &'a mut P,
    opts: &'a LmOptions,
    bounds: Vec<(f64, f64)>,
    bounded: bool,
    r: DVector<f64>,
    j: DMatrix<f64>,
    /// Cost at the start and after every accepted step.
    history: Vec<f64>,
    on_iteration: &'a mut dyn FnMut(usize, f64),
}

impl<P: LsqProblem> lm::Problem<Dyn> for Residuals<'_, P> {
    type Point = DVector<f64>;
    type Error = LmError<P::Error>;

    fn dim(&self) -> Dyn {
        Dyn(self.bounds.len())
    }

    fn cost(&mut self, z: &DVector<f64>) -> Result<f64, Self::Error> {
        self.p
            .residual(z, &mut self.r)
            .map_err(LmError::AtAccepted)?;
        let cost = 0.5 * self.r.norm_squared();
        // The first evaluation is the start point's.
        if self.history.is_empty() {
            self.history.push(cost);
        }
        Ok(cost)
    }

    fn begin(&mut self, z: &DVector<f64>, cost: &mut f64) -> Result<lm::Flow, Self::Error> {
        if self.p.start_iteration(z) {
            self.p
                .residual(z, &mut self.r)
                .map_err(LmError::AtAccepted)?;
            *cost = 0.5 * self.r.norm_squared();
        }
        Ok(if *cost == 0.0 {
            lm::Flow::Done
        } else {
            lm::Flow::Continue
        })
    }

    fn normal_equations(
        &mut self,
        z: &DVector<f64>,
        jtj: &mut DMatrix<f64>,
        g: &mut DVector<f64>,
    ) -> Result<(), Self::Error> {
        self.j.fill(0.0);
        self.p
            .residual(z, &mut self.r)
            .map_err(LmError::AtAccepted)?;
        self.p.jacobian(z, &mut self.j).map_err(LmError::Jacobian)?;
        // gemm (matrixmultiply) is much faster than tr_mul's column dots for tall J.
        jtj.copy_from(&(self.j.transpose() * &self.j));
        self.j.tr_mul_to(&self.r, g);
        Ok(())
    }

    fn retract(&self, z: &DVector<f64>, step: &DVector<f64>) -> DVector<f64> {
        let mut z_new = z + step;
        if self.bounded {
            for (v, (lo, hi)) in z_new.iter_mut().zip(&self.bounds) {
                *v = v.clamp(*lo, *hi);
            }
        }
        z_new
    }

    fn held(&self, z: &DVector<f64>, g: &DVector<f64>, k: usize) -> bool {
        let (lo, hi) = self.bounds[k];
        (z[k] <= lo && g[k] > 0.0) || (z[k] >= hi && g[k] < 0.0)
    }

    fn accepted(&mut self, s: &lm::Accepted<'_, DVector<f64>, Dyn>) -> bool {
        // The step actually taken (after the projection into the box).
        let step = s.to - s.from;
        let small_step = step.norm() <= self.opts.xtol * (s.from.norm() + self.opts.xtol);
        let small_gain = s.cost_before - s.cost_after <= self.opts.ftol * s.cost_before;
        self.history.push(s.cost_after);
        (self.on_iteration)(s.iteration, s.cost_after);
        small_step || small_gain
    }
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
