//! `motion-core`: the 1 ms hard-loop daemon (spec sec. 5.6). See `motion_core::daemon`.

use cdpr_model::config::{Platform, load_platform};
use clap::{CommandFactory, Parser};
use crs_ipc::{
    CueingPose, EventKind, Heartbeat, IpcNode, JointSetpoint, LoopStatsSample, PlatformId,
    PlatformIdentity, ProcessId, StateEvent, SyncSchedule, TopicPublisher, TopicSubscriber,
    WakeupNotifier,
};
use motion_core::daemon::config::DaemonConfig;
use motion_core::daemon::cueing::{CueingFilter, CueingLimits, CueingSource};
use motion_core::daemon::outbox::{Outbox, OutboxSink, StagePorts};
use motion_core::daemon::ride::{RideControl, RidePhase, RideSlot};
use motion_core::daemon::ride_socket;
use motion_core::daemon::stats::LoopStats;
use motion_core::daemon::timeline::Timeline;
use motion_core::daemon::trajectory::{self, Waypoint};
use motion_core::daemon::{
    self, Command, CommandSource, HardLoop, LoopState, ResetGate, ResetIgnored, config, lifecycle,
    outbox, realtime,
};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::time::Duration;

#[derive(Parser, Debug)]
#[command(
    name = "motion-core",
    about = "CRS 1 ms motion loop: IK + surrogate offset → joint setpoints (iceoryx2)"
)]
struct Args {
    /// Daemon TOML (`config/…` is looked up by the stack's rule: $CRS_CONFIG_DIR, ./config,
    /// else /etc/crs/config).
    #[arg(long, default_value = "config/motion-core.toml", value_parser = crs_service::paths::parse_config)]
    config: PathBuf,
    /// Waypoint CSV to run (overrides [trajectory].waypoints).
    #[arg(long)]
    waypoints: Option<PathBuf>,
    /// Exit once the plan has been run and this many seconds of hold have passed (with
    /// `--input cueing`: this many seconds after the last cueing target, once one arrived;
    /// with `--control`: after the first ride an operator started has ended).
    #[arg(long)]
    exit_after_plan_s: Option<f64>,
    /// Reference input: `waypoints` (ruckig plan of the waypoint CSV) or `cueing` (follow the
    /// `crs/v1/cueing_pose` stream through the velocity/acceleration-limited tracker).
    #[arg(long, default_value = "waypoints", value_parser = ["waypoints", "cueing"])]
    input: String,
    /// Take rides from an operator on this Unix socket (`crs ride start FILE | abort | home |
    /// status`): the loop comes up idle, holding the home pose, and ignores the daemon TOML's
    /// [trajectory].waypoints; only an explicit --waypoints runs at start. The installed unit
    /// uses /run/crs/motion-core/control.sock.
    #[arg(long, value_name = "PATH")]
    control: Option<PathBuf>,
}

/// The newest motion-cueing target since the last cycle (drains the subscriber; no allocation).
struct IoxCueing(TopicSubscriber<CueingPose>);
impl CueingSource for IoxCueing {
    #[inline]
    fn latest(&mut self) -> Option<[f64; 6]> {
        let mut newest = None;
        while let Ok(Some(c)) = self.0.receive() {
            newest = Some(c.pose);
        }
        newest
    }
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::Relaxed);
}

/// The publish stage's iceoryx2 ports (see `daemon::outbox`).
struct IoxPorts {
    setpoints: TopicPublisher<JointSetpoint>,
    heartbeats: TopicPublisher<Heartbeat>,
    events: TopicPublisher<StateEvent>,
    identity: TopicPublisher<PlatformIdentity>,
    loop_stats: TopicPublisher<LoopStatsSample>,
    /// drive-io's SYNC schedule (isochronous bus): the loop ticks `sync_lead_ns` before a SYNC.
    sync_schedule: TopicSubscriber<SyncSchedule>,
    sync_lead_ns: u64,
    last_schedule: u64,
    /// "setpoint published" (drive-io's phase-locked cycle follows it).
    setpoint_ready: WakeupNotifier,
    notify_failures: u64,
    platform_identity: PlatformIdentity,
    /// Sequence number of the plan's last setpoint (`MotionState::Plan`): the
    /// safety monitor accepts the end-of-stream announcement only after it.
    plan_end: u64,
    /// With `--control`: the current ride's end, which replaces `plan_end`.
    rides: Option<Arc<RideSlot>>,
    hb_seq: u64,
    _node: IpcNode,
}

