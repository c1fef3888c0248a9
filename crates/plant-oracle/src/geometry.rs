//! Platform pose as position + unit quaternion, and the length of one cable — with a pulley
//! derived here from the tangent condition in the pulley plane.

use crate::robot::{Cable, OracleError};
use glam::{DMat3, DQuat, DVec2, DVec3};
use std::f64::consts::PI;

/// Platform pose: position (m) and orientation (unit quaternion, platform → world).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseQ {
    pub r: DVec3,
    pub q: DQuat,
}

impl PoseQ {
    /// From `[x, y, z, φx, φy, φz]` with R = R_x(φx) R_y(φy) R_z(φz) (the spec's eq. 2.2
    /// convention, built as a quaternion product here).
    pub fn from_array(x: [f64; 6]) -> Self {
        let q = DQuat::from_rotation_x(x[3])
            * DQuat::from_rotation_y(x[4])
            * DQuat::from_rotation_z(x[5]);
        Self {
            r: DVec3::new(x[0], x[1], x[2]),
            q: q.normalize(),
        }
    }

    /// Back to `[x, y, z, φx, φy, φz]`: from R = R_x R_y R_z, R₀₂ = sin φy,
    /// R₁₂ = −sin φx cos φy, R₂₂ = cos φx cos φy, R₀₁ = −cos φy sin φz, R₀₀ = cos φy cos φz
    /// (|φy| < 90°, which every cable robot's workspace satisfies).
    pub fn to_array(&self) -> [f64; 6] {
        let m = DMat3::from_quat(self.q);
        // glam matrices are column-major: R(row, col) = column `col`, component `row`.
        let r02 = m.z_axis.x;
        let r12 = m.z_axis.y;
        let r22 = m.z_axis.z;
        let r01 = m.y_axis.x;
        let r00 = m.x_axis.x;
        [
            self.r.x,
            self.r.y,
            self.r.z,
            (-r12).atan2(r22),
            r02.clamp(-1.0, 1.0).asin(),
            (-r01).atan2(r00),
        ]
    }

    /// This pose moved by `dr` (world, m) and turned by the world-frame rotation vector `dw`
    /// (rad): R' = exp(dw) R.
    pub fn moved(&self, dr: DVec3, dw: DVec3) -> Self {
        Self {
            r: self.r + dr,
            q: (DQuat::from_scaled_axis(dw) * self.q).normalize(),
        }
    }

    /// A platform-frame point in the world frame.
    pub fn point(&self, p: DVec3) -> DVec3 {
        self.r + self.q * p
    }
}

