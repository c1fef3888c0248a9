//! The library's Levenberg–Marquardt against references not written here: nalgebra's SVD for a
//! linear least-squares problem and the `levenberg-marquardt` crate (a port of MINPACK's lmder)
//! for nonlinear ones; and its bounds: every stop other than convergence is typed.

use cdpr_model::levenberg_marquardt::{
    self as lm, Accepted, Damping, LmError, OnSingular, Settings, Stop,
};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};

/// Plain settings: Marquardt scaling, the calibration's schedule.
fn settings() -> Settings {
    Settings {
        max_iterations: 200,
        max_trials: 60,
        initial_damping: 1e-4,
        decrease: 3.0,
        min_damping: 1e-15,
        increase: 4.0,
        max_damping: 1e16,
        damping: Damping::Marquardt { floor: 1e-30 },
        on_singular: OnSingular::IncreaseDamping,
        gradient_tolerance: Some(1e-300),
    }
}

/// A residual function r(z) with an analytic Jacobian, as the library's problem (stops on a
/// relative step below 1e-14).
struct Dense<F, J> {
    n: usize,
    r: F,
    j: J,
    last: DVector<f64>,
}

impl<F, J> lm::Problem<Dyn> for Dense<F, J>
where
    F: Fn(&DVector<f64>) -> DVector<f64>,
    J: Fn(&DVector<f64>) -> DMatrix<f64>,
{
    type Point = DVector<f64>;
    type Error = ();
    fn dim(&self) -> Dyn {
        Dyn(self.n)
    }
    fn cost(&mut self, z: &DVector<f64>) -> Result<f64, ()> {
        self.last = (self.r)(z);
        Ok(0.5 * self.last.norm_squared())
    }
    fn normal_equations(
        &mut self,
        z: &DVector<f64>,
        jtj: &mut DMatrix<f64>,
        g: &mut DVector<f64>,
    ) -> Result<(), ()> {
        let j = (self.j)(z);
        jtj.copy_from(&(j.transpose() * &j));
        g.copy_from(&(j.transpose() * &self.last));
        Ok(())
    }
    fn retract(&self, z: &DVector<f64>, step: &DVector<f64>) -> DVector<f64> {
        z + step
    }
    fn accepted(&mut self, s: &Accepted<'_, DVector<f64>, Dyn>) -> bool {
        s.step.norm() <= 1e-14 * (s.from.norm() + 1e-14)
    }
}

/// The same residual function as the MINPACK port's problem.
struct Minpack<F, J> {
    z: DVector<f64>,
    r: F,
    j: J,
}

impl<F, J> LeastSquaresProblem<f64, Dyn, Dyn> for Minpack<F, J>
where
    F: Fn(&DVector<f64>) -> DVector<f64>,
    J: Fn(&DVector<f64>) -> DMatrix<f64>,
{
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;
    fn set_params(&mut self, z: &DVector<f64>) {
        self.z.copy_from(z);
    }
    fn params(&self) -> DVector<f64> {
        self.z.clone()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        Some((self.r)(&self.z))
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        Some((self.j)(&self.z))
    }
}

/// Solves with both and returns (ours, MINPACK's) optimum and cost.
fn both<F, J>(r: F, j: J, z0: &[f64]) -> ((DVector<f64>, f64), (DVector<f64>, f64))
where
    F: Fn(&DVector<f64>) -> DVector<f64> + Clone,
    J: Fn(&DVector<f64>) -> DMatrix<f64> + Clone,
{
    let z0 = DVector::from_column_slice(z0);
    let mut ours = Dense {
        n: z0.len(),
        r: r.clone(),
        j: j.clone(),
        last: DVector::zeros(0),
    };
    let out = lm::solve(&mut ours, z0.clone(), &settings()).expect("our solve");
    assert_ne!(out.stop, Stop::MaxIterations, "{out:?}");
    let (theirs, report) = LevenbergMarquardt::new()
        .with_ftol(1e-15)
        .with_xtol(1e-15)
        .minimize(Minpack { z: z0, r, j });
    assert!(report.termination.was_successful(), "{report:?}");
    ((out.point, out.cost), (theirs.z, report.objective_function))
}

#[test]
fn a_linear_problem_reaches_the_svd_solution() {
    // A tall, moderately conditioned A (entries from a fixed recurrence, not random).
    let (m, n) = (12, 4);
    let a = DMatrix::from_fn(m, n, |i, k| {
        ((i * 7 + k * 3) % 11) as f64 / 11.0 + if i == k { 1.0 } else { 0.0 }
    });
    let b = DVector::from_fn(m, |i, _| ((i * 5) % 7) as f64 - 3.0);
    let reference = a.clone().svd(true, true).solve(&b, 1e-14).unwrap();
    let (aa, bb) = (a.clone(), b.clone());
    let mut p = Dense {
        n,
        r: move |z: &DVector<f64>| &aa * z - &bb,
        j: move |_: &DVector<f64>| a.clone(),
        last: DVector::zeros(0),
    };
    let out = lm::solve(&mut p, DVector::zeros(n), &settings()).unwrap();
    let err = (&out.point - &reference).amax();
    assert!(err < 1e-10, "{} vs {reference}: {err:e}", out.point);
}

/// A residual function and its Jacobian without captures.
type Residual = fn(&DVector<f64>) -> DVector<f64>;
type Jacobian = fn(&DVector<f64>) -> DMatrix<f64>;

/// Rosenbrock as least squares: r = (10 (z₁ − z₀²), 1 − z₀), minimum 0 at (1, 1).
fn rosenbrock() -> (Residual, Jacobian) {
    (
        |z| DVector::from_vec(vec![10.0 * (z[1] - z[0] * z[0]), 1.0 - z[0]]),
        |z| DMatrix::from_row_slice(2, 2, &[-20.0 * z[0], 10.0, -1.0, 0.0]),
    )
}