impl IoxPorts {
    fn announce_plan(&mut self) {
        self.hb_seq += 1;
        let end = self.rides.as_ref().map_or(self.plan_end, |r| r.plan_end());
        let _ = self.events.publish(&StateEvent::plan(end, self.hb_seq));
    }
}
impl StagePorts for IoxPorts {
    fn setpoint(&mut self, sp: &JointSetpoint) -> bool {
        self.setpoints.publish(sp).is_ok()
    }
    fn heartbeat(&mut self, state: crs_ipc::MotionState, overruns: u64) {
        self.hb_seq += 1;
        let mut hb = Heartbeat::motion(state, self.hb_seq);
        hb.overruns = overruns.min(u32::MAX as u64) as u32;
        let _ = self.heartbeats.publish(&hb);
    }
    fn loop_stats(&mut self, stats: &LoopStats, outbox: &Outbox) {
        let lat = stats.lateness.snapshot();
        let cmp = stats.compute.snapshot();
        let s = LoopStatsSample {
            state: outbox.state.load(Ordering::Relaxed).into(),
            timestamp_ns: realtime::monotonic_ns(),
            cycles: stats.cycles.load(Ordering::Relaxed),
            overruns: stats.overruns.load(Ordering::Relaxed),
            rejected: stats.rejected.load(Ordering::Relaxed),
            dropped: outbox.dropped.load(Ordering::Relaxed),
            lateness_p50_ns: lat.quantile_ns(0.5),
            lateness_p99_ns: lat.quantile_ns(0.99),
            lateness_p999_ns: lat.quantile_ns(0.999),
            lateness_max_ns: lat.max_ns,
            compute_p50_ns: cmp.quantile_ns(0.5),
            compute_p99_ns: cmp.quantile_ns(0.99),
            compute_max_ns: cmp.max_ns,
            ..LoopStatsSample::default()
        };
        let _ = self.loop_stats.publish(&s);
    }
    fn announce(&mut self) {
        // iceoryx2's history reaches a late subscriber only on the publisher's next activity,
        // so the identity is re-sent about once per second for a monitor (re)started later.
        let mut id = self.platform_identity;
        id.timestamp_ns = crs_ipc::monotonic_ns();
        let _ = self.identity.publish(&id);
        self.announce_plan();
    }
    fn sync_schedule(&mut self, timeline: &Timeline) {
        if self.sync_lead_ns == 0 {
            return;
        }
        match self.sync_schedule.latest() {
            Ok(Some(s)) if s.sequence != self.last_schedule => {
                self.last_schedule = s.sequence;
                let lead = i64::try_from(self.sync_lead_ns).unwrap_or(i64::MAX);
                match s.phase_ns(-lead) {
                    Some(phase) if timeline.set_phase(phase, s.period_ns) => {
                        tracing::info!(
                            phase_us = phase / 1000,
                            lead_us = self.sync_lead_ns / 1000,
                            "loop ticks placed before drive-io's SYNC"
                        );
                    }
                    _ => tracing::warn!(
                        period_ns = s.period_ns,
                        loop_period_ns = timeline.period_ns(),
                        "drive-io's SYNC period differs from the loop's: not aligned"
                    ),
                }
            }
            Ok(_) => {}
            Err(e) => tracing::warn!(error = %e, "SYNC schedule ignored"),
        }
    }
    fn setpoints_sent(&mut self) {
        if let Err(e) = self.setpoint_ready.notify() {
            // drive-io falls back to its own clock `setpoint_wait_us` late: log, go on.
            self.notify_failures += 1;
            if self.notify_failures.is_power_of_two() {
                tracing::warn!(error = %e, failures = self.notify_failures, "setpoint notification failed");
            }
        }
    }
    fn stream_end(&mut self) {
        self.hb_seq += 1;
        let ev = StateEvent::motion(crs_ipc::MotionState::Stopping, self.hb_seq);
        let _ = self.events.publish(&ev);
    }
    fn state_changed(&mut self, _from: crs_ipc::MotionState, to: crs_ipc::MotionState) {
        let kind = if to.is_latched() {
            EventKind::Fault
        } else {
            EventKind::StateChanged
        };
        let mut ev = StateEvent::new(ProcessId::MotionCore, kind, self.hb_seq);
        ev.state = to.into();
        let _ = self.events.publish(&ev);
    }
}

