//! The ways through the supervision a review found: motion from rest, a reset asked for by a
//! foreign process, fluttering forces, the monitor's identifiers spoken by another node, a
//! state-event flood, a producer's timestamp jump, drive feedback republished stale. Each
//! injects the fault while the stack runs and requires the monitor's trip (or refusal) and
//! braked drives.

use crate::Res;
use crate::configs::{LOAD_CELL_EVERY_N_SYNCS, home_length};
use crate::scenarios::reset_authority::{BusSpy, require_still_latched, spy_pairs};
use crate::scenarios::{Outcome, ms, trip_ms};
use crate::stack::{Stack, describe_answer, open_bus};
use crs_ipc::{EventKind, IpcNode, ProcessId, StateEvent};
use safety_monitor::Cause;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// From rest (the stream holding the home pose) the pose moves at 4 m/s at once, with
/// consistent cable lengths: Δq stays 0 and the velocity is below table 5.1's 5 m/s (+25 %),
/// only the acceleration out of the hold (4000 m/s² ≫ 14 m/s²) shows it.
pub fn jump_from_rest(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let t0 = st.inject();
    c.pose_speed_um.store(4_000, Ordering::Relaxed);
    let ev = st.monitor_trip(Cause::MotionAcceleration, 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "motion_acceleration".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: "hold, then 4 mm per 1 ms setpoint (4 m/s) with consistent lengths".into(),
    })
}

/// After a trip whose cause cleared, a process of the stack's user asks for the reset on the
/// process bus (under the operator's source) and through the reset socket as another user
/// (nobody, not in the operator group): both refused, the monitor stays tripped and the
/// drives braked; the operator's key then resets.
pub fn reset_from_foreign_process(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    st.inject();
    c.nan.store(true, Ordering::Relaxed);
    st.monitor_trip(Cause::NonFinite, 10.0)?;
    st.require_braked()?;
    st.clear_non_finite(&c)?;
    // 1. On the process bus, claiming the operator's source.
    let node = IpcNode::with_prefix("shil-foreign", &st.prefix).map_err(|e| e.to_string())?;
    let publ = node.publisher::<StateEvent>().map_err(|e| e.to_string())?;
    let answers0 = st.reset_answers.len();
    let req = StateEvent::reset_request(7);
    publ.publish(&req).map_err(|e| e.to_string())?;
    st.wait(
        "the monitor's answer to the process-bus request",
        10.0,
        |s| Ok(s.reset_answers.len() > answers0),
    )?;
    let a = st.reset_answers[answers0];
    if a.monitor_code() != Some(crs_ipc::MonitorCode::ResetDenied) {
        return Err(format!(
            "a reset request on the process bus was not denied: {}",
            describe_answer(&a).1
        ));
    }
    require_still_latched(st, "process-bus reset request")?;
    if st.monitor_resets > 0 {
        return Err("the monitor reset on a process-bus request".into());
    }
    // 2. Through the reset socket as nobody.
    let (ok, text) = st.socket_reset(Some((65_534, 65_534)))?;
    if ok {
        return Err(format!(
            "the reset socket accepted a foreign user: {text:?}"
        ));
    }
    require_still_latched(st, "reset socket as a foreign user")?;
    let log = std::fs::read_to_string(st.dir.join("safety-monitor.log")).unwrap_or_default();
    if !log.contains("REFUSED") {
        return Err("the monitor did not log the refused request with its sender".into());
    }
    // 3. The operator's key: accepted.
    let (ok, key) = st.operator_reset()?;
    if !ok {
        return Err(format!("the operator's key was refused: {key:?}"));
    }
    st.wait("the monitor's Reset event", 10.0, |s| {
        Ok(s.monitor_resets > 0)
    })?;
    c.paused.store(true, Ordering::Relaxed);
    st.wait("the trip at the end", 10.0, |s| {
        Ok(s.monitor_estops.len() >= 2)
    })?;
    st.require_braked()?;
    Ok(Outcome {
        cause: "non_finite; foreign resets refused, key accepted".into(),
        detect_ms: None,
        stop_ms: None,
        note: format!("process bus: denied; socket as nobody: {text:?}; key: {key:?}"),
    })
}

/// The flutter's length: a window of 8 out-of-band readings in 16 trips within a few changes;
/// 40 changes is far past it.
const FLUTTER_MAX_CHANGES: u32 = 40;

