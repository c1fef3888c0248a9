//! Forward kinematics: least-squares ν(q_θ) (eq. 2.9–2.15) and elastostatic
//! (x, f) = ν_el(q_θ, w_e) (eq. 2.42–2.43), both by the library's Levenberg–Marquardt
//! ([`crate::levenberg_marquardt`]) with analytic Jacobians, for the standard and the pulley
//! model. Non-convergence is an error value, never a pose.

mod elastostatic;
mod least_squares;

pub use elastostatic::{WrenchResidual, elastostatic, elastostatic_with, elastostatic_with_law};
pub use least_squares::least_squares;

use crate::kinematics::KinematicsError;
use crate::levenberg_marquardt::{self as lm, Damping, OnSingular};
use crate::pose::Pose;

/// Solver settings. The defaults reach round-off on the CRS geometry in a handful of steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FkOptions {
    /// Iteration limit.
    pub max_iterations: usize,
    /// Converged when an accepted step is smaller than this (max-norm, m and rad).
    pub step_tolerance: f64,
    /// ν_el: converged when ‖A^T f + w_e‖_∞ ≤ this × (Σ f + ‖w_e‖_∞ + 1 N).
    pub wrench_tolerance: f64,
    /// ν_el: a result whose residual wrench exceeds this × (Σ f + ‖w_e‖_∞ + 1 N) is rejected.
    pub wrench_acceptance: f64,
    /// ν: a result whose gradient ‖J^T ρ‖_∞ exceeds this (m²) is rejected.
    pub gradient_acceptance: f64,
    /// Initial Levenberg–Marquardt damping (relative to diag(J^T J)).
    pub initial_damping: f64,
}

impl Default for FkOptions {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            step_tolerance: 1e-11,
            wrench_tolerance: 1e-13,
            wrench_acceptance: 1e-8,
            gradient_acceptance: 1e-9,
            initial_damping: 1e-6,
        }
    }
}

/// A converged forward-kinematics solution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FkSolution {
    pub pose: Pose,
    pub iterations: usize,
    /// ν: ‖q(x) − q_θ‖_2 (m); ν_el: ‖A^T f + w_e‖_2 (N, N·m).
    pub residual_norm: f64,
}

/// Why a forward-kinematics solve did not produce a pose.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum FkError {
    #[error("input is not finite (cable {cable})")]
    NonFiniteInput { cable: usize },
    #[error("wrong number of cable lengths: expected {expected}, got {got}")]
    WrongLength { expected: usize, got: usize },
    #[error("inverse kinematics failed during the solve: {0}")]
    Kinematics(#[from] KinematicsError),
    #[error("the normal equations are singular (iteration {iteration})")]
    Singular { iteration: usize },
    #[error("all cables are slack: no equilibrium")]
    AllSlack,
    #[error("no convergence after {iterations} iterations (residual {residual:.3e})")]
    NotConverged { iterations: usize, residual: f64 },
    #[error("the residual or its gradient is not finite (iteration {iteration})")]
    NonFinite { iteration: usize },
}

impl FkOptions {
    /// The Levenberg–Marquardt bounds of both pose solvers: damping relative to diag(JᵀJ)
    /// (floor 1e-12), ×4 after a rejected step up to 1e12, ÷`decrease` after an accepted one.
    pub(crate) fn lm_settings(&self, decrease: f64) -> lm::Settings {
        lm::Settings {
            max_iterations: self.max_iterations,
            // ×4 from the smallest damping to the largest is < 50 trials; this only bounds
            // a degenerate `initial_damping` (0 would never grow).
            max_trials: 200,
            initial_damping: self.initial_damping,
            decrease,
            min_damping: 1e-15,
            increase: 4.0,
            max_damping: 1e12,
            damping: Damping::Marquardt { floor: 1e-12 },
            on_singular: OnSingular::Fail,
            gradient_tolerance: None,
        }
    }
}

/// The solver's failures as forward-kinematics errors (the problem's own errors unchanged).
pub(crate) fn from_lm(e: lm::LmError<FkError>) -> FkError {
    match e {
        lm::LmError::Start(e) | lm::LmError::Problem { source: e, .. } => e,
        lm::LmError::Singular { iteration } => FkError::Singular { iteration },
        lm::LmError::NonFiniteStart => FkError::NonFinite { iteration: 0 },
        lm::LmError::NonFiniteGradient { iteration } => FkError::NonFinite { iteration },
    }
}

pub(crate) fn check_input(m: usize, q_theta: &[f64], guess: &Pose) -> Result<(), FkError> {
    if q_theta.len() != m {
        return Err(FkError::WrongLength {
            expected: m,
            got: q_theta.len(),
        });
    }
    if let Some(cable) = q_theta.iter().position(|v| !v.is_finite()) {
        return Err(FkError::NonFiniteInput { cable });
    }
    if !guess.is_finite() {
        return Err(FkError::Kinematics(KinematicsError::NonFinitePose));
    }
    Ok(())
}
