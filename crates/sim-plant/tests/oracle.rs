//! The plant as an independent oracle (issue 14): its own geometry, pulley model, cable law and
//! energy-based equilibrium (`sim_plant::oracle`) cross-checked against the model library
//! (`cdpr-model`: `kinematics::inverse`, `LinearElastic`, `statics`, ν_el) on the ideal plant,
//! and a mismatch put into one side only shows as a disagreement far above the tolerance.
//!
//! Tolerances (why round-off): cable lengths are ≈ 10 m, so one ulp is 2e-15 m; the two pulley
//! formulations (tangent construction with arccos vs. atan2 + Rodrigues) differ by a few ulps
//! of β r_p. Lengths and unit vectors must agree to 1e-12 (m, –), i.e. a few hundred ulps.
//! Forces are k_F (q − q_θ)/q with k_F = 2e6 N: a length ulp is 4e-10 N, so forces agree to
//! 1e-8 N. The equilibrium poses come from two different solvers that each stop at their
//! round-off floor (residual wrench ≈ 1e-9 N against a stiffness ≈ 1e6 N/m): poses must agree
//! to 1e-11 m / rad and forces to 1e-6 N (measured: 1e-14 and 1e-9).

#![allow(clippy::needless_range_loop)] // per-cable index loops read like the equations

mod common;
use cdpr_model::config::load_platform;
use cdpr_model::elastostatics;
use cdpr_model::forward::{FkOptions, elastostatic};
use cdpr_model::{Data, Model, Pose, kinematics, statics};
use common::*;
use glam::DVec3;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use sim_plant::cable_law::PlantLaw;
use sim_plant::config::PulleyEffect;
use sim_plant::oracle::{self, OracleModel, State, Workspace};
use sim_plant::{Plant, PlantConfig, PlantState};

const LENGTH_TOL: f64 = 1e-12;
const FORCE_TOL: f64 = 1e-8;
const POSE_TOL: f64 = 1e-11;
const EQ_FORCE_TOL: f64 = 1e-6;

/// The ideal plant of the pulley platform (config/icosahedron-pulleys.toml).
fn ideal_pulleys() -> PlantConfig {
    let path = config_dir().join("icosahedron-pulleys.toml");
    let platform = load_platform(&path).expect("icosahedron-pulleys.toml");
    PlantConfig::ideal(platform, path)
}

/// Seeded poses around home in the operating region (±1.2 m, ±0.3 m in z, ±4°).
fn poses(home: &Pose, n: usize, seed: u64) -> Vec<Pose> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let mut x = home.to_array();
            for k in 0..2 {
                x[k] += rng.random_range(-1.2..1.2);
            }
            x[2] += rng.random_range(-0.3..0.3);
            for k in 3..6 {
                x[k] += rng.random_range(-4.0f64..4.0).to_radians();
            }
            Pose::from_array(x)
        })
        .collect()
}

/// Largest disagreement of the oracle's cables with `kinematics::inverse` over `poses`:
/// (length, free length, wrap angle × r, unit vector).
fn cable_disagreement(model: &Model, oracle_model: &OracleModel, poses: &[Pose]) -> [f64; 4] {
    let mut data = Data::new(model);
    let mut st = State::new(model.m());
    let mut worst = [0.0f64; 4];
    let r_p = |i: usize| model.params().pulleys.as_ref().map_or(0.0, |p| p.radius[i]);
    for x in poses {
        kinematics::inverse(model, &mut data, x).unwrap();
        oracle::place(oracle_model, &x.to_array(), &mut st).unwrap();
        for i in 0..model.m() {
            let c = &st.cables[i];
            let du = (0..3)
                .map(|k| (c.u[k] - data.u[i][k]).abs())
                .fold(0.0, f64::max);
            let d = [
                (c.q - data.q[i]).abs(),
                (c.q_free - data.q_free[i]).abs(),
                ((c.beta - data.beta[i]) * r_p(i)).abs(),
                du,
            ];
            for k in 0..4 {
                worst[k] = worst[k].max(d[k]);
            }
        }
    }
    worst
}

