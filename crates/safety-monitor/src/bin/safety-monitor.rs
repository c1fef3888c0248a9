//! `safety-monitor`: the independent 15 ms safety stage (see the crate docs and
//! docs/safety-monitor.md).
//!
//! * `safety-monitor [--config F] [--transport T] [--ipc-prefix P]`: run the monitor.
//! * `safety-monitor reset [--config F] [--socket S]`: operator reset through the monitor's
//!   reset socket (this process's credentials must show the operator group); exit 0 if
//!   accepted (or nothing to reset), 1 if refused or denied.
//! * `safety-monitor identity [--config F]`: print the platform identity the monitor computes.
//! * `safety-monitor accept NEW.toml [--config F] [--yes]`: show the parameter diff of a
//!   (re)calibrated platform against the one the monitor runs; with `--yes` make it the
//!   monitor's accepted platform.

use clap::{CommandFactory, Parser, Subcommand};
use safety_monitor::daemon::{self, ResetReply};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

#[derive(Parser)]
#[command(
    name = "safety-monitor",
    about = "Independent 15 ms safety monitor: redundant kinematics check, latched e-stop, fail-safe CAN heartbeat"
)]
struct Args {
    #[command(subcommand)]
    cmd: Option<Cmd>,
    /// Monitor TOML (`config/…` is looked up by the stack's rule: $CRS_CONFIG_DIR, ./config,
    /// else /etc/crs/config).
    #[arg(long, default_value = "config/safety-monitor.toml", global = true, value_parser = crs_service::paths::parse_config)]
    config: PathBuf,
    /// Override an interface's transport: `NAME=SPEC` per interface (names from the drives
    /// file), or a bare SPEC when there is one: socketcan:<iface> | udpbus:<group>:<port> |
    /// udp:<l>-><r> | wire:<socket>.
    #[arg(long)]
    transport: Vec<String>,
    /// iceoryx2 service-name prefix (default: $CRS_IPC_PREFIX or none).
    #[arg(long, global = true)]
    ipc_prefix: Option<String>,
}

#[derive(Subcommand)]
enum Cmd {
    /// Ask the running monitor to release its latched e-stop (refused while the cause
    /// persists), through its reset socket: only members of the operator group may.
    Reset {
        /// How long to wait for the monitor's answer (ms).
        #[arg(long, default_value_t = 2000)]
        timeout_ms: u64,
        /// The reset socket (default: `[reset] socket` of --config).
        #[arg(long)]
        socket: Option<PathBuf>,
    },
    /// Print the platform identity (SHA-256) the monitor computes from the platform TOML.
    Identity,
    /// Show what a new platform file changes against the monitor's accepted one; with --yes
    /// write it as the monitor's accepted copy and pin its SHA-256 in the config.
    Accept {
        /// The candidate platform TOML (e.g. a calibration's output).
        platform: PathBuf,
        /// Accept after reviewing the diff (without it nothing is written).
        #[arg(long)]
        yes: bool,
    },
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

fn node(name: &str, prefix: &Option<String>) -> Result<crs_ipc::IpcNode, crs_ipc::IpcError> {
    match prefix {
        Some(p) => crs_ipc::IpcNode::with_prefix(name, p),
        None => crs_ipc::IpcNode::new(name),
    }
}

fn main() -> ExitCode {
    if let Some(code) = crs_service::gen_man_if_asked("safety-monitor", Args::command) {
        return code;
    }
    crs_log::init("safety-monitor");
    let args = Args::parse();
    match run(args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("safety-monitor: error: {e}");
            ExitCode::from(2)
        }
    }
}

type Res = Result<ExitCode, Box<dyn std::error::Error>>;

fn run(args: Args) -> Res {
    match args.cmd {
        Some(Cmd::Reset { timeout_ms, socket }) => reset(&args.config, timeout_ms, socket),
        Some(Cmd::Accept { platform, yes }) => accept(&args.config, &platform, yes),
        Some(Cmd::Identity) => identity(&args.config),
        None => monitor(&args),
    }
}

