//! One cable's potential energy as a function of where its ends are, and what its load cell
//! reads. Three laws, each written from its own physics (none is the control model's
//! φ_el = q (1 − f/k_F) with a correction term):
//!
//! * [`Law::Linear`]: a linear rope of axial stiffness EA with `extra` metres of rope in the
//!   drive train between the winch and the frame exit. Rope of unstretched length L + l spans
//!   q + l, so f = EA (q − L)/(q + l) and the energy is plant-oracle's strain energy of that
//!   longer rope, E = EA (L + l)(ε − ln(1 + ε)) with ε = (q − L)/(L + l).
//! * [`Law::Stiffening`]: a stranded rope whose constructional stretch makes it soft at low
//!   tension: with the engineering strain ε = (q − L)/(L + l), F(ε) = EA (ε − ε₀ (1 − e^(−ε/ε₀)))
//!   (tangent stiffness EA (1 − e^(−ε/ε₀)), linear with EA above a few ε₀).
//! * [`Law::Catenary`]: the elastic catenary of a rope of weight w per unstretched length
//!   hanging between the frame exit and the platform anchor (the exact shape, not a sag
//!   correction): end forces (H, V) from the two closure equations, energy = strain energy +
//!   the rope's gravitational potential. The derivative of this energy by the platform anchor
//!   is the rope's end force (envelope theorem), so the equilibrium needs nothing else.

use glam::DVec3;

/// Why a cable's energy cannot be evaluated.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CableError {
    #[error("catenary: span too close to vertical (horizontal span {0:.3e} m)")]
    VerticalSpan(f64),
    #[error("catenary: end forces did not converge")]
    CatenaryNotConverged,
}

/// A cable's elastic law (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Law {
    Linear { ea: f64, extra: f64 },
    Stiffening { ea: f64, extra: f64, eps0: f64 },
    Catenary { ea: f64, weight_per_m: f64 },
}

/// Where a cable is: its path length (with any pulley arc), the frame exit and the platform
/// anchor in the world frame (the catenary needs the chord, the others the length).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Span {
    pub length: f64,
    pub exit: DVec3,
    pub end: DVec3,
}

impl Law {
    /// Axial stiffness EA, N.
    pub fn ea(&self) -> f64 {
        match *self {
            Law::Linear { ea, .. } | Law::Stiffening { ea, .. } | Law::Catenary { ea, .. } => ea,
        }
    }

    /// Potential energy (J) of the cable of unstretched length `l_un` over `span`; for the
    /// catenary including the rope's weight (relative to z = 0).
    pub fn energy(&self, l_un: f64, span: &Span) -> Result<f64, CableError> {
        Ok(match *self {
            Law::Linear { ea, extra } => {
                plant_oracle::cable_energy(ea, l_un + extra, span.length + extra)
            }
            Law::Stiffening { ea, extra, eps0 } => {
                let e = (span.length - l_un) / (l_un + extra);
                (l_un + extra) * stiffening_energy_density(ea, eps0, e)
            }
            Law::Catenary { ea, weight_per_m } => {
                catenary(ea, weight_per_m, l_un, span.end, span.exit)?.energy
            }
        })
    }

    /// Tension at the platform anchor (what a load cell there reads), N; 0 when slack.
    pub fn tension(&self, l_un: f64, span: &Span) -> Result<f64, CableError> {
        Ok(match *self {
            Law::Linear { ea, extra } => {
                if span.length <= l_un {
                    0.0
                } else {
                    ea * (span.length - l_un) / (span.length + extra)
                }
            }
            Law::Stiffening { ea, extra, eps0 } => {
                stiffening_force(ea, eps0, (span.length - l_un) / (l_un + extra))
            }
            Law::Catenary { ea, weight_per_m } => {
                let c = catenary(ea, weight_per_m, l_un, span.end, span.exit)?;
                (c.h * c.h + c.v0 * c.v0).sqrt()
            }
        })
    }
}

/// F(ε) = EA (ε − ε₀ (1 − e^(−ε/ε₀))), 0 for ε ≤ 0.
pub fn stiffening_force(ea: f64, eps0: f64, e: f64) -> f64 {
    if e <= 0.0 {
        return 0.0;
    }
    if eps0 <= 0.0 {
        return ea * e;
    }
    ea * (e + eps0 * (-e / eps0).exp_m1())
}

