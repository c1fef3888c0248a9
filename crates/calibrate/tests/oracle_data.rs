//! Identification on data the model library did not make. The other identification tests
//! record their data on sim-plant, whose equilibrium is the model library's own elastostatic
//! forward kinematics — the equations calibration inverts — so "recovers to round-off" there
//! would survive an error both share (a sign of a moment arm, the stretch law). Here the
//! measurements come from `plant-oracle`: the equilibrium as the minimum of the potential
//! energy from cable lengths alone (glam, no model-library code; crates/plant-oracle). The
//! robot is the CRS nominal platform with the CRS-like plant's geometry deviations, its own
//! k_F and load; calibration must find those numbers from (command, oracle pose, oracle forces)
//! alone, to the oracle's resolution.

mod common;
use calibrate::params::{Group, group};
use calibrate::{CalModel, FitSpec, Kind, Observation, ParamId, fit};
use cdpr_model::config::Platform;
use cdpr_model::{Data, Pose, elastostatics, kinematics, statics};
use common::*;
use nalgebra::Vector3;
use sim_plant::config::Effects;
use sim_plant::{Plant, PlantConfig, oracle_check};

/// Largest parameter error accepted: anchors in m, k_F relative, w_e in kN. Measured on this
/// data: 4.1e-8; the oracle resolves its pose to ~1e-11 m and its forces to ~1e-5 N,
/// and cond(J W_pc) ≈ 4e4 turns that into the parameters. A 1 mm anchor error is 1e-3.
const TOLERANCE: f64 = 1e-6;

/// The nominal platform without a load torque: the oracle's load has a potential only as a
/// weight, and a weight at the platform origin is the calibration model's constant w_e at
/// every rotation (a constant world torque has no potential, see plant-oracle's docs).
fn truth_platform() -> Platform {
    let mut pf = nominal();
    pf.model = pf
        .model
        .with_params(|p| p.w_e.fixed_rows_mut::<3>(3).fill(0.0))
        .unwrap();
    pf
}

/// The physical robot: the platform with the CRS-like geometry deviations, told to the oracle
/// as numbers (frame exits, anchors, k_F, load).
fn truth_plant() -> Plant {
    let mut cfg = PlantConfig::ideal(truth_platform(), config_dir().join("crs-nominal.toml"));
    cfg.effects = Effects {
        geometry: crs_like_effects().geometry,
        ..Effects::default()
    };
    Plant::new(cfg).unwrap()
}

/// xorshift64*: a fixed, dependency-free sequence in [0, 1).
struct Seq(u64);
impl Seq {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `n` samples: the nominal model's elastostatic command for its reference forces (eq. 3.41,
/// 2.37) at random poses of the sec. 6.1 box, the oracle's equilibrium for that command on
/// `robot` (pose and forces measured exactly).
fn oracle_campaign(robot: &plant_oracle::Robot, n: usize) -> Vec<Observation> {
    let pf = truth_platform();
    let (model, p) = (&pf.model, pf.model.params());
    let mut data = Data::new(model);
    let (mut f_ref, mut q) = (vec![0.0; model.m()], vec![0.0; model.m()]);
    let mut rnd = Seq(0x5eed_0f0a_ac1e);
    let mut obs = Vec::new();
    while obs.len() < n {
        let mut u = || 2.0 * rnd.next() - 1.0;
        let x = Pose::new(
            Vector3::new(1.5 * u(), 1.5 * u(), 1.625 + 0.375 * u()),
            Vector3::new(u(), u(), u()) * 5f64.to_radians(),
        );
        kinematics::inverse(model, &mut data, &x).unwrap();
        let fd = statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f_ref).unwrap();
        if !fd.feasible {
            continue;
        }
        elastostatics::inverse(model, &mut data, &x, &f_ref, &mut q).unwrap();
        let eq = plant_oracle::equilibrium(robot, &q, x.to_array(), &Default::default())
            .unwrap_or_else(|e| panic!("oracle at {x:?}: {e}"));
        assert!(eq.forces.iter().all(|f| *f > 0.0), "a slack cable: {eq:?}");
        let k = obs.len() as u64;
        obs.push(Observation {
            sample: k,
            pose_index: k,
            phase: crs_dataset::Phase::Pose,
            q_cmd: q.clone(),
            pose: Pose::from_array(eq.pose),
            forces: Some(eq.forces.clone()),
            pose_ref: Some(x),
            direction: vec![0.0; model.m()],
            direction_beyond_noise: vec![0.0; model.m()],
            command_direction: vec![0.0; model.m()],
        });
    }
    obs
}

fn free_base(m: usize) -> Vec<ParamId> {
    [Group::A, Group::B, Group::KF, Group::We, Group::Offset]
        .iter()
        .flat_map(|g| group(*g, m))
        .collect()
}

/// Worst error of the identified parameters against the stated truth (m, relative, kN).
fn worst_error(found: &CalModel, truth: &Plant) -> f64 {
    let t = truth.physical_model().params();
    let mut worst: f64 = 0.0;
    for i in 0..found.m() {
        worst = worst.max((found.a[i] - t.a[i]).amax());
        worst = worst.max((found.b[i] - t.b[i]).amax());
        worst = worst.max(((found.k_f[i] - t.k_f[i]) / t.k_f[i]).abs());
        worst = worst.max(found.offset[i].abs());
    }
    worst.max((found.w_e - t.w_e).amax() / 1e3)
}

fn identify(obs: &[Observation]) -> CalModel {
    let pf = truth_platform();
    let mut start = CalModel::from_model(&pf.model);
    for k in start.k_f.iter_mut() {
        *k *= 1.3;
    }
    start.w_e[2] *= 0.8;
    let spec = FitSpec::new(Kind::Elastostatic, free_base(start.m()));
    let f = fit(&start, obs, &spec, &mut |_, _| {}).expect("fit");
    assert!(
        f.fixed_unobservable.is_empty(),
        "{:?}",
        f.fixed_unobservable
    );
    f.model
}

#[test]
fn elastostatic_identification_recovers_the_oracles_robot() {
    let plant = truth_plant();
    let robot = oracle_check::oracle_robot(&plant).unwrap();
    let obs = oracle_campaign(&robot, 40);
    let worst = worst_error(&identify(&obs), &plant);
    println!("40 oracle samples: worst parameter error {worst:.2e} (tolerance {TOLERANCE:.0e})");
    assert!(worst < TOLERANCE, "worst parameter error {worst:e}");
}

/// Not vacuous: the same identification on data of a robot whose cable 3 frame exit sits 1 mm
/// from what the comparison calls the truth is 1 mm off — far outside the tolerance.
#[test]
fn a_robot_other_than_the_stated_one_is_seen() {
    let plant = truth_plant();
    let right = oracle_check::oracle_robot(&plant).unwrap();
    let mut cables = right.cables().to_vec();
    cables[2].frame_exit.x += 0.001;
    let moved = plant_oracle::Robot::new(cables, *right.load(), 0.0).unwrap();
    let worst = worst_error(&identify(&oracle_campaign(&moved, 40)), &plant);
    println!("robot with a 1 mm moved exit: worst parameter error {worst:.2e}");
    assert!(worst > 100.0 * TOLERANCE, "{worst:e}");
}
