//! The plant checked against its independent oracle (a formulation sharing no code with it).
//!
//! The plant solves its equilibrium with the model library's kinematics, statics and forward
//! kinematics — the same code the controller runs. [`plant_oracle`] finds the same equilibrium
//! as the minimum of the potential energy from cable lengths alone, with its own pulley
//! geometry, rotations and minimiser, and no code of the model library. Here both solve the
//! plant's CONSERVATIVE TWIN — its physical geometry (deviations, pulleys), the linear cable
//! law of eq. 2.33–2.36 and its load — at poses around home, from the same controlled
//! lengths; they must agree to the resolution of the oracle's finite differences. An error in
//! the shared equations (a unit vector, moment arm, pulley term or sign) would show here,
//! where comparing controller and plant could not see it.
//!
//! The twin drops what has no potential or is the plant's own code (powertrain compliance,
//! tension-dependent stiffness, hysteresis, sag, sensor models — `cable_law.rs` is not shared
//! with the controller) and a constant world torque (no potential; a nominal load torque of a
//! vertical weight becomes the equivalent centre of gravity).

use crate::config::{Load, PlantConfig};
use crate::plant::{Plant, PlantError};
use cdpr_model::Pose;
use nalgebra::{Vector3, Vector6};
use plant_oracle::{Cable, Options, OracleError, PoseQ, Pulley, Robot};

/// Largest position difference accepted between plant and oracle, m. The oracle resolves
/// ~1e-11 m, the plant's solver stops at a relative wrench residual of ~1e-10: 1e-7 m is far
/// above both and far below any modelling error worth finding (a 1 mm anchor error moves the
/// equilibrium by ~0.1–1 mm).
pub const POSITION_TOLERANCE_M: f64 = 1e-7;
/// Largest rotation difference accepted, rad.
pub const ROTATION_TOLERANCE_RAD: f64 = 1e-7;
/// Largest cable-force difference accepted, N (measured ~2e-5 N; a 1 mm anchor error gives ~20 N).
pub const FORCE_TOLERANCE_N: f64 = 0.01;

/// Why the check could not be run.
#[derive(Debug, thiserror::Error)]
pub enum OracleCheckError {
    #[error("the oracle cannot describe the plant: {0}")]
    Oracle(#[from] OracleError),
    #[error("the plant's twin cannot be built: {0}")]
    Plant(#[from] PlantError),
    #[error("no pose around home could be set up with the initial tension ({skipped} tried)")]
    NoPose { skipped: usize },
}

/// How the plant and the oracle agreed.
#[derive(Clone, Debug, PartialEq)]
pub struct OracleAgreement {
    /// Poses compared, and poses skipped (outside the region or tension not realisable).
    pub poses: usize,
    pub skipped: usize,
    pub max_position_m: f64,
    pub max_rotation_rad: f64,
    pub max_force_n: f64,
    /// Effects of the plant the twin leaves out (they are the plant's own code or have no
    /// potential).
    pub left_out: Vec<&'static str>,
}

impl OracleAgreement {
    pub fn within_tolerance(&self) -> bool {
        self.max_position_m <= POSITION_TOLERANCE_M
            && self.max_rotation_rad <= ROTATION_TOLERANCE_RAD
            && self.max_force_n <= FORCE_TOLERANCE_N
    }
}

impl std::fmt::Display for OracleAgreement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} poses: position {:.1e} m, rotation {:.1e} rad, force {:.1e} N (tolerances {:.0e} m, \
             {:.0e} rad, {} N)",
            self.poses,
            self.max_position_m,
            self.max_rotation_rad,
            self.max_force_n,
            POSITION_TOLERANCE_M,
            ROTATION_TOLERANCE_RAD,
            FORCE_TOLERANCE_N
        )?;
        if self.skipped > 0 {
            write!(f, ", {} skipped", self.skipped)?;
        }
        if !self.left_out.is_empty() {
            write!(f, "; twin without {}", self.left_out.join(", "))?;
        }
        Ok(())
    }
}