/// ∫₀^ε F dε' = EA ε₀² (t²/2 − t + 1 − e^(−t)), t = ε/ε₀; the bracket by its series for small t
/// (it is t³/6 − t⁴/24 + …, and its terms cancel to that).
fn stiffening_energy_density(ea: f64, eps0: f64, e: f64) -> f64 {
    if e <= 0.0 {
        return 0.0;
    }
    if eps0 <= 0.0 {
        return 0.5 * ea * e * e;
    }
    let t = e / eps0;
    let bracket = if t < 0.1 {
        // Σ_{n≥3} (−1)^(n+1) tⁿ/n!
        let mut term = t * t * t / 6.0;
        let mut sum = 0.0_f64;
        let mut n = 3.0;
        while term.abs() > 1e-20 * (sum.abs() + 1e-300) && n < 30.0 {
            sum += term;
            n += 1.0;
            term *= -t / n;
        }
        sum
    } else {
        0.5 * t * t - t - (-t).exp_m1()
    };
    ea * eps0 * eps0 * bracket
}

/// asinh(a + d) − asinh(a) for a small d > 0, without the cancellation of the difference: for
/// a and b = a + d of one sign it is asinh(d (b + a)/(b √(1 + a²) + a √(1 + b²))).
fn asinh_diff(a: f64, d: f64) -> f64 {
    let b = a + d;
    if a * b > 0.0 {
        let (ra, rb) = ((1.0 + a * a).sqrt(), (1.0 + b * b).sqrt());
        (d * (b + a) / (b * ra + a * rb)).asinh()
    } else {
        b.asinh() - a.asinh()
    }
}

/// The elastic catenary from the platform anchor P to the frame exit A.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Catenary {
    /// Horizontal tension, N (> 0).
    pub h: f64,
    /// Vertical component of the tension at P (pointing from P along the rope), N.
    pub v0: f64,
    /// Strain energy + gravitational potential of the rope, J.
    pub energy: f64,
}