/// Reset events the gate ignored (forged source, epoch not newer), and the source of the last
/// one: counted in the 1 ms loop (no allocation, no logging there), logged by the reporter
/// thread at most once per tick.
static IGNORED_RESETS: AtomicU64 = AtomicU64::new(0);
static IGNORED_RESET_SOURCE: AtomicU32 = AtomicU32::new(0);

/// E-stop events from any process (anyone may stop); resets only through the [`ResetGate`]
/// (the current safety monitor's fresh reset of the epoch it announced).
struct IoxCommands(TopicSubscriber<StateEvent>, ResetGate);
impl CommandSource for IoxCommands {
    #[inline]
    fn poll(&mut self) -> Option<Command> {
        // A sample of a foreign contract version is skipped without ending the drain (a flood
        // of them cannot hold an e-stop back by a cycle per sample); bounded by the buffer.
        for _ in 0..4 * <StateEvent as crs_ipc::Topic>::SUBSCRIBER_BUFFER {
            match self.0.receive() {
                Err(crs_ipc::IpcError::Version { .. }) => continue,
                Ok(Some(ev)) if ev.kind == EventKind::EStop as u32 => return Some(Command::EStop),
                Ok(Some(ev)) => match self.1.check(&ev, crs_ipc::monotonic_ns()) {
                    Ok(r) => return Some(Command::Reset(r)),
                    Err(ResetIgnored::NotAReset) => continue,
                    Err(_) => {
                        IGNORED_RESETS.fetch_add(1, Ordering::Relaxed);
                        IGNORED_RESET_SOURCE.store(ev.source, Ordering::Relaxed);
                        continue;
                    }
                },
                _ => return None,
            }
        }
        None
    }
}

/// sd_notify(3) without libsystemd: one datagram to $NOTIFY_SOCKET, which systemd may give as
/// a filesystem path or as an abstract socket name starting with '@'.
fn sd_notify(msg: &str) {
    use std::os::linux::net::SocketAddrExt;
    let Ok(path) = std::env::var("NOTIFY_SOCKET") else {
        return;
    };
    let Ok(sock) = std::os::unix::net::UnixDatagram::unbound() else {
        return;
    };
    let addr = match path.strip_prefix('@') {
        Some(name) => std::os::unix::net::SocketAddr::from_abstract_name(name.as_bytes()),
        None => std::os::unix::net::SocketAddr::from_pathname(&path),
    };
    if let Ok(addr) = addr {
        let _ = sock.send_to_addr(msg.as_bytes(), &addr);
    }
}

fn main() -> ExitCode {
    if let Some(code) = crs_service::gen_man_if_asked("motion-core", Args::command) {
        return code;
    }
    crs_log::init("motion-core");
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e}");
            eprintln!("motion-core: {e}");
            ExitCode::FAILURE
        }
    }
}