/// The plant's conservative twin and the names of the effects it leaves out.
pub fn conservative_twin(config: &PlantConfig) -> (PlantConfig, Vec<&'static str>) {
    let mut twin = config.clone();
    let fx = &mut twin.effects;
    let mut left_out = Vec::new();
    let mut drop = |on: bool, name| {
        if on {
            left_out.push(name);
        }
    };
    drop(fx.powertrain.take().is_some(), "powertrain");
    drop(fx.stiffness.take().is_some(), "stiffness");
    drop(fx.hysteresis.take().is_some(), "hysteresis");
    drop(fx.sag.take().is_some(), "sag");
    drop(fx.tracker.take().is_some(), "tracker");
    drop(fx.force_sensors.take().is_some(), "force_sensors");
    match &mut fx.load {
        Some(l) => {
            if l.extra_wrench.fixed_rows::<3>(3).norm() > 0.0 {
                l.extra_wrench.fixed_rows_mut::<3>(3).fill(0.0);
                left_out.push("load torque");
            }
        }
        None => {
            let w = twin.platform.model.params().w_e;
            let tau = Vector3::new(w[3], w[4], w[5]);
            if tau.norm() > 0.0 {
                // A vertical weight W with a torque τ ⟂ e_z is W at the centre of gravity c
                // with c × (0, 0, −W) = τ: c = (τ_y/W, −τ_x/W, 0). Same wrench at zero
                // rotation, and a potential.
                let weight = -w[2];
                if w[0] == 0.0 && w[1] == 0.0 && weight > 0.0 && w[5] == 0.0 {
                    let g = crate::config::STANDARD_GRAVITY;
                    fx.load = Some(Load {
                        mass: weight / g,
                        center_of_gravity: Vector3::new(w[4] / weight, -w[3] / weight, 0.0),
                        extra_wrench: Vector6::zeros(),
                        gravity: g,
                    });
                } else {
                    left_out.push("constant torque");
                    let zeroed = twin.platform.model.with_params(|p| {
                        p.w_e.fixed_rows_mut::<3>(3).fill(0.0);
                    });
                    if let Ok(m) = zeroed {
                        twin.platform.model = m;
                    }
                }
            }
        }
    }
    (twin, left_out)
}

/// The oracle's description of a plant: the plant's physical model (geometry with deviations
/// and pulleys, k_F) and its load — numbers, not code.
pub fn oracle_robot(plant: &Plant) -> Result<Robot, OracleError> {
    let p = plant.physical_model().params();
    let v = |x: &Vector3<f64>| glam::DVec3::new(x.x, x.y, x.z);
    let cables = (0..p.a.len())
        .map(|i| Cable {
            frame_exit: v(&p.a[i]),
            anchor: v(&p.b[i]),
            pulley: p.pulleys.as_ref().and_then(|pl| {
                (pl.radius[i] > 0.0).then(|| Pulley {
                    radius: pl.radius[i],
                    axis: v(&pl.axis[i]),
                })
            }),
            k_f: p.k_f[i],
        })
        .collect();
    let (load, torque) = match &plant.config().effects.load {
        Some(l) => (
            plant_oracle::Load {
                mass: l.mass,
                center_of_gravity: v(&l.center_of_gravity),
                gravity: l.gravity,
                force: glam::DVec3::new(l.extra_wrench[0], l.extra_wrench[1], l.extra_wrench[2]),
            },
            l.extra_wrench.fixed_rows::<3>(3).norm(),
        ),
        None => (
            plant_oracle::Load {
                mass: 0.0,
                center_of_gravity: glam::DVec3::ZERO,
                gravity: 0.0,
                force: glam::DVec3::new(p.w_e[0], p.w_e[1], p.w_e[2]),
            },
            p.w_e.fixed_rows::<3>(3).norm(),
        ),
    };
    Robot::new(cables, load, torque)
}

