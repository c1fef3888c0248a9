//! Motion cueing on the whole stack: `crs sim --source cueing --vehicle
//! config/vehicle/braking.csv --check` runs the washout at 1 kHz as motion-core's cueing input
//! while sim-plant, the safety monitor, drive-io and motion-core run as processes — on the
//! nominal icosahedron and on the calibrated one (config/icosahedron-calibrated.toml, on the
//! plant it was calibrated on). The run must pass `--check` (no e-stop, no refused reference,
//! forces within [f_min, f_max], every plant step converged), the tilt must stay below its
//! rate threshold, the reference inside the cueing box, and the perception figures must be
//! written with numbers for the braking axis. (Relaxed 4 ms timing of the debug stack tests,
//! see tests/common.)
mod common;
use common::{relaxed_configs_of, root, sim_command, stack_bin_dir};
use std::path::PathBuf;

fn run(label: &str, daemon: &str, monitor: &str, plant: Option<&str>) {
    let crs = PathBuf::from(env!("CARGO_BIN_EXE_crs"));
    stack_bin_dir(&crs);
    let out = std::env::temp_dir().join(format!("crs-sim-cueing-{label}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let cfg = relaxed_configs_of(&out.join("cfg"), daemon, "drives.toml", monitor);
    let mut c = sim_command(&crs, "wire", &cfg, &out.join("run"));
    c.args([
        "--source",
        "cueing",
        "--vehicle",
        "config/vehicle/braking.csv",
        "--check",
        // Where the braking run ends: 0.15 mm seen on the nominal stack, 4e-5 mm on the
        // calibrated one (relaxed debug runs); 1 mm is ~6× the larger.
        "--max-static-error-mm",
        "1",
    ]);
    if let Some(p) = plant {
        c.args(["--plant", p]);
    }
    let o = c.output().expect("run crs sim");
    let text = format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        o.status.success(),
        "{label}: crs sim --source cueing failed:\n{text}"
    );
    assert!(text.contains("SIM-CHECK: PASS"), "{label}: {text}");
    let sum: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("run/summary.json")).expect("summary.json"),
    )
    .unwrap();
    assert_eq!(sum["estops"], 0, "{label}: {sum}");
    assert_eq!(sum["loop_rejected"], 0, "{label}: {sum}");
    let c = &sum["cueing"];
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    assert!(f(&c["drive_s"]) > 10.9, "{label}: {c}");
    assert!(
        f(&c["max_tilt_rate_deg_per_s"]) <= f(&c["tilt_rate_threshold_deg_per_s"]) + 1e-9,
        "{label}: tilt rate above the threshold: {c}"
    );
    // The braking's pitch tilt used the box; no coordinate beyond its edge (1 = edge).
    let used = c["workspace_use"].as_array().unwrap();
    assert!(
        f(&used[4]) > 0.5,
        "{label}: the pitch tilt barely moved: {c}"
    );
    assert!(
        used.iter().all(|u| f(u) <= 1.0 + 1e-6),
        "{label}: beyond the cueing box: {c}"
    );
    // Perception: numbers for the braking axis (x), the correlation defined and positive.
    let px = &c["perception"]["specific_force"][0]["perceived"];
    assert!(f(&px["rms_error"]).is_finite(), "{label}: {c}");
    assert!(
        f(&px["correlation"]) > 0.3,
        "{label}: perceived f_x barely correlates: {c}"
    );
    for svg in ["cueing-perception.svg", "cueing-motion.svg"] {
        let s = std::fs::read_to_string(out.join("run").join(svg)).expect(svg);
        assert!(s.contains("<polyline"), "{label}: {svg}");
    }
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn braking_runs_clean_on_the_nominal_stack() {
    let _one = common::one_stack();
    run("nominal", "motion-core.toml", "safety-monitor.toml", None);
}

#[test]
fn braking_runs_clean_on_the_calibrated_stack() {
    let _one = common::one_stack();
    let _ = root();
    run(
        "calibrated",
        "motion-core-calibrated.toml",
        "safety-monitor-calibrated.toml",
        Some("config/plant/icosahedron-assembly.toml"),
    );
}

#[test]
fn vehicle_errors_and_flag_mix_ups_are_refused_before_anything_starts() {
    let crs = PathBuf::from(env!("CARGO_BIN_EXE_crs"));
    let dir = std::env::temp_dir().join(format!("crs-cueing-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("drive.csv");
    std::fs::write(
        &bad,
        "t_s,f_x_m_per_s2,f_y_m_per_s2,f_z_m_per_s2,omega_x_rad_per_s,omega_y_rad_per_s,omega_z_rad_per_s\n0,0,0,9.81,0,0,0\n0.01,0,x,9.81,0,0,0\n",
    )
    .unwrap();
    let err = |args: &[&str]| {
        let o = std::process::Command::new(&crs)
            .current_dir(root())
            .arg("sim")
            .args(args)
            .arg("--out")
            .arg(dir.join("out"))
            .output()
            .unwrap();
        assert!(!o.status.success());
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    let e = err(&["--source", "cueing", "--vehicle", bad.to_str().unwrap()]);
    assert!(
        e.contains("drive.csv:3:3: column `f_y_m_per_s2`: not a number: `x`"),
        "{e}"
    );
    let e = err(&["--source", "cueing"]);
    assert!(e.contains("needs --vehicle"), "{e}");
    let e = err(&["--vehicle", "config/vehicle/braking.csv"]);
    assert!(e.contains("--vehicle needs --source cueing"), "{e}");
    let toml = dir.join("cueing.toml");
    std::fs::write(
        &toml,
        std::fs::read_to_string(root().join("config/cueing.toml"))
            .unwrap()
            .replace("rate_max_deg_per_s = 3.0", "rate_max_deg_per_s = 30.0"),
    )
    .unwrap();
    let e = err(&[
        "--source",
        "cueing",
        "--vehicle",
        "config/vehicle/braking.csv",
        "--cueing-config",
        toml.to_str().unwrap(),
    ]);
    assert!(
        e.contains("`tilt.rate_max_deg_per_s`: must lie in (0, 10]"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
