//! # safety-monitor: the independent 15 ms safety stage (spec sec. 5.6)
//!
//! In the CRS a separate SIL-3 stage controller recomputes the kinematics every 15 ms and forces
//! an emergency stop when the drive signal q_θ and its own redundant computation φ*(x) differ by
//! more than Δq_lim = 100 mm. This crate is that stage for the simulated stack:
//!
//! | job | module |
//! |---|---|
//! | own platform reading, identity, kinematics φ*(x), every check, the latched state machine, trip causes | crate `safety-monitor-checks` (re-exported: [`platform`], [`identity`], [`kinematics`], [`monitor`], [`trip`]) |
//! | the monitor's settings (config/safety-monitor.toml) | crate `safety-monitor-config` (re-exported: [`config`]) |
//! | the CANopen frames of the stop path | [`bus_frames`] |
//! | health of the own bus reader thread (fail closed) | [`bus_watch`] |
//! | who may reset: the safety I/O node's key, the reset socket (SO_PEERCRED) | crate `safety-monitor-checks` (re-exported: [`operator`], [`reset_socket`]) |
//! | stop frames with retry and escalation (NMT stop → heartbeat inhibit) | [`stop_path`] |
//! | the process: 15 ms cycle, iceoryx2, CAN stop, safety heartbeat, reset | [`daemon`] |
//!
//! Diverse redundancy: nothing here uses motion-core or nalgebra (motion-core is a
//! dev-dependency only, to test that both implementations agree). The doubled safety heartbeat
//! is `can_transport::safety_frame`; the drives' and drive-io's validation of it is
//! `drive_bus::safety_watch`. See docs/safety-monitor.md.

pub mod bus_frames;
pub mod bus_watch;
pub mod daemon;
pub mod ownership;
pub mod stop_path;
pub mod tx_buses;

// The checks and the settings, under the paths this crate has always offered.
pub use safety_monitor_checks::{
    Cause, Fault, Limits, Monitor, MonitorState, ResetDecision, StateCode, TripRecord, capacity,
    identity, kinematics, monitor, operator, platform, reset_socket, trip,
};
pub use safety_monitor_config::{accept, bus_layout, config};
