//! Statics: structure equation (eq. 2.30–2.31), closed-form force distribution (eq. 3.41),
//! internal/external force split (eq. 2.38–2.40) and section wrenches (eq. 5.11).
//! Every function expects `data` to hold the inverse kinematics of the pose.

use crate::model::Data;
use nalgebra::{DMatrix, Matrix6, Vector6};

/// Why a static computation failed.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum StaticsError {
    #[error("the structure matrix is rank deficient at this pose (A^T A is singular)")]
    Singular,
}

/// A^T f: the wrench the cable forces exert on the platform (eq. 2.30).
pub fn cable_wrench(data: &Data, f: &[f64]) -> Vector6<f64> {
    let mut w = Vector6::zeros();
    for (v, fi) in data.at.iter().zip(f) {
        w += v * *fi;
    }
    w
}

/// γ_sk = A^T f + w_e (eq. 2.31); zero in equilibrium.
pub fn residual_wrench(data: &Data, f: &[f64], w_e: &Vector6<f64>) -> Vector6<f64> {
    cable_wrench(data, f) + w_e
}

/// A^T A = Σ v_i v_i^T (6×6).
pub fn gram(data: &Data) -> Matrix6<f64> {
    let mut g = Matrix6::zeros();
    for v in &data.at {
        g += v * v.transpose();
    }
    g
}

/// The structure matrix A^T as a 6×m matrix (analysis helper; allocates).
pub fn structure_matrix(data: &Data) -> DMatrix<f64> {
    let mut at = DMatrix::zeros(6, data.m());
    for (i, v) in data.at.iter().enumerate() {
        at.set_column(i, v);
    }
    at
}

/// Result of the closed-form force distribution (eq. 3.41) with its feasibility verdict.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceDistribution {
    /// Smallest and largest cable force, N.
    pub f_lo: f64,
    pub f_hi: f64,
    /// Cables holding f_lo and f_hi.
    pub cable_lo: usize,
    pub cable_hi: usize,
    /// f_min ≤ f ≤ f_max for all cables (eq. 3.29).
    pub feasible: bool,
    /// Smallest distance to either limit, N (negative when infeasible).
    pub margin: f64,
}

/// Closed-form force distribution f = f_m − A^{+T}(w_e + A^T f_m), f_m = (f_min + f_max)/2
/// (eq. 3.41, Pott et al. 2009) written to `f_out`, with its feasibility verdict. It is the
/// least-squares closest distribution to f_m that satisfies A^T f + w_e = 0; a feasible result
/// proves wrench feasibility (eq. 3.29), an infeasible one is conservative (another
/// distribution may exist). Allocation-free.
pub fn force_distribution(
    data: &Data,
    w_e: &Vector6<f64>,
    f_min: f64,
    f_max: f64,
    f_out: &mut [f64],
) -> Result<ForceDistribution, StaticsError> {
    let f_m = 0.5 * (f_min + f_max);
    let mut t = *w_e;
    for v in &data.at {
        t += v * f_m;
    }
    // A^{+T} t = A (A^T A)^{-1} t (eq. 2.39): solve the 6×6 system once.
    let chol = gram(data).cholesky().ok_or(StaticsError::Singular)?;
    let y = chol.solve(&t);
    let mut fd = ForceDistribution {
        f_lo: f64::INFINITY,
        f_hi: f64::NEG_INFINITY,
        cable_lo: 0,
        cable_hi: 0,
        feasible: true,
        margin: f64::INFINITY,
    };
    for (i, (v, fo)) in data.at.iter().zip(f_out.iter_mut()).enumerate() {
        let fi = f_m - v.dot(&y);
        *fo = fi;
        if fi < fd.f_lo {
            fd.f_lo = fi;
            fd.cable_lo = i;
        }
        if fi > fd.f_hi {
            fd.f_hi = fi;
            fd.cable_hi = i;
        }
    }
    fd.margin = (fd.f_lo - f_min).min(f_max - fd.f_hi);
    fd.feasible = fd.margin >= 0.0;
    Ok(fd)
}

/// Splits f into the external part f_ext = −A^{+T} w_e (eq. 2.38) and the internal part
/// f_int = (I − A^{+T} A^T) f lying in the kernel of A^T (eq. 2.40). Allocation-free.
pub fn split_internal_external(
    data: &Data,
    w_e: &Vector6<f64>,
    f: &[f64],
    f_ext: &mut [f64],
    f_int: &mut [f64],
) -> Result<(), StaticsError> {
    let chol = gram(data).cholesky().ok_or(StaticsError::Singular)?;
    let y_ext = chol.solve(w_e);
    let y_f = chol.solve(&cable_wrench(data, f));
    for (i, v) in data.at.iter().enumerate() {
        f_ext[i] = -v.dot(&y_ext);
        f_int[i] = f[i] - v.dot(&y_f);
    }
    Ok(())
}

/// Orthonormal basis H (m × (m−6)) of the kernel of A^T, so that A^T H λ = 0 (eq. 2.38).
/// Analysis helper; allocates.
pub fn nullspace_basis(data: &Data) -> DMatrix<f64> {
    let m = data.m();
    // The kernel of A^T is the orthogonal complement of the column space of A (m×6): take the
    // trailing left singular vectors of A from a full SVD of A (A^T A non-singular ⇒ rank 6).
    let a = structure_matrix(data).transpose();
    let svd = nalgebra::linalg::SVD::new(a, true, false);
    let u = svd.u.expect("requested U");
    // U from the thin SVD has only 6 columns; complete the basis by projecting unit vectors.
    let mut basis: Vec<nalgebra::DVector<f64>> =
        (0..u.ncols()).map(|k| u.column(k).into()).collect();
    let mut h = Vec::new();
    for k in 0..m {
        let mut e = nalgebra::DVector::zeros(m);
        e[k] = 1.0;
        for b in &basis {
            let c = b.dot(&e);
            e -= b * c;
        }
        let n = e.norm();
        if n > 1e-8 {
            e /= n;
            basis.push(e.clone());
            h.push(e);
        }
        if h.len() == m - 6 {
            break;
        }
    }
    DMatrix::from_columns(&h)
}

/// Section wrenches of cable subsets, w_Aj = A_j^T f (eq. 5.11), e.g. the helicopter's upper
/// (1,3,5,7) and lower (2,4,6,8) cable sets. `sets` holds 0-based cable indices.
pub fn section_wrench(data: &Data, f: &[f64], set: &[usize]) -> Vector6<f64> {
    let mut w = Vector6::zeros();
    for &i in set {
        w += data.at[i] * f[i];
    }
    w
}
