//! Resets and who may give them: refused while the fault persists, forged Reset
//! events, a reset while armed, the dead monitor's heartbeat replayed.

use crate::Res;
use crate::emulator::DEMAND_FOLLOW;
use crate::scenarios::{Outcome, ms, trip_ms};
use crate::stack::{Stack, open_bus};
use crs_ipc::{BusState, EventKind, IpcNode, ProcessId, StateEvent, monotonic_ns};
use safety_monitor::Cause;
use std::sync::atomic::Ordering;
use std::time::Duration;

pub fn reset_refused_then_accepted(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    c.nan.store(true, Ordering::Relaxed);
    st.monitor_trip(Cause::NonFinite, 10.0)?;
    st.require_braked()?;
    let (ok, text) = st.operator_reset()?;
    if ok || !text.contains("non_finite") {
        return Err(format!(
            "reset while NaN poses persist must be refused: {text:?}"
        ));
    }
    st.poll()?;
    st.require_braked()?;
    st.clear_non_finite(&c)?;
    let t_reset = monotonic_ns();
    let (ok, text2) = st.operator_reset()?;
    if !ok {
        return Err(format!(
            "reset after the fault cleared must be accepted: {text2:?}"
        ));
    }
    st.wait("the monitor's Reset event", 10.0, |s| {
        Ok(s.monitor_resets > 0)
    })?;
    // A trip after the accepted reset ends the wait at once, naming its cause; a timeout
    // says which of the three conditions was still missing.
    let estops_before = st.monitor_estops.len();
    let mut missing = String::new();
    let waited = st.wait("drive-io re-enabled and following", 30.0, |s| {
        if let Some(e) = s.monitor_estops.get(estops_before) {
            return Err(format!(
                "the monitor tripped again after the accepted reset: cause {:?} (cable {})",
                Cause::from_code(e.detail),
                e.detail_node
            ));
        }
        let e = s.emu()?;
        let bus = s.bus_state();
        let not_following = e
            .drives
            .iter()
            .filter(|d| d.demand != DEMAND_FOLLOW)
            .count();
        missing = format!(
            "drive-io bus state {bus:?}, {not_following} drive(s) not following, emulator \
             inhibit {}",
            e.inhibit
        );
        Ok(matches!(bus, Some(BusState::Running)) && not_following == 0 && !e.inhibit)
    });
    if let Err(e) = waited {
        return Err(format!("{e} (last seen: {missing})"));
    }
    let back_ms = (monotonic_ns() - t_reset) as f64 * 1e-6;
    // End of the scenario: the publisher stops => braked again.
    c.paused.store(true, Ordering::Relaxed);
    st.wait("the second trip", 10.0, |s| Ok(s.monitor_estops.len() >= 2))?;
    st.require_braked()?;
    Ok(Outcome {
        cause: "non_finite; reset refused, then accepted".into(),
        detect_ms: None,
        stop_ms: None,
        note: format!(
            "refused: {text:?}; accepted: drives following again {back_ms:.0} ms after the reset"
        ),
    })
}

// Reset authority.

/// The safety pairs on the bus: the last decoded heartbeat, and NMT start frames seen.
#[derive(Default)]
pub struct BusSpy {
    rx: Option<can_transport::safety_frame::PairReceiver>,
    last: Option<can_transport::safety_frame::SafetyHeartbeat>,
    pairs: u64,
    nmt_starts: u64,
    /// Raw safety frames (0x101/0x102) in arrival order, up to `keep`.
    recorded: Vec<can_transport::CanFrame>,
    keep: usize,
}

impl BusSpy {
    /// The last heartbeat decoded from the monitor's pairs.
    pub fn last_heartbeat(&self) -> Option<can_transport::safety_frame::SafetyHeartbeat> {
        self.last
    }

    fn drain(&mut self, bus: &mut dyn can_transport::CanBus) -> Res<()> {
        let rx = self.rx.get_or_insert_with(|| {
            can_transport::safety_frame::PairReceiver::new(0x101, 1_000_000_000)
        });
        while let Some(f) = bus.try_recv().map_err(|e| e.to_string())? {
            let frame = f.frame;
            if frame.id() == 0 && frame.data().first() == Some(&0x01) {
                self.nmt_starts += 1;
            }
            if rx.is_safety_frame(&frame) && self.recorded.len() < self.keep {
                self.recorded.push(frame);
            }
            if let Some(Ok(hb)) = rx.on_frame(&frame, f.rx_monotonic_ns) {
                self.last = Some(hb);
                self.pairs += 1;
            }
        }
        Ok(())
    }
}

/// Waits for `n` more safety pairs from the monitor on the bus.
pub fn spy_pairs(
    st: &mut Stack,
    bus: &mut dyn can_transport::CanBus,
    spy: &mut BusSpy,
    n: u64,
) -> Res<()> {
    spy.drain(bus)?;
    let p0 = spy.pairs;
    st.wait(&format!("{n} safety pairs on the bus"), 20.0, |_| {
        spy.drain(bus)?;
        Ok(spy.pairs >= p0 + n)
    })?;
    Ok(())
}

