//! The plant's cable force law: powertrain compliance (effect 3), tension-dependent stiffness
//! (effect 4a), hysteresis (effect 4b) and sag (effect 5), behind motion-core's
//! [`CableLaw`] so the elastostatic forward kinematics ν_el (eq. 2.42) solves the plant with it.
//!
//! Per cable, with e = q − q_θ (eq. 2.35):
//! * linear compliance c(q) = (q + l_extra)/k_F + c_s (eq. 2.33 with the rope stored in the
//!   drive train, plus series compliances, eq. 6.18); its "linear-equivalent force"
//!   s = e_el / c(q) where e_el is the elastic elongation;
//! * elastic force f = F_b(s) + h(s): F_b is the backbone (s itself when the stiffness is
//!   linear; otherwise the inverse of the elongation integral of k(f) = k_lin ((f+f_0)/(f_ref+f_0))^n)
//!   and h is a Prandtl stop operator h = clamp(h_0 + r (s − s_0), −H, H) whose state
//!   (h_0, s_0) is committed after every plant step (loading/unloading paths of Fig. 5.7);
//! * sag: the chord q is shorter than the stretched rope by the parabolic-catenary sag
//!   shortening Δ = (w cos α)² q³ / (24 f²) (Irvine 1981, "Cable Structures", eq. for the
//!   small-sag elastic catenary; its tangent is Ernst's 1965 equivalent modulus
//!   E_eq = E / (1 + (w l_h)² E A / (12 T³))), so e_el = e + Δ(f): solved per cable for f.
//!   w = μ g is the rope weight per length, α the chord inclination (set by the plant from the
//!   kinematics at every trial pose). The force acts along the chord; the share of the rope
//!   weight the platform carries (half of each span) is added to the wrench by the plant.
//!
//! With every effect off the law is motion-core's [`LinearElastic`] bit for bit.

use crate::config::{Effects, Hysteresis, TensionStiffness};
use cdpr_model::elastostatics::{CableForce, CableLaw, LinearElastic};

/// Force law of the plant's cables plus the hysteresis state.
#[derive(Clone, Debug)]
pub struct PlantLaw {
    k_f: Vec<f64>,
    extra: Vec<f64>,
    series: Vec<f64>,
    powertrain: bool,
    stiffness: Option<TensionStiffness>,
    hysteresis: Option<Hysteresis>,
    /// Rope weight per length w = μ g, N/m (sag on).
    sag_weight: Option<f64>,
    /// cos² α of each chord, frozen during one equilibrium solve.
    pub(crate) sag_cos2: Vec<f64>,
    /// Stop-operator state: output h_0 (N) at input s_0 (N).
    pub(crate) hyst_h: Vec<f64>,
    pub(crate) hyst_s: Vec<f64>,
}

/// Hysteresis state of all cables (for snapshots).
#[derive(Clone, Debug, PartialEq)]
pub struct HysteresisState {
    pub h: Vec<f64>,
    pub s: Vec<f64>,
}

#[derive(Clone, Copy, Debug)]
struct Solved {
    f: f64,
    /// dF/ds of the elastic element at the solution.
    dfds: f64,
    s: f64,
    c: f64,
    /// Sag constant D = (w cos α)² q³ / 24, N²·m.
    d: f64,
}

impl PlantLaw {
    /// Builds the law of a plant from the platform's k_F and the effects.
    pub fn new(platform_k_f: &[f64], fx: &Effects) -> Self {
        let m = platform_k_f.len();
        let (k_f, extra, series, powertrain) = match &fx.powertrain {
            Some(p) => (
                p.k_f.clone(),
                p.extra_length.clone(),
                p.series_compliance.clone(),
                true,
            ),
            None => (platform_k_f.to_vec(), vec![0.0; m], vec![0.0; m], false),
        };
        Self {
            k_f,
            extra,
            series,
            powertrain,
            stiffness: fx.stiffness,
            hysteresis: fx.hysteresis,
            sag_weight: fx.sag.map(|s| s.mass_per_length * s.gravity),
            sag_cos2: vec![0.0; m],
            hyst_h: vec![0.0; m],
            hyst_s: vec![0.0; m],
        }
    }

    /// True when the law is exactly the control model's linear law.
    pub fn is_linear(&self) -> bool {
        !self.powertrain
            && self.stiffness.is_none()
            && self.hysteresis.is_none()
            && self.sag_weight.is_none()
    }

    pub fn has_sag(&self) -> bool {
        self.sag_weight.is_some()
    }

    /// Sets cos² α of every chord (the plant does this from the kinematics before each
    /// evaluation; public for analysis and tests).
    pub fn set_chord_cos2(&mut self, cos2: &[f64]) {
        self.sag_cos2.copy_from_slice(cos2);
    }