/// What `configure` read and checked before anything runs.
struct Setup {
    cfg: DaemonConfig,
    platform: Platform,
    configured: lifecycle::Configured,
    cueing: bool,
    /// The operator's ride control socket (`--control`).
    control: Option<PathBuf>,
    waypoint_file: Option<PathBuf>,
    waypoints: Vec<Waypoint>,
    /// The plan's last setpoint's sequence number (crs_ipc::PLAN_OPEN_END for cueing).
    plan_end: u64,
}

/// The threads and shared state of a running daemon.
struct Running {
    outbox: Arc<Outbox>,
    stats: Arc<LoopStats>,
    timeline: Arc<Timeline>,
    rides: Option<Arc<RideSlot>>,
    stage: std::thread::JoinHandle<()>,
    reporter: std::thread::JoinHandle<()>,
    node: IpcNode,
    /// The operators' and the monitor's events (subscribed before the real-time settings).
    commands: Option<TopicSubscriber<StateEvent>>,
    start_ns: u64,
}

type PlanError = Arc<std::sync::Mutex<Option<trajectory::PlanningFailed>>>;

fn run(args: Args) -> Result<(), String> {
    let setup = configure(&args)?;
    let mut running = start_threads(&setup)?;
    let plan_error: PlanError = Arc::new(std::sync::Mutex::new(None));
    let mut hard_loop = activate(setup, &running, &plan_error)?;
    run_loop(&args, &mut running, &mut hard_loop);
    deactivate(running, hard_loop, &plan_error)
}

/// Configure: the daemon TOML, the platform, the surrogate, the waypoints; the whole plan
/// verified with the loop's own checks before anything moves (a plan that would leave the
/// workspace or the wrench-feasible set is refused, naming where).
fn configure(args: &Args) -> Result<Setup, String> {
    let cfg = config::load(&args.config).map_err(|e| e.to_string())?;
    let platform = load_platform(&cfg.platform).map_err(|e| e.to_string())?;
    // The identity the safety monitor compares: model, workspace box, limits.
    let identity = platform.identity_hex();
    tracing::info!(platform = %platform.name, identity = %identity, cables = platform.model.m(), "platform loaded");
    let configured = lifecycle::configure(&cfg, &platform).map_err(|e| e.to_string())?;
    log_configuration(&configured);
    let cueing = args.input == "cueing";
    if cueing && args.control.is_some() {
        return Err("--control takes waypoint rides: not with --input cueing".into());
    }
    let waypoint_file = if cueing {
        None
    } else if args.control.is_some() {
        // Rides are started on purpose: the configured demo never runs on its own.
        args.waypoints.clone()
    } else {
        args.waypoints.clone().or(cfg.trajectory.waypoints.clone())
    };
    let waypoints: Vec<Waypoint> = match &waypoint_file {
        Some(p) => trajectory::read_waypoints(p).map_err(|e| e.to_string())?,
        None => Vec::new(),
    };
    let plan = match &waypoint_file {
        Some(p) => {
            let ride = trajectory::read_ride(p).map_err(|e| e.to_string())?;
            configured.verify_ride(&ride).map_err(|e| e.to_string())?
        }
        None => configured
            .verify_plan(&waypoints)
            .map_err(|e| e.to_string())?,
    };
    tracing::info!(
        samples = plan.samples,
        duration_s = plan.duration_s,
        "plan verified (workspace, limits, eq. 3.29)"
    );
    // Sequence numbers count published setpoints from 1, one per cycle, so the plan's last
    // reference goes out as number `samples` (later if the planner starved the loop). The
    // cueing input has no planned end.
    let plan_end = if cueing {
        crs_ipc::PLAN_OPEN_END
    } else {
        plan.samples as u64
    };
    Ok(Setup {
        cfg,
        platform,
        configured,
        cueing,
        control: args.control.clone(),
        waypoint_file,
        waypoints,
        plan_end,
    })
}

