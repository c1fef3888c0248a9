//! The planar robots of the spec's chapters 3–4 (eq. 3.40 / 4.24): numbers the text gives,
//! reproduced from the analysis library (`cdpr_analysis::planar`); docs/analysis.md lists each
//! with the spec's value and what is missing where one is not reproduced exactly.

use cdpr_analysis::planar::{self, AreaTest, PlanarPose};
use nalgebra::{DVector, Vector2};

#[test]
fn condition_numbers_of_the_sample_sets_eq_4_26_and_4_28() {
    let model = planar::spec_example();
    // W_T1: 5 × 5 grid of ((-4, 0.5), (4, 6)), eq. (4.25) → cond = 3.2 (eq. 4.26).
    let t1 = planar::sample_grid((-4.0, 0.5), (4.0, 6.0), 5, 5);
    let c1 = planar::condition_number_qa(&model, &t1).unwrap();
    assert!((c1 - 3.2).abs() < 0.05, "cond(J_qa) on W_T1 = {c1}");
    // W_T2: 16 samples (4 × 4) of ((-3, 0.4), (2, 1)), eq. (4.27) → cond = 19.3 (eq. 4.28).
    let t2 = planar::sample_grid((-3.0, 0.4), (2.0, 1.0), 4, 4);
    let c2 = planar::condition_number_qa(&model, &t2).unwrap();
    assert!((c2 - 19.3).abs() < 0.05, "cond(J_qa) on W_T2 = {c2}");
}

#[test]
fn initial_tension_of_fig_3_18a() {
    // f_ini by eq. (3.41) at x_ini = [0, 5.2] m with f ∈ [1000, 8000] N and w_e = 0:
    // fig. 3.18a gives [5196 5247 3380 3394] N.
    let model = planar::spec_example()
        .with(|p| p.w_e = DVector::zeros(2))
        .unwrap();
    let x = PlanarPose::point(0.0, 5.2);
    let c = planar::inverse(&model, &x).unwrap();
    let at = planar::structure_matrix(&model, &x, &c);
    let (f, _) = planar::closed_form(&model, &at).unwrap();
    for (got, want) in f.iter().zip([5196.0, 5247.0, 3380.0, 3394.0]) {
        assert!((got - want).abs() < 1.0, "f_ini = {f:?}");
    }
}

#[test]
fn pulley_lengths_differentiate_to_minus_u_and_match_at_the_reference() {
    for rho in [0.15, 0.4] {
        let model = planar::spec_example()
            .with(|p| p.pulley_radius = rho)
            .unwrap();
        let std = planar::spec_example();
        let x0 = PlanarPose::point(0.0, 5.2);
        let cp = planar::inverse(&model, &x0).unwrap();
        let cs = planar::inverse(&std, &x0).unwrap();
        for i in 0..4 {
            // The outlet is a_i at the reference pose, so lengths and directions agree there.
            assert!((cp.exit[i] - std.params().a[i]).norm() < 1e-9);
            assert!((cp.q[i] - cs.q[i]).abs() < 1e-9);
        }
        // ∂q/∂r = −u_i: the arc takes up what the tangent point's motion adds (eq. 2.29).
        for x in [PlanarPose::point(-3.0, 2.0), PlanarPose::point(3.5, 6.0)] {
            let c = planar::inverse(&model, &x).unwrap();
            let h = 1e-6;
            for k in 0..2 {
                let mut xp = x;
                let mut xm = x;
                xp.r[k] += h;
                xm.r[k] -= h;
                let qp = planar::inverse(&model, &xp).unwrap().q;
                let qm = planar::inverse(&model, &xm).unwrap().q;
                for i in 0..4 {
                    let d = (qp[i] - qm[i]) / (2.0 * h);
                    assert!(
                        (d + c.u[i][k]).abs() < 1e-6,
                        "r_p {rho} cable {i} axis {k}: {d} vs {}",
                        -c.u[i][k]
                    );
                }
            }
        }
    }
}

