//! The identified model written back as a platform TOML loads with motion-core's loader and
//! carries the identified parameters exactly; bad data sets give errors, not panics.

mod common;
use calibrate::effects::Effect;
use calibrate::observation::ObservationError;
use calibrate::{CalModel, from_dataset, report};
use cdpr_model::config::parse_platform;
use common::*;

#[test]
fn platform_toml_round_trips_through_load_platform() {
    let base = nominal();
    let mut cal = CalModel::from_model(&base.model);
    cal.a[2].x += 0.123_456_789_012_345;
    cal.b[5].z -= 0.004_2;
    cal.k_f[1] = 1_987_654.321;
    cal.w_e[4] = -512.25;
    cal.pulleys = true;
    cal.pulley_radius = 0.161;
    let text = report::platform_toml(&base, &cal, "roundtrip").expect("valid model");
    let p = parse_platform(&text, "roundtrip.toml").expect("written platform must load");
    let model = cal.model().unwrap();
    assert_eq!(
        p.model.params(),
        model.params(),
        "parameters must survive bit for bit"
    );
    assert_eq!(p.home, base.home);
    assert_eq!(p.f_ini, base.f_ini);
    assert_eq!(p.region, base.region);
    let side = report::side_file(&cal, &[Effect::Pulleys]);
    assert!(side.contains("effects = [\"pulleys\"]"));
    assert!(
        side.parse::<toml::Table>().is_ok(),
        "side file must be TOML"
    );
}

#[test]
fn bad_data_sets_are_rejected_with_a_reason() {
    let text = "# format: crs-dataset 1\n# units: SI (q_cmd m; x y z m; phi rad, R = Rx Ry Rz eq. 2.2; f N)\nsample,q_cmd_1,x,y,z,phi_x,phi_y,phi_z\n0,1.0,0,0,oops,0,0,0\n";
    let err = crs_dataset::read_dataset(text.as_bytes(), "bad.csv").unwrap_err();
    assert_eq!(err.line, Some(4), "{err}");
    let ok = "# format: crs-dataset 1\n# units: SI (q_cmd m; x y z m; phi rad, R = Rx Ry Rz eq. 2.2; f N)\nsample,q_cmd_1,x,y,z,phi_x,phi_y,phi_z,f_1\n0,1.0,0,0,1,0,0,0,-5\n";
    let ds = crs_dataset::read_dataset(ok.as_bytes(), "one.csv").unwrap();
    assert_eq!(
        from_dataset(&ds, 8),
        Err(ObservationError::CableCount {
            expected: 8,
            got: 1
        })
    );
    assert!(matches!(
        from_dataset(&ds, 1),
        Err(ObservationError::NonPositiveForce {
            sample: 0,
            cable: 1,
            ..
        })
    ));
}

/// A platform with `[dynamics]` whose identified load moved (eq. 6.23): the written platform
/// carries the identified weight and COG in `[dynamics]` too and loads (the loader refuses a
/// `[dynamics]` that contradicts `[load]`).
#[test]
fn an_identified_load_moves_the_dynamics_with_it() {
    let base = cdpr_model::config::load_platform(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/icosahedron.toml"),
    )
    .unwrap();
    assert!(base.dynamics.is_some(), "the icosahedron has [dynamics]");
    let mut cal = CalModel::from_model(&base.model);
    cal.w_e[2] *= 1.06;
    cal.w_e[3] += 150.0;
    cal.w_e[4] -= 90.0;
    let text = report::platform_toml(&base, &cal, "heavier").expect("writable");
    let p = parse_platform(&text, "heavier.toml").expect("written platform must load");
    let d = p.dynamics.unwrap();
    assert!((d.mass_kg * 9.81 + cal.w_e[2]).abs() < 1e-6, "{d:?}");
}

/// An identified yaw torque (eq. 6.23 has one) cannot come from a point weight: the platform
/// is still written and loads, without [dynamics], and says so.
#[test]
fn a_load_no_weight_can_produce_leaves_dynamics_out_and_says_so() {
    let base = cdpr_model::config::load_platform(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/icosahedron.toml"),
    )
    .unwrap();
    let mut cal = CalModel::from_model(&base.model);
    cal.w_e[5] = -99.0;
    let text = report::platform_toml(&base, &cal, "yawed").expect("writable");
    let p = parse_platform(&text, "yawed.toml").expect("written platform must load");
    assert!(p.dynamics.is_none());
    assert!(text.contains("[dynamics] LEFT OUT"), "{text}");
}
