//! The immutable surrogate model `phi_sg` and its real-time evaluation, eq. (5.23):
//! `q_off = phi_sg(x)`, added by the 1 ms loop to the standard kinematics `phi(x)`.

use crate::basis::{Basis, MAX_DEGREE, Tables, fill_tables, for_each_basis, n_basis};
use crate::certificate::{FitOptions, FitReport};
use crate::region::{N_COORDS, Normalisation, Region};

/// Maximum number of cables a surrogate can serve.
pub use crs_limits::MAX_CABLES;

/// Coefficients are packed in groups of 4 cables so the inner accumulation is a fixed-width
/// multiply-add the compiler vectorises.
const LANE: usize = 4;

/// Misuse of [`Surrogate::eval`] (never caused by pose data).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EvalError {
    /// `out` does not have one slot per cable.
    #[error("surrogate output slice has {got} entries, the surrogate has {expected} cables")]
    OutputLength {
        /// Number of cables of the surrogate.
        expected: usize,
        /// Length of the slice passed in.
        got: usize,
    },
}

/// Polynomial surrogate `phi_sg(x)`: per-cable joint-space offset in m over a pose region.
///
/// Immutable after construction (by [`crate::fit()`] or [`Surrogate::load`]); evaluation needs no
/// separate scratch object (Model/Data split) because its small working set (normalised pose,
/// 6 x (d+1) 1-D polynomial values, the `C(6+d, d)` basis values, <= 2 x 16 accumulators) lives
/// on the stack with sizes fixed at compile time per degree: 1 KiB at degree 3, 7.6 KiB at the
/// maximum degree 6. Share it across threads freely (`Send + Sync`, no interior mutability).
#[derive(Clone, Debug)]
pub struct Surrogate {
    pub(crate) platform_id: String,
    pub(crate) region: Region,
    pub(crate) options: FitOptions,
    pub(crate) report: FitReport,
    pub(crate) n_cables: usize,
    /// Cable-major coefficients `[cable][basis]` in m, as fitted and as written to the file.
    pub(crate) coefficients: Vec<Vec<f64>>,
    norm: Normalisation,
    /// Cables rounded up to a multiple of 4 (row stride of `packed`).
    stride: usize,
    /// Basis-major packed copy: `packed[k * stride + j]` = coefficient of basis `k` for cable
    /// `j` (zero for padding cables).
    packed: Vec<f64>,
}

impl Surrogate {
    /// Builds the evaluator from validated parts. Callers guarantee: region valid, degree <=
    /// MAX_DEGREE, 1 <= n_cables <= MAX_CABLES, coefficient shape `[n_cables][n_basis]`.
    pub(crate) fn from_parts(
        platform_id: String,
        region: Region,
        options: FitOptions,
        report: FitReport,
        coefficients: Vec<Vec<f64>>,
    ) -> Self {
        let n_cables = coefficients.len();
        let nb = n_basis(options.degree);
        let stride = n_cables.div_ceil(LANE) * LANE;
        let mut packed = vec![0.0; nb * stride];
        for (j, cj) in coefficients.iter().enumerate() {
            for (k, c) in cj.iter().enumerate() {
                packed[k * stride + j] = *c;
            }
        }
        Surrogate {
            platform_id,
            norm: Normalisation::new(&region),
            region,
            options,
            report,
            n_cables,
            coefficients,
            stride,
            packed,
        }
    }

