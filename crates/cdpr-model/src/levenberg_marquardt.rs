//! The one Levenberg–Marquardt of the stack for small dense nonlinear least-squares problems
//! min ½‖r(x)‖²: the Gauss–Newton step (JᵀJ) δ = −Jᵀr of eq. (2.12–2.15) / (4.11, 4.16), damped
//! until it descends (Marquardt 1963, Moré 1978). Every solver of the model library and of
//! calibration runs on it: ν and ν_el ([`crate::forward`]), the plant's pose-dependent ν_el, the
//! planar ν_el (`cdpr_analysis::planar`) and calibration's identification. docs/adr/0013 says
//! why it is written here and not taken from the `levenberg-marquardt` crate.
//!
//! Bounded: at most `max_iterations` Jacobians and `max_trials` damped steps per Jacobian, the
//! damping clamped to `[min_damping, max_damping]`. The outcome is typed ([`Stop`], [`LmError`]);
//! a stop other than convergence carries the last accepted iterate for the caller's own
//! acceptance test (e.g. the residual wrench of ν_el), never as a solution.
//!
//! Fixed sizes (`U6` for the pose) allocate nothing: the normal equations, the factor and the
//! step live on the stack, so ν and ν_el stay allocation-free in the hard loop. Dynamic sizes
//! allocate the normal equations once per call.

use nalgebra::allocator::Allocator;
use nalgebra::{Cholesky, DefaultAllocator, Dim, OMatrix, OVector};

/// How the damping μ enters the normal equations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Damping {
    /// Marquardt's scaling: (JᵀJ)_kk += μ · max((JᵀJ)_kk, floor), invariant to the units of
    /// each variable.
    Marquardt { floor: f64 },
    /// Levenberg's: (JᵀJ)_kk += μ · max_j (JᵀJ)_jj on every diagonal element.
    Levenberg,
}

/// What a damped system that is not positive definite does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OnSingular {
    /// The solve fails with [`LmError::Singular`] (the pose solvers: JᵀJ + μ D is positive
    /// definite unless J is degenerate, which is an answer in itself).
    Fail,
    /// μ ← max(10 μ, 1e-12) and the trial is repeated (counts as a trial).
    IncreaseDamping,
}

/// The bounds and the damping schedule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Jacobians evaluated at most.
    pub max_iterations: usize,
    /// Damped steps tried per Jacobian before the point counts as stationary.
    pub max_trials: usize,
    pub initial_damping: f64,
    /// μ ← max(μ / `decrease`, `min_damping`) after an accepted step.
    pub decrease: f64,
    pub min_damping: f64,
    /// μ ← μ · `increase` after a rejected step; above `max_damping` the point is stationary.
    pub increase: f64,
    pub max_damping: f64,
    pub damping: Damping,
    pub on_singular: OnSingular,
    /// Stationary when max |Jᵀr|_k over the free variables is at most this (None: no test).
    pub gradient_tolerance: Option<f64>,
}

/// Why the iteration stopped with a point. Only [`Stop::MaxIterations`] means "not converged"
/// in the solver's own terms; every caller still applies its own acceptance test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// The problem's test at the start of an iteration holds ([`Problem::begin`]).
    Satisfied,
    /// The gradient is below `gradient_tolerance`.
    Stationary,
    /// An accepted step met the problem's step test ([`Problem::accepted`]).
    SmallStep,
    /// No damped step descends within `max_trials` / `max_damping`: a stationary point to
    /// working precision (or a stall; the caller's acceptance test tells which).
    NoDescent,
    /// `max_iterations` Jacobians without convergence.
    MaxIterations,
}

/// The last accepted iterate and why the iteration stopped.
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome<P> {
    pub point: P,
    /// ½‖r‖² at `point`.
    pub cost: f64,
    /// Jacobians evaluated.
    pub iterations: usize,
    /// Cost evaluations (the start and every trial).
    pub evaluations: usize,
    pub stop: Stop,
}

