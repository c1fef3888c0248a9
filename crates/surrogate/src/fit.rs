//! Offline least-squares fit of the surrogate to a target offset `q_off(x)` and the bound proof
//! over a separate validation set, eq. (5.26)-(5.27).

use crate::basis::{MAX_DEGREE, basis_row, n_basis};
use crate::certificate::{FitOptions, FitReport, Location};
use crate::design::{DEFAULT_OVERSAMPLING, MAX_SAMPLES, N_GRID, fit_poses, validation_poses};
use crate::model::{MAX_CABLES, Surrogate};
use crate::region::{N_COORDS, Normalisation, Region, RegionError, pose_string};
use nalgebra::DMatrix;
use std::fmt;

/// Condition number of the scaled design above which an un-regularised fit is refused.
const MAX_CONDITION_UNREGULARISED: f64 = 1e12;

/// Why a fit was refused. Nothing is produced on error.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// The region is not a proper box.
    #[error(transparent)]
    Region(#[from] RegionError),
    /// An option or argument is out of range.
    #[error("invalid fit option `{field}`: {reason}")]
    InvalidOption {
        /// Name of the option/argument.
        field: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The target closure returned an error.
    #[error("target offset failed at pose {pose}: {message}")]
    Target {
        /// Pose (formatted with names and units).
        pose: String,
        /// The target's error message.
        message: String,
    },
    /// The target returned the wrong number of cable offsets.
    #[error("target returned {got} offsets at pose {pose}, expected {expected} (one per cable)")]
    TargetLength {
        /// Pose (formatted).
        pose: String,
        /// Number of cables requested.
        expected: usize,
        /// Number returned.
        got: usize,
    },
    /// The target returned NaN or infinity.
    #[error("target offset for cable {cable} is not finite ({value}) at pose {pose}")]
    NonFiniteTarget {
        /// Pose (formatted).
        pose: String,
        /// Cable index.
        cable: usize,
        /// The value returned.
        value: f64,
    },
    /// The least-squares problem is (numerically) rank deficient and no ridge was given.
    #[error(
        "design matrix is rank deficient (condition number {condition_number:.3e} > {MAX_CONDITION_UNREGULARISED:e}); \
         use more fit samples, a lower degree or ridge > 0"
    )]
    RankDeficient {
        /// Condition number of the scaled design matrix.
        condition_number: f64,
    },
    /// The SVD did not converge or produced non-finite coefficients.
    #[error("least-squares solve failed: {0}")]
    Solve(&'static str),
    /// eq. (5.27) with margin violated on the validation set.
    #[error(
        "bound violated: |phi_sg| = {offset_mm:.3} mm for cable {cable} at pose {pose} \
         reaches the limit {limit_mm:.3} mm (bound {bound_mm:.3} mm - margin {margin_mm:.3} mm); \
         surrogate not produced"
    )]
    BoundViolated {
        /// Pose (formatted) of the worst validation sample.
        pose: String,
        /// Where, as numbers.
        at: Location,
        /// Cable index.
        cable: usize,
        /// Signed offset there (mm).
        offset_mm: f64,
        /// bound - margin (mm).
        limit_mm: f64,
        /// Bound (mm).
        bound_mm: f64,
        /// Margin (mm).
        margin_mm: f64,
    },
    /// The certified (all-pose) bound exceeds the limit while `require_certified_bound` is set.
    #[error(
        "certified bound sum|c| = {certified_mm:.3} mm for cable {cable} reaches the limit \
         {limit_mm:.3} mm (require_certified_bound is set); surrogate not produced"
    )]
    CertifiedBoundViolated {
        /// Cable index.
        cable: usize,
        /// sum_k |c_jk| (mm).
        certified_mm: f64,
        /// bound - margin (mm).
        limit_mm: f64,
    },
    /// The fit error exceeds `max_fit_error_m`.
    #[error(
        "fit error {error_mm:.4} mm for cable {cable} at pose {pose} exceeds max_fit_error \
         {limit_mm:.4} mm; surrogate not produced"
    )]
    FitErrorTooLarge {
        /// Pose (formatted).
        pose: String,
        /// Cable index.
        cable: usize,
        /// |phi_sg - q_off| there (mm).
        error_mm: f64,
        /// The configured limit (mm).
        limit_mm: f64,
    },
}

