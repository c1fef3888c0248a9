//! The monitor's platform identity against the golden vector shared through crs-ipc
//! (`crs_ipc::identity_golden`), computed with the monitor's own code only: its own reader
//! (`safety_monitor::platform`) and its own hash (`safety_monitor::identity`). motion-core has the
//! same test with the model library's code (crates/motion-core/tests/identity_golden.rs); both
//! passing means both announce / expect the identity the contract defines, not merely the same
//! one.

use crs_ipc::identity_golden as golden;
use glam::DVec3;
use safety_monitor::identity::{model_identity, platform_identity};
use safety_monitor::platform::{
    MotionLimits, PlatformParams, PulleyParams, WorkspaceBox, parse_platform,
};

fn v3(a: [f64; 3]) -> DVec3 {
    DVec3::from_array(a)
}

/// The golden platform built directly from the shared numbers (no parser), converted as the
/// contract says: degrees × (π/180), axes divided by their Euclidean norm.
fn golden_params() -> PlatformParams {
    let deg = |a: [f64; 3]| v3(a.map(f64::to_radians));
    PlatformParams {
        name: "crs-identity-golden".into(),
        frame_anchors_m: golden::FRAME_ANCHORS_M.map(v3).to_vec(),
        platform_anchors_m: golden::PLATFORM_ANCHORS_M.map(v3).to_vec(),
        pulleys: Some(PulleyParams {
            radius_m: golden::PULLEY_RADIUS_M.to_vec(),
            axis: golden::PULLEY_SWIVEL_AXES
                .map(|[x, y, z]| {
                    let n = (x * x + y * y + z * z).sqrt();
                    DVec3::new(x / n, y / n, z / n)
                })
                .to_vec(),
        }),
        k_f_n: golden::K_F_N.to_vec(),
        wrench_n_nm: golden::WRENCH_N_NM,
        f_min_n: golden::F_MIN_N,
        f_max_n: golden::F_MAX_N,
        workspace: WorkspaceBox {
            position_min_m: v3(golden::POSITION_MIN_M),
            position_max_m: v3(golden::POSITION_MAX_M),
            rotation_min_rad: deg(golden::ROTATION_MIN_DEG),
            rotation_max_rad: deg(golden::ROTATION_MAX_DEG),
        },
        limits: MotionLimits {
            linear_velocity_m_per_s: golden::LINEAR_VELOCITY_MAX_M_PER_S,
            angular_velocity_rad_per_s: golden::ANGULAR_VELOCITY_MAX_DEG_PER_S.to_radians(),
            linear_acceleration_m_per_s2: golden::LINEAR_ACCELERATION_MAX_M_PER_S2,
            angular_acceleration_rad_per_s2: golden::ANGULAR_ACCELERATION_MAX_DEG_PER_S2
                .to_radians(),
        },
    }
}

/// The monitor's hash over the golden numbers is the golden hash (the serialisation).
#[test]
fn monitor_hash_of_the_golden_numbers_is_the_golden_identity() {
    let p = golden_params();
    assert_eq!(model_identity(&p), golden::MODEL_IDENTITY);
    assert_eq!(platform_identity(&p), golden::PLATFORM_IDENTITY);
}

/// The monitor's reader turns the golden file into exactly the golden numbers (bit for bit,
/// including the unit conversion and the axis normalisation), and so into the golden identity.
#[test]
fn monitor_reading_of_the_golden_file_gives_the_golden_identity() {
    let read = parse_platform(golden::PLATFORM_TOML, "identity_golden.toml").unwrap();
    assert_eq!(read, golden_params());
    assert_eq!(model_identity(&read), golden::MODEL_IDENTITY);
    assert_eq!(platform_identity(&read), golden::PLATFORM_IDENTITY);
}

/// The golden comparison sees a change in the last bit of any hashed group: one value of each
/// group, nudged by one ulp, changes the identity.
#[test]
fn one_ulp_anywhere_changes_the_identity() {
    type Field = fn(&mut PlatformParams) -> &mut f64;
    let fields: [(&str, Field); 10] = [
        ("a_8.z", |p| &mut p.frame_anchors_m[7].z),
        ("b_1.x", |p| &mut p.platform_anchors_m[0].x),
        ("k_F,4", |p| &mut p.k_f_n[3]),
        ("tau_z", |p| &mut p.wrench_n_nm[5]),
        ("f_max", |p| &mut p.f_max_n),
        ("r_p,2", |p| &mut p.pulleys.as_mut().unwrap().radius_m[1]),
        ("u_Az,4.y", |p| &mut p.pulleys.as_mut().unwrap().axis[3].y),
        ("position_min.y", |p| &mut p.workspace.position_min_m.y),
        ("rotation_max.z", |p| &mut p.workspace.rotation_max_rad.z),
        ("angular acceleration", |p| {
            &mut p.limits.angular_acceleration_rad_per_s2
        }),
    ];
    for (what, field) in fields {
        let mut p = golden_params();
        let x = field(&mut p);
        *x = f64::from_bits(x.to_bits() + 1);
        assert_ne!(platform_identity(&p), golden::PLATFORM_IDENTITY, "{what}");
    }
}
