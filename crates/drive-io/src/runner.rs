//! The drive-io process loop: SYNC timer + bus + iceoryx2 around [`Master`].

use crate::master::Master;
use crate::reset::{Ignored, ResetGate, is_reset_event};
use crate::sync_clock::{IsoClock, IsoDue, SyncClock};
use can_transport::{CanBus, CanError, CanFrame, RxEvent, wait_readable_any};
use crs_ipc::{
    BusState, DriveFeedback, EventKind, Heartbeat, IpcError, IpcNode, JointSetpoint, ProcessId,
    SetpointReadyListener, StateEvent, SyncSchedule, TopicPublisher, TopicSubscriber,
    WakeupNotifier, monotonic_ns,
};
use drive_bus::canopen::{BusFrames, sync};
use drive_bus::safety_watch::SafetyWatch;
use drives_config::{DrivesConfig, MAX_INTERFACES, SyncSource};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
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
    /// The configuration does not fit its bus budget.
    #[error(transparent)]
    Budget(drive_commissioning::budget::BudgetError),
    /// One bus must be opened per configured interface.
    #[error("drive-io runs {configured} CAN interface(s) but {opened} bus(es) were opened")]
    Interfaces { configured: usize, opened: usize },
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
    /// Cycles started by motion-core's setpoint notification / by drive-io's own clock (in
    /// isochronous mode: at the guard time before the SYNC, holding).
    pub setpoint_cycles: u64,
    pub clock_cycles: u64,
    /// SYNC frames sent (per interface, counted once per instant).
    pub syncs: u64,
    /// Isochronous mode: how late the SYNC left drive-io after its instant, worst case, ns.
    pub sync_late_max_ns: u64,
    /// Setpoints superseded before a cycle read them (a newer one was published first).
    pub superseded_setpoints: u64,
    /// Interfaces whose SYNC went through its own transmit path
    /// ([`CanBus::open_priority_path`]; isochronous mode on `wire:` and SocketCAN), not
    /// behind drive-io's queued frames.
    pub sync_priority_paths: u32,
    /// Isochronous: SYNC instants at which drive-io's frames of the cycle (its RPDOs, its
    /// heartbeat when due) were still not off the wire on some interface: those drives apply
    /// the late RPDOs at the next SYNC (RPDO transmission type 1 latches the last one received
    /// before a SYNC), one period late.
    pub rpdos_late_at_sync: u64,
    /// Isochronous: cycles whose RPDOs were queued on some interface behind drive-io's earlier
    /// frames still not off the wire there. They are queued anyway: the queue keeps their
    /// order, so a drive always latches the newest target that arrived before its SYNC;
    /// withholding them could only leave it an older one.
    pub rpdos_queued_behind: u64,
}

/// Which scheduler times the cycles ([`crate::sync_clock`]).
enum Schedule {
    /// `clock` / `setpoint`: the cycle sends its RPDOs and then the SYNC at once.
    Free(SyncClock),
    /// `isochronous`: the SYNC is the bus clock; the cycle only sends RPDOs.
    Iso(IsoClock),
}

impl Schedule {
    fn wake_at_ns(&self) -> u64 {
        match self {
            Schedule::Free(c) => c.wake_at_ns(),
            Schedule::Iso(c) => c.wake_at_ns(),
        }
    }
    fn notified(&mut self) {
        match self {
            Schedule::Free(c) => c.notified(),
            Schedule::Iso(c) => c.notified(),
        }
    }
    /// The setpoint event failed: run on drive-io's own clock for good.
    fn degrade(&mut self) {
        if let Schedule::Free(c) = self {
            c.degrade_to_clock();
        }
        // Isochronous: the guard time already starts every cycle without notifications.
    }
    fn counts(&self) -> (u64, u64) {
        match self {
            Schedule::Free(c) => (c.locked_cycles(), c.clock_cycles()),
            Schedule::Iso(c) => (c.locked_cycles(), c.guard_cycles()),
        }
    }
}

/// The CAN side of the runner: one bus per interface, in `DrivesConfig::interfaces()` order.
struct Buses<B: CanBus> {
    buses: Vec<B>,
    /// Each interface's SYNC transmit path (isochronous mode, where the transport has one:
    /// a second socket in pfifo_fast's first band, a controller's priority mailbox on the wire
    /// model); `None`: the SYNC goes through `buses[i]`, behind what is queued there.
    sync_paths: Vec<Option<Box<dyn CanBus>>>,
    /// Readiness descriptors (-1 for unused slots); `None` if a transport has none.
    fds: Option<[std::os::fd::RawFd; MAX_INTERFACES]>,
    tx_full: u64,
}

