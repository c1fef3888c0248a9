//! Validation through the model's forward kinematics (eq. 3.3–3.8): for every held-out sample
//! the model predicts the pose x_P from the commanded lengths (kinematic ν, eq. 2.11, or
//! elastostatic ν_el with the identified extensions, eq. 2.42) and the forces f_P, compared with
//! the measured x_M, f_M. Cable-length errors are φ(x_M) − q_θ (eq. 6.6).

use crate::observation::Observation;
use crate::params::CalModel;
use crate::residual::{Kind, Weights};
use cdpr_model::elastostatics::{CableForce, CableLaw};
use cdpr_model::forward::{FkOptions, elastostatic_with_law, least_squares};
use cdpr_model::{Data, Pose, kinematics};
use serde::Serialize;

/// Error statistics over a sample set.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Errors {
    /// Samples evaluated (forward kinematics converged).
    pub n: usize,
    /// Samples whose forward kinematics did not converge (excluded from the statistics).
    pub fk_failures: usize,
    pub pos_mean_mm: f64,
    pub pos_max_mm: f64,
    pub rot_mean_deg: f64,
    pub rot_max_deg: f64,
    pub len_mean_mm: f64,
    pub len_max_mm: f64,
    /// Mean and max over samples of ‖f_P − f_M‖₂, N (elastostatic models with forces).
    pub force_mean_n: Option<f64>,
    pub force_max_n: Option<f64>,
    /// Per sample, in the order evaluated: position error (mm) and force error ‖f_P − f_M‖
    /// (N) through the FK, `None` where the FK failed. For paired comparisons of two models
    /// on the same samples ([`paired_gain`]); not part of the report.
    #[serde(skip)]
    pub per_sample: Vec<Option<(f64, Option<f64>)>>,
}

/// The held-out error channel of a paired comparison.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorChannel {
    Position,
    Force,
}

/// Paired comparison of two models on the same samples: the relative reduction of the mean
/// error (1 − after/before) and its z statistic, mean(d)/(sd(d)/√n) over the per-sample
/// reductions d_j = e_before,j − e_after,j (a paired t-test; n ≥ 30 held-out samples make t ≈ z).
/// A reduction that a few samples carry, or that the sample-to-sample spread swamps, has a small
/// z even when its relative size is large. `None` when fewer than 3 samples pair up.
pub fn paired_gain(before: &Errors, after: &Errors, channel: ErrorChannel) -> Option<(f64, f64)> {
    let pick = |v: &Option<(f64, Option<f64>)>| match channel {
        ErrorChannel::Position => v.map(|(p, _)| p),
        ErrorChannel::Force => v.and_then(|(_, f)| f),
    };
    let pairs: Vec<(f64, f64)> = before
        .per_sample
        .iter()
        .zip(&after.per_sample)
        .filter_map(|(b, a)| Some((pick(b)?, pick(a)?)))
        .collect();
    let n = pairs.len();
    if n < 3 {
        return None;
    }
    let mean_b = pairs.iter().map(|p| p.0).sum::<f64>() / n as f64;
    let mean_a = pairs.iter().map(|p| p.1).sum::<f64>() / n as f64;
    if mean_b <= 0.0 {
        return None;
    }
    let d: Vec<f64> = pairs.iter().map(|(b, a)| b - a).collect();
    let md = d.iter().sum::<f64>() / n as f64;
    let var = d.iter().map(|x| (x - md).powi(2)).sum::<f64>() / (n - 1) as f64;
    let se = (var / n as f64).sqrt();
    let z = if se > 0.0 {
        md / se
    } else if md == 0.0 {
        0.0
    } else {
        md.signum() * f64::INFINITY
    };
    Some((1.0 - mean_a / mean_b, z))
}

impl Errors {
    /// True when the forward kinematics failed on any evaluated sample (or there was none):
    /// the statistics then describe a subset and the model is not validated.
    pub fn failed(&self) -> bool {
        self.fk_failures > 0 || self.n == 0
    }

    /// Total samples evaluated (converged + failed).
    pub fn total(&self) -> usize {
        self.n + self.fk_failures
    }

