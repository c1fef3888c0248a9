//! The equilibrium as the minimum of the potential: damped Newton steps on a finite-difference
//! gradient and Hessian of U in world-frame pose increments (δr, δω).

use crate::energy::{cable_force, potential};
use crate::geometry::{PoseQ, cable_length};
use crate::linalg::cholesky_solve;
use crate::robot::{OracleError, Robot};
use glam::DVec3;

/// Minimiser settings. The defaults resolve the pose of a steel-cable robot to ~1e-11 m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Options {
    pub max_iterations: usize,
    /// Central-difference step of the gradient (m, rad). Balances the truncation error
    /// (∝ h², the third derivative of U) against round-off in U (∝ ε U / h).
    pub gradient_step: f64,
    /// Second-difference step of the Hessian (m, rad); the Hessian only steers the step, so
    /// its accuracy sets the convergence rate, not the answer.
    pub hessian_step: f64,
    /// Converged when a Newton step moves less than this (m, rad).
    pub step_tolerance: f64,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            max_iterations: 60,
            gradient_step: 1e-6,
            hessian_step: 1e-4,
            step_tolerance: 1e-12,
        }
    }
}

/// The minimum found.
#[derive(Clone, Debug, PartialEq)]
pub struct Equilibrium {
    /// `[x, y, z, φx, φy, φz]` (m, rad; R = R_x R_y R_z).
    pub pose: [f64; 6],
    pub pose_q: PoseQ,
    /// Cable forces from the law at the minimum's lengths, N (slack 0).
    pub forces: Vec<f64>,
    pub lengths: Vec<f64>,
    pub iterations: usize,
    /// Size of the last Newton step (m, rad): the resolution reached.
    pub last_step: f64,
    /// |∂U/∂x| at the minimum (N and N·m): the residual of the balance this formulation sees.
    pub gradient_norm: f64,
}

fn split(dx: &[f64; 6]) -> (DVec3, DVec3) {
    (
        DVec3::new(dx[0], dx[1], dx[2]),
        DVec3::new(dx[3], dx[4], dx[5]),
    )
}

/// U(base moved by dx) as a function of the increment dx = (δr, δω).
fn around<'a>(
    robot: &'a Robot,
    q_theta: &'a [f64],
    base: PoseQ,
) -> impl Fn(&[f64; 6]) -> Result<f64, OracleError> + 'a {
    move |dx| {
        let (dr, dw) = split(dx);
        potential(robot, q_theta, &base, dr, dw)
    }
}

fn gradient(
    u: &impl Fn(&[f64; 6]) -> Result<f64, OracleError>,
    h: f64,
) -> Result<[f64; 6], OracleError> {
    let mut g = [0.0; 6];
    for (k, gk) in g.iter_mut().enumerate() {
        let mut p = [0.0; 6];
        p[k] = h;
        let up = u(&p)?;
        p[k] = -h;
        let um = u(&p)?;
        *gk = (up - um) / (2.0 * h);
    }
    Ok(g)
}

fn hessian(
    u: &impl Fn(&[f64; 6]) -> Result<f64, OracleError>,
    u0: f64,
    h: f64,
) -> Result<[[f64; 6]; 6], OracleError> {
    let mut hm = [[0.0; 6]; 6];
    for j in 0..6 {
        let mut p = [0.0; 6];
        p[j] = h;
        let up = u(&p)?;
        p[j] = -h;
        let um = u(&p)?;
        hm[j][j] = (up - 2.0 * u0 + um) / (h * h);
        for k in 0..j {
            let mut v = 0.0;
            for (sj, sk, sign) in [
                (1.0, 1.0, 1.0),
                (1.0, -1.0, -1.0),
                (-1.0, 1.0, -1.0),
                (-1.0, -1.0, 1.0),
            ] {
                let mut p = [0.0; 6];
                p[j] = sj * h;
                p[k] = sk * h;
                v += sign * u(&p)?;
            }
            hm[j][k] = v / (4.0 * h * h);
            hm[k][j] = hm[j][k];
        }
    }
    Ok(hm)
}