#[test]
fn oracle_cable_geometry_matches_the_model_library_to_round_off() {
    for cfg in [ideal(), ideal_pulleys()] {
        let model = cfg.platform.model.clone();
        let om = OracleModel::from_config(&cfg);
        let worst = cable_disagreement(&model, &om, &poses(&cfg.platform.home, 200, 1));
        println!(
            "{}: worst |Δq| {:e} m, |Δq_f| {:e} m, |Δβ r_p| {:e} m, |Δu| {:e}",
            cfg.name, worst[0], worst[1], worst[2], worst[3]
        );
        assert!(
            worst.iter().all(|d| *d < LENGTH_TOL),
            "{}: {worst:?}",
            cfg.name
        );
    }
    // the pulley platform really exercises the pulley model: wrap lengths of decimetres
    let cfg = ideal_pulleys();
    let model = &cfg.platform.model;
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, &cfg.platform.home).unwrap();
    assert!(
        data.beta.iter().all(|b| *b * 0.161 > 0.05),
        "{:?}",
        data.beta
    );
}

#[test]
fn oracle_forces_and_residual_wrench_match_the_model_library() {
    for cfg in [ideal(), ideal_pulleys()] {
        let model = cfg.platform.model.clone();
        let om = OracleModel::from_config(&cfg);
        let mut law = PlantLaw::new(&model.params().k_f, &cfg.effects);
        assert!(law.is_linear());
        let mut data = Data::new(&model);
        let mut st = State::new(model.m());
        let mut worst_f = 0.0f64;
        let mut worst_w = 0.0f64;
        let mut slack = 0;
        for (n, x) in poses(&cfg.platform.home, 50, 2).iter().enumerate() {
            kinematics::inverse(&model, &mut data, x).unwrap();
            // controlled lengths 0–4 cm shorter than the cables (one cable slack now and then)
            let q_theta: Vec<f64> = (0..8)
                .map(|i| data.q[i] - 0.04 * (((n * 8 + i) * 7919 % 101) as f64 / 100.0) + 0.00213)
                .collect();
            elastostatics::cable_forces(&mut data, &model.linear_law(), &q_theta);
            let w_lib = statics::residual_wrench(&data, &data.f, &model.params().w_e);
            oracle::place(&om, &x.to_array(), &mut st).unwrap();
            oracle::tension(&om, &mut law, &q_theta, &mut st);
            for i in 0..8 {
                worst_f = worst_f.max((st.f[i] - data.f[i]).abs());
                slack += usize::from(st.f[i] == 0.0);
                assert_eq!(st.f[i] == 0.0, data.f[i] == 0.0, "slack state of cable {i}");
            }
            for k in 0..6 {
                worst_w = worst_w.max((st.residual[k] - w_lib[k]).abs());
            }
        }
        println!(
            "{}: worst |Δf| {worst_f:e} N, |Δρ| {worst_w:e} N/N·m, {slack} slack",
            cfg.name
        );
        assert!(slack > 0, "the slack branch is exercised");
        assert!(worst_f < FORCE_TOL, "{}: {worst_f:e} N", cfg.name);
        assert!(worst_w < 10.0 * FORCE_TOL, "{}: {worst_w:e}", cfg.name);
    }
}

/// Commands q_θ = φ_el(x, f_ref) of the model library (eq. 2.37, 3.41) for poses around home,
/// each with 0–1 cm of extra length per cable (a tension state away from f_ref), and the pose
/// it was made for (the start of both solvers).
fn elastostatic_commands(cfg: &PlantConfig, n: usize, seed: u64) -> Vec<(Pose, Vec<f64>)> {
    let model = &cfg.platform.model;
    let p = model.params();
    let mut data = Data::new(model);
    let mut f_ref = vec![0.0; 8];
    let mut out = Vec::new();
    for x in poses(&cfg.platform.home, n, seed) {
        kinematics::inverse(model, &mut data, &x).unwrap();
        let fd = statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f_ref).unwrap();
        if !fd.feasible {
            continue;
        }
        let mut q = vec![0.0; 8];
        elastostatics::inverse(model, &mut data, &x, &f_ref, &mut q).unwrap();
        for (i, v) in q.iter_mut().enumerate() {
            *v += 0.01 * ((i * 37 + out.len() * 11) % 17) as f64 / 16.0;
        }
        out.push((x, q));
    }
    out
}

