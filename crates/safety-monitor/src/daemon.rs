//! The monitor process: its own 15 ms absolute-deadline cycle (clock_nanosleep TIMER_ABSTIME)
//! around [`Monitor`], iceoryx2 in, iceoryx2 + CAN out, as configure → activate → cycle →
//! deactivate ([`run_on`]).
//!
//! Per cycle ([`Daemon::cycle`]): drain the state events, EVERY setpoint and feedback sample
//! since the last cycle, then the platform identity (announced before the setpoints it
//! covers), and the bus reader thread's observations; close
//! the cycle; on a new trip send the stop from the monitor's OWN CAN socket (quick stop, NMT
//! stop, STOP heartbeat) and latch an e-stop event on iceoryx2, so the stop works even if
//! motion-core or drive-io hang; act on an operator's reset; publish the doubled safety
//! heartbeat and the iceoryx2 heartbeat. Who may reset and how a reset releases the stack
//! (the codes: [`crs_ipc::MonitorCode`]): docs/safety-monitor.md, "Reset protocol" and "Reset
//! authority".

use crate::bus_frames::{self, Observed};
use crate::bus_watch::{ReaderHealth, ReaderWatch};
use crate::capacity::SENT_OWN_FRAMES;
use crate::config::MonitorConfig;
use crate::identity::platform_identity;
use crate::kinematics::StandardKinematics;
use crate::monitor::{Limits, Monitor, ResetDecision, StateCode};
use crate::stop_path::{StopCounts, StopPath, StopStage};
use crate::trip::{Cause, TripRecord};
use can_transport::{CanBus, CanError, RxEvent, safety_frame};
use crossbeam::queue::ArrayQueue;
use crs_ipc::{
    DriveFeedback, EventKind, Heartbeat, IpcError, IpcNode, JointSetpoint, MAX_CABLES, MonitorCode,
    PlatformIdentity, ProcessId, StateEvent, monotonic_ns,
};
use crs_rt::sleep_until;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

/// More state events than this in one monitor cycle is a flood: the subscriber's buffer (64)
/// may have overwritten an e-stop unseen, so the process bus can no longer be trusted to
/// deliver a stop (`ipc_error`, value = the count). The stack publishes a few events a second.
pub const MAX_EVENTS_PER_CYCLE: u32 = 48;
/// Monitor cycles between two epoch announcements (about one second).
pub const EPOCH_ANNOUNCE_CYCLES: u64 = 67;
/// Requests older than this are stale (e.g. history of a previous run) and ignored.
pub const RESET_REQUEST_MAX_AGE_NS: u64 = 5_000_000_000;
/// How far in the monitor's future an event's timestamp may lie (same CLOCK_MONOTONIC host;
/// covers the sender taking its timestamp just after the monitor's cycle started).
pub const EVENT_FUTURE_TOLERANCE_NS: u64 = 50_000_000;

/// A state event is fresh when its (sender's) timestamp lies within the last
/// [`RESET_REQUEST_MAX_AGE_NS`] of the monitor's clock — and NOT in its future beyond
/// [`EVENT_FUTURE_TOLERANCE_NS`]: a future timestamp would otherwise be "fresh" forever (a
/// replayed or forged request).
pub fn is_fresh(now_ns: u64, event_ns: u64) -> bool {
    event_ns <= now_ns.saturating_add(EVENT_FUTURE_TOLERANCE_NS)
        && now_ns.saturating_sub(event_ns) <= RESET_REQUEST_MAX_AGE_NS
}

/// RUN heartbeats sent after an accepted reset before the Reset event (the drives' and
/// drive-io's watches need `release_pairs` (default 3) consecutive RUN pairs to release).
pub const RESET_MIN_RUN_CYCLES: u32 = 4;
/// The instance nonce of this monitor process (the high half of its reset epoch,
/// [`crs_limits::reset_epoch`]): drawn from the kernel's random source, so a restarted monitor
/// is another instance whose start epoch (count 0) releases none of the consumers that stopped
/// under the previous one; they wait for an operator reset of the new instance. If the draw
/// fails, the monotonic clock's low bits stand in (still different from the previous run's
/// draw with overwhelming probability; a collision only keeps the consumers stopped).
pub fn random_instance() -> u16 {
    let mut b = [0u8; 2];
    // SAFETY: `b` is valid for 2 bytes; getrandom writes at most that many.
    let n = unsafe { libc::getrandom(b.as_mut_ptr().cast(), b.len(), 0) };
    if n == 2 {
        u16::from_le_bytes(b)
    } else {
        (monotonic_ns() >> 10) as u16
    }
}

/// The frames the monitor sent on its own identifiers recently (COB-ID, data, length): a frame
/// on those identifiers that it receives and did not send is another node speaking for it
/// ([`Monitor::on_impersonation`]). As many as the longest reader stall the configuration
/// allows sends ([`SENT_OWN_FRAMES`]): with 64 (16 cycles) a reader that fell 240 ms behind
/// read the monitor's own frames as another node's and tripped (a guest stall).
#[derive(Debug)]
pub struct SentOwn {
    ring: [(u16, [u8; 8], u8); SENT_OWN_FRAMES],
    len: usize,
    next: usize,
}

impl Default for SentOwn {
    fn default() -> Self {
        Self {
            ring: [(0, [0; 8], 0); SENT_OWN_FRAMES],
            len: 0,
            next: 0,
        }
    }
}

impl SentOwn {
    pub fn record(&mut self, f: &can_transport::CanFrame) {
        let mut d = [0u8; 8];
        d[..f.data().len()].copy_from_slice(f.data());
        self.ring[self.next] = (f.id() as u16, d, f.data().len() as u8);
        self.next = (self.next + 1) % self.ring.len();
        self.len = (self.len + 1).min(self.ring.len());
    }

    pub fn contains(&self, cob_id: u16, data: &[u8; 8], len: u8) -> bool {
        self.ring[..self.len].contains(&(cob_id, *data, len))
    }
}

/// The monitor's own recently published state events (kind, sequence, detail): a received
/// event that claims the monitor's source but is not among them was published by another
/// process (iceoryx2 0.10 does not authenticate publishers; whatever of its own events the
/// monitor's subscriber delivers back matches). The monitor publishes a few events per reset
/// or trip, so 32 cover far more than one cycle's worth.
#[derive(Debug, Default)]
pub struct OwnEvents {
    ring: [(u32, u64, u32); 32],
    len: usize,
    next: usize,
}

impl OwnEvents {
    pub fn record(&mut self, ev: &StateEvent) {
        self.ring[self.next] = (ev.kind, ev.sequence, ev.detail);
        self.next = (self.next + 1) % self.ring.len();
        self.len = (self.len + 1).min(self.ring.len());
    }

    pub fn contains(&self, ev: &StateEvent) -> bool {
        self.ring[..self.len].contains(&(ev.kind, ev.sequence, ev.detail))
    }
}

/// Publishes one of the monitor's own events and remembers it ([`OwnEvents`]).
fn publish_own(
    publisher: &crs_ipc::TopicPublisher<StateEvent>,
    own: &mut OwnEvents,
    ev: &StateEvent,
) -> Result<(), IpcError> {
    own.record(ev);
    publisher.publish(ev)
}

