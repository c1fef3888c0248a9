//! # sim-plant: the simulated elastostatic cable robot
//!
//! The "ground truth model" ν̂_el of the spec's meta-model (ch. 3.2, Fig. 3.2/3.7): what the
//! controller and the calibration are tested against. Given commanded (controlled) cable
//! lengths it returns the equilibrium the physical robot settles in — pose x̂ and forces f̂ from
//! the elastostatic forward kinematics (eq. 2.42–2.43) — and what the sensors read.
//!
//! Each physical effect is a named, parameterised block of the plant TOML ([`config`]), off
//! unless switched on, so a data set can carry effects the control model does not know:
//!
//! | effect | block | where |
//! |---|---|---|
//! | 1 geometry deviations Δa, Δb (ch. 3.2, eq. 6.7) | `geometry_deviation` | [`plant`] |
//! | 2 pulley kinematics (eq. 2.16–2.29) | `pulleys` | [`plant`] (motion-core) |
//! | 3 powertrain compliance (sec. 5.1, eq. 6.18) | `powertrain` | [`cable_law`] |
//! | 4 tension-dependent stiffness, hysteresis (Fig. 5.7) | `stiffness`, `hysteresis` | [`cable_law`] |
//! | 5 cable sag (Irvine / Ernst) | `sag` | [`cable_law`] |
//! | 6 drum radius, encoder offsets | `winch_errors` | [`plant`] |
//! | 7 platform mass and centre of gravity (eq. 6.20–6.23) | `load` | [`plant`] |
//! | 8 tracker and force-sensor models | `tracker`, `force_sensors` | [`plant`] |
//!
//! [`oracle_check`] proves the plant's equilibrium against an independent formulation
//! (`plant-oracle`: minimum potential energy from cable lengths, no model-library code), so an
//! error in the equations the plant shares with the controller would show.
//!
//! [`campaign`] drives the plant through measurement campaigns (ch. 6.1, 6.4) and returns its
//! results in the CSV data-set format of the `crs-dataset` crate (docs/data-format.md).

pub mod bus;
pub mod cable_law;
pub mod campaign;
pub mod config;
pub mod oracle_check;
pub mod plant;

pub use campaign::{
    CampaignConfig, CampaignError, CampaignResult, ControlKind, PoseErrors, PoseSet, SkipReason,
    Unreachable, load_campaign, parse_campaign, pose_errors, run_campaign,
};
pub use config::{Effects, PlantConfig, load_plant, parse_plant};
pub use plant::{Equilibrium, Plant, PlantError, PlantState, SensorReading, TensionSetup};
