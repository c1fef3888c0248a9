//! Bench: drive-io's three cycle designs side by side in one run, on the wire model with the
//! shipped CRS layout (config/drives.toml: 8 drives and their load cells on four 1 Mbit/s
//! interfaces; the safety interface is left out: no monitor runs here).
//!
//! drive-io (the real runner) and the winch emulator (playing the drives and load cells) run as
//! threads; an in-process `can-wire` hub carries the four buses with their bit time,
//! arbitration and transmit queues; a listener node on every bus sees each frame at its end of
//! frame (the model's stamp). A publisher thread plays motion-core at 1 kHz: with
//! `sync_source = "isochronous"` it ticks `--lead-us` before each SYNC of the schedule drive-io
//! announces (as motion-core does) and publishes `--publish-phase-us` later (motion-core's
//! publish stage); with `"setpoint"` / `"clock"` it runs on its own 1 ms grid. Every setpoint
//! commands distinct targets, so each RPDO on the wire names the setpoint it carries.
//!
//! Figures per mode (all from the wire model's stamps, CLOCK_MONOTONIC):
//! * SYNC interval on bus can0: sd / min / max, intervals below 0.9 periods;
//! * setpoint published → the last RPDO carrying it off the wire (max over the 8 drives):
//!   p50 / p99 / p99.9 / max;
//! * missed cycles: setpoints whose RPDOs were not all off the wire before the first SYNC after
//!   their publication (on their bus), and setpoints never seen on the wire.
//!
//! usage: bus-latency-bench [--seconds 60] [--modes isochronous,setpoint,clock]
//!        [--rt-priority 80] [--load-cpu 0 | --no-load] [--stack-cpu 1]

use clap::Parser;
use crs_ipc::{IpcNode, JointSetpoint, MAX_CABLES, SyncSchedule, monotonic_ns};
use drive_io::config::{DrivesConfig, SyncSource};
use drive_io::runner;
use drive_rig::emulator::{self, EmulatorConfig, EmulatorControl};
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

#[derive(Parser)]
struct Args {
    /// Seconds per mode.
    #[arg(long, default_value_t = 60)]
    seconds: u64,
    /// The cycle designs to compare, one after the other in this run.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "isochronous,setpoint,clock"
    )]
    modes: Vec<SyncSource>,
    /// Drives TOML (its interfaces get the hub's sockets; the safety interface is dropped).
    #[arg(long, default_value = "config/drives.toml")]
    drives: std::path::PathBuf,
    /// Spin a load thread on this cpu during the whole run ("the other core loaded").
    #[arg(long)]
    load_cpu: Option<usize>,
    /// Pin the stack's threads (publisher, drive-io, emulator, hub, listeners) to this cpu.
    #[arg(long)]
    stack_cpu: Option<usize>,
    /// SCHED_FIFO priority of drive-io (publisher and hub one below); needs root.
    #[arg(long)]
    rt_priority: Option<i32>,
    /// Isochronous: the publisher (motion-core's loop) ticks this long before each SYNC, µs.
    #[arg(long, default_value_t = 700)]
    lead_us: u64,
    /// ... and publishes this long after its tick (motion-core's publish stage), µs.
    #[arg(long, default_value_t = 200)]
    publish_phase_us: u64,
}

const P_NS: u64 = 1_000_000;

/// One quantile definition for this bench: the nearest rank, (n − 1)·q rounded.
fn quantile(sorted: &[u64], q: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    sorted[((sorted.len() as f64 - 1.0) * q).round() as usize]
}

fn place(cpu: Option<usize>, rt: Option<i32>) {
    match (rt, cpu) {
        (Some(p), _) => {
            if let Err(e) = crs_rt::make_realtime(p, cpu) {
                eprintln!("{e}: the bench runs without it");
            }
        }
        (None, Some(c)) => {
            if let Err(e) = crs_rt::pin_to_cpu(c) {
                eprintln!("pinning to cpu {c}: {e}");
            }
        }
        (None, None) => {}
    }
}

/// What the listeners saw on one bus.
#[derive(Default)]
struct Seen {
    /// End-of-frame stamps of the SYNCs.
    syncs: Vec<u64>,
    /// (drive index, target counts, end of frame) of every RPDO.
    rpdos: Vec<(usize, i32, u64)>,
}

