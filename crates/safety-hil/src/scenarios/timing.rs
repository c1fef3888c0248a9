//! The spec's timing per scenario, asserted on the host (`safety-hil --assert-timing`; never in
//! the emulated guest, which is not real time).
//!
//! Detection (fault to the monitor's trip event) is bounded in monitor cycles: a check on the
//! setpoint stream sees every setpoint published since the last cycle, so a fault in the stream
//! is detected in the cycle after it (≤ 2 cycles from the fault, counting the cycle in which it
//! happened); a silence check after its configured number of cycles without the stream (+ 2:
//! the cycle phase and the trip cycle). The stop (fault to every emulated drive braked) is the
//! detection bound plus the drives' safety-heartbeat validation time (SCT; the monitor's quick
//! stop and NMT stop go out in the trip cycle, the STOP heartbeat or its absence brakes the
//! drives within the SCT at the latest) plus one cycle for the emulator's status file.

use crate::Res;
use crate::configs::LOAD_CELL_EVERY_N_SYNCS;
use crate::scenarios::Outcome;

/// The monitor's cycle of the generated config (`[monitor] cycle_ms`).
pub const MONITOR_CYCLE_MS: f64 = 15.0;

/// What the bounds depend on (the command line of the run).
#[derive(Debug, Clone, Copy)]
pub struct TimingArgs {
    /// The drives' and drive-io's safety-heartbeat validation time (ms).
    pub validation_ms: f64,
    /// The monitor's setpoint silence (cycles).
    pub silence_cycles: u32,
    /// The monitor's feedback and force silence (cycles).
    pub feedback_silence_cycles: u32,
    /// The period of the 1 kHz loops (ms).
    pub period_ms: f64,
}

/// A scenario's bounds (ms): detection (None: nothing detects it on the monitor, e.g. the
/// monitor itself is killed) and fault to braked drives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bound {
    pub detect_ms: Option<f64>,
    pub stop_ms: f64,
}

/// Detection in `cycles` monitor cycles, the stop within the SCT after it.
fn by_monitor(cycles: f64, t: &TimingArgs) -> Bound {
    let d = cycles * MONITOR_CYCLE_MS;
    Bound {
        detect_ms: Some(d),
        stop_ms: d + t.validation_ms + MONITOR_CYCLE_MS,
    }
}

/// The spec's bound of scenario `name`, None if it has no timing to assert (a reset, a refused
/// configuration, a fault drive-io stops on its own).
pub fn bound(name: &str, t: &TimingArgs) -> Option<Bound> {
    let silence = f64::from(t.silence_cycles) + 2.0;
    let feedback = f64::from(t.feedback_silence_cycles) + 2.0;
    Some(match name {
        // A setpoint out of bounds: the next cycle sees it.
        "offset_101mm_trips"
        | "nan_pose"
        | "pose_jump_inside_box"
        | "lying_timestamps"
        | "jump_from_rest"
        | "identity_mismatch"
        | "forged_rpdo"
        | "forged_rpdo_other_enabling_controlword"
        | "forged_stopping"
        | "stop_frame_lost"
        | "impersonation_under_isolation"
        | "timestamp_jump"
        | "state_event_flood" => by_monitor(2.0, t),
        // CAN error frames pass the monitor's bus reader thread: one more cycle.
        "can_bus_off" | "can_error_passive" => by_monitor(3.0, t),
        // Every 4th sequence number lost: more than 5 lost after 24 setpoints.
        "sequence_gaps" => by_monitor(2.0 + 24.0 * t.period_ms / MONITOR_CYCLE_MS, t),
        // The stream stops (scenario end or a dead/frozen producer).
        "offset_99mm_no_trip"
        | "frozen_motion_core"
        | "kill_motion_core"
        | "reset_while_armed_changes_nothing" => by_monitor(silence, t),
        // drive-io dies or its feedback is stale: feedback silence.
        "kill_drive_io" => by_monitor(feedback, t),
        // The same at the scenario's longer silence (configs::stale_feedback_silence_cycles).
        "stale_published_feedback" => by_monitor(
            f64::from(crate::configs::stale_feedback_silence_cycles(
                t.feedback_silence_cycles,
            )) + 2.0,
            t,
        ),
        // 8 of the last 16 load-cell readings out of band, from the emulator's first pass
        // with the injected force (the first reading goes out within one reading period),
        // then the monitor's cycle.
        "overload_one_cable" | "slack_one_cable" => {
            let readings = 8.0 * f64::from(LOAD_CELL_EVERY_N_SYNCS) * t.period_ms;
            by_monitor(2.0 + readings / MONITOR_CYCLE_MS, t)
        }
        // Nothing on the monitor detects it: the drives' watch brakes after the SCT.
        "kill_monitor" | "corrupted_safety_frame" => Bound {
            detect_ms: None,
            stop_ms: t.validation_ms + 2.0 * MONITOR_CYCLE_MS,
        },
        // No bound: `foreign_publisher` (t0 is before the publisher's thread and iceoryx2 port
        // exist; opening them has no defined instant), the resets, refused configurations,
        // drive-io's own stops (`lying_timestamps`' step: drive-io, not the monitor) and the
        // flutter (its detection depends on the pattern).
        _ => return None,
    })
}

