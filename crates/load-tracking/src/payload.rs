//! Mass and centre of gravity of the cabin load from cable forces at rest (eq. 6.22–6.23).
//!
//! A load of mass m whose centre of gravity sits at c in the platform frame exerts, at pose
//! x = (r, R), the wrench w_e = [F; (R c) × F] with F = (0, 0, −m g). Each rest sample gives
//! w_e = −A^T(x) f (eq. 2.31); the rows F_z = −g m, τ_x = −g (R m c)_y and τ_y = g (R m c)_x
//! are linear in θ = (m, m c). Least squares over all samples gives θ and, from the residual
//! variance, its covariance. The COG height c_z moves the torque only when the platform is
//! tilted: from level poses alone it is not observable, and the fit says so instead of
//! printing a number.

use crate::{G, wrench_from_forces};
use cdpr_model::kinematics::KinematicsError;
use cdpr_model::{Data, Model, Pose};
use nalgebra::{DMatrix, DVector, Vector3};

/// One rest sample: the platform's pose (measured or commanded) and the cable forces there.
#[derive(Clone, Debug, PartialEq)]
pub struct RestSample {
    pub pose: Pose,
    pub forces: Vec<f64>,
}

/// The identified payload.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Payload {
    pub mass_kg: f64,
    pub mass_std_kg: f64,
    /// Centre of gravity in the platform frame, m; `None` per axis when not observable from
    /// these poses (c_z needs tilted poses).
    pub cog_m: [Option<f64>; 3],
    pub cog_std_m: [Option<f64>; 3],
    /// RMS of the fit's wrench rows (N, N·m): large values mean the load is not a rigid point
    /// mass or the geometry is off.
    pub residual_rms: f64,
    /// The mean residual force the fit cannot explain (F_x, F_y rows), N: cable friction, cable
    /// weight or a wrong geometry show here (eq. 6.23's 22 N / −163 N).
    pub lateral_force_n: [f64; 2],
    pub samples: usize,
}

/// Why a payload could not be identified.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PayloadError {
    #[error("no rest samples")]
    NoSamples,
    #[error("sample {sample}: {err}")]
    Kinematics { sample: usize, err: KinematicsError },
    #[error("sample {sample}: {got} forces for {m} cables")]
    ForceCount { sample: usize, got: usize, m: usize },
    #[error("the mass is not observable from these samples")]
    Unobservable,
}

/// Columns of θ = (m, m c_x, m c_y, m c_z) whose singular value is below this fraction of the
/// largest count as not observable.
const OBSERVABLE: f64 = 1e-6;

/// Fits mass and COG to `samples` with the model's geometry (eq. 6.23 over several poses).
pub fn identify(
    model: &Model,
    data: &mut Data,
    samples: &[RestSample],
) -> Result<Payload, PayloadError> {
    if samples.is_empty() {
        return Err(PayloadError::NoSamples);
    }
    let n = samples.len();
    let mut j = DMatrix::<f64>::zeros(3 * n, 4);
    let mut y = DVector::<f64>::zeros(3 * n);
    let mut lateral = [0.0; 2];
    for (k, s) in samples.iter().enumerate() {
        if s.forces.len() != model.m() {
            return Err(PayloadError::ForceCount {
                sample: k,
                got: s.forces.len(),
                m: model.m(),
            });
        }
        let w = wrench_from_forces(model, data, &s.pose, &s.forces)
            .map_err(|err| PayloadError::Kinematics { sample: k, err })?;
        let r = s.pose.rotation();
        // F_z = −g m
        j[(3 * k, 0)] = -G;
        y[3 * k] = w[2];
        // τ_x = −g (R mc)_y, τ_y = g (R mc)_x
        for c in 0..3 {
            j[(3 * k + 1, 1 + c)] = -G * r[(1, c)];
            j[(3 * k + 2, 1 + c)] = G * r[(0, c)];
        }
        y[3 * k + 1] = w[3];
        y[3 * k + 2] = w[4];
        lateral[0] += w[0] / n as f64;
        lateral[1] += w[1] / n as f64;
    }
    // Column scaling: the mass column is g, the moment columns g as well, but keep it general.
    let scale: Vec<f64> = (0..4)
        .map(|c| j.column(c).norm().max(f64::MIN_POSITIVE))
        .collect();
    let mut js = j.clone();
    for (c, s) in scale.iter().enumerate() {
        js.column_mut(c).scale_mut(1.0 / s);
    }
    let svd = js.clone().svd(true, true);
    let s_max = svd.singular_values.max();
    // Which parameters are observable: a column whose direction lies in the numerical null
    // space (a right singular vector with tiny singular value has weight there) is not.
    let v_t = svd.v_t.as_ref().expect("V^T requested");
    let mut observable = [true; 4];
    for (i, sv) in svd.singular_values.iter().enumerate() {
        if *sv <= OBSERVABLE * s_max {
            for (c, o) in observable.iter_mut().enumerate() {
                if v_t[(i, c)].abs() > 0.1 {
                    *o = false;
                }
            }
        }
    }
    if !observable[0] {
        return Err(PayloadError::Unobservable);
    }
    // Solve on the observable columns only.
    let cols: Vec<usize> = (0..4).filter(|c| observable[*c]).collect();
    let jo = DMatrix::from_fn(3 * n, cols.len(), |r, c| js[(r, cols[c])]);
    let jtj = jo.transpose() * &jo;
    let inv = jtj
        .clone()
        .try_inverse()
        .ok_or(PayloadError::Unobservable)?;
    let zs = &inv * (jo.transpose() * &y);
    let res = &y - &jo * &zs;
    let dof = (3 * n).saturating_sub(cols.len()).max(1) as f64;
    let sigma2 = res.norm_squared() / dof;
    let mut theta = [None; 4];
    let mut theta_var = [None; 4];
    for (k, c) in cols.iter().enumerate() {
        theta[*c] = Some(zs[k] / scale[*c]);
        theta_var[*c] = Some(sigma2 * inv[(k, k)] / (scale[*c] * scale[*c]));
    }
    let m = theta[0].ok_or(PayloadError::Unobservable)?;
    let var_m = theta_var[0].unwrap_or(0.0);
    let mut cog = [None; 3];
    let mut cog_std = [None; 3];
    for a in 0..3 {
        if let (Some(mc), Some(v)) = (theta[1 + a], theta_var[1 + a]) {
            let c = mc / m;
            cog[a] = Some(c);
            // First-order propagation of c = (mc)/m, treating m and mc as independent (the
            // mass row is separate from the moment rows).
            cog_std[a] = Some(((v + c * c * var_m) / (m * m)).sqrt());
        }
    }
    Ok(Payload {
        mass_kg: m,
        mass_std_kg: var_m.sqrt(),
        cog_m: cog,
        cog_std_m: cog_std,
        residual_rms: (res.norm_squared() / (3 * n) as f64).sqrt(),
        lateral_force_n: lateral,
        samples: n,
    })
}

