//! The reports against the model they summarise: each figure a report shows is checked against
//! an independent computation or an invariant, so a report that mislabels or reorders figures
//! fails here.

use cdpr_model::config::load_platform;
use cdpr_model::workspace::FeasibilityTest;
use cdpr_model::{Data, Pose, kinematics};
use crs_test_support::fixtures::config;
use model_analysis::{kinematics as ik_fk, statics, truss, workspace};

#[test]
fn ik_report_lists_every_cable_with_the_model_lengths_and_fk_inverts_it() {
    let pf = load_platform(config("icosahedron.toml")).unwrap();
    let pose = Pose::new(
        nalgebra::Vector3::new(0.3, -0.2, pf.home.r.z + 0.1),
        nalgebra::Vector3::new(0.05, 0.0, -0.1),
    );
    let r = ik_fk::ik(&pf, &pose).unwrap();
    let v = r.json();
    let cables = v["cables"].as_array().unwrap();
    assert_eq!(cables.len(), pf.model.m());
    let mut d = Data::new(&pf.model);
    kinematics::inverse(&pf.model, &mut d, &pose).unwrap();
    for (i, c) in cables.iter().enumerate() {
        assert_eq!(c["cable"], i + 1);
        assert_eq!(c["length_m"].as_f64().unwrap(), d.q[i]);
    }
    // One table row per cable after the two header lines.
    assert_eq!(r.to_string().lines().count(), 2 + pf.model.m());
    // The forward kinematics of those lengths finds the pose again (eq. 2.11).
    let fk = ik_fk::fk(&pf, &d.q, false, &pf.home).unwrap();
    assert!((fk.solution.pose.r - pose.r).norm() < 1e-6, "{}", fk);
    assert!(fk.forces_n.is_none());
}

#[test]
fn forces_report_the_exact_test_accepts_what_the_closed_form_accepts() {
    let pf = load_platform(config("icosahedron.toml")).unwrap();
    let r = statics::forces(&pf, &pf.home).unwrap();
    assert!(r.closed_form.feasible, "home must be feasible:\n{r}");
    // eq. 3.41 is sufficient for eq. 3.29, so the exact margin is at least as large.
    assert!(r.exact.feasible && r.exact.margin >= r.closed_form.margin - 1e-6);
    // f = f_ext + f_int cable by cable.
    for i in 0..r.forces.len() {
        assert!((r.external[i] + r.internal[i] - r.forces[i]).abs() < 1e-6);
    }
    assert!(r.to_string().contains("verdict: FEASIBLE"));
}

#[test]
fn workspace_report_counts_match_its_csv_and_the_closed_form_is_a_subset() {
    let pf = load_platform(config("icosahedron.toml")).unwrap();
    let n = 4;
    let mut r = workspace::workspace(
        &pf,
        pf.region.position,
        [0.0; 3],
        n,
        false,
        &[FeasibilityTest::ClosedForm, FeasibilityTest::Exact],
    )
    .unwrap();
    let dir = std::env::temp_dir().join(format!("model-analysis-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("grid.csv");
    r.write_csv(&csv).unwrap();
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<&str> = text.lines().skip(1).collect();
    assert_eq!(rows.len(), n * n * n);
    let count = |col: usize| {
        rows.iter()
            .filter(|l| l.split(',').nth(col) == Some("true"))
            .count()
    };
    assert_eq!(count(3), r.runs[0].grid.feasible);
    assert_eq!(count(5), r.runs[1].grid.feasible);
    // Every closed-form point is feasible by the exact test too.
    for l in &rows {
        let c: Vec<&str> = l.split(',').collect();
        assert!(c[3] != "true" || c[5] == "true", "{l}");
    }
    assert_eq!(r.json()["feasible"], r.runs[0].grid.feasible);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn truss_worst_case_is_at_least_the_home_pose() {
    let pf = load_platform(config("icosahedron.toml")).unwrap();
    let req = truss::TrussRequest {
        pose: pf.home,
        worst_case: false,
        joint_load_n: 0.0,
        rod_ea_n: cdpr_analysis::truss::ROD_EA_DEFAULT_N,
    };
    let home = truss::truss(&pf, &req).unwrap();
    let worst = truss::truss(
        &pf,
        &truss::TrussRequest {
            worst_case: true,
            ..req
        },
    )
    .unwrap();
    assert_eq!(home.poses, 1);
    assert_eq!(worst.poses, 5 * 5 * 5 * 7);
    assert!(worst.utilisation() >= home.utilisation());
    let (j, f) = home.evaluated.worst;
    let max = home
        .evaluated
        .sol
        .member_forces
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    assert_eq!(f.abs(), max);
    assert_eq!(home.json()["worst_member"], j + 1);
}

#[test]
fn a_written_file_is_named_in_the_table_not_in_the_json() {
    let pf = load_platform(config("icosahedron.toml")).unwrap();
    let mut r = workspace::workspace(
        &pf,
        pf.region.position,
        [0.0; 3],
        2,
        false,
        &[FeasibilityTest::ClosedForm],
    )
    .unwrap();
    assert!(!r.to_string().contains("grid written to"));
    let p = std::env::temp_dir().join(format!("model-analysis-w-{}.csv", std::process::id()));
    r.write_csv(&p).unwrap();
    assert!(
        r.to_string()
            .ends_with(&format!("grid written to {}\n", p.display()))
    );
    assert!(!r.json().to_string().contains("written"));
    std::fs::remove_file(p).ok();
}