struct ModeResult {
    sync_sd_us: f64,
    sync_min_us: f64,
    sync_max_us: f64,
    short_intervals: usize,
    intervals: usize,
    lat: Option<[f64; 4]>,
    measured: usize,
    missed: usize,
    never: usize,
    published: usize,
    rpdo_wire_us: f64,
    summary: runner::RunSummary,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    if args.load_cpu.is_some() && args.load_cpu == args.stack_cpu {
        return Err("--load-cpu and --stack-cpu must differ".into());
    }
    let load_stop = Arc::new(AtomicBool::new(false));
    let load = args.load_cpu.map(|cpu| {
        let stop = load_stop.clone();
        std::thread::spawn(move || {
            place(Some(cpu), None);
            let mut x = 0u64;
            while !stop.load(Ordering::Relaxed) {
                x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
            }
        })
    });
    let mut results = Vec::new();
    for mode in &args.modes {
        results.push((*mode, run_mode(&args, *mode)?));
    }
    load_stop.store(true, Ordering::Relaxed);
    if let Some(l) = load {
        let _ = l.join();
    }
    println!(
        "\n{} s per mode at 1 kHz on the wire model ({}, 4 x 1 Mbit/s, 2 drives + 2 load cells \
         per bus), stack threads on cpu {:?}, {}, {}",
        args.seconds,
        args.drives.display(),
        args.stack_cpu,
        match args.load_cpu {
            Some(c) => format!("a spinning load on cpu {c}"),
            None => "no load thread".into(),
        },
        match args.rt_priority {
            Some(p) => format!("SCHED_FIFO {p} (drive-io) / {} (publisher, hub)", p - 1),
            None => "SCHED_OTHER".into(),
        }
    );
    println!(
        "| sync_source | SYNC interval sd / min / max (µs) | intervals < 0.9 P | published → last RPDO off the wire p50 / p99 / p99.9 / max (µs) | cycle's RPDO wire time (µs) | missed cycles | never on the wire |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (mode, r) in &results {
        let lat = match r.lat {
            Some([a, b, c, d]) => format!("{a:.1} / {b:.1} / {c:.1} / {d:.1}"),
            None => "no setpoint measured".into(),
        };
        println!(
            "| {} | {:.1} / {:.1} / {:.1} | {} of {} | {lat} | {:.0} | {} of {} | {} |",
            mode.name(),
            r.sync_sd_us,
            r.sync_min_us,
            r.sync_max_us,
            r.short_intervals,
            r.intervals,
            r.rpdo_wire_us,
            r.missed,
            r.measured,
            r.never
        );
    }
    for (mode, r) in &results {
        println!(
            "{}: {} setpoints published, {} measured; drive-io: {} cycles ({} by setpoint / {} \
             own clock or guard), {} overruns, {} SYNCs, SYNC left drive-io at most {:.1} µs \
             late, tx_full {}, final state {:?}",
            mode.name(),
            r.published,
            r.measured,
            r.summary.cycles,
            r.summary.setpoint_cycles,
            r.summary.clock_cycles,
            r.summary.overruns,
            r.summary.syncs,
            r.summary.sync_late_max_ns as f64 / 1000.0,
            r.summary.tx_full_drops,
            r.summary.final_state
        );
    }
    Ok(())
}