/// The payload a platform TOML's `[load] wrench_n_nm` describes (at zero rotation): mass
/// m = −F_z / g and the COG's x, y from the torque (c_z cannot be told from a wrench).
pub fn configured(w_e: &nalgebra::Vector6<f64>) -> (f64, Vector3<f64>) {
    let m = -w_e[2] / G;
    if m.abs() < f64::EPSILON {
        return (0.0, Vector3::zeros());
    }
    // τ = c × F with F = (0, 0, −m g): τ_x = −m g c_y, τ_y = m g c_x.
    (m, Vector3::new(w_e[4] / (m * G), -w_e[3] / (m * G), 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdpr_model::config::load_platform;
    use cdpr_model::statics;
    use nalgebra::Vector6;

    fn heli() -> cdpr_model::config::Platform {
        load_platform(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../config/helicopter.toml"
        ))
        .expect("helicopter platform")
    }

    /// Exact forces of a known load at several poses (A^T f = −w_e via the closed form eq.
    /// 3.41) identify exactly that load; with level poses only, c_z is reported unobservable.
    #[test]
    fn a_known_load_is_found_and_cz_needs_tilt() {
        let p = heli();
        let model = &p.model;
        let mut data = Data::new(model);
        let (m_true, c_true) = (700.0, Vector3::new(0.12, -0.08, 0.3));
        let samples = |tilt: bool, data: &mut Data| -> Vec<RestSample> {
            let mut out = Vec::new();
            for (k, (x, y)) in [(0.0, 0.0), (0.3, 0.2), (-0.3, 0.1), (0.2, -0.3)]
                .into_iter()
                .enumerate()
            {
                let phi = if tilt {
                    Vector3::new(0.04 * (k as f64 - 1.5), 0.03 * (1.0 - k as f64), 0.0)
                } else {
                    Vector3::zeros()
                };
                let pose = Pose::new(p.home.r + Vector3::new(x, y, 0.0), phi);
                cdpr_model::kinematics::inverse(model, data, &pose).unwrap();
                let f_vec = Vector3::new(0.0, 0.0, -m_true * G);
                let tau = (pose.rotation() * c_true).cross(&f_vec);
                let w = Vector6::new(f_vec.x, f_vec.y, f_vec.z, tau.x, tau.y, tau.z);
                let mut f = vec![0.0; model.m()];
                statics::force_distribution(data, &w, 1000.0, 9000.0, &mut f).unwrap();
                out.push(RestSample { pose, forces: f });
            }
            out
        };
        let level = samples(false, &mut data);
        let fit = identify(model, &mut data, &level).unwrap();
        assert!((fit.mass_kg - m_true).abs() < 1e-6, "{fit:?}");
        assert!((fit.cog_m[0].unwrap() - c_true.x).abs() < 1e-9);
        assert!((fit.cog_m[1].unwrap() - c_true.y).abs() < 1e-9);
        assert_eq!(fit.cog_m[2], None, "c_z from level poses only: {fit:?}");
        let tilted = samples(true, &mut data);
        let fit = identify(model, &mut data, &tilted).unwrap();
        assert!((fit.cog_m[2].unwrap() - c_true.z).abs() < 1e-6, "{fit:?}");
        assert!(fit.residual_rms < 1e-6);
    }

    #[test]
    fn the_configured_load_round_trips() {
        let w = Vector6::new(0.0, 0.0, -7500.0, 300.0, -600.0, 0.0);
        let (m, c) = configured(&w);
        let f = Vector3::new(0.0, 0.0, -m * G);
        let tau = c.cross(&f);
        assert!((tau.x - 300.0).abs() < 1e-9 && (tau.y + 600.0).abs() < 1e-9);
    }

    #[test]
    fn bad_samples_are_named() {
        let p = heli();
        let mut data = Data::new(&p.model);
        let e = identify(
            &p.model,
            &mut data,
            &[RestSample {
                pose: p.home,
                forces: vec![1.0; 3],
            }],
        )
        .unwrap_err();
        assert_eq!(e.to_string(), "sample 0: 3 forces for 8 cables");
        assert_eq!(
            identify(&p.model, &mut data, &[]).unwrap_err(),
            PayloadError::NoSamples
        );
    }
}
