//! The pose region a surrogate is valid on, and the affine normalisation of the pose coordinates
//! to the unit box `[-1, 1]^6` that the polynomial basis is defined on.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Number of pose coordinates `x = [x, y, z, phi_x, phi_y, phi_z]`.
pub const N_COORDS: usize = 6;

/// Names (with units) of the pose coordinates, in order. Used in error messages and in the file.
pub const COORD_NAMES: [&str; N_COORDS] =
    ["x_m", "y_m", "z_m", "phi_x_rad", "phi_y_rad", "phi_z_rad"];

/// Axis-aligned box in pose space: position in m, orientation in rad.
///
/// The surrogate is fitted and validated inside this box. Outside it, evaluation clamps each
/// normalised coordinate to `[-1, 1]`, i.e. returns the value on the box boundary.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// Lower corner `[x_m, y_m, z_m, phi_x_rad, phi_y_rad, phi_z_rad]`.
    pub lower: [f64; N_COORDS],
    /// Upper corner, same layout; every entry must be strictly greater than in `lower`.
    pub upper: [f64; N_COORDS],
}

/// A region whose bounds are not finite or not strictly increasing.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("invalid region: coordinate {coord} ({name}): lower {lower} / upper {upper}: {reason}")]
pub struct RegionError {
    /// Index of the offending coordinate (0..6).
    pub coord: usize,
    /// Name of the offending coordinate, with unit.
    pub name: &'static str,
    /// Lower bound as given.
    pub lower: f64,
    /// Upper bound as given.
    pub upper: f64,
    /// What is wrong.
    pub reason: &'static str,
}

impl Region {
    /// Checks that every bound is finite, `lower < upper`, and the half width is representable
    /// (its reciprocal is finite), so the normalisation is well defined.
    pub fn validate(&self) -> Result<(), RegionError> {
        for (i, name) in COORD_NAMES.iter().enumerate() {
            let (lo, hi) = (self.lower[i], self.upper[i]);
            let err = |reason| RegionError {
                coord: i,
                name,
                lower: lo,
                upper: hi,
                reason,
            };
            if !lo.is_finite() || !hi.is_finite() {
                return Err(err("bounds must be finite"));
            }
            if lo >= hi {
                return Err(err("lower must be strictly less than upper"));
            }
            let half = 0.5 * (hi - lo);
            if !half.is_finite() || !(1.0 / half).is_finite() || half <= 0.0 {
                return Err(err("width must be finite and not vanishingly small"));
            }
        }
        Ok(())
    }

    /// Centre of the box (per coordinate).
    pub fn centre(&self) -> [f64; N_COORDS] {
        std::array::from_fn(|i| 0.5 * (self.lower[i] + self.upper[i]))
    }

    /// Half width of the box (per coordinate).
    pub fn half_width(&self) -> [f64; N_COORDS] {
        std::array::from_fn(|i| 0.5 * (self.upper[i] - self.lower[i]))
    }

    /// Whether `x` lies inside the closed box.
    pub fn contains(&self, x: &[f64; N_COORDS]) -> bool {
        (0..N_COORDS).all(|i| x[i] >= self.lower[i] && x[i] <= self.upper[i])
    }
}

/// Precomputed affine map pose -> normalised coordinates, `u_i = (x_i - c_i) / h_i`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Normalisation {
    pub centre: [f64; N_COORDS],
    pub half_width: [f64; N_COORDS],
    pub inv_half_width: [f64; N_COORDS],
}

impl Normalisation {
    pub fn new(region: &Region) -> Self {
        let centre = region.centre();
        let half_width = region.half_width();
        Normalisation {
            centre,
            half_width,
            inv_half_width: std::array::from_fn(|i| 1.0 / half_width[i]),
        }
    }

    /// Normalised coordinates clamped to `[-1, 1]` (branch-free min/max). A NaN input coordinate
    /// stays NaN (`f64::clamp` propagates NaN) so a corrupted pose is visible downstream rather
    /// than silently mapped to a boundary; +-inf and huge finite values clamp to +-1.
    #[inline(always)]
    pub fn normalise_clamped(&self, x: &[f64; N_COORDS]) -> [f64; N_COORDS] {
        let mut u = [0.0; N_COORDS];
        for i in 0..N_COORDS {
            u[i] = ((x[i] - self.centre[i]) * self.inv_half_width[i]).clamp(-1.0, 1.0);
        }
        u
    }
}

/// Formats a pose with coordinate names and units for error messages.
pub(crate) struct PoseDisplay<'a>(pub &'a [f64; N_COORDS]);

impl fmt::Display for PoseDisplay<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[")?;
        for (i, v) in self.0.iter().enumerate() {
            if i > 0 {
                write!(f, ", ")?;
            }
            write!(f, "{}={v:.6}", COORD_NAMES[i])?;
        }
        write!(f, "]")
    }
}

/// Pose formatted for messages (owned, so error types can carry it cheaply as a `String`).
pub(crate) fn pose_string(x: &[f64; N_COORDS]) -> String {
    PoseDisplay(x).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_inverted_and_non_finite_bounds_naming_the_coordinate() {
        let mut r = Region {
            lower: [-1.0; 6],
            upper: [1.0; 6],
        };
        assert!(r.validate().is_ok());
        r.upper[3] = -2.0;
        let e = r.validate().unwrap_err();
        assert_eq!(e.coord, 3);
        assert!(e.to_string().contains("phi_x_rad"), "{e}");
        r.upper[3] = 1.0;
        r.lower[5] = f64::NAN;
        assert_eq!(r.validate().unwrap_err().coord, 5);
    }

    #[test]
    fn normalisation_maps_box_to_unit_box_and_clamps() {
        let r = Region {
            lower: [-2.0, 0.0, 1.0, -0.1, -0.2, -0.3],
            upper: [4.0, 1.0, 3.0, 0.1, 0.2, 0.3],
        };
        let n = Normalisation::new(&r);
        let u = n.normalise_clamped(&r.centre());
        assert!(u.iter().all(|v| v.abs() < 1e-15));
        let u = n.normalise_clamped(&r.upper);
        assert!(u.iter().all(|v| (v - 1.0).abs() < 1e-15));
        let u = n.normalise_clamped(&[1e300, -1e300, f64::INFINITY, f64::NEG_INFINITY, 0.0, 0.0]);
        assert_eq!(&u[..4], &[1.0, -1.0, 1.0, -1.0]);
        assert!(n.normalise_clamped(&[f64::NAN, 0., 0., 0., 0., 0.])[0].is_nan());
    }
}
