//! Forward kinematics round trips, model equivalences, statics and the spec's figures.
mod common;

use cdpr_model::elastostatics::{self, ConstantStiffness};
use cdpr_model::forward::{self, FkError, FkOptions};
use cdpr_model::kinematics;
use cdpr_model::statics;
use cdpr_model::{Data, Pose};
use common::*;
use nalgebra::{Vector3, Vector6};

fn guess_off(pose: &Pose) -> Pose {
    // 1 cm / 1° away in every coordinate.
    let d = 1f64.to_radians();
    Pose::new(
        pose.r + Vector3::new(0.01, -0.01, 0.01),
        pose.phi + Vector3::new(d, -d, d),
    )
}

#[test]
fn test_poses_are_wrench_feasible() {
    for model in [icosahedron(), pulley_model()] {
        let mut data = Data::new(&model);
        let mut f = vec![0.0; model.m()];
        for pose in test_poses() {
            let fd = cdpr_model::workspace::check_pose(&model, &mut data, &pose, &mut f).unwrap();
            assert!(
                fd.feasible,
                "{pose:?}: forces {:.0}..{:.0} N",
                fd.f_lo, fd.f_hi
            );
        }
    }
}

#[test]
fn ik_fk_round_trip_standard_and_pulley() {
    for model in [icosahedron(), pulley_model()] {
        let mut data = Data::new(&model);
        for pose in test_poses() {
            kinematics::inverse(&model, &mut data, &pose).unwrap();
            let q = data.q.clone();
            let sol = forward::least_squares(
                &model,
                &mut data,
                &q,
                &guess_off(&pose),
                &FkOptions::default(),
            )
            .unwrap();
            let (dr, dphi) = sol.pose.error_to(&pose);
            assert!(
                dr < 1e-10 && dphi < 1e-10,
                "round trip error {dr:e} m {dphi:e} rad"
            );
            assert!(sol.iterations <= 10, "took {} iterations", sol.iterations);
        }
    }
}

#[test]
fn zero_pulley_radius_equals_standard_model_exactly() {
    // eq. (2.1): φ_pl(x, r_p = 0) = φ(x) for all x, bit for bit.
    let std_model = icosahedron();
    let zero = pulley_model()
        .with_params(|p| {
            p.pulleys
                .as_mut()
                .unwrap()
                .radius
                .iter_mut()
                .for_each(|r| *r = 0.0)
        })
        .unwrap();
    let mut d1 = Data::new(&std_model);
    let mut d2 = Data::new(&zero);
    for pose in test_poses() {
        kinematics::inverse(&std_model, &mut d1, &pose).unwrap();
        kinematics::inverse(&zero, &mut d2, &pose).unwrap();
        assert_eq!(d1.q, d2.q);
        assert_eq!(d1.at, d2.at);
    }
    // ... and a real pulley changes the lengths by a visible amount.
    let pl = pulley_model();
    let mut d3 = Data::new(&pl);
    kinematics::inverse(&pl, &mut d3, &test_poses()[0]).unwrap();
    kinematics::inverse(&std_model, &mut d1, &test_poses()[0]).unwrap();
    let max_dq =
        d1.q.iter()
            .zip(&d3.q)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
    assert!(
        max_dq > 0.05,
        "r_p = 161 mm should change lengths by cm, got {max_dq}"
    );
}

