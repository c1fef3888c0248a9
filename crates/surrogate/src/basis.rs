//! Polynomial basis of total degree `d` in the 6 normalised pose coordinates.
//!
//! Each basis function is a tensor product `b_k(u) = prod_i p_{a_i}(u_i)` with `sum_i a_i <= d`,
//! where `p_n` is either the Legendre polynomial `P_n` or the plain power `u^n`. There are
//! `C(6 + d, d)` of them (84 for `d = 3`). Both 1-D families satisfy `|p_n(u)| <= 1` on
//! `[-1, 1]`, so for either basis `|phi_sg,j(x)| <= sum_k |c_jk|` everywhere (evaluation clamps
//! `u` to the unit box): this is the *certified bound* reported next to the sampled one.
//!
//! The enumeration order is fixed by [`for_each_basis`] (nested loops, `a_0` outermost); the fit,
//! the evaluation and the exponent list written to the file all use that one function, so they
//! cannot disagree.

use crate::region::N_COORDS;
use serde::{Deserialize, Serialize};

/// Highest supported total degree (`C(12, 6) = 924` coefficients per cable). Degree 3 is the
/// default. The cap bounds the evaluator's stack use (7.4 KiB of basis values) and the offline
/// SVD, whose cost grows like `samples x C(6+d, d)^2`.
pub const MAX_DEGREE: usize = 6;

/// 1-D polynomial family the tensor-product basis is built from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Basis {
    /// Legendre polynomials `P_n(u)`: orthogonal under the uniform measure on `[-1, 1]`, so the
    /// least-squares design over a uniform low-discrepancy sample is well conditioned. Default.
    #[default]
    Legendre,
    /// Plain powers `u^n` of the normalised coordinates (worse conditioned; for comparison).
    Monomial,
}

/// Per-coordinate 1-D polynomial values `t[i][n] = p_n(u_i)` for `n <= degree`.
pub(crate) type Tables = [[f64; MAX_DEGREE + 1]; N_COORDS];

/// Legendre three-term recurrence coefficients, `P_n = A_n u P_{n-1} - B_n P_{n-2}`,
/// `A_n = (2n - 1) / n`, `B_n = (n - 1) / n` (entries 0 and 1 unused).
const LEG_A: [f64; MAX_DEGREE + 1] = {
    let mut a = [0.0; MAX_DEGREE + 1];
    let mut n = 2;
    while n <= MAX_DEGREE {
        a[n] = (2 * n - 1) as f64 / n as f64;
        n += 1;
    }
    a
};
const LEG_B: [f64; MAX_DEGREE + 1] = {
    let mut b = [0.0; MAX_DEGREE + 1];
    let mut n = 2;
    while n <= MAX_DEGREE {
        b[n] = (n - 1) as f64 / n as f64;
        n += 1;
    }
    b
};

/// Number of basis functions of total degree `<= degree` in 6 variables, `C(6 + d, d)`.
pub const fn n_basis(degree: usize) -> usize {
    // C(6 + d, 6) computed incrementally; exact in integers for the supported range.
    let mut num: usize = 1;
    let mut i = 1;
    while i <= N_COORDS {
        num = num * (degree + i) / i;
        i += 1;
    }
    num
}

/// Fills the 1-D tables for normalised coordinates `u` up to `degree` (`<= MAX_DEGREE`).
/// Fixed cost: the loop bounds depend on the model's degree only.
#[inline(always)]
pub(crate) fn fill_tables(basis: Basis, degree: usize, u: &[f64; N_COORDS], t: &mut Tables) {
    let d = degree.min(MAX_DEGREE);
    for i in 0..N_COORDS {
        let ui = u[i];
        let ti = &mut t[i];
        ti[0] = 1.0;
        if d >= 1 {
            ti[1] = ui;
        }
        match basis {
            Basis::Legendre => {
                for n in 2..d + 1 {
                    ti[n] = LEG_A[n] * ui * ti[n - 1] - LEG_B[n] * ti[n - 2];
                }
            }
            Basis::Monomial => {
                for n in 2..d + 1 {
                    ti[n] = ui * ti[n - 1];
                }
            }
        }
    }
}