/// Pose and force differences of the plant's equilibrium and the oracle's for the commands
/// `q_cmd`; the oracle starts 3–4 mm and 0.1–0.2° away from the plant's answer, so it finds the
/// minimum itself.
pub fn compare(
    plant: &mut Plant,
    robot: &Robot,
    q_cmd: &[f64],
) -> Result<(f64, f64, f64), OracleCheckError> {
    let eq = plant.step(q_cmd)?;
    let mut guess = eq.pose.to_array();
    for (g, d) in guess.iter_mut().zip([
        0.003,
        -0.002,
        0.004,
        0.2_f64.to_radians(),
        -0.15_f64.to_radians(),
        0.1_f64.to_radians(),
    ]) {
        *g += d;
    }
    let o = plant_oracle::equilibrium(robot, &eq.q_theta, guess, &Options::default())?;
    let x = eq.pose.to_array();
    let dp = ((o.pose[0] - x[0]).powi(2) + (o.pose[1] - x[1]).powi(2) + (o.pose[2] - x[2]).powi(2))
        .sqrt();
    // Angle of the relative rotation, 2 atan2(|v|, |w|): exact at tiny angles, where glam's
    // angle_between (an acos of the dot product) rounds 1e-10 rad to 0.
    let rel = PoseQ::from_array(x).q.inverse() * o.pose_q.q;
    let dr = 2.0 * rel.xyz().length().atan2(rel.w.abs());
    let df = eq
        .forces
        .iter()
        .zip(&o.forces)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    Ok((dp, dr, df))
}

/// The poses of the check as offsets from home (m, rad): home and six around it, ±0.2 m along
/// each axis with a few degrees of rotation.
const OFFSETS: [[f64; 6]; 7] = {
    const D: f64 = 2.0 * std::f64::consts::PI / 180.0;
    [
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.2, 0.0, 0.0, D, 0.0, 0.0],
        [-0.2, 0.0, 0.0, 0.0, -D, 0.0],
        [0.0, 0.2, 0.0, 0.0, 0.0, D],
        [0.0, -0.2, 0.0, -D, D, 0.0],
        [0.0, 0.0, 0.2, 0.0, D, -D],
        [0.15, -0.15, -0.2, D, 0.0, D],
    ]
};

/// The poses of [`OFFSETS`] inside the platform's region.
fn poses(config: &PlantConfig) -> Vec<Pose> {
    let home = config.platform.home.to_array();
    OFFSETS
        .iter()
        .map(|o| Pose::from_array(std::array::from_fn(|k| home[k] + o[k])))
        .filter(|p| config.platform.region.contains(p))
        .collect()
}

/// The set-up forces of the check: the platform's `f_ini`, else (f_min + f_max)/2 per cable
/// (the plant projects them onto its equilibrium, eq. 3.19).
pub fn set_up_forces(plant: &Plant) -> Vec<f64> {
    let params = plant.physical_model().params();
    plant
        .config()
        .platform
        .f_ini
        .clone()
        .unwrap_or_else(|| vec![0.5 * (params.f_min + params.f_max); params.a.len()])
}

/// Builds the twin and compares plant and oracle at the poses around home, each set up with
/// the platform's initial tension (its `f_ini`, else (f_min + f_max)/2 per cable, projected
/// onto the equilibrium by the plant, eq. 3.19).
pub fn check_against_oracle(config: &PlantConfig) -> Result<OracleAgreement, OracleCheckError> {
    let (twin, left_out) = conservative_twin(config);
    let poses = poses(&twin);
    let mut plant = Plant::new(twin)?;
    let robot = oracle_robot(&plant)?;
    let f_ini = set_up_forces(&plant);
    let mut out = OracleAgreement {
        poses: 0,
        skipped: OFFSETS.len() - poses.len(),
        max_position_m: 0.0,
        max_rotation_rad: 0.0,
        max_force_n: 0.0,
        left_out,
    };
    for pose in &poses {
        let Ok(setup) = plant.setup_tension(pose, &f_ini) else {
            out.skipped += 1;
            continue;
        };
        let (dp, dr, df) = compare(&mut plant, &robot, &setup.q_cmd)?;
        out.poses += 1;
        out.max_position_m = out.max_position_m.max(dp);
        out.max_rotation_rad = out.max_rotation_rad.max(dr);
        out.max_force_n = out.max_force_n.max(df);
    }
    if out.poses == 0 {
        return Err(OracleCheckError::NoPose {
            skipped: out.skipped,
        });
    }
    Ok(out)
}
