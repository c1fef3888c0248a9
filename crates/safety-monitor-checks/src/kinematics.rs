//! The monitor's own standard inverse kinematics φ*(x) (spec sec. 2.2), written independently of
//! motion-core (glam instead of nalgebra, rotation as the explicit product of the three
//! elemental rotations instead of a written-out matrix). Sec. 5.6 limits the safety
//! controller to this model: it is what the redundant channel can afford and certify.
//!
//! * R_0P = R_x(φ_x) R_y(φ_y) R_z(φ_z)          (eq. 2.2)
//! * l_i = a_i − r − R_0P b_i^(P)               (eq. 2.5, 2.6)
//! * q_i = ‖l_i‖₂                               (eq. 2.7)
//!
//! Fixed-capacity arrays: evaluating allocates nothing.

use crate::platform::PlatformParams;
use crs_ipc::MAX_CABLES;
use glam::{DMat3, DVec3};

/// Standard kinematics of one platform (immutable after construction).
#[derive(Debug, Clone, Copy)]
pub struct StandardKinematics {
    m: usize,
    a: [DVec3; MAX_CABLES],
    b: [DVec3; MAX_CABLES],
}

impl StandardKinematics {
    pub fn new(p: &PlatformParams) -> Self {
        let m = p.cables().min(MAX_CABLES);
        let mut a = [DVec3::ZERO; MAX_CABLES];
        let mut b = [DVec3::ZERO; MAX_CABLES];
        a[..m].copy_from_slice(&p.frame_anchors_m[..m]);
        b[..m].copy_from_slice(&p.platform_anchors_m[..m]);
        Self { m, a, b }
    }

    /// Number of cables m.
    pub fn cables(&self) -> usize {
        self.m
    }

    /// R_0P of eq. (2.2) as the product of the elemental rotations.
    pub fn rotation(phi_x: f64, phi_y: f64, phi_z: f64) -> DMat3 {
        DMat3::from_rotation_x(phi_x)
            * DMat3::from_rotation_y(phi_y)
            * DMat3::from_rotation_z(phi_z)
    }

    /// Cable lengths q = φ*(x) for pose x = [r_x, r_y, r_z, φ_x, φ_y, φ_z] (m, rad) into
    /// `q[..m]` (eq. 2.5–2.7). Non-finite poses give non-finite lengths (the caller checks).
    #[inline]
    pub fn lengths(&self, x: &[f64; 6], q: &mut [f64; MAX_CABLES]) {
        let r = DVec3::new(x[0], x[1], x[2]);
        let rot = Self::rotation(x[3], x[4], x[5]);
        for ((qi, a), b) in q.iter_mut().zip(&self.a).zip(&self.b).take(self.m) {
            *qi = (*a - r - rot * *b).length();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_is_rx_ry_rz() {
        // Rotating e_z by R_x(90°) R_y(0) R_z(anything) gives -e_y.
        let r = StandardKinematics::rotation(std::f64::consts::FRAC_PI_2, 0.0, 0.3);
        let v = r * DVec3::Z;
        assert!((v - DVec3::new(0.0, -1.0, 0.0)).length() < 1e-15);
        // Order matters: R_y(90°) R_z(90°) e_x = R_y(90°) e_y = e_y.
        let r = StandardKinematics::rotation(
            0.0,
            std::f64::consts::FRAC_PI_2,
            std::f64::consts::FRAC_PI_2,
        );
        assert!((r * DVec3::X - DVec3::Y).length() < 1e-15);
    }
}
