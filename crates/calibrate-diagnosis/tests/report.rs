//! The identified model written back as a platform TOML loads with motion-core's loader and
//! carries the identified parameters exactly (bad data sets: calibrate's tests/data_errors.rs).

#[path = "../../calibrate/tests/common/mod.rs"]
mod common;
use calibrate::CalModel;
use calibrate_diagnosis::effects::Effect;
use calibrate_diagnosis::report;
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