/// Why the iteration produced no point.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LmError<E> {
    /// The cost at the start point could not be evaluated.
    #[error("at the start point: {0}")]
    Start(E),
    /// The cost at the start point is not finite.
    #[error("the cost at the start point is not finite")]
    NonFiniteStart,
    /// The problem failed at an accepted point (normal equations, or its start-of-iteration
    /// test).
    #[error("iteration {iteration}: {source}")]
    Problem { iteration: usize, source: E },
    /// The damped normal equations are not positive definite ([`OnSingular::Fail`]).
    #[error("the normal equations are singular (iteration {iteration})")]
    Singular { iteration: usize },
    /// The gradient is not finite at an accepted point.
    #[error("the gradient is not finite (iteration {iteration})")]
    NonFiniteGradient { iteration: usize },
}

/// What the start of an iteration decides.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    Continue,
    /// Stop with [`Stop::Satisfied`].
    Done,
}

/// An accepted step, for the problem's step test.
pub struct Accepted<'a, P, D: Dim>
where
    DefaultAllocator: Allocator<D>,
{
    pub iteration: usize,
    pub from: &'a P,
    pub to: &'a P,
    /// The step as solved (before any projection the retraction applies).
    pub step: &'a OVector<f64, D>,
    pub cost_before: f64,
    pub cost_after: f64,
}

