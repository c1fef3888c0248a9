//! Polynomial surrogate `phi_sg` of the elastostatic force control (thesis sec. 5.6).
//!
//! The elastostatic model with force control (eq. (3.41) force distribution) is too heavy and too
//! unpredictable in run time for the 1 ms loop and cannot be re-implemented in the safety
//! monitor. Instead its joint-space offset to the standard kinematics is rendered offline into a
//! static polynomial, eq. (5.23)-(5.26):
//!
//! ```text
//! q_theta = phi(x) + phi_sg(x),      q_off(x) = phi_sg(x),      |phi_sg(x)| < Delta q_lim = 100 mm  (5.27)
//! ```
//!
//! One typed API per job:
//!
//! * **Fit (offline):** [`fit`]`(region, &options, n_cables, platform_id, target)` least-squares
//!   fits a total-degree-`d` tensor-product polynomial (Legendre by default) in the pose
//!   coordinates normalised to the [`Region`] box, validates it on a separate denser set, and
//!   refuses it unless eq. (5.27) holds with margin. Returns the [`Surrogate`] and a
//!   [`FitReport`] (condition number, fit errors, bound figures).
//! * **Persist:** [`Surrogate::save`] / [`Surrogate::load`] — versioned JSON with SHA-256
//!   checksum and platform identity; `load` re-proves the bound.
//! * **Evaluate (1 ms loop):** [`Surrogate::eval`] — fixed cost, no allocation, clamps to the
//!   region boundary outside the region.
//!
//! Design choices (see the module sources for details):
//!
//! * **Basis:** tensor products `prod_i P_{a_i}(u_i)` of Legendre polynomials with
//!   `sum a_i <= d` (`C(6+d, d)` per cable: 84 for `d = 3`) in `u = (x - centre) / half_width`.
//!   Legendre polynomials keep the column-scaled design matrix well conditioned (~3.4 at
//!   `d = 3`, ~7 at `d = 5`; monomials are several times worse).
//!   `|P_n| <= 1` on `[-1, 1]` gives the certified all-pose bound `sum_k |c_jk|`.
//! * **Samples:** fit on Halton points `1..=n_fit` (default `6 x` coefficients) in Chebyshev
//!   (arcsine) density, denser towards the faces where fit errors and the bound peak; validate
//!   on the `3^6` grid (corners, edge/face midpoints) plus further uniform Halton points
//!   (default 10 000).
//! * **Solve:** SVD of the column-scaled design matrix; reports its condition number; optional
//!   ridge; refuses a rank-deficient un-regularised problem.
//! * **Outside the region:** normalised coordinates are clamped to `[-1, 1]`, i.e. the offset
//!   is the value on the region boundary, never an extrapolation.
//!
//! File format (`format_version` 1), pretty JSON:
//!
//! ```text
//! { "format": "crs-surrogate", "format_version": 1, "checksum_sha256": "<64 hex>",
//!   "payload": { platform_id, description, coordinates, region, normalisation, basis, degree,
//!                n_cables, exponents, coefficients_m[cable][k], fit_options, validation } }
//! ```
//!
//! `checksum_sha256` = SHA-256 of `"crs-surrogate\n1\n" + compact_json(payload)`; `f64` values are
//! written in shortest round-trip form and parsed bit-exactly. `load` checks syntax/schema,
//! format, version, checksum, platform identity, internal consistency and re-proves the bound.
//!
//! ```
//! use surrogate::{fit, FitOptions, Region};
//! let region = Region { lower: [-1.0, -1.0, 0.0, -0.1, -0.1, -0.1],
//!                       upper: [ 1.0,  1.0, 2.0,  0.1,  0.1,  0.1] };
//! let options = FitOptions { validation_samples: 500, ..FitOptions::default() };
//! // Target: per-cable offset in m (here a made-up smooth function of the pose).
//! let (sg, report) = fit(&region, &options, 2, "demo-platform", |x: &[f64; 6]| {
//!     Ok::<_, std::convert::Infallible>([0.01 * x[0] * x[2], -0.02 * x[4]])
//! }).unwrap();
//! assert!(report.max_abs_offset_mm < 100.0 - 10.0);
//! let mut q_off = [0.0; 2];
//! sg.eval(&[0.2, 0.1, 1.0, 0.0, 0.05, 0.0], &mut q_off).unwrap();
//! assert!((q_off[0] - 0.002).abs() < 1e-12);
//! ```

#![warn(missing_docs)]

mod basis;
mod certificate;
mod design;
mod file;
mod fit;
mod model;
mod region;

pub use basis::{Basis, MAX_DEGREE, n_basis};
pub use certificate::{DELTA_Q_LIMIT_M, FitOptions, FitReport, Location};
pub use file::{FORMAT_NAME, FORMAT_VERSION, FileError};
pub use fit::{FitError, fit};
pub use model::{EvalError, MAX_CABLES, Surrogate};
pub use region::{COORD_NAMES, N_COORDS, Region, RegionError};
