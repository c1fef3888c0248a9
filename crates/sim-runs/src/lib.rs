//! # sim-runs: one run of the whole simulated stack
//!
//! What `crs sim` runs (and what the calibration loop and commissioning run through it), on
//! the processes of [`crs_supervisor`]:
//!
//! - [`sim_run`]: one run of the whole simulated stack (`crs sim`), its summary and verdict.
//! - [`platforms`]: the platforms the stack runs (`crs sim --platform icosahedron|helicopter`)
//!   and the consistent set of daemon, plant, monitor and drives configs of each.
//! - [`campaign`]: calibration-campaign generation and waypoint timing/writing, checked with
//!   motion-core's own [`configure`](motion_core::daemon::lifecycle::configure) step.
//! - [`rest_recording`]: rest points of a run from the live topics → a `crs-dataset 1` file.
//! - [`ride_run`]: the helicopter hover physics (crate `ride-physics`) as the run's motion
//!   source on motion-core's cueing input (`crs sim --source helicopter`), with its [`pilot`]
//!   and [`gamepad`], a game controller as that pilot.
//! - [`cueing_run`]: motion cueing (crate `motion-cueing`) of a vehicle CSV as the run's motion
//!   source on motion-core's cueing input (`crs sim --source cueing`), and what the rider
//!   perceived of it.
//! - [`console_setup`]: the operator console of a stack (platform view, plan progress).

pub mod campaign;
pub mod console_setup;
pub mod cueing_run;
pub mod gamepad;
pub mod pilot;
pub mod platforms;
pub mod rest_recording;
pub mod ride_run;
pub mod sim_run;
