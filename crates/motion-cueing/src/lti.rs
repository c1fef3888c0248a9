//! Linear time-invariant SISO filters: a rational transfer function H(s) = num(s)/den(s) as a
//! continuous state space in controllable canonical form, discretised exactly for a
//! zero-order-held input (Φ = e^{A dt}, Γ = ∫₀^dt e^{Aτ} dτ B, from the exponential of the
//! augmented matrix [[A, B], [0, 0]] dt). The washout filters, the tilt low-pass and the
//! vestibular models are all of this kind.
//!
//! Model/Data split: [`Lti`] holds the discretised matrices (built once, allocates), the state
//! is a plain `SVector` the caller owns; [`Lti::step`] is allocation-free.
//!
//! Canonical form, den(s) = sᴺ + a₁ sᴺ⁻¹ + … + a_N: z₁ = U/den, z_k = s^{k−1} z₁, so
//! ż_k = z_{k+1} (k < N), ż_N = −a_N z₁ − … − a₁ z_N + u; the output of
//! num(s) = b₀ sᴺ + b₁ sᴺ⁻¹ + … + b_N is y = Σ_k (b_{N+1−k} − b₀ a_{N+1−k}) z_k + b₀ u.

use nalgebra::{DMatrix, SMatrix, SVector};

/// Why a transfer function cannot be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LtiError {
    #[error(
        "denominator must have degree {expected} (got {got} coefficients) with a non-zero leading coefficient"
    )]
    Denominator { expected: usize, got: usize },
    #[error("numerator degree {0} exceeds the denominator's (improper transfer function)")]
    Improper(usize),
    #[error("coefficients and the time step must be finite (time step > 0)")]
    NotFinite,
}

/// A discretised SISO transfer function of order N.
#[derive(Clone, Debug, PartialEq)]
pub struct Lti<const N: usize> {
    /// Continuous A, B (canonical form), for derivatives of the state.
    pub a: SMatrix<f64, N, N>,
    pub b: SVector<f64, N>,
    /// Output row C and feed-through D of y = C z + D u.
    pub c: SMatrix<f64, 1, N>,
    pub d: f64,
    /// Zero-order-hold discretisation over `dt`.
    pub phi: SMatrix<f64, N, N>,
    pub gamma: SVector<f64, N>,
    pub dt: f64,
}

impl<const N: usize> Lti<N> {
    /// H(s) = num(s)/den(s), coefficients in descending powers of s; `den` has N + 1 entries
    /// (normalised to a monic polynomial here), `num` at most N + 1.
    pub fn from_tf(num: &[f64], den: &[f64], dt: f64) -> Result<Self, LtiError> {
        if den.len() != N + 1 || den[0] == 0.0 {
            return Err(LtiError::Denominator {
                expected: N,
                got: den.len(),
            });
        }
        if num.len() > N + 1 {
            return Err(LtiError::Improper(num.len() - 1));
        }
        if !(num.iter().chain(den).all(|v| v.is_finite()) && dt.is_finite() && dt > 0.0) {
            return Err(LtiError::NotFinite);
        }
        let lead = den[0];
        // a_k, k = 1..N, and b_k, k = 0..N (num padded with leading zeros), both / den[0].
        let a_coef: Vec<f64> = den[1..].iter().map(|v| v / lead).collect();
        let mut b_coef = vec![0.0; N + 1 - num.len()];
        b_coef.extend(num.iter().map(|v| v / lead));
        let mut a = SMatrix::<f64, N, N>::zeros();
        for k in 0..N.saturating_sub(1) {
            a[(k, k + 1)] = 1.0;
        }
        for k in 0..N {
            // ż_N = −a_N z₁ − a_{N−1} z₂ − … − a₁ z_N + u
            a[(N - 1, k)] = -a_coef[N - 1 - k];
        }
        let mut b = SVector::<f64, N>::zeros();
        b[N - 1] = 1.0;
        let b0 = b_coef[0];
        let mut c = SMatrix::<f64, 1, N>::zeros();
        for k in 0..N {
            // c_k (0-based k) = b_{N−k} − b₀ a_{N−k}
            c[(0, k)] = b_coef[N - k] - b0 * a_coef[N - 1 - k];
        }
        let (phi, gamma) = zoh(&a, &b, dt);
        Ok(Self {
            a,
            b,
            c,
            d: b0,
            phi,
            gamma,
            dt,
        })
    }

