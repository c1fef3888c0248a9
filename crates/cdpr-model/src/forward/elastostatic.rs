//! Elastostatic forward kinematics (x, f) = ν_el(q_θ, w_e) (eq. 2.42): the pose where the
//! residual wrench ρ(x) = A^T(x) f(x, q_θ) + w_e (eq. 2.43) vanishes, by Levenberg–Marquardt
//! with the analytic Jacobian ∂ρ/∂x = K_G − K_C (eq. 2.74, 2.76) in pose coordinates.
//! Slack cables (f < 0) carry no force (see [`crate::elastostatics::cable_forces`]).

use super::{FkError, FkOptions, FkSolution, check_input, from_lm};
use crate::elastostatics::{self, CableLaw, Stiffness};
use crate::kinematics;
use crate::levenberg_marquardt::{self as lm, Accepted, Flow};
use crate::model::{Data, Model};
use crate::pose::{Pose, twist_from_coordinates};
use crate::statics;
use nalgebra::{Matrix6, U6, Vector6};

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

/// ν_el with an arbitrary cable law and external wrench.
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
    let load = w_e.amax();
    elastostatic_with(
        model,
        data,
        |data: &mut Data, x: &Pose| {
            kinematics::inverse(model, data, x)?;
            elastostatics::cable_forces(data, law, q_theta);
            Ok(WrenchResidual {
                rho: statics::cable_wrench(data, &data.f) + w_e,
                load,
            })
        },
        guess,
        opts,
    )
}

/// The residual wrench at a pose and the size of the load it balances there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WrenchResidual {
    /// ρ = A^T f + w_e (eq. 2.43), N and N·m.
    pub rho: Vector6<f64>,
    /// ‖w_e‖_∞ at that pose (the tolerances scale with Σ f + ‖w_e‖_∞ + 1 N).
    pub load: f64,
}

/// ν_el for any equilibrium residual: `residual(data, x)` leaves the kinematics of x in
/// `data.{q, u, at, …}` and the cable forces in `data.f` and returns ρ(x). The Jacobian is
/// K_G − K_C (eq. 2.74, 2.76) of the state in `data`, exact when the law and the wrench do not
/// depend on the pose; the simulated plant passes pose-dependent ones (sag chord angles, a
/// gravity torque), whose neglected derivatives slow the convergence but not its limit.
/// The input lengths are the residual's own; `guess` must be finite.
pub fn elastostatic_with(
    model: &Model,
    data: &mut Data,
    residual: impl FnMut(&mut Data, &Pose) -> Result<WrenchResidual, FkError>,
    guess: &Pose,
    opts: &FkOptions,
) -> Result<FkSolution, FkError> {
    if !guess.is_finite() {
        return Err(FkError::Kinematics(
            kinematics::KinematicsError::NonFinitePose,
        ));
    }
    let mut problem = WrenchProblem {
        model,
        data,
        residual,
        opts,
        last: WrenchResidual {
            rho: Vector6::zeros(),
            load: 0.0,
        },
    };
    let out = lm::solve(&mut problem, *guess, &opts.lm_settings(5.0)).map_err(from_lm)?;
    if out.stop == lm::Stop::Satisfied {
        return Ok(FkSolution {
            pose: out.point,
            iterations: out.iterations,
            residual_norm: problem.last.rho.norm(),
        });
    }
    // Small step, no descent or the iteration limit: the residual wrench decides.
    let rho = (problem.residual)(problem.data, &out.point)?;
    let data = problem.data;
    if data.f.iter().all(|f| *f == 0.0) {
        return Err(FkError::AllSlack);
    }
    if rho.rho.amax() > opts.wrench_acceptance * scale(data, rho.load) {
        return Err(FkError::NotConverged {
            iterations: out.iterations,
            residual: rho.rho.norm(),
        });
    }
    Ok(FkSolution {
        pose: out.point,
        iterations: out.iterations,
        residual_norm: rho.rho.norm(),
    })
}

fn scale(data: &Data, load: f64) -> f64 {
    data.f.iter().sum::<f64>() + load + 1.0
}

struct WrenchProblem<'a, R> {
    model: &'a Model,
    data: &'a mut Data,
    residual: R,
    opts: &'a FkOptions,
    /// The residual of the last evaluated point.
    last: WrenchResidual,
}

impl<R> lm::Problem<U6> for WrenchProblem<'_, R>
where
    R: FnMut(&mut Data, &Pose) -> Result<WrenchResidual, FkError>,
{
    type Point = Pose;
    type Error = FkError;

    fn dim(&self) -> U6 {
        U6
    }

    fn cost(&mut self, x: &Pose) -> Result<f64, FkError> {
        self.last = (self.residual)(self.data, x)?;
        Ok(0.5 * self.last.rho.norm_squared())
    }

    fn begin(&mut self, _x: &Pose, _cost: &mut f64) -> Result<Flow, FkError> {
        // The current point was the last one evaluated: `data` and `last` hold its state.
        if self.data.f.iter().all(|f| *f == 0.0) {
            return Err(FkError::AllSlack);
        }
        if self.last.rho.amax() <= self.opts.wrench_tolerance * scale(self.data, self.last.load) {
            return Ok(Flow::Done);
        }
        Ok(Flow::Continue)
    }

    fn normal_equations(
        &mut self,
        x: &Pose,
        jtj: &mut Matrix6<f64>,
        g: &mut Vector6<f64>,
    ) -> Result<(), FkError> {
        let j = Stiffness::at(self.model, self.data).k_wx * twist_from_coordinates(x);
        *jtj = j.transpose() * j;
        *g = j.transpose() * self.last.rho;
        Ok(())
    }

    fn retract(&self, x: &Pose, step: &Vector6<f64>) -> Pose {
        x.add_increment(step)
    }

    fn accepted(&mut self, s: &Accepted<'_, Pose, U6>) -> bool {
        s.step.amax() < self.opts.step_tolerance
    }
}
