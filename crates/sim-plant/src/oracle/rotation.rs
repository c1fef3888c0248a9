//! The platform orientation R(φ) = R_x(φ_x) R_y(φ_y) R_z(φ_z) (eq. 2.2) and its partial
//! derivatives, written with glam from the exponential form of an elemental rotation rather
//! than from the angle Jacobian J_P of eq. 2.45–2.46 that the model library uses.
//!
//! R_k(φ) = exp(φ K_k) with K_k = [e_k]× (the cross-product matrix of the axis), so
//! dR_k/dφ = K_k R_k = R_k K_k and, by the product rule,
//!   ∂R/∂φ_x = K_x R,   ∂R/∂φ_y = R_x K_y R_y R_z,   ∂R/∂φ_z = R K_z.
//! The angular velocity that a change of φ_k produces is the axial vector of (∂R/∂φ_k) Rᵀ; it is
//! taken from the matrices themselves ([`Orientation::omega`]), so no closed form of J_P enters.

use glam::{DMat3, DVec3};

/// R(φ) and ∂R/∂φ_k at one pose.
#[derive(Clone, Copy, Debug)]
pub struct Orientation {
    /// R_0P, eq. (2.2).
    pub r: DMat3,
    /// ∂R/∂φ_x, ∂R/∂φ_y, ∂R/∂φ_z.
    pub d: [DMat3; 3],
}

/// Cross-product matrix [v]× (columns: v × e_x, v × e_y, v × e_z).
fn cross_matrix(v: DVec3) -> DMat3 {
    DMat3::from_cols(v.cross(DVec3::X), v.cross(DVec3::Y), v.cross(DVec3::Z))
}

/// Axial vector w of a skew-symmetric matrix S = [w]×.
fn axial(s: DMat3) -> DVec3 {
    // S = [w]×: column x is w × e_x = (0, w_z, −w_y), column y is (−w_z, 0, w_x).
    // Averaging the two entries of each pair halves the round-off of a nearly skew S.
    DVec3::new(
        0.5 * (s.y_axis.z - s.z_axis.y),
        0.5 * (s.z_axis.x - s.x_axis.z),
        0.5 * (s.x_axis.y - s.y_axis.x),
    )
}

impl Orientation {
    /// R and its derivatives at angles φ = (φ_x, φ_y, φ_z), rad.
    pub fn at(phi: [f64; 3]) -> Self {
        let rx = DMat3::from_rotation_x(phi[0]);
        let ry = DMat3::from_rotation_y(phi[1]);
        let rz = DMat3::from_rotation_z(phi[2]);
        let r = rx * ry * rz;
        let d = [
            cross_matrix(DVec3::X) * r,
            rx * cross_matrix(DVec3::Y) * ry * rz,
            r * cross_matrix(DVec3::Z),
        ];
        Self { r, d }
    }

    /// Angular velocity per unit rate of φ_k: the axial vector of (∂R/∂φ_k) Rᵀ.
    pub fn omega(&self, k: usize) -> DVec3 {
        axial(self.d[k] * self.r.transpose())
    }

    /// Partial derivatives of a body point p = r + R p_P with respect to the six pose
    /// coordinates: ∂p/∂r = I, ∂p/∂φ_k = (∂R/∂φ_k) p_P.
    pub fn point_derivatives(&self, p_platform: DVec3) -> [DVec3; 6] {
        [
            DVec3::X,
            DVec3::Y,
            DVec3::Z,
            self.d[0] * p_platform,
            self.d[1] * p_platform,
            self.d[2] * p_platform,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivatives_match_finite_differences_and_omega_is_the_rotation_rate() {
        let phi = [0.3, -0.7, 1.1];
        let o = Orientation::at(phi);
        let h = 1e-6;
        for k in 0..3 {
            let (mut p, mut m) = (phi, phi);
            p[k] += h;
            m[k] -= h;
            let fd = (Orientation::at(p).r - Orientation::at(m).r) * (0.5 / h);
            let err = (fd - o.d[k])
                .to_cols_array()
                .iter()
                .fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(err < 1e-9, "∂R/∂φ_{k}: {err:e}");
            // (∂R/∂φ_k) Rᵀ is skew: the derivative is a pure rotation rate
            let s = o.d[k] * o.r.transpose();
            let sym = (s + s.transpose())
                .to_cols_array()
                .iter()
                .fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(sym < 1e-15, "{sym:e}");
        }
        // R_x R_y R_z: the rate of φ_x is about the world x axis, of φ_z about the body z axis
        assert!((o.omega(0) - DVec3::X).length() < 1e-15);
        assert!((o.omega(2) - o.r * DVec3::Z).length() < 1e-15);
    }
}