/// Calls `f(a, b_k)` for every basis function in the canonical order, with its exponent tuple `a`
/// and value `b_k = prod_i t[i][a_i]`. One multiplication per basis function.
#[inline(always)]
pub(crate) fn for_each_basis(t: &Tables, degree: usize, mut f: impl FnMut(&[usize; 6], f64)) {
    // Exclusive ranges over slices (not `0..=d` index loops): no per-iteration bounds checks and
    // none of `RangeInclusive`'s extra exhaustion bookkeeping in this hot loop nest.
    let d = degree.min(MAX_DEGREE);
    for (a0, &t0) in t[0][..d + 1].iter().enumerate() {
        let r0 = d - a0;
        for (a1, &t1) in t[1][..r0 + 1].iter().enumerate() {
            let p1 = t0 * t1;
            let r1 = r0 - a1;
            for (a2, &t2) in t[2][..r1 + 1].iter().enumerate() {
                let p2 = p1 * t2;
                let r2 = r1 - a2;
                for (a3, &t3) in t[3][..r2 + 1].iter().enumerate() {
                    let p3 = p2 * t3;
                    let r3 = r2 - a3;
                    for (a4, &t4) in t[4][..r3 + 1].iter().enumerate() {
                        let p4 = p3 * t4;
                        let r4 = r3 - a4;
                        for (a5, &t5) in t[5][..r4 + 1].iter().enumerate() {
                            f(&[a0, a1, a2, a3, a4, a5], p4 * t5);
                        }
                    }
                }
            }
        }
    }
}

/// Exponent tuples of the basis functions in canonical order (written to the file so the file
/// says which polynomial each coefficient multiplies).
pub(crate) fn exponents(degree: usize) -> Vec<[u8; 6]> {
    let t: Tables = [[0.0; MAX_DEGREE + 1]; N_COORDS];
    let mut out = Vec::with_capacity(n_basis(degree));
    for_each_basis(&t, degree, |a, _| {
        out.push(a.map(|v| v as u8));
    });
    out
}

/// Values of all basis functions at normalised `u` (offline use: design matrix rows).
pub(crate) fn basis_row(basis: Basis, degree: usize, u: &[f64; N_COORDS], row: &mut [f64]) {
    let mut t: Tables = [[0.0; MAX_DEGREE + 1]; N_COORDS];
    fill_tables(basis, degree, u, &mut t);
    let mut k = 0;
    for_each_basis(&t, degree, |_, b| {
        row[k] = b;
        k += 1;
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_match_binomial() {
        assert_eq!(n_basis(0), 1);
        assert_eq!(n_basis(1), 7);
        assert_eq!(n_basis(2), 28);
        assert_eq!(n_basis(3), 84);
        assert_eq!(n_basis(6), 924);
        for d in 0..=MAX_DEGREE {
            let e = exponents(d);
            assert_eq!(e.len(), n_basis(d));
            assert!(
                e.iter()
                    .all(|a| a.iter().map(|&v| v as usize).sum::<usize>() <= d)
            );
            let mut sorted = e.clone();
            sorted.sort();
            sorted.dedup();
            assert_eq!(
                sorted.len(),
                e.len(),
                "duplicate exponent tuples at degree {d}"
            );
        }
    }

    #[test]
    fn legendre_tables_match_closed_forms() {
        let u = [0.3, -0.7, 1.0, -1.0, 0.0, 0.55];
        let mut t: Tables = [[0.0; MAX_DEGREE + 1]; N_COORDS];
        fill_tables(Basis::Legendre, 4, &u, &mut t);
        for i in 0..N_COORDS {
            let x = u[i];
            let p2 = 0.5 * (3.0 * x * x - 1.0);
            let p3 = 0.5 * (5.0 * x * x * x - 3.0 * x);
            let p4 = (35.0 * x.powi(4) - 30.0 * x * x + 3.0) / 8.0;
            assert!((t[i][2] - p2).abs() < 1e-15);
            assert!((t[i][3] - p3).abs() < 1e-15);
            assert!((t[i][4] - p4).abs() < 1e-15);
        }
    }

    #[test]
    fn basis_row_is_product_of_tables() {
        let u = [0.1, 0.2, -0.3, 0.4, -0.5, 0.6];
        let d = 3;
        let mut row = vec![0.0; n_basis(d)];
        basis_row(Basis::Monomial, d, &u, &mut row);
        for (k, a) in exponents(d).iter().enumerate() {
            let want: f64 = (0..6).map(|i| u[i].powi(a[i] as i32)).product();
            assert!((row[k] - want).abs() < 1e-15, "k={k} a={a:?}");
        }
    }
}