/// Largest disagreement of the plant's equilibrium with the model library's ν_el, both
/// started from the command's pose: (position m, rotation rad, force N), and the number
/// compared.
fn equilibrium_disagreement(
    plant_cfg: PlantConfig,
    model: &Model,
    commands: &[(Pose, Vec<f64>)],
) -> ([f64; 3], usize) {
    let mut data = Data::new(model);
    let mut worst = [0.0f64; 3];
    let mut plant = Plant::new(plant_cfg).unwrap();
    let fresh = plant.state();
    for (x, q) in commands {
        plant.restore(&PlantState {
            pose: *x,
            ..fresh.clone()
        });
        let eq = plant.step(q).unwrap();
        let sol = elastostatic(model, &mut data, q, x, &FkOptions::default()).unwrap();
        let (dp, dr) = eq.pose.error_to(&sol.pose);
        worst[0] = worst[0].max(dp);
        worst[1] = worst[1].max(dr);
        for i in 0..8 {
            worst[2] = worst[2].max((eq.forces[i] - data.f[i]).abs());
        }
    }
    (worst, commands.len())
}

#[test]
fn ideal_plant_equilibrium_matches_the_model_library_nu_el_to_round_off() {
    for cfg in [ideal(), ideal_pulleys()] {
        let cmds = elastostatic_commands(&cfg, 30, 3);
        let model = cfg.platform.model.clone();
        let name = cfg.name.clone();
        let (worst, n) = equilibrium_disagreement(cfg, &model, &cmds);
        println!(
            "{name}: {n} equilibria, worst Δpose {:e} m {:e} rad, Δf {:e} N",
            worst[0], worst[1], worst[2]
        );
        assert!(n >= 20, "{name}: {n} feasible poses");
        assert!(
            worst[0] < POSE_TOL && worst[1] < POSE_TOL,
            "{name}: {worst:?}"
        );
        assert!(worst[2] < EQ_FORCE_TOL, "{name}: {worst:?}");
    }
}

#[test]
fn a_mismatch_in_one_formulation_is_detected() {
    // The model library keeps r_p = 161 mm; the plant's pulley effect says 161.1 mm (0.1 mm).
    let cfg = ideal_pulleys();
    let model = cfg.platform.model.clone();
    let mut wrong = cfg.clone();
    let pl = model.params().pulleys.clone().unwrap();
    wrong.effects.pulleys = Some(PulleyEffect {
        radius: pl.radius.iter().map(|r| r + 1e-4).collect(),
        axis: pl.axis.clone(),
    });
    let home = cfg.platform.home;
    let ps = poses(&home, 20, 4);
    let d = cable_disagreement(&model, &OracleModel::from_config(&wrong), &ps);
    println!("r_p + 0.1 mm: worst |Δq| {:e} m", d[0]);
    assert!(
        d[0] > 1e3 * LENGTH_TOL,
        "pulley radius error not seen in lengths: {d:?}"
    );
    let cmds = elastostatic_commands(&cfg, 10, 5);
    let (worst, _) = equilibrium_disagreement(wrong, &model, &cmds);
    println!(
        "r_p + 0.1 mm: worst Δpose {:e} m, Δf {:e} N",
        worst[0], worst[2]
    );
    assert!(
        worst[0] > 1e3 * POSE_TOL,
        "pulley radius error not seen in poses: {worst:?}"
    );

    // One frame anchor 1 µm off in the plant only.
    let mut shifted = ideal();
    let model = shifted.platform.model.clone();
    let mut offsets = vec![nalgebra::Vector3::zeros(); 8];
    offsets[3].x = 1e-6;
    shifted.effects.geometry = Some(sim_plant::config::GeometryDeviation {
        frame_anchor_offsets: offsets,
        platform_anchor_offsets: vec![nalgebra::Vector3::zeros(); 8],
    });
    let d = cable_disagreement(
        &model,
        &OracleModel::from_config(&shifted),
        &poses(&home, 20, 6),
    );
    println!("a_3 + 1 µm: worst |Δq| {:e} m", d[0]);
    assert!(
        d[0] > 10.0 * LENGTH_TOL,
        "1 µm anchor error not seen: {d:?}"
    );
    let cmds = elastostatic_commands(&shifted, 10, 7);
    let (worst, _) = equilibrium_disagreement(shifted, &model, &cmds);
    println!(
        "a_3 + 1 µm: worst Δpose {:e} m, Δf {:e} N",
        worst[0], worst[2]
    );
    assert!(
        worst[0] > 10.0 * POSE_TOL || worst[2] > 10.0 * EQ_FORCE_TOL,
        "{worst:?}"
    );
}

