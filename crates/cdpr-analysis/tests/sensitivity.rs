//! Pose sensitivity to parameter errors (eq. 3.28) against the full elastostatic forward
//! kinematics (eq. 2.42) of a robot whose parameters really differ: the linear prediction
//! J_xp Δp must match where the perturbed robot settles, and the RMS estimate must match a
//! Monte-Carlo of such robots.

// The model library's test helpers (shipped platforms, feasible test poses), shared, not copied.
#[path = "../../cdpr-model/tests/common/mod.rs"]
mod common;
use cdpr_analysis::sensitivity::{self, Parameter, ParameterErrors};
use cdpr_model::forward::{self, FkOptions};
use cdpr_model::{Data, Model, Pose, elastostatics};
use rand::{Rng, SeedableRng};

/// Standard normal sample (Box–Muller), so the test needs no distribution crate.
fn normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.random_range(1e-12..1.0);
    let u2: f64 = rng.random_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

fn perturbed(model: &Model, params: &[Parameter], dp: &[f64]) -> Model {
    model
        .with_params(|p| {
            for (par, d) in params.iter().zip(dp) {
                match *par {
                    Parameter::FrameAnchor { cable, axis } => p.a[cable][axis] += d,
                    Parameter::PlatformAnchor { cable, axis } => p.b[cable][axis] += d,
                    Parameter::Stiffness { cable } => p.k_f[cable] += d,
                }
            }
        })
        .unwrap()
}

/// Where the robot `truth` settles when commanded the lengths `model` computes for (x, f).
fn settled(model: &Model, truth: &Model, x: &Pose, f: &[f64]) -> Pose {
    let mut d = Data::new(model);
    let mut q_theta = vec![0.0; model.m()];
    elastostatics::inverse(model, &mut d, x, f, &mut q_theta).unwrap();
    let mut dt = Data::new(truth);
    forward::elastostatic(truth, &mut dt, &q_theta, x, &FkOptions::default())
        .unwrap()
        .pose
}

fn draw(model: &Model, params: &[Parameter], e: &ParameterErrors, rng: &mut impl Rng) -> Vec<f64> {
    params
        .iter()
        .map(|p| {
            normal(rng)
                * match *p {
                    Parameter::FrameAnchor { .. } => e.frame_anchor_m,
                    Parameter::PlatformAnchor { .. } => e.platform_anchor_m,
                    Parameter::Stiffness { cable } => e.stiffness_rel * model.params().k_f[cable],
                }
        })
        .collect()
}

const ERRORS: ParameterErrors = ParameterErrors {
    frame_anchor_m: 2e-3,
    platform_anchor_m: 1e-3,
    stiffness_rel: 0.05,
};

#[test]
fn linear_prediction_matches_the_perturbed_robots_forward_kinematics() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(28);
    for model in [common::icosahedron(), common::pulley_model()] {
        for x in common::test_poses() {
            let f = sensitivity::commanded_forces(&model, &x).unwrap();
            let s = sensitivity::parameter_sensitivity(&model, &x, &f).unwrap();
            assert_eq!(s.j_xp.ncols(), 7 * model.m());
            for _ in 0..5 {
                // 1 % stiffness errors: Δx is bilinear in Δk_F and the compliance, so the
                // second-order term is ~σ_kF of the stiffness part (5 % would need 5 %).
                let e = ParameterErrors {
                    stiffness_rel: 0.01,
                    ..ERRORS
                };
                let dp = draw(&model, &s.params, &e, &mut rng);
                let truth = perturbed(&model, &s.params, &dp);
                let xs = settled(&model, &truth, &x, &f);
                let dr_fk = xs.r - x.r;
                let pred = s.predict(&dp);
                let dr_lin = nalgebra::Vector3::new(pred[0], pred[1], pred[2]);
                // Second-order terms of mm-sized errors are µm; 3 % + 5 µm bounds them.
                let err = (dr_fk - dr_lin).norm();
                assert!(
                    err <= 0.03 * dr_fk.norm() + 5e-6,
                    "pose {:?}: FK moved {:.3} mm, eq. 3.28 predicts {:.3} mm (diff {:.4} mm)",
                    x.r,
                    dr_fk.norm() * 1e3,
                    dr_lin.norm() * 1e3,
                    err * 1e3
                );
                assert!(dr_fk.norm() > 1e-5, "the errors must move the platform");
            }
        }
    }
}