    /// "FK failed on k/n" when [`Errors::failed`], for the error columns of a failed step.
    pub fn failure_text(&self) -> Option<String> {
        self.failed()
            .then(|| format!("FK failed on {}/{}", self.fk_failures, self.total()))
    }
}

/// The extended cable law of a [`CalModel`] (see [`crate::residual`]) for ν_el: the inverse
/// q_θ = q + S/f² − (q + l)/k_F (g(f) − d H) is solved for f per cable.
#[derive(Clone, Debug)]
pub struct ExtendedLaw {
    pub k_f: Vec<f64>,
    pub extra: Vec<f64>,
    /// Drive-train series compliance c_s (m/N).
    pub series: f64,
    pub kappa: f64,
    pub hysteresis: f64,
    pub sag_w2: f64,
    /// cos² of the chord inclination, frozen per solve.
    pub cos2: Vec<f64>,
    /// Direction of motion per cable (hysteresis), ±1 or 0.
    pub direction: Vec<f64>,
    /// Flexible per-cable length correction β_ik ([`crate::params::ParamId::Flex`]).
    pub flex: Vec<[f64; crate::params::FLEX_TERMS]>,
}

impl ExtendedLaw {
    pub fn new(cal: &CalModel, direction: &[f64]) -> Self {
        Self {
            k_f: cal.k_f.clone(),
            extra: cal.extra_length.clone(),
            series: cal.series_compliance,
            kappa: cal.stiffness_kappa,
            hysteresis: cal.hysteresis,
            sag_w2: cal.sag_w2,
            cos2: vec![0.0; cal.m()],
            direction: direction.to_vec(),
            flex: cal.flex.clone(),
        }
    }

    /// The flexible correction of cable i and its derivatives by f and q.
    fn flex(&self, i: usize, q: f64, f: f64) -> (f64, f64, f64) {
        crate::params::flex_eval(&self.flex[i], f, q)
    }

    fn parts(&self, i: usize, q: f64, f: f64) -> (f64, f64, f64) {
        let (g, dg, _) = crate::params::stiffness_load(self.kappa, f);
        let s = self.sag_w2 * self.cos2[i] * q.powi(3) / 24.0;
        (g - self.direction[i] * self.hysteresis, dg, s)
    }
}

impl CableLaw for ExtendedLaw {
    fn force(&self, i: usize, q: f64, q_theta: f64) -> CableForce {
        let c = (q + self.extra[i]) / self.k_f[i] + self.series;
        let dh = self.direction[i] * self.hysteresis;
        let lin = (q - q_theta) / c + dh;
        if self.kappa == 0.0
            && (self.sag_w2 == 0.0 || self.cos2[i] == 0.0)
            && self.flex[i] == [0.0; crate::params::FLEX_TERMS]
        {
            return CableForce {
                f: lin,
                df_dq: (1.0 - (lin - dh) / self.k_f[i]) / c,
                df_dqt: -1.0 / c,
            };
        }
        // Safeguarded Newton on h(f) = φ(f) − q_θ, decreasing in f on the physical branch.
        let h = |f: f64| {
            let (load, dg, s) = self.parts(i, q, f);
            let sag = if s > 0.0 { s / (f * f) } else { 0.0 };
            let dsag = if s > 0.0 { -2.0 * s / (f * f * f) } else { 0.0 };
            let (fl, dfl, _) = self.flex(i, q, f);
            (q + sag - c * load + fl - q_theta, dsag - c * dg + dfl)
        };
        let sagging = self.sag_w2 > 0.0 && self.cos2[i] > 0.0;
        // The flexible correction is a polynomial in f: far outside the operating forces its
        // u² term would dominate and h would not be monotone. Its bracket is the physical one,
        // a taut cable below 100 kN (a root outside it is an FK failure, reported as such).
        let flexed = self.flex[i] != [0.0; crate::params::FLEX_TERMS];
        let (mut lo, mut hi): (f64, f64) = if sagging {
            (1e-9, 1e8)
        } else if flexed {
            (0.0, 1e5)
        } else {
            (-1e8, 1e8)
        };
        let mut f = if sagging {
            lin.max(1.0)
        } else if flexed {
            lin.clamp(1.0, 0.99e5)
        } else {
            lin
        };
        if !(f > lo && f < hi) {
            f = 0.5 * (lo.max(-1e5) + hi.min(1e5));
        }
        for _ in 0..100 {
            let (v, dv) = h(f);
            // An exact root: Newton's next point is this one, which the bracket update below
            // would have made its own end (and bisection would have walked away from it).
            if v == 0.0 {
                break;
            }
            if v > 0.0 {
                lo = f;
            } else {
                hi = f;
            }
            let mut next = f - v / dv;
            if !(next > lo && next < hi && next.is_finite()) {
                next = if sagging && lo > 0.0 {
                    (lo * hi).sqrt()
                } else {
                    0.5 * (lo + hi)
                };
            }
            let done = (next - f).abs() <= 1e-13 * (1.0 + f.abs());
            f = next;
            if done {
                break;
            }
        }
        let (load, dg, s) = self.parts(i, q, f);
        let (_, dfl_df, dfl_dq) = self.flex(i, q, f);
        let dphi_df = if sagging { -2.0 * s / (f * f * f) } else { 0.0 } - c * dg + dfl_df;
        let dphi_dq =
            1.0 + if sagging { 3.0 * s / (q * f * f) } else { 0.0 } - load / self.k_f[i] + dfl_dq;
        CableForce {
            f,
            df_dq: -dphi_dq / dphi_df,
            df_dqt: 1.0 / dphi_df,
        }
    }

