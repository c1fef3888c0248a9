//! What the rider perceives: linear vestibular models of the otoliths (specific force) and the
//! semicircular canals (angular velocity), one per head axis, and the perception error of the
//! cabin's motion against the vehicle's.
//!
//! Otolith (Young & Meiry 1968; time constants as revised by Telban & Cardullo 2005, NASA
//! CR-2005-213747):
//!
//!   f̂/f (s) = K_oto (τ_a s + 1) / ((τ_L s + 1)(τ_S s + 1)),   τ_a = 10 s, τ_L = 5 s, τ_S = 0.016 s.
//!
//! Semicircular canals (Fernandez & Goldberg 1971, Zacharias 1978; with the adaptation term
//! and lead as in Telban & Cardullo 2005):
//!
//!   ω̂/ω (s) = K_scc τ_a τ_L s² (τ_lead s + 1) / ((τ_a s + 1)(τ_L s + 1)(τ_S s + 1)),
//!   τ_a = 80 s, τ_L = 5.73 s, τ_S = 0.005 s, τ_lead = 0.06 s.
//!
//! The gains are normalised here (K_oto = 1: static gain 1, so a perceived specific force is in
//! m/s²; K_scc = 1: mid-band gain 1, rad/s): the literature's gains scale afferent firing rates,
//! which the comparison of vehicle and cabin does not need (both go through the same model).
//! Perception thresholds (used for the share of time an error would be noticed): specific force
//! 0.17 m/s² (Telban & Cardullo 2005), angular velocity 3°/s (the tilt-rate threshold of
//! Groen & Bles 2004 and Nesti et al. 2012, also used to bound the tilt coordination).

use crate::lti::{Lti, LtiError};
use nalgebra::{SVector, Vector3};

/// Parameters of both models (SI: s, m/s², rad/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VestibularParams {
    pub otolith_tau_a_s: f64,
    pub otolith_tau_l_s: f64,
    pub otolith_tau_s_s: f64,
    pub canal_tau_a_s: f64,
    pub canal_tau_l_s: f64,
    pub canal_tau_s_s: f64,
    pub canal_tau_lead_s: f64,
    /// Perception thresholds: specific force (m/s²) and angular velocity (rad/s).
    pub threshold_specific_force: f64,
    pub threshold_angular_velocity: f64,
}

impl Default for VestibularParams {
    /// The literature values of the module docs.
    fn default() -> Self {
        Self {
            otolith_tau_a_s: 10.0,
            otolith_tau_l_s: 5.0,
            otolith_tau_s_s: 0.016,
            canal_tau_a_s: 80.0,
            canal_tau_l_s: 5.73,
            canal_tau_s_s: 0.005,
            canal_tau_lead_s: 0.06,
            threshold_specific_force: 0.17,
            threshold_angular_velocity: 3f64.to_radians(),
        }
    }
}

/// The two models discretised for one sample period.
#[derive(Clone, Debug, PartialEq)]
pub struct Vestibular {
    pub params: VestibularParams,
    pub otolith: Lti<2>,
    pub canal: Lti<3>,
}

impl Vestibular {
    pub fn new(p: VestibularParams, dt: f64) -> Result<Self, LtiError> {
        let otolith = Lti::<2>::from_tf(
            &[p.otolith_tau_a_s, 1.0],
            &[
                p.otolith_tau_l_s * p.otolith_tau_s_s,
                p.otolith_tau_l_s + p.otolith_tau_s_s,
                1.0,
            ],
            dt,
        )?;
        // (τ_a s + 1)(τ_L s + 1)(τ_S s + 1) expanded.
        let (ta, tl, ts) = (p.canal_tau_a_s, p.canal_tau_l_s, p.canal_tau_s_s);
        let den = [ta * tl * ts, ta * tl + ta * ts + tl * ts, ta + tl + ts, 1.0];
        let k = ta * tl;
        let canal = Lti::<3>::from_tf(&[k * p.canal_tau_lead_s, k, 0.0, 0.0], &den, dt)?;
        Ok(Self {
            params: p,
            otolith,
            canal,
        })
    }

    /// A perceiver at rest in gravity: otoliths settled on `f0` (e.g. [0, 0, g]), canals at 0.
    pub fn perceiver(&self, f0: &Vector3<f64>) -> Perceiver {
        let mut oto = [SVector::<f64, 2>::zeros(); 3];
        if let Some(z) = self.otolith.steady_state(1.0) {
            for k in 0..3 {
                oto[k] = z * f0[k];
            }
        }
        Perceiver {
            oto,
            canal: [SVector::zeros(); 3],
        }
    }