    /// Evaluates the offsets `q_off = phi_sg(x)` (m, one per cable) at pose `x`
    /// (`[x_m, y_m, z_m, phi_x_rad, phi_y_rad, phi_z_rad]`), eq. (5.23).
    ///
    /// Real-time properties: fixed cost (the work depends on the model's degree and cable count
    /// only, never on `x`), no allocation, no locks, no panics.
    ///
    /// Outside the fitted [`Region`] each normalised coordinate is clamped to `[-1, 1]`, so the
    /// result equals the value at the nearest point of the region's boundary box (to round-off
    /// of the normalisation) and is never extrapolated; the certified bound
    /// [`FitReport::certified_bound_mm`] therefore holds for every input. A NaN coordinate yields
    /// NaN outputs (not masked, so the caller's plausibility checks see it).
    ///
    /// Errors only if `out.len() != self.n_cables()`; then `out` is left untouched.
    ///
    /// Not `#[inline]`: the body holds one kernel per (degree, cable group) and should exist
    /// once, not at every call site.
    pub fn eval(&self, x: &[f64; N_COORDS], out: &mut [f64]) -> Result<(), EvalError> {
        if out.len() != self.n_cables {
            return Err(EvalError::OutputLength {
                expected: self.n_cables,
                got: out.len(),
            });
        }
        let u = self.norm.normalise_clamped(x);
        let mut acc = [0.0; MAX_CABLES];
        // Dispatch on the model's degree and padded cable count (never on data) to a kernel with
        // compile-time sizes, so the basis loops unroll without data-independent-but-unpredictable
        // loop exits and the row update is a fixed-width vector multiply-add.
        macro_rules! by_stride {
            ($d:literal, $nb:literal) => {
                match self.stride {
                    4 => self.kernel::<$d, $nb, 4>(&u, &mut acc),
                    8 => self.kernel::<$d, $nb, 8>(&u, &mut acc),
                    12 => self.kernel::<$d, $nb, 12>(&u, &mut acc),
                    _ => self.kernel::<$d, $nb, 16>(&u, &mut acc),
                }
            };
        }
        // The basis counts below are C(6 + d, d), checked at compile time.
        const _: () = assert!(
            n_basis(0) == 1
                && n_basis(1) == 7
                && n_basis(2) == 28
                && n_basis(3) == 84
                && n_basis(4) == 210
                && n_basis(5) == 462
                && n_basis(6) == 924
                && MAX_DEGREE == 6
        );
        match self.options.degree {
            0 => by_stride!(0, 1),
            1 => by_stride!(1, 7),
            2 => by_stride!(2, 28),
            3 => by_stride!(3, 84),
            4 => by_stride!(4, 210),
            5 => by_stride!(5, 462),
            _ => by_stride!(6, 924),
        }
        out.copy_from_slice(&acc[..self.n_cables]);
        Ok(())
    }

    /// `acc[j] = sum_k b_k(u) c_jk` for total degree `D` (`NB = n_basis(D)` basis functions)
    /// and row stride `W` (cables padded to a multiple of 4); `D`, `NB`, `W` match the model
    /// (guaranteed by the dispatch in `eval`). The `zip`s/`chunks_exact` keep every access in
    /// bounds without panicking paths.
    #[inline(always)]
    fn kernel<const D: usize, const NB: usize, const W: usize>(
        &self,
        u: &[f64; N_COORDS],
        acc: &mut [f64; MAX_CABLES],
    ) {
        let mut t: Tables = [[0.0; MAX_DEGREE + 1]; N_COORDS];
        fill_tables(self.options.basis, D, u, &mut t);
        let mut b = [0.0; NB];
        let mut slots = b.iter_mut();
        for_each_basis(&t, D, |_, v| {
            if let Some(s) = slots.next() {
                *s = v;
            }
        });
        // Two independent accumulator sets (even / odd basis functions) halve the add-latency
        // chain that otherwise bounds this loop.
        let (mut even, mut odd) = ([0.0; W], [0.0; W]);
        let mut rows = self.packed.chunks_exact(W);
        let mut pairs = b.chunks_exact(2);
        for pair in &mut pairs {
            let (Some(r0), Some(r1)) = (rows.next(), rows.next()) else {
                break;
            };
            let (b0, b1) = (pair[0], pair[1]);
            for (((e, o), c0), c1) in even.iter_mut().zip(odd.iter_mut()).zip(r0).zip(r1) {
                *e += b0 * c0;
                *o += b1 * c1;
            }
        }
        if let (Some(&bl), Some(r)) = (pairs.remainder().first(), rows.next()) {
            for (e, c) in even.iter_mut().zip(r) {
                *e += bl * c;
            }
        }
        for ((a, e), o) in acc.iter_mut().zip(even).zip(odd) {
            *a = e + o;
        }
    }

    /// Number of cables (length of the `out` slice of [`Surrogate::eval`]).
    pub fn n_cables(&self) -> usize {
        self.n_cables
    }

    /// Platform identity string the surrogate was fitted for (supplied by the caller of `fit`).
    pub fn platform_id(&self) -> &str {
        &self.platform_id
    }