impl<B: CanBus> Buses<B> {
    fn new(mut buses: Vec<B>) -> Self {
        let mut fds = [-1; MAX_INTERFACES];
        let mut all = true;
        for (i, b) in buses.iter_mut().enumerate() {
            // Bus-off / error-passive stop every drive (Master::on_bus_error).
            if let Err(e) = b.subscribe_bus_errors() {
                tracing::warn!(error = %e, interface = b.interface(), "CAN error frames not available on this transport");
            }
            match b.readiness_fd() {
                Some(fd) => fds[i] = fd,
                None => all = false,
            }
        }
        let sync_paths = buses.iter().map(|_| None).collect();
        Self {
            buses,
            sync_paths,
            fds: all.then_some(fds),
            tx_full: 0,
        }
    }

    /// Opens every interface's SYNC transmit path where the transport has one; returns how
    /// many did.
    fn open_sync_paths(&mut self) -> Result<u32, CanError> {
        let mut n = 0;
        for (b, p) in self.buses.iter().zip(self.sync_paths.iter_mut()) {
            *p = b.open_priority_path()?;
            match p {
                Some(_) => n += 1,
                None => tracing::info!(
                    interface = b.interface(),
                    "no separate SYNC transmit path on this transport (no transmit queue to overtake): the SYNC goes through the interface's own socket"
                ),
            }
        }
        Ok(n)
    }

    /// Whether drive-io's frames sent earlier on interface `i` are still not off the wire
    /// (where the transport knows; otherwise taken as no).
    fn backlog(&self, i: usize) -> bool {
        self.buses[i].tx_backlog().is_some_and(|n| n > 0)
    }

    fn send(&mut self, iface: usize, f: &CanFrame) -> Result<(), CanError> {
        let r = self.buses[iface].send(f);
        self.counting_full(r)
    }

    /// A send's result with a full transmit queue counted (`tx_full`), not an error.
    fn counting_full(&mut self, r: Result<(), CanError>) -> Result<(), CanError> {
        match r {
            Err(CanError::TxFull { .. }) => {
                self.tx_full += 1;
                Ok(())
            }
            r => r,
        }
    }

    /// Sends the cycle's frames, interface by interface (each interface's queue is its own
    /// FIFO, so the RPDOs go before a SYNC queued after them). Returns whether this cycle's
    /// RPDOs were queued behind earlier frames of drive-io still not off the wire on some
    /// interface (checked only with `check_backlog`).
    fn send_frames(&mut self, out: &BusFrames, check_backlog: bool) -> Result<bool, CanError> {
        let mut behind = false;
        for i in 0..self.buses.len() {
            let busy = check_backlog && self.backlog(i);
            for (f, is_rpdo) in out.on_tagged(i) {
                behind |= busy && is_rpdo;
                self.send(i, f)?;
            }
        }
        Ok(behind)
    }

    /// The SYNC on every interface, through its own transmit path where there is one.
    fn send_sync(&mut self) -> Result<(), CanError> {
        let s = sync();
        for i in 0..self.buses.len() {
            let r = match self.sync_paths[i].as_mut() {
                Some(p) => p.send(&s),
                None => self.buses[i].send(&s),
            };
            self.counting_full(r)?;
        }
        Ok(())
    }

    /// Whether some interface still holds drive-io's earlier frames not off the wire.
    #[cfg(test)]
    fn any_backlog(&self) -> bool {
        (0..self.buses.len()).any(|i| self.backlog(i))
    }

    /// Whether an interface whose SYNC has its own path still holds drive-io's frames not off
    /// the wire in its own queue.
    fn backlog_behind_sync(&self) -> bool {
        (0..self.buses.len()).any(|i| self.sync_paths[i].is_some() && self.backlog(i))
    }

    /// Handles what is queued on every bus, at most [`MAX_DRAIN_PER_CYCLE`] events each.
    fn drain(
        &mut self,
        master: &mut Master,
        mut watch: Option<&mut SafetyWatch>,
    ) -> Result<(), CanError> {
        for (i, bus) in self.buses.iter_mut().enumerate() {
            for _ in 0..MAX_DRAIN_PER_CYCLE {
                match bus.try_recv_event()? {
                    Some(ev) => on_rx(i, ev, master, watch.as_deref_mut()),
                    None => break,
                }
            }
        }
        Ok(())
    }
}

/// Cycles run by this process so far, for the systemd watchdog thread (`crs-service`): it
/// pings only while this advances. A Relaxed store per cycle, nothing else in the loop.
pub static CYCLES_RUN: AtomicU64 = AtomicU64::new(0);

/// Runs drive-io until `stop` is set: one cycle per SYNC period over every CAN interface of
/// `buses` (one per `cfg.interfaces()` entry, in that order), handling received frames while it
/// waits; each cycle reads the newest setpoint and e-stop events, writes RPDOs, publishes
/// feedback; the SYNC goes on every interface at the same instant. No allocation per cycle
/// (iceoryx2 loan/receive and the fixed [`BusFrames`] only).
pub fn run<B: CanBus>(
    cfg: &DrivesConfig,
    buses: Vec<B>,
    ipc: &IpcNode,
    stop: &AtomicBool,
) -> Result<RunSummary, RunError> {
    run_with(cfg, buses, ipc, stop, Budget::Enforce)
}