#[test]
fn elastostatic_fk_returns_the_pose_that_holds_the_closed_form_forces() {
    let model = planar::spec_example();
    let x = PlanarPose::point(1.3, 3.1);
    let c = planar::inverse(&model, &x).unwrap();
    let at = planar::structure_matrix(&model, &x, &c);
    let (f, margin) = planar::closed_form(&model, &at).unwrap();
    assert!(margin > 0.0);
    let k = &model.params().k_f;
    let q_theta: Vec<f64> = (0..4).map(|i| c.q[i] * (1.0 - f[i] / k[i])).collect();
    let guess = PlanarPose::point(1.0, 3.5);
    let (xm, fm) = planar::elastostatic_fk(&model, &q_theta, &guess).unwrap();
    assert!((xm.r - x.r).norm() < 1e-8, "{:?}", xm.r);
    assert!((fm - f).norm() < 1e-3);
}

#[test]
fn physical_and_reachable_areas_of_sec_3_6() {
    // Sec. 3.6: the kinematic controller reaches 51 m² of a 70 m² physical workspace (73 %).
    // The text does not give f_max for fig. 3.11; with fig. 3.18a's [1000, 8000] N the exact
    // W_PHYS and the full-FK W_R come out as below (docs/analysis.md).
    let model = planar::spec_example();
    let h = 0.2;
    let grid = planar::frame_grid(&model, Vector2::new(-6.4, -0.5), Vector2::new(5.5, 8.5), h);
    let (exact, err_e) = planar::feasible_area(&model, &grid, h, 0.0, AreaTest::Exact);
    let (closed, err_c) = planar::feasible_area(&model, &grid, h, 0.0, AreaTest::ClosedForm);
    assert_eq!((err_e, err_c), (0, 0));
    assert!(
        closed < exact,
        "closed form {closed} m² vs exact {exact} m²"
    );
    assert!(
        (exact - 70.0).abs() / 70.0 < 0.05,
        "W_PHYS = {exact} m² (spec 70)"
    );
    let r = planar::reachable(&model, &model, &PlanarPose::point(0.0, 5.2), &grid, h).unwrap();
    let ratio = r.area_m2 / exact;
    assert!(
        (ratio - 0.73).abs() < 0.03,
        "W_R = {} m², {:.1} % of W_PHYS",
        r.area_m2,
        100.0 * ratio
    );
    assert!(r.area_m2 < exact);
    println!(
        "W_PHYS exact {exact:.2} m², closed form {closed:.2} m², W_R {:.2} m² ({:.1} %), mean error {:.1} mm, max {:.1} mm, FK failures {}",
        r.area_m2,
        100.0 * ratio,
        1e3 * r.mean_error_m,
        1e3 * r.max_error_m,
        r.fk_failures
    );
}

#[test]
fn pulleys_shrink_the_physical_workspace_slightly_sec_3_8() {
    let h = 0.2;
    let base = planar::spec_example();
    let grid = planar::frame_grid(&base, Vector2::new(-6.4, -0.5), Vector2::new(5.5, 8.5), h);
    let (a0, _) = planar::feasible_area(&base, &grid, h, 0.0, AreaTest::Exact);
    let mut ratios = Vec::new();
    for rho in [0.15, 0.4] {
        let m = base.with(|p| p.pulley_radius = rho).unwrap();
        let (a, errs) = planar::feasible_area(&m, &grid, h, 0.0, AreaTest::Exact);
        // Grid points within r_p of an outlet put the anchor inside the pulley: not a pose.
        assert!(
            errs <= 10,
            "{errs} grid points could not be evaluated with r_p = {rho}"
        );
        ratios.push(a / a0);
    }
    println!(
        "W_PHYS(r_p)/W_PHYS(0): 150 mm {:.2} %, 400 mm {:.2} %",
        100.0 * ratios[0],
        100.0 * ratios[1]
    );
    // Spec: 98.95 % and 97.54 % — smaller with larger pulleys. Reproduced in direction, NOT in
    // magnitude: this model gives 99.64 % / 98.87 % (docs/analysis.md). The text gives neither
    // the side of the cable the pulley sits on nor the force limits of fig. 3.21; finer grids
    // (0.05 m: 99.66 / 98.89 %) and other limits ([100, 3000] N: 99.19 / 97.27 %; [100, 8000] N:
    // 99.89 / 99.47 %) do not reproduce both numbers. So the test pins what this model gives,
    // to its grid's resolution (one 0.2 m cell of ~67 m² is 0.06 %), not the spec's value.
    assert!(ratios[1] < ratios[0] && ratios[0] < 1.0, "{ratios:?}");
    assert!((ratios[0] - 0.9964).abs() < 0.0006, "{ratios:?}");
    assert!((ratios[1] - 0.9887).abs() < 0.0006, "{ratios:?}");
}