/// Solves the elastic catenary (Irvine 1981, Lagrangian coordinate s from P, s ∈ [0, L]):
/// the tension is T(s) = (H, V₀ + w s) and the rope's shape
///   x(s) = H s/EA + (H/w)(asinh((V₀ + w s)/H) − asinh(V₀/H)),
///   z(s) = (V₀ s + w s²/2)/EA + (√(H² + (V₀ + w s)²) − √(H² + V₀²))/w;
/// (H, V₀) by Newton's method on x(L) = X, z(L) = Z. Energy: ∫ T²/(2EA) ds + w ∫ z ds.
pub fn catenary(ea: f64, w: f64, l: f64, p: DVec3, a: DVec3) -> Result<Catenary, CableError> {
    let d = a - p;
    let x_span = (d.x * d.x + d.y * d.y).sqrt();
    let z_span = d.z;
    if x_span < 1e-3 {
        return Err(CableError::VerticalSpan(x_span));
    }
    let chord = d.length();
    // Start: the straight rope's tension along the chord, with half the rope's weight at P.
    let t0 = (ea * (chord - l) / l).max(w * l);
    let mut h = t0 * x_span / chord;
    let mut v0 = t0 * z_span / chord - 0.5 * w * l;
    let closure = |h: f64, v0: f64| {
        let v1 = v0 + w * l;
        let (r0, r1) = ((h * h + v0 * v0).sqrt(), (h * h + v1 * v1).sqrt());
        let das = asinh_diff(v0 / h, w * l / h);
        let x = h * l / ea + h / w * das;
        // r1 − r0 = (v1² − v0²)/(r1 + r0) = w L (v1 + v0)/(r1 + r0): no cancellation.
        let z = (v0 * l + 0.5 * w * l * l) / ea + l * (v1 + v0) / (r1 + r0);
        // Jacobian ∂(x, z)/∂(H, V₀).
        let dx_dh = l / ea + das / w - (v1 / r1 - v0 / r0) / w;
        let dx_dv = (h / r1 - h / r0) / w;
        let dz_dh = dx_dv;
        let dz_dv = l / ea + (v1 / r1 - v0 / r0) / w;
        ((x - x_span, z - z_span), (dx_dh, dx_dv, dz_dh, dz_dv))
    };
    // Newton until the closure error stops falling (its floor is round-off, ~1e-15 m): the
    // energy's differences by the anchor position must not see the solver's tolerance.
    let mut err = f64::INFINITY;
    let mut stalls = 0;
    for _ in 0..100 {
        let ((fx, fz), (a11, a12, a21, a22)) = closure(h, v0);
        let e = fx.abs().max(fz.abs());
        if e >= err {
            stalls += 1;
            if stalls >= 2 {
                break;
            }
        } else {
            stalls = 0;
        }
        err = err.min(e);
        if e == 0.0 {
            break;
        }
        let det = a11 * a22 - a12 * a21;
        if !(det.is_finite() && det != 0.0) {
            break;
        }
        let dh = -(a22 * fx - a12 * fz) / det;
        let dv = -(-a21 * fx + a11 * fz) / det;
        // Halve until H stays positive and the closure error does not grow.
        let mut t = 1.0;
        loop {
            let (hn, vn) = (h + t * dh, v0 + t * dv);
            if hn > 0.0 {
                let ((gx, gz), _) = closure(hn, vn);
                if gx.abs().max(gz.abs()) <= e || t < 1e-6 {
                    h = hn;
                    v0 = vn;
                    break;
                }
            }
            t *= 0.5;
            if t < 1e-12 {
                return Err(CableError::CatenaryNotConverged);
            }
        }
    }
    let ((fx, fz), _) = closure(h, v0);
    if fx.abs().max(fz.abs()) > 1e-10 * (1.0 + chord) {
        return Err(CableError::CatenaryNotConverged);
    }
    let v1 = v0 + w * l;
    let (r0, r1) = ((h * h + v0 * v0).sqrt(), (h * h + v1 * v1).sqrt());
    let strain = (h * h * l + (v1 * v1 * v1 - v0 * v0 * v0) / (3.0 * w)) / (2.0 * ea);
    // ∫₀ᴸ z(s) ds with G(t) = ½ (t √(H² + t²) + H² asinh(t/H)), ∫ √(H² + (V₀ + ws)²) ds = ΔG / w.
    let g = |t: f64, r: f64| 0.5 * (t * r + h * h * (t / h).asinh());
    let int_z =
        (0.5 * v0 * l * l + w * l * l * l / 6.0) / ea + ((g(v1, r1) - g(v0, r0)) / w - l * r0) / w;
    let energy = strain + w * (l * p.z + int_z);
    Ok(Catenary { h, v0, energy })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn span(q: f64) -> Span {
        Span {
            length: q,
            exit: DVec3::ZERO,
            end: DVec3::ZERO,
        }
    }

    /// Each law's energy derivative by the length is its tension (central differences).
    #[test]
    fn energy_derivative_is_the_tension() {
        let laws = [
            Law::Linear {
                ea: 2e6,
                extra: 0.0,
            },
            Law::Linear {
                ea: 2e6,
                extra: 12.0,
            },
            Law::Stiffening {
                ea: 2e6,
                extra: 5.0,
                eps0: 8e-4,
            },
        ];
        for law in laws {
            for (l, q) in [(8.0, 8.01), (8.0, 8.0001), (8.0, 8.03)] {
                let h = 1e-6;
                let d = (law.energy(l, &span(q + h)).unwrap()
                    - law.energy(l, &span(q - h)).unwrap())
                    / (2.0 * h);
                let f = law.tension(l, &span(q)).unwrap();
                assert!(
                    (d - f).abs() < 1e-6 * f + 1e-3,
                    "{law:?} q {q}: dE/dq {d} vs {f}"
                );
            }
        }
    }

    /// The extra rope makes the cable softer exactly as a longer rope: f = EA (q − L)/(q + l).
    #[test]
    fn extra_rope_is_a_longer_rope() {
        let law = Law::Linear {
            ea: 2e6,
            extra: 10.0,
        };
        let f = law.tension(8.0, &span(8.02)).unwrap();
        assert!((f - 2e6 * 0.02 / 18.02).abs() < 1e-9, "{f}");
    }

    /// The catenary's end tension is the derivative of its energy by the platform anchor
    /// (components H along the horizontal chord, V₀), the rope's weight is carried by its two
    /// ends (V₁ − V₀ = w L), and a stiff light rope tends to the straight chord.
    #[test]
    fn catenary_forces_are_the_energy_gradient() {
        let (ea, w, l) = (2e6, 7.85, 9.97);
        let p = DVec3::new(0.3, -0.2, 1.5);
        let a = DVec3::new(5.2, 7.5, 6.4);
        let c = catenary(ea, w, l, p, a).unwrap();
        let h = 1e-6;
        let mut grad = DVec3::ZERO;
        for k in 0..3 {
            let mut e = DVec3::ZERO;
            e[k] = h;
            let up = catenary(ea, w, l, p + e, a).unwrap().energy;
            let dn = catenary(ea, w, l, p - e, a).unwrap().energy;
            grad[k] = (up - dn) / (2.0 * h);
        }
        // Force on the platform = −∂E/∂P = the tension at P along the rope towards A.
        let d = a - p;
        let horiz = DVec3::new(d.x, d.y, 0.0).normalize();
        let force = horiz * c.h + DVec3::Z * c.v0;
        assert!(
            (-grad - force).length() < 1e-4 * force.length(),
            "{grad:?} vs {force:?}"
        );
        // Light rope: the chord's straight elastic law (engineering strain).
        let c0 = catenary(ea, 0.05, l, p, a).unwrap();
        let chord = d.length();
        let f_straight = ea * (chord - l) / l;
        assert!(
            ((c0.h * c0.h + c0.v0 * c0.v0).sqrt() - f_straight).abs() < 1e-3 * f_straight,
            "{c0:?} vs {f_straight}"
        );
    }
}