/// Whether [`run_with`] refuses a configuration above its bus budget.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Budget {
    /// Refuse it before anything is sent (the daemon, always).
    Enforce,
    /// Log the refusal and run anyway: only for the test that shows what such a configuration
    /// does on the wire model (the daemon binary has no way to ask for this).
    RunAnywayForTest,
}

/// [`run`] with a choice of what to do about the bus budget: the daemon's lifecycle,
/// configure → activate → run → deactivate.
pub fn run_with<B: CanBus>(
    cfg: &DrivesConfig,
    buses: Vec<B>,
    ipc: &IpcNode,
    stop: &AtomicBool,
    budget: Budget,
) -> Result<RunSummary, RunError> {
    let configured = configure(cfg, buses, ipc, budget)?;
    let mut d = activate(configured, cfg, ipc)?;
    while !stop.load(Ordering::Relaxed) {
        step(&mut d)?;
    }
    Ok(deactivate(d))
}

/// The iceoryx2 ports of the loop, opened before anything is sent.
struct Ports {
    setpoints: TopicSubscriber<JointSetpoint>,
    events: TopicSubscriber<StateEvent>,
    feedback: TopicPublisher<DriveFeedback>,
    event_pub: TopicPublisher<StateEvent>,
    heartbeat: TopicPublisher<Heartbeat>,
    /// Wakes sleeping watchers on stops only (rare): notify() costs 10-30 us, never per cycle.
    wakeup: WakeupNotifier,
}

/// What [`configure`] prepared: the ports, the master with its nodes' start-up plans (their
/// bus budget checked), the safety watch, the buses. Nothing is on the bus yet.
struct Configured<B: CanBus> {
    ports: Ports,
    master: Master,
    watch: Option<SafetyWatch>,
    buses: Buses<B>,
    dcf_pending: Option<std::path::PathBuf>,
}

/// Counters of the loop, reported by [`deactivate`] ([`RunSummary`]).
#[derive(Default)]
struct LoopStats {
    cycles: u64,
    overruns: u32,
    syncs: u64,
    sync_late_max_ns: u64,
    sync_priority_paths: u32,
    rpdos_late_at_sync: u64,
    rpdos_queued_behind: u64,
    event_seq: u64,
    schedule_seq: u64,
    ignored_resets: u64,
    bad_events: u64,
}

/// The running daemon: everything the loop touches, allocated before the first cycle.
struct Active<B: CanBus> {
    ports: Ports,
    master: Master,
    watch: Option<SafetyWatch>,
    buses: Buses<B>,
    dcf_pending: Option<std::path::PathBuf>,
    schedule: Schedule,
    /// Isochronous: where the SYNC instants are published for motion-core's timeline.
    schedule_pub: Option<TopicPublisher<SyncSchedule>>,
    /// The "setpoint published" event (all modes but clock): a cycle starts on it.
    ready_port: Option<SetpointReadyListener>,
    /// False once the event channel failed: drive-io's own clock for good.
    ready_live: bool,
    out: BusFrames,
    period_ns: u64,
    /// Reset authority: the latch is left only with the monitor's reset event whose epoch the
    /// watch verified on CAN, newer than the epoch in force.
    gate: ResetGate,
    pending_reset: Option<(StateEvent, u64)>,
    /// systemd (Type=notify): told once the drives are operational.
    notified_ready: bool,
    stats: LoopStats,
}