/// Bus observations buffered between two cycles.
const OBS_QUEUE: usize = 8192;

#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error(transparent)]
    Ipc(#[from] IpcError),
    #[error(transparent)]
    Can(#[from] CanError),
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error("{0}")]
    Other(String),
}

/// What the process did, returned when it stops.
#[derive(Debug, Clone, Copy, Default)]
pub struct Summary {
    pub cycles: u64,
    pub overruns: u64,
    pub trips: u64,
    pub setpoints_checked: u64,
    pub setpoints_missing: u64,
    pub rpdo_checked: u64,
    /// Frames not sent after every retry (all kinds) and the stop path's counts.
    pub can_send_errors: u64,
    pub stop: StopCounts,
    /// CAN error frames received from the bus controller.
    pub bus_errors: u64,
    pub max_abs_dq_m: f64,
    pub max_lateness_ns: u64,
}

#[derive(Debug, Clone, Copy)]
struct Obs {
    /// The CAN interface it was seen on.
    iface: u8,
    what: Observed,
    rx_ns: u64,
}

/// Batch period of the bus reader: it drains its socket this often instead of waking for
/// every frame (a 1 kHz drive bus carries ~26 frames/ms; one wake-up per frame cost the
/// monitor ~16 % of a core, see benches/RESULTS.md ("Safety monitor")).
const READER_BATCH: Duration = Duration::from_millis(3);

