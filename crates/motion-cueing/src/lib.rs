//! # motion-cueing: a vehicle's motion in the CRS cabin (spec sec. 5.6)
//!
//! The CRS takes its Cartesian motion from "a trajectory generator, a motion cueing algorithm,
//! or a human-in-the-loop physics simulation" (sec. 5.6). This crate is the second: the
//! classical washout with tilt coordination, scaled and limited so that every pose stays in
//! the cabin's small operating region (table 5.1: ±4–5° of rotation) and its wrench-feasible
//! set, and the vestibular models that tell what the rider perceives of it against what the
//! vehicle's occupant perceived.
//!
//! | job | module | literature / spec |
//! |---|---|---|
//! | exact (zero-order-hold) discretisation of transfer functions | [`lti`] | |
//! | classical washout, tilt coordination, scaling, workspace limiter | [`washout`] | Reid & Nahon 1985; Nesti et al. 2012 |
//! | the cueing TOML (units, bounds) and the platform check | [`settings`] | table 5.1, eq. 3.29, 3.41, 5.13–5.16 |
//! | a drive as a stream: fade in/out, settle at home | [`source`] | |
//! | what the rider feels in the cabin (specific force at the head, body rates) | [`cabin`] | eq. 2.2, 2.45–2.46 |
//! | otolith and semicircular-canal models, perception error per axis | [`vestibular`] | Young & Meiry 1968; Telban & Cardullo 2005 |
//! | perception of a whole run: vehicle vs cabin vs perceived | [`perception`] | |
//! | vehicle CSV (documented format, errors by line and column) | [`vehicle`] | |
//! | the generated vehicle profiles of `config/vehicle/` | [`profiles`] | |
//! | SVG plots of a run | [`plot`] | |
//!
//! No IPC, real time or CLI here: `sim-runs` runs a [`source::CueingSource`] at 1 kHz on a
//! thread off the hard loop and feeds motion-core's cueing input (`crs sim --source cueing`).

pub mod cabin;
pub mod lti;
pub mod perception;
pub mod plot;
pub mod profiles;
pub mod settings;
pub mod source;
pub mod vehicle;
pub mod vestibular;
pub mod washout;

pub use settings::CueingSettings;
pub use source::{CueingSource, DriveSample};
pub use vehicle::{VehicleSample, VehicleTrack};
pub use washout::{CueOutput, TrackerLimits, Washout, WashoutState};