/// The surrogate and the wrench check in force, in the log.
fn log_configuration(configured: &lifecycle::Configured) {
    match configured.surrogate() {
        None => tracing::info!(
            "no surrogate configured: zero offset, pure standard kinematics (eq. 2.3)"
        ),
        Some(s) => tracing::info!(
            path = %s.path.display(),
            bound_mm = s.certified_bound_mm,
            "surrogate loaded (eq. 5.26)"
        ),
    }
    let lim = configured.planner_limits();
    match configured.dynamic_limits() {
        Some(d) => tracing::info!(
            acceleration_factor = d.acceleration_factor,
            linear_acceleration = lim.linear_acceleration,
            angular_acceleration_deg = lim.angular_acceleration.to_degrees(),
            "dynamic wrench w = w_e + w_in checked every cycle (eq. 5.13-5.16); planner accelerations scaled to what stays feasible (bound at cable {} at [{:.2}, {:.2}, {:.2}] m)",
            d.cable + 1,
            d.bound_at.r.x,
            d.bound_at.r.y,
            d.bound_at.r.z
        ),
        None => tracing::info!(
            "static wrench w_e checked (no [dynamics] in the platform TOML, or dynamic_wrench = false)"
        ),
    }
}

/// Starts the publish stage and the reporter, the signal handlers, then the loop thread's
/// real-time settings (last, so start-up allocations happen before mlockall/SCHED_FIFO and
/// only the loop gets its priority).
fn start_threads(setup: &Setup) -> Result<Running, String> {
    let cfg = &setup.cfg;
    let rides = setup
        .control
        .as_ref()
        .map(|_| Arc::new(RideSlot::new(setup.platform.home, setup.plan_end)));
    let start_ns = realtime::monotonic_ns() + 50_000_000;
    let timeline = Arc::new(Timeline::new(cfg.realtime.period_ns));
    let outbox = Arc::new(Outbox::new(64));
    if rides.is_some() && setup.waypoint_file.is_none() {
        // Comes up idle: the first heartbeat says so, and no RUNNING -> HOLDING change is
        // announced for a loop that never ran.
        outbox
            .state
            .store(crs_ipc::MotionState::Holding, Ordering::Relaxed);
    }
    let stats = Arc::new(LoopStats::default());
    let stage = spawn_publish_stage(setup, &outbox, &stats, &timeline, &rides, start_ns)?;
    let node = IpcNode::new("motion-core").map_err(|e| e.to_string())?;
    let commands = node.subscriber::<StateEvent>().map_err(|e| e.to_string())?;
    // SAFETY: installing an async-signal-safe handler that only stores to an atomic.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
    let reporter = {
        let (stats, outbox) = (stats.clone(), outbox.clone());
        let interval = cfg.stats_interval_s;
        let file = cfg.stats_file.clone();
        std::thread::Builder::new()
            .name("crs-stats".into())
            .spawn(move || report_loop(&stats, &outbox, interval, file.as_deref()))
            .map_err(|e| e.to_string())?
    };
    let report = realtime::apply(&cfg.realtime);
    for (name, applied) in report.lines() {
        match applied {
            realtime::Applied::Degraded(_) => tracing::warn!("realtime {name}: {applied}"),
            _ => tracing::info!("realtime {name}: {applied}"),
        }
    }
    Ok(Running {
        outbox,
        stats,
        timeline,
        rides,
        stage,
        reporter,
        node,
        commands: Some(commands),
        start_ns,
    })
}