/// Configure: the ports, the master from the nodes' EDS, the bus budget (refused before
/// anything is sent), the safety watch.
fn configure<B: CanBus>(
    cfg: &DrivesConfig,
    buses: Vec<B>,
    ipc: &IpcNode,
    budget: Budget,
) -> Result<Configured<B>, RunError> {
    // Timer slack 1 ns (kernel default 50 µs), so the ppoll deadline of the SYNC tick is met as
    // closely as the scheduler allows. The prctl only fails for an invalid argument; say so.
    if let Err(e) = crs_rt::set_timer_slack(1) {
        tracing::warn!(error = %e, "timer slack not tightened: SYNC ticks may be up to 50 µs late");
    }
    let n_itf = cfg.interfaces().len();
    if buses.len() != n_itf || n_itf == 0 || n_itf > MAX_INTERFACES {
        return Err(RunError::Interfaces {
            configured: n_itf,
            opened: buses.len(),
        });
    }
    let ports = Ports {
        setpoints: ipc.subscriber::<JointSetpoint>()?,
        events: ipc.subscriber::<StateEvent>()?,
        feedback: ipc.publisher::<DriveFeedback>()?,
        event_pub: ipc.publisher::<StateEvent>()?,
        heartbeat: ipc.publisher::<Heartbeat>()?,
        wakeup: ipc.wakeup_notifier()?,
    };
    let master = Master::new(cfg)?;
    for p in master.plans() {
        tracing::info!(node = p.node, kind = %p.kind, eds = %p.eds.file, "configured from its EDS");
    }
    check_budget(cfg, &master, budget)?;
    // Optional validation of the safety monitor's doubled heartbeat (drives.toml
    // `[safety_heartbeat]`): without a valid RUN pair within the validation time the bus is
    // e-stopped and resets are refused.
    let watch = cfg.safety_heartbeat.map(SafetyWatch::new);
    if let Some(w) = &watch {
        tracing::info!(config = ?w.config(), "validating the safety monitor's heartbeat");
    } else {
        tracing::warn!(
            "no [safety_heartbeat]: resets are checked against the monitor's event only \
             (source and epoch, not authenticated; bench setups only)"
        );
    }
    Ok(Configured {
        ports,
        master,
        watch,
        buses: Buses::new(buses),
        dcf_pending: cfg.bus.dcf_dir.as_ref().map(|d| cfg.resolve(d)),
    })
}

/// The bus budget of the frames the master's plans produce.
fn check_budget(cfg: &DrivesConfig, master: &Master, budget: Budget) -> Result<(), RunError> {
    for ib in drive_commissioning::budget::of_plans(cfg, master.plans()) {
        match (ib.check(), budget) {
            (Ok(()), _) => tracing::info!(
                interface = %ib.name,
                load_percent = format_args!("{:.1}", ib.load_percent()),
                budget_percent = ib.budget_percent,
                worst_period_us = format_args!("{:.0}", ib.worst_cycle_us()),
                rpdo_window_us = format_args!("{:.0}", ib.rpdo_window_us()),
                "bus budget"
            ),
            (Err(e), Budget::Enforce) => return Err(RunError::Budget(e)),
            (Err(e), Budget::RunAnywayForTest) => {
                tracing::error!("{e} (running anyway: test of the overload)")
            }
        }
    }
    Ok(())
}

/// Activate: the cycle's clock (isochronous, setpoint or clock), the SYNC's own transmit
/// paths, the schedule publisher and the setpoint event.
fn activate<B: CanBus>(
    c: Configured<B>,
    cfg: &DrivesConfig,
    ipc: &IpcNode,
) -> Result<Active<B>, RunError> {
    let Configured {
        ports,
        master,
        watch,
        mut buses,
        dcf_pending,
    } = c;
    let period_ns = master.sync_period_ns();
    let start_ns = monotonic_ns();
    let schedule = match cfg.bus.sync_source {
        SyncSource::Isochronous => Schedule::Iso(IsoClock::new(
            period_ns,
            u64::from(cfg.bus.rpdo_guard_us) * 1000,
            u64::from(cfg.bus.sync_spin_us) * 1000,
            start_ns,
        )),
        source => Schedule::Free(SyncClock::new(
            source,
            period_ns,
            u64::from(cfg.bus.setpoint_wait_us) * 1000,
            start_ns,
        )),
    };
    // Isochronous: the SYNC is the bus clock and must not wait behind drive-io's own queued
    // frames; in the other two modes it follows the cycle's RPDOs in the same FIFO (a SYNC
    // overtaking them would make the drives latch the previous targets).
    let sync_priority_paths = match &schedule {
        Schedule::Iso(_) => buses.open_sync_paths()?,
        Schedule::Free(_) => 0,
    };
    let schedule_pub = match &schedule {
        Schedule::Iso(_) => Some(ipc.publisher::<SyncSchedule>()?),
        Schedule::Free(_) => None,
    };
    let ready_port = match cfg.bus.sync_source {
        SyncSource::Setpoint | SyncSource::Isochronous => Some(ipc.setpoint_ready_listener()?),
        SyncSource::Clock => None,
    };
    tracing::info!(
        sync_source = cfg.bus.sync_source.name(),
        interfaces = cfg.interfaces().len(),
        multiplexed = buses.fds.is_some(),
        "cycle timing"
    );
    Ok(Active {
        ports,
        master,
        watch,
        out: BusFrames::new(cfg.interfaces().len()),
        buses,
        dcf_pending,
        schedule,
        schedule_pub,
        ready_port,
        ready_live: true,
        period_ns,
        gate: ResetGate::new(),
        pending_reset: None,
        notified_ready: false,
        stats: LoopStats {
            sync_priority_paths,
            ..LoopStats::default()
        },
    })
}