/// One phase of the flutter, in drive-io SYNC cycles: 5 load-cell readings (one every
/// `LOAD_CELL_EVERY_N_SYNCS` SYNCs), 25 ms at the host's 1 kHz. Paced by drive-io's feedback,
/// not by the harness's clock: in the emulated guest (4 ms SYNC, stalls) a phase of fixed
/// wall time holds one or two readings, and the slack share of the window is then decided by
/// aliasing, not by the flutter.
const FLUTTER_PHASE_SYNCS: u64 = 5 * LOAD_CELL_EVERY_N_SYNCS as u64;

/// One cable's load cell flutters between slack (200 N) and in band (3 kN), 5 readings each:
/// the window (8 of the last 16 readings) trips although no reading run is long, and it must
/// trip while the flutter goes on.
pub fn flutter_force(st: &mut Stack) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let t0 = st.inject();
    let mut slack = true;
    let mut n = 0;
    // The trip must come DURING the flutter: a steady slack after it would trip any filter,
    // the one that restarts on each in-range reading too (tools/safety-mutants.sh).
    loop {
        if n == FLUTTER_MAX_CHANGES {
            return Err(format!(
                "the flutter was not caught: no trip in {n} changes of 200 N / 3 kN, \
                 {FLUTTER_PHASE_SYNCS} SYNC cycles each"
            ));
        }
        st.set_force(2, Some(if slack { 200.0 } else { 3_000.0 }))?;
        slack = !slack;
        n += 1;
        let f0 = st.feedback_count;
        st.wait("one phase of the flutter (drive-io feedback)", 10.0, |s| {
            Ok(!s.monitor_estops.is_empty() || s.feedback_count >= f0 + FLUTTER_PHASE_SYNCS)
        })?;
        if !st.monitor_estops.is_empty() {
            break;
        }
    }
    let ev = st.monitor_trip(Cause::ForceSlack, 1.0)?;
    if ev.detail_node != 2 {
        return Err(format!("tripped on cable {}, expected 2", ev.detail_node));
    }
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "force_slack cable 2 (flutter)".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!(
            "200 N / 3 kN alternating every {FLUTTER_PHASE_SYNCS} SYNCs (5 load-cell readings); \
             {n} changes before the trip"
        ),
    })
}

/// Another node on the safety bus sends the monitor's own heartbeat COB-IDs (a RUN pair,
/// valid CRCs, the monitor's epoch and the next counter): the monitor recognises frames it did
/// not send and trips `impersonation`; the drives brake.
pub fn impersonation_under_isolation(st: &mut Stack) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let mut bus = open_bus(st, "safety")?;
    let mut spy = BusSpy::default();
    spy_pairs(st, bus.as_mut(), &mut spy, 3)?;
    let mut hb = spy.last_heartbeat().ok_or("no safety pair seen")?;
    let t0 = st.inject();
    // The other node goes on sending a pair per monitor cycle until it is caught.
    let pairs = st.send_until_trip(t0, Duration::from_millis(15), "impersonating pairs", || {
        hb.counter = hb.counter.wrapping_add(1);
        for f in can_transport::safety_frame::encode(&hb, 0x101) {
            bus.send(&f).map_err(|e| e.to_string())?;
        }
        Ok(())
    })?;
    let ev = st.monitor_trip(Cause::Impersonation, 1.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "impersonation".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!(
            "RUN pairs 0x101/0x102 of epoch {} from another node, {pairs} sent before the trip",
            hb.epoch
        ),
    })
}

/// A process floods the state-event topic with events of a foreign contract version while
/// the operator presses stop: the flood cannot hold the stop back (every event of a cycle is
/// drained; the foreign versions themselves trip `ipc_error`).
pub fn state_event_flood(st: &mut Stack) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let node = IpcNode::with_prefix("shil-flood", &st.prefix).map_err(|e| e.to_string())?;
    let publ = node.publisher::<StateEvent>().map_err(|e| e.to_string())?;
    let t0 = st.inject();
    let mut bad = StateEvent::new(ProcessId::Test, EventKind::StateChanged, 1);
    bad.version = 0xDEAD;
    for k in 0..2_000u64 {
        bad.sequence = k;
        publ.publish(&bad).map_err(|e| e.to_string())?;
        if k == 1_000 {
            publ.publish(&StateEvent::new(ProcessId::Operator, EventKind::EStop, 1))
                .map_err(|e| e.to_string())?;
        }
    }
    let ev = st.monitor_trip_any(&[Cause::IpcError, Cause::EStopEvent], 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: Cause::from_code(ev.detail).map_or("?".into(), |c| c.to_string()),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: "2000 events of version 0xDEAD, the operator's e-stop among them".into(),
    })
}