/// The publish stage owns the iceoryx2 publishers (iceoryx2's `ipc::Service` ports are not
/// `Send`, and publishing allocates: see `daemon::outbox`). It is spawned before the real-time
/// settings so it does not inherit the loop's priority; it sets its own below it. Returns once
/// its ports are open (or with the reason they are not).
fn spawn_publish_stage(
    setup: &Setup,
    outbox: &Arc<Outbox>,
    stats: &Arc<LoopStats>,
    timeline: &Arc<Timeline>,
    rides: &Option<Arc<RideSlot>>,
    start_ns: u64,
) -> Result<std::thread::JoinHandle<()>, String> {
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), String>>();
    let (outbox, stats, timeline, rides) = (
        outbox.clone(),
        stats.clone(),
        timeline.clone(),
        rides.clone(),
    );
    let identity = PlatformIdentity::new(
        PlatformId::new(setup.platform.identity()),
        setup.platform.model.m() as u32,
    );
    let period_ns = setup.cfg.realtime.period_ns;
    let sync_lead_ns = setup.cfg.sync_lead_ns;
    let plan_end = setup.plan_end;
    let mut rt = setup.cfg.realtime;
    rt.priority = (rt.priority - 1).max(0);
    rt.lock_memory = false;
    let stage = std::thread::Builder::new()
        .name("crs-publish".into())
        .spawn(move || {
            let ports = open_ports(identity, sync_lead_ns, plan_end, rides);
            let mut ports = match ports {
                Ok(p) => {
                    let _ = ready_tx.send(Ok(()));
                    p
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                    return;
                }
            };
            for (name, applied) in realtime::apply(&rt).lines() {
                if let realtime::Applied::Degraded(_) = applied {
                    tracing::warn!("publish stage realtime {name}: {applied}");
                }
            }
            outbox::run_publish_stage(
                &outbox,
                &stats,
                &mut ports,
                start_ns,
                &timeline,
                outbox::PUBLISH_PHASE_NS.min(period_ns / 2),
                10,
                &STOP,
            );
        })
        .map_err(|e| e.to_string())?;
    ready_rx
        .recv()
        .map_err(|_| "publish stage died during start-up".to_string())??;
    Ok(stage)
}

/// The publish stage's iceoryx2 ports; the platform identity published and the plan announced.
fn open_ports(
    identity: PlatformIdentity,
    sync_lead_ns: u64,
    plan_end: u64,
    rides: Option<Arc<RideSlot>>,
) -> Result<IoxPorts, String> {
    let node = IpcNode::new("motion-core-publish").map_err(|e| e.to_string())?;
    let ports = IoxPorts {
        setpoints: node
            .publisher::<JointSetpoint>()
            .map_err(|e| e.to_string())?,
        heartbeats: node.publisher::<Heartbeat>().map_err(|e| e.to_string())?,
        events: node.publisher::<StateEvent>().map_err(|e| e.to_string())?,
        identity: node
            .publisher::<PlatformIdentity>()
            .map_err(|e| e.to_string())?,
        loop_stats: node
            .publisher::<LoopStatsSample>()
            .map_err(|e| e.to_string())?,
        sync_schedule: node
            .subscriber::<SyncSchedule>()
            .map_err(|e| e.to_string())?,
        sync_lead_ns,
        last_schedule: 0,
        setpoint_ready: node.setpoint_ready_notifier().map_err(|e| e.to_string())?,
        notify_failures: 0,
        platform_identity: identity,
        plan_end,
        rides,
        hb_seq: 0,
        _node: node,
    };
    ports
        .identity
        .publish(&identity)
        .map_err(|e| e.to_string())?;
    let mut ports = ports;
    ports.announce_plan();
    Ok(ports)
}