fn invalid(field: &'static str, reason: impl Into<String>) -> FitError {
    FitError::InvalidOption {
        field,
        reason: reason.into(),
    }
}

fn check_options(options: &FitOptions, n_cables: usize, platform_id: &str) -> Result<(), FitError> {
    if options.degree > MAX_DEGREE {
        return Err(invalid(
            "degree",
            format!("{} exceeds the maximum {MAX_DEGREE}", options.degree),
        ));
    }
    if n_cables == 0 || n_cables > MAX_CABLES {
        return Err(invalid(
            "n_cables",
            format!("{n_cables} not in 1..={MAX_CABLES}"),
        ));
    }
    if platform_id.trim().is_empty() {
        return Err(invalid("platform_id", "must not be empty"));
    }
    let nb = n_basis(options.degree);
    let n_fit = options.fit_samples.unwrap_or(nb);
    if n_fit < nb {
        let n = n_fit;
        return Err(invalid(
            "fit_samples",
            format!(
                "{n} is fewer than the {nb} coefficients per cable of degree {}",
                options.degree
            ),
        ));
    }
    if n_fit > MAX_SAMPLES {
        return Err(invalid(
            "fit_samples",
            format!("{n_fit} exceeds the maximum {MAX_SAMPLES}"),
        ));
    }
    if options.validation_samples > MAX_SAMPLES {
        return Err(invalid(
            "validation_samples",
            format!(
                "{} exceeds the maximum {MAX_SAMPLES}",
                options.validation_samples
            ),
        ));
    }
    if !(options.ridge.is_finite() && options.ridge >= 0.0) {
        return Err(invalid(
            "ridge",
            format!("{} must be finite and >= 0", options.ridge),
        ));
    }
    if !(options.bound_m.is_finite() && options.bound_m > 0.0) {
        return Err(invalid(
            "bound_m",
            format!("{} must be finite and > 0", options.bound_m),
        ));
    }
    if !(options.margin_m.is_finite()
        && options.margin_m >= 0.0
        && options.margin_m < options.bound_m)
    {
        return Err(invalid(
            "margin_m",
            format!(
                "{} must be finite, >= 0 and < bound_m ({})",
                options.margin_m, options.bound_m
            ),
        ));
    }
    let e = options.max_fit_error_m.unwrap_or(1.0);
    if !(e.is_finite() && e > 0.0) {
        return Err(invalid(
            "max_fit_error_m",
            format!("{e} must be finite and > 0"),
        ));
    }
    Ok(())
}

/// Calls the target and checks shape and finiteness.
fn eval_target<F, T, E>(
    target: &mut F,
    pose: &[f64; N_COORDS],
    n_cables: usize,
) -> Result<T, FitError>
where
    F: FnMut(&[f64; N_COORDS]) -> Result<T, E>,
    T: AsRef<[f64]>,
    E: fmt::Display,
{
    let q = target(pose).map_err(|e| FitError::Target {
        pose: pose_string(pose),
        message: e.to_string(),
    })?;
    let s = q.as_ref();
    if s.len() != n_cables {
        return Err(FitError::TargetLength {
            pose: pose_string(pose),
            expected: n_cables,
            got: s.len(),
        });
    }
    if let Some((cable, &value)) = s.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(FitError::NonFiniteTarget {
            pose: pose_string(pose),
            cable,
            value,
        });
    }
    Ok(q)
}

