//! Bench: setpoint published (iceoryx2) -> RPDO written to the bus by drive-io, at 1 kHz.
//!
//! drive-io (the real runner) and the winch emulator run as threads on a CAN-over-UDP multicast
//! bus; a publisher thread plays motion-core with an absolute 1 ms clock_nanosleep loop. Latency
//! per setpoint = `DriveFeedback.applied_setpoint_write_ns - JointSetpoint.timestamp_ns`
//! (both CLOCK_MONOTONIC). It includes the wait for drive-io's next SYNC tick (the two 1 ms loops
//! are not phase-locked), so it is also reported split: tick -> RPDO written (drive-io's own
//! processing) = `applied_setpoint_write_ns - DriveFeedback.timestamp_ns`.
//!
//! usage: bus-latency-bench [--seconds 60] [--transport udpbus:239.255.70.3:41000]

use clap::Parser;
use crs_ipc::{DriveFeedback, IpcNode, JointSetpoint, MAX_CABLES, monotonic_ns};
use drive_io::emulator::{self, EmulatorConfig, EmulatorControl};
use drive_io::{hil, runner};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

#[derive(Parser)]
struct Args {
    #[arg(long, default_value_t = 60)]
    seconds: u64,
    #[arg(long, default_value = "udpbus:239.255.70.3:41000")]
    transport: String,
}

const RING: usize = 8192;

fn sleep_until(t_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (t_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (t_ns % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: valid timespec; absolute CLOCK_MONOTONIC sleep; EINTR just returns early.
    unsafe {
        libc::clock_nanosleep(
            libc::CLOCK_MONOTONIC,
            libc::TIMER_ABSTIME,
            &ts,
            std::ptr::null_mut(),
        )
    };
}

fn pct(v: &mut [u64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_unstable();
    let i = ((v.len() as f64 - 1.0) * p).round() as usize;
    v[i] as f64 / 1000.0
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let cfg = hil::hil_config(&args.transport);
    let spec = cfg.transport()?;
    let prefix = format!("bench/{}/", std::process::id());
    let control = EmulatorControl::new();
    let mut ecfg = EmulatorConfig::from_drives(&cfg, 5.0)?;
    ecfg.initial_length_m = vec![5.0; cfg.winches.len()];
    let emu_bus = can_transport::open(&spec)?;
    let dio_bus = can_transport::open(&spec)?;
    let c2 = control.clone();
    let emu = std::thread::spawn(move || emulator::run(emu_bus, &ecfg, &c2));
    let stop = Arc::new(AtomicBool::new(false));
    let (s2, cfg2, p2) = (stop.clone(), cfg.clone(), prefix.clone());
    let dio = std::thread::spawn(move || -> Result<runner::RunSummary, String> {
        let ipc = IpcNode::with_prefix("drive-io", &p2).map_err(|e| e.to_string())?;
        runner::run(&cfg2, dio_bus, &ipc, &s2).map_err(|e| e.to_string())
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
    let publisher = std::thread::spawn(move || -> Result<u64, String> {
        runner::tighten_timer_slack();
        let node = IpcNode::with_prefix("bench-pub", &p3).map_err(|e| e.to_string())?;
        let p = node
            .publisher::<JointSetpoint>()
            .map_err(|e| e.to_string())?;
        let n = secs * 1000;
        let mut next = monotonic_ns() + 1_000_000;
        for seq in 1..=n {
            sleep_until(next);
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
    let n = total.len();
    let max_t = total.iter().copied().max().unwrap_or(0) as f64 / 1000.0;
    let max_p = processing.iter().copied().max().unwrap_or(0) as f64 / 1000.0;
    println!(
        "transport {} | {} s at 1 kHz | {published} setpoints published, {n} applied+measured",
        args.transport, args.seconds
    );
    println!(
        "setpoint published -> RPDO written (us): p50 {:.1}  p99 {:.1}  p99.9 {:.1}  max {:.1}",
        pct(&mut total, 0.5),
        pct(&mut total, 0.99),
        pct(&mut total, 0.999),
        max_t
    );
    println!(
        "drive-io SYNC tick -> RPDO written (us): p50 {:.1}  p99 {:.1}  p99.9 {:.1}  max {:.1}",
        pct(&mut processing, 0.5),
        pct(&mut processing, 0.99),
        pct(&mut processing, 0.999),
        max_p
    );
    println!(
        "drive-io cycles {} overruns {} tx_full {} final state {:?}; feedback samples not Running: {not_running}",
        summary.cycles, summary.overruns, summary.tx_full_drops, summary.final_state
    );
    Ok(())
}
