//! Faults on the bus and at the drives: a corrupted safety pair, forged RPDOs, CAN error frames
//! (bus-off, error-passive), and the monitor's lost NMT stop.

use crate::Res;
use crate::configs::home_length;
use crate::scenarios::{Outcome, ms, trip_ms};
use crate::stack::{Stack, open_bus};
use crs_ipc::monotonic_ns;
use safety_monitor::Cause;
use std::sync::atomic::Ordering;
use std::time::Duration;

pub fn corrupted_safety_frame(st: &mut Stack) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let mut bus = open_bus(st, "safety")?;
    use can_transport::safety_frame::{SafetyHeartbeat, SafetyState, encode};
    let [a, b] = encode(
        &SafetyHeartbeat {
            state: SafetyState::Run,
            cause: 0,
            counter: 0x1234,
            epoch: 0,
        },
        0x101,
    );
    let mut d = [0u8; 8];
    d.copy_from_slice(b.data());
    d[4] ^= 0x08; // one bit of the inverted copy flipped
    let b = can_transport::CanFrame::new(0x102, &d).map_err(|e| e.to_string())?;
    let t0 = monotonic_ns();
    bus.send(&a).map_err(|e| e.to_string())?;
    bus.send(&b).map_err(|e| e.to_string())?;
    let (e, stopped) = st.stopped_by_the_drives_watch()?;
    Ok(Outcome {
        cause: "drives: invalid pair (inverse mismatch)".into(),
        detect_ms: ms(t0, e.safety_tripped_ns),
        stop_ms: ms(t0, stopped),
        note: "one injected pair with 1 bit flipped".into(),
    })
}

pub fn forged_rpdo(st: &mut Stack) -> Res<Outcome> {
    forged_rpdo_with(st, 0x000F)
}

/// Bits 4–6 and 8–15 of the controlword are mode/manufacturer bits: the drive still enables
/// operation and follows the target, so the monitor must check this RPDO too.
pub fn forged_rpdo_other_enabling_controlword(st: &mut Stack) -> Res<Outcome> {
    forged_rpdo_with(st, 0x001F)
}

pub fn forged_rpdo_with(st: &mut Stack, controlword: u16) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    // On node 4's interface (cables 3 and 4 are on can1).
    let mut bus = open_bus(st, crate::configs::drive_interface(3))?;
    // A faulty drive adapter: RPDO1 to node 4 (sign -1, offset 200e6) 300 mm off.
    let counts_per_m = 10.0 * 1_048_576.0 / (std::f64::consts::PI * 0.305);
    let target = 200_000_000.0 - (home_length() + 0.3) * counts_per_m;
    let f = safety_monitor::bus_frames::rpdo1(4, controlword, target.round() as i32);
    // A faulty adapter sends its RPDO every SYNC period until it is stopped.
    let t0 = monotonic_ns();
    let period = Duration::from_micros(u64::from(st.period_us));
    let sent = st.send_until_trip(t0, period, "forged RPDOs", || {
        bus.send(&f).map_err(|e| e.to_string())
    })?;
    let ev = st.monitor_trip(Cause::RpdoMismatch, 1.0)?;
    if ev.detail_node != 4 {
        return Err(format!("tripped on cable {}, expected 4", ev.detail_node));
    }
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "rpdo_mismatch cable 4".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!(
            "forged RPDO1 (controlword {controlword:#06x}) 300 mm off φ*(x), {sent} sent \
             before the trip"
        ),
    })
}

/// The bus controller reports `error` (injected: an error frame with CAN_ERR_FLAG, which
/// vcan and the UDP bus forward to every subscribed socket, as cansend would send it): the
/// monitor trips `can_bus_error`, drive-io stops every drive on its own (Fault BUS_ERROR).
pub fn can_bus_error(st: &mut Stack, error: can_transport::BusErrorFrame) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    // The controller of the first drive bus reports it.
    let mut bus = open_bus(st, "can0")?;
    let t0 = monotonic_ns();
    bus.send_bus_error(&error).map_err(|e| e.to_string())?;
    let ev = st.monitor_trip(Cause::CanBusError, 10.0)?;
    st.wait(
        "drive-io stopped on the error frame (Fault BUS_ERROR)",
        10.0,
        |s| Ok(s.last_feedback.and_then(|f| f.fault().ok()) == Some(crs_ipc::FaultCode::BusError)),
    )?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: format!(
            "can_bus_error ({}); drive-io BUS_ERROR",
            error.condition().name()
        ),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!("injected error frame {error}"),
    })
}

pub fn can_bus_off(st: &mut Stack) -> Res<Outcome> {
    can_bus_error(st, can_transport::BusErrorFrame::bus_off())
}

pub fn can_error_passive(st: &mut Stack) -> Res<Outcome> {
    can_bus_error(st, can_transport::BusErrorFrame::error_passive(128, 0))
}

/// The monitor's NMT stop cannot be sent (its process runs with the injected ENOBUFS on every
/// NMT frame): the stop escalates to the safety heartbeat's STOP, and the drives brake through
/// their watch, NOT through NMT (they stay NMT operational).
pub fn stop_frame_lost(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    c.cable.store(2, Ordering::Relaxed);
    st.wait_following(false)?;
    c.offset_target_um.store(101_000, Ordering::Relaxed);
    let ev = st.monitor_trip(Cause::DqLimit, 10.0)?;
    let t_cross = c.crossed_ns.load(Ordering::Relaxed);
    let stopped = st.require_braked()?;
    let e = st.emu()?;
    if e.drives.iter().any(|d| d.nmt == 4) {
        return Err("a drive is NMT-stopped: the NMT stop was not lost".into());
    }
    if e.safety_trips == 0 {
        return Err("the drives' safety watch did not trip".into());
    }
    let log = std::fs::read_to_string(st.dir.join("safety-monitor.log")).unwrap_or_default();
    if !log.contains("stop path ESCALATED") {
        return Err("the monitor did not log the escalation".into());
    }
    Ok(Outcome {
        cause: "dq_limit; NMT stop unsent → heartbeat inhibit".into(),
        detect_ms: trip_ms(t_cross, ev.timestamp_ns),
        stop_ms: ms(t_cross, stopped),
        note: "every NMT frame of the monitor fails (ENOBUFS injected); drives stay NMT operational, brake on the STOP pair".into(),
    })
}
