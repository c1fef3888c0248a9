//! Strain energy of one cable and the total potential of the robot.

use crate::geometry::{PoseQ, cable_length};
use crate::robot::{OracleError, Robot};
use glam::DVec3;

/// Strain energy stored in a cable of specific stiffness `k_f` (N), unstretched length
/// `q_theta` and length `q` (m), J: the integral of f(s) = k_F (1 − q_θ/s) (eq. 2.33–2.36)
/// from q_θ to q, E = k_F q_θ (ε − ln(1 + ε)) with the strain ε = (q − q_θ)/q_θ; 0 when slack.
///
/// ε − ln(1 + ε) ≈ ε²/2 loses most digits to cancellation at the strains of steel cables
/// (ε ~ 10⁻³), so small strains use its alternating series.
pub fn cable_energy(k_f: f64, q_theta: f64, q: f64) -> f64 {
    if q <= q_theta {
        return 0.0;
    }
    let e = (q - q_theta) / q_theta;
    let g = if e < 0.05 {
        // Σ_{n≥2} (−1)ⁿ εⁿ / n; 14 terms leave < 1e-18 relative at ε = 0.05.
        let mut sum = 0.0;
        let mut pow = e * e;
        for n in 2..16 {
            let term = pow / n as f64;
            sum += if n % 2 == 0 { term } else { -term };
            pow *= e;
        }
        sum
    } else {
        e - e.ln_1p()
    };
    k_f * q_theta * g
}

/// The force law the energy integrates, N: f = k_F (q − q_θ)/q, 0 when slack.
pub fn cable_force(k_f: f64, q_theta: f64, q: f64) -> f64 {
    if q <= q_theta {
        0.0
    } else {
        k_f * (q - q_theta) / q
    }
}

/// Potential energy of the robot at `base` moved by (dr, dw), relative to `base` for the load
/// (so its large absolute value m g z does not swamp the differences the minimiser takes), J.
pub(crate) fn potential(
    robot: &Robot,
    q_theta: &[f64],
    base: &PoseQ,
    dr: DVec3,
    dw: DVec3,
) -> Result<f64, OracleError> {
    let pose = base.moved(dr, dw);
    let mut u = 0.0;
    for (i, (c, qt)) in robot.cables.iter().zip(q_theta).enumerate() {
        let q = cable_length(c, &pose).map_err(|e| match e {
            OracleError::PulleyGeometry { .. } => OracleError::PulleyGeometry { cable: i },
            other => other,
        })?;
        u += cable_energy(c.k_f, *qt, q);
    }
    let l = &robot.load;
    // Height change of the centre of gravity: δr_z + ((exp(dw) − I) R c)_z, the rotation part
    // by Rodrigues' formula written for the difference (no cancellation at small dw).
    let c_world = base.q * l.center_of_gravity;
    let th = dw.length();
    let (s1, s2) = if th < 1e-4 {
        (1.0 - th * th / 6.0, 0.5 - th * th / 24.0)
    } else {
        (th.sin() / th, (1.0 - th.cos()) / (th * th))
    };
    let dc = dw.cross(c_world) * s1 + dw.cross(dw.cross(c_world)) * s2;
    u += l.mass * l.gravity * (dr.z + dc.z);
    u -= l.force.dot(dr);
    Ok(u)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The energy's derivative is the force law (central differences), across the series /
    /// closed-form switch, and it is continuous at slack.
    #[test]
    fn energy_derivative_is_the_force_law() {
        let (k_f, qt) = (1.2e7, 10.0);
        for q in [10.0001, 10.01, 10.2, 10.49, 10.51, 11.0] {
            let h = 1e-6;
            let d = (cable_energy(k_f, qt, q + h) - cable_energy(k_f, qt, q - h)) / (2.0 * h);
            let f = cable_force(k_f, qt, q);
            assert!(
                (d - f).abs() < 1e-6 * f.max(1.0) + 1e-3,
                "q {q}: dE/dq {d} vs f {f}"
            );
        }
        assert_eq!(cable_energy(k_f, qt, 9.9), 0.0);
        assert!(cable_energy(k_f, qt, 10.0 + 1e-9) < 1e-9);
    }

    /// Series and closed form agree where both are accurate.
    #[test]
    fn series_matches_the_closed_form() {
        let (k_f, qt) = (1.0, 1.0);
        for e in [0.01_f64, 0.03, 0.0499] {
            let closed = e - e.ln_1p();
            let s = cable_energy(k_f, qt, qt * (1.0 + e));
            assert!(
                (s - closed).abs() < 1e-13 * closed.max(1e-12) + 1e-16,
                "{e}"
            );
        }
    }
}