    fn controlled_length(&self, i: usize, q: f64, f: f64) -> f64 {
        let c = (q + self.extra[i]) / self.k_f[i] + self.series;
        let (load, _, s) = self.parts(i, q, f);
        let sag = if s > 0.0 && f > 0.0 { s / (f * f) } else { 0.0 };
        q + sag - c * load + self.flex(i, q, f).0
    }
}

/// A forward-kinematics prediction for one sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    pub pose: Pose,
    pub forces: Option<Vec<f64>>,
}

/// Why a sample's pose could not be predicted.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PredictError {
    #[error("invalid model: {0}")]
    Model(#[from] cdpr_model::ModelError),
    #[error(transparent)]
    Kinematics(#[from] cdpr_model::kinematics::KinematicsError),
    #[error(transparent)]
    Forward(#[from] cdpr_model::forward::FkError),
    /// The pose-dependent load / sag fixed point did not settle in its iterations.
    #[error("pose-dependent load/sag iteration did not settle")]
    LoadIteration,
}

/// Predicts the pose (and forces) of sample `o` from its command with the model.
pub fn predict(kind: Kind, cal: &CalModel, o: &Observation) -> Result<Prediction, PredictError> {
    let model = cal.model()?;
    let mut data = Data::new(&model);
    let m = cal.m();
    let q_theta: Vec<f64> = (0..m)
        .map(|i| match kind {
            Kind::Elastostatic => cal.q_theta_of(i, o),
            _ => cal.q_theta(i, o.q_cmd[i]),
        })
        .collect();
    let guess = o.pose_ref.unwrap_or(o.pose);
    let opts = FkOptions {
        max_iterations: 200,
        ..FkOptions::default()
    };
    match kind {
        // A model fitted on the Cartesian residual is a kinematic model.
        Kind::Kinematic | Kind::Cartesian => {
            let sol = least_squares(&model, &mut data, &q_theta, &guess, &opts)?;
            Ok(Prediction {
                pose: sol.pose,
                forces: None,
            })
        }
        Kind::Elastostatic => {
            let loading: Vec<f64> = (0..m)
                .map(|i| o.loading(cal.hysteresis_source, i))
                .collect();
            let mut law = ExtendedLaw::new(cal, &loading);
            let dependent = cal.sag_w2 != 0.0 || cal.cog != nalgebra::Vector3::zeros();
            let mut x = guess;
            for _ in 0..30 {
                kinematics::inverse(&model, &mut data, &x)?;
                for i in 0..m {
                    law.cos2[i] = (1.0 - data.u[i].z * data.u[i].z).max(0.0);
                }
                let w = cal.wrench_at(&x.rotation());
                let sol = elastostatic_with_law(&model, &mut data, &law, &w, &q_theta, &x, &opts)?;
                let dx = (sol.pose.to_vector() - x.to_vector()).amax();
                x = sol.pose;
                if !dependent || dx < 1e-11 {
                    return Ok(Prediction {
                        pose: x,
                        forces: Some(data.f.clone()),
                    });
                }
            }
            Err(PredictError::LoadIteration)
        }
    }
}

/// Error statistics of the model on `obs` (eq. 3.3–3.4, 6.6).
pub fn evaluate(kind: Kind, cal: &CalModel, obs: &[Observation]) -> Errors {
    let mut e = Errors::default();
    let (mut sp, mut sr, mut sf, mut nf) = (0.0, 0.0, 0.0, 0usize);
    let mut fmax = 0.0f64;
    for o in obs {
        match predict(kind, cal, o) {
            Ok(p) => {
                let (dp, dr) = p.pose.error_to(&o.pose);
                let mut fe = None;
                sp += dp;
                sr += dr;
                e.pos_max_mm = e.pos_max_mm.max(dp * 1e3);
                e.rot_max_deg = e.rot_max_deg.max(dr.to_degrees());
                e.n += 1;
                if let (Some(fp), Some(fm)) = (&p.forces, &o.forces) {
                    let d: f64 = fp
                        .iter()
                        .zip(fm)
                        .map(|(a, b)| (a - b).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    sf += d;
                    fmax = fmax.max(d);
                    nf += 1;
                    fe = Some(d);
                }
                e.per_sample.push(Some((dp * 1e3, fe)));
            }
            Err(_) => {
                e.fk_failures += 1;
                e.per_sample.push(None);
            }
        }
    }
    if e.n > 0 {
        e.pos_mean_mm = sp / e.n as f64 * 1e3;
        e.rot_mean_deg = (sr / e.n as f64).to_degrees();
    }
    if nf > 0 {
        e.force_mean_n = Some(sf / nf as f64);
        e.force_max_n = Some(fmax);
    }
    let lens = length_errors(kind, cal, obs);
    let all: Vec<f64> = lens.iter().flatten().map(|v| v.abs()).collect();
    if !all.is_empty() {
        e.len_mean_mm = all.iter().sum::<f64>() / all.len() as f64 * 1e3;
        e.len_max_mm = all.iter().fold(0.0f64, |a, b| a.max(*b)) * 1e3;
    }
    e
}

/// Cable-length residuals φ(x_M) − q_θ (kinematic) or φ_el(x_M, f_M) − q_θ (elastostatic) per
/// cable: `out[i]` holds cable i's residuals over the samples, m.
pub fn length_errors(kind: Kind, cal: &CalModel, obs: &[Observation]) -> Vec<Vec<f64>> {
    // A model fitted on the Cartesian residual is a kinematic model: its length errors are the
    // joint-space residual's.
    let kind = if kind == Kind::Cartesian {
        Kind::Kinematic
    } else {
        kind
    };
    let m = cal.m();
    let mut out = vec![Vec::new(); m];
    let w = Weights {
        wrench: 1.0,
        length: 1.0,
    };
    for o in obs {
        let Ok(r) = crate::identify::residual(kind, cal, std::slice::from_ref(o), w) else {
            continue;
        };
        let off = r.len() - m;
        for i in 0..m {
            out[i].push(r[off + i]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_extended_law_with_a_flexible_correction_inverts_its_controlled_length() {
        let mut cal_law = ExtendedLaw {
            k_f: vec![2e6],
            extra: vec![0.0],
            series: 0.0,
            kappa: 0.0,
            hysteresis: 0.0,
            sag_w2: 0.0,
            cos2: vec![0.0],
            direction: vec![0.0],
            flex: vec![[0.002, -0.003, 0.001, 0.0015]],
        };
        for &(q, f) in &[(4.0, 800.0), (8.0, 5000.0), (12.0, 11000.0)] {
            let qt = cal_law.controlled_length(0, q, f);
            let cf = cal_law.force(0, q, qt);
            assert!((cf.f - f).abs() < 1e-6, "q {q}: f {f} → {}", cf.f);
            // df/dq_θ against a central difference.
            let h = 1e-7;
            let num = (cal_law.force(0, q, qt + h).f - cal_law.force(0, q, qt - h).f) / (2.0 * h);
            assert!(
                (cf.df_dqt / num - 1.0).abs() < 1e-5,
                "{} vs {num}",
                cf.df_dqt
            );
        }
        cal_law.flex = vec![[0.0; crate::params::FLEX_TERMS]];
        let qt = cal_law.controlled_length(0, 8.0, 5000.0);
        assert!((cal_law.force(0, 8.0, qt).f - 5000.0).abs() < 1e-6);
    }

    /// The tension-dependent stiffness's law inverts its controlled length over the whole
    /// force range for every κ of its range, with the exact-root case (Newton lands on the
    /// root: the bisection must not walk away from it, which made every FK fail) and beyond
    /// the parabola's usable branch (its tangent continuation).
    #[test]
    fn the_stiffness_law_inverts_its_controlled_length_for_every_kappa() {
        for kappa in [-0.9, -0.5, -0.17, 0.0, 0.06, 0.1, 0.19, 0.5, 0.9] {
            let law = ExtendedLaw {
                k_f: vec![2e6],
                extra: vec![5.0],
                series: 1e-6,
                kappa,
                hysteresis: 0.0,
                sag_w2: 0.0,
                cos2: vec![0.0],
                direction: vec![0.0],
                flex: vec![[0.0; crate::params::FLEX_TERMS]],
            };
            for f in [200.0, 1000.0, 2500.0, 5000.0, 9000.0, 14000.0, 40000.0] {
                let q = 8.0;
                let qt = law.controlled_length(0, q, f);
                let cf = law.force(0, q, qt);
                assert!(
                    (cf.f - f).abs() < 1e-6 * f,
                    "kappa {kappa}, f {f}: got {}",
                    cf.f
                );
                assert!(cf.df_dqt < 0.0, "kappa {kappa}, f {f}");
            }
        }
    }

    fn errors(pos: &[f64], force: &[f64]) -> Errors {
        Errors {
            per_sample: pos
                .iter()
                .zip(force)
                .map(|(p, f)| Some((*p, Some(*f))))
                .collect(),
            ..Errors::default()
        }
    }

    #[test]
    fn paired_gain_is_the_relative_reduction_and_the_paired_t_statistic() {
        // d = before − after = [1, 2, 3, 2]: mean 2, sd √(2/3), se √(2/3)/2 → z = 2/(√(2/3)/2).
        let before = errors(&[4.0, 5.0, 6.0, 5.0], &[100.0, 100.0, 100.0, 100.0]);
        let after = errors(&[3.0, 3.0, 3.0, 3.0], &[100.0, 110.0, 90.0, 100.0]);
        let (g, z) = paired_gain(&before, &after, ErrorChannel::Position).unwrap();
        assert!((g - 0.4).abs() < 1e-12, "{g}");
        let z_ref = 2.0 / ((2.0f64 / 3.0).sqrt() / 2.0);
        assert!((z - z_ref).abs() < 1e-12, "{z} vs {z_ref}");
        // Force: the mean does not move, the spread is large: gain 0, z 0.
        let (g, z) = paired_gain(&before, &after, ErrorChannel::Force).unwrap();
        assert!(g.abs() < 1e-12 && z.abs() < 1e-12, "{g} {z}");
    }

    #[test]
    fn a_sample_whose_fk_failed_in_either_model_is_left_out_of_the_pairs() {
        let mut before = errors(&[4.0, 5.0, 6.0, 5.0], &[1.0; 4]);
        let after = errors(&[3.0, 3.0, 3.0, 100.0], &[1.0; 4]);
        before.per_sample[3] = None;
        let (g, _) = paired_gain(&before, &after, ErrorChannel::Position).unwrap();
        assert!((g - 0.4).abs() < 1e-12, "{g}");
        before.per_sample[2] = None;
        before.per_sample[1] = None;
        assert!(paired_gain(&before, &after, ErrorChannel::Position).is_none());
    }
}