/// drive-io, the drives' watch and the drives after a forged release attempt: drive-io must
/// still be latched (not Ready/Running), the watch inhibiting, the drives braked.
pub fn require_still_latched(st: &mut Stack, what: &str) -> Res<()> {
    // drive-io reads the state events every SYNC cycle before it publishes its feedback:
    // 1.2 s worth of samples cover its 1 s window for a reset waiting for the watch's epoch.
    let n0 = st.feedback_count;
    let n = 1_200_000 / u64::from(st.period_us.max(1)) + 1;
    st.wait(
        &format!("{n} drive-io cycles after the forgery"),
        60.0,
        |s| Ok(s.feedback_count >= n0 + n),
    )?;
    if matches!(st.bus_state(), Some(BusState::Ready | BusState::Running)) {
        return Err(format!(
            "{what}: drive-io left its latch ({:?})",
            st.bus_state()
        ));
    }
    if !st.emu()?.inhibit {
        return Err(format!("{what}: the drives' safety watch released"));
    }
    st.require_braked()?;
    Ok(())
}

/// Reset events forged by another process release nothing. From any other source
/// they are ignored by motion-core and drive-io (and the tripped monitor re-asserts its
/// e-stop); even with the monitor's source and a newer epoch (which motion-core cannot tell
/// from the real thing: iceoryx2 0.10 does not authenticate publishers) drive-io stays latched
/// and the drives braked, because the epoch is not in the monitor's doubled heartbeat on CAN.
pub fn forged_reset_ignored(st: &mut Stack) -> Res<Outcome> {
    st.start_motion_core()?;
    st.wait_following(true)?;
    let mut bus = open_bus(st, "safety")?;
    let mut spy = BusSpy::default();
    // The operator's e-stop (the console's stop button): every process stops, the monitor
    // latches it.
    let node = IpcNode::with_prefix("shil-forger", &st.prefix).map_err(|e| e.to_string())?;
    let publ = node.publisher::<StateEvent>().map_err(|e| e.to_string())?;
    publ.publish(&StateEvent::new(ProcessId::Operator, EventKind::EStop, 1))
        .map_err(|e| e.to_string())?;
    st.monitor_trip(Cause::EStopEvent, 10.0)?;
    st.require_braked()?;
    st.wait("motion-core latched (E-STOPPED)", 10.0, |s| {
        Ok(s.motion_state == Some(crs_ipc::MotionState::EStopped))
    })?;
    spy_pairs(st, bus.as_mut(), &mut spy, 3)?;
    let epoch = spy.last.map(|h| h.epoch).ok_or("no safety pair seen")?;
    let forged = |src: ProcessId, seq: u64| {
        let mut ev = StateEvent::new(src, EventKind::Reset, seq);
        ev.detail = epoch.wrapping_add(1);
        ev
    };
    for (k, src) in [
        ProcessId::Operator,
        ProcessId::Test,
        ProcessId::DriveIo,
        ProcessId::MotionCore,
    ]
    .into_iter()
    .enumerate()
    {
        publ.publish(&forged(src, 100 + k as u64))
            .map_err(|e| e.to_string())?;
    }
    // The monitor saw them: it answers a foreign reset while tripped with its e-stop again.
    st.wait("the monitor re-asserting its e-stop", 10.0, |s| {
        Ok(s.monitor_estops.len() >= 2)
    })?;
    require_still_latched(st, "reset forged with another source")?;
    // motion-core's heartbeat after the forgeries (its stage publishes every few cycles).
    let state = st.fresh_motion_state()?;
    if state != Some(crs_ipc::MotionState::EStopped) {
        return Err(format!(
            "motion-core left its latch on a forged reset (state {:?})",
            state
        ));
    }
    // The monitor's source claimed, with a newer epoch: not on the bus, so drive-io and the
    // drives stay stopped; the monitor recognises an event it did not publish and re-asserts
    // its e-stop, which latches motion-core again.
    let n_estops = st.monitor_estops.len();
    publ.publish(&forged(ProcessId::SafetyMonitor, 200))
        .map_err(|e| e.to_string())?;
    st.wait(
        "the monitor re-asserting its e-stop on the impersonation",
        10.0,
        |s| Ok(s.monitor_estops.len() > n_estops),
    )?;
    require_still_latched(st, "reset forged with the monitor's source")?;
    let state = st.fresh_motion_state()?;
    if state != Some(crs_ipc::MotionState::EStopped) {
        return Err(format!(
            "motion-core should be e-stopped again after the monitor's answer (state {:?})",
            state
        ));
    }
    spy_pairs(st, bus.as_mut(), &mut spy, 3)?;
    let on_bus = spy.last.map(|h| h.epoch);
    if on_bus != Some(epoch) || spy.nmt_starts > 0 {
        return Err(format!(
            "the monitor's epoch moved ({epoch} -> {on_bus:?}) or NMT start sent ({})",
            spy.nmt_starts
        ));
    }
    let trips = std::fs::read_to_string(st.dir.join("safety-monitor.log")).unwrap_or_default();
    if !trips.contains("did not publish") {
        return Err("the monitor did not log the impersonation".into());
    }
    Ok(Outcome {
        cause: "estop_event; forged resets ignored".into(),
        detect_ms: None,
        stop_ms: None,
        note: format!(
            "Operator/Test/DriveIo/MotionCore resets: all latched; 'SafetyMonitor' reset with \
             epoch {}: recognised by the monitor (e-stop re-asserted, motion-core e-stopped \
             again), drive-io latched, drives braked",
            epoch.wrapping_add(1)
        ),
    })
}

