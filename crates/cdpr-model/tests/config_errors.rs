//! Bad platform TOML is rejected with file, key and line; nothing is half-applied.
mod common;

use cdpr_model::config::parse_platform;

fn base() -> String {
    std::fs::read_to_string(common::config_path("icosahedron.toml")).unwrap()
}

fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).unwrap() + 1
}

#[test]
fn all_shipped_configs_load() {
    for f in [
        "icosahedron.toml",
        "icosahedron-pulleys.toml",
        "helicopter.toml",
        "crs-nominal.toml",
    ] {
        let p = common::platform(f);
        assert_eq!(p.model.m(), 8, "{f}");
    }
    let nominal = common::platform("crs-nominal.toml");
    assert_eq!(nominal.f_ini.as_ref().unwrap()[0], 3678.0); // eq. (6.22)
    assert_eq!(nominal.model.params().w_e[4], -480.0); // eq. (6.20)
}

#[test]
fn unknown_key_is_rejected_with_its_line() {
    let text = base().replace("f_min_n = 1000.0", "f_min_n = 1000.0\nf_minimum_n = 3.0");
    let e = parse_platform(&text, "ico.toml").unwrap_err();
    assert_eq!(e.line, Some(line_of(&text, "f_minimum_n")), "{e}");
    assert!(e.to_string().contains("f_minimum_n"), "{e}");
    assert!(e.to_string().starts_with("ico.toml:"), "{e}");
}

#[test]
fn non_finite_numbers_are_rejected() {
    let text = base().replace("k_f_n = 2.0e6", "k_f_n = nan");
    let e = parse_platform(&text, "ico.toml").unwrap_err();
    assert_eq!(e.key, "elasticity.k_f_n");
    assert_eq!(e.line, Some(line_of(&text, "k_f_n = nan")));
    let text = base().replace("[ 5.016,  7.555,  6.503]", "[ 5.016,  inf,  6.503]");
    let e = parse_platform(&text, "ico.toml").unwrap_err();
    assert!(e.key.starts_with("geometry.frame_anchors_m"), "{e}");
}

#[test]
fn geometry_errors_name_the_key() {
    // Too few cables (m ≥ 7 for 6 DOF).
    let mut text = base();
    for row in [
        "  [-5.461, -6.509, -1.067],\n",
        "  [-1.434, -0.393,  0.748],\n",
    ] {
        text = text.replacen(row, "", 1);
    }
    let t2 = text
        .replacen("  [-5.451, -6.492,  6.630],\n", "", 1)
        .replacen("  [-0.935, -1.170, -0.746],\n", "", 1);
    let e = parse_platform(&t2, "x.toml").unwrap_err();
    assert!(e.message.contains("at least 7"), "{e}");
    assert_eq!(e.key, "geometry.frame_anchors_m");
    // Row count mismatch between a and b.
    let t3 = base().replacen("  [-1.434, -0.393,  0.748],\n", "", 1);
    let e = parse_platform(&t3, "x.toml").unwrap_err();
    assert_eq!(e.key, "geometry.platform_anchors_m", "{e}");
    // Duplicate anchor.
    let t4 = base().replace("[ 5.016,  7.555,  6.503]", "[-5.380,  7.677,  6.524]");
    let e = parse_platform(&t4, "x.toml").unwrap_err();
    assert!(e.message.contains("coincide"), "{e}");
    // Wrong arity of a point.
    let t5 = base().replace("[ 5.016,  7.555,  6.503]", "[ 5.016,  7.555]");
    assert!(parse_platform(&t5, "x.toml").is_err());
}

#[test]
fn limits_must_be_ordered_and_positive() {
    let e = parse_platform(
        &base().replace("f_min_n = 1000.0", "f_min_n = 9500.0"),
        "x.toml",
    )
    .unwrap_err();
    assert_eq!(e.key, "forces.f_min_n", "{e}");
    let e = parse_platform(
        &base().replace("f_max_n = 9000.0", "f_max_n = 15000.0"),
        "x.toml",
    )
    .unwrap_err();
    assert_eq!(e.key, "forces.f_max_n", "{e}");
    let e =
        parse_platform(&base().replace("k_f_n = 2.0e6", "k_f_n = -2.0e6"), "x.toml").unwrap_err();
    assert_eq!(e.key, "elasticity.k_f_n[0]", "{e}");
    let e = parse_platform(
        &base().replace("drum_diameter_m = 0.305", "drum_diameter_m = 0.0"),
        "x.toml",
    )
    .unwrap_err();
    assert_eq!(e.key, "winch.drum_diameter_m", "{e}");
    let e = parse_platform(
        &base().replace(
            "position_m = [0.0, 0.0, 2.0]",
            "position_m = [0.0, 0.0, 7.0]",
        ),
        "x.toml",
    )
    .unwrap_err();
    assert_eq!(e.key, "home", "{e}");
    let e = parse_platform(
        &base().replace(
            "position_max_m = [1.5, 1.5, 2.75]",
            "position_max_m = [1.5, -2.0, 2.75]",
        ),
        "x.toml",
    )
    .unwrap_err();
    assert_eq!(e.key, "workspace.position_max_m[1]", "{e}");
}

#[test]
fn missing_file_and_syntax_errors_are_clear() {
    let e = cdpr_model::config::load_platform("/nonexistent/p.toml").unwrap_err();
    assert!(e.to_string().contains("/nonexistent/p.toml") && e.message.contains("cannot read"));
    let e = parse_platform(&base().replace("[forces]", "[forces"), "x.toml").unwrap_err();
    assert!(e.line.is_some(), "{e}");
    let e = parse_platform("", "x.toml").unwrap_err();
    assert!(e.message.contains("missing"), "{e}");
}

#[test]
fn dynamics_that_contradict_the_static_load_are_refused_by_key_and_line() {
    // [dynamics] + [dynamics.payload] of the icosahedron make the 5500 N of [load].
    let p = common::platform("icosahedron.toml");
    let d = p.dynamics.expect("[dynamics]");
    assert!((d.mass_kg - 560.7).abs() < 1e-9 && d.cog_m.norm() < 1e-12);
    let text = base().replace("mass_kg = 480.7", "mass_kg = 380.7");
    let e = parse_platform(&text, "ico.toml").unwrap_err();
    assert_eq!(e.key, "dynamics.mass_kg", "{e}");
    assert!(
        e.to_string().contains("load.wrench_n_nm carries 5500 N"),
        "{e}"
    );
    let text = base().replace(
        "center_of_gravity_m = [0.0, 0.0, 0.0]\ninertia_kg_m2 = [104.5",
        "center_of_gravity_m = [0.1, 0.0, 0.0]\ninertia_kg_m2 = [104.5",
    );
    let e = parse_platform(&text, "ico.toml").unwrap_err();
    assert_eq!(e.key, "dynamics.center_of_gravity_m", "{e}");
    // Not a real mass distribution: I_zz > I_xx + I_yy.
    let text = base().replace("[104.5, 104.5, 104.5]", "[10.0, 10.0, 104.5]");
    let e = parse_platform(&text, "ico.toml").unwrap_err();
    assert_eq!(e.key, "dynamics.inertia_kg_m2", "{e}");
    assert_eq!(e.line, Some(line_of(&text, "[10.0, 10.0, 104.5]")), "{e}");
}
