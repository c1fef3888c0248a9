//! `crs model planar` and `crs model workspace --test both` as a user runs them.

use std::process::Command;

fn crs_json(args: &[&str]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_crs"))
        .args(args)
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .output()
        .expect("run crs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

#[test]
fn planar_report_reproduces_the_spec_condition_numbers() {
    let v = crs_json(&["model", "planar", "--json"]);
    assert!((v["cond_j_qa_w_t1"].as_f64().unwrap() - 3.2).abs() < 0.05);
    assert!((v["cond_j_qa_w_t2"].as_f64().unwrap() - 19.3).abs() < 0.05);
    let (wr, wp) = (
        v["w_r_m2"].as_f64().unwrap(),
        v["w_phys_exact_m2"].as_f64().unwrap(),
    );
    assert!(wr > 0.0 && wr < wp && v["w_phys_closed_form_m2"].as_f64().unwrap() < wp);
    // Tighter force limits shrink the physical workspace.
    let tight = crs_json(&["model", "planar", "--json", "--f-max-n", "3000"]);
    assert!(tight["w_phys_exact_m2"].as_f64().unwrap() < wp);
}

#[test]
fn planar_refuses_a_bad_grid_and_bad_limits_by_name() {
    for (args, needle) in [
        (vec!["model", "planar", "--grid-m", "0"], "--grid-m"),
        (vec!["model", "planar", "--f-min-n", "9000"], "f_min"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_crs"))
            .args(&args)
            .output()
            .unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

#[test]
fn workspace_both_tests_side_by_side() {
    let v = crs_json(&[
        "model",
        "workspace",
        "--json",
        "--test",
        "both",
        "--resolution",
        "7",
        "--min-m=-4,-5,0",
        "--max-m=4,6,6",
    ]);
    let cf = v["closed_form"]["feasible"].as_u64().unwrap();
    let ex = v["exact"]["feasible"].as_u64().unwrap();
    assert!(cf < ex, "closed form {cf} vs exact {ex}");
    assert_eq!(
        v["feasible"], v["closed_form"]["feasible"],
        "top level keeps the first test"
    );
}

#[test]
fn truss_worst_case_reports_the_rating_and_joint_loads_raise_it() {
    let base = crs_json(&["model", "truss", "--worst-case", "--json"]);
    let loaded = crs_json(&[
        "model",
        "truss",
        "--worst-case",
        "--json",
        "--joint-load-n",
        "10000",
    ]);
    assert_eq!(base["rating_n"].as_f64(), Some(151_000.0));
    assert_eq!(base["member_forces_n"].as_array().unwrap().len(), 30);
    let (u0, u1) = (
        base["utilisation"].as_f64().unwrap(),
        loaded["utilisation"].as_f64().unwrap(),
    );
    assert!(u0 > 0.0 && u0 < u1 && u1 < 1.0, "{u0} {u1}");
    assert_eq!(base["poses_failed"].as_u64(), Some(0));
    // Cable loads balance: the supports carry nothing; 12 × 10 kN come back as reaction.
    let r0: f64 = base["reaction_sum_n"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap().abs())
        .sum();
    assert!(r0 < 1.0, "{r0}");
}

#[test]
fn reachable_workspace_prediction_matches_the_ideal_plant() {
    // The ideal plant is the model's own elastostatics run by sim-plant's solver: prediction
    // (model library) and measurement (plant) must agree almost everywhere, and W_R lies inside
    // the exact W_WF (eq. 3.33 ⊂ 3.29).
    let v = crs_json(&[
        "model",
        "workspace",
        "--reachable",
        "--json",
        "--resolution",
        "5",
        "--plant",
        "config/plant/icosahedron-ideal.toml",
    ]);
    let pred = v["reachable_predicted"].as_u64().unwrap();
    let exact = v["exact_feasible"].as_u64().unwrap();
    assert!(pred > 0 && pred < exact, "W_R {pred} of W_WF {exact}");
    let plant = &v["plant"];
    assert!(plant["agreement"].as_f64().unwrap() >= 0.97, "{plant}");
    assert!(
        plant["sensitivity_rel_error_median"].as_f64().unwrap() < 0.01,
        "{plant}"
    );
    assert_eq!(v["predicted_fk_failures"].as_u64(), Some(0));
    // The linear prediction of eq. (3.24) is close to the full FK inside the region (fig. 3.11b).
    let (lin, err) = (
        v["linearisation_error_mean_m"].as_f64().unwrap(),
        v["predicted_mean_error_m"].as_f64().unwrap(),
    );
    assert!(
        err > 1e-3 && lin < 0.1 * err,
        "linearisation {lin} m vs error {err} m"
    );
}

#[test]
fn sensitivity_report_is_linear_in_the_errors_and_its_groups_add_up() {
    let base = [
        "model",
        "sensitivity",
        "--json",
        "--platform",
        "config/crs-nominal.toml",
    ];
    let v = crs_json(&[&base[..], &["--map-resolution", "3"]].concat());
    let rms = v["rms_position_m"].as_f64().unwrap();
    let g = &v["groups_rms_position_m"];
    let sum_sq: f64 = ["frame_anchors", "platform_anchors", "stiffness"]
        .iter()
        .map(|k| g[k].as_f64().unwrap().powi(2))
        .sum();
    // Independent groups: the variances add (E‖Δr‖² = Σ ‖∂r/∂p_j‖² σ_j²).
    assert!(rms > 1e-4 && (sum_sq.sqrt() - rms).abs() < 1e-9 * rms.max(1.0));
    assert_eq!(v["parameters"].as_array().unwrap().len(), 7 * 8);
    let map = &v["map"];
    assert_eq!(map["points"].as_u64(), Some(27));
    assert_eq!(
        map["estimated"].as_u64().unwrap()
            + map["not_wrench_feasible"].as_u64().unwrap()
            + map["failed"].as_u64().unwrap(),
        27
    );
    // Doubling every σ doubles the expected error; no stiffness error removes its group.
    let v2 = crs_json(
        &[
            &base[..],
            &[
                "--frame-anchor-sigma-mm",
                "2",
                "--platform-anchor-sigma-mm",
                "2",
                "--stiffness-sigma-pct",
                "10",
            ],
        ]
        .concat(),
    );
    assert!((v2["rms_position_m"].as_f64().unwrap() / rms - 2.0).abs() < 1e-9);
    let v0 = crs_json(&[&base[..], &["--stiffness-sigma-pct", "0"]].concat());
    assert_eq!(v0["groups_rms_position_m"]["stiffness"].as_f64(), Some(0.0));
    assert!(v0["rms_position_m"].as_f64().unwrap() < rms);
}

#[test]
fn sensitivity_refuses_bad_errors_and_infeasible_poses_by_name() {
    for (args, needle) in [
        (
            vec!["model", "sensitivity", "--frame-anchor-sigma-mm", "-1"],
            "--frame-anchor-sigma-mm",
        ),
        (
            vec!["model", "sensitivity", "--position-m", "0,0,40"],
            "not wrench feasible",
        ),
        (
            vec!["model", "sensitivity", "--map-resolution", "1"],
            "--map-resolution",
        ),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_crs"))
            .args(&args)
            .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
            .output()
            .expect("run crs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(needle),
            "{args:?}: {err}"
        );
        assert!(out.stdout.is_empty(), "{args:?} printed a result");
    }
}
