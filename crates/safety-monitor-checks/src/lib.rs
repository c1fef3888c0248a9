//! # safety-monitor-checks: what the independent safety stage computes and judges (spec sec. 5.6)
//!
//! The stage recomputes the kinematics every 15 ms and stops the robot when the drive signal
//! q_θ and its own computation φ*(x) differ by more than Δq_lim = 100 mm. This crate holds its
//! model and checks, free of any process plumbing; the process (iceoryx2, CAN, the cycle) is
//! the `safety-monitor` crate, its settings `safety-monitor-config`.
//!
//! | job | module |
//! |---|---|
//! | own platform TOML reading (glam, no motion-core code) | [`platform`] |
//! | own platform identity (SHA-256 of the parameters) | [`identity`] |
//! | own standard inverse kinematics φ*(x), eq. 2.2–2.7 | [`kinematics`] |
//! | every check + the latched state machine | [`monitor`] |
//! | trip causes and the trip log | [`trip`] |
//! | who may reset: the operator's request as a type, the safety I/O node's key, the reset socket (SO_PEERCRED) | [`operator`], [`reset_socket`] |
//! | fixed capacities of the preallocated state | [`capacity`] |
//!
//! Diverse redundancy: nothing here uses motion-core or nalgebra. See docs/safety-monitor.md.

pub mod capacity;
pub mod identity;
pub mod kinematics;
pub mod monitor;
pub mod operator;
pub mod platform;
pub mod reset_socket;
pub mod trip;

pub use monitor::{Limits, Monitor, MonitorState, ResetDecision, StateCode};
pub use trip::{Cause, Fault, TripRecord};
