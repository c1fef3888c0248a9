//! What a fit is asked to do ([`FitOptions`]) and what it proved ([`FitReport`], the surrogate
//! file's `validation` section): the types the fit writes and the surrogate carries.

use crate::basis::Basis;
use crate::region::{N_COORDS, pose_string};
use serde::{Deserialize, Serialize};
use std::fmt;

/// Safety controller threshold on the joint-signal misalignment, `Delta q_theta_lim = 100 mm`
/// (sec. 5.6); the default for [`FitOptions::bound_m`].
pub use crs_limits::DELTA_Q_LIMIT_M;

/// How to fit and what to prove. `Default` gives degree 3, Legendre basis, `6 x n_coeffs` fit
/// samples, 10 000 (+729 grid) validation samples, no ridge, bound 100 mm, margin 10 mm.
///
/// Deserialisable from operator config (e.g. a `[surrogate]` TOML table): unknown fields are
/// refused, missing fields take the defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FitOptions {
    /// Total polynomial degree `d` (0..=[`MAX_DEGREE`]); `C(6 + d, d)` coefficients per cable.
    pub degree: usize,
    /// 1-D family of the tensor-product basis.
    pub basis: Basis,
    /// Number of fit samples (Halton points); `None` = 6 x coefficients per cable.
    /// Must be at least the number of coefficients per cable.
    pub fit_samples: Option<usize>,
    /// Number of Halton validation samples, in addition to the 3^6 = 729 grid points
    /// (corners, edge and face midpoints, centre) that are always validated.
    pub validation_samples: usize,
    /// Tikhonov parameter `lambda >= 0` of the column-scaled problem
    /// `min |A_s c - y|^2 + lambda |c|^2` (`A_s` has unit-norm columns, so `lambda` is
    /// dimensionless and relative to the squared singular values, ~1 for a well-posed design).
    pub ridge: f64,
    /// Bound of eq. (5.27) on `|phi_sg|` (m): the safety monitor's `Delta q_theta_lim`.
    pub bound_m: f64,
    /// Safety margin (m): the fit is refused unless `max |phi_sg| < bound_m - margin_m`
    /// over the validation set. It must cover what the sampled check cannot see: the residual
    /// between the safety monitor's own kinematics and `phi(x)` (both enter its `Delta q`), and
    /// excursions of the polynomial between validation samples (see `certified_bound_mm` for an
    /// all-pose bound).
    pub margin_m: f64,
    /// If set, the fit is refused when the max fit error over the validation set reaches it (m).
    pub max_fit_error_m: Option<f64>,
    /// If true, additionally require the certified bound `max_j sum_k |c_jk| < bound_m -
    /// margin_m`, which holds for every pose (not only the sampled ones) but can be pessimistic.
    pub require_certified_bound: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            degree: 3,
            basis: Basis::Legendre,
            fit_samples: None,
            validation_samples: 10_000,
            ridge: 0.0,
            bound_m: DELTA_Q_LIMIT_M,
            margin_m: 0.010,
            max_fit_error_m: None,
            require_certified_bound: false,
        }
    }
}

/// A pose and cable index where a figure of the report was attained.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Location {
    /// Pose `[x_m, y_m, z_m, phi_x_rad, phi_y_rad, phi_z_rad]`.
    pub pose: [f64; N_COORDS],
    /// Cable index (0-based).
    pub cable: usize,
}

/// Fit statistics and the validation figures that prove the bound of eq. (5.27).
/// Stored in the surrogate file as its `validation` section.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitReport {
    /// Total degree.
    pub degree: usize,
    /// Basis family.
    pub basis: Basis,
    /// Number of cables.
    pub n_cables: usize,
    /// Coefficients per cable, `C(6 + degree, degree)`.
    pub n_coeffs_per_cable: usize,
    /// Number of fit samples (target evaluations in the least-squares problem).
    pub n_fit_samples: usize,
    /// Number of validation samples (grid + Halton).
    pub n_validation_samples: usize,
    /// Ridge parameter used.
    pub ridge: f64,
    /// 2-norm condition number `sigma_max / sigma_min` of the column-scaled design matrix.
    pub condition_number: f64,
    /// Max |phi_sg - q_off| over validation samples and cables (mm).
    pub max_fit_error_mm: f64,
    /// Mean |phi_sg - q_off| over validation samples and cables (mm).
    pub mean_fit_error_mm: f64,
    /// Where the max fit error occurred.
    pub max_fit_error_at: Location,
    /// Max |phi_sg| over validation samples and cables (mm): the sampled bound, eq. (5.27).
    pub max_abs_offset_mm: f64,
    /// Where the max |phi_sg| occurred.
    pub max_abs_offset_at: Location,
    /// Max over cables of `sum_k |c_jk|` (mm): upper bound of |phi_sg| for every pose.
    pub certified_bound_mm: f64,
    /// Bound of eq. (5.27) (mm).
    pub bound_mm: f64,
    /// Margin below the bound required of `max_abs_offset_mm` (mm).
    pub margin_mm: f64,
}

impl fmt::Display for FitReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "surrogate fit: degree {} ({:?}), {} cables x {} coeffs, {} fit / {} validation samples",
            self.degree,
            self.basis,
            self.n_cables,
            self.n_coeffs_per_cable,
            self.n_fit_samples,
            self.n_validation_samples
        )?;
        writeln!(
            f,
            "  condition number {:.3e} (ridge {:e})",
            self.condition_number, self.ridge
        )?;
        writeln!(
            f,
            "  fit error: max {:.4} mm (cable {} at {}), mean {:.4} mm",
            self.max_fit_error_mm,
            self.max_fit_error_at.cable,
            pose_string(&self.max_fit_error_at.pose),
            self.mean_fit_error_mm
        )?;
        write!(
            f,
            "  max |offset| {:.3} mm (cable {} at {}), certified bound {:.3} mm, limit {:.1} - {:.1} mm",
            self.max_abs_offset_mm,
            self.max_abs_offset_at.cable,
            pose_string(&self.max_abs_offset_at.pose),
            self.certified_bound_mm,
            self.bound_mm,
            self.margin_mm
        )
    }
}