/// Reads every interface on its own sockets and queues RPDO targets, drive heartbeats, forces
/// and the controllers' error frames (subscribed when the sockets were opened). A batch counts
/// as complete when every interface was drained.
fn bus_reader(
    mut buses: Vec<Box<dyn CanBus>>,
    layout: crate::bus_layout::BusLayout,
    own_cob: u16,
    queue: Arc<ArrayQueue<Obs>>,
    stop: Arc<AtomicBool>,
    health: Arc<ReaderHealth>,
) {
    let mut next = monotonic_ns();
    while !stop.load(Ordering::Relaxed) {
        next += READER_BATCH.as_nanos() as u64;
        sleep_until(next);
        let now = monotonic_ns();
        if now > next + 100_000_000 {
            next = now;
        }
        let mut complete = true;
        for (iface, bus) in buses.iter_mut().enumerate() {
            loop {
                let (what, rx_ns) = match bus.try_recv_event() {
                    Ok(Some(RxEvent::Frame(rx))) => {
                        match bus_frames::own_id(own_cob, &rx.frame)
                            .or_else(|| bus_frames::observe(&layout, iface, &rx.frame))
                        {
                            Some(what) => (what, rx.rx_monotonic_ns),
                            None => continue,
                        }
                    }
                    Ok(Some(RxEvent::BusError(e))) => {
                        (Observed::BusError(e.error.condition()), e.rx_monotonic_ns)
                    }
                    Ok(None) => break,
                    Err(e) => {
                        health.errors.fetch_add(1, Ordering::Relaxed);
                        tracing::error!(error = %e, interface = iface, "bus reader: receive failed");
                        complete = false;
                        std::thread::sleep(Duration::from_millis(50));
                        break;
                    }
                };
                let obs = Obs {
                    iface: iface as u8,
                    what,
                    rx_ns,
                };
                if queue.push(obs).is_err() {
                    health.dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        if complete {
            health.batches.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// One line in the trip log when the stop path escalated (NMT stop unsent, or nothing sent).
fn append_stop_log(path: &std::path::Path, stage: StopStage, c: &StopCounts) {
    append_line(
        path,
        &format!(
            "stop_path={} nmt_stop_unsent={} quick_stop_unsent={} heartbeat_unsent={} \
             retried_ok={}",
            stage.name(),
            c.nmt_stop_unsent,
            c.quick_stop_unsent,
            c.heartbeat_unsent,
            c.retried_ok
        ),
    );
}

fn append_trip_log(path: &std::path::Path, rec: &TripRecord) {
    append_line(path, &rec.to_string());
}

fn append_line(path: &std::path::Path, text: &str) {
    use std::io::Write;
    let unix = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0);
    let line = format!("t_unix_s={unix:.3} {text}\n");
    let r = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .and_then(|mut f| f.write_all(line.as_bytes()));
    if let Err(e) = r {
        tracing::error!(path = %path.display(), error = %e, "cannot append to the trip log");
    }
}

/// One socket per interface, in `MonitorConfig::interfaces` order.
pub type Sockets = Vec<Box<dyn CanBus>>;

/// Opens a sending and a receiving socket on every interface of `cfg` (in order).
pub fn open_buses(cfg: &MonitorConfig) -> Result<(Sockets, Sockets), DaemonError> {
    let specs = cfg.transports()?;
    let mut tx = Vec::with_capacity(specs.len());
    let mut rx = Vec::with_capacity(specs.len());
    for spec in &specs {
        tx.push(can_transport::open(spec)?);
        rx.push(can_transport::open(spec)?);
    }
    Ok((tx, rx))
}

/// Runs the monitor on every interface of `cfg` until `stop` is set.
pub fn run(cfg: &MonitorConfig, ipc: &IpcNode, stop: &AtomicBool) -> Result<Summary, DaemonError> {
    let (tx, rx) = open_buses(cfg)?;
    run_on(cfg, tx, rx, ipc, stop)
}

/// Cycles run by this process so far, for the systemd watchdog thread (`crs-service`): it
/// pings only while this advances. A Relaxed add per 15 ms cycle, nothing else in the loop.
pub static CYCLES_RUN: AtomicU64 = AtomicU64::new(0);

/// [`run`] on given sockets, one of each per interface (`cfg.interfaces` order): `tx` send the
/// stop frames and the heartbeat, `rx` are the bus reader's (they subscribe to the
/// controllers' error frames). Tests and the HIL matrix pass a failing `tx`
/// ([`crate::stop_path::FailingSends`]).
///
/// The lifecycle of ros2_control's components: [`configure`] (sockets, ports, the Monitor),
/// [`activate`] (the bus reader thread, real-time scheduling, ready), the cycle
/// ([`Daemon::cycle`]) until `stop` is set, [`deactivate`] (the reader stopped, the summary).
pub fn run_on(
    cfg: &MonitorConfig,
    tx: Sockets,
    rx: Sockets,
    ipc: &IpcNode,
    stop: &AtomicBool,
) -> Result<Summary, DaemonError> {
    let (mut daemon, rx) = configure(cfg, tx, rx, ipc)?;
    let mut reader = activate(&mut daemon, rx)?;
    while !stop.load(Ordering::Relaxed) {
        daemon.cycle(&mut reader);
    }
    Ok(deactivate(daemon, reader))
}

/// The monitor's iceoryx2 ports.
struct Ports {
    setpoints: crs_ipc::TopicSubscriber<JointSetpoint>,
    feedback: crs_ipc::TopicSubscriber<DriveFeedback>,
    identities: crs_ipc::TopicSubscriber<PlatformIdentity>,
    events: crs_ipc::TopicSubscriber<StateEvent>,
    event_pub: crs_ipc::TopicPublisher<StateEvent>,
    heartbeat_pub: crs_ipc::TopicPublisher<Heartbeat>,
    wakeup: crs_ipc::WakeupNotifier,
}

/// What the configuration fixes for the whole run.
struct Setup<'a> {
    cfg: &'a MonitorConfig,
    identity: crs_ipc::PlatformId,
    /// Cable count.
    m: usize,
    cob: u16,
    period: u64,
    trip_log: Option<std::path::PathBuf>,
    /// The configuration signature: the SRDO configuration CRC the consumers check and the
    /// CRC of the safety parameter set, doubled like the heartbeat, every cycle.
    signature: [can_transport::CanFrame; 2],
    /// The reset key of the safety I/O node is a reset channel.
    key_enabled: bool,
    /// The high half of this monitor's reset epochs ([`random_instance`]).
    instance: u16,
    started_ns: u64,
    transport: String,
}

impl Setup<'_> {
    /// The cable of the drive `node` on interface `iface`.
    fn node_index(&self, iface: u8, node: u8) -> Option<usize> {
        self.cfg
            .winches
            .iter()
            .position(|w| w.node_id == node && w.interface == usize::from(iface))
    }
}

/// The state one run carries from cycle to cycle, allocated before the first cycle.
struct RunState {
    monitor: Monitor,
    tx: crate::tx_buses::TxBuses,
    stops: StopPath,
    last_stage: Option<StopStage>,
    sum: Summary,
    /// One owner per stream: setpoints, feedback and identity.
    owners: [crate::ownership::OwnerWatch; 3],
    procs: crate::ownership::ProcFs,
    /// The operator's reset channels (crate::operator): the safety I/O node's key, the socket.
    key: crate::operator::KeyWatch,
    reset_socket: Option<crate::reset_socket::ResetSocket>,
    sent_own: SentOwn,
    own: OwnEvents,
    impersonations: u64,
    denied: u64,
    forged: u64,
    ignored_resets: u64,
    bus_errors: u64,
    last_announced: Option<u32>,
    /// Safety heartbeat counter.
    counter: u16,
    event_seq: u64,
    last_target: [Option<i32>; MAX_CABLES],
    drive_state: [u8; MAX_CABLES],
    drive_state_ns: [u64; MAX_CABLES],
    /// After an accepted reset: (NMT start time, cycles since).
    resetting: Option<(u64, u32)>,
    deadline: u64,
    last_overrun_log_ns: u64,
}

/// A configured monitor process: [`configure`] builds it, [`Daemon::cycle`] runs it.
pub struct Daemon<'a> {
    setup: Setup<'a>,
    ports: Ports,
    st: RunState,
}

/// The bus reader thread and what it shares with the cycle.
pub struct Reader {
    queue: Arc<ArrayQueue<Obs>>,
    stop: Arc<AtomicBool>,
    health: Arc<ReaderHealth>,
    watch: ReaderWatch,
    thread: std::thread::JoinHandle<()>,
}

/// What one cycle's inputs ask of its end: an operator's reset, a foreign Reset event.
#[derive(Default)]
struct Requests {
    reset: Option<(crate::operator::OperatorReset, ReplyTo)>,
    foreign_reset: bool,
}

/// Configure: checks the sockets against the configuration, subscribes to the controllers'
/// error frames, builds the Monitor and opens every iceoryx2 port and the reset socket.
/// Returns the daemon and the bus reader's sockets.
pub fn configure<'a>(
    cfg: &'a MonitorConfig,
    tx: Sockets,
    mut rx: Sockets,
    ipc: &IpcNode,
) -> Result<(Daemon<'a>, Sockets), DaemonError> {
    if tx.len() != cfg.interfaces.len() || rx.len() != cfg.interfaces.len() {
        return Err(DaemonError::Other(format!(
            "{} interfaces configured, {} sending / {} receiving sockets given",
            cfg.interfaces.len(),
            tx.len(),
            rx.len()
        )));
    }
    // Error frames (bus-off, error-passive) are a trip cause: without the subscription the
    // monitor could not see them, so a transport that cannot carry them is refused.
    for b in &mut rx {
        b.subscribe_bus_errors()?;
    }
    let transport = tx
        .iter()
        .map(|b| b.interface().to_string())
        .collect::<Vec<_>>()
        .join(", ");
    let tx = crate::tx_buses::TxBuses::new(tx, &cfg.safety_interfaces);
    let identity = platform_identity(&cfg.platform);
    let kin = StandardKinematics::new(&cfg.platform);
    let instance = random_instance();
    let monitor = Monitor::new(Limits::from(cfg), kin, identity).with_instance(instance);
    let cob = cfg.can.safety_cob_id;
    let ports = Ports {
        setpoints: ipc.subscriber::<JointSetpoint>()?,
        feedback: ipc.subscriber::<DriveFeedback>()?,
        identities: ipc.subscriber::<PlatformIdentity>()?,
        events: ipc.subscriber::<StateEvent>()?,
        event_pub: ipc.publisher::<StateEvent>()?,
        heartbeat_pub: ipc.publisher::<Heartbeat>()?,
        wakeup: ipc.wakeup_notifier()?,
    };
    let setup = Setup {
        cfg,
        identity,
        m: cfg.platform.cables(),
        cob,
        period: cfg.cycle_ns(),
        trip_log: cfg.trip_log(),
        signature: safety_frame::ConfigSignature {
            srdo_crc: cfg.srdo().crc(),
            safety_params_crc: cfg.safety_params_crc,
        }
        .encode(cob),
        key_enabled: cfg.reset.key && cfg.layout.safety_io.is_some(),
        instance,
        started_ns: 0,
        transport,
    };
    let reset_socket = match &cfg.reset_socket {
        Some((path, gid)) => {
            let s = crate::reset_socket::ResetSocket::bind(path, *gid)
                .map_err(|e| DaemonError::Other(e.to_string()))?;
            tracing::info!(socket = %path.display(), operator_gid = gid, "reset socket listening");
            Some(s)
        }
        None => None,
    };
    let st = RunState {
        monitor,
        tx,
        stops: StopPath::new(),
        last_stage: None,
        sum: Summary::default(),
        owners: [
            crate::ownership::OwnerWatch::new("setpoints", cfg.ipc.setpoint_owners.clone()),
            crate::ownership::OwnerWatch::new("drive feedback", cfg.ipc.feedback_owners.clone()),
            crate::ownership::OwnerWatch::new("platform identity", cfg.ipc.identity_owners.clone()),
        ],
        procs: crate::ownership::ProcFs,
        key: crate::operator::KeyWatch::new(),
        reset_socket,
        sent_own: SentOwn::default(),
        own: OwnEvents::default(),
        impersonations: 0,
        denied: 0,
        forged: 0,
        ignored_resets: 0,
        bus_errors: 0,
        last_announced: None,
        counter: 0,
        event_seq: 0,
        last_target: [None; MAX_CABLES],
        drive_state: [0; MAX_CABLES],
        drive_state_ns: [0; MAX_CABLES],
        resetting: None,
        deadline: 0,
        last_overrun_log_ns: 0,
    };
    Ok((Daemon { setup, ports, st }, rx))
}

/// Activate: starts the bus reader thread, makes the cycle thread real-time, logs the start
/// and tells systemd the monitor is ready; the first deadline is one period from now. The
/// start-up verification (every drive operational with live feedback) runs in the cycle: the
/// monitor says STOP until it holds.
pub fn activate(d: &mut Daemon<'_>, rx: Sockets) -> Result<Reader, DaemonError> {
    let cfg = d.setup.cfg;
    let reader = spawn_reader(cfg, rx)?;
    if cfg.monitor.rt_priority > 0 {
        let cpu = usize::try_from(cfg.monitor.cpu).ok();
        // The OS plumbing is shared with the other loops (crs-rt: no controller code). Every
        // setting is attempted even when another is refused; the monitor keeps running on
        // what was granted (it must not stop the stack's supervision over a missing
        // capability), and the warning names what was not.
        match crs_rt::make_realtime(cfg.monitor.rt_priority, cpu) {
            Ok(_) => tracing::info!(
                priority = cfg.monitor.rt_priority,
                ?cpu,
                "SCHED_FIFO + mlockall"
            ),
            Err(e) => tracing::warn!("{e}; the monitor runs without it"),
        }
    }
    tracing::info!(
        platform = %cfg.platform.name,
        identity = %crate::identity::hex(&d.setup.identity),
        cables = d.setup.m,
        cycle_ms = cfg.monitor.cycle_ms,
        dq_limit_mm = cfg.monitor.dq_limit_mm,
        transport = %d.setup.transport,
        safety_cob_id = format_args!("{:#05x}", d.setup.cob),
        reset_epoch = d.st.monitor.reset_epoch(),
        profile = %cfg.monitor.profile,
        platform_sha256 = %cfg.platform_sha256,
        safety_params_crc = format_args!("{:#010x}", cfg.safety_params_crc),
        srdo_crc = format_args!("{:#06x}", cfg.srdo().crc()),
        "safety monitor started"
    );
    if cfg.is_bench() {
        tracing::warn!("BENCH profile: checks may be switched off; not for the robot");
    }
    d.setup.started_ns = monotonic_ns();
    d.st.deadline = monotonic_ns() + d.setup.period;
    // systemd (Type=notify): ready once the CAN sockets and every iceoryx2 port are open.
    crs_service::notify_ready("CAN sockets and iceoryx2 ports open, monitor cycle running");
    Ok(reader)
}

/// The bus reader thread on the receiving sockets.
fn spawn_reader(cfg: &MonitorConfig, rx: Sockets) -> Result<Reader, DaemonError> {
    let queue = Arc::new(ArrayQueue::new(OBS_QUEUE));
    let stop = Arc::new(AtomicBool::new(false));
    let health = Arc::new(ReaderHealth::default());
    let (q, s, h) = (queue.clone(), stop.clone(), health.clone());
    let layout = cfg.layout.clone();
    let own_cob = cfg.can.safety_cob_id;
    // The reader is the monitor's eyes on the bus: at SCHED_OTHER a loaded host starved it
    // for tens of ms, and the cycle thread then saw the safety I/O node (and the drives)
    // silent and tripped although their frames were on the bus. It runs one priority below
    // the cycle thread, on the same CPU, when the monitor runs real-time at all.
    let rt = (cfg.monitor.rt_priority > 1).then(|| {
        (
            cfg.monitor.rt_priority - 1,
            usize::try_from(cfg.monitor.cpu).ok(),
        )
    });
    let thread = std::thread::Builder::new()
        .name("safety-bus-rx".into())
        .spawn(move || {
            if let Some((priority, cpu)) = rt {
                match crs_rt::make_realtime(priority, cpu) {
                    Ok(_) => tracing::info!(priority, ?cpu, "bus reader: SCHED_FIFO"),
                    Err(e) => tracing::warn!("bus reader: {e}; it runs without it"),
                }
            }
            bus_reader(rx, layout, own_cob, q, s, h)
        })
        .map_err(|e| DaemonError::Other(format!("spawning the bus reader: {e}")))?;
    Ok(Reader {
        queue,
        stop,
        health,
        watch: ReaderWatch::new(cfg.can.reader_stall_cycles),
        thread,
    })
}

/// Deactivate: stops and joins the bus reader, returns what the run did.
pub fn deactivate(d: Daemon<'_>, reader: Reader) -> Summary {
    reader.stop.store(true, Ordering::Relaxed);
    let _ = reader.thread.join();
    let mut sum = d.st.sum;
    let st = d.st.monitor.stats();
    sum.cycles = st.cycles;
    sum.setpoints_checked = st.setpoints_checked;
    sum.setpoints_missing = st.setpoints_missing;
    sum.rpdo_checked = st.rpdo_checked;
    sum.max_abs_dq_m = st.max_abs_dq_m;
    sum.stop = d.st.stops.counts();
    sum.can_send_errors = sum.stop.total_unsent();
    sum.bus_errors = d.st.bus_errors;
    let dropped = reader.health.dropped.load(Ordering::Relaxed);
    if dropped > 0 {
        tracing::warn!(dropped, "bus observations dropped (queue full)");
    }
    sum
}

impl Daemon<'_> {
    /// One monitor cycle at its absolute deadline: drain every input, close the cycle, act on
    /// a trip and on an operator's reset, publish. Allocates nothing on its normal path and
    /// waits on no lock.
    pub fn cycle(&mut self, reader: &mut Reader) {
        sleep_until(self.st.deadline);
        CYCLES_RUN.fetch_add(1, Ordering::Relaxed);
        let now = monotonic_ns();
        let late = now.saturating_sub(self.st.deadline);
        self.st.sum.max_lateness_ns = self.st.sum.max_lateness_ns.max(late);
        self.st.monitor.begin_cycle(now);

        let mut req = self.drain_events(now);
        self.poll_reset_socket(now, &mut req);
        self.drain_streams();
        // After the setpoints: a producer announces its identity before its first setpoint,
        // so every identity announced before a setpoint read above is read here, and the
        // setpoints are judged against it at the end of the cycle.
        self.drain_identities();
        self.drain_bus(&reader.queue, &mut req);
        self.check_observers(reader);
        let report = self.st.monitor.end_cycle(now);
        self.log_readiness(&report);
        self.act_on_trip(report.new_trip, report.state, req.foreign_reset);
        if let Some((r, reply)) = req.reset {
            self.handle_reset(r, reply, report.readiness, now);
        }
        self.release_after_reset(now);
        self.announce_epoch();
        self.publish_heartbeats();
        self.keep_deadline(now, late);
    }

    /// The platform identities announced since the last cycle.
    fn drain_identities(&mut self) {
        let monitor = &mut self.st.monitor;
        while let Some(id) = self.ports.identities.receive().unwrap_or_else(|e| {
            tracing::error!(error = %e, "platform identity receive failed");
            monitor.on_ipc_error();
            None
        }) {
            let before = monitor.identity_verified();
            monitor.on_identity(&id);
            if !monitor.identity_verified() {
                tracing::error!(
                    announced = %crate::identity::hex(&id.hash),
                    own = %crate::identity::hex(&self.setup.identity),
                    cables = id.cable_count,
                    "platform identity MISMATCH"
                );
            } else if !before {
                tracing::info!("platform identity verified");
            }
        }
    }

    /// Every state event of this cycle, whatever is wrong with some of them: a sample of a
    /// foreign contract version is a fault (ipc_error) and does not stop the draining, so a
    /// flood of bad events cannot hold an e-stop back; more events than the buffer can be
    /// trusted with in one cycle is a flood and trips (an e-stop may have been overwritten
    /// unseen). Bounded: a publisher faster than this loop cannot keep it here.
    fn drain_events(&mut self, now: u64) -> Requests {
        let mut req = Requests::default();
        let mut events_this_cycle: u32 = 0;
        let mut bad_versions: u32 = 0;
        loop {
            if events_this_cycle >= 4 * MAX_EVENTS_PER_CYCLE {
                break;
            }
            let (ev, sender) = match self.ports.events.receive_with_sender() {
                Ok(Some(x)) => x,
                Ok(None) => break,
                Err(IpcError::Version { found, .. }) => {
                    events_this_cycle += 1;
                    bad_versions += 1;
                    if bad_versions == 1 {
                        tracing::error!(
                            found,
                            "a state event of a foreign contract version: the process bus                              cannot be trusted (ipc_error)"
                        );
                    }
                    continue;
                }
                Err(e) => {
                    tracing::error!(error = %e, "state event receive failed");
                    self.st.monitor.on_ipc_error();
                    break;
                }
            };
            events_this_cycle += 1;
            self.on_event(&ev, sender, now, &mut req);
        }
        if bad_versions > 0 {
            self.st.monitor.on_ipc_error();
        }
        if events_this_cycle > MAX_EVENTS_PER_CYCLE {
            tracing::error!(
                events = events_this_cycle,
                limit = MAX_EVENTS_PER_CYCLE,
                "state-event flood: an e-stop may have been lost in the subscriber's buffer \
                 (ipc_error)"
            );
            self.st.monitor.on_ipc_error();
        }
        req
    }

    /// One state event from the process bus (`sender`: the publisher's pid if known).
    fn on_event(&mut self, ev: &StateEvent, sender: Option<i32>, now: u64, req: &mut Requests) {
        let fresh = is_fresh(now, ev.timestamp_ns);
        let monitor = &mut self.st.monitor;
        if ev.source() == ProcessId::SafetyMonitor {
            self.on_own_source_event(ev, req);
        } else if ev.is_reset_request() {
            self.deny_bus_reset_request(ev, sender);
        } else if ev.source() == ProcessId::MotionCore
            && let Some(end) = ev.plan_end()
            && fresh
        {
            monitor.on_plan_announced(end);
        } else if ev.is_stream_end() && fresh {
            // Accepted only at the end of the announced plan, evaluated at the end of this
            // cycle after this cycle's setpoints (otherwise unplanned_stream_end).
            tracing::info!(
                at_plan_end = monitor.stream_end_planned(),
                "motion-core announced the end of its setpoint stream"
            );
            monitor.on_stream_end();
        } else if ev.kind == EventKind::EStop as u32 && fresh {
            // Anyone may stop; the monitor latches it so that only its verified reset ends
            // the stop in motion-core and drive-io.
            tracing::warn!(source = ev.source, "e-stop from another process: latched");
            monitor.on_estop_event(ev.source);
        } else if ev.kind == EventKind::Reset as u32 && fresh {
            // Only this monitor mints resets: anyone else's is ignored, logged
            // (rate-limited) and, while tripped, answered with the e-stop again.
            req.foreign_reset = true;
            self.st.ignored_resets += 1;
            if self.st.ignored_resets.is_power_of_two() {
                tracing::warn!(
                    source = ev.source,
                    ignored = self.st.ignored_resets,
                    "a Reset event from another process IGNORED: only the monitor resets"
                );
            }
        }
    }

    /// An event claiming the monitor's source. Our own events come back through our
    /// subscriber; anything else claiming our source is a second publisher impersonating the
    /// monitor: stamped after this monitor started (also in its future; older ones are a
    /// previous instance's history), or carrying this instance's epoch whatever its stamp.
    fn on_own_source_event(&mut self, ev: &StateEvent, req: &mut Requests) {
        let instance = self.setup.instance;
        let this_instance = |e: u32| crs_limits::reset_epoch::instance(e) == instance;
        let claims_instance = (ev.kind == EventKind::Reset as u32 && this_instance(ev.detail))
            || (ev.monitor_code() == Some(MonitorCode::EpochAnnounce)
                && this_instance(ev.detail_node));
        if (ev.timestamp_ns >= self.setup.started_ns || claims_instance)
            && !self.st.own.contains(ev)
        {
            self.st.forged += 1;
            if self.st.forged.is_power_of_two() {
                tracing::error!(
                    kind = ev.kind,
                    sequence = ev.sequence,
                    detail = ev.detail,
                    forged = self.st.forged,
                    "an event claiming the monitor's source that it did not publish: \
                     forged, e-stop"
                );
            }
            self.st.monitor.on_forged_event(ev.kind);
            req.foreign_reset |= ev.kind == EventKind::Reset as u32;
        }
    }

    /// A reset request on the process bus: any process of the stack's user can publish it
    /// under any source. Refused, answered, logged with its sender.
    fn deny_bus_reset_request(&mut self, ev: &StateEvent, sender: Option<i32>) {
        self.st.denied += 1;
        let denied = self.st.denied;
        let exe = sender
            .and_then(|pid| std::fs::read_link(format!("/proc/{pid}/exe")).ok())
            .map_or_else(|| "?".to_string(), |p| p.display().to_string());
        if denied.is_power_of_two() || denied < 8 {
            tracing::warn!(
                claimed_source = ev.source,
                sender_pid = ?sender,
                sender_executable = %exe,
                denied,
                "reset request on the process bus REFUSED: only the safety I/O node's \
                 reset key or the reset socket (operator group) may reset"
            );
        }
        let ans = StateEvent::monitor(
            self.st.monitor.state_code(),
            MonitorCode::ResetDenied,
            ev.sequence,
        );
        let _ = publish_own(&self.ports.event_pub, &mut self.st.own, &ans);
    }

    /// The reset socket: at most one request per cycle.
    fn poll_reset_socket(&mut self, now: u64, req: &mut Requests) {
        let Some(sock) = self.st.reset_socket.as_mut() else {
            return;
        };
        if req.reset.is_some() {
            return;
        }
        match sock.poll(now) {
            Some(crate::reset_socket::Request::Reset(r)) => {
                req.reset = Some((r, ReplyTo::Socket));
            }
            Some(crate::reset_socket::Request::Denied { peer, why }) => {
                self.st.denied += 1;
                tracing::warn!(
                    pid = peer.pid,
                    uid = peer.uid,
                    gid = peer.gid,
                    executable = %peer.executable(),
                    why,
                    "reset request on the reset socket DENIED"
                );
                sock.answer(&format!("denied {why}"));
            }
            None => {}
        }
    }

    /// EVERY setpoint and feedback sample since the last cycle.
    fn drain_streams(&mut self) {
        let monitor = &mut self.st.monitor;
        if let Err(e) = self.ports.setpoints.drain(|sp| monitor.on_setpoint(sp)) {
            tracing::error!(error = %e, "setpoint receive failed");
            monitor.on_ipc_error();
        }
        if let Err(e) = self.ports.feedback.drain(|fb| monitor.on_feedback(fb)) {
            tracing::error!(error = %e, "drive feedback receive failed");
            monitor.on_ipc_error();
        }
    }

    /// The bus reader's observations since the last cycle.
    fn drain_bus(&mut self, queue: &ArrayQueue<Obs>, req: &mut Requests) {
        while let Some(o) = queue.pop() {
            self.on_observed(o, req);
        }
    }

    /// One observation of the bus reader.
    fn on_observed(&mut self, o: Obs, req: &mut Requests) {
        let (setup, st) = (&self.setup, &mut self.st);
        let m = setup.m;
        match o.what {
            Observed::Rpdo {
                cable: i,
                controlword,
                target_counts,
            } => {
                if i < m {
                    st.last_target[i] = Some(target_counts);
                    if bus_frames::enables_operation(controlword) {
                        let l = setup.cfg.winches[i].counts_to_length_m(target_counts);
                        st.monitor.on_rpdo(i, l, o.rx_ns);
                    }
                }
            }
            Observed::Heartbeat { node, state } => {
                if let Some(i) = setup.node_index(o.iface, node) {
                    st.drive_state[i] = state;
                    st.drive_state_ns[i] = o.rx_ns;
                    st.monitor.on_drive_report(
                        i,
                        state == bus_frames::NMT_STATE_OPERATIONAL,
                        o.rx_ns,
                    );
                }
            }
            Observed::Force { cable, force_n } => {
                if cable < m {
                    st.monitor.on_force(cable, force_n, o.rx_ns);
                }
            }
            Observed::SafetyIo { inputs, outputs } => {
                st.monitor.on_safety_io(inputs, outputs, o.rx_ns);
                if setup.key_enabled {
                    on_key(&mut st.key, inputs, o.rx_ns, req);
                }
            }
            Observed::OwnId { cob_id, data, len } => {
                if !st.sent_own.contains(cob_id, &data, len) {
                    st.impersonations += 1;
                    if st.impersonations.is_power_of_two() {
                        tracing::error!(
                            cob_id = format_args!("{cob_id:#05x}"),
                            interface = o.iface,
                            impersonations = st.impersonations,
                            "a frame on the monitor's own identifiers that it did not send: \
                             another node speaks for the monitor (impersonation)"
                        );
                    }
                    st.monitor.on_impersonation(cob_id);
                }
            }
            Observed::BusError(condition) => {
                st.bus_errors += 1;
                if condition.is_loss_of_communication() || st.bus_errors.is_power_of_two() {
                    tracing::error!(
                        condition = condition.name(),
                        bus_errors = st.bus_errors,
                        "CAN error frame from the bus controller"
                    );
                }
                st.monitor.on_bus_error(condition);
            }
        }
    }

    /// The checks of the monitor's own observers: the streams' owners, the bus reader's
    /// health.
    fn check_observers(&mut self, reader: &mut Reader) {
        check_owners(
            &mut self.st.owners,
            [
                publishers_of(&self.ports.setpoints),
                publishers_of(&self.ports.feedback),
                publishers_of(&self.ports.identities),
            ],
            &mut self.st.procs,
            &mut self.st.monitor,
        );
        if let Some(f) = reader.watch.check(&reader.health) {
            tracing::error!(?f, "the monitor's own bus reader failed");
            self.st.monitor.on_bus_observation_failed(f.value());
        }
    }

    /// Says when the monitor became ready, and about once a second why it is not.
    fn log_readiness(&self, report: &crate::monitor::CycleReport) {
        let readiness = report.readiness;
        if report.became_ready {
            tracing::info!(
                identity_verified = readiness.identity_verified,
                "ready: every drive operational with live feedback; permitting motion (RUN)"
            );
        } else if report.state == StateCode::NotReady && self.st.counter.is_multiple_of(67) {
            tracing::info!(
                identity_verified = readiness.identity_verified,
                not_operational = format_args!("{:#x}", readiness.not_operational),
                no_feedback = format_args!("{:#x}", readiness.no_feedback),
                "not ready: motion not permitted (STOP) until every drive (bit = cable) is \
                 operational and sends force readings"
            );
        }
    }

    /// On a new trip the stop path and the latched e-stop event; while tripped the NMT stop
    /// every cycle and, after a foreign Reset, the e-stop event again.
    fn act_on_trip(&mut self, new_trip: Option<TripRecord>, state: StateCode, foreign: bool) {
        let (setup, st, ports) = (&self.setup, &mut self.st, &self.ports);
        let winches = &setup.cfg.winches;
        if let Some(rec) = new_trip {
            // Stop path first: quick stop to EVERY drive (holding its last target seen on the
            // bus; a drive whose RPDO was never seen gets target 0, which a CiA 402 drive in
            // quick stop does not follow), then the NMT stop of every drive (retried and
            // escalated when unsent: stop_path).
            for (i, l) in setup.cfg.layout.rpdo.iter().enumerate() {
                if let Some(bus) = st.tx.on(l.interface) {
                    st.stops.quick_stop(bus, l, st.last_target[i].unwrap_or(0));
                }
            }
            st.stops
                .nmt_stop_drives(&mut st.tx, winches.iter().map(|w| (w.interface, w.node_id)));
            st.resetting = None;
            st.event_seq += 1;
            let ev = estop_event(&rec, st.event_seq);
            if let Err(e) = publish_own(&ports.event_pub, &mut st.own, &ev) {
                tracing::error!(error = %e, "publishing the e-stop failed");
            }
            let _ = ports.wakeup.notify();
            st.sum.trips += 1;
            tracing::error!(%rec, "SAFETY TRIP: e-stop latched (NMT stop + quick stop sent)");
            if let Some(p) = &setup.trip_log {
                append_trip_log(p, &rec);
            }
        } else if state == StateCode::Tripped {
            st.stops
                .nmt_stop_drives(&mut st.tx, winches.iter().map(|w| (w.interface, w.node_id)));
            if foreign && let Some(rec) = st.monitor.trip() {
                st.event_seq += 1;
                let ev = estop_event(rec, st.event_seq);
                let _ = publish_own(&ports.event_pub, &mut st.own, &ev);
                let _ = ports.wakeup.notify();
                tracing::warn!("a Reset from another process while tripped: e-stop re-asserted");
            }
        }
    }

    /// An operator's reset request: the monitor decides, the decision is published (and
    /// answered on the socket it came from); an accepted one sends the NMT start.
    fn handle_reset(
        &mut self,
        req: crate::operator::OperatorReset,
        reply: ReplyTo,
        readiness: crate::monitor::Readiness,
        now: u64,
    ) {
        let st = &mut self.st;
        let channel = req.channel();
        let decision = st.monitor.request_reset(req);
        let (detail, cause) = match decision {
            ResetDecision::Accepted { .. } => (MonitorCode::ResetAccepted, 0),
            ResetDecision::NotTripped => (MonitorCode::ResetNotTripped, 0),
            ResetDecision::Refused(c) => (MonitorCode::ResetRefused, u32::from(c)),
            ResetDecision::NotReady => (MonitorCode::ResetNotReady, 0),
            ResetDecision::InstanceExhausted => (MonitorCode::ResetExhausted, 0),
        };
        st.event_seq += 1;
        let mut ev = StateEvent::monitor(st.monitor.state_code(), detail, st.event_seq);
        ev.detail_node = cause;
        let _ = publish_own(&self.ports.event_pub, &mut st.own, &ev);
        if let (ReplyTo::Socket, Some(sock)) = (reply, st.reset_socket.as_mut()) {
            sock.answer(&match decision {
                ResetDecision::Accepted { epoch } => format!("accepted epoch {epoch:#010x}"),
                ResetDecision::NotTripped => "not-tripped".into(),
                ResetDecision::Refused(c) => format!("refused {c}"),
                ResetDecision::NotReady => "not-ready".into(),
                ResetDecision::InstanceExhausted => "exhausted".into(),
            });
        }
        match decision {
            ResetDecision::Refused(c) => {
                tracing::warn!(cause = %c, %channel, "reset REFUSED: the cause persists or is not shown cleared")
            }
            ResetDecision::NotReady => {
                tracing::warn!(?readiness, %channel, "reset REFUSED: not ready yet")
            }
            ResetDecision::InstanceExhausted => tracing::error!(
                %channel,
                "reset REFUSED: this monitor instance has counted 65535 resets; restart it"
            ),
            // Armed and no consumer waits: nothing is latched here, so nothing changes
            // anywhere (no NMT start, no Reset event that would clear latches the monitor
            // never evaluated).
            ResetDecision::NotTripped => {
                tracing::info!(%channel, "reset request while armed: nothing to reset, nothing changed")
            }
            ResetDecision::Accepted { epoch } => {
                tracing::info!(
                    epoch = format_args!("{epoch:#010x}"),
                    %channel,
                    "reset ACCEPTED: new reset epoch, NMT start, releasing the stack"
                );
                st.stops
                    .other(&mut st.tx, &bus_frames::nmt(bus_frames::NMT_START, 0));
                st.resetting = Some((now, 0));
            }
        }
    }

    /// After an accepted reset: once the consumers' watches had their RUN pairs of the new
    /// epoch and every drive reports operational (or the wait timed out), the epoch
    /// announcement and the Reset event that releases the stack.
    fn release_after_reset(&mut self, now: u64) {
        let (setup, st) = (&self.setup, &mut self.st);
        let Some((t0, n)) = st.resetting.as_mut() else {
            return;
        };
        *n += 1;
        let all_up = (0..setup.m).all(|i| {
            st.drive_state[i] == bus_frames::NMT_STATE_OPERATIONAL && st.drive_state_ns[i] > *t0
        });
        let timed_out =
            now.saturating_sub(*t0) > u64::from(setup.cfg.can.reset_wait_ms) * 1_000_000;
        if *n >= RESET_MIN_RUN_CYCLES && (all_up || timed_out) {
            if !all_up {
                tracing::warn!(
                    "not every drive reported operational after the NMT start; releasing anyway"
                );
            }
            // The epoch announcement first (motion-core accepts a Reset only of the epoch
            // the current monitor announced), then the Reset itself.
            st.event_seq += 1;
            let ann = epoch_announcement(&st.monitor, st.event_seq);
            let _ = publish_own(&self.ports.event_pub, &mut st.own, &ann);
            st.last_announced = Some(st.monitor.reset_epoch());
            st.event_seq += 1;
            let mut ev = StateEvent::new(ProcessId::SafetyMonitor, EventKind::Reset, st.event_seq);
            // The epoch this reset minted; drive-io acts on it only once its watch has
            // verified the same epoch in the doubled heartbeat on CAN.
            ev.detail = st.monitor.reset_epoch();
            let _ = publish_own(&self.ports.event_pub, &mut st.own, &ev);
            st.resetting = None;
        }
    }

    /// The epoch announcement about once a second (motion-core, which has no CAN, learns
    /// which epoch the current monitor stands for); not while a reset's Reset event is
    /// pending (that announces the new epoch itself, right before the event).
    fn announce_epoch(&mut self) {
        let st = &mut self.st;
        if st.resetting.is_none()
            && (st.last_announced != Some(st.monitor.reset_epoch())
                || st
                    .monitor
                    .stats()
                    .cycles
                    .is_multiple_of(EPOCH_ANNOUNCE_CYCLES))
        {
            st.event_seq += 1;
            let ann = epoch_announcement(&st.monitor, st.event_seq);
            let _ = publish_own(&self.ports.event_pub, &mut st.own, &ann);
            st.last_announced = Some(st.monitor.reset_epoch());
        }
    }

    /// The fail-safe heartbeat: every cycle, STOP while tripped, after the signature (a
    /// consumer counts a RUN pair only with a recent signature of its own CRC). Every frame
    /// on the monitor's own identifiers is remembered: one it receives and did not send is
    /// an impersonation. Then the heartbeat on the process bus.
    fn publish_heartbeats(&mut self) {
        let (setup, st) = (&self.setup, &mut self.st);
        for f in &setup.signature {
            st.sent_own.record(f);
            st.stops.other(&mut st.tx.safety(), f);
        }
        let tripped = st.monitor.state().is_tripped();
        let pair = safety_frame::encode(&st.monitor.heartbeat(st.counter), setup.cob);
        for f in &pair {
            st.sent_own.record(f);
        }
        let stage = st.stops.heartbeat(&mut st.tx.safety(), &pair, tripped);
        if let Some(s) = stage
            && st.last_stage != Some(s)
        {
            if s != StopStage::NmtStop
                && let Some(p) = &setup.trip_log
            {
                append_stop_log(p, s, &st.stops.counts());
            }
            st.last_stage = Some(s);
        }
        st.counter = st.counter.wrapping_add(1);
        let mut hb = Heartbeat::monitor(st.monitor.state_code(), st.monitor.stats().cycles);
        hb.overruns = st.sum.overruns.min(u64::from(u32::MAX)) as u32;
        let _ = self.ports.heartbeat_pub.publish(&hb);
    }

    /// The next deadline; missed ones are skipped and counted as overruns.
    fn keep_deadline(&mut self, now: u64, late: u64) {
        let period = self.setup.period;
        let st = &mut self.st;
        st.deadline += period;
        let done = monotonic_ns();
        if done > st.deadline {
            // Skip missed deadlines instead of bursting; the setpoint buffer (64) covers a late
            // cycle, lost samples show up as sequence gaps.
            let missed = (done - st.deadline) / period + 1;
            st.sum.overruns += missed;
            st.deadline += missed * period;
            // Said when it happens (at most once a second): a late monitor also delays its
            // safety heartbeat pairs, and the drives' watch stops the robot after the
            // validation time — the log must show whether the MONITOR was late.
            if done.saturating_sub(st.last_overrun_log_ns) > 1_000_000_000 {
                st.last_overrun_log_ns = done;
                tracing::warn!(
                    woke_late_ms = late as f64 * 1e-6,
                    cycle_took_ms = done.saturating_sub(now) as f64 * 1e-6,
                    missed_cycles = missed,
                    overruns = st.sum.overruns,
                    "monitor cycle overran its deadline"
                );
            }
        }
    }
}