#[test]
fn rosenbrock_agrees_with_minpack() {
    let (r, j) = rosenbrock();
    let ((ours, c_ours), (theirs, c_theirs)) = both(r, j, &[-1.2, 1.0]);
    assert!((&ours - &theirs).amax() < 1e-9, "{ours} vs {theirs}");
    assert!((&ours - DVector::from_vec(vec![1.0, 1.0])).amax() < 1e-9);
    assert!(
        c_ours < 1e-20 && c_theirs < 1e-20,
        "{c_ours:e} {c_theirs:e}"
    );
}

#[test]
fn an_exponential_fit_with_a_nonzero_residual_agrees_with_minpack() {
    // y_i = 5 e^{−0.7 t_i} + 1 plus a fixed non-random perturbation: the optimum has a
    // residual, so both stop at a stationary point, not at zero.
    let t: Vec<f64> = (0..20).map(|i| 0.25 * i as f64).collect();
    let y: Vec<f64> = t
        .iter()
        .enumerate()
        .map(|(i, t)| 5.0 * (-0.7 * t).exp() + 1.0 + 0.02 * ((i * 37 % 11) as f64 - 5.0))
        .collect();
    let (t1, y1, t2) = (t.clone(), y.clone(), t.clone());
    let r = move |z: &DVector<f64>| {
        DVector::from_fn(t1.len(), |i, _| z[0] * (-z[1] * t1[i]).exp() + z[2] - y1[i])
    };
    let j = move |z: &DVector<f64>| {
        DMatrix::from_fn(t2.len(), 3, |i, k| {
            let e = (-z[1] * t2[i]).exp();
            [e, -z[0] * t2[i] * e, 1.0][k]
        })
    };
    let ((ours, c_ours), (theirs, c_theirs)) = both(r, j, &[1.0, 0.1, 0.0]);
    assert!((&ours - &theirs).amax() < 1e-8, "{ours} vs {theirs}");
    assert!(
        (c_ours - c_theirs).abs() <= 1e-12 * c_theirs,
        "{c_ours:e} {c_theirs:e}"
    );
    assert!(c_ours > 1e-4, "the fit has a residual: {c_ours:e}");
}

#[test]
fn the_iteration_limit_is_a_typed_stop() {
    let (r, j) = rosenbrock();
    let mut p = Dense {
        n: 2,
        r,
        j,
        last: DVector::zeros(0),
    };
    let s = Settings {
        max_iterations: 2,
        ..settings()
    };
    let out = lm::solve(&mut p, DVector::from_vec(vec![-1.2, 1.0]), &s).unwrap();
    assert_eq!(out.stop, Stop::MaxIterations);
    assert_eq!(out.iterations, 2);
}

/// r = (z₀ − 1, 0): the second column of J is zero, so JᵀJ is singular.
fn degenerate() -> Dense<Residual, Jacobian> {
    Dense {
        n: 2,
        r: |z| DVector::from_vec(vec![z[0] - 1.0, 0.0]),
        j: |_| DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 0.0]),
        last: DVector::zeros(0),
    }
}

#[test]
fn a_singular_system_fails_or_is_damped_within_the_trial_bound() {
    let z0 = DVector::from_vec(vec![3.0, 0.0]);
    // Without a floor the damping cannot make the zero column definite.
    let fail = Settings {
        damping: Damping::Marquardt { floor: 0.0 },
        on_singular: OnSingular::Fail,
        ..settings()
    };
    assert_eq!(
        lm::solve(&mut degenerate(), z0.clone(), &fail),
        Err(LmError::Singular { iteration: 1 })
    );
    let damp = Settings {
        on_singular: OnSingular::IncreaseDamping,
        max_trials: 7,
        ..fail
    };
    let out = lm::solve(&mut degenerate(), z0.clone(), &damp).unwrap();
    assert_eq!(out.stop, Stop::NoDescent);
    assert_eq!(out.evaluations, 1, "no trial point was evaluated");
    assert_eq!(out.point, z0);
    // With Marquardt's floor the same problem is solved.
    let out = lm::solve(&mut degenerate(), z0, &settings()).unwrap();
    assert!((out.point[0] - 1.0).abs() < 1e-12, "{out:?}");
}

#[test]
fn a_non_finite_start_is_an_error_not_a_point() {
    let mut p = Dense {
        n: 1,
        r: |z: &DVector<f64>| z.map(|v| v.sqrt()),
        j: |z: &DVector<f64>| DMatrix::from_element(1, 1, 0.5 / z[0].sqrt()),
        last: DVector::zeros(0),
    };
    assert_eq!(
        lm::solve(&mut p, DVector::from_vec(vec![-1.0]), &settings()),
        Err(LmError::NonFiniteStart)
    );
}

#[test]
fn a_problem_without_descent_stops_at_the_damping_bound() {
    // The gradient points the wrong way (J of the negated residual): no damped step descends.
    let mut p = Dense {
        n: 1,
        r: |z: &DVector<f64>| z.clone(),
        j: |_: &DVector<f64>| DMatrix::from_element(1, 1, -1.0),
        last: DVector::zeros(0),
    };
    let s = Settings {
        max_trials: 1000,
        max_damping: 1e6,
        ..settings()
    };
    let out = lm::solve(&mut p, DVector::from_vec(vec![1.0]), &s).unwrap();
    assert_eq!(out.stop, Stop::NoDescent);
    // μ from 1e-4 by ×4 past 1e6: 17 rejected trials.
    assert_eq!(out.evaluations, 1 + 17);
    assert_eq!(out.point[0], 1.0);
}
