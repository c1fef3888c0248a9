//! # crs-supervisor: the processes of a running stack
//!
//! What every run of the stack needs to start and stop its processes, and nothing else, so the
//! safety HIL (which runs the monitor's fault matrix under this supervisor) links no simulator,
//! calibration or report code:
//!
//! - [`supervisor`]: ONE process supervisor — start the daemons in order with their logs and
//!   IPC prefix, notice the first child that dies, stop all (SIGTERM, then SIGKILL) in reverse
//!   order, Ctrl-C handling.
//! - [`transport`]: which CAN transport a run uses (vcan0 or the UDP loopback bus).
//! - [`timing`]: the timing profiles of a run (spec, relaxed for loaded hosts, emulated for the
//!   QEMU guest): the relaxed copies of the daemon, drives and monitor configs.

pub mod supervisor;
pub mod timing;
pub mod transport;