/// The reset key's inputs from the safety I/O node: turned and released is an operator's
/// reset (the first of the cycle counts).
fn on_key(key: &mut crate::operator::KeyWatch, inputs: u8, rx_ns: u64, req: &mut Requests) {
    use crate::operator::KeyEvent;
    match key.on_inputs(inputs, rx_ns) {
        KeyEvent::Reset(r) => {
            if req.reset.is_none() {
                req.reset = Some((r, ReplyTo::Key));
            }
        }
        KeyEvent::Turned => tracing::info!("reset key turned"),
        KeyEvent::Stuck { held_ns } => tracing::warn!(
            held_ms = held_ns as f64 * 1e-6,
            "reset key held too long: ignored until released and turned again"
        ),
        KeyEvent::None => {}
    }
}

/// The publishers of a stream: (count, the first four).
fn publishers_of<T: crs_ipc::Topic>(
    sub: &crs_ipc::TopicSubscriber<T>,
) -> (usize, [crs_ipc::PublisherInfo; 4]) {
    let mut buf = [crs_ipc::PublisherInfo::default(); 4];
    let n = sub.publishers(&mut buf);
    (n, buf)
}

/// Applies the owner checks of this cycle: a stream with several or a foreign publisher trips
/// `foreign_publisher` every cycle it lasts (so a reset needs it gone).
fn check_owners(
    owners: &mut [crate::ownership::OwnerWatch; 3],
    seen: [(usize, [crs_ipc::PublisherInfo; 4]); 3],
    procs: &mut impl crate::ownership::ProcessLookup,
    monitor: &mut Monitor,
) {
    use crate::ownership::Ownership;
    for (w, (n, buf)) in owners.iter_mut().zip(seen) {
        let stream = w.stream();
        let (verdict, changed) = w.check(n, &buf[..n.min(4)], procs);
        match verdict {
            Ownership::Ok => {
                if changed && n > 0 {
                    tracing::info!(stream, publisher_pid = ?buf[0].pid, "stream owner verified");
                }
            }
            Ownership::Several(k) => {
                if changed {
                    tracing::error!(
                        stream,
                        publishers = k,
                        "a second publisher on a single-owner stream: e-stop"
                    );
                }
                monitor.on_foreign_publisher(*k as u32);
            }
            Ownership::Foreign(pid, exe) => {
                if changed {
                    tracing::error!(stream, pid, executable = %exe, "a foreign process owns a single-owner stream: e-stop");
                }
                monitor.on_foreign_publisher(1);
            }
        }
    }
}

