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

/// Milliseconds from the fault (`from_ns`) to the monitor's trip event (`trip_ns`, its
/// timestamp). The monitor stamps a trip with the START of the cycle that detected it: a fault
/// injected while that cycle ran (its events drained after the injection) is stamped up to one
/// cycle before the fault. Such a trip was detected in the cycle running at the injection and
/// counts as 0 ms; a trip stamped more than one cycle before the fault is no detection of it
/// (None: "not measured", which fails a timed scenario).
pub fn trip_ms(from_ns: u64, trip_ns: u64) -> Option<f64> {
    if from_ns == 0 || trip_ns == 0 {
        return None;
    }
    if trip_ns >= from_ns {
        return ms(from_ns, trip_ns);
    }
    let early_ms = (from_ns - trip_ns) as f64 * 1e-6;
    (early_ms <= timing::MONITOR_CYCLE_MS).then_some(0.0)
}

pub mod timing;
pub use timing::{TimingArgs, check_timing};

#[cfg(test)]
mod trip_time_tests {
    use super::*;

    #[test]
    fn a_trip_stamped_in_the_cycle_running_at_the_fault_is_detected_at_once() {
        let t0 = 1_000_000_000;
        assert_eq!(trip_ms(t0, t0 + 3_000_000), Some(3.0));
        // Stamped at the start of the cycle that drained the fault's events: 0 ms.
        assert_eq!(trip_ms(t0, t0 - 4_000_000), Some(0.0));
        // More than a monitor cycle before the fault: no detection of it.
        assert_eq!(trip_ms(t0, t0 - 16_000_000), None);
        assert_eq!(trip_ms(0, t0), None);
        assert_eq!(trip_ms(t0, 0), None);
        // Other stamps (the drives braked) before the fault stay unmeasured.
        assert_eq!(ms(t0, t0 - 1), None);
    }
}
