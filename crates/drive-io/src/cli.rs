//! The drive-io daemon's command line and process (`src/bin/drive-io.rs` is only its
//! `main`). Shared with the bench-only `drive-io-bench` of crates/drive-rig, which is the ONLY
//! way to run without the safety monitor's heartbeat ([`Bench`]): the production binary has no
//! switch for it.

use crate::runner;
use clap::Parser;
use drives_config::DrivesConfig;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

/// Whether a configuration without `[safety_heartbeat]` may run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bench {
    /// The production binary: refused (the heartbeat is mandatory).
    Refused,
    /// `drive-io-bench` (crates/drive-rig): runs, logged as an error at start.
    WithoutSafetyHeartbeat,
}

#[derive(Parser)]
#[command(about = "CANopen CiA 402 master for the cable-robot winch drives (CSP, 1 ms SYNC)")]
pub struct Args {
    /// Drive bus configuration (TOML; `config/…` is looked up by the stack's rule:
    /// $CRS_CONFIG_DIR, ./config, else /etc/crs/config).
    #[arg(long, default_value = "config/drives.toml", value_parser = crs_service::paths::parse_config)]
    config: PathBuf,
    /// Override an interface's transport: `NAME=SPEC` (repeat per interface), or a bare SPEC
    /// when the configuration has one interface (e.g. socketcan:can0, wire:/run/crs/can0.sock).
    #[arg(long)]
    transport: Vec<String>,
    /// iceoryx2 service-name prefix (default: $CRS_IPC_PREFIX or none).
    #[arg(long)]
    ipc_prefix: Option<String>,
    /// Run the SYNC loop as SCHED_FIFO with this priority (1..=99) and mlockall.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    rt_priority: Option<i32>,
    /// Pin the SYNC loop to this CPU (with --rt-priority).
    #[arg(long)]
    cpu: Option<usize>,
    /// Override `bus.eds`: the drives' EDS (CiA 306) to configure them from.
    #[arg(long)]
    eds: Option<String>,
    /// Override `bus.dcf_dir`: write node<NN>.dcf of every configured drive here.
    #[arg(long)]
    dcf_dir: Option<String>,
    /// Print the start-up SDO script of every drive (from the EDS and the TOML) and exit,
    /// without touching the bus.
    #[arg(long)]
    print_plan: bool,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Runs the daemon (or `--print-plan`) until SIGINT/SIGTERM. `bench`: what a configuration
/// without `[safety_heartbeat]` does (the production binary refuses it).
pub fn run(args: Args, bench: Bench) -> Result<(), Box<dyn std::error::Error>> {
    let mut cfg = DrivesConfig::load(&args.config)?;
    cfg.override_transports(&args.transport)?;
    if let Some(e) = args.eds {
        // A path given on the command line is relative to the working directory.
        cfg.bus.eds = Some(std::path::absolute(e)?.display().to_string());
    }
    if let Some(d) = args.dcf_dir {
        cfg.bus.dcf_dir = Some(std::path::absolute(d)?.display().to_string());
    }
    if args.print_plan {
        return print_plan(&cfg);
    }
    let specs = cfg.transports()?;
    if cfg.require_safety_heartbeat(bench == Bench::WithoutSafetyHeartbeat)? {
        tracing::error!(
            "BENCH EXECUTABLE {}: running WITHOUT the safety monitor's heartbeat; a dead or \
             absent monitor does not stop the drives. Never use this on the robot.",
            drives_config::BENCH_EXECUTABLE
        );
        eprintln!(
            "drive-io: WARNING: {}: no safety heartbeat validation",
            drives_config::BENCH_EXECUTABLE
        );
    }
    // SAFETY: the handler only stores to an atomic (async-signal-safe).
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
    let ipc = match args.ipc_prefix {
        Some(p) => crs_ipc::IpcNode::with_prefix("drive-io", &p)?,
        None => crs_ipc::IpcNode::new("drive-io")?,
    };
    let mut buses: Vec<Box<dyn can_transport::CanBus>> = Vec::with_capacity(specs.len());
    for spec in &specs {
        let bus = can_transport::open(spec)?;
        buses.push(match &cfg.bus.candump_log {
            // One file for every interface (append mode: each interface's lines stay whole,
            // their order across interfaces is that of the buffer flushes).
            Some(path) => Box::new(can_transport::LoggingBus::create(bus, path.as_ref())?),
            None => bus,
        });
    }
    if let Some(p) = args.rt_priority {
        crs_rt::make_realtime(p, args.cpu)?;
        tracing::info!(priority = p, cpu = ?args.cpu, "SCHED_FIFO + mlockall");
    }
    for (itf, spec) in cfg.interfaces().iter().zip(&specs) {
        tracing::info!(interface = %itf.name, transport = %spec, "CAN interface");
    }
    tracing::info!(drives = cfg.winches.len(), "drive-io starting");
    // systemd: READY=1 comes from the runner once the drives are operational; the watchdog pings only
    // while the SYNC loop's cycle count advances.
    let watchdog = crs_service::Watchdog::spawn(|| {
        runner::CYCLES_RUN.load(std::sync::atomic::Ordering::Relaxed)
    })?;
    let summary = runner::run(&cfg, buses, &ipc, &STOP);
    crs_service::notify_stopping();
    if let Some(w) = watchdog {
        w.stop();
    }
    let summary = summary?;
    tracing::info!(?summary, "drive-io stopped");
    Ok(())
}

/// `--print-plan`: what drive-io will check, write and read back in every drive and force
/// sensor, with EDS names, and the PDO frames each puts on the bus.
fn print_plan(cfg: &DrivesConfig) -> Result<(), Box<dyn std::error::Error>> {
    use drive_bus::mapping::{Direction, Transmission};
    use drive_commissioning::commissioning::SdoOp;
    use std::fmt::Write as _;
    // Written at once at the end: a reader that closes the pipe early (`| head`) ends the
    // output, not the process with a panic.
    let mut out = String::new();
    let plans = drive_commissioning::commissioning::plan_all(cfg, None)?;
    for plan in &plans {
        let (n, eds) = (plan.node, &plan.eds);
        writeln!(
            out,
            "# {} node {n} ({}), EDS {} ({} SDO transfers)",
            plan.kind,
            plan.key,
            eds.file,
            plan.ops.len()
        )?;
        for op in &plan.ops {
            let (index, sub) = op.index_sub();
            let text = |at, len| String::from_utf8_lossy(plan.bytes(at, len)).into_owned();
            // Signed objects as signed decimals, the rest as the hex the drive manuals use.
            let num = |v: u32| match eds.entry(index, sub).map(|e| e.data_type) {
                Some(t) if t.is_signed() => t.to_i64(v).to_string(),
                _ => format!("0x{v:08X}"),
            };
            let (what, value) = match *op {
                SdoOp::Write { value, .. } => ("write ", num(value)),
                SdoOp::Verify { value, .. } => ("verify", num(value)),
                SdoOp::Check { value, .. } => ("check ", num(value)),
                SdoOp::WriteBytes { at, len, .. } => ("write ", format!("{:?}", text(at, len))),
                SdoOp::VerifyBytes { at, len, check, .. } => (
                    if check { "check " } else { "verify" },
                    format!("{:?}", text(at, len)),
                ),
                SdoOp::Read { .. } => ("read  ", String::new()),
            };
            writeln!(out, "{n:3} {what} {value:10}  {}", eds.describe(index, sub))?;
        }
        for f in plan.pdo_frames() {
            let dir = match f.direction {
                Direction::ToNode => "RPDO (drive-io sends)",
                Direction::FromNode => "TPDO (node sends)",
            };
            let when = match f.transmission {
                Transmission::Sync { every: 1 } => "every SYNC".to_string(),
                Transmission::Sync { every } => format!("every {every}th SYNC"),
                Transmission::Event {
                    inhibit_us,
                    event_timer_ms,
                } => format!("on change, inhibit {inhibit_us} us, event timer {event_timer_ms} ms"),
            };
            writeln!(
                out,
                "{n:3} frame  0x{:03X} DLC {} {dir}, {when}{}",
                f.cob_id,
                f.dlc,
                if f.used {
                    ""
                } else {
                    " (unused, cannot be disabled)"
                }
            )?;
        }
    }
    // The bus budget of every interface with these frames (docs/can-protocol.md "Bus budget").
    let budgets = drive_commissioning::budget::of_plans(cfg, &plans);
    for ib in &budgets {
        write!(out, "{ib}")?;
    }
    write_stdout(&out)?;
    for ib in &budgets {
        ib.check()?;
    }
    Ok(())
}

/// Writes `text` to stdout; a closed pipe is the reader's choice, not an error.
fn write_stdout(text: &str) -> std::io::Result<()> {
    use std::io::Write as _;
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => r,
    }
}
