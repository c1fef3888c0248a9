//! Bench: setpoint published (iceoryx2) -> RPDO written to the bus by drive-io, at 1 kHz.
//!
//! drive-io (the real runner) and the winch emulator run as threads on a CAN-over-UDP multicast
//! bus; a publisher thread plays motion-core with an absolute 1 ms clock_nanosleep loop. Latency
//! per setpoint = `DriveFeedback.applied_setpoint_write_ns - JointSetpoint.timestamp_ns`
//! (both CLOCK_MONOTONIC). It includes the wait for drive-io's next SYNC tick (the two 1 ms loops
//! are not phase-locked), so it is also reported split: tick -> RPDO written (drive-io's own
//! processing) = `applied_setpoint_write_ns - DriveFeedback.timestamp_ns`.
//!
//! Issue 20 item 3: the free-running design (`sync_source = "clock"`) and the phase-locked one
//! (`"setpoint"`: drive-io starts its cycle on motion-core's "setpoint published" event) run one
//! after the other in ONE run, same load, same host; by default a thread spins on cpu 0 ("the
//! other core loaded") while the stack's threads are pinned to cpu 1.
//!
//! usage: bus-latency-bench [--seconds 30] [--modes clock,setpoint] [--no-load]
//!        [--rt-priority 80] [--transport udpbus:239.255.70.3:41000]

use clap::Parser;
use crs_ipc::{DriveFeedback, IpcNode, JointSetpoint, MAX_CABLES, monotonic_ns};
use drive_io::config::SyncSource;
use drive_io::emulator::{self, EmulatorConfig, EmulatorControl};
use drive_io::{hil, runner};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

#[derive(Parser)]
struct Args {
    /// Seconds per mode.
    #[arg(long, default_value_t = 30)]
    seconds: u64,
    /// UDP bus of the first mode; the next mode uses port + 1.
    #[arg(long, default_value = "udpbus:239.255.70.3:41000")]
    transport: String,
    /// The cycle designs to compare, one after the other in this run.
    #[arg(long, value_delimiter = ',', default_value = "clock,setpoint")]
    modes: Vec<SyncSource>,
    /// Spin a load thread on this cpu during the whole run ("the other core loaded").
    #[arg(long, default_value = "0")]
    load_cpu: Option<usize>,
    /// Run without the load thread.
    #[arg(long, conflicts_with = "load_cpu")]
    no_load: bool,
    /// Pin the stack's threads (publisher, drive-io, emulator) to this cpu.
    #[arg(long, default_value_t = 1)]
    stack_cpu: usize,
    /// SCHED_FIFO priority of drive-io (the publisher one below), with mlockall; needs root.
    #[arg(long)]
    rt_priority: Option<i32>,
}

const RING: usize = 8192;

