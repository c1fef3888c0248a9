//! # bench-plant: an independent plant for the calibration diagnosis benchmark
//!
//! The residual diagnosis of `calibrate` names the physical effect a control model lacks. Held
//! to data from sim-plant — whose effects are written in the same parameterization, by the
//! same hands, as calibrate's candidates — it measures agreement with itself. This crate writes
//! the effects a second time, as a calibration engineer meets them on real machines, on a
//! different formulation:
//!
//! * The equilibrium is the minimum of the robot's potential energy ([`equilibrium`]) with
//!   cable lengths from plant-oracle (pulleys from the tangent condition); every force
//!   direction, moment arm and end force comes out of differences of energies. No structure
//!   matrix, no φ_el, no cdpr-model, no nalgebra (`crates/crs/tests/layering.rs`).
//! * Each effect has its own physics and its own parameters ([`scenario::Kind`]): drum radius
//!   errors counted from the set-up or from zero and a rope-layer step; length hysteresis
//!   switched by the command direction or by the force direction, with and without a dead
//!   band, its state held between commands; stored rope and drive-train compliance; a rope
//!   soft at low tension (constructional stretch); exact elastic catenaries; pulleys with their
//!   own radii and tilted axes; a cabin whose gravity torque turns with the platform; load-cell
//!   gains and offsets; encoder offsets after a re-homing; any two at once.
//! * The controller is the nominal kinematic one with the initial tension set at the home pose
//!   by hand ([`plant::Plant::set_up`]); the campaign is random poses with tension tests
//!   ([`campaign`]), read through a noisy tracker and load cells.
//!
//! The crate knows neither calibrate nor any data-set format: it returns rows of numbers, the
//! caller (calibration-campaigns' `bench_generator`) writes them as data sets.
//!
//! Units: SI (m, rad, N, kg). Poses are `[x, y, z, φx, φy, φz]` with R = R_x R_y R_z (eq. 2.2).

pub mod cable;
pub mod campaign;
pub mod equilibrium;
pub mod plant;
pub mod robot;
pub mod scenario;

pub use campaign::{Campaign, Controller, Nominal, Phase, Recording, Row, random_poses, record};
pub use plant::{Plant, PlantSpec};
pub use robot::PlantError;
pub use scenario::{Kind, TrueValue, Truth, build};

/// Shortening of every cable in the tension test after each pose, m (the experiments' tension
/// test, Fig. 6.15).
pub const TENSION_TEST_M: f64 = 0.03;

/// An identification and a validation data set of one scenario.
#[derive(Clone, Debug, PartialEq)]
pub struct Generated {
    pub truth: Truth,
    pub train: Recording,
    pub holdout: Recording,
}

/// Records one scenario: `poses` reachable random poses (drawn until that many kept their
/// forces inside the limits, at most 4× as many tried) with tension tests for identification,
/// and 3/4 as many (other poses, other noise) for validation, each campaign after its own
/// (identical, deterministic) set-up of the initial tension. `u` is the magnitude fraction per
/// kind.
pub fn generate(
    nominal: &Nominal,
    kinds: &[Kind],
    u: &[f64],
    seed: u64,
    poses: usize,
) -> Result<Generated, PlantError> {
    let truth = build(nominal, kinds, u, seed);
    let campaign = |plant: &mut Plant, count: usize, pose_seed: u64, rehome: Option<usize>| {
        let controller = Controller::new(nominal, plant.set_up_commands());
        record(
            plant,
            &controller,
            nominal,
            &Campaign {
                poses: random_poses(4 * count, pose_seed),
                reachable: Some(count),
                tension_shortening: Some(TENSION_TEST_M),
                rehome_after: rehome,
            },
        )
    };
    let mut plant = Plant::set_up(truth.spec.clone(), nominal.home, &nominal.f_ini, seed)?;
    let train = campaign(
        &mut plant,
        poses,
        seed.wrapping_mul(2).wrapping_add(1),
        truth.rehome_half_way.then_some(poses / 2),
    );
    let mut plant = Plant::set_up(
        truth.spec.clone(),
        nominal.home,
        &nominal.f_ini,
        seed.wrapping_add(0x9E37_79B9),
    )?;
    if truth.rehome_half_way {
        plant.rehome();
    }
    let holdout = campaign(
        &mut plant,
        (poses * 3).div_ceil(4),
        seed.wrapping_mul(2).wrapping_add(0x5151),
        None,
    );
    Ok(Generated {
        truth,
        train,
        holdout,
    })
}