    /// Output y_k = C z_k + D u_k, then z_{k+1} = Φ z_k + Γ u_k. Allocation-free.
    #[inline]
    pub fn step(&self, z: &mut SVector<f64, N>, u: f64) -> f64 {
        let y = (self.c * *z)[0] + self.d * u;
        *z = self.phi * *z + self.gamma * u;
        y
    }

    /// The state derivative ż = A z + B u at the current state (continuous time).
    #[inline]
    pub fn derivative(&self, z: &SVector<f64, N>, u: f64) -> SVector<f64, N> {
        self.a * z + self.b * u
    }

    /// The steady state for a constant input u (A z + B u = 0), None when A is singular (a
    /// pure integrator or differentiator in the denominator).
    pub fn steady_state(&self, u: f64) -> Option<SVector<f64, N>> {
        self.a.try_inverse().map(|inv| -(inv * self.b) * u)
    }

    /// The static gain H(0) (None when den(0) = 0).
    pub fn dc_gain(&self) -> Option<f64> {
        self.steady_state(1.0).map(|z| (self.c * z)[0] + self.d)
    }
}

/// Φ = e^{A dt}, Γ = ∫₀^dt e^{Aτ} dτ B from the exponential of [[A, B], [0, 0]]·dt.
fn zoh<const N: usize>(
    a: &SMatrix<f64, N, N>,
    b: &SVector<f64, N>,
    dt: f64,
) -> (SMatrix<f64, N, N>, SVector<f64, N>) {
    let mut m = DMatrix::<f64>::zeros(N + 1, N + 1);
    m.view_mut((0, 0), (N, N)).copy_from(&(a * dt));
    m.view_mut((0, N), (N, 1)).copy_from(&(b * dt));
    let e = m.exp();
    let phi = SMatrix::<f64, N, N>::from_fn(|i, j| e[(i, j)]);
    let gamma = SVector::<f64, N>::from_fn(|i, _| e[(i, N)]);
    (phi, gamma)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_low_pass_matches_the_exact_exponential() {
        // H = 1/(τ s + 1): y(t) = 1 − e^{−t/τ} for a unit step; ZOH is exact for a step.
        let tau = 0.5;
        let f = Lti::<1>::from_tf(&[1.0], &[tau, 1.0], 1e-3).unwrap();
        let mut z = SVector::<f64, 1>::zeros();
        let mut y = 0.0;
        for _ in 0..1000 {
            f.step(&mut z, 1.0);
            y = (f.c * z)[0];
        }
        assert!((y - (1.0 - (-1.0f64 / tau).exp())).abs() < 1e-12, "{y}");
        assert!((f.dc_gain().unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn feed_through_and_canonical_outputs() {
        // H = (s + 3)/(s + 1): D = 1, C = 3 − 1 = 2; DC gain 3.
        let f = Lti::<1>::from_tf(&[1.0, 3.0], &[1.0, 1.0], 1e-3).unwrap();
        assert_eq!(f.d, 1.0);
        assert!((f.c[0] - 2.0).abs() < 1e-15);
        assert!((f.dc_gain().unwrap() - 3.0).abs() < 1e-12);
        // A second-order high-pass has no static gain and a unit high-frequency gain.
        let hp = Lti::<2>::from_tf(&[1.0, 0.0, 0.0], &[1.0, 2.0, 1.0], 1e-3).unwrap();
        assert!(hp.dc_gain().unwrap().abs() < 1e-12);
        assert_eq!(hp.d, 1.0);
        assert!(matches!(
            Lti::<2>::from_tf(&[1.0, 0.0, 0.0, 0.0], &[1.0, 2.0, 1.0], 1e-3),
            Err(LtiError::Improper(3))
        ));
        assert!(matches!(
            Lti::<2>::from_tf(&[1.0], &[1.0, 2.0], 1e-3),
            Err(LtiError::Denominator { .. })
        ));
        assert!(matches!(
            Lti::<1>::from_tf(&[1.0], &[1.0, f64::NAN], 1e-3),
            Err(LtiError::NotFinite)
        ));
    }
}