/// Activate: the hard loop with its inputs (the cueing stream, the operator's rides).
fn activate(setup: Setup, running: &Running, plan_error: &PlanError) -> Result<HardLoop, String> {
    let (cfg, platform) = (&setup.cfg, &setup.platform);
    let lim = setup.configured.planner_limits();
    let period_s = setup.configured.period_s();
    tracing::info!(
        period_us = cfg.realtime.period_ns / 1000,
        "hard loop starting"
    );
    sd_notify("READY=1\nSTATUS=motion loop running");
    let pe = plan_error.clone();
    let on_plan_error = move |e: trajectory::PlanningFailed| {
        tracing::error!("planner: {e}");
        *pe.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
    };
    let mut hard_loop = setup.configured.activate(setup.waypoints, on_plan_error);
    if setup.cueing {
        let limits = CueingLimits {
            linear_velocity: lim.linear_velocity,
            linear_acceleration: lim.linear_acceleration,
            angular_velocity: lim.angular_velocity,
            angular_acceleration: lim.angular_acceleration,
        };
        let filter = CueingFilter::new(&platform.home, limits, period_s);
        let sub = running
            .node
            .subscriber::<CueingPose>()
            .map_err(|e| e.to_string())?;
        hard_loop = hard_loop.with_cueing(filter, Box::new(IoxCueing(sub)));
        tracing::info!("reference input: motion-cueing stream (crs/v1/cueing_pose)");
    }
    if let (Some(path), Some(slot)) = (&setup.control, &running.rides) {
        hard_loop = hard_loop.with_rides(slot.clone(), lim, period_s, platform.home);
        serve_rides(path, slot.clone(), cfg, platform)?;
    }
    Ok(hard_loop)
}

/// The operator's ride control socket, served by its own thread.
fn serve_rides(
    path: &std::path::Path,
    slot: Arc<RideSlot>,
    cfg: &DaemonConfig,
    platform: &Platform,
) -> Result<(), String> {
    let control =
        RideControl::new(lifecycle::configure_checks(cfg, platform).map_err(|e| e.to_string())?);
    let listener = ride_socket::bind(path)
        .map_err(|e| format!("{}: cannot bind the control socket: {e}", path.display()))?;
    std::thread::Builder::new()
        .name("crs-ride-control".into())
        .spawn(move || {
            for conn in listener.incoming() {
                let Ok(conn) = conn else { continue };
                let on_error = |e: trajectory::PlanningFailed| {
                    tracing::error!("ride planner: {e}; the loop holds where the plan ended")
                };
                match ride_socket::serve_one(conn, &control, &slot, on_error) {
                    Ok(reply) => tracing::info!("operator: {reply}"),
                    Err(e) => tracing::warn!("control socket: {e}"),
                }
            }
        })
        .map_err(|e| e.to_string())?;
    tracing::info!(
        socket = %path.display(),
        "idle, holding the home pose: rides start with `crs ride start FILE`"
    );
    Ok(())
}

/// Run: the 1 ms loop until a signal, or `--exit-after-plan-s` after the plan, ride or cueing
/// stream ended.
fn run_loop(args: &Args, running: &mut Running, hard_loop: &mut HardLoop) {
    let Some(commands) = running.commands.take() else {
        return;
    };
    let (outbox, rides) = (&running.outbox, &running.rides);
    let mut sink = OutboxSink(outbox);
    let mut cmds = IoxCommands(commands, ResetGate::new());
    let mut plan_done_at: Option<u64> = None;
    let exit_after = args.exit_after_plan_s.map(|s| (s * 1e9) as u64);
    daemon::run_timed(
        hard_loop,
        running.start_ns,
        &running.timeline,
        &mut sink,
        &mut cmds,
        &running.stats,
        &STOP,
        |hl, now| {
            // The publish stage's heartbeats and the reporter both read the loop state here.
            outbox.state.store(hl.state_code(), Ordering::Relaxed);
            if let Some(after) = exit_after {
                let latched = hl.state().is_latched();
                // With --control the loop idles until an operator starts a ride: its plan is
                // done once a ride was started (by the loop, this very thread) and ended.
                let ride_done = rides
                    .as_ref()
                    .is_none_or(|r| r.rides_started() > 0 && r.phase() == RidePhase::Idle);
                if plan_done_at.is_none()
                    && (latched || (!hl.is_cueing() && hl.plan_finished() && ride_done))
                {
                    plan_done_at = Some(now);
                }
                // A finite cueing stream is done when its source falls silent: the hold
                // counts from its last target.
                let from = plan_done_at.or(hl.cueing_last_ns().filter(|_| hl.is_cueing()));
                if from.is_some_and(|t0| now > t0 + after) {
                    STOP.store(true, Ordering::Relaxed);
                }
            }
        },
    );
}