/// A least-squares problem: its cost, its normal equations and how a step moves a point.
pub trait Problem<D: Dim>
where
    DefaultAllocator: Allocator<D, D> + Allocator<D>,
{
    /// A point of the search space (a pose, a parameter vector).
    type Point: Clone;
    type Error;
    /// Number of variables.
    fn dim(&self) -> D;
    /// ½‖r(x)‖². `Err` marks x as outside the problem's valid region: a trial there counts as
    /// uphill. The problem may remember what it computed for a trial that is then accepted.
    fn cost(&mut self, x: &Self::Point) -> Result<f64, Self::Error>;
    /// JᵀJ and g = Jᵀr at the current point (the last accepted one, which was also the last
    /// point whose cost was evaluated).
    fn normal_equations(
        &mut self,
        x: &Self::Point,
        jtj: &mut OMatrix<f64, D, D>,
        g: &mut OVector<f64, D>,
    ) -> Result<(), Self::Error>;
    /// x ⊕ δ (a pose increment, a step clipped into a box).
    fn retract(&self, x: &Self::Point, step: &OVector<f64, D>) -> Self::Point;
    /// At the start of each iteration, at the current point: a residual test that stops the
    /// solve, or a change of the objective (new robust weights: the cost is then updated).
    fn begin(&mut self, _x: &Self::Point, _cost: &mut f64) -> Result<Flow, Self::Error> {
        Ok(Flow::Continue)
    }
    /// Whether a trial with cost `cost_new` replaces the current point of cost `cost`.
    fn accepts(&mut self, cost: f64, cost_new: f64) -> bool {
        cost_new <= cost
    }
    /// Is variable k held this iteration (at a bound its descent direction −g_k leaves)?
    fn held(&self, _x: &Self::Point, _g: &OVector<f64, D>, _k: usize) -> bool {
        false
    }
    /// Called for every accepted step; true when the step is small enough to stop.
    fn accepted(&mut self, step: &Accepted<'_, Self::Point, D>) -> bool;
}

/// Runs Levenberg–Marquardt from `x0` within the bounds of `settings`.
pub fn solve<D: Dim, P: Problem<D>>(
    problem: &mut P,
    x0: P::Point,
    settings: &Settings,
) -> Result<Outcome<P::Point>, LmError<P::Error>>
where
    DefaultAllocator: Allocator<D, D> + Allocator<D>,
{
    let d = problem.dim();
    let n = d.value();
    let mut x = x0;
    let mut cost = problem.cost(&x).map_err(LmError::Start)?;
    if !cost.is_finite() {
        return Err(LmError::NonFiniteStart);
    }
    let mut evaluations = 1;
    let mut jtj = OMatrix::<f64, D, D>::zeros_generic(d, d);
    let mut lhs = OMatrix::<f64, D, D>::zeros_generic(d, d);
    let mut g = OVector::<f64, D>::zeros_generic(d, nalgebra::Const::<1>);
    let mut step = OVector::<f64, D>::zeros_generic(d, nalgebra::Const::<1>);
    let mut mu = settings.initial_damping;
    let outcome = |point, cost, iterations, evaluations, stop| Outcome {
        point,
        cost,
        iterations,
        evaluations,
        stop,
    };
    for it in 1..=settings.max_iterations {
        let flow = problem
            .begin(&x, &mut cost)
            .map_err(|source| LmError::Problem {
                iteration: it,
                source,
            })?;
        if flow == Flow::Done {
            return Ok(outcome(x, cost, it - 1, evaluations, Stop::Satisfied));
        }
        problem
            .normal_equations(&x, &mut jtj, &mut g)
            .map_err(|source| LmError::Problem {
                iteration: it,
                source,
            })?;
        if g.iter().any(|v| !v.is_finite()) {
            return Err(LmError::NonFiniteGradient { iteration: it });
        }
        if let Some(tol) = settings.gradient_tolerance {
            let free_max = (0..n)
                .filter(|k| !problem.held(&x, &g, *k))
                .map(|k| g[k].abs())
                .fold(0.0, f64::max);
            if free_max <= tol {
                return Ok(outcome(x, cost, it, evaluations, Stop::Stationary));
            }
        }
        let mut trials = 0;
        loop {
            if trials == settings.max_trials {
                return Ok(outcome(x, cost, it, evaluations, Stop::NoDescent));
            }
            trials += 1;
            lhs.copy_from(&jtj);
            match settings.damping {
                Damping::Marquardt { floor } => {
                    for k in 0..n {
                        lhs[(k, k)] += mu * jtj[(k, k)].max(floor);
                    }
                }
                Damping::Levenberg => {
                    let scale = (0..n).map(|k| jtj[(k, k)]).fold(f64::MIN, f64::max);
                    for k in 0..n {
                        lhs[(k, k)] += mu * scale;
                    }
                }
            }
            step.copy_from(&g);
            step.neg_mut();
            for k in 0..n {
                if problem.held(&x, &g, k) {
                    lhs.row_mut(k).fill(0.0);
                    lhs.column_mut(k).fill(0.0);
                    lhs[(k, k)] = 1.0;
                    step[k] = 0.0;
                }
            }
            // In place and without a copy: `new_unchecked` computes the same factor as
            // `Cholesky::new`, which fails exactly where a diagonal entry is not > 0.
            let factor = Cholesky::new_unchecked(lhs);
            let definite = (0..n).all(|k| factor.l_dirty()[(k, k)] > 0.0);
            if definite {
                factor.solve_mut(&mut step);
            }
            lhs = factor.unpack_dirty();
            if !definite {
                match settings.on_singular {
                    OnSingular::Fail => return Err(LmError::Singular { iteration: it }),
                    OnSingular::IncreaseDamping => {
                        mu = (mu * 10.0).max(1e-12);
                        continue;
                    }
                }
            }
            let trial = problem.retract(&x, &step);
            evaluations += 1;
            let accepted = match problem.cost(&trial) {
                Ok(cost_new) if problem.accepts(cost, cost_new) => Some(cost_new),
                _ => None,
            };
            if let Some(cost_new) = accepted {
                mu = (mu / settings.decrease).max(settings.min_damping);
                let small = problem.accepted(&Accepted {
                    iteration: it,
                    from: &x,
                    to: &trial,
                    step: &step,
                    cost_before: cost,
                    cost_after: cost_new,
                });
                x = trial;
                cost = cost_new;
                if small {
                    return Ok(outcome(x, cost, it, evaluations, Stop::SmallStep));
                }
                break;
            }
            mu *= settings.increase;
            if mu > settings.max_damping {
                return Ok(outcome(x, cost, it, evaluations, Stop::NoDescent));
            }
        }
    }
    let iterations = settings.max_iterations;
    Ok(outcome(
        x,
        cost,
        iterations,
        evaluations,
        Stop::MaxIterations,
    ))
}
