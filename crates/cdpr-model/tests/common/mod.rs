#![allow(dead_code)]
use cdpr_model::config::{Platform, load_platform};
use cdpr_model::{Model, Pose};
use nalgebra::{DMatrix, Vector3};

pub fn config_path(name: &str) -> String {
    format!("{}/../../config/{name}", env!("CARGO_MANIFEST_DIR"))
}

pub fn platform(name: &str) -> Platform {
    load_platform(config_path(name)).unwrap_or_else(|e| panic!("{e}"))
}

pub fn icosahedron() -> Model {
    platform("icosahedron.toml").model
}

pub fn pulley_model() -> Model {
    platform("icosahedron-pulleys.toml").model
}

/// A few wrench-feasible poses (eq. 3.29) inside the operating region with non-trivial rotation.
pub fn test_poses() -> Vec<Pose> {
    vec![
        Pose::new(Vector3::new(0.0, 0.0, 2.0), Vector3::zeros()),
        Pose::new(
            Vector3::new(0.4, -0.3, 1.8),
            Vector3::new(0.05, -0.04, 0.08),
        ),
        Pose::new(
            Vector3::new(-0.4, 0.5, 1.9),
            Vector3::new(0.02, -0.015, 0.025),
        ),
        Pose::new(Vector3::new(0.9, 0.8, 1.6), Vector3::new(0.025, 0.02, 0.03)),
    ]
}

/// Central finite differences of a vector function of the pose coordinates (δr, δφ).
pub fn fd_pose(pose: &Pose, h: f64, mut f: impl FnMut(&Pose) -> Vec<f64>) -> DMatrix<f64> {
    let n = f(pose).len();
    let mut j = DMatrix::zeros(n, 6);
    for k in 0..6 {
        let mut xp = pose.to_array();
        let mut xm = pose.to_array();
        xp[k] += h;
        xm[k] -= h;
        let fp = f(&Pose::from_array(xp));
        let fm = f(&Pose::from_array(xm));
        for r in 0..n {
            j[(r, k)] = (fp[r] - fm[r]) / (2.0 * h);
        }
    }
    j
}

/// max |a − b| / max(1, max |b|): relative agreement of two Jacobians.
pub fn rel_diff(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).amax() / b.amax().max(1.0)
}