/// Run, one step: wait for what is due, then either the isochronous SYNC instant or a cycle.
fn step<B: CanBus>(d: &mut Active<B>) -> Result<(), RunError> {
    let now = wait_until_due(d)?;
    if sync_instant(d, now)? {
        return Ok(());
    }
    let cycle_now = start_cycle(d, now)?;
    take_events(d, cycle_now);
    apply_pending_reset(d, cycle_now);
    write_cycle(d, cycle_now)?;
    publish(d)
}

/// Waits for what is due next, handling TPDOs / heartbeats / EMCY / SDO and the setpoint
/// event as they arrive. Returns the time it woke.
fn wait_until_due<B: CanBus>(d: &mut Active<B>) -> Result<u64, RunError> {
    let mut now = monotonic_ns();
    loop {
        let wake = d.schedule.wake_at_ns();
        if now >= wake {
            return Ok(now);
        }
        let left = Duration::from_nanos(wake - now);
        let ready = d.ready_port.as_ref().filter(|_| d.ready_live);
        match d.buses.fds {
            Some(bus_fds) => {
                let mut fds = [-1; MAX_INTERFACES + 1];
                fds[..MAX_INTERFACES].copy_from_slice(&bus_fds);
                if let Some(l) = ready {
                    fds[MAX_INTERFACES] = l.raw_fd();
                }
                let readable = wait_readable_any(fds, left).map_err(|e| CanError::Io {
                    iface: d.buses.buses[0].interface().to_string(),
                    op: "ppoll",
                    source: e,
                })?;
                if readable[MAX_INTERFACES]
                    && let Some(l) = ready
                    && drain_ready(l, &mut d.schedule)
                {
                    d.ready_live = false;
                }
                if readable[..MAX_INTERFACES].iter().any(|r| *r) {
                    d.buses.drain(&mut d.master, d.watch.as_mut())?;
                }
            }
            None => {
                // A transport without a descriptor: receive in slices of 50 µs.
                let slice = left.min(Duration::from_micros(50));
                if d.buses.buses.len() == 1 {
                    if let Some(ev) = d.buses.buses[0].recv_event_timeout(slice)? {
                        on_rx(0, ev, &mut d.master, d.watch.as_mut());
                    }
                } else {
                    std::thread::sleep(slice);
                    d.buses.drain(&mut d.master, d.watch.as_mut())?;
                }
                if let Some(l) = ready
                    && drain_ready(l, &mut d.schedule)
                {
                    d.ready_live = false;
                }
            }
        }
        now = monotonic_ns();
    }
}

/// Isochronous: the SYNC instant (after the period's cycle) is its own step. True if this
/// wake-up was the SYNC instant.
fn sync_instant<B: CanBus>(d: &mut Active<B>, now: u64) -> Result<bool, RunError> {
    let Schedule::Iso(iso) = &mut d.schedule else {
        return Ok(false);
    };
    if iso.due(now) != IsoDue::Sync {
        return Ok(false);
    }
    // Active wait for the instant: the timer's wake-up jitter must not reach the wire.
    let at = iso.sync_at_ns();
    let mut t = now;
    while t < at {
        std::hint::spin_loop();
        t = monotonic_ns();
    }
    let s = &mut d.stats;
    if d.out.sync_requested() {
        d.buses.send_sync()?;
        s.syncs += 1;
        // CiA 402 CSP with RPDO transmission type 1: a drive applies the last RPDO
        // received before the SYNC; one still queued now is applied a period late.
        // Checked after the SYNC is out (no system call before it), on the interfaces
        // whose SYNC went through its own path (the others' backlog holds the SYNC).
        if d.buses.backlog_behind_sync() {
            s.rpdos_late_at_sync += 1;
        }
    }
    let sent = monotonic_ns();
    s.sync_late_max_ns = s.sync_late_max_ns.max(sent.saturating_sub(at));
    let skipped = iso.sync_sent(sent);
    if skipped > 0 {
        s.overruns = s.overruns.saturating_add(skipped);
        d.master.add_overruns(skipped);
    }
    Ok(true)
}

/// Starts a cycle at `now`: drains what is already queued and counts the cycle. Returns the
/// cycle's time.
fn start_cycle<B: CanBus>(d: &mut Active<B>, now: u64) -> Result<u64, RunError> {
    // Drain what is already queued (after a preemption the wait loop above is skipped):
    // judging heartbeats/TPDOs before reading them would fault on our own lateness.
    // Bounded so a flooded bus cannot stall the cycle.
    d.buses.drain(&mut d.master, d.watch.as_mut())?;
    // Cycle time = after the drain, so every frame handled is older than the cycle.
    let cycle_now = monotonic_ns();
    let s = &mut d.stats;
    match &mut d.schedule {
        Schedule::Free(clock) => {
            let (_trigger, missed) = clock.start(now);
            if missed > 0 {
                s.overruns = s.overruns.saturating_add(missed);
                d.master.add_overruns(missed);
            }
        }
        Schedule::Iso(iso) => {
            iso.cycle_started();
        }
    }
    s.cycles += 1;
    CYCLES_RUN.store(s.cycles, Ordering::Relaxed);
    Ok(cycle_now)
}

