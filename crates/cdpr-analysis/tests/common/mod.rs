//! The shipped platforms and the test poses the analysis tests share.
#![allow(dead_code)]
use cdpr_model::config::{Platform, load_platform};
use cdpr_model::{Model, Pose};
use nalgebra::Vector3;

pub fn platform(name: &str) -> Platform {
    load_platform(crs_test_support::fixtures::config(name)).unwrap_or_else(|e| panic!("{e}"))
}

pub fn icosahedron() -> Model {
    platform("icosahedron.toml").model
}

pub fn pulley_model() -> Model {
    platform("icosahedron-pulleys.toml").model
}

/// A few wrench-feasible poses (eq. 3.29) inside the operating region with non-trivial rotation
/// (the same as the model library's tests).
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