#[test]
fn elastostatic_fk_with_unit_stiffness_and_no_load_is_least_squares_fk() {
    // Remark at eq. (2.81): ν_el with K = I and w_e = 0 equals ν.
    let model = icosahedron();
    let ones = vec![1.0; model.m()];
    let law = ConstantStiffness { k: &ones };
    let mut data = Data::new(&model);
    for pose in test_poses() {
        kinematics::inverse(&model, &mut data, &pose).unwrap();
        // Inconsistent lengths (all cables stretched, by different amounts).
        let q_theta: Vec<f64> = data
            .q
            .iter()
            .enumerate()
            .map(|(i, q)| q - 0.02 - 0.001 * i as f64)
            .collect();
        let ls = forward::least_squares(&model, &mut data, &q_theta, &pose, &FkOptions::default())
            .unwrap();
        // Every cable stays stretched at the solution, so no cable goes slack in ν_el.
        assert!(data.q.iter().zip(&q_theta).all(|(q, qt)| q > qt));
        let el = forward::elastostatic_with_law(
            &model,
            &mut data,
            &law,
            &Vector6::zeros(),
            &q_theta,
            &pose,
            &FkOptions::default(),
        )
        .unwrap();
        let (dr, dphi) = ls.pose.error_to(&el.pose);
        assert!(
            dr < 1e-10 && dphi < 1e-10,
            "ν vs ν_el: {dr:e} m {dphi:e} rad"
        );
        assert!(
            ls.residual_norm > 1e-3,
            "the test must use inconsistent lengths"
        );
    }
}

#[test]
fn elastostatic_inverse_then_forward_returns_pose_and_forces() {
    // φ_el (eq. 2.37) with f_ref (eq. 3.41), then ν_el (eq. 2.42): same pose, same forces.
    for model in [icosahedron(), pulley_model()] {
        let p = model.params().clone();
        let mut data = Data::new(&model);
        for pose in test_poses() {
            let mut f = vec![0.0; model.m()];
            kinematics::inverse(&model, &mut data, &pose).unwrap();
            statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f).unwrap();
            let mut q_theta = vec![0.0; model.m()];
            elastostatics::inverse(&model, &mut data, &pose, &f, &mut q_theta).unwrap();
            let sol = forward::elastostatic(
                &model,
                &mut data,
                &q_theta,
                &guess_off(&pose),
                &FkOptions::default(),
            )
            .unwrap();
            let (dr, dphi) = sol.pose.error_to(&pose);
            assert!(
                dr < 1e-10 && dphi < 1e-10,
                "ν_el∘φ_el: {dr:e} m {dphi:e} rad"
            );
            for (fa, fb) in data.f.iter().zip(&f) {
                assert!((fa - fb).abs() < 1e-5, "force {fa} vs {fb}");
            }
        }
    }
}

#[test]
fn kinematic_command_on_elastic_model_moves_the_platform() {
    // Force propagation (eq. 3.24): commanding φ(x) − q_off with tension set at the home pose
    // does not land exactly on x elsewhere; ν_el must say so rather than return x.
    let model = icosahedron();
    let p = model.params().clone();
    let home = Pose::new(Vector3::new(0.0, 0.0, 2.0), Vector3::zeros());
    let mut data = Data::new(&model);
    let mut f = vec![0.0; model.m()];
    kinematics::inverse(&model, &mut data, &home).unwrap();
    statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f).unwrap();
    let q_home = data.q.clone();
    let mut qt_home = vec![0.0; model.m()];
    elastostatics::inverse(&model, &mut data, &home, &f, &mut qt_home).unwrap();
    let q_off: Vec<f64> = qt_home.iter().zip(&q_home).map(|(a, b)| a - b).collect();
    let target = Pose::new(Vector3::new(1.2, 1.0, 1.5), Vector3::zeros());
    kinematics::inverse(&model, &mut data, &target).unwrap();
    let q_theta: Vec<f64> = data.q.iter().zip(&q_off).map(|(q, o)| q + o).collect();
    let sol =
        forward::elastostatic(&model, &mut data, &q_theta, &target, &FkOptions::default()).unwrap();
    let (dr, _) = sol.pose.error_to(&target);
    assert!(
        dr > 1e-4 && dr < 0.05,
        "expected mm-level drift, got {dr} m"
    );
}

