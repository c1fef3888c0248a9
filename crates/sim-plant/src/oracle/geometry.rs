//! The plant's own cable geometry: frame exit points a_i, platform anchors b_i^(P) and, with
//! pulleys, the cable's path over the redirection pulley (sec. 2.2–2.3), written as a
//! tangent construction in the pulley plane rather than the model library's closed forms.
//!
//! Standard model: p_B = r + R b^(P) (eq. 2.6), l = a − p_B (eq. 2.5), q = ‖l‖ (eq. 2.7).
//!
//! Pulley model (fig. 2.8, parameters p_pl = [a b r_p u_Az], eq. 2.18): the cable arrives at a
//! along the swivel axis n = u_Az, is tangent there to the pulley circle of radius r_p whose
//! plane contains n and p_B (the pulley swivels), wraps by β and leaves at the contact point
//! p_A towards p_B. In the pulley plane with origin a, unit vectors e_x (towards p_B, normal to
//! n) and n, the centre is C = (r_p, 0) and p_B = (b_xy, b_z) (eq. 2.21). The tangent from p_B
//! touches the circle at the angle θ_T = θ_P + arccos(r_p / b_M) seen from C, where θ_P is the
//! direction of p_B from C and b_M = ‖p_B − C‖ (eq. 2.20); a sits at the angle π, so the wrap
//! angle is β = π − θ_T (the same angle as eq. 2.19), the free length
//! q_f = √(b_M² − r_p²) (eq. 2.22) and q = q_f + β r_p (eq. 2.17, 2.28–2.29).
//! (The model library evaluates β with atan2 forms and the contact point with Rodrigues'
//! formula, eq. 2.23–2.27; the two agree wherever the cable does not wrap past the bottom of
//! the pulley, which no pose of a CDPR reaches.)
//!
//! The length gradient needs no pulley differentials: moving p_B by δp changes the free length
//! by −u·(δp − δp_A) and δp_A = −r_p δβ u (p_A slides along the cable direction) or is normal
//! to the pulley plane (swivel), so δq = δq_f + r_p δβ = −u·δp, u = (p_A − p_B)/q_f. The
//! tests check this against finite differences of [`Geometry::cable`] itself.

use glam::DVec3;

/// Why a pose has no cable geometry.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum GeometryError {
    #[error("pose is not finite")]
    NonFinitePose,
    #[error("cable {cable} has zero length")]
    DegenerateCable { cable: usize },
    #[error("the platform anchor of cable {cable} lies inside its pulley circle")]
    InsidePulley { cable: usize },
    #[error("the platform anchor of cable {cable} lies on its pulley's swivel axis")]
    OnSwivelAxis { cable: usize },
}

/// One redirection pulley: radius r_p (m) and unit swivel axis u_Az (world frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pulley {
    pub radius: f64,
    pub axis: DVec3,
}

/// The plant's geometry: per cable a_i (world), b_i^(P) (platform frame) and the pulley.
#[derive(Clone, Debug, PartialEq)]
pub struct Geometry {
    pub frame: Vec<DVec3>,
    pub platform: Vec<DVec3>,
    /// `None`: the standard model (eq. 2.3–2.8).
    pub pulleys: Option<Vec<Pulley>>,
}

/// One cable at one pose.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cable {
    /// Geometric length q = q_f + β r_p, m.
    pub q: f64,
    /// Free length q_f between contact point and platform anchor, m.
    pub q_free: f64,
    /// Wrap angle β, rad (0 without pulley).
    pub beta: f64,
    /// Unit vector from the platform anchor towards the contact point (the direction the
    /// cable pulls the platform).
    pub u: DVec3,
    /// Contact point p_A (a without pulley), world frame.
    pub p_exit: DVec3,
    /// Platform anchor p_B = r + R b^(P), world frame.
    pub p_anchor: DVec3,
}

impl Geometry {
    pub fn m(&self) -> usize {
        self.frame.len()
    }

    /// Cable i for the platform anchor at `p_anchor` (world frame).
    pub fn cable(&self, i: usize, p_anchor: DVec3) -> Result<Cable, GeometryError> {
        let a = self.frame[i];
        match self.pulleys.as_ref().map(|p| p[i]) {
            Some(p) if p.radius > 0.0 => pulley_cable(i, a, p, p_anchor),
            _ => {
                let l = a - p_anchor;
                let q = l.length();
                if q.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                    return Err(GeometryError::DegenerateCable { cable: i });
                }
                Ok(Cable {
                    q,
                    q_free: q,
                    beta: 0.0,
                    u: l / q,
                    p_exit: a,
                    p_anchor,
                })
            }
        }
    }
}

