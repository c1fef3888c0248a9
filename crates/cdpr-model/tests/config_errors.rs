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
    // Named at the later row, the copy (as the monitor's reader names it).
    let later = t4
        .lines()
        .position(|l| l.contains("[-5.380,  7.677,  6.524]"))
        .map(|first| {
            first
                + 1
                + t4.lines()
                    .skip(first + 1)
                    .position(|l| l.contains("[-5.380,  7.677,  6.524]"))
                    .expect("two coinciding rows")
        })
        .unwrap();
    assert_eq!(e.line, Some(later + 1), "{e}");
    assert!(e.key.starts_with("geometry.frame_anchors_m["), "{e}");
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

/// 1-based line and column of the first occurrence of `needle`.
fn where_is(text: &str, needle: &str) -> (usize, usize) {
    let at = text
        .find(needle)
        .unwrap_or_else(|| panic!("{needle:?} not found"));
    let before = &text[..at];
    let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
    (before.matches('\n').count() + 1, col)
}

/// `text` with `from` replaced once (it must occur).
fn edit(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "{from:?} not in the file");
    text.replacen(from, to, 1)
}

/// Parses `bad`, expecting a refusal of `key` located at `needle` with a message containing
/// `says`, printed as `p.toml:line:column: `key`: message`.
fn refused(bad: &str, key: &str, needle: &str, says: &str) {
    let e = parse_platform(bad, "p.toml").expect_err(key);
    let (line, column) = where_is(bad, needle);
    assert_eq!(e.key, key, "{e}");
    assert_eq!((e.line, e.column), (Some(line), Some(column)), "{key}: {e}");
    assert!(e.message.contains(says), "{key}: {e}");
    assert!(
        e.to_string()
            .starts_with(&format!("p.toml:{line}:{column}: `{key}`: ")),
        "{e}"
    );
}

/// A bad element of an array of rows is named by row and column, at its own line and column,
/// as the safety monitor's reader names it (the flattened index `frame_anchors_m[7]` at the
/// array's first line was a number the operator could not find).
#[test]
fn bad_elements_of_rows_are_named_by_row_and_column() {
    let t = base();
    let third = "[ 5.016,  7.555,  6.503]";
    refused(
        &edit(&t, third, "[ 5.016,  nan,  6.503]"),
        "geometry.frame_anchors_m[2][1]",
        "nan,",
        "finite",
    );
    refused(
        &edit(&t, third, "[ 5.016,  7.555,  -inf]"),
        "geometry.frame_anchors_m[2][2]",
        "-inf",
        "finite",
    );
    refused(
        &edit(&t, third, "[ 5.016,  \"7.555\",  6.503]"),
        "geometry.frame_anchors_m[2][1]",
        "\"7.555\"",
        "invalid type: string",
    );
    refused(
        &edit(&t, "[ 1.403, -0.551,  0.746]", "[ true, -0.551,  0.746]"),
        "geometry.platform_anchors_m[5][0]",
        "true",
        "invalid type: boolean",
    );
    // The wrong arity of a row names the row.
    refused(
        &edit(&t, third, "[ 5.016,  7.555]"),
        "geometry.frame_anchors_m[2]",
        "[ 5.016,  7.555]",
        "invalid length 2, expected an array of length 3",
    );
    refused(
        &edit(&t, third, "\"5.016 7.555 6.503\""),
        "geometry.frame_anchors_m[2]",
        "\"5.016",
        "invalid type: string",
    );
    // The helicopter's platform anchors (eq. 5.17).
    let heli = std::fs::read_to_string(common::config_path("helicopter.toml")).unwrap();
    refused(
        &edit(&heli, "[-0.233,  0.453, -0.940]", "[-0.233,  0.453, nan]"),
        "geometry.platform_anchors_m[3][2]",
        "nan]",
        "finite",
    );
}

/// A fourth coordinate (or a seventh wrench component) is refused: serde's `[f64; N]` under
/// `toml` read the first N and dropped the rest, so the typo loaded silently (the monitor's
/// reader refused the same file).
#[test]
fn extra_elements_of_fixed_arrays_are_refused() {
    let t = base();
    refused(
        &edit(
            &t,
            "[ 5.016,  7.555,  6.503]",
            "[ 5.016,  7.555,  6.503, 1.0]",
        ),
        "geometry.frame_anchors_m[2]",
        "[ 5.016,  7.555,  6.503, 1.0]",
        "invalid length 4, expected an array of length 3",
    );
    let wrench = "[0.0, 0.0, -5500.0, 0.0, 0.0, 0.0]";
    refused(
        &edit(&t, wrench, "[0.0, 0.0, -5500.0, 0.0, 0.0, 0.0, 1.0]"),
        "load.wrench_n_nm",
        "[0.0, 0.0, -5500.0",
        "invalid length 7, expected an array of length 6",
    );
    refused(
        &edit(
            &t,
            "position_m = [0.0, 0.0, 2.0]",
            "position_m = [0.0, 0.0, 2.0, 0.0]",
        ),
        "home.position_m",
        "[0.0, 0.0, 2.0, 0.0]",
        "invalid length 4, expected an array of length 3",
    );
    // A bad element of a flat array keeps its index and now its own column.
    refused(
        &edit(&t, wrench, "[0.0, 0.0, -5500.0, 0.0, \"x\", 0.0]"),
        "load.wrench_n_nm[4]",
        "\"x\"",
        "invalid type: string",
    );
}

/// Pulley swivel axes: a bad element names `pulleys.swivel_axes[row][column]`, a zero axis
/// the row (it was `pulleys[2]`, a key the file does not have).
#[test]
fn bad_pulley_axes_are_named_by_row_and_column() {
    let t = std::fs::read_to_string(common::config_path("icosahedron-pulleys.toml")).unwrap();
    let rows = "  [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0],\n";
    let third = |row: &str| {
        edit(
            &t,
            rows,
            &format!("  [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], {row}, [0.0, 0.0, 1.0],\n"),
        )
    };
    refused(
        &third("[nan, 0.0, 1.0]"),
        "pulleys.swivel_axes[2][0]",
        "nan",
        "finite",
    );
    refused(
        &third("[0.0, \"z\", 1.0]"),
        "pulleys.swivel_axes[2][1]",
        "\"z\"",
        "invalid type: string",
    );
    refused(
        &third("[0.0, 0.0]"),
        "pulleys.swivel_axes[2]",
        "[0.0, 0.0]",
        "invalid length 2",
    );
    refused(
        &third("[0.0, 0.0, 0.0]"),
        "pulleys.swivel_axes[2]",
        "[0.0, 0.0, 0.0]",
        "non-zero",
    );
}

/// Errors that are not about a value keep an empty key: a syntax error, a missing key, an
/// unknown key (their messages name the key).
#[test]
fn errors_not_about_a_value_have_no_key() {
    let t = base();
    for bad in [
        edit(&t, "[forces]", "[forces"),
        edit(&t, "f_max_n = 9000.0\n", ""),
        edit(
            &t,
            "f_min_n = 1000.0",
            "f_min_n = 1000.0\nf_minimum_n = 3.0",
        ),
    ] {
        let e = parse_platform(&bad, "p.toml").unwrap_err();
        assert_eq!(e.key, "", "{e}");
        assert!(e.line.is_some(), "{e}");
    }
    let e = parse_platform(
        &edit(&t, "f_min_n = 1000.0", "f_min_n = \"1000\""),
        "p.toml",
    )
    .unwrap_err();
    assert_eq!(e.key, "forces.f_min_n", "{e}");
}
