//! `crs model planar` and `crs model workspace --test both` as a user runs them (issue 17).

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
