//! The identity motion-core announces (`cdpr_model::config::Platform::identity`, published by
//! the motion-core binary as `PlatformIdentity`) against the golden vector shared through
//! crs-ipc (`crs_ipc::identity_golden`), computed with the model library's code only. The safety
//! monitor has the same test with its own, independently written reader and hash
//! (crates/safety-monitor/tests/identity_golden.rs).

use cdpr_model::config::{MotionLimits, Platform, Region, WinchData, parse_platform};
use cdpr_model::workspace::PositionBox;
use cdpr_model::{Model, ModelParams, Pose, Pulleys};
use crs_ipc::identity_golden as golden;
use nalgebra::{Vector3, Vector6};

fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::from(a)
}

/// The golden platform built from the shared numbers through the model library's constructor
/// (`Model::new` validates and normalises the axes), not its file reader. Only the identity's
/// inputs matter; the rest (winch, home) is what any valid platform needs.
fn golden_platform() -> Platform {
    let model = Model::new(ModelParams {
        a: golden::FRAME_ANCHORS_M.map(v3).to_vec(),
        b: golden::PLATFORM_ANCHORS_M.map(v3).to_vec(),
        pulleys: Some(Pulleys {
            radius: golden::PULLEY_RADIUS_M.to_vec(),
            axis: golden::PULLEY_SWIVEL_AXES.map(v3).to_vec(),
        }),
        k_f: golden::K_F_N.to_vec(),
        w_e: Vector6::from_column_slice(&golden::WRENCH_N_NM),
        f_min: golden::F_MIN_N,
        f_max: golden::F_MAX_N,
    })
    .expect("the golden platform is a valid model");
    Platform {
        name: "crs-identity-golden".into(),
        description: String::new(),
        model,
        f_abs_max: 9000.0,
        limits: MotionLimits {
            linear_velocity_max: golden::LINEAR_VELOCITY_MAX_M_PER_S,
            angular_velocity_max: golden::ANGULAR_VELOCITY_MAX_DEG_PER_S.to_radians(),
            linear_acceleration_max: golden::LINEAR_ACCELERATION_MAX_M_PER_S2,
            angular_acceleration_max: golden::ANGULAR_ACCELERATION_MAX_DEG_PER_S2.to_radians(),
        },
        winch: WinchData {
            drum_diameter: 0.2,
            rope_diameter: 0.01,
        },
        region: Region {
            position: PositionBox {
                min: v3(golden::POSITION_MIN_M),
                max: v3(golden::POSITION_MAX_M),
            },
            rotation_min: v3(golden::ROTATION_MIN_DEG).map(f64::to_radians),
            rotation_max: v3(golden::ROTATION_MAX_DEG).map(f64::to_radians),
        },
        home: Pose::new(Vector3::new(0.0, 0.0, 1.6), Vector3::zeros()),
        f_ini: None,
        sections: Vec::new(),
        dynamics: None,
    }
}

/// The model library's hash over the golden numbers is the golden hash (the serialisation).
#[test]
fn model_library_hash_of_the_golden_numbers_is_the_golden_identity() {
    let p = golden_platform();
    assert_eq!(p.model.identity(), golden::MODEL_IDENTITY);
    assert_eq!(p.identity(), golden::PLATFORM_IDENTITY);
}

/// The model library's reader turns the golden file into exactly the golden platform (bit for
/// bit, unit conversion and axis normalisation included), so motion-core announces the golden
/// identity for it.
#[test]
fn model_library_reading_of_the_golden_file_gives_the_golden_identity() {
    let read = parse_platform(golden::PLATFORM_TOML, "identity_golden.toml").unwrap();
    assert_eq!(read, golden_platform());
    assert_eq!(read.model.identity(), golden::MODEL_IDENTITY);
    assert_eq!(read.identity(), golden::PLATFORM_IDENTITY);
}
