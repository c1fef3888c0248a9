//! The drive-io process loop: SYNC timer + bus + iceoryx2 around [`Master`].

use crate::canopen::FrameBuf;
use crate::config::DrivesConfig;
use crate::config::SyncSource;
use crate::master::Master;
use crate::reset::{Ignored, ResetGate, is_reset_event};
use crate::safety_watch::SafetyWatch;
use crate::sync_clock::SyncClock;
use can_transport::{CanBus, CanError, RxEvent, wait_readable_any};
use crs_ipc::{
    BusState, DriveFeedback, EventKind, Heartbeat, IpcError, IpcNode, JointSetpoint, ProcessId,
    SetpointReadyListener, StateEvent, monotonic_ns,
};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error(transparent)]
    Can(#[from] CanError),
    #[error("drive-io set-up: {0}")]
    Setup(#[from] crate::master::SetupError),
    /// A drive refused (or did not keep) its start-up configuration: start-up stops.
    #[error("drive start-up configuration failed: {0}")]
    Commissioning(String),
    #[error("writing the DCF {path}: {source}")]
    Dcf {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

/// Writes `node<NN>.dcf` for every configured drive and force sensor into `dir` (once, after
/// start-up).
pub fn write_dcfs(master: &Master, dir: &std::path::Path) -> Result<(), RunError> {
    let dcf_err = |path: &std::path::Path, source| RunError::Dcf {
        path: path.display().to_string(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(|e| dcf_err(dir, e))?;
    let kbit = 1000;
    for (node, text) in (0..master.node_count()).filter_map(|i| master.dcf(i, kbit)) {
        let path = dir.join(format!("node{node:02}.dcf"));
        std::fs::write(&path, text).map_err(|e| dcf_err(&path, e))?;
    }
    tracing::info!(dir = %dir.display(), "DCF of every configured drive written");
    Ok(())
}

/// Frames handled at most between the tick and the cycle computation.
const MAX_DRAIN_PER_CYCLE: usize = 512;

/// How long the monitor's reset event may wait for the safety watch to verify its epoch on
/// the bus (the watch needs `release_pairs` RUN pairs of the new epoch, 45 ms by default).
const RESET_VERIFY_WINDOW_NS: u64 = 1_000_000_000;

/// Logs an ignored reset, rate-limited (the 1st, 2nd, 4th, 8th, ... occurrence): a flood of
/// forged events cannot flood the log or the loop.
fn log_ignored(count: &mut u64, why: Ignored, source: u32) {
    *count += 1;
    if count.is_power_of_two() {
        tracing::warn!(
            ?why,
            source,
            ignored = *count,
            "reset event IGNORED: only the safety monitor's verified reset epoch releases drive-io"
        );
    }
}

/// Summary returned when the loop ends.
#[derive(Debug, Clone, Copy)]
pub struct RunSummary {
    pub cycles: u64,
    pub overruns: u32,
    pub final_state: BusState,
    pub tx_full_drops: u64,
    /// Cycles started by motion-core's setpoint notification / by drive-io's own clock.
    pub setpoint_cycles: u64,
    pub clock_cycles: u64,
}

/// Runs drive-io until `stop` is set: waits for each SYNC tick while processing received frames,
/// then reads the newest setpoint and e-stop events, writes RPDOs + SYNC, publishes feedback.
/// No allocation per cycle (iceoryx2 loan/receive and the fixed [`FrameBuf`] only).
pub fn run(
    cfg: &DrivesConfig,
    mut bus: impl CanBus,
    ipc: &IpcNode,
    stop: &AtomicBool,
) -> Result<RunSummary, RunError> {
    // Timer slack 1 ns (kernel default 50 µs), so the ppoll deadline of the SYNC tick is met as
    // closely as the scheduler allows. The prctl only fails for an invalid argument; say so.
    if let Err(e) = crs_rt::set_timer_slack(1) {
        tracing::warn!(error = %e, "timer slack not tightened: SYNC ticks may be up to 50 µs late");
    }
    let setpoints = ipc.subscriber::<JointSetpoint>()?;
    let events = ipc.subscriber::<StateEvent>()?;
    let feedback = ipc.publisher::<DriveFeedback>()?;
    let event_pub = ipc.publisher::<StateEvent>()?;
    let heartbeat = ipc.publisher::<Heartbeat>()?;
    // Wake sleeping watchers on stops only (rare): notify() costs 10-30 us, never per cycle.
    let wakeup = ipc.wakeup_notifier()?;
    let mut master = Master::new(cfg)?;
    for p in master.plans() {
        tracing::info!(node = p.node, kind = %p.kind, eds = %p.eds.file, "configured from its EDS");
    }
    let mut dcf_pending = cfg.bus.dcf_dir.as_ref().map(|d| cfg.resolve(d));
    let period = master.sync_period_ns();
    let mut out = FrameBuf::default();
    let mut event_seq = 0u64;
    let mut tx_full = 0u64;
    let mut overruns = 0u32;
    let mut cycles = 0u64;
    // Optional validation of the safety monitor's doubled heartbeat (drives.toml
    // `[safety_heartbeat]`): without a valid RUN pair within the validation time the bus is
    // e-stopped and resets are refused.
    let mut watch = cfg.safety_heartbeat.map(SafetyWatch::new);
    if let Some(w) = &watch {
        tracing::info!(config = ?w.config(), "validating the safety monitor's heartbeat");
    } else {
        tracing::warn!(
            "no [safety_heartbeat]: resets are checked against the monitor's event only \
             (source and epoch, not authenticated; bench setups only)"
        );
    }
    // Reset authority (issue 16): the latch is left only with the monitor's reset event whose
    // epoch the watch verified on CAN, newer than the epoch in force.
    let mut gate = ResetGate::new();
    let mut pending_reset: Option<(StateEvent, u64)> = None;
    let mut ignored_resets = 0u64;
    // Bus-off / error-passive stop every drive (Master::on_bus_error).
    if let Err(e) = bus.subscribe_bus_errors() {
        tracing::warn!(error = %e, "CAN error frames not available on this transport");
    }
    // Phase lock (issue 20 item 3, crate::sync_clock): wait on the CAN socket and motion-core's
    // "setpoint published" event in one ppoll.
    let mut clock = SyncClock::new(
        cfg.bus.sync_source,
        period,
        u64::from(cfg.bus.setpoint_wait_us) * 1000,
        monotonic_ns(),
    );
    let ready_port = match cfg.bus.sync_source {
        SyncSource::Setpoint => Some(ipc.setpoint_ready_listener()?),
        SyncSource::Clock => None,
    };
    // Dropped to None (own clock for good) if the event channel fails.
    let mut ready = ready_port.as_ref();
    let bus_fd = bus.readiness_fd();
    tracing::info!(sync_source = ?cfg.bus.sync_source, multiplexed = bus_fd.is_some(), "cycle timing");
    while !stop.load(Ordering::Relaxed) {
        // Wait for the cycle, handling TPDOs / heartbeats / EMCY / SDO as they arrive.
        let mut now = monotonic_ns();
        loop {
            let wake = clock.wake_at_ns();
            if now >= wake {
                break;
            }
            let left = Duration::from_nanos(wake - now);
            match (ready, bus_fd) {
                (Some(listener), Some(fd)) => {
                    let [can, note] =
                        wait_readable_any([fd, listener.raw_fd()], left).map_err(|e| {
                            CanError::Io {
                                iface: bus.interface().to_string(),
                                op: "ppoll",
                                source: e,
                            }
                        })?;
                    if note && drain_ready(listener, &mut clock) {
                        ready = None;
                    }
                    if can {
                        drain_bus(&mut bus, &mut master, watch.as_mut())?;
                    }
                }
                _ => {
                    // No descriptor to multiplex (or clock mode): receive until the tick, and
                    // look at the event every 50 µs.
                    let slice = if ready.is_some() {
                        left.min(Duration::from_micros(50))
                    } else {
                        left
                    };
                    if let Some(ev) = bus.recv_event_timeout(slice)? {
                        on_rx(ev, &mut master, watch.as_mut());
                    }
                    if let Some(listener) = ready
                        && drain_ready(listener, &mut clock)
                    {
                        ready = None;
                    }
                }
            }
            now = monotonic_ns();
        }
        // Drain what is already queued (after a preemption the wait loop above is skipped):
        // judging heartbeats/TPDOs before reading them would fault on our own lateness.
        // Bounded so a flooded bus cannot stall the cycle.
        drain_bus(&mut bus, &mut master, watch.as_mut())?;
        // Cycle time = after the drain, so every frame handled is older than the cycle.
        let cycle_now = monotonic_ns();
        let (_trigger, missed) = clock.start(now);
        if missed > 0 {
            overruns = overruns.saturating_add(missed);
            master.add_overruns(missed);
        }
        cycles += 1;

        let permit = watch.as_mut().is_none_or(|w| w.permits(cycle_now));
        let grace = watch
            .as_mut()
            .is_some_and(|w| w.in_startup_grace(cycle_now));
        if let Some((reason, at_ns)) = watch.as_mut().and_then(SafetyWatch::take_trip) {
            tracing::error!(
                ?reason,
                at_ns,
                "safety heartbeat invalid or missing: e-stop"
            );
        }
        gate.note(
            watch.as_ref().and_then(SafetyWatch::verified_epoch),
            master.is_latched(),
        );
        while let Some(ev) = events.receive().unwrap_or_else(|e| {
            tracing::warn!(error = %e, "bad state event ignored");
            None
        }) {
            if ev.source == ProcessId::DriveIo as u32 {
                continue;
            }
            if is_reset_event(&ev) {
                if ev.source == ProcessId::SafetyMonitor as u32 {
                    pending_reset = Some((ev, cycle_now));
                } else {
                    log_ignored(&mut ignored_resets, Ignored::Source(ev.source), ev.source);
                }
                continue;
            }
            master.on_event(&ev, cycle_now);
        }
        if let Some((ev, t0)) = pending_reset {
            let verdict = match &watch {
                Some(w) => gate.check(&ev, w.verified_epoch()),
                None => gate.check_unauthenticated(&ev),
            };
            match verdict {
                Ok(grant) if master.reset(grant, cycle_now) => {
                    gate.granted(grant);
                    pending_reset = None;
                }
                Ok(_) if !master.is_latched() => pending_reset = None,
                // Latched but a heartbeat is stale, or the watch has not verified the epoch
                // yet: retry within the window.
                Ok(_) | Err(Ignored::NotVerified { .. })
                    if cycle_now.saturating_sub(t0) < RESET_VERIFY_WINDOW_NS => {}
                Ok(_) => {
                    tracing::warn!("reset not applied: a drive heartbeat is stale");
                    pending_reset = None;
                }
                Err(why) => {
                    log_ignored(&mut ignored_resets, why, ev.source);
                    pending_reset = None;
                }
            }
        }
        if !permit && !grace && matches!(master.state(), BusState::Ready | BusState::Running) {
            let ev = StateEvent::new(ProcessId::DriveIo, EventKind::EStop, 0);
            master.on_event(&ev, cycle_now);
        }
        // A setpoint with a foreign contract version is an error: treat as no setpoint (stale).
        let sp = setpoints.latest().unwrap_or_else(|e| {
            tracing::error!(error = %e, "setpoint rejected");
            None
        });
        out.clear();
        master.cycle(cycle_now, sp.as_ref(), &mut out);
        for f in out.as_slice() {
            match bus.send(f) {
                Ok(()) => {}
                Err(CanError::TxFull { .. }) => tx_full += 1,
                Err(e) => return Err(e.into()),
            }
        }
        master.mark_written(monotonic_ns());
        if let Some(msg) = master.describe_commissioning_fault() {
            // Start-up stops: the quick-stop frames of this cycle are on the bus already.
            return Err(RunError::Commissioning(msg));
        }
        if dcf_pending.is_some() && master.configured() {
            // Once, right after start-up (not in the steady loop).
            if let Some(dir) = dcf_pending.take() {
                write_dcfs(&master, &dir)?;
            }
        }
        feedback.publish(master.feedback())?;
        if let Some(ev) = master.take_state_event(event_seq + 1) {
            event_seq += 1;
            tracing::info!(state = ?BusState::from_u32(ev.state), detail = ev.detail, node = ev.detail_node, "bus state");
            event_pub.publish(&ev)?;
            if ev.kind == EventKind::Fault as u32 || ev.state == BusState::EStop as u32 {
                wakeup.notify()?;
            }
        }
        if cycles.is_multiple_of(100) {
            let mut hb = Heartbeat::new(ProcessId::DriveIo, master.state() as u32, cycles);
            hb.overruns = overruns;
            heartbeat.publish(&hb)?;
        }
    }
    tracing::info!(
        setpoint_cycles = clock.locked_cycles(),
        clock_cycles = clock.clock_cycles(),
        "cycles started by a setpoint / by drive-io's own clock"
    );
    Ok(RunSummary {
        cycles,
        overruns,
        final_state: master.state(),
        tx_full_drops: tx_full,
        setpoint_cycles: clock.locked_cycles(),
        clock_cycles: clock.clock_cycles(),
    })
}

/// Handles what is queued on the bus, at most [`MAX_DRAIN_PER_CYCLE`] events.
fn drain_bus(
    bus: &mut impl CanBus,
    master: &mut Master,
    mut watch: Option<&mut SafetyWatch>,
) -> Result<(), CanError> {
    for _ in 0..MAX_DRAIN_PER_CYCLE {
        match bus.try_recv_event()? {
            Some(ev) => on_rx(ev, master, watch.as_deref_mut()),
            None => break,
        }
    }
    Ok(())
}

/// One received frame or bus error into the safety watch and the master.
fn on_rx(ev: RxEvent, master: &mut Master, watch: Option<&mut SafetyWatch>) {
    match ev {
        RxEvent::Frame(rx) => {
            if let Some(w) = watch {
                w.on_frame(&rx.frame, rx.rx_monotonic_ns);
            }
            master.on_frame(&rx);
        }
        RxEvent::BusError(e) => master.on_bus_error(&e.error),
    }
}

/// Drains the "setpoint published" event into the clock. True if the event channel failed:
/// drive-io then runs on its own clock for good (SYNC never stops for an IPC error).
fn drain_ready(listener: &SetpointReadyListener, clock: &mut SyncClock) -> bool {
    match listener.drain() {
        Ok(true) => {
            clock.notified();
            false
        }
        Ok(false) => false,
        Err(e) => {
            tracing::error!(error = %e, "setpoint event failed: SYNC on drive-io's own clock from now on");
            clock.degrade_to_clock();
            true
        }
    }
}
