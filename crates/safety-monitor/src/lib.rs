//! # safety-monitor: the independent 15 ms safety stage (spec sec. 5.6)
//!
//! In the CRS a separate SIL-3 stage controller recomputes the kinematics every 15 ms and forces
//! an emergency stop when the drive signal q_θ and its own redundant computation φ*(x) differ by
//! more than Δq_lim = 100 mm. This crate is that stage for the simulated stack:
//!
//! | job | module |
//! |---|---|
//! | own platform TOML reading (glam, no motion-core code) | [`platform`] |
//! | own platform identity (SHA-256 of the parameters) | [`identity`] |
//! | own standard inverse kinematics φ*(x), eq. 2.2–2.7 | [`kinematics`] |
//! | the monitor's settings (config/safety-monitor.toml) | [`config`] |
//! | every check + the latched state machine | [`monitor`] |
//! | trip causes and the trip log | [`trip`] |
//! | the CANopen frames of the stop path | [`bus_frames`] |
//! | health of the own bus reader thread (fail closed) | [`bus_watch`] |
//! | who may reset: the safety I/O node's key, the reset socket (SO_PEERCRED) | [`operator`], [`reset_socket`] |
//! | stop frames with retry and escalation (NMT stop → heartbeat inhibit) | [`stop_path`] |
//! | the process: 15 ms cycle, iceoryx2, CAN stop, safety heartbeat, reset | [`daemon`] |
//!
//! Diverse redundancy: nothing here uses motion-core or nalgebra (motion-core is a
//! dev-dependency only, to test that both implementations agree). The doubled safety heartbeat
//! is `can_transport::safety_frame`; the drives' and drive-io's validation of it is
//! `drive_io::safety_watch`. See docs/safety-monitor.md.

pub mod accept;
pub mod bus_frames;
pub mod bus_layout;
pub mod bus_watch;
pub mod capacity;
pub mod config;
pub mod daemon;
pub mod identity;
pub mod kinematics;
pub mod monitor;
pub mod operator;
pub mod ownership;
pub mod platform;
pub mod reset_socket;
pub mod stop_path;
pub mod trip;
pub mod tx_buses;

pub use monitor::{Limits, Monitor, MonitorState, ResetDecision, StateCode};
pub use trip::{Cause, Fault, TripRecord};
