//! One run of the whole simulated stack as separate processes (`crs sim`, the closed
//! calibration loop), as a user runs it.
//!
//! sim-plant (the winches + platform physics on the bus), safety-monitor (when built),
//! drive-io (CiA 402 master) and motion-core (the 1 ms loop) start in that order on one
//! platform's set of configs ([`crate::platforms`]: the icosahedron or the helicopter cabin),
//! over vcan0 when the kernel has it and over the CAN-over-UDP loopback bus otherwise (the
//! launcher says which). motion-core runs the demo trajectory; the
//! launcher listens on iceoryx2 (its own service prefix per run) and prints the tracked-pose
//! error against the reference, the cable forces against the limits, the loop statistics and the
//! monitor state. Ctrl-C stops all children cleanly; a child that dies stops the rest.
//!
//! Commissioning: sim-plant homes the drives to the controller's full command at the home pose,
//! q_θ(home) = φ(home) + φ_sg(home) (eq. 5.26), computed here from the daemon TOML with
//! motion-core's own cycle computation (`--home-lengths-m`, see `sim_plant::bus`), so a
//! surrogate's offset at home does not make the first setpoint jump.
//!
//! Recording (`--record FILE`, [`crate::rest_recording`]): with `--dwell-s` the waypoints are
//! timed so the platform rests that long at each; every rest point (reference constant for at
//! least `--settle-s`) gives one `crs-dataset 1` sample — commanded lengths, tracker pose,
//! force sensors, reference — and the summary reports the measured pose error at the rest points.

use crate::campaign::{timed_waypoints, write_waypoints};
use crate::cueing_run::CueingRun;
use crate::rest_recording::{RestErrors, RestRecorder, rest_errors, to_dataset};
use crate::ride_run::PreparedRide;
use cdpr_model::Pose;
use cdpr_model::config::Platform;
use cdpr_model::config::load_platform;
use crs_ipc::{
    DriveFeedback, Heartbeat, IpcNode, JointSetpoint, LoopStatsSample, PlantTruth, ProcessId,
    StateEvent, TopicSubscriber, TrackerPose,
};
use crs_supervisor::supervisor::{self, Supervisor};
use crs_supervisor::transport;
use drive_commissioning::budget::InterfaceBudget;
use drives_config::DrivesConfig;
use motion_core::daemon::config::DaemonConfig;
use motion_core::daemon::lifecycle;
use motion_core::daemon::trajectory::{self};
use ride_physics::HoverModel;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// One run of the stack (the options of `crs sim`; paths as given).
#[derive(Clone, Debug)]
pub struct SimOptions {
    /// motion-core daemon TOML (platform, surrogate, realtime, trajectory).
    pub config: PathBuf,
    /// Drive bus TOML.
    pub drives: PathBuf,
    /// Plant TOML (must be the platform of the daemon TOML).
    pub plant: PathBuf,
    /// `wire` / `auto` (the wire model: a can-wire hub, a bus per interface), `vcan` (the same
    /// over vcan ports, the QEMU guest), `udpbus` (no bus physics), or transports such as
    /// `socketcan:vcan0` / `udpbus:239.255.70.9:20900`.
    pub transport: String,
    /// Waypoint CSV for the demo trajectory (default: the daemon TOML's).
    pub waypoints: Option<PathBuf>,
    /// Seconds to hold after the trajectory before stopping (static error is taken here).
    pub hold_s: f64,
    /// Give up after this many seconds.
    pub timeout_s: f64,
    /// Directory with the stack's binaries (default: next to this `crs`).
    pub bin_dir: Option<PathBuf>,
    /// Directory for the children's logs and the JSON summary.
    pub out: PathBuf,
    /// Run without the safety monitor even if it is built.
    pub no_monitor: bool,
    /// Fail (exit 1) unless the run meets the expectations: trajectory completed, no e-stop,
    /// every plant step converged, forces within [f_min, f_max], static error below
    /// --max-static-error-mm. For tests and CI.
    pub check: bool,
    /// Static (at rest) position error bound for --check, mm.
    pub max_static_error_mm: f64,
    /// Safety-monitor TOML (its [monitor] platform must be the daemon's platform).
    pub monitor_config: PathBuf,
    /// Rest this long at every waypoint (s): the waypoint times are recomputed with the
    /// daemon's planner limits (written to <out>/waypoints-timed.csv). Default: the CSV's times.
    pub dwell_s: Option<f64>,
    /// Write the rest points of the run as a crs-dataset 1 CSV (docs/data-format.md):
    /// commanded lengths, tracker pose, force sensors, reference pose.
    pub record: Option<PathBuf>,
    /// A rest point needs the reference constant for at least this long (s); its sample is the
    /// last tracker / force reading before the reference moves again.
    pub settle_s: f64,
    /// Record the MEAN of the force readings in each rest point's settled window instead of
    /// the last one (commissioning: a payload's COG height comes from the small torque a 2°
    /// tilt adds, which a single 10 N-noise reading per cable cannot resolve; calibration keeps
    /// the last reading, the sample its noise model and figures were made with).
    pub record_mean_forces: bool,
    /// Campaign name for the recording's metadata (default: the waypoint file's name).
    pub campaign: Option<String>,
    /// Run drive-io's SYNC loop (this priority) and sim-plant's loop (5 below) as SCHED_FIFO
    /// with mlockall, as motion-core and the monitor run theirs: keeps the setpoint stream and
    /// the SYNCs going on a loaded host (needs root; ignored with a note otherwise).
    pub rt_priority: Option<i32>,
    /// Fly the helicopter hover physics as the motion source instead of the waypoint plan
    /// ([`crate::ride_run`]; motion-core follows it on its cueing input).
    pub ride: Option<crate::ride_run::RideSpec>,
    /// Drive a vehicle's motion through the motion cueing instead of the waypoint plan
    /// ([`crate::cueing_run`]; motion-core follows it on its cueing input).
    pub cueing: Option<crate::cueing_run::CueingSpec>,
    /// motion-core comes up idle and holding with its control socket (`<out>/control.sock`)
    /// and runs the ride only when an operator starts it (the console's START RIDE button, or
    /// `crs ride start` on that socket), instead of at launch.
    pub operator_start: bool,
}

/// Default at-rest position error bound of `crs sim --check`, mm: twice the largest seen on the
/// shipped plants (relaxed debug runs on this host, 2026-11-26: 4.86 / 4.94 mm where the hover
/// flight of `--source helicopter --pilot config/pilot-demo.csv` ends, at a wall, where the mild
/// plant's mm assembly errors count most; 0.20 / 0.33 mm after the icosahedron's demo tour,
/// 0.41 / 0.44 mm after the helicopter's, 0.15 mm after the braking cueing run, all ending at
/// or near home). The tests pass bounds near what their own run achieves.
pub const DEFAULT_MAX_STATIC_ERROR_MM: f64 = 10.0;