/// The monitor's heartbeat and this cycle's state events into the master; a reset event of
/// the monitor is kept for [`apply_pending_reset`].
fn take_events<B: CanBus>(d: &mut Active<B>, cycle_now: u64) {
    // The monitor's heartbeat: without a permit (past the start-up grace) an enabled bus
    // is e-stopped here, before this cycle's events and its RPDOs.
    if let Some(w) = d.watch.as_mut() {
        d.master.supervise_safety_heartbeat(w, cycle_now);
    }
    d.gate.note(
        d.watch.as_ref().and_then(SafetyWatch::verified_epoch),
        d.master.is_latched(),
    );
    // Every event of this cycle is drained: a sample of a foreign contract version is
    // skipped (and logged, rate-limited) without ending the drain, so a flood of bad events
    // cannot hold an e-stop back by a cycle per bad sample. Bounded by the buffer's worth.
    let s = &mut d.stats;
    for _ in 0..4 * <StateEvent as crs_ipc::Topic>::SUBSCRIBER_BUFFER {
        let ev = match d.ports.events.receive() {
            Ok(Some(ev)) => ev,
            Ok(None) => break,
            Err(e @ crs_ipc::IpcError::Version { .. }) => {
                s.bad_events += 1;
                if s.bad_events.is_power_of_two() {
                    tracing::warn!(error = %e, bad_events = s.bad_events, "bad state event ignored");
                }
                continue;
            }
            Err(e) => {
                tracing::warn!(error = %e, "state event receive failed");
                break;
            }
        };
        if ev.source == ProcessId::DriveIo as u32 {
            continue;
        }
        if is_reset_event(&ev) {
            if ev.source == ProcessId::SafetyMonitor as u32 {
                d.pending_reset = Some((ev, cycle_now));
            } else {
                log_ignored(&mut s.ignored_resets, Ignored::Source(ev.source), ev.source);
            }
            continue;
        }
        d.master.on_event(&ev, cycle_now);
    }
}

/// The monitor's pending reset through the gate into the master, retried within
/// [`RESET_VERIFY_WINDOW_NS`] while the watch has not verified its epoch.
fn apply_pending_reset<B: CanBus>(d: &mut Active<B>, cycle_now: u64) {
    let Some((ev, t0)) = d.pending_reset else {
        return;
    };
    // Freshness is judged at the event's arrival (t0): the wait for the watch below
    // must not make a fresh event stale.
    let verdict = match &d.watch {
        Some(w) => d.gate.check(&ev, w.verified_epoch(), t0),
        None => d.gate.check_unauthenticated(&ev, t0),
    };
    let in_window = cycle_now.saturating_sub(t0) < RESET_VERIFY_WINDOW_NS;
    match verdict {
        Ok(grant) => match d.master.reset(grant, cycle_now) {
            Ok(epoch) => {
                d.gate.granted(epoch);
                d.pending_reset = None;
            }
            Err(_) if !d.master.is_latched() => d.pending_reset = None,
            // Latched but a heartbeat is stale: retry within the window.
            Err(_) if in_window => {}
            Err(_) => {
                tracing::warn!("reset not applied: a drive heartbeat is stale");
                d.pending_reset = None;
            }
        },
        // The watch has not verified the epoch yet: retry within the window.
        Err(Ignored::NotVerified { .. }) if in_window => {}
        Err(why) => {
            log_ignored(&mut d.stats.ignored_resets, why, ev.source);
            d.pending_reset = None;
        }
    }
}

/// The master's cycle on the newest setpoint, its frames on the bus (and the SYNC right after
/// them outside isochronous mode); start-up stops on a commissioning fault.
fn write_cycle<B: CanBus>(d: &mut Active<B>, cycle_now: u64) -> Result<(), RunError> {
    // A setpoint with a foreign contract version is an error: treat as no setpoint (stale).
    let sp = d.ports.setpoints.latest().unwrap_or_else(|e| {
        tracing::error!(error = %e, "setpoint rejected");
        None
    });
    d.out.clear();
    d.master.cycle(cycle_now, sp.as_ref(), &mut d.out);
    let iso = matches!(d.schedule, Schedule::Iso(_));
    if d.buses.send_frames(&d.out, iso)? {
        d.stats.rpdos_queued_behind += 1;
    }
    if !iso && d.out.sync_requested() {
        d.buses.send_sync()?;
        d.stats.syncs += 1;
    }
    d.master.mark_written(monotonic_ns());
    if let Some(msg) = d.master.describe_commissioning_fault() {
        // Start-up stops: the quick-stop frames of this cycle are on the bus already.
        return Err(RunError::Commissioning(msg));
    }
    if d.dcf_pending.is_some() && d.master.configured() {
        // Once, right after start-up (not in the steady loop).
        if let Some(dir) = d.dcf_pending.take() {
            write_dcfs(&d.master, &dir)?;
        }
    }
    Ok(())
}

