//! The surrogate's evaluation on the plant (`crs surrogate fit`'s tracking table,
//! `plant_experiments::surrogate_evaluation::evaluate`) against an independent plant. `evaluate`
//! measures each controller on sim-plant, whose equilibrium is the model library's own
//! elastostatics — the equations the surrogate's target q_off = φ_el(x, f_ref) − φ(x) was
//! computed with — so an error both share (the stretch law, a moment arm) would cancel in its
//! table. Here the same commands (the controller's φ(x) + φ_sg(x) and set-up offsets) go to
//! `plant-oracle`, the equilibrium as the minimum of the potential energy from cable lengths
//! alone (glam, no model-library code), set up at home from its own cable lengths. For every
//! pose of the grid the oracle's position and force errors must be the evaluation's.

use cdpr_model::config::load_platform;
use cdpr_model::offset_target::OffsetTarget;
use cdpr_model::{Data, Pose, kinematics};
use plant_experiments::surrogate_evaluation::{evaluate, fit_platform};
use plant_oracle::{PoseQ, cable_length, equilibrium};
use std::path::{Path, PathBuf};

/// Largest differences accepted between the evaluation's per-pose errors and the oracle's.
/// Both resolve their equilibrium far better (plant: relative wrench residual 1e-10; oracle
/// ~1e-11 m, ~1e-5 N); measured: 7.1e-8 mm and 9.6e-6 N. A model error worth finding (1 mm of an
/// anchor, 1 % of a stiffness) is 0.1–1 mm and tens of N.
const POSITION_TOLERANCE_MM: f64 = 1e-4;
const FORCE_TOLERANCE_N: f64 = 0.01;

fn config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(name)
}

/// crs-nominal and the crs-ideal plant, with the load's torque dropped (the oracle's load has a
/// potential only as a weight; a weight at the platform origin is a constant wrench at every
/// rotation, as the platform's w_e is).
fn files(dir: &Path) -> (PathBuf, PathBuf) {
    let pf = std::fs::read_to_string(config("crs-nominal.toml")).unwrap();
    let no_torque = pf.replace(
        "wrench_n_nm = [0.0, 0.0, -5500.0, 0.0, -480.0, 0.0]",
        "wrench_n_nm = [0.0, 0.0, -5500.0, 0.0, 0.0, 0.0]",
    );
    assert_ne!(no_torque, pf, "crs-nominal's [load] changed");
    let plant = std::fs::read_to_string(config("plant/crs-ideal.toml")).unwrap();
    let plant = plant.replace("../crs-nominal.toml", "crs-nominal.toml");
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("crs-nominal.toml"), no_torque).unwrap();
    std::fs::write(dir.join("crs-ideal.toml"), plant).unwrap();
    (dir.join("crs-nominal.toml"), dir.join("crs-ideal.toml"))
}