/// `safety-monitor reset`: asks the running monitor on its reset socket.
fn reset(config: &std::path::Path, timeout_ms: u64, socket: Option<std::path::PathBuf>) -> Res {
    let socket = match socket {
        Some(s) => s,
        None => {
            let cfg = safety_monitor::config::load(config)?;
            cfg.reset_socket.map(|(p, _)| p).ok_or_else(|| {
                format!(
                    "{}: no [reset] socket configured (the reset is the safety I/O \
                     node's key)",
                    config.display()
                )
            })?
        }
    };
    match daemon::request_reset(&socket, Duration::from_millis(timeout_ms))? {
        ResetReply::Accepted => {
            println!("reset accepted: e-stop released, drives re-enabled by drive-io");
            Ok(ExitCode::SUCCESS)
        }
        ResetReply::NotTripped => {
            println!("reset not needed: nothing was latched, nothing changed");
            Ok(ExitCode::SUCCESS)
        }
        ResetReply::NotReady => {
            println!(
                "reset REFUSED: the monitor is not ready yet (not every drive is operational \
                 with live force readings; see its log)"
            );
            Ok(ExitCode::FAILURE)
        }
        ResetReply::Refused(c) => {
            println!(
                "reset REFUSED: the cause persists ({})",
                c.map_or("unknown".to_string(), |c| c.to_string())
            );
            Ok(ExitCode::FAILURE)
        }
        ResetReply::Denied(why) => {
            println!("reset DENIED: {why}");
            Ok(ExitCode::FAILURE)
        }
        ResetReply::Exhausted => {
            println!(
                "reset REFUSED: this monitor instance has counted all the resets it can; \
                 restart it (then reset the new instance)"
            );
            Ok(ExitCode::FAILURE)
        }
    }
}

/// `safety-monitor accept`: the diff against the running platform, the copy with `--yes`.
fn accept(config: &std::path::Path, platform: &std::path::Path, yes: bool) -> Res {
    let r = safety_monitor::accept::accept(config, platform, yes)?;
    println!(
        "monitor config {}: runs {} ({})",
        config.display(),
        r.current.display(),
        r.current_status
    );
    println!("candidate {}:", platform.display());
    println!("  sha256   {}", r.new_sha256);
    println!("  identity {}", r.new_identity);
    if r.diff.is_empty() {
        println!("  no parameter differs");
    } else {
        println!("  {} parameter(s) differ:", r.diff.len());
        for l in &r.diff {
            println!("    {l}");
        }
    }
    match r.written {
        Some(copy) => {
            tracing::warn!(
                copy = %copy.display(),
                sha256 = %r.new_sha256,
                "platform ACCEPTED for the safety monitor"
            );
            println!(
                "ACCEPTED: the monitor now runs {} (sha256 {}); restart it",
                copy.display(),
                r.new_sha256
            );
            Ok(ExitCode::SUCCESS)
        }
        None => {
            println!("not accepted: review the diff, then run again with --yes");
            Ok(ExitCode::FAILURE)
        }
    }
}

/// `safety-monitor identity`: the platform identity the monitor computes.
fn identity(config: &std::path::Path) -> Res {
    let cfg = safety_monitor::config::load(config)?;
    let id = safety_monitor::identity::platform_identity(&cfg.platform);
    println!(
        "{id}  {} ({} cables)",
        cfg.platform_file.display(),
        cfg.platform.cables()
    );
    Ok(ExitCode::SUCCESS)
}

/// The monitor process itself, until SIGINT/SIGTERM.
fn monitor(args: &Args) -> Res {
    let mut cfg = safety_monitor::config::load(&args.config)?;
    cfg.override_transports(&args.transport)?;
    // SAFETY: the handler only stores to an atomic (async-signal-safe).
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
    let ipc = node("safety-monitor", &args.ipc_prefix)?;
    let (tx, rx) = daemon::open_buses(&cfg)?;
    // WATCHDOG=1 only while the 15 ms cycle advances (READY=1 comes from run_on).
    let watchdog = crs_service::Watchdog::spawn(|| {
        daemon::CYCLES_RUN.load(std::sync::atomic::Ordering::Relaxed)
    })?;
    let s = daemon::run_on(&cfg, tx, rx, &ipc, &STOP);
    crs_service::notify_stopping();
    if let Some(w) = watchdog {
        w.stop();
    }
    let s = s?;
    tracing::info!(
        ?s,
        "safety monitor stopped (the drives brake without its heartbeat)"
    );
    Ok(ExitCode::SUCCESS)
}