/// What a run measured (printed, and written to <out>/summary.json).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Summary {
    /// The platform the daemon ran (its TOML `[platform] name`).
    pub platform: String,
    /// The run ended as planned: motion-core finished its trajectory and held, with no e-stop,
    /// no refused reference and no bus stop while it streamed.
    pub completed: bool,
    /// Who stopped the run and why, in words (the first e-stop's source and cause).
    pub stopped_by: Option<String>,
    pub transport: String,
    pub monitor: bool,
    pub plant_samples: u64,
    pub setpoints: u64,
    pub tracking_position_mean_mm: f64,
    pub tracking_position_max_mm: f64,
    pub tracking_rotation_mean_deg: f64,
    pub tracking_rotation_max_deg: f64,
    pub static_position_mm: f64,
    pub static_rotation_deg: f64,
    pub force_min_n: f64,
    pub force_max_n: f64,
    pub f_min_n: f64,
    pub f_max_n: f64,
    pub non_converged_plant_steps: u64,
    pub loop_cycles: u64,
    pub loop_overruns: u64,
    pub loop_rejected: u64,
    /// Setpoints the loop could not hand to its publish stage (stage stalled; each one is a
    /// sequence gap the monitor counts).
    pub loop_dropped: u64,
    pub loop_lateness_p99_us: f64,
    pub loop_lateness_max_us: f64,
    pub loop_compute_p99_us: f64,
    pub estops: u64,
    /// The monitor's trip records (its log's `SAFETY TRIP` lines): why it stopped the run.
    pub monitor_trips: Vec<String>,
    pub monitor_heartbeats: u64,
    pub drive_faults: u64,
    /// Pose error at the rest points (measured: tracker vs reference; true: plant vs reference).
    pub rest: RestErrors,
    /// Settled stretches without readings (tracker invalid or no force feedback).
    pub rest_points_skipped: usize,
    /// drive-io stopped the bus (stale setpoints, e-stop, fault: [`crs_ipc::BusState`]) while
    /// motion-core was still streaming: the drives held from then on (on an overloaded host a
    /// gap of > `bus.stale_setpoint_cycles` SYNC periods in the setpoint stream does this).
    pub bus_stopped_during_run: Option<String>,
    /// drive-io's ERROR lines of such a stop (which watch or fault stopped the bus).
    pub bus_stop_reasons: Vec<String>,
    /// The recording written (--record).
    pub record: Option<PathBuf>,
    /// The hover flight (`--source helicopter`).
    pub ride: Option<crate::ride_run::RideSummary>,
    /// The motion cueing (`--source cueing`): what it did and what the rider perceived.
    pub cueing: Option<crate::cueing_run::CueingSummary>,
    /// The wire model's final statistics per bus (load, frames dropped at a full transmit
    /// queue, worst frame latency); empty without the hub (`--transport udpbus` / explicit).
    pub wire: Vec<crs_supervisor::transport::WireSummary>,
    pub duration_s: f64,
}

impl Summary {
    /// What fails `crs sim --check`: e-stops, plant steps without equilibrium, forces outside
    /// [f_min, f_max] (or none seen), static error above `max_static_error_mm` (or not
    /// reached), rejected references, drive faults, a bus stop during the run. Empty = pass.
    /// (A run that does not complete never gets here: `execute` returns its error.) Each
    /// branch is failed by a run of the real stack in crates/crs/tests/sim_check_fails.rs.
    pub fn check_failures(&self, max_static_error_mm: f64) -> Vec<String> {
        let (f_min, f_max) = (self.f_min_n, self.f_max_n);
        let mut fails = Vec::new();
        if self.estops > 0 {
            fails.push(format!("{} e-stop(s)", self.estops));
        }
        if self.non_converged_plant_steps > 0 {
            fails.push(format!(
                "{} plant steps without equilibrium",
                self.non_converged_plant_steps
            ));
        }
        if self.force_min_n > self.force_max_n {
            // No plant state carried a force (min/max still at ±∞): nothing was shown within.
            fails.push("no cable force seen".into());
        } else if !(self.force_min_n >= f_min && self.force_max_n <= f_max) {
            fails.push(format!(
                "forces {:.0} … {:.0} N outside [{f_min:.0}, {f_max:.0}] N",
                self.force_min_n, self.force_max_n
            ));
        }
        if self.static_position_mm.is_nan() || self.static_position_mm > max_static_error_mm {
            fails.push(format!(
                "static position error {:.2} mm > {} mm",
                self.static_position_mm, max_static_error_mm
            ));
        }
        if self.loop_rejected > 0 {
            fails.push(format!(
                "{} references rejected by motion-core",
                self.loop_rejected
            ));
        }
        if self.drive_faults > 0 {
            fails.push(format!("{} drive fault reports", self.drive_faults));
        }
        if let Some(b) = &self.bus_stopped_during_run {
            fails.push(format!("drive-io stopped the bus during the run ({b})"));
        }
        for w in self.wire.iter().filter(|w| w.dropped > 0) {
            fails.push(format!(
                "bus {}: {} frames dropped at a full transmit queue (the bus is overloaded)",
                w.bus, w.dropped
            ));
        }
        fails
    }
}

/// Runs of this process (each gets its own iceoryx2 prefix and UDP port).
static RUNS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);

/// What a run is, for an observer starting alongside it.
pub struct RunStart<'a> {
    /// The run's iceoryx2 service prefix.
    pub prefix: &'a str,
    pub daemon: &'a motion_core::daemon::config::DaemonConfig,
    pub platform: &'a cdpr_model::config::Platform,
    /// The waypoint file motion-core runs (None: the daemon TOML's own).
    pub waypoints: Option<&'a Path>,
    /// motion-core's control socket when an operator starts the ride ([`SimOptions::operator_start`]).
    pub control: Option<&'a Path>,
}

/// Something that follows a run next to the summary (the operator console, the run's plots):
/// it sees every sample the launcher receives, on the launcher's thread, and is told when the
/// run is over. It never talks to the processes of the stack.
pub trait RunObserver {
    fn started(&mut self, _run: &RunStart<'_>) -> Result<(), ObserverError> {
        Ok(())
    }
    fn setpoint(&mut self, _sp: &JointSetpoint) {}
    fn truth(&mut self, _t: &PlantTruth) {}
    fn loop_stats(&mut self, _s: &LoopStatsSample) {}
    fn event(&mut self, _e: &StateEvent) {}
    /// After the summary was written to `out`.
    fn finished(&mut self, _out: &Path, _summary: &Summary) {}
}

/// No observer.
pub struct NoObserver;
impl RunObserver for NoObserver {}

