//! `can-wire`: runs the wire model of one or more CAN buses and connects the stack to it.

use can_wire::{BusSpec, Hub, HubConfig};
use clap::Parser;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

#[derive(Parser)]
#[command(
    about = "The CAN bus as it is on the wire: bit time, arbitration and transmit queues for the stack's processes",
    long_about = "Runs the bus model for every --bus in real time. Host: processes connect with the \
                  transport wire:<socket path>. Guest (vcan): every node writes to its own \
                  interface, the hub forwards to the others at each frame's end of frame. \
                  Prints `ready` once every socket and interface is open."
)]
struct Args {
    /// A bus: name=can0,bitrate=1000000,socket=PATH (host) or ports=vcan10+vcan11 (guest);
    /// optional queue=10 (frames a node holds not yet off the wire), nodes=32, ids=128.
    #[arg(long = "bus", required = true)]
    buses: Vec<BusSpec>,
    /// Statistics JSON, rewritten about once per second and at exit.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Statistics period, ms.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(100..=60_000))]
    stats_period_ms: u64,
    /// Hub time runs this far behind the clock, µs: a submission reaching the hub within it
    /// still competes at its stamp.
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u64).range(0..=100_000))]
    lookahead_us: u64,
    /// Wake this long after the earliest due event and handle everything due by then in one
    /// pass, µs: fewer wake-ups (CPU), deliveries up to this late in real time (stamps stay
    /// exact; a node's answer to a late delivery is stamped late). 0: every event on time.
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u64).range(0..=10_000))]
    coalesce_us: u64,
    /// Written (with "ready") once every socket and interface is open.
    #[arg(long)]
    ready_file: Option<PathBuf>,
    /// SCHED_FIFO priority of the hub thread (1..=99; 0: SCHED_OTHER). Degrades with a
    /// warning when not permitted.
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(i32).range(0..=99))]
    rt_priority: i32,
    /// Pin the hub thread to this CPU.
    #[arg(long)]
    cpu: Option<usize>,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

fn main() -> ExitCode {
    crs_log::init("can-wire");
    let args = Args::parse();
    match run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("can-wire: error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> Result<(), Box<dyn std::error::Error>> {
    let cfg = HubConfig {
        buses: args.buses,
        lookahead_ns: args.lookahead_us * 1000,
        coalesce_ns: args.coalesce_us * 1000,
        stats_path: args.stats,
        stats_period_ns: args.stats_period_ms * 1_000_000,
        ready_file: args.ready_file,
    };
    cfg.validate()?;
    // SAFETY: the handler only stores to an atomic (async-signal-safe).
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
    let rt = crs_rt::apply(&crs_rt::RealtimeSettings {
        period_ns: 0,
        priority: args.rt_priority,
        cpu: args.cpu,
        lock_memory: args.rt_priority > 0,
        timer_slack_ns: 1,
    });
    for (what, a) in rt.lines() {
        match a {
            crs_rt::Applied::Degraded(_) => tracing::warn!("real time: {what}: {a}"),
            _ => tracing::info!("real time: {what}: {a}"),
        }
    }
    let scheduler = rt.scheduler.to_string();
    let hub = Hub::open(cfg.clone(), scheduler)?;
    for b in &cfg.buses {
        tracing::info!(
            bus = %b.name,
            bitrate_bps = b.bitrate_bps,
            queue_len = b.queue_len,
            endpoint = ?b.endpoint,
            "bus open"
        );
    }
    if let Some(p) = &cfg.ready_file {
        let tmp = p.with_extension("tmp");
        std::fs::write(&tmp, "ready\n")?;
        std::fs::rename(&tmp, p)?;
    }
    println!("ready");
    use std::io::Write;
    std::io::stdout().flush()?;
    hub.run(&STOP)?;
    Ok(())
}