#[test]
fn closed_form_forces_satisfy_wrench_closure() {
    // eq. (3.41) satisfies A^T f + w_e = 0 (eq. 2.31) and splits by eq. (2.38)-(2.40).
    let model = icosahedron();
    let p = model.params().clone();
    let mut data = Data::new(&model);
    for pose in test_poses() {
        kinematics::inverse(&model, &mut data, &pose).unwrap();
        let mut f = vec![0.0; model.m()];
        let fd = statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f).unwrap();
        assert!(statics::residual_wrench(&data, &f, &p.w_e).amax() < 1e-8);
        assert!(fd.f_lo <= fd.f_hi);
        let (mut fe, mut fi) = (vec![0.0; model.m()], vec![0.0; model.m()]);
        statics::split_internal_external(&data, &p.w_e, &f, &mut fe, &mut fi).unwrap();
        assert!(
            statics::cable_wrench(&data, &fi).amax() < 1e-8,
            "f_int lies in ker A^T"
        );
        for k in 0..model.m() {
            assert!((fe[k] + fi[k] - f[k]).abs() < 1e-8);
        }
        let h = statics::nullspace_basis(&data);
        assert_eq!(h.shape(), (model.m(), model.m() - 6));
        assert!((statics::structure_matrix(&data) * &h).amax() < 1e-10);
        assert!((h.transpose() * &h - nalgebra::DMatrix::identity(2, 2)).amax() < 1e-10);
        // φ_el(x, w_e, λ) (eq. 2.41): the forces it realises close the wrench.
        let mut qt = vec![0.0; model.m()];
        let used = elastostatics::inverse_wrench_lambda(
            &model,
            &mut data,
            &pose,
            &p.w_e,
            &[1000.0, 2000.0],
            &mut qt,
        )
        .unwrap();
        kinematics::inverse(&model, &mut data, &pose).unwrap();
        assert!(statics::residual_wrench(&data, &used, &p.w_e).amax() < 1e-8);
    }
}

#[test]
fn helicopter_forces_and_section_wrenches_match_the_spec() {
    // eq. (5.11)-(5.20): x = [0 0 2.5 0 0 0], w_e = [0 0 −7500 0 −600 327], f in [1000, 9000].
    // The text says frame a of eq. (5.8); the printed forces reproduce to the newton with the
    // laser-tracker frame a_N of eq. (6.1) instead (with eq. 5.8 they differ by up to 206 N).
    let pf = platform("helicopter.toml");
    let a_n = platform("crs-nominal.toml").model.params().a.clone();
    let model = pf.model.with_params(|p| p.a = a_n).unwrap();
    let mut data = Data::new(&model);
    let pose = Pose::new(Vector3::new(0.0, 0.0, 2.5), Vector3::zeros());
    kinematics::inverse(&model, &mut data, &pose).unwrap();
    let w_e = Vector6::new(0.0, 0.0, -7500.0, 0.0, -600.0, 327.0);
    let mut f = vec![0.0; 8];
    let fd = statics::force_distribution(&data, &w_e, 1000.0, 9000.0, &mut f).unwrap();
    assert!(fd.feasible);
    let spec = [
        7491.0, 2431.0, 7146.0, 3049.0, 7929.0, 3156.0, 8360.0, 2679.0,
    ]; // eq. (5.18)
    for (i, (a, b)) in f.iter().zip(spec).enumerate() {
        assert!(
            (a - b).abs() < 1.0,
            "cable {}: {a:.0} N vs spec {b} N",
            i + 1
        );
    }
    let upper = &pf
        .sections
        .iter()
        .find(|s| s.name == "upper")
        .unwrap()
        .cables;
    let lower = &pf
        .sections
        .iter()
        .find(|s| s.name == "lower")
        .unwrap()
        .cables;
    let w1 = statics::section_wrench(&data, &f, upper);
    let w2 = statics::section_wrench(&data, &f, lower);
    let w1_spec = [-728.0, -100.0, 10472.0, -156.0, 829.0, -372.0]; // eq. (5.19)
    let w2_spec = [728.0, 100.0, -2972.0, 156.0, -229.0, 45.0]; // eq. (5.20)
    for k in 0..6 {
        assert!(
            (w1[k] - w1_spec[k]).abs() < 1.0,
            "w_A1[{k}] = {:.0} vs {}",
            w1[k],
            w1_spec[k]
        );
        assert!(
            (w2[k] - w2_spec[k]).abs() < 1.0,
            "w_A2[{k}] = {:.0} vs {}",
            w2[k],
            w2_spec[k]
        );
    }
}