/// The producer's timestamps jump 10 000 s into the future, then a faulty adapter sends an
/// RPDO 300 mm off: the monitor stamps setpoints within its own clock, so the RPDO is still
/// compared and trips `rpdo_mismatch` (not skipped as "no setpoint before it").
pub fn timestamp_jump(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    // One jump, then the normal period on top of it (the lie accumulates per setpoint).
    c.timestamp_lie_ns
        .store(10_000_000_000_000, Ordering::Relaxed);
    std::thread::sleep(Duration::from_millis(2));
    c.timestamp_lie_ns.store(0, Ordering::Relaxed);
    // More jumped setpoints than the monitor's setpoint history holds: none from before the
    // jump is left to check the forged RPDO against (with fewer, the old entries kept the
    // check armed and a monitor blinded by the jump passed too; tools/safety-mutants.sh).
    let jumped = safety_monitor::capacity::HISTORY as u64 + 44;
    let p0 = c.published.load(Ordering::Relaxed);
    st.wait("jumped setpoints past the monitor's history", 10.0, |_| {
        Ok(c.published.load(Ordering::Relaxed) >= p0 + jumped)
    })?;
    st.poll()?;
    if !st.monitor_estops.is_empty() {
        return Err(format!(
            "tripped before the forged RPDO: {:?}",
            st.monitor_estops[0]
        ));
    }
    let mut bus = open_bus(st, crate::configs::drive_interface(3))?;
    let counts_per_m = 10.0 * 1_048_576.0 / (std::f64::consts::PI * 0.305);
    let target = 200_000_000.0 - (home_length() + 0.3) * counts_per_m;
    let f = safety_monitor::bus_frames::rpdo1(4, 0x000F, target.round() as i32);
    let t0 = st.inject();
    bus.send(&f).map_err(|e| e.to_string())?;
    let ev = st.monitor_trip(Cause::RpdoMismatch, 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "rpdo_mismatch after a timestamp jump".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!(
            "timestamps +10 000 s for {jumped} setpoints, then a forged RPDO1 300 mm off"
        ),
    })
}

/// The operator presses the e-stop button of the safety I/O node's circuit: the monitor
/// reads it from the node's TPDO1 and trips `estop_circuit`; the node itself takes STO off.
pub fn estop_circuit_pressed(st: &mut Stack) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let t0 = st.inject();
    st.set_estop(true)?;
    let ev = st.monitor_trip(Cause::EStopCircuit, 10.0)?;
    let stopped = st.require_braked()?;
    // Released again, the latch stays until the operator's reset.
    st.set_estop(false)?;
    require_still_latched(st, "e-stop button released")?;
    Ok(Outcome {
        cause: "estop_circuit".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: "safety I/O node input bit 0 opened (control file), then closed: still latched"
            .into(),
    })
}

