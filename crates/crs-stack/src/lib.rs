//! # crs-stack: the running stack as a library
//!
//! What `crs sim`, the closed calibration loop (`crs calibrate loop`) and the HIL runners share,
//! so the `crs` binary stays command-line glue:
//!
//! - [`calibration_loop`]: the closed calibration loop (`crs calibrate loop`): before run,
//!   identification, after run, report.
//! - [`supervisor`]: ONE process supervisor — start the daemons in order with their logs and
//!   IPC prefix, notice the first child that dies, stop all (SIGTERM, then SIGKILL) in reverse
//!   order, Ctrl-C handling.
//! - [`rest_recording`]: rest points of a run from the live topics → a `crs-dataset 1` file.
//! - [`campaign`]: calibration-campaign generation and waypoint timing/writing, checked with
//!   motion-core's own [`configure`](motion_core::daemon::lifecycle::configure) step.
//! - [`platforms`]: the platforms the stack runs (`crs sim --platform icosahedron|helicopter`)
//!   and the consistent set of daemon, plant, monitor and drives configs of each.
//! - [`ride_run`]: the helicopter hover physics (crate `ride-physics`) as the run's motion
//!   source on motion-core's cueing input (`crs sim --source helicopter`), and
//!   [`gamepad`], a game controller as its pilot.
//! - [`sim_run`]: one run of the whole simulated stack (`crs sim`), its summary and verdict.
//! - [`surrogate_evaluation`]: the surrogate fit of a platform and its evaluation on the plant.
//! - [`transport`]: which CAN transport a run uses (vcan0 or the UDP loopback bus).

pub mod calibration_loop;
pub mod campaign;
pub mod gamepad;
pub mod platforms;
pub mod rest_recording;
pub mod ride_run;
pub mod sim_run;
pub mod supervisor;
pub mod surrogate_evaluation;
pub mod transport;
