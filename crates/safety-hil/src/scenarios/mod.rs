//! The scenarios, grouped by topic; each starts from a running stack ([`crate::stack::Stack`]),
//! injects one fault and returns what it measured.

pub mod bus;
pub mod forces;
pub mod holes;
pub mod integrity;
pub mod process_faults;
pub mod reset_authority;
pub mod setpoint_stream;

/// What a scenario measured (ms; None if not applicable).
#[derive(Debug, Default, Clone)]
pub struct Outcome {
    pub cause: String,
    pub detect_ms: Option<f64>,
    pub stop_ms: Option<f64>,
    pub note: String,
}

/// Milliseconds from `from_ns` to `to_ns` (CLOCK_MONOTONIC), None if either is unknown.
pub fn ms(from_ns: u64, to_ns: u64) -> Option<f64> {
    (from_ns > 0 && to_ns >= from_ns).then(|| (to_ns - from_ns) as f64 * 1e-6)
}

pub mod timing;
pub use timing::{TimingArgs, check_timing};