/// Where the answer to an operator's reset goes besides the monitor's state event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ReplyTo {
    Key,
    Socket,
}

/// The monitor's epoch announcement (see [`MonitorCode::EpochAnnounce`]).
fn epoch_announcement(monitor: &Monitor, seq: u64) -> StateEvent {
    let mut ev = StateEvent::monitor(monitor.state_code(), MonitorCode::EpochAnnounce, seq);
    ev.detail_node = monitor.reset_epoch();
    ev
}

fn estop_event(rec: &TripRecord, seq: u64) -> StateEvent {
    let mut ev = StateEvent::new(ProcessId::SafetyMonitor, EventKind::EStop, seq);
    // The time of the cycle that detected the fault (the stop frames went out right after).
    ev.timestamp_ns = rec.detected_ns;
    ev.state = StateCode::Tripped.into();
    ev.detail = rec.fault.cause.into();
    ev.detail_node = rec.fault.cable.map_or(0, |c| u32::from(c) + 1);
    ev
}

/// The monitor's answer to a reset request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ResetReply {
    Accepted,
    NotTripped,
    Refused(Option<Cause>),
    /// The monitor is still in its start-up state (not every drive verified yet).
    NotReady,
    /// The request did not come from an authorised channel (the peer is not in the operator
    /// group): the monitor's reason.
    Denied(String),
    /// This monitor instance cannot count more resets (restart it).
    Exhausted,
}