/// The equilibrium the robot settles in with unstretched cable lengths `q_theta` (m), searched
/// from `guess` (`[x, y, z, φx, φy, φz]`): the local minimum of U nearest the guess.
pub fn equilibrium(
    robot: &Robot,
    q_theta: &[f64],
    guess: [f64; 6],
    opts: &Options,
) -> Result<Equilibrium, OracleError> {
    let m = robot.m();
    if q_theta.len() != m {
        return Err(OracleError::WrongLength {
            expected: m,
            got: q_theta.len(),
        });
    }
    if let Some(cable) = q_theta.iter().position(|q| !(q.is_finite() && *q > 0.0)) {
        return Err(OracleError::BadInput {
            cable,
            field: "controlled length",
        });
    }
    if guess.iter().any(|v| !v.is_finite()) {
        return Err(OracleError::BadInput {
            cable: 0,
            field: "guess",
        });
    }
    let mut base = PoseQ::from_array(guess);
    let mut last_step = f64::INFINITY;
    let mut iterations = 0;
    let mut converged = false;
    for it in 1..=opts.max_iterations {
        iterations = it;
        let u = around(robot, q_theta, base);
        let u0 = u(&[0.0; 6])?;
        let g = gradient(&u, opts.gradient_step)?;
        let h = hessian(&u, u0, opts.hessian_step)?;
        let rhs = g.map(|v| -v);
        // Levenberg damping only where the Hessian is not positive definite (slack cables
        // far from the minimum, a saddle): H + λ diag(H) + λ·scale I.
        let scale = (0..6).map(|k| h[k][k].abs()).fold(0.0, f64::max).max(1.0);
        let mut lambda = 0.0;
        let (s, t) = loop {
            let mut hd = h;
            for (k, row) in hd.iter_mut().enumerate() {
                row[k] += lambda * (h[k][k].abs() + scale);
            }
            let bump = |l: f64| if l == 0.0 { 1e-9 } else { l * 10.0 };
            let Some(s) = cholesky_solve(&hd, &rhs) else {
                lambda = bump(lambda);
                if lambda > 1e9 {
                    return Err(OracleError::NotConverged {
                        iterations: it,
                        last_step,
                    });
                }
                continue;
            };
            let step = s.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
            // Near the minimum, differences of U sink below its round-off: the full Newton
            // step is taken. Farther out, halve it until U decreases; a direction that never
            // does is damped towards the gradient instead.
            if step <= 1e-6 {
                break (s, 1.0);
            }
            let mut t = 1.0;
            let mut decreased = false;
            while t >= 1.0 / 1024.0 {
                if u(&s.map(|v| v * t))? < u0 {
                    decreased = true;
                    break;
                }
                t *= 0.5;
            }
            if decreased {
                break (s, t);
            }
            lambda = bump(lambda);
            if lambda > 1e9 {
                return Err(OracleError::NotConverged {
                    iterations: it,
                    last_step,
                });
            }
        };
        let step = s.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        let (dr, dw) = split(&s.map(|v| v * t));
        base = base.moved(dr, dw);
        let prev_step = last_step;
        last_step = step * t;
        if last_step < opts.step_tolerance
            // At the resolution of the finite differences the steps stop shrinking
            // quadratically: take that as the minimum.
            || (last_step < 1e-9 && last_step > 0.25 * prev_step)
        {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(OracleError::NotConverged {
            iterations,
            last_step,
        });
    }
    let mut lengths = Vec::with_capacity(m);
    let mut forces = Vec::with_capacity(m);
    for (i, (c, qt)) in robot.cables.iter().zip(q_theta).enumerate() {
        let q = cable_length(c, &base).map_err(|_| OracleError::PulleyGeometry { cable: i })?;
        lengths.push(q);
        forces.push(cable_force(c.k_f, *qt, q));
    }
    if forces.iter().all(|f| *f == 0.0) {
        return Err(OracleError::AllSlack);
    }
    let g = gradient(&around(robot, q_theta, base), opts.gradient_step)?;
    Ok(Equilibrium {
        pose: base.to_array(),
        pose_q: base,
        forces,
        lengths,
        iterations,
        last_step,
        gradient_norm: g.iter().map(|v| v * v).sum::<f64>().sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::{Cable, Load};

    /// A symmetric robot: 8 cables from the corners of a 4 m cube to the corners of a 0.5 m
    /// platform cube, crossed in z so the platform is rotationally constrained. By symmetry the
    /// minimum is at x = y = 0 without rotation; its height balances 8 equal cable forces'
    /// vertical components against the weight, found here by bisection on that scalar equation
    /// (a different method than the Newton minimiser).
    fn cube_robot(mass: f64) -> (Robot, Vec<f64>) {
        let mut cables = Vec::new();
        for sx in [-1.0, 1.0] {
            for sy in [-1.0, 1.0] {
                for sz in [-1.0, 1.0] {
                    cables.push(Cable {
                        frame_exit: DVec3::new(2.0 * sx, 2.0 * sy, 2.0 + 2.0 * sz),
                        anchor: DVec3::new(0.25 * sx, 0.25 * sy, -0.25 * sz),
                        pulley: None,
                        k_f: 1.0e6,
                    });
                }
            }
        }
        let load = Load {
            mass,
            center_of_gravity: DVec3::ZERO,
            gravity: 9.81,
            force: DVec3::ZERO,
        };
        let robot = Robot::new(cables, load, 0.0).unwrap();
        // Unstretched lengths: 0.5 % shorter than the distances at z = 2.
        let home = PoseQ::from_array([0.0, 0.0, 2.0, 0.0, 0.0, 0.0]);
        let qt = robot
            .cables()
            .iter()
            .map(|c| 0.995 * cable_length(c, &home).unwrap())
            .collect();
        (robot, qt)
    }

    fn vertical_balance(robot: &Robot, qt: &[f64], z: f64) -> f64 {
        let pose = PoseQ::from_array([0.0, 0.0, z, 0.0, 0.0, 0.0]);
        let mut fz = -robot.load().mass * robot.load().gravity;
        for (c, q_t) in robot.cables().iter().zip(qt) {
            let p = pose.point(c.anchor);
            let d = c.frame_exit - p;
            fz += cable_force(c.k_f, *q_t, d.length()) * d.z / d.length();
        }
        fz
    }

    #[test]
    fn symmetric_robot_settles_where_its_vertical_forces_balance() {
        let (robot, qt) = cube_robot(500.0);
        let (mut lo, mut hi) = (1.5, 2.5);
        assert!(vertical_balance(&robot, &qt, lo) > 0.0 && vertical_balance(&robot, &qt, hi) < 0.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if vertical_balance(&robot, &qt, mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let z = 0.5 * (lo + hi);
        let eq = equilibrium(
            &robot,
            &qt,
            [0.02, -0.01, 2.05, 0.01, 0.02, -0.015],
            &Options::default(),
        )
        .unwrap();
        let expected = [0.0, 0.0, z, 0.0, 0.0, 0.0];
        for k in 0..6 {
            assert!(
                (eq.pose[k] - expected[k]).abs() < 1e-10,
                "coordinate {k}: {:?} vs {expected:?} ({} iterations)",
                eq.pose,
                eq.iterations
            );
        }
        assert!(eq.gradient_norm < 1e-3, "{}", eq.gradient_norm);
        assert!(eq.forces.iter().all(|f| *f > 0.0));
    }

    #[test]
    fn bad_input_is_named_and_all_slack_has_no_minimum() {
        let (robot, qt) = cube_robot(500.0);
        let opts = Options::default();
        assert!(matches!(
            equilibrium(&robot, &qt[..3], [0.0, 0.0, 2.0, 0.0, 0.0, 0.0], &opts),
            Err(OracleError::WrongLength {
                expected: 8,
                got: 3
            })
        ));
        let mut nan = qt.clone();
        nan[5] = f64::NAN;
        assert!(matches!(
            equilibrium(&robot, &nan, [0.0, 0.0, 2.0, 0.0, 0.0, 0.0], &opts),
            Err(OracleError::BadInput { cable: 5, .. })
        ));
        // Weightless, with cables 10 m too long: U ≡ 0, every pose is "a minimum" and every
        // cable is slack there.
        let (light, _) = cube_robot(0.0);
        let long: Vec<f64> = qt.iter().map(|q| q + 10.0).collect();
        assert_eq!(
            equilibrium(&light, &long, [0.0, 0.0, 2.0, 0.0, 0.0, 0.0], &opts),
            Err(OracleError::AllSlack)
        );
        assert!(matches!(
            Robot::new(robot.cables().to_vec(), *robot.load(), 600.0),
            Err(OracleError::TorqueNotConservative(_))
        ));
    }
}
