//! `crs calibrate loop` end to end on the running stack (sim-plant, safety-monitor, drive-io,
//! motion-core as separate processes over iceoryx2 and the CAN-over-UDP loopback bus): a short
//! campaign recorded with the nominal model on the assembled plant, identified, the calibrated
//! model and its refitted surrogate deployed, the campaign re-run. The measured (tracker) pose
//! error at the rest points must drop by the stated factor, and every re-run of a campaign
//! (`--retries`) is budgeted, printed and counted.
//!
//! The stack's binaries must sit next to this package's `crs` (target/<profile>/), which
//! `cargo test --workspace` (tools/test.sh) guarantees; with `cargo test -p crs` alone they may
//! be missing or stale, and the test fails saying so (build them with
//! `cargo build --workspace --bins`).
mod common;
use common::{relaxed_configs, root, stack_bin_dir};
use std::path::PathBuf;
use std::process::Command;

/// The measured mean position error after calibration must be at least this many times
/// smaller than before. This test's campaign (20 poses, 15 of them training, relaxed debug
/// stack) gave 7.32 → 1.30, 7.37 → 1.04 and 7.26 → 1.00 mm (5.6–7.3×); 4× leaves room for a
/// loaded host's noisier rest points and still fails a broken identification or deployment
/// (near 1×). The README's 9× is the full 40-pose release run (`crs figures`, group
/// `calibration-loop`), not this campaign.
const FACTOR: f64 = 4.0;

/// Re-runs allowed per campaign run when drive-io stopped the bus (passed as `--retries`).
const RETRIES: usize = 1;

#[test]
fn closed_loop_on_the_stack_reduces_the_measured_pose_error() {
    let crs = PathBuf::from(env!("CARGO_BIN_EXE_crs"));
    stack_bin_dir(&crs);
    let out = std::env::temp_dir().join(format!("crs-loop-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let poses = 20;
    let cfg = relaxed_configs(&out.join("cfg"));
    let o = Command::new(&crs)
        .current_dir(root())
        .args([
            "calibrate",
            "loop",
            "--max-poses",
            &poses.to_string(),
            // Long enough rests that the plant has settled behind the drives when a rest
            // point is taken, also on a loaded host (unsettled samples blur k_F).
            "--dwell-s",
            "0.9",
            "--settle-s",
            "0.5",
            "--holdout-every",
            "4",
            "--surrogate-validation-samples",
            "300",
            // A run that drive-io stopped (a stall of this shared host in the setpoint stream)
            // is run again at most once, printed, and counted in the report: read below.
            "--retries",
            &RETRIES.to_string(),
            "--transport",
            "wire",
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
        let ds = crs_dataset::load_dataset(&rec).unwrap();
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
    // Diagnosis: k_F is the weakest-determined group on a short campaign (12 poses without
    // the loop's ridge on k_F gave 1.0–5.3 MN against 1.9–2.2 MN true and a refitted
    // surrogate above the 100 mm bound of eq. 5.27, which motion-core rightly refused).
    let cal = std::fs::read_to_string(out.join("identification/calibrated.toml")).unwrap();
    if let Some(l) = cal.lines().find(|l| l.starts_with("k_f_n")) {
        eprintln!("identified {l}");
    }
    // No hidden retries: every extra run the report counts was printed with its cause, and
    // none went beyond the budget.
    let attempts = |run: &str| rep[run]["attempts"].as_u64().expect("attempts") as usize;
    let (att_b, att_a) = (attempts("before"), attempts("after"));
    let retried = text
        .matches("run was interrupted: drive-io stopped the bus")
        .count();
    eprintln!(
        "runs needed: before {att_b}, after {att_a} (at most {} each)",
        RETRIES + 1
    );
    assert!(att_b >= 1 && att_a >= 1 && att_b <= RETRIES + 1 && att_a <= RETRIES + 1);
    assert_eq!(
        att_b + att_a - 2,
        retried,
        "retries counted vs printed:\n{text}"
    );
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