/// Length of `cable` at `pose`, m: the straight distance exit → anchor without a pulley; with
/// one, the arc wrapped on the pulley plus the free span from the tangent point.
///
/// Pulley, in the plane spanned by the swivel axis ẑ and the direction ê of the anchor off the
/// axis, with the exit point a at the origin: the rope arrives at a travelling along +ẑ, so the
/// circle's centre is c = (r, 0) and, swept by θ from a in the travel sense, its points are
/// s(θ) = c + r n(θ) with outward normal n(θ) = (−cos θ, sin θ) and travel direction
/// t(θ) = (sin θ, cos θ). The rope leaves at the θ = β where the anchor p lies ahead on the
/// tangent: (p − c)·n(β) = r (tangency) and (p − c)·t(β) > 0 (ahead). With D = p − c written
/// as |D| (cos γ, sin γ) in the basis (−x̂, ẑ), tangency is |D| cos(β − γ) = r, so
/// β = γ ± acos(r/|D|); the sign is the one ahead. Length = r β + |D − r n(β)|.
pub fn cable_length(cable: &Cable, pose: &PoseQ) -> Result<f64, OracleError> {
    let p = pose.point(cable.anchor);
    let d = p - cable.frame_exit;
    let Some(pulley) = cable.pulley else {
        return Ok(d.length());
    };
    let r = pulley.radius;
    let z = d.dot(pulley.axis);
    let off_axis = (d - pulley.axis * z).length();
    if off_axis < 1e-12 {
        return Err(OracleError::PulleyGeometry { cable: 0 });
    }
    // Plane coordinates of D = p − c: (X − r, Z).
    let dd = DVec2::new(off_axis - r, z);
    let rho = dd.length();
    if rho <= r {
        return Err(OracleError::PulleyGeometry { cable: 0 });
    }
    // n(β)·D = −cos β·D.x + sin β·D.y = |D| cos(β − γ) with γ = atan2(D.y, −D.x).
    let gamma = dd.y.atan2(-dd.x);
    let delta = (r / rho).acos();
    let ahead = |b: f64| dd.x * b.sin() + dd.y * b.cos() > 0.0;
    let mut beta = if ahead(gamma + delta) {
        gamma + delta
    } else {
        gamma - delta
    };
    // A rope only wraps forwards: the representative in [−π/2, 3π/2).
    while beta < -0.5 * PI {
        beta += 2.0 * PI;
    }
    while beta >= 1.5 * PI {
        beta -= 2.0 * PI;
    }
    let n = DVec2::new(-beta.cos(), beta.sin());
    Ok(r * beta + (dd - n * r).length())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::Pulley;

    fn pulley_cable(anchor_world: DVec3) -> Cable {
        Cable {
            frame_exit: DVec3::ZERO,
            anchor: anchor_world,
            pulley: Some(Pulley {
                radius: 0.1,
                axis: DVec3::Z,
            }),
            k_f: 1.0,
        }
    }

    fn at_origin() -> PoseQ {
        PoseQ::from_array([0.0; 6])
    }

    /// Hand-made cases: the rope leaves a quarter turn later, horizontally, 1 m to the anchor
    /// (π r/2 + 1); half a turn, straight down (π r + 1); no pulley = distance.
    #[test]
    fn pulley_lengths_of_known_tangent_points() {
        let r = 0.1;
        let q = cable_length(&pulley_cable(DVec3::new(r + 1.0, 0.0, r)), &at_origin()).unwrap();
        assert!((q - (0.5 * PI * r + 1.0)).abs() < 1e-14, "{q}");
        let q = cable_length(&pulley_cable(DVec3::new(2.0 * r, 0.0, -1.0)), &at_origin()).unwrap();
        assert!((q - (PI * r + 1.0)).abs() < 1e-14, "{q}");
        // Rotated plane: the same quarter turn towards −y.
        let q = cable_length(&pulley_cable(DVec3::new(0.0, -(r + 1.0), r)), &at_origin()).unwrap();
        assert!((q - (0.5 * PI * r + 1.0)).abs() < 1e-14, "{q}");
        let mut c = pulley_cable(DVec3::new(3.0, 4.0, 0.0));
        c.pulley = None;
        assert_eq!(cable_length(&c, &at_origin()).unwrap(), 5.0);
    }

    #[test]
    fn an_anchor_inside_the_pulley_or_on_its_axis_is_an_error() {
        assert!(cable_length(&pulley_cable(DVec3::new(0.15, 0.0, 0.0)), &at_origin()).is_err());
        assert!(cable_length(&pulley_cable(DVec3::new(0.0, 0.0, 2.0)), &at_origin()).is_err());
    }

    /// The quaternion pose reproduces R_x R_y R_z (eq. 2.2) written out as matrices, and its
    /// angles round-trip.
    #[test]
    fn pose_convention_is_rx_ry_rz() {
        let x = [0.1, -0.2, 1.5, 0.05, -0.08, 0.12];
        let p = PoseQ::from_array(x);
        let m = DMat3::from_rotation_x(x[3])
            * DMat3::from_rotation_y(x[4])
            * DMat3::from_rotation_z(x[5]);
        let v = DVec3::new(0.3, -0.7, 0.2);
        assert!((p.q * v - m * v).length() < 1e-15);
        let back = p.to_array();
        for k in 0..6 {
            assert!((back[k] - x[k]).abs() < 1e-14, "{k}: {back:?}");
        }
    }
}
