//! Elastic safety walls (eq. 5.22): f_e = (Δx·n) k_w e + (ẋ·n) d_w e along the inward wall
//! normal while the body penetrates a wall, nothing inside. Each face of an axis-aligned box
//! is one wall; at an edge or a corner the faces add up. The wall only pushes (a damper that
//! pulled on the way out would make the wall sticky), so the force along the normal is clamped
//! at zero. The same law acts on the rotation coordinates (k_w,rot, d_w,rot) so the attitude
//! has a soft border too.

use nalgebra::Vector3;

/// One axis-aligned box of walls with their spring and damper.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Walls {
    /// Lower and upper wall per axis (m for positions, rad for rotation coordinates).
    pub min: Vector3<f64>,
    pub max: Vector3<f64>,
    /// Spring k_w (N/m or N·m/rad) and damper d_w (N·s/m or N·m·s/rad), eq. 5.22.
    pub stiffness: f64,
    pub damping: f64,
}

impl Walls {
    /// The wall force (generalized force along the coordinates) at position `x` with velocity
    /// `v`, eq. 5.22. Allocation-free.
    #[inline]
    pub fn force(&self, x: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
        let mut f = Vector3::zeros();
        for k in 0..3 {
            // Penetration depth Δx·n ≥ 0 and inward normal e (+1 on the lower wall).
            let (depth, e) = if x[k] < self.min[k] {
                (self.min[k] - x[k], 1.0)
            } else if x[k] > self.max[k] {
                (x[k] - self.max[k], -1.0)
            } else {
                continue;
            };
            // ẋ·n with n pointing into the wall: positive while moving deeper.
            let into = -v[k] * e;
            f[k] = e * (self.stiffness * depth + self.damping * into).max(0.0);
        }
        f
    }

    /// How far `x` lies beyond the walls (0 inside), per axis.
    pub fn penetration(&self, x: &Vector3<f64>) -> Vector3<f64> {
        Vector3::from_fn(|k, _| (self.min[k] - x[k]).max(x[k] - self.max[k]).max(0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn w() -> Walls {
        Walls {
            min: Vector3::new(-1.0, -1.0, 1.0),
            max: Vector3::new(1.0, 1.0, 2.0),
            stiffness: 1000.0,
            damping: 100.0,
        }
    }

    #[test]
    fn inside_no_force_beyond_spring_and_damper_along_the_normal() {
        let w = w();
        assert_eq!(
            w.force(&Vector3::new(0.5, 0.0, 1.5), &Vector3::new(3.0, 0.0, 0.0)),
            Vector3::zeros()
        );
        // 0.1 m beyond +x moving out at 0.2 m/s: 1000·0.1 + 100·0.2 = 120 N inward.
        let f = w.force(&Vector3::new(1.1, 0.0, 1.5), &Vector3::new(0.2, 0.0, 0.0));
        assert!((f - Vector3::new(-120.0, 0.0, 0.0)).norm() < 1e-9, "{f}");
        // Lower z wall, a corner adds the x wall.
        let f = w.force(&Vector3::new(-1.05, 0.0, 0.9), &Vector3::zeros());
        assert!((f - Vector3::new(50.0, 0.0, 100.0)).norm() < 1e-9, "{f}");
        // Leaving fast: the damper would pull, the wall only stops pushing.
        let f = w.force(&Vector3::new(1.01, 0.0, 1.5), &Vector3::new(-1.0, 0.0, 0.0));
        assert_eq!(f, Vector3::zeros());
        assert!(
            (w.penetration(&Vector3::new(1.1, -1.2, 1.5)) - Vector3::new(0.1, 0.2, 0.0)).norm()
                < 1e-12
        );
    }
}