/// Deactivate: the threads stopped, the loop's figures logged, a planning failure returned.
fn deactivate(running: Running, hard_loop: HardLoop, plan_error: &PlanError) -> Result<(), String> {
    STOP.store(true, Ordering::Relaxed);
    let _ = running.stage.join();
    let _ = running.reporter.join();
    let stats = &running.stats;
    tracing::info!(
        "loop stopped: {} cycles, {} overruns, {} rejected references; lateness {}; compute {}",
        stats.cycles.load(Ordering::Relaxed),
        stats.overruns.load(Ordering::Relaxed),
        stats.rejected.load(Ordering::Relaxed),
        stats.lateness.snapshot().summary(),
        stats.compute.snapshot().summary()
    );
    let (final_state, _) = hard_loop.deactivate();
    if let LoopState::Refused(r) = final_state {
        tracing::warn!("the loop holds after refusing a reference: {r}");
    }
    if let Some(e) = plan_error.lock().unwrap_or_else(|p| p.into_inner()).take() {
        return Err(format!("trajectory planning failed: {e}"));
    }
    Ok(())
}

fn report_loop(
    stats: &LoopStats,
    outbox: &Outbox,
    interval_s: f64,
    file: Option<&std::path::Path>,
) {
    let tick = Duration::from_millis(100);
    let mut last_cycles = 0;
    let mut ignored_logged = 0u64;
    let mut since = Duration::ZERO;
    while !STOP.load(Ordering::Relaxed) {
        std::thread::sleep(tick);
        since += tick;
        let ignored = IGNORED_RESETS.load(Ordering::Relaxed);
        if ignored != ignored_logged {
            ignored_logged = ignored;
            tracing::warn!(
                ignored,
                last_source = IGNORED_RESET_SOURCE.load(Ordering::Relaxed),
                "reset event(s) IGNORED: only the safety monitor's reset with a newer epoch \
                 releases the loop"
            );
        }
        let cycles = stats.cycles.load(Ordering::Relaxed);
        // Watchdog only while the loop makes progress: a frozen loop lets systemd kill us.
        if cycles > last_cycles {
            sd_notify("WATCHDOG=1");
        }
        last_cycles = cycles;
        if interval_s > 0.0 && since.as_secs_f64() >= interval_s {
            since = Duration::ZERO;
            let lat = stats.lateness.snapshot();
            let cmp = stats.compute.snapshot();
            tracing::info!(
                state = u32::from(outbox.state.load(Ordering::Relaxed)),
                overruns = stats.overruns.load(Ordering::Relaxed),
                "cycles {cycles}; lateness {}; compute {}",
                lat.summary(),
                cmp.summary()
            );
            if let Some(path) = file {
                let json = serde_json::json!({
                    "cycles": cycles,
                    "overruns": stats.overruns.load(Ordering::Relaxed),
                    "rejected": stats.rejected.load(Ordering::Relaxed),
                    "outbox_dropped": outbox.dropped.load(Ordering::Relaxed),
                    "publish_failures": outbox.publish_failures.load(Ordering::Relaxed),
                    "state": u32::from(outbox.state.load(Ordering::Relaxed)),
                    "lateness_ns": {"p50": lat.quantile_ns(0.5), "p99": lat.quantile_ns(0.99), "p999": lat.quantile_ns(0.999), "max": lat.max_ns},
                    "compute_ns": {"p50": cmp.quantile_ns(0.5), "p99": cmp.quantile_ns(0.99), "p999": cmp.quantile_ns(0.999), "max": cmp.max_ns},
                });
                let tmp = path.with_extension("tmp");
                if std::fs::write(&tmp, json.to_string()).is_ok() {
                    let _ = std::fs::rename(&tmp, path);
                }
            }
        }
    }
}