#[test]
fn the_evaluations_errors_are_the_oracles() {
    let dir = std::env::temp_dir().join(format!("crs-surrogate-oracle-{}", std::process::id()));
    let (pf_path, plant_path) = files(&dir);
    let pf = load_platform(&pf_path).unwrap();
    let (sg, _) = fit_platform(&pf, &surrogate::FitOptions::default()).unwrap();
    let grid = 2;
    let ev = evaluate(&pf, &sg, &plant_path, grid).unwrap();

    // The oracle's robot: the same numbers (no deviations on the ideal plant).
    let p = pf.model.params();
    let v = |x: &nalgebra::Vector3<f64>| glam::DVec3::new(x.x, x.y, x.z);
    let robot = plant_oracle::Robot::new(
        (0..pf.model.m())
            .map(|i| plant_oracle::Cable {
                frame_exit: v(&p.a[i]),
                anchor: v(&p.b[i]),
                pulley: None,
                k_f: p.k_f[i],
            })
            .collect(),
        plant_oracle::Load {
            mass: 0.0,
            center_of_gravity: glam::DVec3::ZERO,
            gravity: 0.0,
            force: glam::DVec3::new(p.w_e[0], p.w_e[1], p.w_e[2]),
        },
        0.0,
    )
    .unwrap();
    assert!(p.pulleys.is_none(), "the oracle robot above has no pulleys");

    // The grid of `evaluate`, in its order.
    let (lo, hi) = cdpr_model::offset_target::region_box(&pf.region);
    let at = |d: usize, k: usize| lo[d] + (hi[d] - lo[d]) * k as f64 / (grid - 1) as f64;
    let rot = |d: usize, k: usize| match k {
        0 => lo[d],
        1 => 0.0f64.clamp(lo[d], hi[d]),
        _ => hi[d],
    };
    let mut poses = Vec::new();
    for iz in 0..grid {
        for iy in 0..grid {
            for ix in 0..grid {
                for r in 0..27 {
                    poses.push(Pose::from_array([
                        at(0, ix),
                        at(1, iy),
                        at(2, iz),
                        rot(3, r % 3),
                        rot(4, (r / 3) % 3),
                        rot(5, r / 9),
                    ]));
                }
            }
        }
    }
    assert_eq!(poses.len(), ev.poses);

    let m = pf.model.m();
    let mut target = OffsetTarget::new(&pf.model);
    let mut data = Data::new(&pf.model);
    for (use_surrogate, tracking) in [(false, &ev.kinematic), (true, &ev.surrogate)] {
        // The controller's command φ(x) + φ_sg(x) + c. Set-up at home as sec. 6.1: the cables
        // tensioned to the set-up forces there — f_ini (or f_ref(home)) made to balance the
        // load, f_0 = −A^{+T} w_e + (I − A^{+T} A^T) f_ini (eq. 3.19), the operator's goal —
        // realised on the oracle's robot from its own cable lengths at home and the linear
        // law, q_θ = q (1 − f / k_F); c zeroed against the controller's command there.
        let f_goal: Vec<f64> = if use_surrogate {
            target.reference_forces(&pf.home).unwrap().0.to_vec()
        } else {
            pf.f_ini.clone().unwrap()
        };
        kinematics::inverse(&pf.model, &mut data, &pf.home).unwrap();
        let (mut f_ext, mut f_int) = (vec![0.0; m], vec![0.0; m]);
        cdpr_model::statics::split_internal_external(
            &data, &p.w_e, &f_goal, &mut f_ext, &mut f_int,
        )
        .unwrap();
        let f_setup: Vec<f64> = f_ext.iter().zip(&f_int).map(|(a, b)| a + b).collect();
        let home = PoseQ::from_array(pf.home.to_array());
        let command = |x: &Pose, data: &mut Data| -> Vec<f64> {
            kinematics::inverse(&pf.model, data, x).unwrap();
            let mut off = vec![0.0; m];
            if use_surrogate {
                sg.eval(&x.to_array(), &mut off).unwrap();
            }
            (0..m).map(|i| data.q[i] + off[i]).collect()
        };
        let q_home = command(&pf.home, &mut data);
        let c: Vec<f64> = (0..m)
            .map(|i| {
                let q = cable_length(&robot.cables()[i], &home).unwrap();
                q * (1.0 - f_setup[i] / p.k_f[i]) - q_home[i]
            })
            .collect();
        let (mut worst_dp, mut worst_df, mut compared) = (0.0_f64, 0.0_f64, 0);
        let (mut max_p, mut max_f) = (0.0_f64, 0.0_f64);
        for (k, x) in poses.iter().enumerate() {
            if !tracking.position_error_mm[k].is_finite() {
                continue; // the plant found no equilibrium there: nothing to compare
            }
            let q: Vec<f64> = command(x, &mut data)
                .iter()
                .zip(&c)
                .map(|(q, c)| q + c)
                .collect();
            let eq = equilibrium(&robot, &q, x.to_array(), &Default::default())
                .unwrap_or_else(|e| panic!("oracle at pose {k} {x:?}: {e}"));
            let (dp, _) = Pose::from_array(eq.pose).error_to(x);
            let f_ref = target.reference_forces(x).unwrap().0.to_vec();
            let fe = eq
                .forces
                .iter()
                .zip(&f_ref)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            worst_dp = worst_dp.max((dp * 1e3 - tracking.position_error_mm[k]).abs());
            worst_df = worst_df.max((fe - tracking.force_error_n[k]).abs());
            max_p = max_p.max(dp * 1e3);
            max_f = max_f.max(fe);
            compared += 1;
        }
        let name = if use_surrogate {
            "kinematics + surrogate"
        } else {
            "kinematics"
        };
        println!(
            "{name}: {compared} of {} poses; oracle max position error {max_p:.3} mm, force error \
             {max_f:.1} N; evaluation vs oracle per pose: {worst_dp:.1e} mm, {worst_df:.1e} N",
            poses.len()
        );
        assert!(
            compared * 10 >= poses.len() * 9,
            "{name}: only {compared} compared"
        );
        assert!(worst_dp < POSITION_TOLERANCE_MM, "{name}: {worst_dp} mm");
        assert!(worst_df < FORCE_TOLERANCE_N, "{name}: {worst_df} N");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