/// Tangent construction in the pulley plane (see the module doc).
fn pulley_cable(i: usize, a: DVec3, p: Pulley, p_anchor: DVec3) -> Result<Cable, GeometryError> {
    let r_p = p.radius;
    let n = p.axis;
    let d = p_anchor - a;
    let b_z = d.dot(n);
    let radial = d - b_z * n;
    let b_xy = radial.length(); // eq. (2.21)
    if b_xy <= 1e-12 * (1.0 + d.length()) {
        return Err(GeometryError::OnSwivelAxis { cable: i });
    }
    let e_x = radial / b_xy;
    // p_B seen from the pulley centre C = a + r_p e_x.
    let (cx, cz) = (b_xy - r_p, b_z);
    let b_m = cx.hypot(cz); // eq. (2.20)
    if b_m <= r_p {
        return Err(GeometryError::InsidePulley { cable: i });
    }
    let theta_p = cz.atan2(cx);
    let theta_t = theta_p + (r_p / b_m).acos();
    let beta = std::f64::consts::PI - theta_t; // wrap from a (angle π) to the tangent point
    let q_free = ((b_m - r_p) * (b_m + r_p)).sqrt(); // eq. (2.22)
    let centre = a + r_p * e_x;
    let p_exit = centre + r_p * (theta_t.cos() * e_x + theta_t.sin() * n);
    let l = p_exit - p_anchor;
    let len = l.length();
    if len.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Err(GeometryError::DegenerateCable { cable: i });
    }
    Ok(Cable {
        q: q_free + beta * r_p, // eq. (2.17)
        q_free,
        beta,
        u: l / len,
        p_exit,
        p_anchor,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_pulley(radius: f64) -> Geometry {
        Geometry {
            frame: vec![DVec3::new(1.0, 2.0, 6.0)],
            platform: vec![DVec3::ZERO],
            pulleys: Some(vec![Pulley {
                radius,
                axis: DVec3::Z,
            }]),
        }
    }

    #[test]
    fn tangent_point_is_on_the_circle_and_the_cable_is_tangent_there() {
        let g = one_pulley(0.161);
        let pb = DVec3::new(-2.0, -1.0, 1.5);
        let c = g.cable(0, pb).unwrap();
        let e_x = {
            let d = pb - g.frame[0];
            let r = d - d.dot(DVec3::Z) * DVec3::Z;
            r / r.length()
        };
        let centre = g.frame[0] + 0.161 * e_x;
        let radius = c.p_exit - centre;
        assert!((radius.length() - 0.161).abs() < 1e-14);
        assert!(radius.dot(c.u).abs() < 1e-13, "not tangent");
        assert!((c.q_free - (c.p_exit - pb).length()).abs() < 1e-13);
        // the wrap angle is the angle between the radii to a and to p_A
        let cos_beta = (g.frame[0] - centre).dot(radius) / (0.161 * 0.161);
        assert!((cos_beta - c.beta.cos()).abs() < 1e-12);
    }

    #[test]
    fn zero_radius_is_the_straight_cable_and_length_gradient_is_minus_u() {
        let pb = DVec3::new(-2.0, -1.0, 1.5);
        let straight = one_pulley(0.0).cable(0, pb).unwrap();
        assert_eq!(straight.q, (DVec3::new(1.0, 2.0, 6.0) - pb).length());
        for r in [0.0, 0.161, 0.5] {
            let g = one_pulley(r);
            let c = g.cable(0, pb).unwrap();
            let h = 1e-6;
            for (k, e) in [DVec3::X, DVec3::Y, DVec3::Z].into_iter().enumerate() {
                let fd = (g.cable(0, pb + h * e).unwrap().q - g.cable(0, pb - h * e).unwrap().q)
                    / (2.0 * h);
                assert!(
                    (fd + c.u.dot(e)).abs() < 1e-8,
                    "r {r} axis {k}: {fd} vs {}",
                    -c.u[k]
                );
            }
        }
    }

    #[test]
    fn anchor_on_the_axis_or_inside_the_pulley_is_an_error() {
        let g = one_pulley(0.161);
        assert_eq!(
            g.cable(0, DVec3::new(1.0, 2.0, 1.0)),
            Err(GeometryError::OnSwivelAxis { cable: 0 })
        );
        assert_eq!(
            g.cable(0, DVec3::new(1.161, 2.0, 6.05)),
            Err(GeometryError::InsidePulley { cable: 0 })
        );
    }
}
