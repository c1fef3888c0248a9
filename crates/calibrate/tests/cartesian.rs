//! The optional Cartesian residual through the forward kinematics (eq. 4.3–4.4): its analytic
//! Jacobian against finite differences, and recovery of the geometry on exact kinematic data.

mod common;
use calibrate::identify::{jacobian, residual};
use calibrate::params::{Group, group};
use calibrate::{CalModel, FitSpec, Kind, Observation, ParamId, Weights, fit};
use common::*;
use sim_plant::config::Effects;

/// Exactly kinematic data of the CRS-like geometry (frame/platform anchors off nominal by
/// cm, cable offsets 10 mm): commands q = φ_true(x) − 0.01 at the campaign's measured poses.
fn kinematic_data() -> (CalModel, CalModel, Vec<Observation>) {
    let geometry = crs_like_effects().geometry.unwrap();
    let nominal = nominal();
    let truth = CalModel::from_model(
        &nominal
            .model
            .with_params(|p| {
                for i in 0..p.a.len() {
                    p.a[i] += geometry.frame_anchor_offsets[i];
                    p.b[i] += geometry.platform_anchor_offsets[i];
                }
            })
            .unwrap(),
    );
    let effects = Effects {
        geometry: Some(geometry),
        ..Effects::default()
    };
    let mut obs = campaign(effects, 20, 5, false);
    let model = truth.model().unwrap();
    let mut data = cdpr_model::Data::new(&model);
    for s in &mut obs {
        cdpr_model::kinematics::inverse(&model, &mut data, &s.pose).unwrap();
        s.q_cmd = data.q.iter().map(|q| q - 0.01).collect();
    }
    // The truth includes the cable offsets the commands were made with.
    let mut truth = truth;
    truth.offset.iter_mut().for_each(|d| *d = 0.01);
    (CalModel::from_model(&nominal.model), truth, obs)
}

fn free(m: usize) -> Vec<ParamId> {
    [Group::A, Group::B, Group::Offset]
        .iter()
        .flat_map(|g| group(*g, m))
        .collect()
}

/// Largest relative difference between the analytic Cartesian Jacobian at `at` and central
/// differences of the residual.
fn jacobian_error(at: &CalModel, obs: &[Observation]) -> f64 {
    let w = Weights {
        wrench: 1.0,
        length: 1.0,
    };
    let mut params = free(at.m());
    params.push(ParamId::DrumScale(2));
    let j = jacobian(Kind::Cartesian, at, obs, w, &params).unwrap();
    assert_eq!(j.nrows(), 6 * obs.len());
    let mut worst: f64 = 0.0;
    for (c, p) in params.iter().enumerate() {
        let h = 1e-6;
        let (mut plus, mut minus) = (at.clone(), at.clone());
        plus.set(*p, at.get(*p) + h);
        minus.set(*p, at.get(*p) - h);
        let rp = residual(Kind::Cartesian, &plus, obs, w).unwrap();
        let rm = residual(Kind::Cartesian, &minus, obs, w).unwrap();
        for r in 0..j.nrows() {
            let fd = (rp[r] - rm[r]) / (2.0 * h);
            let scale = 1e-2 + fd.abs().max(j[(r, c)].abs());
            worst = worst.max((j[(r, c)] - fd).abs() / scale);
        }
    }
    worst
}

#[test]
fn cartesian_jacobian_matches_finite_differences() {
    let (start, truth, obs) = kinematic_data();
    let obs = &obs[..6];
    // At a consistent model (FK residual zero, rotation error zero) the implicit-function
    // Jacobian is exact.
    let at_truth = jacobian_error(&truth, obs);
    assert!(at_truth < 1e-4, "at the truth: {at_truth:e}");
    // Away from it, it is the Gauss–Newton approximation: the dropped term Σ e_i ∇e_i scales
    // with the FK residual e, so the error shrinks as the model approaches a consistent one
    // (the nominal model is cm off; the midpoint half of that).
    let mut mid = truth.clone();
    for i in 0..truth.m() {
        mid.a[i] = 0.5 * (start.a[i] + truth.a[i]);
        mid.b[i] = 0.5 * (start.b[i] + truth.b[i]);
        mid.offset[i] = 0.5 * (start.offset[i] + truth.offset[i]);
    }
    let (at_start, at_mid) = (jacobian_error(&start, obs), jacobian_error(&mid, obs));
    assert!(
        at_mid < at_start && at_start < 0.5,
        "nominal {at_start:e}, midpoint {at_mid:e}"
    );
}

#[test]
fn cartesian_identification_recovers_the_geometry_on_kinematic_data() {
    let (start, truth, obs) = kinematic_data();
    let m = start.m();
    let r0 = residual(Kind::Cartesian, &start, &obs, Weights::default()).unwrap();
    let mut spec = FitSpec::new(Kind::Cartesian, free(m));
    spec.weights = Weights {
        wrench: 1.0,
        length: 1.0,
    };
    let f = fit(&start, &obs, &spec, &mut |_, _| {}).expect("fit");
    // The nominal model is cm off at the start; the fit is exact at the truth.
    assert!(r0.iter().map(|r| r.abs()).fold(0.0, f64::max) > 1e-3 * 1e4);
    for i in 0..m {
        let ea = (f.model.a[i] - truth.a[i]).amax();
        let eb = (f.model.b[i] - truth.b[i]).amax();
        // The residual goes through an iterative FK: µm, not round-off (the joint-space fit
        // reaches 1e-9 m, tests/identification.rs).
        assert!(
            ea < 1e-5 && eb < 1e-5,
            "cable {i}: a error {ea:e}, b error {eb:e}"
        );
        assert!((f.model.offset[i] - 0.01).abs() < 1e-5, "offset {i}");
    }
    let r = residual(Kind::Cartesian, &f.model, &obs, spec.weights).unwrap();
    let worst = r.iter().map(|r| r.abs()).fold(0.0, f64::max);
    assert!(worst < 1e-7, "pose residual after the fit {worst:e} m/rad");
}
