//! Core identification: recovery of the plant's parameters to round-off on noise-free data.

mod common;
use calibrate::params::{Group, group};
use calibrate::{CalModel, FitSpec, Kind, ParamId, fit};
use common::*;
use sim_plant::config::Effects;

fn free_base(m: usize) -> Vec<ParamId> {
    [Group::A, Group::B, Group::KF, Group::We, Group::Offset]
        .iter()
        .flat_map(|g| group(*g, m))
        .collect()
}

#[test]
fn elastostatic_identification_recovers_plant_parameters_to_round_off() {
    // Plant: nominal platform with the CRS-like geometry deviations, every other effect off.
    let geometry = crs_like_effects().geometry;
    let effects = Effects {
        geometry: geometry.clone(),
        ..Effects::default()
    };
    let obs = campaign(effects, 24, 7, true);
    assert!(obs.len() >= 40, "{} samples", obs.len());
    let nominal = nominal();
    let mut start = CalModel::from_model(&nominal.model);
    // Start also off in stiffness and load.
    for k in start.k_f.iter_mut() {
        *k *= 1.3;
    }
    start.w_e[2] *= 0.8;
    let m = start.m();
    let spec = FitSpec::new(Kind::Elastostatic, free_base(m));
    let f = fit(&start, &obs, &spec, &mut |_, _| {}).expect("fit");
    assert!(
        f.fixed_unobservable.is_empty(),
        "{:?}",
        f.fixed_unobservable
    );
    let g = geometry.unwrap();
    let truth = nominal.model.params();
    let mut worst: f64 = 0.0;
    for i in 0..m {
        worst = worst.max((f.model.a[i] - (truth.a[i] + g.frame_anchor_offsets[i])).amax());
        worst = worst.max((f.model.b[i] - (truth.b[i] + g.platform_anchor_offsets[i])).amax());
        worst = worst.max(((f.model.k_f[i] - truth.k_f[i]) / truth.k_f[i]).abs());
        worst = worst.max(f.model.offset[i].abs());
    }
    worst = worst.max((f.model.w_e - truth.w_e).amax() / 1e3);
    assert!(
        worst < 1e-9,
        "worst parameter error {worst:e} (iterations {})",
        f.iterations
    );
    assert!(
        f.cond_start_scaled < f.cond_start_unscaled,
        "preconditioning must help"
    );
}

#[test]
fn kinematic_identification_recovers_geometry_on_kinematic_data() {
    // Joint-space residual eq. 4.8: with an infinitely stiff plant the kinematic model is exact.
    let geometry = crs_like_effects().geometry;
    let mut effects = Effects {
        geometry: geometry.clone(),
        ..Effects::default()
    };
    // Very stiff cables: the elastic elongation is below 1e-9 m.
    let _ = &mut effects;
    let nominal = nominal();
    let stiff = nominal
        .model
        .with_params(|p| p.k_f.iter_mut().for_each(|k| *k = 1e18))
        .unwrap();
    let obs = {
        let mut o = campaign(effects, 20, 3, false);
        // Re-derive commands from the true geometry so the data are exactly kinematic.
        let truth = CalModel::from_model(
            &stiff
                .with_params(|p| {
                    let g = geometry.as_ref().unwrap();
                    for i in 0..p.a.len() {
                        p.a[i] += g.frame_anchor_offsets[i];
                        p.b[i] += g.platform_anchor_offsets[i];
                    }
                })
                .unwrap(),
        );
        let model = truth.model().unwrap();
        let mut data = cdpr_model::Data::new(&model);
        for s in &mut o {
            cdpr_model::kinematics::inverse(&model, &mut data, &s.pose).unwrap();
            s.q_cmd = data.q.iter().map(|q| q - 0.01).collect();
        }
        o
    };
    let start = CalModel::from_model(&nominal.model);
    let m = start.m();
    let free: Vec<ParamId> = [Group::A, Group::B, Group::Offset]
        .iter()
        .flat_map(|g| group(*g, m))
        .collect();
    let f = fit(
        &start,
        &obs,
        &FitSpec::new(Kind::Kinematic, free),
        &mut |_, _| {},
    )
    .expect("fit");
    let g = geometry.unwrap();
    for i in 0..m {
        let ea = (f.model.a[i] - (nominal.model.params().a[i] + g.frame_anchor_offsets[i])).amax();
        assert!(ea < 1e-9, "a_{i} error {ea:e}");
        assert!((f.model.offset[i] - 0.01).abs() < 1e-9);
    }
}

#[test]
fn constant_orientation_data_fix_the_unobservable_platform_geometry() {
    // ch. 6.3: without rotations a_i and b_i are indistinguishable (q depends on a_i − b_i − r).
    let nominal = nominal();
    let truth = CalModel::from_model(&nominal.model);
    let model = truth.model().unwrap();
    let mut obs = campaign(Effects::default(), 20, 5, false);
    let mut data = cdpr_model::Data::new(&model);
    for s in &mut obs {
        s.pose.phi = nalgebra::Vector3::zeros();
        cdpr_model::kinematics::inverse(&model, &mut data, &s.pose).unwrap();
        s.q_cmd = data.q.clone();
    }
    let m = truth.m();
    let free: Vec<ParamId> = [Group::A, Group::B]
        .iter()
        .flat_map(|g| group(*g, m))
        .collect();
    let f = fit(
        &truth,
        &obs,
        &FitSpec::new(Kind::Kinematic, free),
        &mut |_, _| {},
    )
    .expect("fit");
    assert_eq!(
        f.fixed_unobservable.len(),
        3 * m,
        "{:?}",
        f.fixed_unobservable
    );
    assert!(
        f.fixed_unobservable
            .iter()
            .all(|(p, _)| matches!(p, ParamId::B(..)))
    );
    assert!(
        f.cond_end_scaled < 1e6,
        "cond after fixing {}",
        f.cond_end_scaled
    );
}

#[test]
fn ridge_and_lasso_hold_the_platform_geometry() {
    // eq. 4.32: a strong penalty on b keeps it at the start (lasso: exactly, up to the IRLS
    // floor), a weak one lets it move to the plant's value; the data rows then absorb the rest.
    let geometry = crs_like_effects().geometry;
    let effects = Effects {
        geometry: geometry.clone(),
        ..Effects::default()
    };
    let obs = campaign(effects, 16, 9, true);
    let nominal = nominal();
    let start = CalModel::from_model(&nominal.model);
    let m = start.m();
    let b_ids = group(Group::B, m);
    let db = |f: &calibrate::Fit| {
        (0..m)
            .map(|i| (f.model.b[i] - start.b[i]).amax())
            .fold(0.0f64, f64::max)
    };
    let mut spec = FitSpec::new(Kind::Elastostatic, free_base(m));
    spec.lasso = b_ids.iter().map(|p| (*p, 1e8)).collect();
    let lasso = fit(&start, &obs, &spec, &mut |_, _| {}).unwrap();
    assert!(db(&lasso) < 1e-4, "lasso moved b by {:e}", db(&lasso));
    spec.lasso.clear();
    spec.ridge = b_ids.iter().map(|p| (*p, 1e-6)).collect();
    let weak = fit(&start, &obs, &spec, &mut |_, _| {}).unwrap();
    let g = geometry.unwrap();
    let truth_db = g
        .platform_anchor_offsets
        .iter()
        .map(|d| d.amax())
        .fold(0.0f64, f64::max);
    assert!(
        (db(&weak) - truth_db).abs() < 1e-4,
        "weak ridge: {:e} vs {truth_db:e}",
        db(&weak)
    );
    assert!(lasso.cost > weak.cost);
}
