//! Platform pose x = [r; φ] and its rotation parametrisation (eq. 2.2, 2.44–2.46).

use nalgebra::{Matrix3, Vector3, Vector6};

/// Platform pose: position `r` (m) and the three elemental rotation angles `phi` (rad),
/// x^T = [r_x r_y r_z φ_x φ_y φ_z] with R_0P = R_x(φ_x) R_y(φ_y) R_z(φ_z) (eq. 2.2).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Pose {
    /// Position of the platform origin in the world frame, m.
    pub r: Vector3<f64>,
    /// Rotation angles φ_x, φ_y, φ_z, rad (eq. 2.2).
    pub phi: Vector3<f64>,
}

impl Pose {
    pub fn new(r: Vector3<f64>, phi: Vector3<f64>) -> Self {
        Self { r, phi }
    }

    /// Pose from `[x, y, z, φx, φy, φz]` (m, rad).
    pub fn from_array(x: [f64; 6]) -> Self {
        Self {
            r: Vector3::new(x[0], x[1], x[2]),
            phi: Vector3::new(x[3], x[4], x[5]),
        }
    }

    pub fn to_array(&self) -> [f64; 6] {
        [
            self.r.x, self.r.y, self.r.z, self.phi.x, self.phi.y, self.phi.z,
        ]
    }

    pub fn to_vector(&self) -> Vector6<f64> {
        Vector6::from_column_slice(&self.to_array())
    }

    pub fn from_vector(v: &Vector6<f64>) -> Self {
        Self::from_array([v[0], v[1], v[2], v[3], v[4], v[5]])
    }

    /// True when every coordinate is finite.
    pub fn is_finite(&self) -> bool {
        self.r.iter().chain(self.phi.iter()).all(|v| v.is_finite())
    }

    /// Adds an increment given in pose coordinates (δr, δφ).
    pub fn add_increment(&self, dx: &Vector6<f64>) -> Pose {
        Pose {
            r: self.r + dx.fixed_rows::<3>(0),
            phi: self.phi + dx.fixed_rows::<3>(3),
        }
    }

    /// R_0P = R_x(φ_x) R_y(φ_y) R_z(φ_z), eq. (2.2).
    pub fn rotation(&self) -> Matrix3<f64> {
        // Product R_x R_y R_z written out (saves two 3×3 products in the 1 ms loop).
        let (sx, cx) = self.phi.x.sin_cos();
        let (sy, cy) = self.phi.y.sin_cos();
        let (sz, cz) = self.phi.z.sin_cos();
        Matrix3::new(
            cy * cz,
            -cy * sz,
            sy,
            cx * sz + sx * sy * cz,
            cx * cz - sx * sy * sz,
            -sx * cy,
            sx * sz - cx * sy * cz,
            sx * cz + cx * sy * sz,
            cx * cy,
        )
    }

    /// Geometric Jacobian J_P mapping angle increments to the infinitesimal rotation vector,
    /// ω = J_P δφ, J_P = [e_x, R_x e_y, R_x R_y e_z], eq. (2.45)–(2.46).
    pub fn angle_jacobian(&self) -> Matrix3<f64> {
        let rx = rot_x(self.phi.x);
        let rxy = rx * rot_y(self.phi.y);
        let mut j = Matrix3::zeros();
        j.set_column(0, &Vector3::x());
        j.set_column(1, &(rx * Vector3::y()));
        j.set_column(2, &(rxy * Vector3::z()));
        j
    }

    /// Position error (m) and rotation error angle (rad) of `self` against `other`: the
    /// rotation error is the angle of R_self^T R_other (axis-angle magnitude), the metric used
    /// for ε_x and ε_φ (eq. 3.3).
    pub fn error_to(&self, other: &Pose) -> (f64, f64) {
        let dr = (self.r - other.r).norm();
        let rel = self.rotation().transpose() * other.rotation();
        // atan2 of sine and cosine parts keeps full precision for small angles (acos does not).
        let s = 0.5
            * Vector3::new(
                rel[(2, 1)] - rel[(1, 2)],
                rel[(0, 2)] - rel[(2, 0)],
                rel[(1, 0)] - rel[(0, 1)],
            )
            .norm();
        let c = (rel.trace() - 1.0) * 0.5;
        (dr, s.atan2(c))
    }
}

pub fn rot_x(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

pub fn rot_y(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

pub fn rot_z(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// Skew-symmetric matrix ṽ with ṽ w = v × w (used in eq. 2.47–2.50, 2.70).
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Block matrix diag(I, J_P): maps pose-coordinate increments (δr, δφ) to the twist
/// δx = [δr; ω] of eq. (2.44). Jacobians in this crate are taken with respect to the twist
/// (as in the spec); right-multiplying by this matrix gives them in pose coordinates.
pub fn twist_from_coordinates(pose: &Pose) -> nalgebra::Matrix6<f64> {
    let mut t = nalgebra::Matrix6::identity();
    t.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&pose.angle_jacobian());
    t
}