/// The cycle's feedback, readiness, state event, heartbeat and SYNC schedule.
fn publish<B: CanBus>(d: &mut Active<B>) -> Result<(), RunError> {
    let (p, s) = (&d.ports, &mut d.stats);
    p.feedback.publish(d.master.feedback())?;
    // Ready once the drives are operational (NMT boot, SDO, CiA 402 enabled), so motion-core
    // (After= drive-io) starts on drives that follow its setpoints, as `crs sim` starts it.
    if !d.notified_ready && matches!(d.master.state(), BusState::Ready | BusState::Running) {
        crs_service::notify_ready("drives operational, SYNC loop running");
        d.notified_ready = true;
    }
    if let Some(ev) = d.master.take_state_event(s.event_seq + 1) {
        s.event_seq += 1;
        tracing::info!(state = ?BusState::from_u32(ev.state), detail = ev.detail, node = ev.detail_node, "bus state");
        p.event_pub.publish(&ev)?;
        if ev.kind == EventKind::Fault as u32 || ev.state == BusState::EStop as u32 {
            p.wakeup.notify()?;
        }
    }
    if s.cycles.is_multiple_of(100) {
        let mut hb = Heartbeat::new(ProcessId::DriveIo, d.master.state() as u32, s.cycles);
        hb.overruns = s.overruns;
        p.heartbeat.publish(&hb)?;
    }
    if let (Some(sp), Schedule::Iso(iso)) = (&d.schedule_pub, &d.schedule)
        && (s.cycles == 1 || s.cycles.is_multiple_of(1000))
    {
        s.schedule_seq += 1;
        sp.publish(&SyncSchedule::new(
            iso.sync_at_ns(),
            d.period_ns,
            s.schedule_seq,
        ))?;
    }
    Ok(())
}

/// Deactivate: the summary of the run (the ports and buses close when dropped).
fn deactivate<B: CanBus>(d: Active<B>) -> RunSummary {
    let (setpoint_cycles, clock_cycles) = d.schedule.counts();
    let s = &d.stats;
    tracing::info!(
        setpoint_cycles,
        clock_cycles,
        syncs = s.syncs,
        sync_late_max_us = s.sync_late_max_ns as f64 / 1000.0,
        sync_priority_paths = s.sync_priority_paths,
        rpdos_late_at_sync = s.rpdos_late_at_sync,
        rpdos_queued_behind = s.rpdos_queued_behind,
        "cycles started by a setpoint / by drive-io's own clock"
    );
    RunSummary {
        cycles: s.cycles,
        overruns: s.overruns,
        final_state: d.master.state(),
        tx_full_drops: d.buses.tx_full,
        setpoint_cycles,
        clock_cycles,
        syncs: s.syncs,
        sync_late_max_ns: s.sync_late_max_ns,
        superseded_setpoints: d.master.superseded_setpoints(),
        sync_priority_paths: s.sync_priority_paths,
        rpdos_late_at_sync: s.rpdos_late_at_sync,
        rpdos_queued_behind: s.rpdos_queued_behind,
    }
}

/// One received frame or bus error into the safety watch and the master.
fn on_rx(iface: usize, ev: RxEvent, master: &mut Master, watch: Option<&mut SafetyWatch>) {
    match ev {
        RxEvent::Frame(rx) => {
            if let Some(w) = watch {
                w.on_frame(&rx.frame, rx.rx_monotonic_ns);
            }
            master.on_frame(iface, &rx);
        }
        RxEvent::BusError(e) => master.on_bus_error(&e.error),
    }
}

