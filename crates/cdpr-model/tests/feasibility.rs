//! Exact wrench feasibility (eq. 3.29) on the spatial platforms: the two exact solvers
//! (vertex enumeration in the kernel, microlp's simplex) agree, the exact margin is never
//! below the closed form's (eq. 3.41 is sufficient), and the exact test accepts poses the closed
//! form rejects near the border. scipy's HiGHS checks the same figures in
//! tools/feasibility_vs_scipy.py.

mod common;
use cdpr_model::feasibility;
use cdpr_model::workspace::{self, FeasibilityTest, PositionBox};
use cdpr_model::{Data, Pose, statics};
use nalgebra::{DVector, Vector3};
use rand::{Rng, SeedableRng};

#[test]
fn vertex_and_simplex_agree_and_bound_the_closed_form_from_above() {
    for name in [
        "icosahedron.toml",
        "icosahedron-pulleys.toml",
        "helicopter.toml",
    ] {
        let pf = common::platform(name);
        let model = &pf.model;
        let p = model.params();
        let mut data = Data::new(model);
        let mut f = vec![0.0; model.m()];
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let b = pf.region.position;
        let (mut n_exact_only, mut n_checked) = (0, 0);
        for _ in 0..300 {
            // Sample a box 40 % larger than the operating region (and at least 1.5 m wide: the
            // helicopter's region is only 0.5 m high and lies inside the closed form's
            // workspace) so the border is crossed.
            let c = (b.min + b.max) * 0.5;
            let h = ((b.max - b.min) * 0.7).map(|x| x.max(0.75));
            let r = Vector3::from_fn(|k, _| c[k] + h[k] * rng.random_range(-1.0..1.0));
            let phi = Vector3::from_fn(|_, _| rng.random_range(-0.15..0.15));
            let pose = Pose::new(r, phi);
            let Ok(cf) = workspace::check_pose(model, &mut data, &pose, &mut f) else {
                continue;
            };
            let at = statics::structure_matrix(&data);
            let w = DVector::from_column_slice(p.w_e.as_slice());
            let v = feasibility::exact_vertex(&at, &w, p.f_min, p.f_max).unwrap();
            let l = feasibility::exact_lp(&at, &w, p.f_min, p.f_max).unwrap();
            let range = p.f_max - p.f_min;
            assert!(
                (v.margin - l.margin).abs() < 1e-5 * range,
                "{name} {pose:?}: vertex {} vs simplex {}",
                v.margin,
                l.margin
            );
            assert_eq!(v.feasible, l.feasible, "{name} {pose:?}");
            assert!(
                v.margin >= cf.margin - 1e-6 * range,
                "{name}: exact margin {} below the closed form's {}",
                v.margin,
                cf.margin
            );
            if cf.feasible {
                assert!(v.feasible, "{name}: closed form feasible, exact not");
            }
            if v.feasible && !cf.feasible {
                n_exact_only += 1;
            }
            // The proving distribution balances the wrench and keeps the margin it claims.
            let res = &at * &v.forces + &w;
            assert!(
                res.norm() < 1e-6 * p.f_max,
                "{name}: residual {}",
                res.norm()
            );
            let lo = v
                .forces
                .iter()
                .map(|fi| fi - p.f_min)
                .fold(f64::INFINITY, f64::min);
            let hi = v
                .forces
                .iter()
                .map(|fi| p.f_max - fi)
                .fold(f64::INFINITY, f64::min);
            assert!((lo.min(hi) - v.margin).abs() < 1e-6 * range);
            n_checked += 1;
        }
        assert!(n_checked > 250, "{name}: only {n_checked} poses evaluated");
        assert!(
            n_exact_only > 0,
            "{name}: no pose where only the exact test is feasible (the border was not crossed)"
        );
    }
}

#[test]
fn exact_workspace_contains_the_closed_form_workspace() {
    let pf = common::platform("icosahedron.toml");
    let b = pf.region.position;
    let c = (b.min + b.max) * 0.5;
    let h = (b.max - b.min) * 0.8;
    let bounds = PositionBox {
        min: c - h,
        max: c + h,
    };
    let phi = Vector3::zeros();
    let cf = workspace::sample_grid_with(
        &pf.model,
        &bounds,
        &phi,
        [9; 3],
        FeasibilityTest::ClosedForm,
    );
    let ex = workspace::sample_grid_with(&pf.model, &bounds, &phi, [9; 3], FeasibilityTest::Exact);
    for ((r1, a), (r2, b)) in cf.points.iter().zip(&ex.points) {
        assert_eq!(r1, r2);
        assert!(!a || *b, "closed form feasible but exact not at {r1:?}");
    }
    assert!(
        ex.feasible > cf.feasible,
        "{} vs {}",
        ex.feasible,
        cf.feasible
    );
}

#[test]
fn reachable_analysis_holds_f_ini_at_home_and_stiffer_cables_track_better() {
    let pf = common::platform("icosahedron.toml");
    let model = &pf.model;
    let f_ini = workspace::setup_tension(model, &pf.home, None).unwrap();
    let dw = nalgebra::Vector6::new(0.0, 0.0, -1000.0, 0.0, 0.0, 0.0);
    let refs = vec![
        pf.home,
        Pose::new(pf.home.r + Vector3::new(0.6, -0.4, 0.2), Vector3::zeros()),
        Pose::new(pf.home.r + Vector3::new(-0.8, 0.5, -0.4), Vector3::zeros()),
    ];
    let a = workspace::reachable_kinematic(model, model, &pf.home, &f_ini, &refs, &dw).unwrap();
    match &a.points[0].1 {
        workspace::Reach::Settled { pose, forces, .. } => {
            assert!((pose.r - pf.home.r).norm() < 1e-7, "{pose:?}");
            for (f, g) in forces.iter().zip(&f_ini) {
                assert!((f - g).abs() < 1e-3, "{f} vs {g}");
            }
        }
        other => panic!("{other:?}"),
    }
    let stiff = model
        .with_params(|p| p.k_f.iter_mut().for_each(|k| *k *= 10.0))
        .unwrap();
    let b = workspace::reachable_kinematic(&stiff, &stiff, &pf.home, &f_ini, &refs, &dw).unwrap();
    let err = |r: &workspace::ReachableAnalysis| {
        r.points
            .iter()
            .map(|(x, o)| match o {
                workspace::Reach::Settled { pose, .. } => (pose.r - x.r).norm(),
                _ => f64::INFINITY,
            })
            .sum::<f64>()
    };
    assert!(
        err(&b) < err(&a),
        "stiffer cables: {} vs {}",
        err(&b),
        err(&a)
    );
}
