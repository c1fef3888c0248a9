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
//! Why this basis, these samples and clamping instead of extrapolation: docs/adr/0003; the
//! file format: docs/surrogate.md, "The file".
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
mod json_layout;
mod model;
mod region;

pub use basis::{Basis, MAX_DEGREE, n_basis};
pub use certificate::{DELTA_Q_LIMIT_M, FitOptions, FitReport, Location};
pub use file::{FORMAT_NAME, FORMAT_VERSION, FileError};
pub use fit::{FitError, fit};
pub use model::{EvalError, MAX_CABLES, Surrogate};
pub use region::{COORD_NAMES, N_COORDS, Region, RegionError};