/// The monitor dies while the drives follow and is started again: the new instance's start
/// epoch (count 0) releases nothing that was stopped, and Reset events forged in the monitor's
/// name with the new instance's epoch (and its next count), stamped before its start, release
/// neither drive-io nor the drives. Only the operator's key, verified by the new instance,
/// brings the stack back.
pub fn reset_across_monitor_restart(st: &mut Stack) -> Res<Outcome> {
    use crs_limits::reset_epoch;
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let mut bus = open_bus(st, "safety")?;
    let mut spy = BusSpy::default();
    spy_pairs(st, bus.as_mut(), &mut spy, 3)?;
    let old = spy.last_heartbeat().ok_or("no safety pair seen")?.epoch;
    let t0 = st.inject();
    st.signal("safety-monitor", libc::SIGKILL)?;
    st.reap("safety-monitor");
    let (_, stopped) = st.stopped_by_the_drives_watch()?;
    st.spawn_monitor("safety-monitor")?;
    // The new instance's pairs on the bus.
    let new = loop {
        spy_pairs(st, bus.as_mut(), &mut spy, 1)?;
        let e = spy.last_heartbeat().ok_or("no safety pair seen")?.epoch;
        if reset_epoch::instance(e) != reset_epoch::instance(old) {
            break e;
        }
    };
    if reset_epoch::count(new) != 0 {
        return Err(format!(
            "the new instance starts at count {}",
            reset_epoch::count(new)
        ));
    }
    spy_pairs(st, bus.as_mut(), &mut spy, 20)?;
    require_still_latched(st, "restarted monitor (start epoch)")?;
    // Forged resets in the monitor's name, stamped before its start (a replayed or pre-made
    // event): the new epoch and its next count.
    let node = IpcNode::with_prefix("shil-forger", &st.prefix).map_err(|e| e.to_string())?;
    let publ = node.publisher::<StateEvent>().map_err(|e| e.to_string())?;
    for (k, epoch) in [new, new.wrapping_add(1)].into_iter().enumerate() {
        let mut ev = StateEvent::new(ProcessId::SafetyMonitor, EventKind::Reset, 900 + k as u64);
        ev.detail = epoch;
        ev.timestamp_ns = t0;
        publ.publish(&ev).map_err(|e| e.to_string())?;
    }
    require_still_latched(st, "reset forged for the restarted monitor")?;
    // The operator's key: the new instance verifies and resets.
    let (ok, text) = st.operator_reset()?;
    if !ok {
        return Err(format!(
            "the operator's key after the restart was refused: {text:?}"
        ));
    }
    st.wait("drive-io re-enabled and following", 30.0, |s| {
        let e = s.emu()?;
        Ok(matches!(s.bus_state(), Some(crs_ipc::BusState::Running))
            && e.drives
                .iter()
                .all(|d| d.demand == crate::emulator::DEMAND_FOLLOW)
            && !e.inhibit)
    })?;
    c.paused.store(true, Ordering::Relaxed);
    st.wait("the trip at the end", 10.0, |s| {
        Ok(!s.monitor_estops.is_empty())
    })?;
    st.require_braked()?;
    Ok(Outcome {
        cause: "drives: heartbeat timeout; restart released nothing; key accepted".into(),
        detect_ms: None,
        stop_ms: ms(t0, stopped),
        note: format!(
            "instance {:#06x} -> {:#06x}; forged resets with epochs {new:#x}, {:#x}: still \
             latched; key: {text:?}",
            reset_epoch::instance(old),
            reset_epoch::instance(new),
            new.wrapping_add(1)
        ),
    })
}

