//! # ride-physics: what the riders feel (spec sec. 5.5)
//!
//! A Newton–Euler rigid-body hover model of the helicopter cabin driven by thrust, roll, pitch
//! and yaw inputs with aerial damping (eq. 5.21), and the border of the operating region
//! represented physically by elastic safety walls (spring k_w, damper d_w along the wall
//! normal, eq. 5.22), so a pilot flying into the border is pushed back softly instead of the
//! hard loop latching an e-stop.
//!
//! | job | module | spec |
//! |---|---|---|
//! | hover model (Model/Data split, one free `step`) | [`hover`] | 5.21 |
//! | elastic safety walls, translational and rotational | [`walls`] | 5.22 |
//! | pilot inputs: recorded CSV, scripted manoeuvres | [`pilot`] | sec. 5.5 |
//! | the ride TOML (damping, walls, assist) + the platform's `[dynamics]` | [`settings`] | 5.13–5.14, 5.21–5.22 |
//! | SVG of the flown path against the walls | [`plot`] | fig. 5.19 |
//!
//! No IPC, real time or CLI here: `sim-runs` runs the model at 1 kHz on a thread off the hard
//! loop and feeds motion-core's cueing input (`crs sim --source helicopter`).

pub mod hover;
pub mod pilot;
pub mod plot;
pub mod settings;
pub mod walls;

pub use hover::{HoverModel, HoverState, step};
pub use pilot::{PilotInput, PilotTrack};
pub use walls::Walls;