fn run_mode(args: &Args, mode: SyncSource) -> Result<ModeResult, Box<dyn std::error::Error>> {
    let mut cfg = DrivesConfig::load(&args.drives)?;
    // No monitor here: its interface, the safety I/O node and the heartbeat watch go.
    cfg.safety_io = None;
    cfg.safety_heartbeat = None;
    cfg.bus.interfaces.retain(|i| i.name != "safety");
    cfg.bus.sync_source = mode;
    cfg.bus.stale_setpoint_cycles = 100;
    cfg.bus.heartbeat_timeout_ms = 200;
    let names: Vec<String> = cfg.interfaces().iter().map(|i| i.name.clone()).collect();
    let dir = std::env::temp_dir().join(format!(
        "bus-latency-bench-{}-{}",
        std::process::id(),
        mode.name()
    ));
    let buses: Vec<(&str, u32)> = names.iter().map(|n| (n.as_str(), 1_000_000)).collect();
    let (hub, transports) = can_wire::HubThread::start(&dir, &buses, 50, 0, 100)?;
    for (itf, t) in cfg.bus.interfaces.iter_mut().zip(&transports) {
        itf.transport = t.clone();
    }
    cfg.validate()?;
    let specs = cfg.transports()?;
    let open = || -> Result<Vec<Box<dyn can_transport::CanBus>>, can_transport::CanError> {
        specs.iter().map(can_transport::open).collect()
    };
    let (emu_buses, dio_buses, mut listeners) = (open()?, open()?, open()?);
    // The cycle's RPDOs on one bus, exact bits (what the wire takes without a blocking frame).
    let m = cfg.winches.len();
    let prefix = format!("bench/{}/{}/", std::process::id(), mode.name());
    let control = EmulatorControl::new();
    let mut ecfg = EmulatorConfig::from_drives(&cfg, 5.0)?;
    ecfg.initial_length_m = vec![5.0; m];
    let cpu = args.stack_cpu;
    let rt = args.rt_priority;
    let c2 = control.clone();
    let emu = std::thread::spawn(move || {
        place(cpu, None);
        emulator::run(emu_buses, &ecfg, &c2)
    });
    let stop = Arc::new(AtomicBool::new(false));
    let (s2, cfg2, p2) = (stop.clone(), cfg.clone(), prefix.clone());
    let dio = std::thread::spawn(move || -> Result<runner::RunSummary, String> {
        place(cpu, rt);
        let ipc = IpcNode::with_prefix("drive-io", &p2).map_err(|e| e.to_string())?;
        runner::run(&cfg2, dio_buses, &ipc, &s2).map_err(|e| e.to_string())
    });
    // The listeners: every frame of every bus with its end-of-frame stamp.
    let seen: Arc<Mutex<Vec<Seen>>> = Arc::new(Mutex::new(
        (0..listeners.len()).map(|_| Seen::default()).collect(),
    ));
    let listen_stop = Arc::new(AtomicBool::new(false));
    let (seen2, ls2) = (seen.clone(), listen_stop.clone());
    let drive_of: Vec<(usize, u16)> = (0..m)
        .map(|i| {
            (
                cfg.winch_interface(i),
                0x200 + u16::from(cfg.winches[i].node_id),
            )
        })
        .collect();
    let drive_of_l = drive_of.clone();
    let listener = std::thread::spawn(move || {
        let drive_of = drive_of_l;
        place(cpu, None);
        let mut cursor = 0;
        let mut local: Vec<Seen> = (0..listeners.len()).map(|_| Seen::default()).collect();
        while !ls2.load(Ordering::Relaxed) {
            match can_transport::recv_any(&mut listeners, Duration::from_millis(5), &mut cursor) {
                Ok(Some((b, can_transport::RxEvent::Frame(rx)))) => {
                    let id = rx.frame.id() as u16;
                    if id == 0x080 {
                        local[b].syncs.push(rx.rx_monotonic_ns);
                    } else if let Some(i) = drive_of.iter().position(|d| *d == (b, id))
                        && rx.frame.data().len() == 6
                    {
                        let d = rx.frame.data();
                        let t = i32::from_le_bytes([d[2], d[3], d[4], d[5]]);
                        local[b].rpdos.push((i, t, rx.rx_monotonic_ns));
                    }
                }
                Ok(_) => {}
                Err(e) => {
                    eprintln!("listener: {e}");
                    break;
                }
            }
        }
        *seen2.lock().unwrap_or_else(|p| p.into_inner()) = local;
    });
    let node = IpcNode::with_prefix("bench", &prefix)?;
    let fb = node.subscriber::<crs_ipc::DriveFeedback>()?;
    let t0 = Instant::now();
    let init: [f64; MAX_CABLES];
    loop {
        if let Some(f) = fb.latest()?
            && f.bus_state == crs_ipc::BusState::Ready as u32
        {
            init = f.cable_length_m;
            break;
        }
        if t0.elapsed() > Duration::from_secs(60) {
            return Err(format!("{}: drive-io did not reach Ready", mode.name()).into());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    // The publisher: motion-core's loop and publish stage.
    let winches = cfg.winches.clone();
    let secs = args.seconds;
    let (lead, phase) = (args.lead_us * 1000, args.publish_phase_us * 1000);
    let p3 = prefix.clone();
    let publisher = std::thread::spawn(move || -> Result<Vec<(u64, [i32; MAX_CABLES])>, String> {
        place(cpu, rt.map(|p| p - 1));
        let _ = crs_rt::set_timer_slack(1);
        let node = IpcNode::with_prefix("bench-pub", &p3).map_err(|e| e.to_string())?;
        let p = node
            .publisher::<JointSetpoint>()
            .map_err(|e| e.to_string())?;
        let ready = node.setpoint_ready_notifier().map_err(|e| e.to_string())?;
        let schedule = node
            .subscriber::<SyncSchedule>()
            .map_err(|e| e.to_string())?;
        let mut phase_of_grid: Option<u64> = None;
        let n = secs * 1000;
        let mut out = Vec::with_capacity(n as usize);
        let mut tick = monotonic_ns() + 2 * P_NS;
        for seq in 1..=n {
            if let Ok(Some(s)) = schedule.latest() {
                phase_of_grid = s.phase_ns(-(lead as i64));
            }
            if mode == SyncSource::Isochronous
                && let Some(ph) = phase_of_grid
            {
                // The next tick at the schedule's phase (lead before a SYNC), never sooner
                // than half a period after the last.
                let base = tick - tick % P_NS + ph;
                tick = if base + P_NS / 2 < tick {
                    base + P_NS
                } else {
                    base
                };
            }
            crs_rt::sleep_until(tick + phase);
            let t = seq as f64 * 1e-3;
            let mut sp = JointSetpoint {
                cable_count: winches.len() as u32,
                sequence: seq,
                ..Default::default()
            };
            let mut counts = [0i32; MAX_CABLES];
            for (i, w) in winches.iter().enumerate() {
                // A smooth motion whose every setpoint differs (1 µm per ms at least).
                let l = init[i] + 0.05 * (1.0 - (t * 0.5).cos()) + 1e-6 * t;
                sp.cable_length_m[i] = l;
                counts[i] = w.length_to_counts(l).unwrap_or(0);
            }
            sp.timestamp_ns = monotonic_ns();
            p.publish(&sp).map_err(|e| e.to_string())?;
            ready.notify().map_err(|e| e.to_string())?;
            out.push((sp.timestamp_ns, counts));
            tick += P_NS;
        }
        Ok(out)
    });
    let published = publisher.join().map_err(|_| "publisher panicked")??;
    std::thread::sleep(Duration::from_millis(20));
    listen_stop.store(true, Ordering::Release);
    listener.join().map_err(|_| "listener panicked")?;
    stop.store(true, Ordering::Release);
    let summary = dio.join().map_err(|_| "drive-io panicked")??;
    control.stop.store(true, Ordering::Release);
    emu.join().map_err(|_| "emulator panicked")??;
    let _stats = hub.stop()?;
    let _ = std::fs::remove_dir_all(&dir);
    let seen = std::mem::take(&mut *seen.lock().unwrap_or_else(|p| p.into_inner()));

    // SYNC intervals on can0.
    let s0 = &seen[0].syncs;
    let iv: Vec<f64> = s0
        .windows(2)
        .map(|w| (w[1] - w[0]) as f64 / 1000.0)
        .collect();
    let n = iv.len().max(1) as f64;
    let mean = iv.iter().sum::<f64>() / n;
    let sd = (iv.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n).sqrt();
    let (mn, mx) = iv
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(*x), b.max(*x)));
    let short = iv.iter().filter(|x| **x < 900.0).count();
    // Per setpoint: when was each drive's RPDO carrying it off the wire, and the first SYNC
    // after its publication on that drive's bus.
    // The first time each (drive, target) was on the wire: every setpoint's targets are new.
    let first: Vec<std::collections::HashMap<(usize, i32), u64>> = seen
        .iter()
        .map(|s| {
            let mut h = std::collections::HashMap::with_capacity(s.rpdos.len());
            for (d, t, at) in &s.rpdos {
                h.entry((*d, *t)).or_insert(*at);
            }
            h
        })
        .collect();
    let mut lat = Vec::new();
    let (mut missed, mut never) = (0, 0);
    for (t_pub, counts) in &published {
        let mut last: Option<u64> = None;
        let mut late = false;
        let mut complete = true;
        for (i, c) in counts.iter().enumerate().take(m) {
            let b = drive_of[i].0;
            let Some(&off) = first[b].get(&(i, *c)).filter(|at| **at >= *t_pub) else {
                complete = false;
                continue;
            };
            let k = seen[b].syncs.partition_point(|s| *s <= *t_pub);
            late |= seen[b].syncs.get(k).is_none_or(|s| off > *s);
            last = Some(last.map_or(off, |l: u64| l.max(off)));
        }
        match (complete, last) {
            (true, Some(l)) => {
                lat.push(l - t_pub);
                missed += usize::from(late);
            }
            _ => never += 1,
        }
    }
    lat.sort_unstable();
    let us = |v: u64| v as f64 / 1000.0;
    // RPDO wire time of one bus's cycle: its two RPDOs' exact lengths.
    let rpdo_wire_us = 2.0
        * can_transport::wire::bits::exact(&can_transport::CanFrame::new(
            0x201,
            &[0x0F, 0, 1, 2, 3, 4],
        )?)
        .total() as f64;
    Ok(ModeResult {
        sync_sd_us: sd,
        sync_min_us: mn,
        sync_max_us: mx,
        short_intervals: short,
        intervals: iv.len(),
        lat: (!lat.is_empty()).then(|| {
            [
                us(quantile(&lat, 0.5)),
                us(quantile(&lat, 0.99)),
                us(quantile(&lat, 0.999)),
                us(*lat.last().unwrap_or(&0)),
            ]
        }),
        measured: lat.len(),
        missed,
        never,
        published: published.len(),
        rpdo_wire_us,
        summary,
    })
}