/// An operator reset while the monitor is armed changes nothing anywhere: no NMT
/// start, no Reset event, the same epoch, the drives keep following.
pub fn reset_while_armed_changes_nothing(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let mut bus = open_bus(st, "safety")?;
    let mut spy = BusSpy::default();
    spy_pairs(st, bus.as_mut(), &mut spy, 3)?;
    let epoch = spy.last.map(|h| h.epoch).ok_or("no safety pair seen")?;
    spy.nmt_starts = 0;
    let (ok, text) = st.operator_reset()?;
    if !ok || !text.contains("nothing changed") {
        return Err(format!("unexpected answer while armed: {text:?}"));
    }
    // Ten monitor cycles after the answer.
    spy_pairs(st, bus.as_mut(), &mut spy, 10)?;
    st.poll()?;
    let on_bus = spy.last.map(|h| h.epoch);
    if spy.nmt_starts > 0 || st.monitor_resets > 0 || on_bus != Some(epoch) {
        return Err(format!(
            "a reset while armed changed something: {} NMT start(s), {} Reset event(s), epoch \
             {epoch} -> {on_bus:?}",
            spy.nmt_starts, st.monitor_resets
        ));
    }
    let e = st.emu()?;
    if st.bus_state() != Some(BusState::Running)
        || e.drives.iter().any(|d| d.demand != DEMAND_FOLLOW)
        || st.monitor_state != Some(crs_ipc::MonitorState::Armed)
    {
        return Err("the stack should still run".into());
    }
    // End of the scenario: the publisher stops => silence trip => braked.
    c.paused.store(true, Ordering::Relaxed);
    let t0 = monotonic_ns();
    let ev = st.monitor_trip(Cause::SetpointSilence, 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "none (reset while armed); then setpoint_silence".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!("answer {text:?}; no NMT start, no Reset event, epoch {epoch} unchanged"),
    })
}

/// No self-release: after the monitor died, its recorded heartbeats replayed
/// verbatim, then continued with fresh counters and the same epoch, never release the drives'
/// watch or drive-io.
pub fn replayed_heartbeat_after_monitor_death(st: &mut Stack) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let mut bus = open_bus(st, "safety")?;
    let mut spy = BusSpy {
        keep: 40,
        ..BusSpy::default()
    };
    spy_pairs(st, bus.as_mut(), &mut spy, 20)?;
    let last = spy.last.ok_or("no safety pair seen")?;
    let t0 = monotonic_ns();
    st.signal("safety-monitor", libc::SIGKILL)?;
    st.reap("safety-monitor");
    let (_, stopped) = st.stopped_by_the_drives_watch()?;
    // A release would show as the watch permitting during the replay, and afterwards as one
    // more Permit -> Inhibit transition (the replay ends, the validation time runs out).
    let trips0 = st.emu()?.safety_trips;
    let mut released = 0u32;
    // 1. The recorded frames verbatim, one pair per monitor cycle (the stimulus is paced like
    //    the monitor; the observations below are paced by the emulator's status time).
    let cycle = Duration::from_millis(15);
    for f in &spy.recorded {
        bus.send(f).map_err(|e| e.to_string())?;
        if f.id() == 0x102 {
            std::thread::sleep(cycle);
            released += u32::from(!st.emu()?.inhibit);
        }
    }
    // 2. The last pair continued: fresh counters, the same epoch, RUN.
    let mut hb = last;
    hb.state = can_transport::safety_frame::SafetyState::Run;
    for _ in 0..60 {
        hb.counter = hb.counter.wrapping_add(1);
        for f in can_transport::safety_frame::encode(&hb, 0x101) {
            bus.send(&f).map_err(|e| e.to_string())?;
        }
        std::thread::sleep(cycle);
        released += u32::from(!st.emu()?.inhibit);
    }
    let t_sent = monotonic_ns();
    // The emulator handled every frame sent before its status time.
    st.wait("the emulator past the replay", 10.0, |s| {
        Ok(s.emu()?.time_ns > t_sent)
    })?;
    require_still_latched(st, "replayed heartbeat")?;
    let trips1 = st.emu()?.safety_trips;
    if released > 0 || trips1 != trips0 {
        return Err(format!(
            "the replay released the drives' safety watch ({released} samples permitting, \
             {} more trips)",
            trips1 - trips0
        ));
    }
    Ok(Outcome {
        cause: "drives: safety heartbeat timeout; replay ignored".into(),
        detect_ms: None,
        stop_ms: ms(t0, stopped),
        note: format!(
            "{} recorded frames replayed + 60 continued pairs of epoch {}: still inhibited",
            spy.recorded.len(),
            last.epoch
        ),
    })
}