fn pct(v: &mut [u64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_unstable();
    let i = ((v.len() as f64 - 1.0) * p).round() as usize;
    v[i] as f64 / 1000.0
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = Args::parse();
    if args.no_load {
        args.load_cpu = None;
    }
    if args.load_cpu.is_some_and(|c| c == args.stack_cpu) {
        return Err("--load-cpu and --stack-cpu must differ".into());
    }
    // The load: one thread spinning on the other core for the whole run.
    let load_stop = Arc::new(AtomicBool::new(false));
    let load = args.load_cpu.map(|cpu| {
        let stop = load_stop.clone();
        std::thread::spawn(move || {
            pin(cpu);
            let mut x = 0u64;
            while !stop.load(Ordering::Relaxed) {
                x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
            }
        })
    });
    let mut results = Vec::new();
    for (k, mode) in args.modes.iter().enumerate() {
        let transport = with_port_offset(&args.transport, k as u16)?;
        results.push((*mode, run_mode(&args, *mode, &transport)?));
    }
    load_stop.store(true, Ordering::Relaxed);
    if let Some(l) = load {
        let _ = l.join();
    }
    println!(
        "\n{} s per mode at 1 kHz, transport {}, stack threads on cpu {}, {}, {}",
        args.seconds,
        args.transport,
        args.stack_cpu,
        match args.load_cpu {
            Some(c) => format!("a spinning load on cpu {c}"),
            None => "no load thread".into(),
        },
        match args.rt_priority {
            Some(p) => format!("SCHED_FIFO {p} (drive-io) / {} (publisher)", p - 1),
            None => "SCHED_OTHER".into(),
        }
    );
    println!(
        "| sync_source | published -> RPDOs+SYNC written p50 | p99 | p99.9 | max | cycle start -> written p99 | cycles by setpoint / by clock | overruns |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (mode, r) in &results {
        println!(
            "| {} | {:.1} µs | {:.1} µs | {:.1} µs | {:.1} µs | {:.1} µs | {} / {} | {} |",
            match mode {
                SyncSource::Isochronous => "isochronous (SYNC is the bus clock)",
                SyncSource::Setpoint => "setpoint (phase-locked)",
                SyncSource::Clock => "clock (free-running)",
            },
            r.p50,
            r.p99,
            r.p999,
            r.max,
            r.processing_p99,
            r.summary.setpoint_cycles,
            r.summary.clock_cycles,
            r.summary.overruns
        );
    }
    for (mode, r) in &results {
        println!(
            "{mode:?}: {} setpoints published, {} applied and measured, {} feedback samples not Running, tx_full {}, final state {:?}",
            r.published, r.measured, r.not_running, r.summary.tx_full_drops, r.summary.final_state
        );
    }
    Ok(())
}

/// The same multicast group on port + k: each mode on its own bus.
fn with_port_offset(transport: &str, k: u16) -> Result<String, String> {
    let (head, port) = transport
        .rsplit_once(':')
        .ok_or_else(|| format!("--transport {transport:?}: expected udpbus:<group>:<port>"))?;
    let port: u16 = port
        .parse()
        .map_err(|_| format!("--transport {transport:?}: bad port"))?;
    Ok(format!("{head}:{}", port + k))
}

/// Pins the calling thread; a refusal is reported and the bench goes on unpinned (its output
/// states the placement it asked for, so the reader can judge the figures).
fn pin(cpu: usize) {
    if let Err(e) = crs_rt::pin_to_cpu(cpu) {
        eprintln!("pinning to cpu {cpu} failed: {e}");
    }
}

/// Pins (and with `rt`, SCHED_FIFO + mlockall) the calling thread. crs-rt attempts every
/// setting even when one is refused, so the thread is pinned whatever else was granted; the
/// error lists what was not.
fn place(cpu: usize, rt: Option<i32>) {
    match rt {
        Some(p) => {
            if let Err(e) = crs_rt::make_realtime(p, Some(cpu)) {
                eprintln!("{e}: the bench runs without it");
            }
        }
        None => pin(cpu),
    }
}

struct ModeResult {
    p50: f64,
    p99: f64,
    p999: f64,
    max: f64,
    processing_p99: f64,
    published: u64,
    measured: usize,
    not_running: u64,
    summary: runner::RunSummary,
}

fn run_mode(
    args: &Args,
    mode: SyncSource,
    transport: &str,
) -> Result<ModeResult, Box<dyn std::error::Error>> {
    let mut cfg = hil::hil_config(transport);
    cfg.bus.sync_source = mode;
    let spec = cfg.transport()?;
    let prefix = format!("bench/{}/{mode:?}/", std::process::id());
    let control = EmulatorControl::new();
    let mut ecfg = EmulatorConfig::from_drives(&cfg, 5.0)?;
    ecfg.initial_length_m = vec![5.0; cfg.winches.len()];
    let emu_bus = can_transport::open(&spec)?;
    let dio_bus = can_transport::open(&spec)?;
    let c2 = control.clone();
    let cpu = args.stack_cpu;
    let rt = args.rt_priority;
    let emu = std::thread::spawn(move || {
        pin(cpu);
        emulator::run(vec![emu_bus], &ecfg, &c2)
    });
    let stop = Arc::new(AtomicBool::new(false));
    let (s2, cfg2, p2) = (stop.clone(), cfg.clone(), prefix.clone());
    let dio = std::thread::spawn(move || -> Result<runner::RunSummary, String> {
        place(cpu, rt);
        let ipc = IpcNode::with_prefix("drive-io", &p2).map_err(|e| e.to_string())?;
        runner::run(&cfg2, vec![dio_bus], &ipc, &s2).map_err(|e| e.to_string())
    });
    let node = IpcNode::with_prefix("bench", &prefix)?;
    let fb = node.subscriber::<DriveFeedback>()?;
    // Wait for Ready.
    let t0 = std::time::Instant::now();
    let init: [f64; MAX_CABLES];
    loop {
        if let Some(f) = fb.latest()?
            && f.bus_state == crs_ipc::BusState::Ready as u32
        {
            init = f.cable_length_m;
            break;
        }
        if t0.elapsed() > Duration::from_secs(30) {
            return Err("drive-io did not reach Ready".into());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let stamps: Arc<Vec<AtomicU64>> = Arc::new((0..RING).map(|_| AtomicU64::new(0)).collect());
    let done = Arc::new(AtomicBool::new(false));
    let (st2, d2, p3, m) = (
        stamps.clone(),
        done.clone(),
        prefix.clone(),
        cfg.winches.len(),
    );
    let secs = args.seconds;
    // Plays motion-core's publish stage: publish, then notify (in both modes, as motion-core
    // always does; in clock mode drive-io does not listen).
    let publisher = std::thread::spawn(move || -> Result<u64, String> {
        place(cpu, rt.map(|p| p - 1));
        // Timer slack 1 ns, as drive-io's runner sets for its own loop (kernel default 50 µs).
        if let Err(e) = crs_rt::set_timer_slack(1) {
            eprintln!("timer slack not tightened: {e}");
        }
        let node = IpcNode::with_prefix("bench-pub", &p3).map_err(|e| e.to_string())?;
        let p = node
            .publisher::<JointSetpoint>()
            .map_err(|e| e.to_string())?;
        let ready = node.setpoint_ready_notifier().map_err(|e| e.to_string())?;
        let n = secs * 1000;
        let mut next = monotonic_ns() + 1_000_000;
        for seq in 1..=n {
            crs_rt::sleep_until(next);
            next += 1_000_000;
            let t = seq as f64 * 1e-3;
            let mut sp = JointSetpoint {
                cable_count: m as u32,
                sequence: seq,
                ..Default::default()
            };
            for (l, l0) in sp.cable_length_m.iter_mut().zip(init).take(m) {
                *l = l0 + 0.05 * (1.0 - (t * 0.5).cos());
            }
            sp.timestamp_ns = monotonic_ns();
            st2[(seq as usize) % RING].store(sp.timestamp_ns, Ordering::Release);
            p.publish(&sp).map_err(|e| e.to_string())?;
            ready.notify().map_err(|e| e.to_string())?;
        }
        d2.store(true, Ordering::Release);
        Ok(n)
    });
    let mut total = Vec::with_capacity(args.seconds as usize * 1000);
    let mut processing = Vec::with_capacity(args.seconds as usize * 1000);
    let mut last_seq = 0;
    let mut not_running = 0u64;
    while !done.load(Ordering::Acquire) {
        fb.drain(|f| {
            if f.bus_state != crs_ipc::BusState::Running as u32 {
                not_running += 1;
            }
            let s = f.applied_setpoint_sequence;
            if s > last_seq {
                last_seq = s;
                let ts = stamps[(s as usize) % RING].load(Ordering::Acquire);
                if ts != 0 && f.applied_setpoint_write_ns >= ts {
                    total.push(f.applied_setpoint_write_ns - ts);
                    processing.push(f.applied_setpoint_write_ns.saturating_sub(f.timestamp_ns));
                }
            }
        })?;
        std::thread::sleep(Duration::from_micros(500));
    }
    let published = publisher.join().map_err(|_| "publisher panicked")??;
    stop.store(true, Ordering::Release);
    let summary = dio.join().map_err(|_| "drive-io panicked")??;
    control.stop.store(true, Ordering::Release);
    emu.join().map_err(|_| "emulator panicked")??;
    let measured = total.len();
    if measured == 0 {
        return Err(format!("{mode:?}: no setpoint was applied (drive-io never ran)").into());
    }
    let max = total.iter().copied().max().unwrap_or(0) as f64 / 1000.0;
    Ok(ModeResult {
        p50: pct(&mut total, 0.5),
        p99: pct(&mut total, 0.99),
        p999: pct(&mut total, 0.999),
        max,
        processing_p99: pct(&mut processing, 0.99),
        published,
        measured,
        not_running,
        summary,
    })
}