#[test]
fn each_parameter_column_matches_a_one_parameter_perturbation() {
    let model = common::icosahedron();
    let x = common::test_poses()[1];
    let f = sensitivity::commanded_forces(&model, &x).unwrap();
    let s = sensitivity::parameter_sensitivity(&model, &x, &f).unwrap();
    for (j, par) in s.params.iter().enumerate() {
        let h = match par {
            Parameter::Stiffness { cable } => 0.01 * model.params().k_f[*cable],
            _ => 1e-3,
        };
        let mut dp = vec![0.0; s.params.len()];
        dp[j] = h;
        let xs = settled(&model, &perturbed(&model, &s.params, &dp), &x, &f);
        let got = (xs.r - x.r) / h;
        let col = s.j_xp.column(j);
        let want = nalgebra::Vector3::new(col[0], col[1], col[2]);
        assert!(
            (got - want).norm() <= 0.03 * want.norm() + 1e-9 / h.max(1e-3),
            "{}: FK {got:?} vs J_xp {want:?}",
            par.name()
        );
    }
}

#[test]
fn rms_estimate_matches_a_monte_carlo_of_perturbed_robots() {
    let model = common::icosahedron();
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    for x in common::test_poses().into_iter().take(3) {
        let f = sensitivity::commanded_forces(&model, &x).unwrap();
        let s = sensitivity::parameter_sensitivity(&model, &x, &f).unwrap();
        let est = s.pose_error(&model, &ERRORS);
        let n = 200;
        let mut ms = 0.0;
        for _ in 0..n {
            let dp = draw(&model, &s.params, &ERRORS, &mut rng);
            let xs = settled(&model, &perturbed(&model, &s.params, &dp), &x, &f);
            ms += (xs.r - x.r).norm_squared();
        }
        let rms_mc = (ms / n as f64).sqrt();
        let rel = (rms_mc - est.rms_position_m).abs() / est.rms_position_m;
        // 200 draws of a sum of ~50 weighted χ² terms: the sample RMS is within ~10 %.
        assert!(
            rel < 0.15,
            "pose {:?}: Monte-Carlo RMS {:.3} mm, eq. 3.28 estimate {:.3} mm",
            x.r,
            rms_mc * 1e3,
            est.rms_position_m * 1e3
        );
        let (dom, g) = est.dominant.unwrap();
        assert!(g > 0.0 && g <= est.rms_position_m, "{} {g}", dom.name());
    }
}

#[test]
fn rigid_shifts_of_all_anchors_move_the_platform_by_exactly_that_shift() {
    // Known answers: moving every frame anchor a_i by d moves the whole robot by d; moving
    // every platform anchor b_i by d (platform frame) is the platform placed at r − R d.
    for model in [common::icosahedron(), common::pulley_model()] {
        // Without an external wrench: w_e acts at the platform origin, which a b-shift moves
        // relative to the anchors, so with gravity the shift is not a pure relabelling.
        let model = model
            .with_params(|p| p.w_e = nalgebra::Vector6::zeros())
            .unwrap();
        for x in common::test_poses() {
            let f = sensitivity::commanded_forces(&model, &x).unwrap();
            let s = sensitivity::parameter_sensitivity(&model, &x, &f).unwrap();
            let d = nalgebra::Vector3::new(1e-3, -2e-3, 0.5e-3);
            let dp_a: Vec<f64> = s
                .params
                .iter()
                .map(|p| match *p {
                    Parameter::FrameAnchor { axis, .. } => d[axis],
                    _ => 0.0,
                })
                .collect();
            let dx = s.predict(&dp_a);
            if !model.has_pulleys() {
                // (With pulleys the swivel axes stay put, so the shift is not rigid.)
                let dr = nalgebra::Vector3::new(dx[0], dx[1], dx[2]);
                assert!((dr - d).norm() < 1e-7, "a-shift: {dr:?} vs {d:?}");
                assert!(dx.fixed_rows::<3>(3).norm() < 1e-7);
            }
            let dp_b: Vec<f64> = s
                .params
                .iter()
                .map(|p| match *p {
                    Parameter::PlatformAnchor { axis, .. } => d[axis],
                    _ => 0.0,
                })
                .collect();
            let dx = s.predict(&dp_b);
            let want = -(x.rotation() * d);
            let dr = nalgebra::Vector3::new(dx[0], dx[1], dx[2]);
            assert!((dr - want).norm() < 1e-7, "b-shift: {dr:?} vs {want:?}");
            assert!(dx.fixed_rows::<3>(3).norm() < 1e-7);
        }
    }
}
