//! Exact wrench feasibility (eq. 3.29): does *any* force distribution f with
//! A^T f + w_e = 0 and f_min ≤ f ≤ f_max exist?
//!
//! The closed form of eq. (3.41) ([`crate::statics::force_distribution`]) answers a narrower
//! question — is the one distribution closest to f_m inside the limits? — so it is sufficient,
//! not necessary: near the workspace border another distribution often fits where f_ref does
//! not, and the closed form shrinks the usable workspace. It stays the hard loop's test (it is
//! allocation-free and a few hundred ns); this module is the analysis tool.
//!
//! Both solvers here answer the same max-margin linear program
//!
//! ```text
//!   t* = max t   s.t.   A^T f = −w_e,   f_min + t ≤ f_i ≤ f_max − t   (i = 1..m)
//! ```
//!
//! so that the pose is wrench feasible iff t* ≥ 0, and t* (N) is the largest distance to the
//! nearer limit any distribution can keep (the exact counterpart of the closed form's margin,
//! and never smaller than it). Bounded: 2t ≤ f_max − f_min, and every direction of the kernel
//! moves some f_i towards a limit.
//!
//! * [`exact_vertex`]: a dedicated solver for redundancy r = m − n ≤ 2 (the CRS: m = 8, n = 6;
//!   the spec's planar examples: m = 4, n = 2). Writing f = f_p + H λ with the minimum-norm
//!   particular solution f_p = −A (A^T A)^{-1} w_e (eq. 2.38) and an orthonormal basis H of the
//!   kernel of A^T (eq. 2.40), the LP lives in (λ, t) ∈ R^{r+1} with 2m half-spaces; its optimum
//!   is a vertex, found by enumerating the C(2m, r+1) intersections (560 for m = 8). This is
//!   Pott's nullspace view of the force distribution, solved exactly instead of in closed form.
//! * [`exact_lp`]: the same LP in the original variables handed to `microlp` (a maintained
//!   pure-Rust simplex), for any redundancy. The two are independent implementations of one
//!   question and are cross-checked in the tests (and against scipy's HiGHS in
//!   `tools/feasibility_vs_scipy.py`).

use nalgebra::{DMatrix, DVector, Matrix3, SymmetricEigen, Vector3};

/// Why the exact test could not give an answer (never "infeasible": that is a result).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FeasibilityError {
    #[error("the structure matrix is rank deficient (A^T A is singular)")]
    Singular,
    #[error("the structure matrix has {rows} rows and {cols} cables: need more cables than DOF")]
    NotRedundant { rows: usize, cols: usize },
    #[error("w_e has {got} entries, the structure matrix {rows} rows")]
    WrenchLength { got: usize, rows: usize },
    #[error("the vertex solver handles redundancy m − n ≤ 2, got {0}")]
    RedundancyTooHigh(usize),
    #[error("force limits must satisfy f_min < f_max (got {f_min} N, {f_max} N)")]
    ForceLimits { f_min: f64, f_max: f64 },
    #[error("the LP solver failed: {0}")]
    Solver(String),
}

/// The exact verdict of eq. (3.29) with the max-margin distribution that proves it.
#[derive(Clone, Debug, PartialEq)]
pub struct ExactFeasibility {
    /// t* ≥ 0 (within round-off): some distribution satisfies the limits.
    pub feasible: bool,
    /// t*, N: the largest margin to the nearer limit any distribution achieves (negative: the
    /// smallest violation any distribution must accept).
    pub margin: f64,
    /// The distribution achieving t*, N.
    pub forces: DVector<f64>,
}

/// Round-off allowance on the margin, relative to the force range.
const MARGIN_TOL_REL: f64 = 1e-9;

fn check_inputs(
    at: &DMatrix<f64>,
    w_e: &DVector<f64>,
    f_min: f64,
    f_max: f64,
) -> Result<(), FeasibilityError> {
    let (n, m) = at.shape();
    if m <= n {
        return Err(FeasibilityError::NotRedundant { rows: n, cols: m });
    }
    if w_e.len() != n {
        return Err(FeasibilityError::WrenchLength {
            got: w_e.len(),
            rows: n,
        });
    }
    if !f_min.is_finite() || !f_max.is_finite() || f_min >= f_max {
        return Err(FeasibilityError::ForceLimits { f_min, f_max });
    }
    Ok(())
}