/// Fits `phi_sg` to the target offset `q_off(x)` (m per cable) over `region`, then validates it
/// on a separate, denser sample set and proves eq. (5.27) with margin.
///
/// * `target(x)` returns the `n_cables` offsets at pose `x` (e.g. elastostatic IK with the
///   eq. (3.41) force distribution minus standard IK); any error aborts the fit.
/// * Design: normalised coordinates `u = (x - centre) / half_width`, tensor-product basis of
///   total degree `options.degree`, Halton fit samples, least squares via SVD of the
///   column-scaled design matrix (optional ridge). See the `design` module docs for the sets.
/// * Refuses (returns `Err`, produces nothing) if the sampled max `|phi_sg|` reaches
///   `bound_m - margin_m`, naming pose, cable and value; likewise for the optional certified
///   bound and fit-error limit.
///
/// `platform_id` identifies the platform geometry/parameters the target was computed for (e.g.
/// a hash of the platform config); it is stored in the file and checked on load.
pub fn fit<F, T, E>(
    region: &Region,
    options: &FitOptions,
    n_cables: usize,
    platform_id: &str,
    mut target: F,
) -> Result<(Surrogate, FitReport), FitError>
where
    F: FnMut(&[f64; N_COORDS]) -> Result<T, E>,
    T: AsRef<[f64]>,
    E: fmt::Display,
{
    region.validate()?;
    check_options(options, n_cables, platform_id)?;
    let degree = options.degree;
    let nb = n_basis(degree);
    let n_fit = options.fit_samples.unwrap_or(DEFAULT_OVERSAMPLING * nb);
    let norm = Normalisation::new(region);

    // Design matrix A (n_fit x nb) and targets Y (n_fit x m). Rows use the same normalisation
    // and basis code as `Surrogate::eval`.
    let mut a = DMatrix::<f64>::zeros(n_fit, nb);
    let mut y = DMatrix::<f64>::zeros(n_fit, n_cables);
    let mut row = vec![0.0; nb];
    for (i, pose) in fit_poses(region, n_fit).enumerate() {
        let q = eval_target(&mut target, &pose, n_cables)?;
        for (j, v) in q.as_ref().iter().enumerate() {
            y[(i, j)] = *v;
        }
        basis_row(
            options.basis,
            degree,
            &norm.normalise_clamped(&pose),
            &mut row,
        );
        for (k, v) in row.iter().enumerate() {
            a[(i, k)] = *v;
        }
    }

    // Column scaling to unit 2-norm: the reported condition number is that of this scaled
    // matrix (it removes the trivial imbalance between basis functions of different norm).
    let mut scale = vec![0.0; nb];
    for (k, s) in scale.iter_mut().enumerate() {
        let n = a.column(k).norm();
        if !(n.is_finite() && n > 0.0) {
            return Err(FitError::RankDeficient {
                condition_number: f64::INFINITY,
            });
        }
        *s = 1.0 / n;
        a.column_mut(k).scale_mut(*s);
    }
    let svd = a
        .try_svd(true, true, f64::EPSILON, 100_000)
        .ok_or(FitError::Solve("SVD did not converge"))?;
    let sv = &svd.singular_values;
    let s_max = sv.max();
    let s_min = sv.min();
    let condition_number = if s_min > 0.0 {
        s_max / s_min
    } else {
        f64::INFINITY
    };
    if options.ridge == 0.0
        && (condition_number.is_nan() || condition_number > MAX_CONDITION_UNREGULARISED)
    {
        return Err(FitError::RankDeficient { condition_number });
    }
    let (Some(u), Some(v_t)) = (&svd.u, &svd.v_t) else {
        return Err(FitError::Solve("SVD factors missing"));
    };
    // c_s = V diag(s / (s^2 + lambda)) U^T Y ; c = diag(scale) c_s.
    let mut uty = u.transpose() * &y;
    for (r, s) in sv.iter().enumerate() {
        let f = if *s > 0.0 {
            s / (s * s + options.ridge)
        } else {
            0.0
        };
        uty.row_mut(r).scale_mut(f);
    }
    let c_scaled = v_t.transpose() * uty; // nb x m
    let mut coefficients = vec![vec![0.0; nb]; n_cables];
    for (j, cj) in coefficients.iter_mut().enumerate() {
        for (k, c) in cj.iter_mut().enumerate() {
            *c = c_scaled[(k, j)] * scale[k];
        }
    }
    if coefficients.iter().flatten().any(|c| !c.is_finite()) {
        return Err(FitError::Solve("non-finite coefficients"));
    }

    let placeholder = Location {
        pose: [0.0; N_COORDS],
        cable: 0,
    };
    let mut report = FitReport {
        degree,
        basis: options.basis,
        n_cables,
        n_coeffs_per_cable: nb,
        n_fit_samples: n_fit,
        n_validation_samples: N_GRID + options.validation_samples,
        ridge: options.ridge,
        condition_number,
        max_fit_error_mm: 0.0,
        mean_fit_error_mm: 0.0,
        max_fit_error_at: placeholder,
        max_abs_offset_mm: 0.0,
        max_abs_offset_at: placeholder,
        certified_bound_mm: 0.0,
        bound_mm: options.bound_m * 1e3,
        margin_mm: options.margin_m * 1e3,
    };
    let mut surrogate = Surrogate::from_parts(
        platform_id.to_owned(),
        *region,
        options.clone(),
        report.clone(),
        coefficients,
    );

    // Validation: fit error against the target and the sampled bound, on the separate set.
    let mut phi = vec![0.0; n_cables];
    let (mut max_err, mut sum_err, mut max_abs) = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut max_abs_signed = 0.0;
    let mut n_terms = 0usize;
    for pose in validation_poses(region, n_fit, options.validation_samples) {
        let q = eval_target(&mut target, &pose, n_cables)?;
        surrogate
            .eval(&pose, &mut phi)
            .map_err(|_| FitError::Solve("internal: output length"))?;
        for (cable, (p, t)) in phi.iter().zip(q.as_ref()).enumerate() {
            if !p.is_finite() {
                return Err(FitError::Solve(
                    "surrogate value not finite on a validation pose",
                ));
            }
            let err = (p - t).abs();
            sum_err += err;
            n_terms += 1;
            if err > max_err {
                max_err = err;
                report.max_fit_error_at = Location { pose, cable };
            }
            if p.abs() > max_abs {
                max_abs = p.abs();
                max_abs_signed = *p;
                report.max_abs_offset_at = Location { pose, cable };
            }
        }
    }
    let certified = surrogate.certified_bounds_m();
    let (cert_cable, cert_max) =
        certified
            .iter()
            .copied()
            .enumerate()
            .fold(
                (0, 0.0_f64),
                |acc, (j, v)| if v > acc.1 { (j, v) } else { acc },
            );
    report.max_fit_error_mm = max_err * 1e3;
    report.mean_fit_error_mm = if n_terms > 0 {
        sum_err / n_terms as f64 * 1e3
    } else {
        0.0
    };
    report.max_abs_offset_mm = max_abs * 1e3;
    report.certified_bound_mm = cert_max * 1e3;

    let limit_m = options.bound_m - options.margin_m;
    if max_abs >= limit_m {
        let at = report.max_abs_offset_at;
        return Err(FitError::BoundViolated {
            pose: pose_string(&at.pose),
            at,
            cable: at.cable,
            offset_mm: max_abs_signed * 1e3,
            limit_mm: limit_m * 1e3,
            bound_mm: options.bound_m * 1e3,
            margin_mm: options.margin_m * 1e3,
        });
    }
    if options.require_certified_bound && cert_max >= limit_m {
        return Err(FitError::CertifiedBoundViolated {
            cable: cert_cable,
            certified_mm: cert_max * 1e3,
            limit_mm: limit_m * 1e3,
        });
    }
    let lim = options.max_fit_error_m.unwrap_or(f64::INFINITY);
    if max_err >= lim {
        let at = report.max_fit_error_at;
        return Err(FitError::FitErrorTooLarge {
            pose: pose_string(&at.pose),
            cable: at.cable,
            error_mm: max_err * 1e3,
            limit_mm: lim * 1e3,
        });
    }
    surrogate.report = report.clone();
    Ok((surrogate, report))
}
