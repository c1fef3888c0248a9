//! Finite-difference checks of every analytic Jacobian (standard, pulley, elastostatic).
mod common;

use cdpr_model::elastostatics::{self, Stiffness};
use cdpr_model::forward::{self, FkOptions};
use cdpr_model::kinematics::{self, differential};
use cdpr_model::pose::twist_from_coordinates;
use cdpr_model::{Data, Model, Pose};
use common::*;
use nalgebra::{DMatrix, Matrix3x6, RowVector6};

fn to_dm3(m: &Matrix3x6<f64>) -> DMatrix<f64> {
    DMatrix::from_iterator(3, 6, m.iter().copied())
}

fn analytic_rows(
    model: &Model,
    pose: &Pose,
    row: impl Fn(&Model, &Data, usize) -> RowVector6<f64>,
) -> DMatrix<f64> {
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, pose).unwrap();
    let t = twist_from_coordinates(pose);
    let mut j = DMatrix::zeros(model.m(), 6);
    for i in 0..model.m() {
        let r = row(model, &data, i) * t;
        for k in 0..6 {
            j[(i, k)] = r[k];
        }
    }
    j
}

fn check_models() -> Vec<(&'static str, Model)> {
    vec![("standard", icosahedron()), ("pulley", pulley_model())]
}

#[test]
fn length_jacobian_is_minus_a() {
    // eq. (2.54) standard; sec. 2.7 pulley (u at the contact point).
    for (name, model) in check_models() {
        for pose in test_poses() {
            let analytic = analytic_rows(&model, &pose, |_, d, i| {
                differential::length_jacobian_row(d, i)
            });
            let mut data = Data::new(&model);
            let fd = fd_pose(&pose, 1e-6, |x| {
                kinematics::inverse(&model, &mut data, x).unwrap();
                data.q.clone()
            });
            let e = rel_diff(&analytic, &fd);
            assert!(e < 1e-7, "{name}: dq/dx mismatch {e:e} at {pose:?}");
        }
    }
}

#[test]
fn unit_vector_jacobian_matches_fd() {
    // eq. (2.65) standard; eq. (2.87) + (2.62) pulley.
    for (name, model) in check_models() {
        for pose in test_poses() {
            let mut data = Data::new(&model);
            kinematics::inverse(&model, &mut data, &pose).unwrap();
            let t = twist_from_coordinates(&pose);
            for i in 0..model.m() {
                let analytic = to_dm3(&(differential::unit_vector_jacobian(&model, &data, i) * t));
                let mut d2 = Data::new(&model);
                let fd = fd_pose(&pose, 1e-6, |x| {
                    kinematics::inverse(&model, &mut d2, x).unwrap();
                    d2.u[i].iter().copied().collect()
                });
                let e = rel_diff(&analytic, &fd);
                assert!(e < 1e-6, "{name}: du/dx cable {i} mismatch {e:e}");
            }
        }
    }
}

#[test]
fn pulley_differentials_match_fd() {
    // eq. (2.83)-(2.87): wound arc length, contact point, cable vector.
    let model = pulley_model();
    for pose in test_poses() {
        let mut data = Data::new(&model);
        kinematics::inverse(&model, &mut data, &pose).unwrap();
        let t = twist_from_coordinates(&pose);
        let r_p = model.params().pulleys.as_ref().unwrap().radius[0];
        for i in 0..model.m() {
            let mut d2 = Data::new(&model);
            let fd_arc = fd_pose(&pose, 1e-6, |x| {
                kinematics::inverse(&model, &mut d2, x).unwrap();
                vec![d2.beta[i] * r_p]
            });
            let an_arc = differential::arc_length_jacobian(&model, &data, i) * t;
            let an_arc = DMatrix::from_row_slice(1, 6, an_arc.as_slice());
            assert!(rel_diff(&an_arc, &fd_arc) < 1e-6, "arc length cable {i}");

            let fd_pa = fd_pose(&pose, 1e-6, |x| {
                kinematics::inverse(&model, &mut d2, x).unwrap();
                d2.p_exit[i].iter().copied().collect()
            });
            let an_pa = to_dm3(&(differential::contact_point_jacobian(&model, &data, i) * t));
            assert!(rel_diff(&an_pa, &fd_pa) < 1e-6, "contact point cable {i}");
            assert!(
                fd_pa.amax() > 1e-4,
                "the contact point must move with the platform"
            );

            let fd_l = fd_pose(&pose, 1e-6, |x| {
                kinematics::inverse(&model, &mut d2, x).unwrap();
                d2.l[i].iter().copied().collect()
            });
            let an_l = to_dm3(&(differential::cable_vector_jacobian(&model, &data, i) * t));
            assert!(rel_diff(&an_l, &fd_l) < 1e-6, "cable vector cable {i}");

            let fd_qf = fd_pose(&pose, 1e-6, |x| {
                kinematics::inverse(&model, &mut d2, x).unwrap();
                vec![d2.q_free[i]]
            });
            let an_qf = differential::free_length_jacobian(&model, &data, i) * t;
            let an_qf = DMatrix::from_row_slice(1, 6, an_qf.as_slice());
            assert!(rel_diff(&an_qf, &fd_qf) < 1e-6, "free length cable {i}");
        }
    }
}

