//! The monitor's own platform reader (`safety_monitor::platform`, a hand walk over the spanned
//! TOML tree): every refusal names the value's full path, line and column, and every file it
//! refuses is refused by the model library's reader too (the two readers are independent; they
//! must not disagree about what a usable platform is, or the stack could not start).

use safety_monitor::platform::{PlatformError, parse_platform};
use std::path::PathBuf;

fn icosahedron() -> String {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/icosahedron.toml");
    std::fs::read_to_string(p).unwrap()
}

/// `text` with `from` replaced once (it must occur).
fn edit(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "{from:?} not in the file");
    text.replacen(from, to, 1)
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

/// Parses `bad`, expecting a refusal at `key` located at `needle`'s position, with a message
/// containing `says`; the model library refuses the file too.
fn refused(bad: &str, key: &str, needle: &str, says: &str) -> PlatformError {
    let e = parse_platform(bad, "p.toml").expect_err(key);
    assert_eq!(e.key, key, "{e}");
    let (line, column) = where_is(bad, needle);
    assert_eq!((e.line, e.column), (Some(line), Some(column)), "{key}: {e}");
    assert!(e.message.contains(says), "{key}: {e}");
    assert!(
        e.to_string()
            .starts_with(&format!("p.toml:{line}:{column}: `{key}`: ")),
        "{e}"
    );
    assert!(
        cdpr_model::config::parse_platform(bad, "p.toml").is_err(),
        "{key}: the model library accepts what the monitor refuses"
    );
    e
}

#[test]
fn the_real_platforms_are_read() {
    let p = parse_platform(&icosahedron(), "icosahedron.toml").unwrap();
    assert_eq!(p.cables(), 8);
    assert_eq!(p.name, "crs-icosahedron");
    assert_eq!(p.k_f_n, vec![2.0e6; 8]);
    assert_eq!(p.frame_anchors_m[3].y, 7.638);
    assert_eq!(p.workspace.rotation_max_rad.y, 5.0f64.to_radians());
    assert!(p.pulleys.is_none());
}

#[test]
fn bad_numbers_name_the_element() {
    let t = icosahedron();
    refused(
        &edit(&t, "[ 5.152, -6.182,  6.642]", "[ 5.152, inf,  6.642]"),
        "geometry.frame_anchors_m[4][1]",
        "inf,",
        "finite",
    );
    refused(
        &edit(&t, "f_max_n = 9000.0", "f_max_n = -nan"),
        "forces.f_max_n",
        "-nan",
        "finite",
    );
    refused(
        &edit(&t, "f_min_n = 1000.0", "f_min_n = \"1000\""),
        "forces.f_min_n",
        "\"1000\"",
        "expected a number, found a string",
    );
    refused(
        &edit(&t, "[ 0.954,  1.147,  0.745]", "[ 0.954,  1.147]"),
        "geometry.platform_anchors_m[3]",
        "[ 0.954,  1.147]",
        "expected 3 numbers, found 2",
    );
    refused(
        &edit(
            &t,
            "[0.0, 0.0, -5500.0, 0.0, 0.0, 0.0]",
            "[0.0, 0.0, -5500.0, 0.0, 0.0]",
        ),
        "load.wrench_n_nm",
        "[0.0, 0.0, -5500.0",
        "expected 6 numbers, found 5",
    );
}

#[test]
fn per_cable_values_and_counts() {
    let t = icosahedron();
    refused(
        &edit(&t, "k_f_n = 2.0e6", "k_f_n = 0.0"),
        "elasticity.k_f_n",
        "0.0\n",
        "must be > 0",
    );
    refused(
        &edit(
            &t,
            "k_f_n = 2.0e6",
            "k_f_n = [2e6, 2e6, 2e6, 2e6, -1e6, 2e6, 2e6, 2e6]",
        ),
        "elasticity.k_f_n[4]",
        "-1e6",
        "must be > 0",
    );
    refused(
        &edit(
            &t,
            "k_f_n = 2.0e6",
            "k_f_n = [2e6, 2e6, 2e6, 2e6, 2e6, 2e6, 2e6]",
        ),
        "elasticity.k_f_n",
        "[2e6,",
        "has 7 entries but there are 8 cables",
    );
    refused(
        &edit(
            &t,
            "platform_anchors_m = [\n  [-1.383,  0.528, -0.747],\n",
            "platform_anchors_m = [\n",
        ),
        "geometry.platform_anchors_m",
        "[\n  [-0.799",
        "has 7 rows but there are 8 cables",
    );
    // Integers are numbers (as serde reads them): the same platform.
    let ints = edit(&t, "f_min_n = 1000.0", "f_min_n = 1_000");
    assert_eq!(
        parse_platform(&ints, "p.toml").unwrap(),
        parse_platform(&t, "p.toml").unwrap()
    );
}