    /// One sample: perceived specific force and angular velocity for the head's specific force
    /// `f` (m/s²) and angular velocity `w` (rad/s), both in head (cabin / vehicle body) axes.
    #[inline]
    pub fn step(
        &self,
        s: &mut Perceiver,
        f: &Vector3<f64>,
        w: &Vector3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let mut fp = Vector3::zeros();
        let mut wp = Vector3::zeros();
        for k in 0..3 {
            fp[k] = self.otolith.step(&mut s.oto[k], f[k]);
            wp[k] = self.canal.step(&mut s.canal[k], w[k]);
        }
        (fp, wp)
    }
}

/// The models' state for one rider (Data).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Perceiver {
    oto: [SVector<f64, 2>; 3],
    canal: [SVector<f64, 3>; 3],
}

/// Per-axis comparison of one signal (cabin) against a reference (vehicle).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct AxisError {
    /// RMS of the reference and of the signal about their means.
    pub rms_reference: f64,
    pub rms_signal: f64,
    /// RMS of (signal − reference).
    pub rms_error: f64,
    /// Pearson correlation of signal and reference; None when either does not vary (its
    /// standard deviation below 1e-9 of the unit): a correlation is then undefined.
    pub correlation: Option<f64>,
    /// Share of the samples where |signal − reference| exceeds the perception threshold.
    pub above_threshold: f64,
}

/// RMS error, correlation and the share above `threshold` of `signal` against `reference`.
pub fn axis_error(reference: &[f64], signal: &[f64], threshold: f64) -> AxisError {
    let n = reference.len().min(signal.len());
    if n == 0 {
        return AxisError {
            correlation: None,
            ..AxisError::default()
        };
    }
    let nf = n as f64;
    let mr = reference[..n].iter().sum::<f64>() / nf;
    let ms = signal[..n].iter().sum::<f64>() / nf;
    let (mut srr, mut sss, mut srs, mut see, mut above) = (0.0, 0.0, 0.0, 0.0, 0usize);
    for (r, s) in reference[..n].iter().zip(&signal[..n]) {
        let (dr, ds) = (r - mr, s - ms);
        srr += dr * dr;
        sss += ds * ds;
        srs += dr * ds;
        see += (s - r) * (s - r);
        if (s - r).abs() > threshold {
            above += 1;
        }
    }
    let (sr, ss) = ((srr / nf).sqrt(), (sss / nf).sqrt());
    AxisError {
        rms_reference: sr,
        rms_signal: ss,
        rms_error: (see / nf).sqrt(),
        correlation: (sr > 1e-9 && ss > 1e-9).then(|| srs / (srr * sss).sqrt()),
        above_threshold: above as f64 / nf,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn otolith_reads_a_sustained_force_and_canals_wash_out_a_sustained_rate() {
        let v = Vestibular::new(VestibularParams::default(), 1e-3).unwrap();
        assert!((v.otolith.dc_gain().unwrap() - 1.0).abs() < 1e-12);
        assert!(v.canal.dc_gain().unwrap().abs() < 1e-12);
        let g = Vector3::new(0.0, 0.0, 9.81);
        let mut s = v.perceiver(&g);
        // At rest the perceived specific force is gravity from the first sample on.
        let (fp, _) = v.step(&mut s, &g, &Vector3::zeros());
        assert!((fp - g).norm() < 1e-9, "{fp}");
        // 10°/s in yaw, reached over 0.5 s: perceived (mid-band gain 1, plus the lead's τ_lead ω̇ while it ramps), then it decays
        // with τ_L ≈ 5.73 s (and adapts).
        let w_end = Vector3::new(0.0, 0.0, 10f64.to_radians());
        let mut peak: f64 = 0.0;
        let mut at_20s = 0.0;
        for k in 0..20_000 {
            let w = w_end * (k as f64 / 500.0).min(1.0);
            let (_, wp) = v.step(&mut s, &g, &w);
            peak = peak.max(wp.z);
            if k == 19_999 {
                at_20s = wp.z;
            }
        }
        assert!(peak > 0.85 * w_end.z && peak < 1.1 * w_end.z, "{peak}");
        assert!(at_20s < 0.1 * w_end.z, "{at_20s}");
    }

    #[test]
    fn axis_error_of_a_copy_and_of_a_constant() {
        let r: Vec<f64> = (0..100).map(|k| (k as f64 * 0.1).sin()).collect();
        let e = axis_error(&r, &r, 0.1);
        assert_eq!(e.rms_error, 0.0);
        assert!((e.correlation.unwrap() - 1.0).abs() < 1e-12);
        let half: Vec<f64> = r.iter().map(|v| 0.5 * v).collect();
        let e = axis_error(&r, &half, 0.1);
        assert!((e.correlation.unwrap() - 1.0).abs() < 1e-12);
        assert!((e.rms_error - 0.5 * e.rms_reference).abs() < 0.05);
        assert_eq!(axis_error(&r, &vec![1.0; 100], 0.1).correlation, None);
    }
}
