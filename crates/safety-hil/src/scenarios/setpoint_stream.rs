//! Faults in the setpoint stream, injected by the fake motion core: offsets at and just below
//! the 100 mm |Δq| limit, sequence gaps, NaN poses, a wrong identity, a consistent pose jump,
//! a step with lying timestamps.

use crate::Res;
use crate::configs::home_length;
use crate::emulator::DEMAND_FOLLOW;
use crate::fake_motion::FakeCtl;
use crate::scenarios::{Outcome, ms, trip_ms};
use crate::stack::Stack;
use crs_ipc::{BusState, monotonic_ns};
use safety_monitor::Cause;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

pub fn offset_101mm(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    c.cable.store(2, Ordering::Relaxed);
    st.wait_following(false)?;
    c.offset_target_um.store(101_000, Ordering::Relaxed);
    let ev = st.monitor_trip(Cause::DqLimit, 10.0)?;
    if ev.detail_node != 3 {
        return Err(format!("tripped on cable {}, expected 3", ev.detail_node));
    }
    let t_cross = c.crossed_ns.load(Ordering::Relaxed);
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "dq_limit cable 3".into(),
        detect_ms: trip_ms(t_cross, ev.timestamp_ns),
        stop_ms: ms(t_cross, stopped),
        note: "ramp 0.1 m/s; t0 = first setpoint > 100 mm".into(),
    })
}

pub fn offset_99mm(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    c.cable.store(5, Ordering::Relaxed);
    st.wait_following(false)?;
    c.offset_target_um.store(99_000, Ordering::Relaxed);
    st.wait("the 99 mm offset reached", 10.0, |_| {
        Ok(c.offset_um.load(Ordering::Relaxed) == 99_000)
    })?;
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(1500) {
        st.poll()?;
        std::thread::sleep(Duration::from_millis(5));
    }
    if !st.monitor_estops.is_empty() || st.monitor_state != Some(crs_ipc::MonitorState::Armed) {
        return Err(format!(
            "99 mm tripped the monitor: {:?}",
            st.monitor_estops
        ));
    }
    let e = st.emu()?;
    let moved = (e.drives[5].length_m - home_length()).abs();
    if e.drives.iter().any(|d| d.demand != DEMAND_FOLLOW) || moved < 0.098 {
        return Err(format!(
            "the drives should follow the 99 mm offset (cable 6 moved {moved:.4} m)"
        ));
    }
    // End of the scenario: the publisher stops => silence trip => braked.
    c.paused.store(true, Ordering::Relaxed);
    let t_pause = monotonic_ns();
    let ev = st.monitor_trip(Cause::SetpointSilence, 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "none at 99 mm (1.5 s held, cable 6 followed); then setpoint_silence".into(),
        detect_ms: trip_ms(t_pause, ev.timestamp_ns),
        stop_ms: ms(t_pause, stopped),
        note: "times: from the publisher's stop".into(),
    })
}

/// One fault switched on in the fake publisher while the drives follow; the monitor must trip
/// with `cause` and the drives brake.
pub fn publisher_fault(
    st: &mut Stack,
    inject: impl FnOnce(&FakeCtl),
    cause: Cause,
    name: &str,
    note: &str,
) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let t0 = monotonic_ns();
    inject(&c);
    let ev = st.monitor_trip(cause, 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: name.into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: note.into(),
    })
}

pub fn sequence_gaps(st: &mut Stack) -> Res<Outcome> {
    publisher_fault(
        st,
        |c| c.skip_every.store(4, Ordering::Relaxed),
        Cause::SequenceGaps,
        "sequence_gaps",
        "every 4th sequence number skipped; > 5 lost within 67 cycles",
    )
}

pub fn nan_pose(st: &mut Stack) -> Res<Outcome> {
    publisher_fault(
        st,
        |c| c.nan.store(true, Ordering::Relaxed),
        Cause::NonFinite,
        "non_finite",
        "NaN in φ_x, cable lengths valid (drive-io would forward them)",
    )
}

pub fn identity_mismatch(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    c.wrong_identity.store(true, Ordering::Relaxed);
    let ev = st.monitor_trip(Cause::IdentityMismatch, 10.0)?;
    let stopped = st.require_braked()?;
    // t0: the first wrong announcement (the producer re-announces every 100 setpoints).
    let t0 = c.wrong_identity_sent_ns.load(Ordering::Relaxed);
    Ok(Outcome {
        cause: "identity_mismatch".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: "re-announced identity with one byte changed (t0 = its announcement)".into(),
    })
}

/// The pose jumps 200 mm inside the workspace box with cable lengths that agree with it: Δq
/// stays 0, only the monitor's motion plausibility can see it.
pub fn pose_jump_inside_box(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let t0 = monotonic_ns();
    c.pose_jump_um.store(200_000, Ordering::Relaxed);
    let ev = st.monitor_trip(Cause::MotionVelocity, 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "motion_velocity".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: "consistent pose + lengths jump 200 mm in one period".into(),
    })
}

/// A 90 mm step on one cable in one setpoint (4.5 periods of motion at 5 m/s on the guest's 4 ms
/// SYNC; Δq 90 mm passes the monitor's 100 mm) whose timestamp claims 100 ms more: drive-io
/// judges the step on its own clock and the sequence numbers, refuses it and stops the drives.
/// Why 90 and not less: drive-io rightly allows a stream that resumes after k silent SYNC
/// periods a step of k periods of motion, and the emulated guest starves this publisher for 3
/// periods often enough that a 60 mm (3-period) step was let through (a guest flake); 5 silent
/// periods in a row are rare there, and the step stays below the monitor's Δq limit.
pub fn lying_timestamps(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    c.cable.store(1, Ordering::Relaxed);
    st.wait_following(false)?;
    let t0 = monotonic_ns();
    c.timestamp_lie_ns.store(100_000_000, Ordering::Relaxed);
    c.step_um.store(90_000, Ordering::Relaxed);
    st.wait("drive-io faulted on the setpoint step", 10.0, |s| {
        Ok(s.bus_state() == Some(BusState::Fault))
    })?;
    let fc = st.last_feedback.map(|f| f.fault_code).unwrap_or(0);
    if crs_ipc::FaultCode::try_from(fc) != Ok(crs_ipc::FaultCode::SetpointStep) {
        return Err(format!(
            "drive-io faulted with code {fc}, expected SETPOINT_STEP"
        ));
    }
    let t_fault = st.last_feedback.map(|f| f.timestamp_ns).unwrap_or(0);
    let stopped = st.require_braked()?;
    let moved = (st.emu()?.drives[1].length_m - home_length()).abs();
    if moved > 0.045 {
        return Err(format!("cable 2 moved {moved:.3} m: the step was applied"));
    }
    Ok(Outcome {
        cause: "drive-io SETPOINT_STEP (monitor: none, Δq 90 mm)".into(),
        detect_ms: ms(t0, t_fault),
        stop_ms: ms(t0, stopped),
        note: "timestamps +100 ms per setpoint, 90 mm step".into(),
    })
}