    pub fn hysteresis_state(&self) -> HysteresisState {
        HysteresisState {
            h: self.hyst_h.clone(),
            s: self.hyst_s.clone(),
        }
    }

    pub fn set_hysteresis_state(&mut self, st: &HysteresisState) {
        self.hyst_h.copy_from_slice(&st.h);
        self.hyst_s.copy_from_slice(&st.s);
    }

    /// Linear compliance c(q) = (q + l_extra)/k_F + c_s, m/N.
    #[inline]
    fn compliance(&self, i: usize, q: f64) -> f64 {
        (q + self.extra[i]) / self.k_f[i] + self.series[i]
    }

    /// Backbone F_b(s) and its slope.
    #[inline]
    fn backbone(&self, s: f64) -> (f64, f64) {
        match &self.stiffness {
            None => (s, 1.0),
            Some(t) => {
                let (n, f0, fr) = (t.exponent, t.force_offset, t.reference_force);
                if s >= 0.0 {
                    // E(f) = (f_r+f_0)^n/(1−n) [(f+f_0)^(1−n) − f_0^(1−n)], dE/df = ((f_r+f_0)/(f+f_0))^n
                    let a = (fr + f0).powf(n) / (1.0 - n);
                    let f = (s / a + f0.powf(1.0 - n)).powf(1.0 / (1.0 - n)) - f0;
                    (f, ((f + f0) / (fr + f0)).powf(n))
                } else {
                    let k0 = (f0 / (fr + f0)).powf(n);
                    (s * k0, k0)
                }
            }
        }
    }

    /// Inverse of the backbone: s = E(f).
    fn backbone_inverse(&self, f: f64) -> f64 {
        match &self.stiffness {
            None => f,
            Some(t) => {
                let (n, f0, fr) = (t.exponent, t.force_offset, t.reference_force);
                if f >= 0.0 {
                    (fr + f0).powf(n) / (1.0 - n) * ((f + f0).powf(1.0 - n) - f0.powf(1.0 - n))
                } else {
                    f / (f0 / (fr + f0)).powf(n)
                }
            }
        }
    }

    /// Stop operator output at input s from the committed state, and its slope.
    #[inline]
    fn stop(&self, i: usize, s: f64) -> (f64, f64) {
        match &self.hysteresis {
            None => (0.0, 0.0),
            Some(h) => {
                let raw = self.hyst_h[i] + h.stiffness_ratio * (s - self.hyst_s[i]);
                if raw > h.half_width {
                    (h.half_width, 0.0)
                } else if raw < -h.half_width {
                    (-h.half_width, 0.0)
                } else {
                    (raw, h.stiffness_ratio)
                }
            }
        }
    }

    #[inline]
    fn elastic(&self, i: usize, s: f64) -> (f64, f64) {
        let (fb, db) = self.backbone(s);
        let (h, dh) = self.stop(i, s);
        (fb + h, db + dh)
    }

    /// s with elastic(i, s) = f (monotone; safeguarded Newton).
    fn elastic_inverse(&self, i: usize, f: f64) -> f64 {
        if self.hysteresis.is_none() {
            return self.backbone_inverse(f);
        }
        let mut s = self.backbone_inverse(f - self.stop(i, self.backbone_inverse(f)).0);
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for _ in 0..200 {
            let (g, dg) = self.elastic(i, s);
            let r = g - f;
            if r.abs() <= 1e-12 * (1.0 + f.abs()) {
                break;
            }
            if r > 0.0 {
                hi = hi.min(s);
            } else {
                lo = lo.max(s);
            }
            let mut next = s - r / dg;
            if !(next > lo && next < hi) {
                next = if lo.is_finite() && hi.is_finite() {
                    0.5 * (lo + hi)
                } else if lo.is_finite() {
                    lo + 2.0 * (lo.abs() + 1.0)
                } else {
                    hi - 2.0 * (hi.abs() + 1.0)
                };
            }
            s = next;
        }
        s
    }

    #[inline]
    fn sag_d(&self, i: usize, q: f64) -> f64 {
        match self.sag_weight {
            Some(w) => w * w * self.sag_cos2[i] * q * q * q / 24.0,
            None => 0.0,
        }
    }

