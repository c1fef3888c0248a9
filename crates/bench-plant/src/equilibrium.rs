//! The static equilibrium as the minimum of the robot's potential ([`Robot::potential`]):
//! damped Newton steps on central-difference gradients and Hessians of the potential in
//! world-frame pose increments, with a line search on the potential. Every force direction,
//! moment arm and pulley or catenary end force comes out of differences of energies.

use crate::robot::{PlantError, Robot};
use glam::{DQuat, DVec3};
use plant_oracle::PoseQ;
use plant_oracle::cholesky_solve;

/// Central-difference step of the gradient (m, rad): truncation ∝ h² against round-off
/// ∝ ε U/h at potentials of ~10² J.
const GRADIENT_STEP: f64 = 1e-6;
/// Step of the second differences of the Hessian; it only steers the Newton step.
const HESSIAN_STEP: f64 = 1e-4;
/// Converged when a Newton step moves less than this (m, rad).
const STEP_TOLERANCE: f64 = 1e-11;
const MAX_ITERATIONS: usize = 80;

/// The equilibrium found.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    pub pose: PoseQ,
    /// Tension at each platform anchor, N.
    pub tensions: Vec<f64>,
    pub iterations: usize,
}

fn moved(base: &PoseQ, s: &[f64; 6]) -> PoseQ {
    PoseQ {
        r: base.r + DVec3::new(s[0], s[1], s[2]),
        q: (DQuat::from_scaled_axis(DVec3::new(s[3], s[4], s[5])) * base.q).normalize(),
    }
}

/// The equilibrium of `robot` with unstretched lengths `l_un`, the local minimum of its
/// potential nearest `guess`.
pub fn solve(robot: &Robot, l_un: &[f64], guess: PoseQ) -> Result<Solution, PlantError> {
    if l_un.len() != robot.m() {
        return Err(PlantError::WrongLength {
            expected: robot.m(),
            got: l_un.len(),
        });
    }
    let mut base = guess;
    let mut last_step = f64::INFINITY;
    for it in 1..=MAX_ITERATIONS {
        let u = |dx: &[f64; 6]| robot.potential(l_un, &base, dx);
        let u0 = u(&[0.0; 6])?;
        let mut g = [0.0; 6];
        for k in 0..6 {
            let mut p = [0.0; 6];
            p[k] = GRADIENT_STEP;
            let up = u(&p)?;
            p[k] = -GRADIENT_STEP;
            g[k] = (up - u(&p)?) / (2.0 * GRADIENT_STEP);
        }
        let h = hessian(&u, u0)?;
        let scale = (0..6).map(|k| h[k][k].abs()).fold(1.0, f64::max);
        let mut lambda = 0.0;
        let (step, t) = loop {
            let mut hd = h;
            for (k, row) in hd.iter_mut().enumerate() {
                row[k] += lambda * (h[k][k].abs() + scale);
            }
            let grow = |l: f64| if l == 0.0 { 1e-9 } else { 10.0 * l };
            let Some(s) = cholesky_solve(&hd, &g.map(|v| -v)) else {
                lambda = grow(lambda);
                if lambda > 1e9 {
                    return Err(PlantError::NotConverged {
                        iterations: it,
                        last_step,
                    });
                }
                continue;
            };
            let size = s.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
            // Near the minimum the potential's differences sink below its round-off: take the
            // full Newton step there; farther out halve it until the potential decreases.
            if size <= 1e-7 {
                break (s, 1.0);
            }
            let mut t = 1.0;
            let mut decreased = false;
            while t >= 1.0 / 1024.0 {
                if u(&s.map(|v| v * t)).is_ok_and(|v| v < u0) {
                    decreased = true;
                    break;
                }
                t *= 0.5;
            }
            if decreased {
                break (s, t);
            }
            lambda = grow(lambda);
            if lambda > 1e9 {
                return Err(PlantError::NotConverged {
                    iterations: it,
                    last_step,
                });
            }
        };
        base = moved(&base, &step.map(|v| v * t));
        let size = step.iter().fold(0.0_f64, |a, v| a.max(v.abs())) * t;
        let prev = last_step;
        last_step = size;
        // At the resolution of the potential's differences the steps stop shrinking
        // quadratically: that is the minimum (0.1 µm is far below any sensor's noise).
        if size < STEP_TOLERANCE || (size < 1e-7 && size > 0.25 * prev) {
            let tensions = robot.tensions(l_un, &base)?;
            if tensions.iter().all(|f| *f <= 0.0) {
                return Err(PlantError::AllSlack);
            }
            return Ok(Solution {
                pose: base,
                tensions,
                iterations: it,
            });
        }
    }
    Err(PlantError::NotConverged {
        iterations: MAX_ITERATIONS,
        last_step,
    })
}

fn hessian(
    u: &impl Fn(&[f64; 6]) -> Result<f64, PlantError>,
    u0: f64,
) -> Result<[[f64; 6]; 6], PlantError> {
    let h = HESSIAN_STEP;
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
            for (sj, sk) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                let mut p = [0.0; 6];
                p[j] = sj * h;
                p[k] = sk * h;
                v += sj * sk * u(&p)?;
            }
            hm[j][k] = v / (4.0 * h * h);
            hm[k][j] = hm[j][k];
        }
    }
    Ok(hm)
}
