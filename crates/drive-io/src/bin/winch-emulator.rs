//! TEST DOUBLE: answers as the m CiA 402 winch drives of config/drives.toml and moves each cable
//! kinematically (5 m/s, 14 m/s^2). Not the plant: see crates/sim-plant for the physics.

use clap::Parser;
use drive_io::DrivesConfig;
use drive_io::emulator::{self, EmulatorConfig, EmulatorControl};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Duration;

#[derive(Parser)]
#[command(about = "Test double: emulates the winch drives (CiA 402 CSP) on the CAN bus")]
struct Args {
    #[arg(long, default_value = "config/drives.toml")]
    config: PathBuf,
    #[arg(long)]
    transport: Option<String>,
    /// Initial cable length of every winch (m).
    #[arg(long, default_value_t = 5.0)]
    initial_length_m: f64,
    /// Stop the heartbeat of this winch index (0-based) after --mute-after-ms (fault injection).
    #[arg(long)]
    mute_heartbeat_index: Option<usize>,
    #[arg(long, default_value_t = 0)]
    mute_after_ms: u64,
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .init();
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("winch-emulator: error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut cfg = DrivesConfig::load(&args.config)?;
    if let Some(t) = args.transport {
        cfg.bus.transport = t;
        cfg.validate()?;
    }
    if !(args.initial_length_m.is_finite() && args.initial_length_m >= 0.0) {
        return Err("--initial-length-m must be finite and >= 0".into());
    }
    if let Some(i) = args.mute_heartbeat_index
        && i >= cfg.winches.len()
    {
        return Err(format!(
            "--mute-heartbeat-index {i}: only {} winches",
            cfg.winches.len()
        )
        .into());
    }
    let ecfg = EmulatorConfig::from_drives(&cfg, args.initial_length_m);
    let bus = can_transport::open(&cfg.transport()?)?;
    let control = EmulatorControl::new();
    if let Some(i) = args.mute_heartbeat_index {
        let c = control.clone();
        std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(args.mute_after_ms));
            tracing::warn!(index = i, "muting heartbeat (fault injection)");
            c.mute_heartbeat(i);
        });
    }
    tracing::info!(
        drives = cfg.winches.len(),
        "winch emulator (test double) running"
    );
    emulator::run(bus, &ecfg, &control)?;
    control.stop.store(true, Ordering::Release);
    Ok(())
}
