//! The 6 × 6 symmetric solve of the Newton step (Cholesky), written out: glam stops at 4 × 4,
//! and the oracle takes nothing from the model library's nalgebra code paths.
// Index loops: the textbook form of the factorisation, L[i][k] L[j][k], reads best as such.
#![allow(clippy::needless_range_loop)]

/// Solves H s = b for symmetric positive definite `h`; None when H is not positive definite.
pub fn cholesky_solve(h: &[[f64; 6]; 6], b: &[f64; 6]) -> Option<[f64; 6]> {
    let mut l = [[0.0; 6]; 6];
    for i in 0..6 {
        for j in 0..=i {
            let mut s = h[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut y = [0.0; 6];
    for i in 0..6 {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i][k] * y[k];
        }
        y[i] = s / l[i][i];
    }
    let mut x = [0.0; 6];
    for i in (0..6).rev() {
        let mut s = y[i];
        for k in i + 1..6 {
            s -= l[k][i] * x[k];
        }
        x[i] = s / l[i][i];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_spd_system_and_refuses_an_indefinite_one() {
        // H = M Mᵀ + I for a fixed M: SPD.
        let mut m = [[0.0; 6]; 6];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = ((i * 7 + j * 3) % 5) as f64 - 2.0;
            }
        }
        let mut h = [[0.0; 6]; 6];
        for i in 0..6 {
            for j in 0..6 {
                h[i][j] = (0..6).map(|k| m[i][k] * m[j][k]).sum::<f64>() + f64::from(i == j);
            }
        }
        let x_true = [1.0, -2.0, 0.5, 3.0, -0.25, 2.0];
        let mut b = [0.0; 6];
        for i in 0..6 {
            b[i] = (0..6).map(|j| h[i][j] * x_true[j]).sum();
        }
        let x = cholesky_solve(&h, &b).unwrap();
        for i in 0..6 {
            assert!((x[i] - x_true[i]).abs() < 1e-10, "{x:?}");
        }
        h[2][2] = -1.0;
        assert!(cholesky_solve(&h, &b).is_none());
    }
}
