//! TEST RIG (the HIL matrix's `stop_frame_lost`): the safety monitor daemon on a sending socket
//! that fails every NMT frame as on a full TX queue (ENOBUFS,
//! [`safety_monitor::stop_path::FailingSends`]), so its stop must escalate to the safety
//! heartbeat's STOP. A separate executable of this crate: the production `safety-monitor`
//! has no fault-injection switch. Logged as an error at start.
//!
//! `safety-monitor-nmt-unsent --config F [--transport NAME=SPEC ...] [--ipc-prefix P]`

use safety_monitor::daemon;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

fn main() -> ExitCode {
    crs_log::init("safety-monitor");
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("safety-monitor-nmt-unsent: error: {e}");
            ExitCode::from(2)
        }
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let mut config = None;
    let mut transports = Vec::new();
    let mut prefix = None;
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{a}: a value is missing"));
        match a.as_str() {
            "--config" => config = Some(value()?),
            "--transport" => transports.push(value()?),
            "--ipc-prefix" => prefix = Some(value()?),
            other => return Err(format!("unknown argument {other:?}").into()),
        }
    }
    let config = config.ok_or("--config is required")?;
    let mut cfg = safety_monitor::config::load(std::path::Path::new(&config))?;
    cfg.override_transports(&transports)?;
    // SAFETY: the handler only stores to an atomic (async-signal-safe).
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
    let ipc = match prefix {
        Some(p) => crs_ipc::IpcNode::with_prefix("safety-monitor", &p)?,
        None => crs_ipc::IpcNode::new("safety-monitor")?,
    };
    eprintln!("FAULT INJECTION (test rig): every NMT frame of this monitor fails to send");
    let (tx, rx) = daemon::open_buses(&cfg)?;
    let tx = tx
        .into_iter()
        .map(|b| {
            Box::new(safety_monitor::stop_path::FailingSends::new(
                b,
                u32::from(safety_monitor::bus_frames::COB_NMT),
            )) as Box<dyn can_transport::CanBus>
        })
        .collect();
    let s = daemon::run_on(&cfg, tx, rx, &ipc, &STOP)?;
    eprintln!("safety monitor (NMT unsent) stopped: {s:?}");
    Ok(())
}