/// Minimum-norm particular solution f_p of A^T f = −w_e (eq. 2.38) and an orthonormal kernel
/// basis H (m × (m − n)) of A^T (eq. 2.40), from the eigen-decomposition of A A^T: its m − n
/// smallest eigenvalues are zero and their eigenvectors span the kernel.
pub fn nullspace_split(
    at: &DMatrix<f64>,
    w_e: &DVector<f64>,
) -> Result<(DVector<f64>, DMatrix<f64>), FeasibilityError> {
    let (n, m) = at.shape();
    let gram = at * at.transpose();
    let chol = gram.clone().cholesky().ok_or(FeasibilityError::Singular)?;
    // Rank check: Cholesky of a nearly singular Gram matrix can succeed; refuse a condition
    // number beyond what f64 resolves for forces of ~1e4 N.
    let eig_g = SymmetricEigen::new(gram);
    let (gmin, gmax) = eig_g
        .eigenvalues
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), &e| {
            (lo.min(e), hi.max(e))
        });
    if gmin <= gmax * 1e-12 {
        return Err(FeasibilityError::Singular);
    }
    let f_p = -(at.transpose() * chol.solve(w_e));
    let eig = SymmetricEigen::new(at.transpose() * at);
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let h = DMatrix::from_columns(
        &order[..m - n]
            .iter()
            .map(|&k| eig.eigenvectors.column(k).into_owned())
            .collect::<Vec<_>>(),
    );
    Ok((f_p, h))
}

/// Exact eq. (3.29) by vertex enumeration in the kernel (redundancy m − n ∈ {1, 2}).
/// `at` is A^T (n × m), `w_e` the external wrench (n).
pub fn exact_vertex(
    at: &DMatrix<f64>,
    w_e: &DVector<f64>,
    f_min: f64,
    f_max: f64,
) -> Result<ExactFeasibility, FeasibilityError> {
    check_inputs(at, w_e, f_min, f_max)?;
    let (n, m) = at.shape();
    let r = m - n;
    if r > 2 {
        return Err(FeasibilityError::RedundancyTooHigh(r));
    }
    let (f_p, h) = nullspace_split(at, w_e)?;
    // Half-spaces g·z ≥ c in z = (λ_1..λ_r, t) (unused λ components stay 0 for r = 1):
    //   H_i λ − t ≥ f_min − f_p,i   and   −H_i λ − t ≥ f_p,i − f_max.
    let k = 2 * m;
    let mut g = Vec::with_capacity(k);
    let mut c = Vec::with_capacity(k);
    for i in 0..m {
        let hi = |j: usize| if j < r { h[(i, j)] } else { 0.0 };
        g.push(Vector3::new(hi(0), hi(1), -1.0));
        c.push(f_min - f_p[i]);
        g.push(Vector3::new(-hi(0), -hi(1), -1.0));
        c.push(f_p[i] - f_max);
    }
    let scale = f_max - f_min;
    let tol = 1e-9 * scale.max(1.0);
    let mut best: Option<(f64, Vector3<f64>)> = None;
    let mut consider = |z: Vector3<f64>| {
        if !z.iter().all(|v| v.is_finite()) {
            return;
        }
        if (0..k).all(|q| g[q].dot(&z) >= c[q] - tol) && best.is_none_or(|(t, _)| z[2] > t) {
            best = Some((z[2], z));
        }
    };
    if r == 2 {
        for a in 0..k {
            for b in a + 1..k {
                for d in b + 1..k {
                    let mat =
                        Matrix3::from_rows(&[g[a].transpose(), g[b].transpose(), g[d].transpose()]);
                    if let Some(inv) = mat.try_inverse()
                        && inv.iter().all(|v| v.abs() < 1e12)
                    {
                        consider(inv * Vector3::new(c[a], c[b], c[d]));
                    }
                }
            }
        }
    } else {
        // r = 1: vertices of the polygon in (λ_1, t).
        for a in 0..k {
            for b in a + 1..k {
                let (g1, g2) = (g[a], g[b]);
                let det = g1.x * g2.z - g1.z * g2.x;
                if det.abs() < 1e-14 {
                    continue;
                }
                let l = (c[a] * g2.z - g1.z * c[b]) / det;
                let t = (g1.x * c[b] - c[a] * g2.x) / det;
                consider(Vector3::new(l, 0.0, t));
            }
        }
    }
    let (t, z) = best.ok_or_else(|| {
        FeasibilityError::Solver("no vertex satisfies the constraints (degenerate A^T)".into())
    })?;
    let lam = DVector::from_iterator(r, z.iter().take(r).copied());
    let forces = &f_p + &h * lam;
    Ok(ExactFeasibility {
        feasible: t >= -MARGIN_TOL_REL * scale,
        margin: t,
        forces,
    })
}

