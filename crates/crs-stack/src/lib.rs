//! # crs-stack: the running stack as a library
//!
//! What `crs sim`, the closed calibration loop (`crs calibrate loop`) and the HIL runners share,
//! so the `crs` binary stays command-line glue:
//!
//! - [`calibration_demo`]: the demo's identification and validation campaigns on the plant.
//! - [`calibration_loop`]: the closed calibration loop (`crs calibrate loop`): before run,
//!   identification, after run, report.
//! - [`calibration_output`]: one identification run and what it writes (report, plots,
//!   calibrated.toml, side file).
//! - [`supervisor`]: ONE process supervisor — start the daemons in order with their logs and
//!   IPC prefix, notice the first child that dies, stop all (SIGTERM, then SIGKILL) in reverse
//!   order, Ctrl-C handling.
//! - [`progress`]: how a long step shows that it runs (the CLI's spinner).
//! - [`reachable_on_plant`]: the kinematic controller's reachable workspace measured on the plant.
//! - [`rest_recording`]: rest points of a run from the live topics → a `crs-dataset 1` file.
//! - [`campaign`]: calibration-campaign generation and waypoint timing/writing, checked with
//!   motion-core's own [`configure`](motion_core::daemon::lifecycle::configure) step.
//! - [`commission`]: commissioning and the pre-ride check (`crs commission`, eq. 6.21–6.24, 3.42).
//! - [`commission_report`]: what `crs commission` prints of a commissioning.
//! - [`diagnosis_bench`]: the residual diagnosis benchmark (`crs calibrate bench-diagnosis`).
//! - [`figures`]: the docs' headline figures regenerated into one JSON file (`crs figures`).
//! - [`load_experiment`]: the seed's walking-subject load tracking (sec. 5.3) on the plant.
//! - [`plant_check`]: a plant TOML checked and settled at home (`crs plant check`).
//! - [`plant_record`]: a measurement campaign on the plant written as a data set.
//! - [`platforms`]: the platforms the stack runs (`crs sim --platform icosahedron|helicopter`)
//!   and the consistent set of daemon, plant, monitor and drives configs of each.
//! - [`run_plots`]: the plots and index.html of every `crs sim` run.
//! - [`ride_run`]: the helicopter hover physics (crate `ride-physics`) as the run's motion
//!   source on motion-core's cueing input (`crs sim --source helicopter`), and
//!   [`gamepad`], a game controller as its pilot.
//! - [`console_setup`]: the operator console of a stack (platform view, plan progress).
//! - [`cueing_run`]: motion cueing (crate `motion-cueing`) of a vehicle CSV as the run's motion
//!   source on motion-core's cueing input (`crs sim --source cueing`), and what the rider
//!   perceived of it.
//! - [`sim_observer`]: what `crs sim` runs next to the stack: the console and the run's plots.
//! - [`sim_run`]: one run of the whole simulated stack (`crs sim`), its summary and verdict.
//! - [`surrogate_evaluation`]: the surrogate fit of a platform and its evaluation on the plant.
//! - [`surrogate_report`]: report.md/json and tracking.svg of a surrogate evaluation.
//! - [`timing`]: the timing profiles of a run (spec, relaxed for loaded hosts, emulated for the
//!   QEMU guest): the relaxed copies of the daemon, drives and monitor configs.
//! - [`transport`]: which CAN transport a run uses (vcan0 or the UDP loopback bus).

pub mod bench_generator;
pub mod calibration_demo;
pub mod calibration_loop;
pub mod calibration_output;
pub mod campaign;
pub mod commission;
pub mod commission_report;
pub mod console_setup;
pub mod cueing_run;
pub mod diagnosis_bench;
pub mod figures;
pub mod gamepad;
pub mod load_experiment;
pub mod pilot;
pub mod plant_check;
pub mod plant_record;
pub mod platforms;
pub mod progress;
pub mod reachable_on_plant;
pub mod rest_recording;
pub mod ride_run;
pub mod run_plots;
pub mod sim_observer;
pub mod sim_run;
pub mod supervisor;
pub mod surrogate_evaluation;
pub mod surrogate_report;
pub mod timing;
pub mod transport;
