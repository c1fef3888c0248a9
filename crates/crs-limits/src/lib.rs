//! # crs-limits: the fixed limits every layer agrees on, in one place
//!
//! A crate without dependencies so that the model library, the surrogate, the IPC contract and
//! the independent safety monitor can all name the same value without depending on each other
//! (issue 14: the |Δq| limit lived in three crates under three names, the cable count in three).

/// Most cables any platform, payload or drive table of the stack holds: the fixed-size arrays of
/// the `#[repr(C)]` IPC payloads and the allocation-free hot paths are sized by it.
pub const MAX_CABLES: usize = 16;

/// The spec's bound on the joint-space offset |Δq_i| = |q_θ,i − q_i| the surrogate may command
/// and the safety monitor lets through (sec. 5.6, eq. 5.27: 100 mm), m.
pub const DELTA_Q_LIMIT_M: f64 = 0.100;
