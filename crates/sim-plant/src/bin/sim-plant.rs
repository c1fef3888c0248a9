//! sim-plant: the simulated plant on the drive bus. Answers as the m CiA 402 winch drives of
//! the drives config (NMT, SDO, RPDO/SYNC, TPDOs, heartbeats), moves the winches toward their
//! CSP targets, settles the elastostatic plant for the lengths they hold and reports the force
//! sensors in the TPDOs; publishes the ground truth (`crs/v1/plant_truth`) and the tracker pose
//! (`crs/v1/tracker_pose`) on iceoryx2 every plant cycle. See `sim_plant::bus` for the set-up
//! and offset convention (eq. 3.14 / 6.24) and docs/plant-figures.md.

use can_transport::{CanBus, CanError, TransportSpec};
use cdpr_model::config::load_platform;
use clap::{CommandFactory, Parser};
use crs_ipc::{Heartbeat, IpcNode, PlantTruth, TopicPublisher, TrackerPose};
use drives_config::DrivesConfig;
use sim_plant::bus::{self, BusOptions, ConfigFiles, LoopSummary, PlantBus};
use sim_plant::load_plant;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

#[derive(Parser)]
#[command(
    about = "Simulated cable robot on the CAN bus: answers as the winch drives (CiA 402 CSP) \
             with the elastostatic plant behind them"
)]
struct Args {
    /// Plant TOML (effects; its `plant.platform` is the nominal platform).
    #[arg(long, default_value = "config/plant/icosahedron.toml", value_parser = crs_service::paths::parse_config)]
    plant: PathBuf,
    /// Drive bus configuration (TOML): transport, SYNC period, the winches' length <-> counts
    /// scaling (the same file drive-io reads).
    #[arg(long, default_value = "config/drives.toml", value_parser = crs_service::paths::parse_config)]
    drives: PathBuf,
    /// Platform TOML of the CONTROL model whose φ(home) the drives read at start (default: the
    /// plant's nominal platform). Must be the one motion-core runs.
    #[arg(long)]
    control_platform: Option<PathBuf>,
    /// Override an interface's transport: `NAME=SPEC` per interface, or a bare SPEC when the
    /// drives config has one interface (socketcan:vcan0, udpbus:239.255.70.1:20000, wire:PATH).
    #[arg(long)]
    transport: Vec<String>,
    /// iceoryx2 service-name prefix (default: $CRS_IPC_PREFIX or none).
    #[arg(long)]
    ipc_prefix: Option<String>,
    /// Plant cycle while no SYNC arrives (µs); with SYNC the plant steps once per SYNC.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u32).range(100..=100_000))]
    period_us: u32,
    /// Re-solve the equilibrium only when a held cable length moved by more than this (m).
    #[arg(long, default_value_t = 1e-7)]
    resolve_epsilon_m: f64,
    /// Initial cable forces at the home pose (N), comma separated, one per cable. Default: the
    /// control platform's `home.f_ini_n`, else (f_min + f_max)/2 projected (eq. 3.19 / 3.41).
    #[arg(long, value_delimiter = ',')]
    f_ini_n: Option<Vec<f64>>,
    /// Lengths the drives read at the home pose after homing (m), comma separated, one per
    /// cable: the controller's full command there. Default: φ(home) of the control platform
    /// (a controller without surrogate); with a surrogate pass φ(home) + φ_sg(home) (eq. 5.26),
    /// as `crs sim` does, so the first setpoint equals the drives' positions.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    home_lengths_m: Option<Vec<f64>>,
    /// The operator's hand on the safety I/O node (drives.toml `[safety_io]`): re-read this
    /// file every 20 ms; a line `reset_key on` turns the reset key (the monitor resets when it
    /// is released again: `off`, or the line removed), `estop pressed` opens the e-stop
    /// circuit. A missing file: key at rest, e-stop released (`crs sim` prints the path).
    #[arg(long)]
    io_control: Option<std::path::PathBuf>,
    /// Run the plant loop as SCHED_FIFO with this priority (1..=99) and mlockall.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    rt_priority: Option<i32>,
    /// Pin the plant loop to this CPU (with --rt-priority).
    #[arg(long)]
    cpu: Option<usize>,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

fn main() -> ExitCode {
    if let Some(code) = crs_service::gen_man_if_asked("sim-plant", Args::command) {
        return code;
    }
    crs_log::init("sim-plant");
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sim-plant: error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `--io-control`: the safety I/O node's inputs from a file (see [`Args`]).
fn io_control_loop(path: &std::path::Path, inputs: &std::sync::atomic::AtomicU8) {
    let mut last = None;
    while !STOP.load(Ordering::Relaxed) {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        let mut v = 0u8;
        for (n, line) in text.lines().enumerate() {
            match line.split_whitespace().collect::<Vec<_>>().as_slice() {
                [] => {}
                [c, ..] if c.starts_with('#') => {}
                ["reset_key", "on"] => v |= 2,
                ["reset_key", "off"] | ["estop", "released"] => {}
                ["estop", "pressed"] => v |= 1,
                _ => tracing::error!(
                    "{}:{}: expected `reset_key on|off` or `estop pressed|released`",
                    path.display(),
                    n + 1
                ),
            }
        }
        if last != Some(v) {
            inputs.store(v, std::sync::atomic::Ordering::Release);
            tracing::info!(
                reset_key = v & 2 != 0,
                estop_pressed = v & 1 != 0,
                "safety I/O node inputs (--io-control)"
            );
            last = Some(v);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

type BoxError = Box<dyn std::error::Error>;

/// The daemon as its lifecycle: configure (files, the oracle check, the plant at home),
/// activate (signals, iceoryx2, the buses, real time, systemd), run (the plant loop until a
/// signal), deactivate.
fn run(args: Args) -> Result<(), BoxError> {
    let configured = configure(&args)?;
    let mut active = activate(&args, configured)?;
    let summary = run_plant(&mut active, &args);
    deactivate(active, summary)
}

/// The configured plant: set up at the home pose, nothing opened yet.
struct Configured {
    plant: PlantBus,
    /// One transport per drive-bus interface.
    specs: Vec<TransportSpec>,
}

/// Reads the plant, drives and control platform files, proves the plant's equilibrium against
/// the independent oracle and sets the plant up at the home pose.
fn configure(args: &Args) -> Result<Configured, BoxError> {
    let plant_file = args.plant.display().to_string();
    let drives_file = args.drives.display().to_string();
    // Plant TOML errors carry file:line:column and the key (motion-core's ConfigError).
    let plant_cfg = load_plant(&args.plant)?;
    let mut drives = DrivesConfig::load(&args.drives).map_err(|e| format!("{drives_file}: {e}"))?;
    drives
        .override_transports(&args.transport)
        .map_err(|e| format!("--transport {:?}: {e}", args.transport))?;
    let specs = drives
        .transports()
        .map_err(|e| format!("{drives_file}: {e}"))?;
    let (control, control_file) = match &args.control_platform {
        Some(p) => (load_platform(p)?, p.display().to_string()),
        None => (
            plant_cfg.platform.clone(),
            plant_cfg.platform_path.display().to_string(),
        ),
    };
    let mut opts = BusOptions::new(&drives, &control);
    opts.resolve_epsilon_m = args.resolve_epsilon_m;
    opts.f_ini_n = args.f_ini_n.clone();
    opts.home_lengths_m = args.home_lengths_m.clone();
    opts.files = ConfigFiles {
        plant: plant_file.clone(),
        control: control_file.clone(),
        drives: drives_file.clone(),
    };
    // The ground truth proves its equilibrium against the independent formulation before it
    // serves as one: an error in the equations it shares with the controller shows here.
    let oracle = sim_plant::oracle_check::check_against_oracle(&plant_cfg)
        .map_err(|e| format!("{plant_file}: the oracle check could not run: {e}"))?;
    if !oracle.within_tolerance() {
        return Err(format!(
            "{plant_file}: the plant's equilibrium disagrees with the independent oracle \
             (minimum potential energy): {oracle}"
        )
        .into());
    }
    tracing::info!(agreement = %oracle, "equilibrium agrees with the independent oracle (minimum potential energy)");
    let name = plant_cfg.name.clone();
    let effects = plant_cfg.effects.enabled_names().join(", ");
    let plant = PlantBus::new(plant_cfg, &control, &drives, opts)?;
    let (lo, hi) = plant
        .q_off()
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let (dp, dr) = plant.equilibrium().pose.error_to(plant.home());
    tracing::info!(
        plant = %name,
        effects = if effects.is_empty() { "none" } else { effects.as_str() },
        control = %control_file,
        drives = %drives_file,
        cables = plant.m(),
        "plant set up at the home pose"
    );
    tracing::info!(
        home = ?plant.home().to_array(),
        pose_error_mm = dp * 1e3,
        rotation_error_deg = dr.to_degrees(),
        forces_n = ?plant.setup().forces,
        home_lengths_m = ?plant.home_drive_lengths(),
        q_off_min_mm = lo * 1e3,
        q_off_max_mm = hi * 1e3,
        "initial tension set (eq. 3.19); encoders homed so the drives read q_home (eq. 3.14/6.24)"
    );
    Ok(Configured { plant, specs })
}

/// The running daemon's resources. Field order is drop order: the publishers go before the
/// iceoryx2 node that made them.
struct Active {
    plant: PlantBus,
    buses: Vec<Box<dyn CanBus>>,
    truth_pub: TopicPublisher<PlantTruth>,
    tracker_pub: TopicPublisher<TrackerPose>,
    heartbeat_pub: TopicPublisher<Heartbeat>,
    /// Plant steps, for the systemd watchdog.
    steps: crs_service::CycleCounter,
    watchdog: Option<crs_service::Watchdog>,
    _ipc: IpcNode,
}

/// Installs the signal handlers, opens the iceoryx2 ports and the buses, starts the
/// `--io-control` reader, applies the real-time settings and tells systemd it is ready.
fn activate(args: &Args, configured: Configured) -> Result<Active, BoxError> {
    let Configured { plant, specs } = configured;
    // SAFETY: the handler only stores to an atomic (async-signal-safe).
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
    let ipc = match &args.ipc_prefix {
        Some(p) => IpcNode::with_prefix("sim-plant", p)?,
        None => IpcNode::new("sim-plant")?,
    };
    let truth_pub = ipc.publisher::<PlantTruth>()?;
    let tracker_pub = ipc.publisher::<TrackerPose>()?;
    let heartbeat_pub = ipc.publisher::<Heartbeat>()?;
    let buses = specs
        .iter()
        .map(|spec| can_transport::open(spec).map_err(|e| format!("transport {spec}: {e}")))
        .collect::<Result<Vec<_>, _>>()?;
    if let Some(path) = args.io_control.clone() {
        let inputs = plant.io_inputs();
        std::thread::spawn(move || io_control_loop(&path, &inputs));
    }
    if let Some(p) = args.rt_priority {
        crs_rt::make_realtime(p, args.cpu)?;
        tracing::info!(priority = p, cpu = ?args.cpu, "SCHED_FIFO + mlockall");
    }
    tracing::info!(
        transports = %specs.iter().map(ToString::to_string).collect::<Vec<_>>().join(", "),
        period_us = args.period_us,
        truth = truth_pub.service_name(),
        tracker = tracker_pub.service_name(),
        "sim-plant running"
    );
    // systemd (Type=notify): ready once its CAN sockets and iceoryx2 ports are open; the
    // watchdog pings only while the plant steps.
    let steps = crs_service::CycleCounter::new();
    let watchdog = crs_service::Watchdog::spawn({
        let steps = steps.clone();
        move || steps.get()
    })?;
    crs_service::notify_ready("CAN interfaces and iceoryx2 ports open, plant stepping");
    Ok(Active {
        plant,
        buses,
        truth_pub,
        tracker_pub,
        heartbeat_pub,
        steps,
        watchdog,
        _ipc: ipc,
    })
}

/// The plant loop until SIGINT / SIGTERM: every step publishes the ground truth and the
/// tracker pose (failures logged, never fatal), logs brake and convergence changes and sends
/// the plant's heartbeat every 100th step.
fn run_plant(a: &mut Active, args: &Args) -> Result<LoopSummary, CanError> {
    let mut publish_errors = 0u64;
    let mut was_braked = None;
    let mut was_converged = true;
    let (steps, truth_pub, tracker_pub, heartbeat_pub) =
        (&a.steps, &a.truth_pub, &a.tracker_pub, &a.heartbeat_pub);
    bus::run(
        &mut a.buses,
        &mut a.plant,
        Duration::from_micros(u64::from(args.period_us)),
        &STOP,
        |truth, tracker| {
            steps.tick();
            let r = truth_pub
                .publish(truth)
                .and_then(|()| tracker_pub.publish(tracker));
            if let Err(e) = r {
                // Log the first and then every 1000th failure: never flood, never stop the plant.
                if publish_errors.is_multiple_of(1000) {
                    tracing::warn!(error = %e, count = publish_errors + 1, "publishing failed");
                }
                publish_errors += 1;
            }
            let braked = truth.braked != 0;
            if was_braked != Some(braked) {
                tracing::info!(
                    braked,
                    "winch brakes {}",
                    if braked { "engaged" } else { "released" }
                );
                was_braked = Some(braked);
            }
            if was_converged && truth.converged == 0 {
                tracing::warn!("plant truth: converged = 0");
            }
            was_converged = truth.converged != 0;
            if truth.sequence.is_multiple_of(100) {
                let state = if truth.braked != 0 {
                    crs_ipc::PlantState::Braked
                } else {
                    crs_ipc::PlantState::Free
                };
                let hb = Heartbeat::plant(state, truth.sequence);
                let _ = heartbeat_pub.publish(&hb);
            }
        },
    )
}

/// Tells systemd the daemon is stopping, stops the watchdog and reports how the loop ended.
fn deactivate(a: Active, summary: Result<LoopSummary, CanError>) -> Result<(), BoxError> {
    crs_service::notify_stopping();
    if let Some(w) = a.watchdog {
        w.stop();
    }
    let summary = summary?;
    tracing::info!(?summary, "sim-plant stopped");
    Ok(())
}