/// Operator side (`safety-monitor reset`): asks the monitor through its reset socket
/// ([`crate::reset_socket`]); the kernel passes this process's credentials, which must show
/// membership of the operator group.
pub fn request_reset(
    socket: &std::path::Path,
    timeout: Duration,
) -> Result<ResetReply, DaemonError> {
    let line = crate::reset_socket::request(socket, timeout).map_err(|e| {
        DaemonError::Other(format!(
            "reset socket {}: {e} (is the monitor running with this [reset] socket?)",
            socket.display()
        ))
    })?;
    let (word, rest) = line.split_once(' ').unwrap_or((line.as_str(), ""));
    Ok(match word {
        "accepted" => ResetReply::Accepted,
        "not-tripped" => ResetReply::NotTripped,
        "not-ready" => ResetReply::NotReady,
        "refused" => {
            ResetReply::Refused(Cause::ALL.iter().copied().find(|c| c.name() == rest.trim()))
        }
        "denied" => ResetReply::Denied(rest.trim().to_string()),
        "exhausted" => ResetReply::Exhausted,
        _ => {
            return Err(DaemonError::Other(format!(
                "reset socket {}: unexpected answer {line:?}",
                socket.display()
            )));
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_events_are_recognised_and_others_are_not() {
        let mut own = OwnEvents::default();
        let mut mine = StateEvent::new(ProcessId::SafetyMonitor, EventKind::Reset, 7);
        mine.detail = 42;
        own.record(&mine);
        assert!(own.contains(&mine));
        let mut forged = mine;
        forged.detail = 43;
        assert!(!own.contains(&forged));
        forged = mine;
        forged.sequence = 8;
        assert!(!own.contains(&forged));
        // The ring keeps the last 32.
        for k in 100..132 {
            own.record(&StateEvent::new(
                ProcessId::SafetyMonitor,
                EventKind::EStop,
                k,
            ));
        }
        assert!(!own.contains(&mine));
    }

    /// The monitor's own frames of the longest reader stall the configuration allows are
    /// still recognised when the stalled reader delivers them (the impersonation check must not
    /// trip on the monitor's own echo); older ones are not remembered.
    #[test]
    fn own_frames_of_the_longest_reader_stall_are_recognised() {
        use crate::capacity::{MAX_READER_STALL_CYCLES, OWN_FRAMES_PER_CYCLE};
        let frame = |k: u32| {
            let [a, b, c, d] = k.to_le_bytes();
            can_transport::CanFrame::new(0x101, &[a, b, c, d, 0, 0, 0, 0]).expect("frame")
        };
        let mut sent = SentOwn::default();
        let frames = OWN_FRAMES_PER_CYCLE as u32 * (MAX_READER_STALL_CYCLES + 1);
        for k in 0..frames {
            sent.record(&frame(k));
        }
        let first = frame(0);
        let mut d = [0u8; 8];
        d.copy_from_slice(first.data());
        assert!(
            sent.contains(0x101, &d, 8),
            "the first frame of a {MAX_READER_STALL_CYCLES}-cycle stall is forgotten"
        );
        sent.record(&frame(frames));
        assert!(!sent.contains(0x101, &d, 8));
    }

    #[test]
    fn events_from_the_future_or_too_old_are_not_fresh() {
        let now = 100_000_000_000;
        assert!(is_fresh(now, now));
        assert!(is_fresh(now, now - RESET_REQUEST_MAX_AGE_NS));
        assert!(!is_fresh(now, now - RESET_REQUEST_MAX_AGE_NS - 1));
        assert!(is_fresh(now, now + EVENT_FUTURE_TOLERANCE_NS));
        // Before: saturating_sub made any future timestamp fresh.
        assert!(!is_fresh(now, now + EVENT_FUTURE_TOLERANCE_NS + 1));
        assert!(!is_fresh(now, u64::MAX));
    }
}