#[test]
fn ideal_equilibrium_is_the_minimum_of_the_potential_energy() {
    let cfg = ideal();
    let mut om = OracleModel::from_config(&cfg);
    // crs-nominal's constant torque τ_y = −480 N·m has no potential in pose coordinates; the
    // same torque at home from the weight acting 87 mm off the origin has one.
    assert_eq!(om.loads.constant, [0.0, 0.0, -5500.0, 0.0, -480.0, 0.0]);
    om.loads.constant = [0.0; 6];
    om.loads.weight = Some((
        DVec3::new(0.0, 0.0, -5500.0),
        DVec3::new(-480.0 / 5500.0, 0.0, 0.0),
    ));
    let mut law = PlantLaw::new(&cfg.platform.model.params().k_f, &cfg.effects);
    let (x_cmd, q) = &elastostatic_commands(&cfg, 3, 8)[1];
    let mut ws = Workspace::new(8);
    let sol = oracle::solve(&om, &mut law, q, &x_cmd.to_array(), &mut ws).unwrap();
    let mut st = State::new(8);
    let mut energy = |x: &[f64; 6], law: &mut PlantLaw| {
        oracle::place(&om, x, &mut st).unwrap();
        oracle::tension(&om, law, q, &mut st);
        (oracle::potential(&om, q, &st).unwrap(), st.gradient)
    };
    let (u0, _) = energy(&sol.x, &mut law);
    // g is ∂U/∂x (central differences of U at a pose away from the equilibrium)
    let mut x1 = sol.x;
    x1[0] += 0.003;
    x1[4] += 0.002;
    let (_, g1) = energy(&x1, &mut law);
    for k in 0..6 {
        let h = 1e-6;
        let (mut a, mut b) = (x1, x1);
        a[k] += h;
        b[k] -= h;
        let fd = (energy(&a, &mut law).0 - energy(&b, &mut law).0) / (2.0 * h);
        assert!(
            (fd - g1[k]).abs() < 1e-3 * (1.0 + g1[k].abs()),
            "∂U/∂x_{k}: {fd} vs {}",
            g1[k]
        );
    }
    assert!(
        g1.iter().any(|g| g.abs() > 100.0),
        "the test pose is away from equilibrium"
    );
    // every nearby pose has more energy: a strict minimum
    let mut rng = StdRng::seed_from_u64(9);
    for _ in 0..50 {
        let x: [f64; 6] = std::array::from_fn(|k| sol.x[k] + rng.random_range(-1e-3..1e-3));
        let (u, _) = energy(&x, &mut law);
        assert!(u > u0, "U {u} at {x:?} below the equilibrium's {u0}");
    }
}

#[test]
fn crs_like_plant_is_in_equilibrium_by_the_model_library_statics() {
    // The other direction with every effect on: the model library's kinematics of the plant's
    // physical model (geometry errors, pulleys) at the plant's pose gives the plant's lengths,
    // and its statics closes the wrench with the plant's forces and load (sag share included).
    let mut plant = Plant::new(crs_like()).unwrap();
    let q0 = home_command(&mut plant);
    let model = plant.physical_model().clone();
    let mut data = Data::new(&model);
    let mut n = 0;
    for k in 0..6 {
        let q: Vec<f64> = q0
            .iter()
            .enumerate()
            .map(|(i, v)| v + 0.03 * (((i + k) % 4) as f64 - 1.5))
            .collect();
        let eq = plant.step(&q).unwrap();
        kinematics::inverse(&model, &mut data, &eq.pose).unwrap();
        for i in 0..8 {
            assert!((eq.lengths[i] - data.q[i]).abs() < LENGTH_TOL, "cable {i}");
        }
        let r = statics::residual_wrench(&data, &eq.forces, &eq.wrench);
        assert!(r.amax() < 1e-6, "{r}");
        assert!(eq.forces.iter().all(|f| *f > 0.0));
        n += 1;
    }
    assert_eq!(n, 6);
}