/// Exact eq. (3.29) for any redundancy: the max-margin LP in the original variables, solved by
/// `microlp`'s simplex. Forces are scaled to O(1) (by f_max − f_min) for the solver.
pub fn exact_lp(
    at: &DMatrix<f64>,
    w_e: &DVector<f64>,
    f_min: f64,
    f_max: f64,
) -> Result<ExactFeasibility, FeasibilityError> {
    use microlp::{ComparisonOp, OptimizationDirection, Problem};
    check_inputs(at, w_e, f_min, f_max)?;
    let (n, m) = at.shape();
    let s = f_max - f_min;
    let mut lp = Problem::new(OptimizationDirection::Maximize);
    let fv: Vec<_> = (0..m)
        .map(|_| lp.add_var(0.0, (f64::NEG_INFINITY, f64::INFINITY)))
        .collect();
    // t ≤ s/2 is implied; the lower bound only keeps the simplex away from infinite values.
    let t = lp.add_var(1.0, (-1e3, 0.5));
    for row in 0..n {
        let terms: Vec<_> = (0..m).map(|i| (fv[i], at[(row, i)])).collect();
        lp.add_constraint(&terms, ComparisonOp::Eq, -w_e[row] / s);
    }
    for &v in &fv {
        lp.add_constraint([(v, 1.0), (t, -1.0)], ComparisonOp::Ge, f_min / s);
        lp.add_constraint([(v, 1.0), (t, 1.0)], ComparisonOp::Le, f_max / s);
    }
    let outcome = lp
        .solve()
        .map_err(|e| FeasibilityError::Solver(e.to_string()))?;
    if !outcome.is_optimal() {
        return Err(FeasibilityError::Solver(format!(
            "the simplex stopped without proving optimality ({:?})",
            outcome.termination_reason()
        )));
    }
    let sol = outcome
        .into_solution()
        .map_err(|_| FeasibilityError::Solver("no solution returned".into()))?;
    let margin = sol.var_value(t) * s;
    let forces = DVector::from_iterator(m, fv.iter().map(|&v| sol.var_value(v) * s));
    Ok(ExactFeasibility {
        feasible: margin >= -1e-7 * s,
        margin,
        forces,
    })
}

/// Exact eq. (3.29) with the faster solver that applies: vertex enumeration for m − n ≤ 2,
/// the simplex otherwise.
pub fn exact(
    at: &DMatrix<f64>,
    w_e: &DVector<f64>,
    f_min: f64,
    f_max: f64,
) -> Result<ExactFeasibility, FeasibilityError> {
    let (n, m) = at.shape();
    if m > n && m - n <= 2 {
        exact_vertex(at, w_e, f_min, f_max)
    } else {
        exact_lp(at, w_e, f_min, f_max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Planar point mass hanging in four cables from the corners of a 2 × 2 frame.
    fn square(r: nalgebra::Vector2<f64>) -> DMatrix<f64> {
        let a = [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)];
        DMatrix::from_fn(2, 4, |row, i| {
            let d = nalgebra::Vector2::new(a[i].0, a[i].1) - r;
            d.normalize()[row]
        })
    }

    #[test]
    fn symmetric_pose_has_the_analytic_margin() {
        // At the centre with no load every cable is at 45°; the kernel is 2-D and the
        // distribution f_i = (f_min + f_max)/2 for all i is admissible: t* = (f_max − f_min)/2.
        let at = square(nalgebra::Vector2::zeros());
        let w = DVector::zeros(2);
        for r in [
            exact_vertex(&at, &w, 100.0, 900.0),
            exact_lp(&at, &w, 100.0, 900.0),
        ] {
            let r = r.unwrap();
            assert!(r.feasible);
            assert!((r.margin - 400.0).abs() < 1e-6, "{}", r.margin);
            let res = &at * &r.forces + &w;
            assert!(res.norm() < 1e-6);
        }
    }

    #[test]
    fn a_load_beyond_the_limits_is_infeasible_by_both_solvers() {
        let at = square(nalgebra::Vector2::zeros());
        // Four cables at 45° carry at most 2·√2·f_max/… vertically: 10 kN down with f_max 1 kN
        // cannot be held.
        let w = DVector::from_vec(vec![0.0, -10_000.0]);
        let v = exact_vertex(&at, &w, 100.0, 1000.0).unwrap();
        let l = exact_lp(&at, &w, 100.0, 1000.0).unwrap();
        assert!(!v.feasible && !l.feasible);
        assert!(
            (v.margin - l.margin).abs() < 1e-3 * 900.0,
            "{} {}",
            v.margin,
            l.margin
        );
    }

    #[test]
    fn rejects_bad_inputs_with_named_errors() {
        let at = square(nalgebra::Vector2::zeros());
        let w = DVector::zeros(3);
        assert_eq!(
            exact(&at, &w, 0.0, 1.0).unwrap_err(),
            FeasibilityError::WrenchLength { got: 3, rows: 2 }
        );
        let w = DVector::zeros(2);
        assert!(matches!(
            exact(&at, &w, 5.0, 1.0),
            Err(FeasibilityError::ForceLimits { .. })
        ));
        let sq = DMatrix::identity(2, 2);
        assert!(matches!(
            exact(&sq, &w, 0.0, 1.0),
            Err(FeasibilityError::NotRedundant { .. })
        ));
    }
}
