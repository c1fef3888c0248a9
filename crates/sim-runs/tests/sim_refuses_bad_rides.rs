//! `crs sim` checks the ride (the waypoint file motion-core would run) before any process
//! starts: a missing file, a NaN, or a waypoint outside the region is refused naming the
//! file, the line and (outside the region) the axis and the bound, and no child is spawned.
//!
//! The bin dir holds empty stand-ins for the stack's binaries: if the launcher got as far as
//! starting processes, spawning them would fail with a different error and leave child logs.

use sim_runs::sim_run::{SimError, SimOptions, execute};
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("crs-sim-bad-ride-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(d.join("bin")).unwrap();
    for b in [
        "motion-core",
        "drive-io",
        "sim-plant",
        "can-wire",
        "safety-monitor",
    ] {
        std::fs::write(d.join("bin").join(b), "").unwrap();
    }
    d
}

fn options(dir: &Path, waypoints: PathBuf) -> SimOptions {
    let c = repo().join("config");
    SimOptions {
        operator_start: false,
        config: c.join("motion-core.toml"),
        drives: c.join("drives.toml"),
        plant: c.join("plant/icosahedron.toml"),
        transport: "auto".into(),
        waypoints: Some(waypoints),
        hold_s: 1.0,
        timeout_s: 60.0,
        bin_dir: Some(dir.join("bin")),
        out: dir.join("out"),
        no_monitor: false,
        check: true,
        max_static_error_mm: 20.0,
        monitor_config: c.join("safety-monitor.toml"),
        dwell_s: None,
        record: None,
        settle_s: 0.5,
        record_mean_forces: false,
        campaign: None,
        rt_priority: None,
        ride: None,
        cueing: None,
    }
}

/// Runs `crs sim`'s launcher on a ride file with `body` and returns the refusal's text,
/// asserting that nothing was started (no output directory, so no child log).
fn refusal(name: &str, body: Option<&str>) -> String {
    let dir = scratch(name);
    let file = dir.join(format!("{name}.csv"));
    if let Some(b) = body {
        std::fs::write(&file, b).unwrap();
    }
    let err = match execute(&options(&dir, file.clone())) {
        Err(e) => e,
        Ok(_) => panic!("{name}: the run was not refused"),
    };
    assert!(matches!(err, SimError::RideRefused(_)), "{name}: {err:?}");
    assert!(
        !dir.join("out").exists(),
        "{name}: the launcher created its output (and would have started processes)"
    );
    let text = err.to_string();
    assert!(text.contains(&file.display().to_string()), "{text}");
    text
}

const HEADER: &str = "t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg\n";

#[test]
fn a_waypoint_outside_the_region_names_file_line_axis_and_bound() {
    let body = format!(
        "# a ride\n{HEADER}0,0.4,0,2,0,0,0\n2,0,0.5,2,0,0,0\n4,0,4.0,2,0,0,0\n6,0,0,2,0,0,0\n"
    );
    let text = refusal("outside", Some(&body));
    assert!(text.contains("outside.csv:5:"), "{text}");
    assert!(text.contains("waypoint 3"), "{text}");
    assert!(text.contains("y_m = 4.000 m"), "{text}");
    assert!(text.contains("[-1.500, 1.500] m"), "{text}");
}

#[test]
fn a_rotation_outside_the_region_is_named_in_degrees() {
    let body = format!("{HEADER}0,0,0,2,0,9,0\n");
    let text = refusal("tilt", Some(&body));
    assert!(text.contains("tilt.csv:2:"), "{text}");
    assert!(text.contains("phi_y_deg = 9.000 °"), "{text}");
    assert!(text.contains("[-5.000, 5.000] °"), "{text}");
}

#[test]
fn a_nan_waypoint_names_line_and_column() {
    let body = format!("{HEADER}0,0.4,0,2,0,0,0\n2,NaN,0,2,0,0,0\n");
    let text = refusal("nan", Some(&body));
    assert!(text.contains("nan.csv:3:"), "{text}");
    assert!(text.contains("x_m"), "{text}");
}

#[test]
fn a_missing_ride_file_is_refused() {
    let text = refusal("missing", None);
    assert!(text.contains("cannot read"), "{text}");
}

#[test]
fn a_ride_without_waypoints_is_refused() {
    let text = refusal("empty", Some(HEADER));
    assert!(text.contains("no waypoint rows"), "{text}");
}
