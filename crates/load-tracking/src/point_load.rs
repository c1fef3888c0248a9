//! A moving point load on the platform (a subject walking on the cabin floor) from the change
//! of the platform wrench against the unloaded state (eq. 5.9–5.10).
//!
//! With the platform level, a load of mass m_s at horizontal offset p = (p_x, p_y) from the
//! platform origin adds F = (0, 0, −m_s g) and τ = p × F, so τ_x = −m_s g p_y and
//! τ_y = m_s g p_x: the xy torque of eq. 5.9, with the unloaded state's torque as its zero
//! (eq. 5.10). The height of the load does not enter (and cannot be seen); tilting the
//! platform mixes it in, which is why the seed records at zero pitch and roll.

use crate::{G, wrench_from_forces};
use cdpr_model::kinematics::KinematicsError;
use cdpr_model::{Data, Model, Pose};
use nalgebra::{Matrix2x3, Matrix3, Vector6};

/// The unloaded state: the platform wrench before the subject steps on (eq. 5.10), at the pose
/// the controller holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Baseline {
    pub pose: Pose,
    pub wrench: Vector6<f64>,
}

/// One estimate of the point load.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct PointLoad {
    pub mass_kg: f64,
    /// Horizontal offset from the platform origin (world axes), m.
    pub x_m: f64,
    pub y_m: f64,
    /// 1σ of x and y from the force-sensor noise through A^T (eq. 5.9); 0 when no noise given.
    pub x_std_m: f64,
    pub y_std_m: f64,
}

/// Why no estimate exists for a sample.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PointLoadError {
    #[error(transparent)]
    Kinematics(#[from] KinematicsError),
    /// The added weight is below what the torque can be divided by: nobody on the platform.
    #[error("added weight {0:.1} N is below the detection threshold")]
    NoLoad(f64),
}

/// The baseline at `pose` from the forces before the load steps on.
pub fn baseline(
    model: &Model,
    data: &mut Data,
    pose: &Pose,
    f: &[f64],
) -> Result<Baseline, KinematicsError> {
    Ok(Baseline {
        pose: *pose,
        wrench: wrench_from_forces(model, data, pose, f)?,
    })
}

/// Estimates the point load from forces `f` measured while the controller holds
/// `baseline.pose` (the model's A^T at that pose, not the platform's true pose: the controller
/// does not know it). `sigma_f` is the force sensors' noise (N, 1σ) for the uncertainty;
/// `min_weight_n` the smallest added weight that counts as a load.
pub fn estimate(
    model: &Model,
    data: &mut Data,
    base: &Baseline,
    f: &[f64],
    sigma_f: f64,
    min_weight_n: f64,
) -> Result<PointLoad, PointLoadError> {
    let w = crate::wrench_from_forces(model, data, &base.pose, f)?;
    let dw = w - base.wrench;
    let fz = dw[2];
    if -fz < min_weight_n {
        return Err(PointLoadError::NoLoad(-fz));
    }
    // τ_x = p_y F_z, τ_y = −p_x F_z (F_z = −m g < 0).
    let x = -dw[4] / fz;
    let y = dw[3] / fz;
    // Uncertainty: Δw = −A^T Δf, Cov(Δw) = σ_f² A^T A for one reading minus a noiseless
    // baseline (a baseline averaged over many readings has negligible noise). Jacobian of
    // (x, y) with respect to (F_z, τ_x, τ_y).
    let mut cov = Matrix3::zeros();
    for a in &data.at {
        let v = nalgebra::Vector3::new(a[2], a[3], a[4]);
        cov += v * v.transpose() * sigma_f * sigma_f;
    }
    let jac = Matrix2x3::new(
        dw[4] / (fz * fz),
        0.0,
        -1.0 / fz,
        -dw[3] / (fz * fz),
        1.0 / fz,
        0.0,
    );
    let c = jac * cov * jac.transpose();
    Ok(PointLoad {
        mass_kg: -fz / G,
        x_m: x,
        y_m: y,
        x_std_m: c[(0, 0)].max(0.0).sqrt(),
        y_std_m: c[(1, 1)].max(0.0).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdpr_model::config::load_platform;
    use cdpr_model::{kinematics, statics};
    use nalgebra::Vector3;

    /// Forces that carry the platform's own load plus a subject at a known spot give back the
    /// subject's mass and position; no subject is "no load", not a position.
    #[test]
    fn a_subject_is_found_where_it_stands() {
        let p = load_platform(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../config/icosahedron.toml"
        ))
        .unwrap();
        let model = &p.model;
        let mut data = Data::new(model);
        let pose = p.home;
        kinematics::inverse(model, &mut data, &pose).unwrap();
        let w0 = model.params().w_e;
        let mut f0 = vec![0.0; model.m()];
        statics::force_distribution(&data, &w0, 1000.0, 9000.0, &mut f0).unwrap();
        let base = baseline(model, &mut data, &pose, &f0).unwrap();
        let e = estimate(model, &mut data, &base, &f0, 10.0, 50.0).unwrap_err();
        assert!(matches!(e, PointLoadError::NoLoad(_)), "{e}");
        let (m_s, at) = (80.0, Vector3::new(0.6, -0.4, -0.7));
        let fs = Vector3::new(0.0, 0.0, -m_s * G);
        let tau = at.cross(&fs);
        let w = w0 + Vector6::new(fs.x, fs.y, fs.z, tau.x, tau.y, tau.z);
        let mut f = vec![0.0; model.m()];
        kinematics::inverse(model, &mut data, &pose).unwrap();
        statics::force_distribution(&data, &w, 1000.0, 9000.0, &mut f).unwrap();
        let est = estimate(model, &mut data, &base, &f, 10.0, 50.0).unwrap();
        assert!((est.mass_kg - m_s).abs() < 1e-6, "{est:?}");
        assert!((est.x_m - at.x).abs() < 1e-9 && (est.y_m - at.y).abs() < 1e-9);
        // 10 N sensor noise on eight cables: centimetres, not millimetres or metres.
        assert!(est.x_std_m > 0.005 && est.x_std_m < 0.5, "{est:?}");
    }
}