    /// Solves the cable: force, elastic input s, compliance and sag constant.
    fn solve(&self, i: usize, q: f64, q_theta: f64) -> Solved {
        let e = q - q_theta;
        let c = self.compliance(i, q);
        let d = self.sag_d(i, q);
        if d <= 0.0 {
            let s = if self.powertrain {
                e / c
            } else {
                self.k_f[i] / q * e
            };
            let (f, dfds) = self.elastic(i, s);
            return Solved {
                f,
                dfds,
                s,
                c,
                d: 0.0,
            };
        }
        // G(f) = F_el((e + D/f²)/c) − f is strictly decreasing on f > 0, +∞ at 0+.
        let g = |f: f64| {
            let s = (e + d / (f * f)) / c;
            let (fe, dfe) = self.elastic(i, s);
            (fe - f, dfe * (-2.0 * d / (f * f * f * c)) - 1.0, s, dfe)
        };
        // Without sag the force would be F_el(e/c); the sag only adds elongation, so the root
        // lies above it. G is convex (stiffening backbone, s ∝ 1/f²), so Newton from the left
        // climbs monotonically; the bracket [lo, hi] guards the kinks of the stop operator.
        let f_nosag = self.elastic(i, e / c).0;
        let mut lo = 0.0;
        let mut hi = f64::INFINITY;
        let mut f = if f_nosag > 0.0 {
            f_nosag
        } else if e < 0.0 {
            // slack in the linear sense: the inextensible catenary f = sqrt(D / −e) is above
            (d / -e).sqrt()
        } else {
            (d / c).sqrt().cbrt().max(1.0)
        };
        for _ in 0..200 {
            let (r, dr, _, _) = g(f);
            if r > 0.0 {
                lo = f;
            } else {
                hi = f;
            }
            let mut next = f - r / dr;
            if !(next > lo && next < hi && next.is_finite()) {
                next = if hi.is_finite() {
                    if lo > 0.0 { (lo * hi).sqrt() } else { 0.5 * hi }
                } else {
                    2.0 * f
                };
            }
            let done = (next - f).abs() <= 1e-14 * f;
            f = next;
            if done || (hi.is_finite() && hi - lo <= 1e-14 * hi) {
                break;
            }
        }
        let (_, _, s, dfds) = g(f);
        Solved { f, dfds, s, c, d }
    }

    /// Quasi-static move of one cable to (q, q_θ): its force, and the hysteresis state
    /// committed there (what the plant does for every cable after an equilibrium).
    pub fn advance(&mut self, i: usize, q: f64, q_theta: f64) -> CableForce {
        let f = self.force(i, q, q_theta);
        let s = self.elastic_input(i, q, q_theta);
        self.commit(i, s);
        f
    }

    /// Linear-equivalent elastic input s of cable i at (q, q_θ) (for the hysteresis commit).
    pub(crate) fn elastic_input(&self, i: usize, q: f64, q_theta: f64) -> f64 {
        self.solve(i, q, q_theta).s
    }

    /// Commits the stop operator of cable i to input s (end of a plant step).
    pub(crate) fn commit(&mut self, i: usize, s: f64) {
        if self.hysteresis.is_some() {
            let h = self.stop(i, s).0;
            self.hyst_h[i] = h;
            self.hyst_s[i] = s;
        }
    }

    /// Resets cable i to the virgin hysteresis state h = 0 at the input that carries `f` on
    /// the backbone (the tension was set and the rope settled, sec. 6.1).
    pub(crate) fn reset_at_force(&mut self, i: usize, f: f64) {
        self.hyst_h[i] = 0.0;
        self.hyst_s[i] = self.backbone_inverse(f);
    }
}

impl CableLaw for PlantLaw {
    fn force(&self, i: usize, q: f64, q_theta: f64) -> CableForce {
        if self.is_linear() {
            return LinearElastic { k_f: &self.k_f }.force(i, q, q_theta);
        }
        let r = self.solve(i, q, q_theta);
        if r.d <= 0.0 {
            let dc_dq = 1.0 / self.k_f[i];
            if self.powertrain {
                CableForce {
                    f: r.f,
                    df_dq: r.dfds * (1.0 - r.s * dc_dq) / r.c,
                    df_dqt: -r.dfds / r.c,
                }
            } else {
                let k = self.k_f[i] / q;
                CableForce {
                    f: r.f,
                    df_dq: r.dfds * k * q_theta / q,
                    df_dqt: -r.dfds * k,
                }
            }
        } else {
            // Implicit derivatives of f = F(s), s = (q − q_θ + D(q)/f²)/c(q), D ∝ q³.
            let f3 = r.f * r.f * r.f;
            let den = 1.0 + r.dfds * 2.0 * r.d / (f3 * r.c);
            let dd_dq = 3.0 * r.d / q;
            CableForce {
                f: r.f,
                df_dq: r.dfds * (1.0 + dd_dq / (r.f * r.f) - r.s / self.k_f[i]) / (r.c * den),
                df_dqt: -r.dfds / (r.c * den),
            }
        }
    }

    fn controlled_length(&self, i: usize, q: f64, f: f64) -> f64 {
        if self.is_linear() {
            return LinearElastic { k_f: &self.k_f }.controlled_length(i, q, f);
        }
        let s = self.elastic_inverse(i, f);
        let d = self.sag_d(i, q);
        let sag = if d > 0.0 && f > 0.0 { d / (f * f) } else { 0.0 };
        let c = if self.powertrain {
            self.compliance(i, q)
        } else {
            q / self.k_f[i]
        };
        q + sag - c * s
    }
}