/// Drains the "setpoint published" event into the clock. True if the event channel failed:
/// drive-io then runs on its own clock for good (SYNC never stops for an IPC error).
fn drain_ready(listener: &SetpointReadyListener, schedule: &mut Schedule) -> bool {
    match listener.drain() {
        Ok(true) => {
            schedule.notified();
            false
        }
        Ok(false) => false,
        Err(e) => {
            tracing::error!(error = %e, "setpoint event failed: cycles on drive-io's own clock from now on");
            schedule.degrade();
            true
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use can_transport::RxFrame;
    use drive_bus::canopen::{NmtState, heartbeat, nmt};
    use std::sync::{Arc, Mutex};

    /// What a fake interface was handed: (path, frame); path 0 = the interface's own socket,
    /// 1 = its priority path.
    type Log = Arc<Mutex<Vec<(u8, CanFrame)>>>;

    /// A transport with a transmit queue the test sets ([`CanBus::tx_backlog`]) and, if
    /// `priority`, a priority path; every send is logged.
    struct FakeBus {
        log: Log,
        path: u8,
        priority: bool,
        backlog: Arc<Mutex<u64>>,
    }

    impl CanBus for FakeBus {
        fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
            self.log.lock().unwrap().push((self.path, *frame));
            Ok(())
        }
        fn recv_timeout(&mut self, _: Duration) -> Result<Option<RxFrame>, CanError> {
            Ok(None)
        }
        fn interface(&self) -> &str {
            "fake"
        }
        fn open_priority_path(&self) -> Result<Option<Box<dyn CanBus>>, CanError> {
            Ok(self.priority.then(|| {
                Box::new(FakeBus {
                    log: self.log.clone(),
                    path: 1,
                    priority: false,
                    backlog: Arc::new(Mutex::new(0)),
                }) as Box<dyn CanBus>
            }))
        }
        fn tx_backlog(&self) -> Option<u64> {
            Some(*self.backlog.lock().unwrap())
        }
    }

    fn fake(priority: bool) -> (FakeBus, Log, Arc<Mutex<u64>>) {
        let log = Log::default();
        let backlog = Arc::new(Mutex::new(0));
        let b = FakeBus {
            log: log.clone(),
            path: 0,
            priority,
            backlog: backlog.clone(),
        };
        (b, log, backlog)
    }

    fn rpdo(node: u16) -> CanFrame {
        CanFrame::new(0x200 + node, &[0x0F, 0, 1, 2, 3, 4]).unwrap()
    }

    #[test]
    fn the_sync_goes_through_the_priority_path_where_the_transport_has_one() {
        let (a, log_a, _) = fake(true);
        let (b, log_b, backlog_b) = fake(false);
        let mut buses = Buses::new(vec![a, b]);
        // Before the paths are opened (clock / setpoint mode): behind the RPDOs, same socket.
        buses.send_sync().unwrap();
        assert_eq!(log_a.lock().unwrap().last().unwrap().0, 0);
        assert_eq!(buses.open_sync_paths().unwrap(), 1);
        buses.send_sync().unwrap();
        assert_eq!(*log_a.lock().unwrap().last().unwrap(), (1, sync()));
        // Interface b's transport has no priority path: its SYNC stays on its socket, and its
        // backlog (which holds that SYNC) is not counted as RPDOs late at the SYNC.
        assert_eq!(*log_b.lock().unwrap().last().unwrap(), (0, sync()));
        *backlog_b.lock().unwrap() = 1;
        assert!(!buses.backlog_behind_sync());
        // The cycle's RPDOs still go through the interface's own socket.
        let mut out = BusFrames::new(2);
        out.push_rpdo(0, rpdo(1));
        assert!(!buses.send_frames(&out, true).unwrap());
        assert_eq!(*log_a.lock().unwrap().last().unwrap(), (0, rpdo(1)));
    }

    #[test]
    fn rpdos_queued_behind_earlier_frames_are_sent_and_counted() {
        let (a, log_a, backlog_a) = fake(true);
        let (b, log_b, _) = fake(true);
        let mut buses = Buses::new(vec![a, b]);
        buses.open_sync_paths().unwrap();
        let mut out = BusFrames::new(2);
        out.push_rpdo(0, rpdo(1));
        out.push(0, heartbeat(0x7F, NmtState::Operational));
        out.push(0, nmt(0x01, 1));
        out.push_rpdo(1, rpdo(2));
        *backlog_a.lock().unwrap() = 2;
        assert!(buses.any_backlog());
        assert!(buses.backlog_behind_sync());
        // Interface a: queued behind its earlier frames (counted), all of it still sent in
        // order, through its own socket; b unaffected.
        assert!(buses.send_frames(&out, true).unwrap());
        let sent_a: Vec<(u8, CanFrame)> = log_a.lock().unwrap().clone();
        assert_eq!(
            sent_a,
            vec![
                (0, rpdo(1)),
                (0, heartbeat(0x7F, NmtState::Operational)),
                (0, nmt(0x01, 1))
            ]
        );
        assert_eq!(*log_b.lock().unwrap(), vec![(0, rpdo(2))]);
        // Not checked (clock / setpoint mode): not counted.
        assert!(!buses.send_frames(&out, false).unwrap());
        // A backlog without RPDOs in the cycle is not a cycle's RPDOs queued behind.
        let mut hb_only = BusFrames::new(2);
        hb_only.push(0, heartbeat(0x7F, NmtState::Operational));
        assert!(!buses.send_frames(&hb_only, true).unwrap());
        // The queue drained: not counted.
        *backlog_a.lock().unwrap() = 0;
        assert!(!buses.any_backlog());
        assert!(!buses.backlog_behind_sync());
        assert!(!buses.send_frames(&out, true).unwrap());
    }
}
