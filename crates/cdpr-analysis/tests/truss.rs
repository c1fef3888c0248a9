//! The icosahedron cabin's space frame (eq. 5.2–5.7) under the cable forces of real poses:
//! equilibrium at every joint, rigid-body modes, determinacy, and the rod rating.

// The model library's test helpers (shipped platforms, feasible test poses), shared, not copied.
#[path = "../../cdpr-model/tests/common/mod.rs"]
mod common;
use cdpr_analysis::truss::{self, ROD_EA_DEFAULT_N, ROD_RATING_N};
use cdpr_model::{Data, Pose, kinematics, statics};
use nalgebra::Vector3;

fn cabin() -> (cdpr_model::config::Platform, truss::Truss, Vec<usize>) {
    let pf = common::platform("icosahedron.toml");
    let (t, cn) = truss::icosahedron_cabin(&pf.model.params().b, ROD_EA_DEFAULT_N).unwrap();
    (pf, t, cn)
}

#[test]
fn the_fitted_icosahedron_has_12_joints_30_rods_and_every_cable_on_its_own_joint() {
    let (pf, t, cn) = cabin();
    assert_eq!((t.nodes.len(), t.members.len()), (12, 30));
    let mut seen = cn.clone();
    seen.sort();
    seen.dedup();
    assert_eq!(seen.len(), 8, "cables share a joint: {cn:?}");
    for (i, &k) in cn.iter().enumerate() {
        assert!(
            (t.nodes[k] - pf.model.params().b[i]).norm() < 1e-12,
            "cable {i} not at its joint"
        );
    }
    // Every joint has 5 rods (icosahedron).
    for k in 0..12 {
        assert_eq!(
            t.members.iter().filter(|(p, q)| *p == k || *q == k).count(),
            5
        );
    }
}

#[test]
fn free_frame_has_exactly_six_rigid_body_modes() {
    let (_, t, _) = cabin();
    let k = t.stiffness().unwrap();
    let eig = k.symmetric_eigen().eigenvalues;
    let max = eig.amax();
    let zeros = eig.iter().filter(|e| e.abs() < 1e-9 * max).count();
    assert_eq!(zeros, 6, "{eig:?}");
    // The 3-2-1 support fixes exactly six coordinates.
    let fixed: usize = t
        .fixed
        .iter()
        .map(|f| f.iter().filter(|b| **b).count())
        .sum();
    assert_eq!(fixed, 6);
}

#[test]
fn cable_forces_of_a_pose_balance_at_every_joint_and_leave_no_reaction() {
    let (pf, t, cn) = cabin();
    let model = &pf.model;
    let p = model.params();
    let mut data = Data::new(model);
    let pose = Pose::new(
        Vector3::new(0.4, -0.3, 1.8),
        Vector3::new(0.05, -0.04, 0.08),
    );
    kinematics::inverse(model, &mut data, &pose).unwrap();
    let mut f = vec![0.0; model.m()];
    statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f).unwrap();
    let w_force = Vector3::new(p.w_e[0], p.w_e[1], p.w_e[2]);
    let w = truss::cabin_loads(
        &t,
        &cn,
        &pose.rotation(),
        &data.u,
        &f,
        &w_force,
        &Vector3::zeros(),
    );
    let s = truss::solve(&t, &w).unwrap();
    // Loads in equilibrium (A^T f + w_e = 0) → no support reaction.
    for r in &s.reactions {
        assert!(r.norm() < 1e-6 * p.f_max, "reaction {r:?}");
    }
    // Joint equilibrium with the physical forces: Σ f_j · (unit towards the far end) + w = 0.
    for (k, wk) in w.iter().enumerate() {
        let mut sum = *wk;
        for (j, &(a, b)) in t.members.iter().enumerate() {
            let other = if a == k {
                b
            } else if b == k {
                a
            } else {
                continue;
            };
            sum += (t.nodes[other] - t.nodes[k]).normalize() * s.member_forces[j];
        }
        assert!(sum.norm() < 1e-6 * p.f_max, "joint {k}: {sum:?}");
    }
    // Determinate: member forces do not depend on the rod stiffness.
    let mut stiff = t.clone();
    stiff
        .ea
        .iter_mut()
        .enumerate()
        .for_each(|(j, e)| *e *= 1.0 + j as f64);
    let s2 = truss::solve(&stiff, &w).unwrap();
    for (a, b) in s.member_forces.iter().zip(&s2.member_forces) {
        assert!((a - b).abs() < 1e-6 * p.f_max);
    }
    let worst = s.member_forces.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(worst > 1000.0 && worst < ROD_RATING_N, "{worst}");
}

#[test]
fn joint_loads_of_fig_5_10b_are_carried_by_the_supports() {
    let (_, t, cn) = cabin();
    let zero = vec![0.0; 8];
    let u = vec![Vector3::z(); 8];
    let w = truss::cabin_loads(
        &t,
        &cn,
        &nalgebra::Matrix3::identity(),
        &u,
        &zero,
        &Vector3::zeros(),
        &Vector3::new(0.0, 0.0, -10_000.0),
    );
    let s = truss::solve(&t, &w).unwrap();
    let total: Vector3<f64> = s.reactions.iter().sum();
    assert!(
        (total - Vector3::new(0.0, 0.0, 120_000.0)).norm() < 1e-6,
        "{total:?}"
    );
}