    /// Pose region of the fit.
    pub fn region(&self) -> &Region {
        &self.region
    }

    /// Options the surrogate was fitted with (degree, basis, sample counts, bound, margin, ...).
    pub fn options(&self) -> &FitOptions {
        &self.options
    }

    /// Fit statistics and the bound proof (validation figures), as fitted / as stored in the file.
    pub fn report(&self) -> &FitReport {
        &self.report
    }

    /// Coefficients of cable `cable` (m), in the basis order written to the file
    /// (`exponents`), or `None` if `cable >= n_cables()`.
    pub fn coefficients(&self, cable: usize) -> Option<&[f64]> {
        self.coefficients.get(cable).map(Vec::as_slice)
    }

    /// Per-cable certified bound `max_x |phi_sg,j(x)| <= sum_k |c_jk|` (m), valid for all `x`
    /// because every basis function is bounded by 1 on the (clamped) unit box.
    pub(crate) fn certified_bounds_m(&self) -> Vec<f64> {
        self.coefficients
            .iter()
            .map(|c| c.iter().map(|v| v.abs()).sum())
            .collect()
    }

    /// Degree and basis, for code that needs them without the options struct.
    pub(crate) fn degree_basis(&self) -> (usize, Basis) {
        (self.options.degree, self.options.basis)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::basis::basis_row;
    use crate::certificate::Location;

    fn dummy_report(degree: usize, basis: Basis, n_cables: usize) -> FitReport {
        let at = Location {
            pose: [0.0; N_COORDS],
            cable: 0,
        };
        FitReport {
            degree,
            basis,
            n_cables,
            n_coeffs_per_cable: n_basis(degree),
            n_fit_samples: 0,
            n_validation_samples: 0,
            ridge: 0.0,
            condition_number: 1.0,
            max_fit_error_mm: 0.0,
            mean_fit_error_mm: 0.0,
            max_fit_error_at: at,
            max_abs_offset_mm: 0.0,
            max_abs_offset_at: at,
            certified_bound_mm: 0.0,
            bound_mm: 100.0,
            margin_mm: 10.0,
        }
    }

    #[test]
    fn surrogate_is_send_and_sync() {
        fn check<T: Send + Sync>() {}
        check::<Surrogate>();
    }

    /// Every (degree, stride) kernel instantiation equals the plain dot product of the basis row
    /// with the coefficients, for every cable count.
    #[test]
    fn all_kernels_match_naive_evaluation() {
        let region = Region {
            lower: [-2.0, -1.0, 0.0, -0.2, -0.3, -0.4],
            upper: [2.0, 3.0, 1.0, 0.2, 0.3, 0.4],
        };
        let norm = Normalisation::new(&region);
        let x = [0.3, 2.1, 0.9, -0.15, 0.01, 0.33];
        let u = norm.normalise_clamped(&x);
        for basis in [Basis::Legendre, Basis::Monomial] {
            for degree in 0..=MAX_DEGREE {
                let nb = n_basis(degree);
                let mut row = vec![0.0; nb];
                basis_row(basis, degree, &u, &mut row);
                for m in [1, 3, 4, 5, 8, 9, 12, 13, 16] {
                    let coeffs: Vec<Vec<f64>> = (0..m)
                        .map(|j| {
                            (0..nb)
                                .map(|k| ((j * 1000 + k) as f64 * 0.7).sin() * 1e-3)
                                .collect()
                        })
                        .collect();
                    let options = FitOptions {
                        degree,
                        basis,
                        ..FitOptions::default()
                    };
                    let s = Surrogate::from_parts(
                        "t".into(),
                        region,
                        options,
                        dummy_report(degree, basis, m),
                        coeffs.clone(),
                    );
                    let mut out = vec![0.0; m];
                    s.eval(&x, &mut out).unwrap();
                    for j in 0..m {
                        let want: f64 = row.iter().zip(&coeffs[j]).map(|(b, c)| b * c).sum();
                        assert!(
                            (out[j] - want).abs() < 1e-15 + 1e-12 * want.abs(),
                            "{basis:?} degree {degree} m {m} cable {j}: {} vs {want}",
                            out[j]
                        );
                    }
                }
            }
        }
    }
}
