//! # calibration-campaigns: identification on the plant and on the running stack
//!
//! - [`calibration_loop`]: the closed calibration loop (`crs calibrate loop`): before run,
//!   identification, after run, report.
//! - [`calibration_output`]: one identification run and what it writes (report, plots,
//!   calibrated.toml, side file).
//! - [`calibration_demo`]: the demo's identification and validation campaigns on the plant.
//! - [`diagnosis_bench`]: the residual diagnosis benchmark (`crs calibrate bench-diagnosis`),
//!   with [`bench_generator`], its data sets drawn from the independent benchmark plant.
//! - [`commission`]: commissioning and the pre-ride check (`crs commission`, eq. 6.21–6.24, 3.42).
//! - [`progress`]: how a long step shows that it runs (the CLI's spinner).

pub mod bench_generator;
pub mod calibration_demo;
pub mod calibration_loop;
pub mod calibration_output;
pub mod commission;
pub mod diagnosis_bench;
pub mod progress;
