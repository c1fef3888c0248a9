//! Payload identification on forces the model library did not compute. The unit tests in
//! `payload.rs` make their rest forces with the model library's own statics (A^T f = −w_e,
//! eq. 3.41) and identify with the same structure matrix, so a sign error both share would
//! cancel. Here the cabin's rest poses and cable forces come from `plant-oracle`: the minimum of
//! the potential energy of the helicopter cabin's elastic cables and a load of known mass and
//! centre of gravity (glam, no model-library code). The fit must return that load.

use cdpr_model::config::load_platform;
use cdpr_model::{Data, Pose, kinematics, statics};
use glam::DVec3;
use load_tracking::G;
use load_tracking::payload::{RestSample, identify};
use nalgebra::{Vector3, Vector6};

/// Largest errors accepted: the oracle resolves forces to ~1e-5 N and poses to ~1e-11 m.
/// Measured: mass 5e-12 kg, centre of gravity 4.8e-9 m. A 1 mm error of one cable exit moves
/// them by 1.1e-2 kg and 3.5e-5 m.
const MASS_TOLERANCE_KG: f64 = 1e-6;
const COG_TOLERANCE_M: f64 = 1e-7;

/// The helicopter platform's cables and a load `mass_kg` at `cog_m` (platform frame), as numbers.
fn robot(mass_kg: f64, cog_m: [f64; 3], exit_shift_m: f64) -> plant_oracle::Robot {
    let pf = load_platform(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/helicopter.toml"
    ))
    .unwrap();
    let p = pf.model.params();
    let v = |x: &Vector3<f64>| DVec3::new(x.x, x.y, x.z);
    let cables = (0..p.a.len())
        .map(|i| plant_oracle::Cable {
            frame_exit: v(&p.a[i]) + DVec3::new(if i == 2 { exit_shift_m } else { 0.0 }, 0.0, 0.0),
            anchor: v(&p.b[i]),
            pulley: None,
            k_f: p.k_f[i],
        })
        .collect();
    let load = plant_oracle::Load {
        mass: mass_kg,
        center_of_gravity: DVec3::from_array(cog_m),
        gravity: G,
        force: DVec3::ZERO,
    };
    plant_oracle::Robot::new(cables, load, 0.0).unwrap()
}

/// Rest samples at level and tilted poses: commands that tension the cables about each pose
/// (eq. 3.41 forces of the stated load, stretched by the linear law), the oracle's equilibrium
/// (pose and forces) for them on `robot`.
fn rest_samples(robot: &plant_oracle::Robot, mass_kg: f64, cog_m: [f64; 3]) -> Vec<RestSample> {
    let pf = load_platform(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/helicopter.toml"
    ))
    .unwrap();
    let (model, p) = (&pf.model, pf.model.params());
    let mut data = Data::new(model);
    let mut out = Vec::new();
    for (k, (x, y)) in [
        (0.0, 0.0),
        (0.3, 0.2),
        (-0.3, 0.1),
        (0.2, -0.3),
        (-0.2, -0.2),
    ]
    .into_iter()
    .enumerate()
    {
        let phi = Vector3::new(0.04 * (k as f64 - 2.0), 0.03 * (1.0 - k as f64), 0.02);
        let pose = Pose::new(pf.home.r + Vector3::new(x, y, 0.0), phi);
        kinematics::inverse(model, &mut data, &pose).unwrap();
        let weight = Vector3::new(0.0, 0.0, -mass_kg * G);
        let tau = (pose.rotation() * Vector3::from(cog_m)).cross(&weight);
        let w = Vector6::new(weight.x, weight.y, weight.z, tau.x, tau.y, tau.z);
        let mut f = vec![0.0; model.m()];
        statics::force_distribution(&data, &w, p.f_min, p.f_max, &mut f).unwrap();
        let q_theta: Vec<f64> = (0..model.m())
            .map(|i| data.q[i] * (1.0 - f[i] / p.k_f[i]))
            .collect();
        let eq = plant_oracle::equilibrium(robot, &q_theta, pose.to_array(), &Default::default())
            .unwrap();
        assert!(eq.forces.iter().all(|f| *f > 0.0), "{eq:?}");
        out.push(RestSample {
            pose: Pose::from_array(eq.pose),
            forces: eq.forces,
        });
    }
    out
}

fn fit(samples: &[RestSample]) -> load_tracking::payload::Payload {
    let pf = load_platform(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/helicopter.toml"
    ))
    .unwrap();
    let mut data = Data::new(&pf.model);
    identify(&pf.model, &mut data, samples).unwrap()
}

#[test]
fn the_oracles_load_is_found() {
    let (m, c) = (764.5, [0.12, -0.08, 0.3]);
    let p = fit(&rest_samples(&robot(m, c, 0.0), m, c));
    let cog: Vec<f64> = p.cog_m.iter().map(|v| v.expect("observable")).collect();
    let dm = (p.mass_kg - m).abs();
    let dc = (0..3).map(|k| (cog[k] - c[k]).abs()).fold(0.0, f64::max);
    println!(
        "oracle rest data: mass {:.6} kg (true {m}), COG {cog:?} (true {c:?}); errors {dm:.1e} kg, {dc:.1e} m",
        p.mass_kg
    );
    assert!(dm < MASS_TOLERANCE_KG, "{p:?}");
    assert!(dc < COG_TOLERANCE_M, "{p:?}");
}

/// Not vacuous: forces of a robot whose cable 3 exits 1 mm elsewhere than the model says
/// give a load outside the tolerances.
#[test]
fn a_robot_other_than_the_model_is_seen() {
    let (m, c) = (764.5, [0.12, -0.08, 0.3]);
    let p = fit(&rest_samples(&robot(m, c, 0.001), m, c));
    let dm = (p.mass_kg - m).abs();
    let dc = (0..3)
        .map(|k| (p.cog_m[k].unwrap_or(f64::NAN) - c[k]).abs())
        .fold(0.0, f64::max);
    println!("robot with a 1 mm moved exit: errors {dm:.1e} kg, {dc:.1e} m");
    assert!(
        dm > 10.0 * MASS_TOLERANCE_KG || dc > 10.0 * COG_TOLERANCE_M,
        "{p:?}"
    );
}