#[test]
fn non_convergence_is_an_error_not_a_pose() {
    let model = icosahedron();
    let mut data = Data::new(&model);
    let pose = test_poses()[1];
    kinematics::inverse(&model, &mut data, &pose).unwrap();
    // Every cable 1 m longer than needed: all slack, no equilibrium.
    let q_theta: Vec<f64> = data.q.iter().map(|q| q + 1.0).collect();
    let err = forward::elastostatic(&model, &mut data, &q_theta, &pose, &FkOptions::default())
        .unwrap_err();
    assert_eq!(err, FkError::AllSlack);
    // An iteration budget too small to converge from far away.
    kinematics::inverse(&model, &mut data, &pose).unwrap();
    let q = data.q.clone();
    let far = Pose::new(
        pose.r + Vector3::new(1.0, -1.0, 0.5),
        Vector3::new(0.3, 0.2, -0.3),
    );
    let opts = FkOptions {
        max_iterations: 2,
        ..FkOptions::default()
    };
    assert!(matches!(
        forward::least_squares(&model, &mut data, &q, &far, &opts),
        Err(FkError::NotConverged { .. })
    ));
    assert!(matches!(
        forward::elastostatic(&model, &mut data, &q, &far, &opts),
        Err(FkError::NotConverged { .. })
    ));
    // Bad input is named.
    assert!(matches!(
        forward::least_squares(&model, &mut data, &q[..7], &pose, &opts),
        Err(FkError::WrongLength { .. })
    ));
    let mut nan = q.clone();
    nan[3] = f64::NAN;
    assert_eq!(
        forward::least_squares(&model, &mut data, &nan, &pose, &opts),
        Err(FkError::NonFiniteInput { cable: 3 })
    );
}

#[test]
fn workspace_sampler_and_hull_agree() {
    let pf = platform("icosahedron.toml");
    let model = &pf.model;
    let hull =
        cdpr_model::workspace::hull(model, &pf.home.r, &Vector3::zeros(), 2, 8.0, 1e-3).unwrap();
    // Grid over the hull's bounding box, padded, so both see the whole workspace.
    let mut bounds = cdpr_model::workspace::PositionBox {
        min: hull.center,
        max: hull.center,
    };
    for v in &hull.vertices {
        bounds.min = bounds.min.inf(v);
        bounds.max = bounds.max.sup(v);
    }
    bounds.min -= Vector3::repeat(0.3);
    bounds.max += Vector3::repeat(0.3);
    let g = cdpr_model::workspace::sample_grid(model, &bounds, &Vector3::zeros(), [25, 25, 25]);
    assert!(
        g.fraction > 0.05 && g.fraction < 0.95,
        "fraction {}",
        g.fraction
    );
    assert!(!g.boundary.is_empty());
    let rel = (hull.volume - g.volume).abs() / g.volume;
    assert!(
        rel < 0.1,
        "hull {:.2} m³ vs grid {:.2} m³",
        hull.volume,
        g.volume
    );
    // Every hull vertex is feasible, a step outward is not.
    let mut data = Data::new(model);
    let mut f = vec![0.0; 8];
    for v in &hull.vertices {
        let d = (v - hull.center).normalize();
        let inside = cdpr_model::workspace::check_pose(
            model,
            &mut data,
            &Pose::new(*v, Vector3::zeros()),
            &mut f,
        );
        assert!(inside.unwrap().feasible);
        let out = cdpr_model::workspace::check_pose(
            model,
            &mut data,
            &Pose::new(v + d * 0.01, Vector3::zeros()),
            &mut f,
        );
        assert!(out.map(|fd| !fd.feasible).unwrap_or(true) || (v - hull.center).norm() > 7.9);
    }
}