/// Checks a passed scenario's measured times against its bound: a bound whose time was not
/// measured fails too (a scenario that asserts timing must measure it).
pub fn check_timing(name: &str, o: &Outcome, t: &TimingArgs) -> Res<()> {
    let Some(b) = bound(name, t) else {
        return Ok(());
    };
    if let Some(limit) = b.detect_ms {
        match o.detect_ms {
            Some(d) if d <= limit => {}
            Some(d) => {
                return Err(format!(
                    "detection took {d:.1} ms, the spec allows {limit:.1} ms ({:.1} cycles)",
                    limit / MONITOR_CYCLE_MS
                ));
            }
            None => return Err("detection time not measured".into()),
        }
    }
    match o.stop_ms {
        Some(s) if s <= b.stop_ms => Ok(()),
        Some(s) => Err(format!(
            "fault to braked drives took {s:.1} ms, the spec allows {:.1} ms",
            b.stop_ms
        )),
        None => Err("fault-to-braked time not measured".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HOST: TimingArgs = TimingArgs {
        validation_ms: 50.0,
        silence_cycles: 2,
        feedback_silence_cycles: 4,
        period_ms: 1.0,
    };

    fn outcome(detect: Option<f64>, stop: Option<f64>) -> Outcome {
        Outcome {
            detect_ms: detect,
            stop_ms: stop,
            ..Outcome::default()
        }
    }

    #[test]
    fn a_setpoint_fault_is_detected_within_two_cycles() {
        let b = bound("offset_101mm_trips", &HOST).expect("bounded");
        assert_eq!(b.detect_ms, Some(30.0));
        assert_eq!(b.stop_ms, 30.0 + 50.0 + 15.0);
        assert!(
            check_timing(
                "offset_101mm_trips",
                &outcome(Some(29.9), Some(60.0)),
                &HOST
            )
            .is_ok()
        );
        let late = check_timing(
            "offset_101mm_trips",
            &outcome(Some(30.1), Some(60.0)),
            &HOST,
        );
        assert!(late.unwrap_err().contains("detection took 30.1 ms"));
        let slow_stop = check_timing(
            "offset_101mm_trips",
            &outcome(Some(10.0), Some(95.1)),
            &HOST,
        );
        assert!(
            slow_stop
                .unwrap_err()
                .contains("braked drives took 95.1 ms")
        );
    }

    #[test]
    fn silence_bounds_follow_the_configured_cycles() {
        let b = bound("frozen_motion_core", &HOST).expect("bounded");
        assert_eq!(b.detect_ms, Some(4.0 * 15.0));
        let b = bound("kill_drive_io", &HOST).expect("bounded");
        assert_eq!(b.detect_ms, Some(6.0 * 15.0));
    }

    #[test]
    fn an_unmeasured_time_of_a_bounded_scenario_fails() {
        assert!(check_timing("nan_pose", &outcome(None, Some(10.0)), &HOST).is_err());
        assert!(check_timing("nan_pose", &outcome(Some(10.0), None), &HOST).is_err());
        // The drives' watch: no detection on the monitor, only the stop is bounded.
        assert!(check_timing("kill_monitor", &outcome(None, Some(79.0)), &HOST).is_ok());
        assert!(check_timing("kill_monitor", &outcome(None, Some(81.0)), &HOST).is_err());
    }

    #[test]
    fn the_force_window_bound_counts_eight_load_cell_readings() {
        // 8 readings every 5 SYNCs at 1 kHz + 2 cycles, from the emulator's first pass with
        // the injected force.
        let b = bound("overload_one_cable", &HOST).expect("bounded");
        assert!((b.detect_ms.expect("monitor") - (40.0 + 30.0)).abs() < 1e-9);
    }

    #[test]
    fn scenarios_without_timing_are_not_checked() {
        assert!(bound("reset_refused_then_accepted", &HOST).is_none());
        assert!(check_timing("tampered_safety_config", &outcome(None, None), &HOST).is_ok());
    }
}