#[test]
fn geometry_rules() {
    let t = icosahedron();
    refused(
        &edit(&t, "[ 5.218, -6.304, -0.615]", "[-5.421,  7.668, -1.242]"),
        "geometry.frame_anchors_m[5]",
        "[-5.421,  7.668, -1.242],\n  [-5.451",
        "coincides with row 1",
    );
    refused(
        &edit(
            &t,
            "frame_anchors_m = [",
            "scale = 1.0\nframe_anchors_m = [",
        ),
        "geometry.scale",
        "scale",
        "unknown key",
    );
    let pulleys = "\n[pulleys]\nradius_m = 0.1\nswivel_axes = [[0, 0, 1], [0, 0, 1], [0, 0, 1], \
                   [0, 0, 0], [0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, 1]]\n";
    refused(
        &(t.clone() + pulleys),
        "pulleys.swivel_axes[3]",
        "[0, 0, 0]",
        "non-zero",
    );
    refused(
        &(t.clone() + &pulleys.replace("radius_m = 0.1", "radius_m = -0.1")),
        "pulleys.radius_m",
        "-0.1",
        ">= 0",
    );
}

#[test]
fn ranges_and_boxes() {
    let t = icosahedron();
    refused(
        &edit(&t, "f_max_n = 9000.0", "f_max_n = 1000.0"),
        "forces.f_max_n",
        "1000.0\n# Max",
        "must be greater than forces.f_min_n",
    );
    refused(
        &edit(&t, "f_min_n = 1000.0", "f_min_n = -1.0"),
        "forces.f_min_n",
        "-1.0\nf_max_n",
        ">= 0",
    );
    refused(
        &edit(
            &t,
            "position_max_m = [1.5, 1.5, 2.75]",
            "position_max_m = [1.5, 1.5, 1.25]",
        ),
        "workspace.position_max_m[2]",
        "1.25]\nrotation_min",
        "must be greater than workspace.position_min_m[2]",
    );
    refused(
        &edit(
            &t,
            "linear_velocity_max_m_per_s = 5.0",
            "linear_velocity_max_m_per_s = 0",
        ),
        "limits.linear_velocity_max_m_per_s",
        "0\nangular_velocity",
        "must be > 0",
    );
    refused(
        &edit(&t, "name = \"crs-icosahedron\"", "name = \"  \""),
        "platform.name",
        "\"  \"",
        "must not be empty",
    );
}

#[test]
fn missing_parts_and_syntax() {
    let t = icosahedron();
    // A missing key is reported at its table's header.
    let bad = edit(&t, "f_max_n = 9000.0\n", "");
    let e = refused(
        &bad,
        "forces.f_max_n",
        "[forces]",
        "[forces] has no key `f_max_n`",
    );
    assert!(e.line.is_some());
    // A missing table has no line to point at.
    let bad = t.replace("[limits]", "[limits_old]");
    let e = parse_platform(&bad, "p.toml").unwrap_err();
    assert_eq!((e.key.as_str(), e.line), ("limits", None), "{e}");
    assert!(e.message.contains("no [limits] table"), "{e}");
    // TOML syntax: the toml crate's message at its line and column.
    let bad = edit(&t, "f_min_n = 1000.0", "f_min_n = = 1000.0");
    let e = parse_platform(&bad, "p.toml").unwrap_err();
    assert_eq!(e.key, "");
    assert_eq!(e.line, Some(where_is(&bad, "f_min_n = =").0), "{e}");
    assert!(e.column.is_some(), "{e}");
}
