//! `crs calibrate loop` end to end on the running stack (sim-plant, safety-monitor, drive-io,
//! motion-core as separate processes over iceoryx2 and the CAN-over-UDP loopback bus): a short
//! campaign recorded with the nominal model on the assembled plant, identified, the calibrated
//! model and its refitted surrogate deployed, the campaign re-run. The measured (tracker) pose
//! error at the rest points must drop by the stated factor.
//!
//! The stack's binaries must sit next to this package's `crs` (target/<profile>/), which
//! `cargo test --workspace` (tools/test.sh) guarantees; with `cargo test -p crs` alone they may
//! be missing or stale, and the test fails saying so (build them with
//! `cargo build --workspace --bins`).
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The measured mean position error after calibration must be at least this many times
/// smaller than before (12 poses, 9 of them training: 6.14 → 1.45 mm = 4.2× and, with the
/// relaxed timing, 6.11 → 1.80 mm = 3.4× in debug runs; the full 40-pose release run gives
/// 11×, docs/calibration.md). A broken identification or deployment leaves it near 1×.
const FACTOR: f64 = 2.0;

/// Copies of the stack's daemon, drives and monitor TOML with the timing relaxed for this test
/// (as tools/stack-hil.sh does for the emulated guest): 4 ms loop and SYNC, drives' stale
/// setpoints 100 cycles, heartbeat timeout 300 ms, safety-heartbeat validation 150 ms, monitor
/// silence 10 / feedback silence 20 cycles. The test runs DEBUG builds of four processes on a
/// shared 2-core host, where the spec's 1 ms / 50 ms watchdogs trip on scheduling stalls (seen:
/// the drives' safety-heartbeat timeout, then sequence gaps). It asserts what calibration does
/// on the running stack, not timing: timing is the benches' job (benches/RESULTS.md). Returns
/// [daemon, drives, monitor].
fn relaxed_configs(dir: &Path) -> [PathBuf; 3] {
    std::fs::create_dir_all(dir).unwrap();
    let edit = |name: &str, rules: &[(&str, &str)]| -> PathBuf {
        let text = std::fs::read_to_string(root().join("config").join(name)).unwrap();
        let mut seen = vec![0usize; rules.len()];
        let lines: Vec<String> = text
            .lines()
            .map(|l| {
                for (k, (key, value)) in rules.iter().enumerate() {
                    if l.starts_with(&format!("{key} = ")) {
                        seen[k] += 1;
                        return format!("{key} = {value}");
                    }
                }
                l.to_string()
            })
            .collect();
        assert!(
            seen.iter().all(|n| *n > 0),
            "config/{name}: a relaxed key is missing: {rules:?} {seen:?}"
        );
        let path = dir.join(name);
        std::fs::write(&path, lines.join("\n") + "\n").unwrap();
        path
    };
    [
        edit("motion-core.toml", &[("period_us", "4000")]),
        edit(
            "drives.toml",
            &[
                ("sync_period_us", "4000"),
                ("stale_setpoint_cycles", "100"),
                ("heartbeat_producer_ms", "20"),
                ("heartbeat_timeout_ms", "300"),
                ("validation_time_ms", "150"),
                ("pair_window_ms", "75"),
            ],
        ),
        // Both silence_cycles keys ([monitor] and [feedback]) become 10; identity grace 40.
        edit(
            "safety-monitor.toml",
            &[("silence_cycles", "10"), ("identity_grace_cycles", "40")],
        ),
    ]
}

#[test]
fn closed_loop_on_the_stack_reduces_the_measured_pose_error() {
    let crs = PathBuf::from(env!("CARGO_BIN_EXE_crs"));
    let bin_dir = crs.parent().unwrap().to_path_buf();
    let missing: Vec<&str> = ["motion-core", "drive-io", "sim-plant", "safety-monitor"]
        .into_iter()
        .filter(|n| !bin_dir.join(n).is_file())
        .collect();
    assert!(
        missing.is_empty(),
        "{missing:?} not built in {}: run `cargo test --workspace` or `cargo build --workspace --bins` first",
        bin_dir.display()
    );
    let out = std::env::temp_dir().join(format!("crs-loop-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let port = 20000 + (std::process::id() % 20000);
    let poses = 12;
    let cfg = relaxed_configs(&out.join("cfg"));
    let o = Command::new(&crs)
        .current_dir(root())
        .args([
            "calibrate",
            "loop",
            "--max-poses",
            &poses.to_string(),
            "--dwell-s",
            "0.6",
            "--settle-s",
            "0.3",
            "--holdout-every",
            "4",
            "--surrogate-validation-samples",
            "300",
            "--transport",
            &format!("udpbus:239.255.70.9:{port}"),
            "--daemon-config",
            cfg[0].to_str().unwrap(),
            "--drives",
            cfg[1].to_str().unwrap(),
            "--monitor-config",
            cfg[2].to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .expect("run crs calibrate loop");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(o.status.success(), "{text}");
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    for run in ["before", "after"] {
        let s = &rep[run]["summary"];
        assert_eq!(s["rest"]["rest_points"], poses, "{run}: {text}");
        assert_eq!(s["estops"], 0, "{run}");
        assert_eq!(s["drive_faults"], 0, "{run}");
        assert!(
            f(&s["force_min_n"]) >= f(&s["f_min_n"]) && f(&s["force_max_n"]) <= f(&s["f_max_n"]),
            "{run}: forces outside the limits: {s}"
        );
        // The recording is a crs-dataset 1 file of the rest points with forces and references.
        let rec = out.join(run).join("campaign.csv");
        let ds = sim_plant::load_dataset(&rec).unwrap();
        assert_eq!(ds.samples.len(), poses);
        assert!(ds.has_forces && ds.has_reference);
        assert_eq!(ds.meta("control_model"), Some("kinematic+surrogate"));
        // The commanded lengths are the surrogate controller's: φ(x_ref) + φ_sg(x_ref) differs
        // from the measured pose's φ by the stretch, never by more than the 100 mm bound.
        for s in &ds.samples {
            let (dp, _) = s.pose.error_to(s.pose_ref.as_ref().unwrap());
            assert!(dp < 0.2, "{run}: rest point {} is {dp} m off", s.sample);
        }
    }
    let before = f(&rep["before"]["summary"]["rest"]["position_mean_mm"]);
    let after = f(&rep["after"]["summary"]["rest"]["position_mean_mm"]);
    eprintln!("measured mean position error at the rest points: {before:.2} mm -> {after:.2} mm");
    assert!(
        after * FACTOR < before,
        "measured mean position error {before:.2} mm → {after:.2} mm: not {FACTOR}× smaller\n{text}"
    );
    // The after run ran the calibrated platform (safety monitor and daemon agreed on it).
    let after_pf = rep["after"]["platform"].as_str().unwrap();
    assert!(after_pf.ends_with("calibrated.toml"), "{after_pf}");
    assert!(out.join("report.md").is_file());
    let _ = std::fs::remove_dir_all(&out);
}