/// A rigid planar platform (n = 3) in four cables (redundancy 1).
fn rigid() -> planar::PlanarModel {
    use planar::{PlanarDof, PlanarParams};
    planar::PlanarModel::new(PlanarParams {
        dof: PlanarDof::Rigid,
        a: vec![
            Vector2::new(-4.0, 4.0),
            Vector2::new(4.0, 4.0),
            Vector2::new(4.0, -4.0),
            Vector2::new(-4.0, -4.0),
        ],
        b: vec![
            Vector2::new(-0.5, 0.3),
            Vector2::new(0.5, 0.3),
            Vector2::new(0.5, -0.3),
            Vector2::new(-0.5, -0.3),
        ],
        k_f: vec![1.0e6; 4],
        w_e: DVector::from_vec(vec![0.0, -981.0, 0.0]),
        f_min: 200.0,
        f_max: 5000.0,
        pulley_radius: 0.0,
        pulley_reference: PlanarPose::point(0.0, 0.0),
    })
    .unwrap()
}

#[test]
fn rigid_platform_structure_matrix_is_minus_dq_dx() {
    // ∂q/∂(x, y, θ) = −A (eq. 2.47 in the plane): the third row of A^T is (R b_i) × u_i.
    let model = rigid();
    let x = PlanarPose {
        r: Vector2::new(0.7, -0.4),
        theta: 0.2,
    };
    let c = planar::inverse(&model, &x).unwrap();
    let at = planar::structure_matrix(&model, &x, &c);
    let h = 1e-6;
    for k in 0..3 {
        let shift = |s: f64| {
            let mut p = x;
            if k < 2 {
                p.r[k] += s;
            } else {
                p.theta += s;
            }
            planar::inverse(&model, &p).unwrap().q
        };
        let (qp, qm) = (shift(h), shift(-h));
        for i in 0..4 {
            let d = (qp[i] - qm[i]) / (2.0 * h);
            assert!(
                (d + at[(k, i)]).abs() < 1e-6,
                "row {k} cable {i}: {d} vs {}",
                -at[(k, i)]
            );
        }
    }
}

#[test]
fn rigid_platform_exact_test_agrees_between_solvers() {
    // Redundancy 1 takes the vertex solver's polygon branch; the simplex checks it.
    let model = rigid();
    let p = model.params();
    let mut n_feasible = 0;
    for i in 0..15 {
        for j in 0..15 {
            let x = PlanarPose {
                r: Vector2::new(-3.5 + 0.5 * i as f64, -3.5 + 0.5 * j as f64),
                theta: 0.1 * ((i + j) as f64 - 14.0) / 14.0,
            };
            let c = planar::inverse(&model, &x).unwrap();
            let at = planar::structure_matrix(&model, &x, &c);
            let v = cdpr_model::feasibility::exact_vertex(&at, &p.w_e, p.f_min, p.f_max).unwrap();
            let l = cdpr_model::feasibility::exact_lp(&at, &p.w_e, p.f_min, p.f_max).unwrap();
            assert!(
                (v.margin - l.margin).abs() < 1e-4 * (p.f_max - p.f_min),
                "{x:?}: {} vs {}",
                v.margin,
                l.margin
            );
            n_feasible += usize::from(v.feasible);
        }
    }
    assert!(
        n_feasible > 10 && n_feasible < 225,
        "{n_feasible} of 225 feasible"
    );
}