#[test]
fn parameter_jacobian_matches_fd() {
    // eq. (4.5)-(4.6), both models.
    for (name, model) in check_models() {
        let pose = test_poses()[1];
        let mut data = Data::new(&model);
        kinematics::inverse(&model, &mut data, &pose).unwrap();
        let h = 1e-6;
        for i in 0..model.m() {
            let (ja, jb) = differential::length_parameter_jacobian(&data, &pose, i);
            for k in 0..3 {
                for (which, analytic) in [("a", ja[k]), ("b", jb[k])] {
                    let q_at = |delta: f64| {
                        let mm = model
                            .with_params(|p| {
                                if which == "a" {
                                    p.a[i][k] += delta
                                } else {
                                    p.b[i][k] += delta
                                }
                            })
                            .unwrap();
                        let mut d = Data::new(&mm);
                        kinematics::inverse(&mm, &mut d, &pose).unwrap();
                        d.q[i]
                    };
                    let fd = (q_at(h) - q_at(-h)) / (2.0 * h);
                    assert!(
                        (fd - analytic).abs() < 1e-7,
                        "{name}: dq{i}/d{which}{k}: fd {fd} vs {analytic}"
                    );
                }
            }
        }
    }
}

#[test]
fn residual_wrench_jacobian_is_kg_minus_kc() {
    // eq. (2.66)-(2.76): ∂(A^T f + w_e)/∂x at fixed q_θ = K_G − K_C, standard and pulley.
    for (name, model) in check_models() {
        let law = model.linear_law();
        for pose in test_poses() {
            let mut data = Data::new(&model);
            // Controlled lengths giving a realistic tension state at this pose (eq. 2.37).
            let mut f = vec![0.0; model.m()];
            kinematics::inverse(&model, &mut data, &pose).unwrap();
            let p = model.params();
            cdpr_model::statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f)
                .unwrap();
            let mut q_theta = vec![0.0; model.m()];
            elastostatics::inverse(&model, &mut data, &pose, &f, &mut q_theta).unwrap();
            elastostatics::cable_forces(&mut data, &law, &q_theta);
            let s = Stiffness::at(&model, &data);
            let kwx = s.k_wx * twist_from_coordinates(&pose);
            let analytic = DMatrix::from_iterator(6, 6, kwx.iter().copied());
            let mut d2 = Data::new(&model);
            let fd = fd_pose(&pose, 1e-7, |x| {
                kinematics::inverse(&model, &mut d2, x).unwrap();
                elastostatics::cable_forces(&mut d2, &law, &q_theta);
                let w = cdpr_model::statics::cable_wrench(&d2, &d2.f);
                w.iter().copied().collect()
            });
            let e = rel_diff(&analytic, &fd);
            assert!(e < 1e-6, "{name}: K_G − K_C mismatch {e:e}");
            // K_G is small but not zero, and K_C dominates (sec. 2.6).
            assert!(s.k_g.amax() > 1.0 && s.k_g.amax() < 0.1 * s.k_c.amax());
        }
    }
}

#[test]
fn pose_sensitivity_matches_fd_of_elastostatic_fk() {
    // eq. (2.80): δx = J_xθ δq_θ, checked against ν_el itself.
    for (name, model) in check_models() {
        let pose = test_poses()[1];
        let mut data = Data::new(&model);
        kinematics::inverse(&model, &mut data, &pose).unwrap();
        let p = model.params();
        let mut f = vec![0.0; model.m()];
        cdpr_model::statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f).unwrap();
        let mut q_theta = vec![0.0; model.m()];
        elastostatics::inverse(&model, &mut data, &pose, &f, &mut q_theta).unwrap();
        elastostatics::cable_forces(&mut data, &model.linear_law(), &q_theta);
        let j = elastostatics::pose_sensitivity(&model, &data).unwrap();
        let h = 1e-6;
        let opts = FkOptions::default();
        for i in 0..model.m() {
            let solve = |d: f64| {
                let mut qt = q_theta.clone();
                qt[i] += d;
                let mut dd = Data::new(&model);
                forward::elastostatic(&model, &mut dd, &qt, &pose, &opts)
                    .unwrap()
                    .pose
                    .to_vector()
            };
            let fd = (solve(h) - solve(-h)) / (2.0 * h);
            // J_xθ is in twist coordinates; convert the FD (pose coordinates) to the twist.
            let fd_twist = twist_from_coordinates(&pose) * fd;
            let col = j.column(i);
            let e = (fd_twist - col).amax() / col.amax().max(1e-3);
            assert!(e < 1e-4, "{name}: J_xθ column {i} mismatch {e:e}");
        }
    }
}