/// Why an observer could not start following a run.
#[derive(Debug, thiserror::Error)]
pub enum ObserverError {
    /// The operator console did not start (address in use, ...).
    #[error(transparent)]
    Console(#[from] crs_console::ConsoleError),
    /// The console's start button (its ride refused, ...).
    #[error(transparent)]
    ConsoleSetup(#[from] crate::console_setup::ConsoleSetupError),
}

/// Why a run of the stack failed: refused before anything started (bad inputs, a missing
/// binary, configs that disagree) or ended other than by motion-core finishing its plan.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The running executable's path (where the stack's binaries are looked for).
    #[error("{0}")]
    CurrentExe(#[source] std::io::Error),
    /// The directory of the running executable.
    #[error("cannot locate the binary directory")]
    NoBinDir,
    /// A binary of the stack is not built.
    #[error(
        "{} not found: build the stack first (`cargo build --release --workspace --bins`) or pass --bin-dir",
        exe.display()
    )]
    MissingBinary { exe: PathBuf },
    /// The daemon TOML or its platform TOML (names the file and key).
    #[error(transparent)]
    Config(#[from] cdpr_model::config::ConfigError),
    /// A config file given on the command line does not exist.
    #[error("{}: no such file", path.display())]
    NoSuchFile { path: PathBuf },
    /// The drives config does not load.
    #[error("{}: {source}", drives.display())]
    Drives {
        drives: PathBuf,
        #[source]
        source: drives_config::ConfigError,
    },
    /// The drives wait for the monitor's heartbeat but no monitor runs (`monitor_exe`: the
    /// binary that is not built; None: `--no-monitor`).
    #[error(
        "{}: [safety_heartbeat] is set, so the drives stay braked without the safety monitor's \
         heartbeat; {}. Use a drives config without [safety_heartbeat] to run without it",
        drives.display(),
        match monitor_exe {
            None => "--no-monitor was given".to_string(),
            Some(exe) => format!("{} is not built", exe.display()),
        }
    )]
    HeartbeatWithoutMonitor {
        drives: PathBuf,
        monitor_exe: Option<PathBuf>,
    },
    #[error("--hold-s must be ≥ 0 and --timeout-s > 0")]
    BadDurations { hold_s: f64, timeout_s: f64 },
    /// `--settle-s` (the rest recorder).
    #[error(transparent)]
    Recording(#[from] crate::rest_recording::RecordingError),
    #[error(
        "--hold-s {hold_s} < --settle-s {settle_s}: the last waypoint could not become a rest point"
    )]
    HoldShorterThanSettle { hold_s: f64, settle_s: f64 },
    /// The controller cannot be configured for the daemon's platform.
    #[error(transparent)]
    Configure(#[from] motion_core::daemon::lifecycle::ConfigureError),
    /// The monitor config does not load.
    #[error(transparent)]
    MonitorConfig(#[from] safety_monitor::config::ConfigError),
    /// The monitor times pose velocities with another period than motion-core's loop.
    #[error(
        "{}: [motion] setpoint_period_ms = {setpoint_period_ms} but motion-core ({}) runs its loop every \
         {loop_ms} ms; set setpoint_period_ms = {loop_ms} (the monitor times the pose's \
         velocity by it)",
        monitor_config.display(),
        daemon_config.display()
    )]
    MonitorPeriod {
        monitor_config: PathBuf,
        daemon_config: PathBuf,
        setpoint_period_ms: f64,
        loop_ms: f64,
    },
    /// The monitor would supervise another platform.
    #[error(transparent)]
    MonitorPlatform(#[from] crate::platforms::MonitorPlatformError),
    /// The hover ride (settings, pilot, thread, plot).
    #[error(transparent)]
    Ride(#[from] crate::ride_run::RideError),
    #[error(
        "--source helicopter flies the hover model: --waypoints, --dwell-s and --record belong to the waypoint plan"
    )]
    RideWithWaypointPlan,
    /// The motion cueing (settings, vehicle, thread, figures).
    #[error(transparent)]
    Cueing(#[from] crate::cueing_run::CueingError),
    #[error("the controller refuses the home pose: {0}")]
    HomePose(#[source] motion_core::daemon::cycle::Rejection),
    /// A file or directory of the run's output (`path`).
    #[error("{source}")]
    Output {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The waypoint file (`--dwell-s`).
    #[error(transparent)]
    Waypoints(#[from] trajectory::WaypointError),
    /// The ride (the waypoint file motion-core would run) refused before anything started.
    #[error("ride refused, nothing started: {0}")]
    RideRefused(#[from] lifecycle::RideRefused),
    /// Timing or writing the waypoints (`--dwell-s`).
    #[error(transparent)]
    Campaign(#[from] crate::campaign::CampaignError),
    #[error("--dwell-s needs waypoints (--waypoints or [trajectory].waypoints)")]
    DwellWithoutWaypoints,
    #[error(
        "--start-from-console starts a waypoint ride: it needs waypoints (--waypoints or [trajectory].waypoints) and no --source helicopter / cueing"
    )]
    OperatorStartWithoutRide,
    #[error(transparent)]
    Transport(#[from] crs_supervisor::transport::BadTransport),
    #[error("{}: {source}", drives.display())]
    Budget {
        drives: PathBuf,
        #[source]
        source: drive_commissioning::budget::CheckError,
    },
    /// The launcher's own iceoryx2 node or subscribers.
    #[error(transparent)]
    Ipc(#[from] crs_ipc::IpcError),
    #[error(transparent)]
    Observer(#[from] ObserverError),
    #[error(transparent)]
    Spawn(#[from] supervisor::SpawnError),
    /// A child exited while the launcher waited for `what` (`log_tail`: its last log lines).
    #[error("{name} exited ({status}) while waiting for {what}:\n{log_tail}")]
    ExitedWhileWaiting {
        name: &'static str,
        status: std::process::ExitStatus,
        what: String,
        log_tail: String,
    },
    #[error("interrupted")]
    InterruptedWhileWaiting,
    #[error("timed out after {secs} s waiting for {what}")]
    WaitTimeout { secs: f64, what: String },
    #[error("interrupted (Ctrl-C): stopped all processes")]
    Interrupted,
    /// A child other than a successfully finished motion-core exited during the run.
    #[error("{name} exited ({status}); stopping the stack:\n{log_tail}")]
    Exited {
        name: &'static str,
        status: std::process::ExitStatus,
        log_tail: String,
    },
    #[error("timed out after {timeout_s} s")]
    Timeout { timeout_s: f64 },
    /// Writing the recorded data set `path` (`--record`).
    #[error("{}: {source}", path.display())]
    Record {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Summary(#[from] serde_json::Error),
    #[error("the run produced no plant states or no setpoints")]
    NoSamples,
}

fn output(path: &Path) -> impl FnOnce(std::io::Error) -> SimError + '_ {
    move |source| SimError::Output {
        path: path.to_path_buf(),
        source,
    }
}

/// Runs the stack once as `crs sim` does (without the --check verdict): starts the processes,
/// follows the run, stops everything, prints and writes the summary (and the recording).
pub fn execute(a: &SimOptions) -> Result<Summary, SimError> {
    execute_observed(a, &mut NoObserver)
}

/// [`execute`] with an observer, in four stages: prepare (every input checked, nothing
/// started) → start (the processes in order, each waited for) → follow (until motion-core
/// ends its plan, a process dies, Ctrl-C or the timeout) → finish (stop all, summary,
/// recording).
pub fn execute_observed(
    a: &SimOptions,
    observer: &mut dyn RunObserver,
) -> Result<Summary, SimError> {
    let mut run = prepare(a)?;
    let mut started = start(a, &run, observer)?;
    let mut followed = Following::new(&run, started.first_truth.take());
    let result = follow(a, &mut run, &mut started, &mut followed, observer);
    finish(a, run, started, followed, result, observer)
}

/// A run checked and set up before any process starts: the inputs validated, the motion
/// source prepared, the waypoints timed, the run's iceoryx2 prefix chosen.
struct Prepared {
    run_no: u32,
    bin_dir: PathBuf,
    with_monitor: bool,
    daemon: DaemonConfig,
    platform: Platform,
    drives: DrivesConfig,
    budgets: Vec<InterfaceBudget>,
    bus_mode: transport::BusMode,
    recorder: Option<RestRecorder>,
    configured: lifecycle::Configured,
    /// The helicopter ride, until its thread starts (with motion-core's first setpoint).
    ride: Option<PreparedRide>,
    ride_model: Option<HoverModel>,
    cueing: Option<CueingRun>,
    /// The controller's command at home: the drives are homed to it.
    home_q: Vec<f64>,
    /// The waypoint file of the plan (the option's or the daemon TOML's).
    waypoint_file: Option<PathBuf>,
    /// The waypoint file motion-core is given (the timed copy with --dwell-s).
    waypoints_arg: Option<PathBuf>,
    control_socket: Option<PathBuf>,
    rt: Option<i32>,
    transport: String,
    prefix: String,
}

impl Prepared {
    fn exe(&self, name: &str) -> PathBuf {
        self.bin_dir.join(name)
    }
}

/// The directory of the stack's binaries (the option's, else this executable's), each checked.
fn locate_binaries(a: &SimOptions) -> Result<PathBuf, SimError> {
    let bin_dir = match &a.bin_dir {
        Some(d) => d.clone(),
        None => std::env::current_exe()
            .map_err(SimError::CurrentExe)?
            .parent()
            .map(Path::to_path_buf)
            .ok_or(SimError::NoBinDir)?,
    };
    for need in ["motion-core", "drive-io", "sim-plant", "can-wire"] {
        if !bin_dir.join(need).is_file() {
            return Err(SimError::MissingBinary {
                exe: bin_dir.join(need),
            });
        }
    }
    Ok(bin_dir)
}

/// The configs of a run, read and checked against each other before anything starts.
struct Inputs {
    daemon: DaemonConfig,
    platform: Platform,
    drives: DrivesConfig,
    budgets: Vec<InterfaceBudget>,
    bus_mode: transport::BusMode,
    recorder: Option<RestRecorder>,
}

fn check_inputs(a: &SimOptions, bin_dir: &Path, with_monitor: bool) -> Result<Inputs, SimError> {
    let daemon = motion_core::daemon::config::load(&a.config)?;
    let platform = load_platform(&daemon.platform)?;
    for f in [&a.drives, &a.plant] {
        if !f.is_file() {
            return Err(SimError::NoSuchFile { path: f.clone() });
        }
    }
    // Drives that validate the monitor's safety heartbeat never enable without it: refuse the
    // run up front instead of letting drive-io time out waiting for operational drives.
    let drives = DrivesConfig::load(&a.drives).map_err(|source| SimError::Drives {
        drives: a.drives.clone(),
        source,
    })?;
    // The bus budget of every interface, with the frames every node will be configured with:
    // a layout the wire cannot carry is refused before anything starts.
    let budgets =
        drive_commissioning::budget::check(&drives).map_err(|source| SimError::Budget {
            drives: a.drives.clone(),
            source,
        })?;
    let bus_mode = transport::BusMode::parse(&a.transport)?;
    if drives.safety_heartbeat.is_some() && !with_monitor {
        return Err(SimError::HeartbeatWithoutMonitor {
            drives: a.drives.clone(),
            monitor_exe: (!a.no_monitor).then(|| bin_dir.join("safety-monitor")),
        });
    }
    if !(a.hold_s.is_finite() && a.hold_s >= 0.0 && a.timeout_s > 0.0) {
        return Err(SimError::BadDurations {
            hold_s: a.hold_s,
            timeout_s: a.timeout_s,
        });
    }
    let recorder = match &a.record {
        Some(_) => Some(RestRecorder::new(a.settle_s)?.averaging_forces(a.record_mean_forces)),
        None => None,
    };
    if a.record.is_some() && a.hold_s < a.settle_s {
        return Err(SimError::HoldShorterThanSettle {
            hold_s: a.hold_s,
            settle_s: a.settle_s,
        });
    }
    Ok(Inputs {
        daemon,
        platform,
        drives,
        budgets,
        bus_mode,
        recorder,
    })
}

/// Stage 1: every input checked and the run set up; no process started yet.
fn prepare(a: &SimOptions) -> Result<Prepared, SimError> {
    let run_no = RUNS.fetch_add(1, Ordering::Relaxed);
    let bin_dir = locate_binaries(a)?;
    let with_monitor = !a.no_monitor && bin_dir.join("safety-monitor").is_file();
    let Inputs {
        daemon,
        platform,
        drives,
        budgets,
        bus_mode,
        recorder,
    } = check_inputs(a, &bin_dir, with_monitor)?;
    // The controller's command at home (the drives are homed to it) and, with --dwell-s, the
    // waypoints timed for a rest at each.
    let mut configured = lifecycle::configure(&daemon, &platform)?;
    if with_monitor {
        check_monitor_period(&a.monitor_config, &a.config, configured.period_s())?;
        crate::platforms::check_monitor_platform(
            &a.monitor_config,
            &a.config,
            &daemon.platform,
            &platform,
        )?;
    }
    let ride = match &a.ride {
        Some(spec) => Some(crate::ride_run::prepare(spec, &platform)?),
        None => None,
    };
    if ride.is_some() && (a.record.is_some() || a.dwell_s.is_some() || a.waypoints.is_some()) {
        return Err(SimError::RideWithWaypointPlan);
    }
    let cueing = match &a.cueing {
        Some(_)
            if ride.is_some()
                || a.record.is_some()
                || a.dwell_s.is_some()
                || a.waypoints.is_some() =>
        {
            return Err(crate::cueing_run::CueingError::WithOtherSource.into());
        }
        Some(spec) => Some(CueingRun::new(crate::cueing_run::prepare(
            spec,
            &platform,
            &configured,
        )?)),
        None => None,
    };
    let home_q = configured.home_command().map_err(SimError::HomePose)?;
    let waypoint_file = a.waypoints.clone().or(daemon.trajectory.waypoints.clone());
    if a.operator_start && (ride.is_some() || cueing.is_some() || waypoint_file.is_none()) {
        return Err(SimError::OperatorStartWithoutRide);
    }
    let control_socket = a.operator_start.then(|| a.out.join("control.sock"));
    // The ride motion-core will run, checked with the loop's own checks before any process
    // starts: a refusal names the file, the line and (outside the region) the axis and bound.
    if ride.is_none()
        && cueing.is_none()
        && let Some(file) = &waypoint_file
    {
        let ride_file = trajectory::read_ride(file).map_err(lifecycle::RideRefused::from)?;
        configured.verify_ride(&ride_file)?;
    }
    std::fs::create_dir_all(&a.out).map_err(output(&a.out))?;
    let waypoints_arg = time_waypoints(a, &platform, &configured, waypoint_file.as_deref())?;
    let rt = rt_priority(a);
    let transport = bus_mode.describe();
    let prefix = format!("crs-sim-{}-{run_no}/", std::process::id());
    println!(
        "crs sim: platform `{}`, buses: {transport}, iceoryx2 prefix {prefix}, safety monitor {}",
        platform.name,
        if with_monitor {
            "on"
        } else if a.no_monitor {
            "off (--no-monitor)"
        } else {
            "not built (crates/safety-monitor): running without"
        }
    );
    let ride_model = ride.as_ref().map(|r| r.model);
    Ok(Prepared {
        run_no,
        bin_dir,
        with_monitor,
        daemon,
        platform,
        drives,
        budgets,
        bus_mode,
        recorder,
        configured,
        ride,
        ride_model,
        cueing,
        home_q,
        waypoint_file,
        waypoints_arg,
        control_socket,
        rt,
        transport,
        prefix,
    })
}

/// The waypoint file motion-core is given: with --dwell-s the plan's waypoints timed for a rest
/// at each, written into the run's directory; else the option's file (None: the daemon TOML's).
fn time_waypoints(
    a: &SimOptions,
    platform: &Platform,
    configured: &lifecycle::Configured,
    waypoint_file: Option<&Path>,
) -> Result<Option<PathBuf>, SimError> {
    match (a.dwell_s, waypoint_file) {
        (Some(dwell), Some(file)) => {
            let wps = trajectory::read_waypoints(file)?;
            let (timed, dur) = timed_waypoints(
                platform.home,
                &wps,
                configured.planner_limits(),
                configured.period_s(),
                dwell,
            )?;
            let path = a.out.join("waypoints-timed.csv");
            write_waypoints(
                &path,
                &timed,
                &format!(
                    "{} timed by `crs sim --dwell-s {dwell}`: rest {dwell} s at every waypoint; plan {dur:.1} s",
                    file.display()
                ),
            )?;
            println!(
                "  {} waypoints timed for a {dwell} s rest at each: plan {dur:.1} s ({})",
                timed.len(),
                path.display()
            );
            Ok(Some(path))
        }
        (Some(_), None) => Err(SimError::DwellWithoutWaypoints),
        (None, _) => Ok(a.waypoints.clone()),
    }
}

/// SCHED_FIFO + mlockall for drive-io and sim-plant only where it cannot fail (root).
fn rt_priority(a: &SimOptions) -> Option<i32> {
    a.rt_priority.filter(|_| {
        // SAFETY: geteuid(2) has no preconditions.
        let root = unsafe { libc::geteuid() } == 0;
        if !root {
            println!("  --rt-priority ignored: not root (drive-io and sim-plant run SCHED_OTHER)");
        }
        root
    })
}

/// The topics the launcher listens to (on the run's own prefix).
struct Topics {
    truth: TopicSubscriber<PlantTruth>,
    setpoints: TopicSubscriber<JointSetpoint>,
    loop_stats: TopicSubscriber<LoopStatsSample>,
    events: TopicSubscriber<StateEvent>,
    heartbeats: TopicSubscriber<Heartbeat>,
    feedback: TopicSubscriber<DriveFeedback>,
    tracker: TopicSubscriber<TrackerPose>,
}

impl Topics {
    fn subscribe(node: &IpcNode) -> Result<Self, SimError> {
        Ok(Self {
            truth: node.subscriber()?,
            setpoints: node.subscriber()?,
            loop_stats: node.subscriber()?,
            events: node.subscriber()?,
            heartbeats: node.subscriber()?,
            feedback: node.subscriber()?,
            tracker: node.subscriber()?,
        })
    }
}

/// The processes of a started run and what the launcher listens to. The supervisor is
/// dropped first (it stops whatever still runs), the IPC node last.
struct Started {
    stack: Supervisor,
    buses: transport::StackBuses,
    topics: Topics,
    _node: IpcNode,
    /// The plant's first state (waited for before the drives start).
    first_truth: Option<PlantTruth>,
}

fn arg(p: &Path) -> String {
    p.display().to_string()
}

fn rt_args(p: Option<i32>) -> Vec<String> {
    match p {
        Some(p) => vec!["--rt-priority".to_string(), p.to_string()],
        None => Vec::new(),
    }
}

/// Polls `ready` every 10 ms until it holds; a process that exits, Ctrl-C or `secs` end the
/// wait with an error naming `what` was awaited.
fn wait_for(
    what: &str,
    secs: f64,
    ready: &mut dyn FnMut() -> bool,
    stack: &mut Supervisor,
) -> Result<(), SimError> {
    let t0 = Instant::now();
    while !ready() {
        if let Some(e) = stack.exited() {
            return Err(SimError::ExitedWhileWaiting {
                name: e.name,
                status: e.status,
                what: what.to_string(),
                log_tail: supervisor::log_tail(&e.log, 15),
            });
        }
        if supervisor::interrupted() {
            return Err(SimError::InterruptedWhileWaiting);
        }
        if t0.elapsed().as_secs_f64() > secs {
            return Err(SimError::WaitTimeout {
                secs,
                what: what.to_string(),
            });
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    Ok(())
}

/// Stage 2: the observer, then the buses, the plant, the monitor, the drive adapter and
/// motion-core, in that order, each waited for where the next one needs it.
fn start(
    a: &SimOptions,
    run: &Prepared,
    observer: &mut dyn RunObserver,
) -> Result<Started, SimError> {
    supervisor::install_interrupt_handler();
    let node = IpcNode::with_prefix("crs-sim", &run.prefix)?;
    let topics = Topics::subscribe(&node)?;
    observer.started(&RunStart {
        prefix: &run.prefix,
        daemon: &run.daemon,
        platform: &run.platform,
        waypoints: run
            .waypoints_arg
            .as_deref()
            .or(run.waypoint_file.as_deref()),
        control: run.control_socket.as_deref(),
    })?;
    let mut stack = Supervisor::new(&run.prefix, &a.out);
    for ib in &run.budgets {
        println!(
            "  bus {}: {:.1} % of {} kbit/s (budget {:.0} %), RPDO window {:.0} µs",
            ib.name,
            ib.load_percent(),
            ib.bitrate_bit_per_s / 1000,
            ib.budget_percent,
            ib.rpdo_window_us()
        );
    }
    // The buses first: every CAN node of the run connects to them.
    let mut nodes = vec!["sim-plant", "drive-io"];
    if run.with_monitor {
        nodes.push("safety-monitor");
    }
    let buses = transport::start(
        &run.bus_mode,
        &run.drives,
        &nodes,
        &mut stack,
        &run.exe("can-wire"),
        &a.out,
        &format!("{}-{}", std::process::id(), run.run_no),
    )?;
    spawn_plant(a, run, &buses, &mut stack)?;
    let mut first_truth = None;
    wait_for(
        "the plant's first state",
        20.0,
        &mut || {
            while let Ok(Some(t)) = topics.truth.receive() {
                first_truth = Some(t);
            }
            first_truth.is_some()
        },
        &mut stack,
    )?;
    spawn_drive_side(a, run, &buses, &mut stack)?;
    wait_for(
        "the drives to be operational (NMT boot, SDO, CiA 402 enable)",
        30.0,
        &mut || {
            let mut ok = false;
            while let Ok(Some(f)) = topics.feedback.receive() {
                ok |= f.bus() == Ok(crs_ipc::BusState::Ready);
            }
            ok
        },
        &mut stack,
    )?;
    spawn_motion_core(a, run, &mut stack)?;
    Ok(Started {
        stack,
        buses,
        topics,
        _node: node,
        first_truth,
    })
}

/// sim-plant, homed to the controller's command at home, with the operator's hand on the
/// safety I/O node (its reset key and e-stop) as a control file.
fn spawn_plant(
    a: &SimOptions,
    run: &Prepared,
    buses: &transport::StackBuses,
    stack: &mut Supervisor,
) -> Result<(), SimError> {
    stack.spawn(
        "sim-plant",
        &run.exe("sim-plant"),
        &[
            rt_args(run.rt.map(|p| p - 5)),
            vec![
                "--plant".into(),
                arg(&a.plant),
                "--drives".into(),
                arg(&a.drives),
            ],
            buses.args("sim-plant"),
            vec![
                "--control-platform".into(),
                arg(&run.daemon.platform),
                "--home-lengths-m".into(),
                run.home_q
                    .iter()
                    .map(|q| format!("{q:?}"))
                    .collect::<Vec<_>>()
                    .join(","),
                // The operator's hand on the safety I/O node (its reset key and e-stop).
                "--io-control".into(),
                arg(&a.out.join("safety-io.control")),
            ],
        ]
        .concat(),
        &[],
    )?;
    if run.with_monitor && run.drives.safety_io.is_some() {
        println!(
            "  the safety I/O node's reset key: `echo reset_key on > {0}` then `: > {0}` (turned \
             and released: the monitor's operator reset); `echo estop pressed > {0}`: its \
             e-stop button",
            a.out.join("safety-io.control").display()
        );
    }
    Ok(())
}

/// The safety monitor (when the run has it), then the drive adapter.
fn spawn_drive_side(
    a: &SimOptions,
    run: &Prepared,
    buses: &transport::StackBuses,
    stack: &mut Supervisor,
) -> Result<(), SimError> {
    if run.with_monitor {
        stack.spawn(
            "safety-monitor",
            &run.exe("safety-monitor"),
            &[
                vec!["--config".to_string(), arg(&a.monitor_config)],
                buses.args("safety-monitor"),
            ]
            .concat(),
            &[],
        )?;
    }
    // The heartbeat is mandatory for drive-io: only a run without the monitor (--no-monitor, a
    // bench) with a drives config without it runs the test rigs' bench executable instead.
    let drive_io_exe = if !run.with_monitor && run.drives.safety_heartbeat.is_none() {
        run.exe(drives_config::BENCH_EXECUTABLE)
    } else {
        run.exe("drive-io")
    };
    stack.spawn(
        "drive-io",
        &drive_io_exe,
        &[
            rt_args(run.rt),
            vec!["--config".into(), arg(&a.drives)],
            buses.args("drive-io"),
        ]
        .concat(),
        &[],
    )?;
    Ok(())
}

/// motion-core on its input: the cueing input (a ride or motion cueing), the control socket
/// (an operator starts the ride) or the waypoint plan.
fn spawn_motion_core(
    a: &SimOptions,
    run: &Prepared,
    stack: &mut Supervisor,
) -> Result<(), SimError> {
    let mut mc_args = vec![
        "--config".into(),
        arg(&a.config),
        "--exit-after-plan-s".into(),
        a.hold_s.to_string(),
    ];
    if run.ride.is_some() || run.cueing.is_some() {
        mc_args.extend(["--input".into(), "cueing".into()]);
    } else if let Some(sock) = &run.control_socket {
        // Idle and holding until an operator starts the ride on the control socket.
        mc_args.extend(["--control".into(), arg(sock)]);
        println!(
            "  motion-core idles at home, holding: the ride starts when an operator starts it \
             (the console's START RIDE, or `crs ride start FILE --socket {}`)",
            sock.display()
        );
    } else if let Some(w) = &run.waypoints_arg {
        mc_args.push("--waypoints".into());
        mc_args.push(arg(w));
    }
    stack.spawn("motion-core", &run.exe("motion-core"), &mc_args, &[])?;
    Ok(())
}

/// What the launcher gathers while it follows the run.
struct Following {
    sum: Summary,
    /// The newest references (timestamp, pose), for the tracking error of each plant state.
    refs: VecDeque<(u64, [f64; 6])>,
    /// Sums of the tracking errors (m, rad) over `n_track` plant states.
    sum_p: f64,
    sum_r: f64,
    n_track: u64,
    last_truth: Option<PlantTruth>,
    last_ref: Option<[f64; 6]>,
    last_sp_ns: u64,
    was_running: bool,
    /// The first bus state other than running after it ran (timestamp, state).
    bus_stop: Option<(u64, u32)>,
    /// A stop named only by the monitor's echo of somebody's e-stop event.
    echoed_stop: Option<String>,
    /// The hover model's thread, started with motion-core's first setpoint.
    ride_thread: Option<crate::ride_run::RideThread>,
    /// Every 10th reference position, for the ride's path plot.
    ride_reference: Vec<[f64; 3]>,
    t0: Instant,
}

impl Following {
    fn new(run: &Prepared, first_truth: Option<PlantTruth>) -> Self {
        let p = run.platform.model.params();
        Self {
            sum: Summary {
                platform: run.platform.name.clone(),
                transport: run.transport.clone(),
                monitor: run.with_monitor,
                force_min_n: f64::INFINITY,
                static_position_mm: f64::NAN,
                static_rotation_deg: f64::NAN,
                force_max_n: f64::NEG_INFINITY,
                f_min_n: p.f_min,
                f_max_n: p.f_max,
                ..Summary::default()
            },
            refs: VecDeque::new(),
            sum_p: 0.0,
            sum_r: 0.0,
            n_track: 0,
            last_truth: first_truth,
            last_ref: None,
            last_sp_ns: 0,
            was_running: false,
            bus_stop: None,
            echoed_stop: None,
            ride_thread: None,
            ride_reference: Vec::new(),
            t0: Instant::now(),
        }
    }

    fn setpoints(&mut self, run: &mut Prepared, topics: &Topics, observer: &mut dyn RunObserver) {
        while let Ok(Some(sp)) = topics.setpoints.receive() {
            observer.setpoint(&sp);
            self.sum.setpoints += 1;
            self.last_sp_ns = self.last_sp_ns.max(sp.timestamp_ns);
            if let Some(r) = run.recorder.as_mut() {
                let m = (sp.cable_count as usize).min(crs_ipc::MAX_CABLES);
                r.setpoint(sp.timestamp_ns, sp.pose, &sp.cable_length_m[..m]);
            }
            self.refs.push_back((sp.timestamp_ns, sp.pose));
            self.last_ref = Some(sp.pose);
            if let Some(c) = run.cueing.as_mut() {
                c.setpoint(&sp);
            }
            if run.ride_model.is_some() && self.sum.setpoints.is_multiple_of(10) {
                self.ride_reference
                    .push([sp.pose[0], sp.pose[1], sp.pose[2]]);
            }
            if self.refs.len() > 4000 {
                self.refs.pop_front();
            }
        }
    }

    fn truths(&mut self, run: &mut Prepared, topics: &Topics, observer: &mut dyn RunObserver) {
        let sum = &mut self.sum;
        while let Ok(Some(t)) = topics.truth.receive() {
            observer.truth(&t);
            sum.plant_samples += 1;
            if t.converged == 0 {
                sum.non_converged_plant_steps += 1;
            }
            for f in &t.force_n[..t.cable_count as usize] {
                sum.force_min_n = sum.force_min_n.min(*f);
                sum.force_max_n = sum.force_max_n.max(*f);
            }
            // Tracking error against the newest reference published before this plant state.
            if let Some((_, x_ref)) = self.refs.iter().rev().find(|(ts, _)| *ts <= t.timestamp_ns) {
                let (dp, dr) = Pose::from_array(t.pose).error_to(&Pose::from_array(*x_ref));
                self.sum_p += dp;
                self.sum_r += dr;
                self.n_track += 1;
                sum.tracking_position_max_mm = sum.tracking_position_max_mm.max(dp * 1e3);
                sum.tracking_rotation_max_deg = sum.tracking_rotation_max_deg.max(dr.to_degrees());
            }
            if let Some(r) = run.recorder.as_mut() {
                r.truth(t.timestamp_ns, t.pose);
            }
            self.last_truth = Some(t);
        }
    }

    /// The tracker, the loop statistics, the state events and the heartbeats.
    fn reports(&mut self, run: &mut Prepared, topics: &Topics, observer: &mut dyn RunObserver) {
        let sum = &mut self.sum;
        while let Ok(Some(tp)) = topics.tracker.receive() {
            if let Some(r) = run.recorder.as_mut() {
                r.tracker(tp.timestamp_ns, tp.pose, tp.valid != 0);
            }
        }
        while let Ok(Some(s)) = topics.loop_stats.receive() {
            observer.loop_stats(&s);
            sum.loop_cycles = s.cycles;
            sum.loop_overruns = s.overruns;
            sum.loop_rejected = s.rejected;
            sum.loop_dropped = s.dropped;
            sum.loop_lateness_p99_us = s.lateness_p99_ns as f64 * 1e-3;
            sum.loop_lateness_max_us = s.lateness_max_ns as f64 * 1e-3;
            sum.loop_compute_p99_us = s.compute_p99_ns as f64 * 1e-3;
        }
        while let Ok(Some(e)) = topics.events.receive() {
            observer.event(&e);
            if let Some(words) = crs_console::status::estop_in_words(&e) {
                sum.estops += 1;
                println!("  E-STOP by {words}");
                // The monitor's trip on somebody's e-stop event echoes that event: the stop
                // belongs to its sender. The two arrive from different publishers in no fixed
                // order, so the echo only names the stop if no sender's event is seen.
                let echo = e.source() == ProcessId::SafetyMonitor
                    && e.trip_cause() == Ok(crs_ipc::TripCause::EStopEvent);
                if echo {
                    self.echoed_stop.get_or_insert(words);
                } else {
                    sum.stopped_by.get_or_insert(words);
                }
            }
        }
        while let Ok(Some(h)) = topics.heartbeats.receive() {
            if h.source == ProcessId::SafetyMonitor as u32 {
                sum.monitor_heartbeats += 1;
            }
        }
    }

    fn drive_feedback(&mut self, run: &mut Prepared, topics: &Topics) {
        while let Ok(Some(f)) = topics.feedback.receive() {
            if f.fault() != Ok(crs_ipc::FaultCode::None) {
                self.sum.drive_faults += 1;
            }
            let running = f.bus() == Ok(crs_ipc::BusState::Running);
            self.was_running |= running;
            if self.was_running && self.bus_stop.is_none() && !running {
                self.bus_stop = Some((f.timestamp_ns, f.bus_state));
            }
            if let Some(r) = run.recorder.as_mut() {
                let m = (f.cable_count as usize).min(crs_ipc::MAX_CABLES);
                r.forces(f.timestamp_ns, &f.cable_force_n[..m]);
            }
        }
    }

    /// The ride's or the cueing's source starts with motion-core's first setpoint (its cueing
    /// subscriber is up).
    fn start_source(&mut self, run: &mut Prepared) -> Result<(), SimError> {
        if self.sum.setpoints > 0
            && self.ride_thread.is_none()
            && let Some(r) = run.ride.take()
        {
            println!(
                "  hover physics (eq. 5.21-5.22) flying {} for {:.1} s on motion-core's cueing input",
                r.describe, r.duration_s
            );
            self.ride_thread = Some(crate::ride_run::start(r, &run.prefix, run.platform.home)?);
        }
        if let Some(c) = run
            .cueing
            .as_mut()
            .filter(|c| self.sum.setpoints > 0 && !c.started())
        {
            c.start(&run.prefix)?;
        }
        Ok(())
    }
}

/// Stage 3: every 5 ms, what arrived on the topics into the summary and the recording, until
/// motion-core ends its plan (Ok), a process exits, Ctrl-C or the timeout.
fn follow(
    a: &SimOptions,
    run: &mut Prepared,
    started: &mut Started,
    f: &mut Following,
    observer: &mut dyn RunObserver,
) -> Result<(), SimError> {
    loop {
        std::thread::sleep(Duration::from_millis(5));
        f.setpoints(run, &started.topics, observer);
        f.truths(run, &started.topics, observer);
        f.reports(run, &started.topics, observer);
        f.drive_feedback(run, &started.topics);
        f.start_source(run)?;
        if supervisor::interrupted() {
            return Err(SimError::Interrupted);
        }
        if let Some(e) = started.stack.exited() {
            if e.name == "motion-core" && e.status.success() {
                return Ok(());
            }
            return Err(SimError::Exited {
                name: e.name,
                status: e.status,
                log_tail: supervisor::log_tail(&e.log, 20),
            });
        }
        if f.t0.elapsed().as_secs_f64() > a.timeout_s {
            return Err(SimError::Timeout {
                timeout_s: a.timeout_s,
            });
        }
    }
}

/// Stage 4: stop every process (the hub last), collect what the motion source and the hub
/// measured, conclude the summary, print and write it (and the recording of a run that ended
/// well), tell the observer.
fn finish(
    a: &SimOptions,
    mut run: Prepared,
    mut started: Started,
    mut f: Following,
    result: Result<(), SimError>,
    observer: &mut dyn RunObserver,
) -> Result<Summary, SimError> {
    stop(a, &mut run, &mut started, &mut f)?;
    conclude(a, &mut run, &mut f, result.is_ok());
    let mut sum = f.sum;
    print_summary(&sum);
    if let (Some(path), Some(r), Ok(())) = (&a.record, &run.recorder, &result) {
        write_recording(a, &run, r, path)?;
        sum.record = Some(path.clone());
    }
    let json = a.out.join("summary.json");
    std::fs::write(&json, serde_json::to_string_pretty(&sum)?).map_err(output(&json))?;
    println!("summary written to {}", json.display());
    observer.finished(&a.out, &sum);
    result?;
    if sum.plant_samples == 0 || sum.setpoints == 0 {
        return Err(SimError::NoSamples);
    }
    Ok(sum)
}

/// Lets the last plant states arrive, stops everything, and collects the wire hub's
/// statistics, the ride's summary and plot and the cueing's perception report.
fn stop(
    a: &SimOptions,
    run: &mut Prepared,
    started: &mut Started,
    f: &mut Following,
) -> Result<(), SimError> {
    std::thread::sleep(Duration::from_millis(50));
    while let Ok(Some(t)) = started.topics.truth.receive() {
        f.last_truth = Some(t);
    }
    started.stack.stop_all_then("can-wire");
    // The hub stopped last (it started first): its statistics cover the whole run.
    if let Some(p) = &started.buses.stats {
        match transport::read_wire_stats(p) {
            Some(w) => f.sum.wire = w,
            None => println!(
                "  the wire hub's statistics {} could not be read",
                p.display()
            ),
        }
    }
    if let (Some(t), Some(model)) = (f.ride_thread.take(), run.ride_model) {
        let (mut rs, path) = t.join()?;
        crate::ride_run::write_svg(
            &a.out,
            &run.platform,
            &model,
            &mut rs,
            &path,
            &f.ride_reference,
        )?;
        f.sum.ride = Some(rs);
    }
    if let Some(c) = run.cueing.take() {
        f.sum.cueing = c.finish(&a.out, run.configured.period_s())?;
    }
    Ok(())
}

/// The summary's conclusions: means, whether the run completed, the static error, who stopped
/// it and why.
fn conclude(a: &SimOptions, run: &mut Prepared, f: &mut Following, ended_well: bool) {
    let sum = &mut f.sum;
    if f.n_track > 0 {
        sum.tracking_position_mean_mm = f.sum_p / f.n_track as f64 * 1e3;
        sum.tracking_rotation_mean_deg = (f.sum_r / f.n_track as f64).to_degrees();
    }
    sum.completed = ended_well && sum.estops == 0 && sum.loop_rejected == 0;
    // The static error is only that after a completed run (motion-core ended its plan and
    // held); a stopped run leaves it NaN ("not reached").
    if let (Some(t), Some(r), true) = (f.last_truth, f.last_ref, sum.completed) {
        let (dp, dr) = Pose::from_array(t.pose).error_to(&Pose::from_array(r));
        sum.static_position_mm = dp * 1e3;
        sum.static_rotation_deg = dr.to_degrees();
    }
    sum.duration_s = f.t0.elapsed().as_secs_f64();
    // A stop after the last setpoint is the normal end (motion-core exited, setpoints went
    // stale); one while setpoints kept coming (50 ms later) interrupted the run.
    if let Some((ts, state)) = f.bus_stop
        && f.last_sp_ns > ts + 50_000_000
    {
        let name = crs_ipc::BusState::try_from(state)
            .map_or(format!("state {state}"), |b| format!("{b:?}"));
        sum.bus_stopped_during_run = Some(format!(
            "{name} {:.3} s before the last setpoint",
            (f.last_sp_ns - ts) as f64 * 1e-9
        ));
    }
    if let Some(r) = run.recorder.as_mut() {
        r.finish();
        sum.rest = rest_errors(&r.samples);
        sum.rest_points_skipped = r.skipped.len();
    }
    if let Some(words) = f.echoed_stop.take() {
        sum.stopped_by.get_or_insert(words);
    }
    if sum.estops > 0 && run.with_monitor {
        sum.monitor_trips =
            supervisor::log_lines(&a.out.join("safety-monitor.log"), "SAFETY TRIP", 4);
    }
    if let Some(b) = &sum.bus_stopped_during_run {
        sum.completed = false;
        sum.stopped_by
            .get_or_insert_with(|| format!("drive-io: the bus stopped during the run ({b})"));
    }
    if sum.loop_rejected > 0 {
        sum.stopped_by.get_or_insert_with(|| {
            format!(
                "motion-core: refused {} reference(s) and held",
                sum.loop_rejected
            )
        });
    }
    if sum.bus_stopped_during_run.is_some() {
        sum.bus_stop_reasons = supervisor::log_lines(&a.out.join("drive-io.log"), " ERROR ", 2);
    }
}

/// The rest points of the run as a `crs-dataset 1` file at `path`.
fn write_recording(
    a: &SimOptions,
    run: &Prepared,
    r: &RestRecorder,
    path: &Path,
) -> Result<(), SimError> {
    let platform = &run.platform;
    let m = platform.model.m();
    let p = platform.model.params();
    let campaign = a.campaign.clone().unwrap_or_else(|| {
        run.waypoint_file
            .as_ref()
            .and_then(|f| f.file_stem())
            .map_or("waypoints".into(), |n| n.to_string_lossy().into_owned())
    });
    let meta = vec![
        (
            "platform".to_string(),
            format!("{} ({})", platform.name, run.daemon.platform.display()),
        ),
        (
            "control_model".into(),
            if run.daemon.surrogate.is_some() {
                "kinematic+surrogate".into()
            } else {
                "kinematic".into()
            },
        ),
        ("campaign".into(), campaign),
        (
            "recorded".into(),
            format!(
                "crs sim on the running stack ({}): rest points after {} s settled, last tracker/force reading before the reference moved",
                run.transport, a.settle_s
            ),
        ),
        ("force_limits_n".into(), format!("{} {}", p.f_min, p.f_max)),
    ];
    let ds = to_dataset(&r.samples, m, meta)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(output(dir))?;
    }
    crs_dataset::save_dataset(path, &ds).map_err(|source| SimError::Record {
        path: path.to_path_buf(),
        source,
    })?;
    println!(
        "recorded {} rest points to {}",
        r.samples.len(),
        path.display()
    );
    Ok(())
}

fn print_summary(s: &Summary) {
    println!("\n== crs sim summary ({}, {})", s.platform, s.transport);
    println!(
        "  setpoints {}, plant states {} ({} without equilibrium)",
        s.setpoints, s.plant_samples, s.non_converged_plant_steps
    );
    println!(
        "  tracked pose vs reference: position mean {:.2} mm, max {:.2} mm; rotation mean {:.3}°, max {:.3}°",
        s.tracking_position_mean_mm,
        s.tracking_position_max_mm,
        s.tracking_rotation_mean_deg,
        s.tracking_rotation_max_deg
    );
    if !s.completed {
        println!(
            "  STOPPED: the trajectory did not complete ({})",
            s.stopped_by.as_deref().unwrap_or("the run ended early")
        );
    } else if s.static_position_mm.is_nan() {
        println!("  at rest after the trajectory: not measured (no plant state or setpoint)");
    } else {
        println!(
            "  at rest after the trajectory: position {:.2} mm, rotation {:.3}°",
            s.static_position_mm, s.static_rotation_deg
        );
    }
    if s.rest.rest_points > 0 || s.rest_points_skipped > 0 {
        let r = &s.rest;
        println!(
            "  rest points: {} ({} skipped); measured (tracker) vs reference: position mean {:.2} mm, max {:.2} mm; rotation mean {:.3}°, max {:.3}° (true: {:.2} / {:.2} mm)",
            r.rest_points,
            s.rest_points_skipped,
            r.position_mean_mm,
            r.position_max_mm,
            r.rotation_mean_deg,
            r.rotation_max_deg,
            r.true_position_mean_mm,
            r.true_position_max_mm
        );
    }
    for w in &s.wire {
        println!(
            "  bus {}: {} frames, load {:.1} % (busiest second {}), {} dropped at a full queue, \
             worst frame latency {:.0} µs{}",
            w.bus,
            w.frames,
            w.load_mean_percent,
            w.load_max_percent
                .map_or("not measured".to_string(), |x| format!("{x:.1} %")),
            w.dropped,
            w.latency_max_us,
            if w.violations > 0 {
                format!(", {} late submissions (hub behind)", w.violations)
            } else {
                String::new()
            }
        );
    }
    let ok = s.force_min_n >= s.f_min_n && s.force_max_n <= s.f_max_n;
    println!(
        "  cable forces {:.0} … {:.0} N (limits {:.0} … {:.0} N): {}",
        s.force_min_n,
        s.force_max_n,
        s.f_min_n,
        s.f_max_n,
        if ok { "within" } else { "OUTSIDE" }
    );
    println!(
        "  loop: {} cycles, {} overruns, {} rejected, {} not handed to the publish stage; lateness p99 {:.1} µs, max {:.1} µs; compute p99 {:.1} µs",
        s.loop_cycles,
        s.loop_overruns,
        s.loop_rejected,
        s.loop_dropped,
        s.loop_lateness_p99_us,
        s.loop_lateness_max_us,
        s.loop_compute_p99_us
    );
    println!(
        "  safety monitor: {}; e-stops {}; drive faults reported {}",
        if s.monitor {
            format!("{} heartbeats", s.monitor_heartbeats)
        } else {
            "not running".into()
        },
        s.estops,
        s.drive_faults
    );
    for t in &s.monitor_trips {
        println!("  monitor trip: {t}");
    }
    if let Some(c) = &s.cueing {
        crate::cueing_run::print_summary(c);
    }
    if let Some(b) = &s.bus_stopped_during_run {
        println!("  DRIVE BUS STOPPED DURING THE RUN: {b}; the drives held from then on");
        for r in &s.bus_stop_reasons {
            println!("    drive-io: {r}");
        }
    }
    if let Some(r) = &s.ride {
        println!(
            "  hover flight ({}): {:.1} s flown, walls pushed {:.1} s, max beyond the walls [{:.1}, {:.1}, {:.1}] mm (walls [{:.0}, {:.0}, {:.0}] mm inside the region); {} late model steps{}",
            r.pilot,
            r.flown_s,
            r.wall_contact_s,
            r.max_wall_penetration_mm[0],
            r.max_wall_penetration_mm[1],
            r.max_wall_penetration_mm[2],
            r.wall_margin_mm[0],
            r.wall_margin_mm[1],
            r.wall_margin_mm[2],
            r.late_steps,
            r.path_svg
                .as_ref()
                .map_or(String::new(), |p| format!("; path plot {}", p.display()))
        );
    }
}

/// The monitor judges pose velocities per sequence number with its configured stream period:
/// refuse a run whose motion-core loop has another period before anything starts (a shorter
/// configured period would trip every move, a longer one loosen the per-step check).
fn check_monitor_period(
    monitor_config: &std::path::Path,
    daemon_config: &std::path::Path,
    loop_period_s: f64,
) -> Result<(), SimError> {
    let mon = safety_monitor::config::load(monitor_config)?;
    let (sp_ms, loop_ms) = (mon.motion.setpoint_period_ms, loop_period_s * 1e3);
    if mon.motion.check && (sp_ms - loop_ms).abs() > 1e-6 * loop_ms {
        return Err(SimError::MonitorPeriod {
            monitor_config: monitor_config.to_path_buf(),
            daemon_config: daemon_config.to_path_buf(),
            setpoint_period_ms: sp_ms,
            loop_ms,
        });
    }
    Ok(())
}

#[cfg(test)]
mod verdict_tests {
    use super::Summary;

    /// A summary that passes: what a clean run of the demo tour reports.
    fn clean() -> Summary {
        Summary {
            setpoints: 9004,
            plant_samples: 10359,
            force_min_n: 1211.0,
            force_max_n: 7225.0,
            f_min_n: 1000.0,
            f_max_n: 9000.0,
            static_position_mm: 0.3,
            ..Summary::default()
        }
    }

    fn fails(s: &Summary, bound_mm: f64) -> Vec<String> {
        s.check_failures(bound_mm)
    }

    #[test]
    fn a_clean_run_passes_and_every_branch_fails_alone() {
        assert!(
            fails(&clean(), 2.0).is_empty(),
            "{:?}",
            fails(&clean(), 2.0)
        );
        type Break = fn(&mut Summary);
        let cases: [(&str, Break, &str); 9] = [
            ("e-stop", |s| s.estops = 1, "1 e-stop(s)"),
            (
                "plant without equilibrium",
                |s| s.non_converged_plant_steps = 3,
                "3 plant steps without equilibrium",
            ),
            (
                "force below f_min",
                |s| s.force_min_n = 999.0,
                "forces 999 … 7225 N outside",
            ),
            (
                "force above f_max",
                |s| s.force_max_n = 9001.0,
                "forces 1211 … 9001 N outside",
            ),
            (
                "no force seen",
                |s| (s.force_min_n, s.force_max_n) = (f64::INFINITY, f64::NEG_INFINITY),
                "no cable force seen",
            ),
            (
                "static error above the bound",
                |s| s.static_position_mm = 2.01,
                "static position error 2.01 mm > 2 mm",
            ),
            (
                "static error not reached (the run did not complete)",
                |s| s.static_position_mm = f64::NAN,
                "static position error NaN mm",
            ),
            (
                "rejected reference",
                |s| s.loop_rejected = 1,
                "1 references rejected",
            ),
            (
                "drive fault",
                |s| s.drive_faults = 2,
                "2 drive fault reports",
            ),
        ];
        for (what, brk, msg) in cases {
            let mut s = clean();
            brk(&mut s);
            let f = fails(&s, 2.0);
            assert_eq!(f.len(), 1, "{what}: {f:?}");
            assert!(f[0].contains(msg), "{what}: {f:?}");
        }
        let mut s = clean();
        s.bus_stopped_during_run = Some("EStop 1.2 s before the last setpoint".into());
        let f = fails(&s, 2.0);
        assert_eq!(
            f,
            vec!["drive-io stopped the bus during the run (EStop 1.2 s before the last setpoint)"]
        );
    }

    #[test]
    fn the_static_bound_is_inclusive_and_the_default_is_the_stated_one() {
        let mut s = clean();
        s.static_position_mm = 2.0;
        assert!(fails(&s, 2.0).is_empty());
        s.static_position_mm = super::DEFAULT_MAX_STATIC_ERROR_MM;
        assert!(fails(&s, super::DEFAULT_MAX_STATIC_ERROR_MM).is_empty());
        s.static_position_mm = super::DEFAULT_MAX_STATIC_ERROR_MM * 1.001;
        assert_eq!(fails(&s, super::DEFAULT_MAX_STATIC_ERROR_MM).len(), 1);
    }
}
