//! The helicopter cabin on the stack: `crs sim --platform helicopter` picks
//! the helicopter's daemon, plant, monitor and drives configs and runs its demo tour clean
//! (`--check`: trajectory completed, no e-stop, every plant step converged, forces within
//! [f_min, f_max], static error, no rejected reference, no drive fault, no bus stop). The full
//! run uses the real binaries on the CAN-over-UDP loopback bus with the relaxed timing of the
//! other stack tests (debug builds on a shared host; see tests/common). Also: the helicopter's
//! daemon and monitor TOML are the icosahedron's with only the platform (and tour) swapped, its
//! tour lies in its operating region, and a wrong or contradictory platform choice is refused
//! before anything starts.
mod common;
use cdpr_model::config::load_platform;
use common::{relaxed_configs_of, root, sim_command, stack_bin_dir};
use std::path::PathBuf;
use std::process::Command;

fn crs() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_crs"))
}

#[test]
fn crs_sim_platform_helicopter_runs_its_tour_clean() {
    let crs = crs();
    stack_bin_dir(&crs);
    let out = std::env::temp_dir().join(format!("crs-sim-heli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let cfg = relaxed_configs_of(
        &out.join("cfg"),
        "motion-core-helicopter.toml",
        "drives.toml",
        "safety-monitor-helicopter.toml",
    );
    // The plant is not given: --platform helicopter must pick config/plant/helicopter.toml.
    let o = sim_command(&crs, "wire", &cfg, &out.join("run"))
        // The tour ends at home, at rest: 0.41 / 0.44 mm seen (relaxed debug runs); 2 mm is ~4.5×.
        .args([
            "--platform",
            "helicopter",
            "--check",
            "--max-static-error-mm",
            "2",
        ])
        .output()
        .expect("run crs sim");
    let text = format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        o.status.success(),
        "crs sim --platform helicopter failed:\n{text}"
    );
    assert!(text.contains("SIM-CHECK: PASS"), "{text}");
    assert!(
        !text.contains("note: the plant"),
        "plant of another platform:\n{text}"
    );
    let sum: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("run/summary.json")).expect("summary.json"),
    )
    .unwrap();
    let pf = load_platform(root().join("config/helicopter.toml")).unwrap();
    assert_eq!(sum["platform"], pf.name.as_str(), "{sum}");
    assert_eq!(sum["estops"], 0, "{sum}");
    assert_eq!(sum["loop_rejected"], 0, "{sum}");
    assert_eq!(sum["monitor"], true, "{sum}");
    let p = pf.model.params();
    let (lo, hi) = (
        sum["force_min_n"].as_f64().unwrap(),
        sum["force_max_n"].as_f64().unwrap(),
    );
    assert!(
        lo >= p.f_min && hi <= p.f_max,
        "forces {lo} … {hi} N: {sum}"
    );
    assert!(sum["setpoints"].as_u64().unwrap() > 1000, "{sum}");
    let _ = std::fs::remove_dir_all(&out);
}

/// The helicopter's daemon and monitor TOML must not drift from the icosahedron's: the same
/// lines except the platform (and the daemon's tour) and the leading comment.
#[test]
fn helicopter_configs_differ_from_the_icosahedrons_only_in_the_platform() {
    let body = |name: &str| -> Vec<String> {
        std::fs::read_to_string(root().join("config").join(name))
            .unwrap()
            .lines()
            .skip_while(|l| l.starts_with('#'))
            .filter(|l| !l.starts_with("platform = ") && !l.starts_with("waypoints = "))
            // The accepted platform's hash differs with the platform (the monitor pins it).
            .filter(|l| !l.starts_with("platform_sha256 = "))
            .filter(|l| !l.starts_with("# Demo"))
            .map(str::to_string)
            .collect()
    };
    for (ico, heli) in [
        ("motion-core.toml", "motion-core-helicopter.toml"),
        ("safety-monitor.toml", "safety-monitor-helicopter.toml"),
    ] {
        assert_eq!(body(ico), body(heli), "{heli} drifted from {ico}");
        let platform_line = |name: &str| {
            std::fs::read_to_string(root().join("config").join(name))
                .unwrap()
                .lines()
                .find(|l| l.starts_with("platform = "))
                .unwrap()
                .to_string()
        };
        assert_eq!(platform_line(heli), "platform = \"helicopter.toml\"");
    }
}

/// Every waypoint of the helicopter's demo tour lies in its operating region and the hard
/// loop's closed form (eq. 3.41) accepts it with a margin (motion-core checks the planned path
/// at start; the run above checks the plant).
#[test]
fn the_helicopter_tour_lies_in_its_region() {
    let pf = load_platform(root().join("config/helicopter.toml")).unwrap();
    let wps = motion_core::daemon::trajectory::read_waypoints(
        &root().join("config/demo-waypoints-helicopter.csv"),
    )
    .unwrap();
    assert!(wps.len() >= 4);
    let model = &pf.model;
    let p = model.params();
    let mut data = cdpr_model::Data::new(model);
    let mut f = vec![0.0; model.m()];
    for w in &wps {
        assert!(
            pf.region.contains(&w.pose),
            "{:?} outside the region",
            w.pose
        );
        cdpr_model::kinematics::inverse(model, &mut data, &w.pose).unwrap();
        cdpr_model::statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f).unwrap();
        let (lo, hi) = f
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                (a.min(*x), b.max(*x))
            });
        assert!(
            lo >= p.f_min + 500.0 && hi <= p.f_max - 500.0,
            "{:?}: forces {lo:.0} … {hi:.0} N",
            w.pose
        );
    }
    // The tour starts near home and ends there.
    let last = wps.last().unwrap().pose;
    assert!((last.r - pf.home.r).norm() < 1e-9 && last.phi.norm() < 1e-9);
}

#[test]
fn a_wrong_or_contradictory_platform_choice_is_refused_before_anything_starts() {
    // The monitor check needs the monitor built (without it the run is refused for that).
    stack_bin_dir(&crs());
    let run = |args: &[&str]| {
        let o = Command::new(crs())
            .current_dir(root())
            .arg("sim")
            .args(args)
            .args(["--transport", "wire", "--out"])
            .arg(std::env::temp_dir().join(format!("crs-sim-heli-no-{}", std::process::id())))
            .output()
            .expect("run crs sim");
        assert!(!o.status.success());
        let text = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(
            !String::from_utf8_lossy(&o.stdout).contains("started"),
            "something started"
        );
        text
    };
    let e = run(&["--platform", "zeppelin"]);
    assert!(
        e.contains("zeppelin") && e.contains("icosahedron, helicopter"),
        "{e}"
    );
    let e = run(&["--platform", "config/crs-nominal.toml"]);
    assert!(e.contains("no stack configuration"), "{e}");
    let e = run(&[
        "--platform",
        "helicopter",
        "--config",
        "config/motion-core.toml",
    ]);
    assert!(e.contains("leave one out"), "{e}");
    let e = run(&[
        "--platform",
        "helicopter",
        "--monitor-config",
        "config/safety-monitor.toml",
    ]);
    assert!(e.contains("[monitor] platform"), "{e}");
}