/// drive-io's loop hangs while its feedback publisher lives on: the scenario kills drive-io
/// and takes its place at once with an adapter whose bus side still works — SYNC on every
/// drive bus and RPDO1 targets that follow the setpoints' cable lengths, so the drives move
/// and the RPDO check finds nothing wrong — while its feedback publisher republishes
/// drive-io's last sample unchanged (timestamp and SYNC cycle frozen). Cable 1's setpoint
/// ramps 50 mm out at 0.1 m/s meanwhile: the plant moves and no fresh measurement shows it.
/// The monitor must trip `feedback_stale` (at this scenario's feedback silence,
/// `configs::stale_feedback_silence_cycles`: the replacement must fit into it).
pub fn stale_published_feedback(st: &mut Stack) -> Res<Outcome> {
    use crate::configs::{INTERFACES, drive_interface};
    use crs_ipc::{DriveFeedback, JointSetpoint, monotonic_ns};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, AtomicU64};
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let fb0 = st.last_feedback.ok_or("no drive-io feedback")?;
    let e0 = st.emu()?;
    // drive-io's death is preparation: the fault is the replacement's first stale sample. A
    // stall that makes the replacement slower than the feedback silence is no verdict.
    st.injected = false;
    // Everything that takes time is prepared before drive-io dies: the node, the setpoint
    // subscriber and the bus thread (waiting on `go`).
    let node =
        IpcNode::with_prefix("shil-stale-drive-io", &st.prefix).map_err(|e| e.to_string())?;
    let setpoints = node
        .subscriber::<JointSetpoint>()
        .map_err(|e| e.to_string())?;
    let mut buses = INTERFACES[..4]
        .iter()
        .map(|i| open_bus(st, i))
        .collect::<Res<Vec<_>>>()?;
    // The newest setpoint's cable lengths (f64 bits), handed to the bus thread.
    let lengths: Arc<[AtomicU64; 8]> = Arc::new(std::array::from_fn(|_| AtomicU64::new(0)));
    let go = Arc::new(AtomicBool::new(false));
    let stop = Arc::new(AtomicBool::new(false));
    let period = u64::from(st.period_us) * 1000;
    let bus_thread = {
        let (lengths, go, stop) = (lengths.clone(), go.clone(), stop.clone());
        std::thread::spawn(move || {
            let counts_per_m = 10.0 * 1_048_576.0 / (std::f64::consts::PI * 0.305);
            let sync = can_transport::CanFrame::new_std_lossy(0x080, &[]);
            while !go.load(Ordering::Relaxed) && !stop.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_micros(200));
            }
            let mut next = monotonic_ns();
            while !stop.load(Ordering::Relaxed) {
                next += period;
                crs_rt::sleep_until(next);
                for (i, l) in lengths.iter().enumerate() {
                    let l = f64::from_bits(l.load(Ordering::Relaxed));
                    if l <= 0.0 {
                        continue;
                    }
                    // The generated drives: even cables sign +1 offset 0, odd ones sign −1
                    // offset 200 000 000 counts (configs::write_configs).
                    let counts = if i % 2 == 0 {
                        l * counts_per_m
                    } else {
                        200_000_000.0 - l * counts_per_m
                    };
                    let f = safety_monitor::bus_frames::rpdo1(
                        (i + 1) as u8,
                        0x000F,
                        counts.round() as i32,
                    );
                    let b = INTERFACES[..4]
                        .iter()
                        .position(|x| *x == drive_interface(i))
                        .unwrap_or(0);
                    let _ = buses[b].send(&f);
                }
                for bus in &mut buses {
                    let _ = bus.send(&sync);
                }
            }
        })
    };
    let finish = |r: Res<Outcome>| {
        stop.store(true, Ordering::Relaxed);
        r
    };
    let newest = |lengths: &[AtomicU64; 8]| -> Res<()> {
        let mut last = None;
        while let Some(s) = setpoints.receive().map_err(|e| e.to_string())? {
            last = Some(s);
        }
        if let Some(s) = last {
            for (a, l) in lengths.iter().zip(&s.cable_length_m) {
                a.store(l.to_bits(), Ordering::Relaxed);
            }
        }
        Ok(())
    };
    if let Err(e) = newest(&lengths) {
        return finish(Err(e));
    }
    // The feedback topic has one publisher: the replacement takes it once drive-io's is gone.
    st.signal("drive-io", libc::SIGKILL)?;
    st.reap("drive-io");
    let t0 = monotonic_ns();
    go.store(true, Ordering::Relaxed);
    let fb_pub = loop {
        match node.publisher::<DriveFeedback>() {
            Ok(p) => break p,
            Err(e) if monotonic_ns() - t0 > 5_000_000_000 => {
                return finish(Err(format!("replacing drive-io's feedback publisher: {e}")));
            }
            Err(_) => {
                crs_ipc::cleanup_dead_nodes(&crs_ipc::iceoryx_config());
            }
        }
    };
    let t_replaced = monotonic_ns();
    if let Err(e) = fb_pub.publish(&fb0).map_err(|e| e.to_string()) {
        return finish(Err(e));
    }
    st.poll()?;
    if !st.monitor_estops.is_empty() {
        return finish(Err(format!(
            "stalled: replacing drive-io's publisher took {:.0} ms, the monitor tripped first \
             ({:?})",
            (t_replaced - t0) as f64 * 1e-6,
            Cause::from_code(st.monitor_estops[0].detail)
        )));
    }
    st.injected = true;
    // The plant moves: cable 1's setpoint ramps out (the adapter's RPDOs follow it).
    c.cable.store(0, Ordering::Relaxed);
    c.offset_target_um.store(50_000, Ordering::Relaxed);
    let mut next = t_replaced;
    let mut published = 1u64;
    let r = loop {
        next += period;
        crs_rt::sleep_until(next);
        if let Err(e) = newest(&lengths) {
            break Err(e);
        }
        // drive-io's last sample, again: timestamp and cycle frozen.
        let _ = fb_pub.publish(&fb0);
        published += 1;
        st.poll()?;
        if !st.monitor_estops.is_empty() {
            break st.monitor_trip(Cause::FeedbackStale, 1.0);
        }
        if monotonic_ns() - t0 > 10_000_000_000 {
            break Err("no trip within 10 s of stale feedback".into());
        }
    };
    let e1 = st.emu();
    let ev = finish(r.map(|ev| Outcome {
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        ..Outcome::default()
    }))?;
    let _ = bus_thread.join();
    let moved_mm = (e1?.drives[0].length_m - e0.drives[0].length_m).abs() * 1e3;
    if moved_mm < 1.0 {
        return Err(format!(
            "the plant did not move under the stale feedback (cable 1: {moved_mm:.2} mm): the \
             scenario's premise failed"
        ));
    }
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "feedback_stale".into(),
        detect_ms: ev.detect_ms,
        stop_ms: ms(t0, stopped),
        note: format!(
            "drive-io replaced ({:.0} ms gap) by an adapter moving the drives and republishing \
             its last sample {published} times; cable 1 moved {moved_mm:.1} mm unseen",
            (t_replaced - t0) as f64 * 1e-6
        ),
    })
}
