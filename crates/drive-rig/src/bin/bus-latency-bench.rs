//! Bench: drive-io's three cycle designs side by side in one run, on the wire model with the
//! shipped CRS layout (config/drives.toml: 8 drives and their load cells on four 1 Mbit/s
//! interfaces; the safety interface is left out: no monitor runs here), and a bare 1 ms timer
//! loop in the same conditions (this VM's floor).
//!
//! drive-io (the real runner) and the winch emulator (playing the drives and load cells) run as
//! threads; an in-process `can-wire` hub carries the four buses with their bit time,
//! arbitration and transmit queues; a listener node on every bus sees each frame at its end of
//! frame (the model's stamp). drive-io's bus handles record every frame it hands to the wire
//! (send stamp, its transmit queue depth then). A publisher thread plays motion-core at 1 kHz:
//! with `sync_source = "isochronous"` it ticks `--lead-us` before each SYNC of the schedule
//! drive-io announces (as motion-core does) and publishes `--publish-phase-us` later
//! (motion-core's publish stage); with `"setpoint"` / `"clock"` it runs on its own 1 ms grid.
//! The motion is a slow ramp (1 mm/s on every cable): every setpoint's target counts are new
//! on every drive (checked), so each RPDO on the wire names exactly one setpoint.
//!
//! Figures per mode (all from the wire model's stamps, CLOCK_MONOTONIC):
//! * SYNC interval on bus can0: sd / min / max, intervals below 0.9 periods, and why each short
//!   one is short (drive-io sent the two SYNCs closer, or the wire delayed the first: queued
//!   behind drive-io's own frames, or behind a model violation of the hub);
//! * setpoint published → the last RPDO carrying it off the wire (max over the 8 drives):
//!   p50 / p99 / p99.9 / max;
//! * missed cycles: setpoints whose RPDOs were not all off the wire before the first SYNC after
//!   their publication (on their bus); setpoints not on the wire, split into never written by
//!   drive-io (superseded: a newer one was read first — drive-io's own count beside it — or
//!   published after a stop) and lost (written, not all seen by the listener);
//! * the SYNC's transmit path (isochronous: each interface's priority path, see
//!   `CanBus::open_priority_path`; the others: behind the cycle's RPDOs), and drive-io's own
//!   counts of SYNCs with its frames still queued and of cycles whose RPDOs queued behind its
//!   earlier frames, beside the hub's delivery lateness (drive-io sees frames leave that late);
//! * isochronous: when the superseded setpoints were published (the publisher's lateness, and
//!   whether after the guard of the SYNC they were planned for), and schedule phase changes;
//! * the VM's steal time over the mode (/proc/stat).
//!
//! The bare timer rows: an absolute-deadline 1 ms loop on the same cpu at drive-io's priority,
//! once sleeping to the deadline, once sleeping to the deadline − `sync_spin_us` and spinning
//! (as drive-io's isochronous SYNC does); grid instants less than 0.9 periods after the last
//! wake-up are skipped (drive-io's rule). Their "interval" is between wake-ups.
//!
//! usage: bus-latency-bench [--seconds 60] [--modes isochronous,setpoint,clock]
//!        [--rt-priority 80] [--load-cpu 0] [--stack-cpu 1] [--no-baseline]

use can_transport::{BusErrorFrame, CanBus, CanError, CanFrame, RxEvent, RxFrame};
use clap::Parser;
use crs_ipc::{IpcNode, JointSetpoint, MAX_CABLES, SyncSchedule, monotonic_ns};
use drive_io::runner;
use drive_rig::emulator::{self, EmulatorConfig, EmulatorControl};
use drives_config::{DrivesConfig, SyncSource};
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

#[derive(Parser)]
struct Args {
    /// Seconds per mode (and per bare-timer row).
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
    /// Leave out the bare timer rows.
    #[arg(long)]
    no_baseline: bool,
    /// Short SYNC intervals whose neighbourhood is printed per mode.
    #[arg(long, default_value_t = 3)]
    show_short: usize,
    /// SCHED_FIFO priority of the winch emulator (the drives and load cells; default: none,
    /// it competes with everything else on the stack's cpu).
    #[arg(long)]
    emulator_priority: Option<i32>,
    /// Pin the winch emulator to this cpu instead of the stack's (the drives are other
    /// hardware).
    #[arg(long)]
    emulator_cpu: Option<usize>,
}

const P_NS: u64 = 1_000_000;
/// The ramp every cable follows, m/s: ≥ 10 counts per period with the shipped winches, so
/// every setpoint's targets are new.
const RAMP_M_PER_S: f64 = 1e-3;

/// The stack's one quantile definition (nearest rank, [`crs_limits::quantile`]) of sorted
/// samples; 0 for none (the bare timer's lateness when it woke no time).
fn quantile(sorted: &[u64], q: f64) -> u64 {
    crs_limits::quantile::quantile_sorted(sorted, q).unwrap_or(0)
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

/// Steal time so far, in clock ticks: (all cpus, the given cpu) from /proc/stat.
fn steal_ticks(cpu: Option<usize>) -> Option<(u64, u64)> {
    let text = std::fs::read_to_string("/proc/stat").ok()?;
    let field = |name: &str| -> Option<u64> {
        let line = text
            .lines()
            .find(|l| l.split_whitespace().next() == Some(name))?;
        // user nice system idle iowait irq softirq steal
        line.split_whitespace().nth(8)?.parse().ok()
    };
    let all = field("cpu")?;
    let one = match cpu {
        Some(c) => field(&format!("cpu{c}"))?,
        None => all,
    };
    Some((all, one))
}

/// Steal over an interval as a share of it: (all cpus, the stack's cpu), percent.
struct Steal {
    start: Option<(u64, u64)>,
    t0: Instant,
    cpu: Option<usize>,
}

impl Steal {
    fn start(cpu: Option<usize>) -> Self {
        Self {
            start: steal_ticks(cpu),
            t0: Instant::now(),
            cpu,
        }
    }
    fn percent(&self) -> Option<(f64, f64)> {
        let (a0, c0) = self.start?;
        let (a1, c1) = steal_ticks(self.cpu)?;
        // SAFETY: sysconf has no preconditions.
        let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
        // SAFETY: as above.
        let ncpu = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) }.max(1) as f64;
        let ticks = self.t0.elapsed().as_secs_f64() * hz;
        Some((
            100.0 * (a1 - a0) as f64 / (ticks * ncpu),
            100.0 * (c1 - c0) as f64 / ticks,
        ))
    }
}

fn steal_text(s: Option<(f64, f64)>) -> String {
    match s {
        Some((all, cpu)) => format!("{cpu:.1} % ({all:.1} % all cpus)"),
        None => "/proc/stat unreadable".into(),
    }
}

/// One frame drive-io handed to the wire client.
#[derive(Clone, Copy)]
struct Sent {
    at_ns: u64,
    /// drive-io's frames not yet off the wire on the path this one went through (the
    /// interface's queue, or the SYNC's priority path) when it sent this one.
    depth: u64,
    id: u16,
    /// An RPDO's target counts (6-byte frames).
    value: Option<i32>,
}

/// drive-io's end of one bus: the wire client, recording every frame sent (preallocated; the
/// log is handed to the bench when drive-io drops its buses). Its priority path (drive-io's
/// SYNC in isochronous mode) records into slot `index + buses`.
struct Recorded {
    inner: Box<dyn CanBus>,
    log: Vec<Sent>,
    index: usize,
    buses: usize,
    out: Arc<Mutex<Vec<Vec<Sent>>>>,
}

impl Drop for Recorded {
    fn drop(&mut self) {
        let mut out = self.out.lock().unwrap_or_else(|p| p.into_inner());
        out[self.index] = std::mem::take(&mut self.log);
    }
}

impl CanBus for Recorded {
    fn send(&mut self, frame: &CanFrame) -> Result<(), CanError> {
        let depth = self.inner.tx_backlog().unwrap_or(0);
        let at_ns = monotonic_ns();
        let d = frame.data();
        let value = (d.len() == 6).then(|| i32::from_le_bytes([d[2], d[3], d[4], d[5]]));
        let r = self.inner.send(frame);
        if r.is_ok() {
            self.log.push(Sent {
                at_ns,
                depth,
                id: frame.id() as u16,
                value,
            });
        }
        r
    }
    fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<RxFrame>, CanError> {
        self.inner.recv_timeout(timeout)
    }
    fn try_recv(&mut self) -> Result<Option<RxFrame>, CanError> {
        self.inner.try_recv()
    }
    fn interface(&self) -> &str {
        self.inner.interface()
    }
    fn rx_errors(&self) -> u64 {
        self.inner.rx_errors()
    }
    fn subscribe_bus_errors(&mut self) -> Result<(), CanError> {
        self.inner.subscribe_bus_errors()
    }
    fn recv_event_timeout(&mut self, timeout: Duration) -> Result<Option<RxEvent>, CanError> {
        self.inner.recv_event_timeout(timeout)
    }
    fn try_recv_event(&mut self) -> Result<Option<RxEvent>, CanError> {
        self.inner.try_recv_event()
    }
    fn send_bus_error(&mut self, error: &BusErrorFrame) -> Result<(), CanError> {
        self.inner.send_bus_error(error)
    }
    fn bus_errors(&self) -> u64 {
        self.inner.bus_errors()
    }
    fn enable_tx_echo(&mut self) -> Result<(), CanError> {
        self.inner.enable_tx_echo()
    }
    fn readiness_fd(&self) -> Option<std::os::fd::RawFd> {
        self.inner.readiness_fd()
    }
    fn open_priority_path(&self) -> Result<Option<Box<dyn CanBus>>, CanError> {
        Ok(self.inner.open_priority_path()?.map(|p| {
            Box::new(Recorded {
                inner: p,
                log: Vec::with_capacity(self.log.capacity()),
                index: self.index + self.buses,
                buses: self.buses,
                out: self.out.clone(),
            }) as Box<dyn CanBus>
        }))
    }
    fn tx_backlog(&self) -> Option<u64> {
        self.inner.tx_backlog()
    }
}

/// What the listeners saw on one bus.
#[derive(Default)]
struct Seen {
    /// End-of-frame stamps of the SYNCs.
    syncs: Vec<u64>,
    /// (drive index, target counts, end of frame) of every RPDO.
    rpdos: Vec<(usize, i32, u64)>,
    /// (identifier, end of frame) of every frame (bus can0 only).
    all: Vec<(u16, u64)>,
}

/// What the publisher did: (publish time, target counts) per setpoint, when it meant to
/// publish each, and how often the announced schedule's phase changed.
type PublisherLog = (Vec<(u64, [i32; MAX_CABLES])>, Vec<Planned>, u64);

/// When the publisher meant to publish a setpoint, and (isochronous) the SYNC it was for.
struct Planned {
    publish_at_ns: u64,
    sync_at_ns: Option<u64>,
}

/// Why a SYNC interval on the wire was below 0.9 periods.
#[derive(Default, Clone, Copy)]
struct ShortCauses {
    /// drive-io handed the two SYNCs to the wire less than 0.9 P apart.
    sent_closer: usize,
    /// Sent ≥ 0.9 P apart; the first waited on the wire behind drive-io's own frames queued
    /// before it.
    queued_behind_own: usize,
    /// Sent ≥ 0.9 P apart, nothing of drive-io's queued before the first: delayed by the wire
    /// model otherwise (a frame on the wire, or a submission the hub learned too late).
    other: usize,
    /// SYNC sends and SYNCs on the wire could not be paired (the listener lost some).
    unpaired: bool,
}

struct ModeResult {
    /// Isochronous: when the superseded setpoints were published (item: why superseded).
    supersede_text: Option<String>,
    /// drive-io's first fault (code, node, last EMCY code), if it reported one.
    fault: Option<(u32, u32, u32)>,
    /// SYNCs drive-io handed to a priority path.
    prio_syncs: usize,
    /// The hub's delivery lateness, worst bus: p99 and max, ns.
    hub_late_p99_ns: u64,
    hub_late_max_ns: u64,
    sync_sd_us: f64,
    sync_min_us: f64,
    sync_max_us: f64,
    short_intervals: usize,
    intervals: usize,
    causes: ShortCauses,
    neighbourhoods: Vec<String>,
    lat: Option<[f64; 4]>,
    written: Option<[f64; 2]>,
    measured: usize,
    missed: usize,
    superseded: usize,
    lost: usize,
    published: usize,
    rpdo_wire_us: f64,
    violations: u64,
    violation_max_ns: u64,
    rx_dropped: u64,
    hub_cpu_s: f64,
    steal: Option<(f64, f64)>,
    summary: runner::RunSummary,
}

struct BaseResult {
    spin_us: u64,
    sd_us: f64,
    min_us: f64,
    max_us: f64,
    short: usize,
    intervals: usize,
    late_p50_us: f64,
    late_p99_us: f64,
    late_max_us: f64,
    skipped: u64,
    steal: Option<(f64, f64)>,
}

/// sd / min / max of the intervals (µs) and how many are below 0.9 P.
fn interval_figures(stamps: &[u64]) -> (f64, f64, f64, usize, usize) {
    let iv: Vec<f64> = stamps
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
    (sd, mn, mx, short, iv.len())
}

/// The date and time now, UTC, `YYYY-MM-DD HH:MM`.
fn utc_now() -> String {
    // SAFETY: time(NULL) and gmtime_r into a tm we own.
    unsafe {
        let t = libc::time(std::ptr::null_mut());
        let mut tm: libc::tm = std::mem::zeroed();
        libc::gmtime_r(&t, &mut tm);
        format!(
            "{:04}-{:02}-{:02} {:02}:{:02} UTC",
            tm.tm_year + 1900,
            tm.tm_mon + 1,
            tm.tm_mday,
            tm.tm_hour,
            tm.tm_min
        )
    }
}

fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unreadable".into())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    if args.load_cpu.is_some() && args.load_cpu == args.stack_cpu {
        return Err("--load-cpu and --stack-cpu must differ".into());
    }
    let (started, load_start) = (utc_now(), loadavg());
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
    let spin_us = u64::from(DrivesConfig::load(&args.drives)?.bus.sync_spin_us);
    let mut results = Vec::new();
    for mode in &args.modes {
        results.push((*mode, run_mode(&args, *mode)?));
    }
    let mut base = Vec::new();
    if !args.no_baseline {
        for spin in [0, spin_us] {
            base.push(bare_timer(&args, spin));
        }
    }
    load_stop.store(true, Ordering::Relaxed);
    if let Some(l) = load {
        let _ = l.join();
    }
    for (mode, r) in &results {
        println!("\n{}: the shortest SYNC intervals on can0:", mode.name());
        for n in &r.neighbourhoods {
            println!("{n}");
        }
    }
    println!(
        "\n{started} (load average at start {load_start}, at end {}): {} s per row at 1 kHz on \
         the wire model ({}, 4 x 1 Mbit/s, 2 drives + 2 load cells per bus), stack threads on \
         cpu {:?}, {}, {}",
        loadavg(),
        args.seconds,
        args.drives.display(),
        args.stack_cpu,
        match args.load_cpu {
            Some(c) => format!("a spinning load on cpu {c}"),
            None => "no load thread".into(),
        },
        match args.rt_priority {
            Some(p) => format!(
                "SCHED_FIFO {p} (drive-io, bare timer) / {} (publisher, hub)",
                p - 1
            ),
            None => "SCHED_OTHER".into(),
        }
    );
    println!(
        "| design | SYNC path | SYNC interval sd / min / max (µs) | intervals < 0.9 P (drive-io sent closer / queued behind own frames on its path / other) | published → last RPDO off the wire p50 / p99 / p99.9 / max (µs) | cycle's RPDO wire time (µs) | missed cycles | drive-io: SYNCs with its frames still queued / cycles whose RPDOs queued behind its earlier frames | not on the wire: never written by drive-io / partly (queue full at send, or not seen) | steal, stack cpu (all cpus) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (mode, r) in &results {
        let lat = match r.lat {
            Some([a, b, c, d]) => format!("{a:.1} / {b:.1} / {c:.1} / {d:.1}"),
            None => "no setpoint measured".into(),
        };
        let c = r.causes;
        let causes = if c.unpaired {
            "not paired".into()
        } else {
            format!("{} / {} / {}", c.sent_closer, c.queued_behind_own, c.other)
        };
        let path = if r.summary.sync_priority_paths > 0 {
            format!(
                "own (priority) path on {} of 4 buses",
                r.summary.sync_priority_paths
            )
        } else {
            "behind the cycle's RPDOs (one FIFO)".to_string()
        };
        println!(
            "| {} | {path} | {:.1} / {:.1} / {:.1} | {} of {} ({causes}) | {lat} | {:.0} | {} of {} | {} / {} | {} (drive-io: {} superseded) / {} | {} |",
            mode.name(),
            r.sync_sd_us,
            r.sync_min_us,
            r.sync_max_us,
            r.short_intervals,
            r.intervals,
            r.rpdo_wire_us,
            r.missed,
            r.measured,
            r.summary.rpdos_late_at_sync,
            r.summary.rpdos_queued_behind,
            r.superseded,
            r.summary.superseded_setpoints,
            r.lost,
            steal_text(r.steal)
        );
    }
    for b in &base {
        println!(
            "| bare 1 ms timer, {} | — | {:.1} / {:.1} / {:.1} | {} of {} | lateness p50 / p99 / max {:.1} / {:.1} / {:.1} | — | {} grid instants skipped | — | — | {} |",
            if b.spin_us == 0 {
                "sleep to the deadline".to_string()
            } else {
                format!("sleep to deadline − {} µs, spin", b.spin_us)
            },
            b.sd_us,
            b.min_us,
            b.max_us,
            b.short,
            b.intervals,
            b.late_p50_us,
            b.late_p99_us,
            b.late_max_us,
            b.skipped,
            steal_text(b.steal)
        );
    }
    for (mode, r) in &results {
        let w = match r.written {
            Some([a, b]) => format!("{a:.1} / {b:.1} µs"),
            None => "-".into(),
        };
        println!(
            "{}: {} setpoints published, {} measured, published → drive-io's last RPDO send \
             p50 / p99 {w}; drive-io: {} cycles ({} by setpoint / {} own clock or guard), {} \
             overruns, {} superseded setpoints, {} SYNCs, SYNC left drive-io at most {:.1} µs \
             late, tx_full {}, final state {:?}; hub: {} model violations (worst {:.1} µs), {} \
             frames dropped at receiving nodes, hub thread cpu {:.1} s, delivery lateness p99 / max \
             {:.1} / {:.1} µs (drive-io sees its frames leave the wire that much later); {} \
             SYNCs through a priority path",
            mode.name(),
            r.published,
            r.measured,
            r.summary.cycles,
            r.summary.setpoint_cycles,
            r.summary.clock_cycles,
            r.summary.overruns,
            r.summary.superseded_setpoints,
            r.summary.syncs,
            r.summary.sync_late_max_ns as f64 / 1000.0,
            r.summary.tx_full_drops,
            r.summary.final_state,
            r.violations,
            r.violation_max_ns as f64 / 1000.0,
            r.rx_dropped,
            r.hub_cpu_s,
            r.hub_late_p99_ns as f64 / 1000.0,
            r.hub_late_max_ns as f64 / 1000.0,
            r.prio_syncs
        );
        if let Some((code, node, emcy)) = r.fault {
            println!(
                "{}: drive-io's fault: crs_ipc::fault_code {code}, node {node}, last EMCY {emcy:#06x}",
                mode.name()
            );
        }
        if let Some(t) = &r.supersede_text {
            println!("{}: {t}", mode.name());
        }
    }
    Ok(())
}

/// A bare absolute-deadline 1 ms loop where drive-io runs: sleep to the deadline (`spin_us`
/// 0) or to the deadline − `spin_us` and spin. A deadline less than 0.9 P after the last
/// wake-up is skipped (drive-io's catch-up rule).
fn bare_timer(args: &Args, spin_us: u64) -> BaseResult {
    let (secs, cpu, rt) = (args.seconds, args.stack_cpu, args.rt_priority);
    let spin = spin_us * 1000;
    let h = std::thread::spawn(move || {
        place(cpu, rt);
        let _ = crs_rt::set_timer_slack(1);
        let steal = Steal::start(cpu);
        let n = (secs * 1000) as usize;
        let (mut wakes, mut late) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let mut t = monotonic_ns() + 2 * P_NS;
        let mut skipped = 0u64;
        for _ in 0..n {
            crs_rt::sleep_until(t - spin);
            let mut w = monotonic_ns();
            while w < t {
                std::hint::spin_loop();
                w = monotonic_ns();
            }
            wakes.push(w);
            late.push(w - t);
            t += P_NS;
            while t < w + P_NS - P_NS / 10 {
                t += P_NS;
                skipped += 1;
            }
        }
        (wakes, late, skipped, steal.percent())
    });
    let (wakes, mut late, skipped, steal) = h.join().expect("bare timer thread");
    late.sort_unstable();
    let (sd_us, min_us, max_us, short, intervals) = interval_figures(&wakes);
    let us = |v: u64| v as f64 / 1000.0;
    BaseResult {
        spin_us,
        sd_us,
        min_us,
        max_us,
        short,
        intervals,
        late_p50_us: us(quantile(&late, 0.5)),
        late_p99_us: us(quantile(&late, 0.99)),
        late_max_us: us(*late.last().unwrap_or(&0)),
        skipped,
        steal,
    }
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
    let (emu_buses, mut listeners) = (open()?, open()?);
    // drive-io's buses record what it sends (about 4 frames per bus and period).
    let n_bus = transports.len();
    let sent_logs: Arc<Mutex<Vec<Vec<Sent>>>> = Arc::new(Mutex::new(vec![Vec::new(); 2 * n_bus]));
    let mut dio_buses = Vec::with_capacity(n_bus);
    for (index, t) in transports.iter().enumerate() {
        let path = t
            .strip_prefix("wire:")
            .ok_or("hub transport is not wire:")?;
        dio_buses.push(Recorded {
            inner: Box::new(can_transport::wire::WireBus::connect(
                std::path::Path::new(path),
            )?),
            log: Vec::with_capacity(5000 * args.seconds as usize + 20_000),
            index,
            buses: n_bus,
            out: sent_logs.clone(),
        });
    }
    let m = cfg.winches.len();
    let prefix = format!("bench/{}/{}/", std::process::id(), mode.name());
    let control = EmulatorControl::new();
    let mut ecfg = EmulatorConfig::from_drives(&cfg, 5.0)?;
    ecfg.initial_length_m = vec![5.0; m];
    let cpu = args.stack_cpu;
    let rt = args.rt_priority;
    let c2 = control.clone();
    let (emu_rt, emu_cpu) = (args.emulator_priority, args.emulator_cpu.or(cpu));
    let emu = std::thread::spawn(move || {
        place(emu_cpu, emu_rt);
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
                    if b == 0 {
                        local[b].all.push((id, rx.rx_monotonic_ns));
                    }
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
    let steal = Steal::start(cpu);
    let publisher = std::thread::spawn(move || -> Result<PublisherLog, String> {
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
        let mut phase_changes = 0u64;
        let n = secs * 1000;
        let mut out = Vec::with_capacity(n as usize);
        let mut planned = Vec::with_capacity(n as usize);
        let mut tick = monotonic_ns() + 2 * P_NS;
        for seq in 1..=n {
            if let Ok(Some(s)) = schedule.latest() {
                let ph = s.phase_ns(-(lead as i64));
                if phase_of_grid.is_some() && ph != phase_of_grid {
                    phase_changes += 1;
                }
                phase_of_grid = ph;
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
                // A slow ramp: new target counts on every drive in every setpoint.
                let l = init[i] + RAMP_M_PER_S * t;
                sp.cable_length_m[i] = l;
                counts[i] = w.length_to_counts(l).unwrap_or(0);
            }
            sp.timestamp_ns = monotonic_ns();
            p.publish(&sp).map_err(|e| e.to_string())?;
            ready.notify().map_err(|e| e.to_string())?;
            out.push((sp.timestamp_ns, counts));
            planned.push(Planned {
                publish_at_ns: tick + phase,
                sync_at_ns: (mode == SyncSource::Isochronous && phase_of_grid.is_some())
                    .then_some(tick + lead),
            });
            tick += P_NS;
        }
        Ok((out, planned, phase_changes))
    });
    let (published, planned, phase_changes) =
        publisher.join().map_err(|_| "publisher panicked")??;
    // drive-io's last feedback: the first fault's cause if it stopped (crs_ipc::fault_code).
    let last_fb = fb.latest()?;
    let fault = last_fb
        .filter(|f| f.fault_code != 0)
        .map(|f| (f.fault_code, f.fault_node, f.last_emcy_code));
    let steal = steal.percent();
    std::thread::sleep(Duration::from_millis(20));
    let listen_stop_ns = monotonic_ns();
    listen_stop.store(true, Ordering::Release);
    listener.join().map_err(|_| "listener panicked")?;
    stop.store(true, Ordering::Release);
    let summary = dio.join().map_err(|_| "drive-io panicked")??;
    control.stop.store(true, Ordering::Release);
    emu.join().map_err(|_| "emulator panicked")??;
    let stats = hub.stop()?;
    let _ = std::fs::remove_dir_all(&dir);
    let seen = std::mem::take(&mut *seen.lock().unwrap_or_else(|p| p.into_inner()));
    let mut sent = std::mem::take(&mut *sent_logs.lock().unwrap_or_else(|p| p.into_inner()));
    // Each interface's log with its priority path's (the SYNCs in isochronous mode), in send
    // order.
    let prio_logs = sent.split_off(n_bus);
    let prio_syncs: usize = prio_logs.iter().map(Vec::len).sum();
    for (log, p) in sent.iter_mut().zip(prio_logs) {
        log.extend(p);
        log.sort_by_key(|f| f.at_ns);
    }
    // The hub's figures: model violations, frames a receiving node's socket refused.
    let stats: serde_json::Value = serde_json::from_str(&stats)?;
    let (mut violations, mut violation_max_ns, mut rx_dropped) = (0u64, 0u64, 0u64);
    // How late the hub handed frames out (real time − end of frame): drive-io learns that its
    // frames left the wire that much later, so its backlog counts include that lag.
    let (mut hub_late_p99_ns, mut hub_late_max_ns) = (0u64, 0u64);
    for b in stats["buses"].as_array().into_iter().flatten() {
        hub_late_p99_ns =
            hub_late_p99_ns.max(b["delivery_lateness_ns"]["p99"].as_u64().unwrap_or(0));
        hub_late_max_ns =
            hub_late_max_ns.max(b["delivery_lateness_ns"]["max"].as_u64().unwrap_or(0));
        violations += b["violations"].as_u64().unwrap_or(0);
        violation_max_ns = violation_max_ns.max(b["violation_max_ns"].as_u64().unwrap_or(0));
        for n in b["nodes"].as_array().into_iter().flatten() {
            rx_dropped += n["rx_dropped"].as_u64().unwrap_or(0);
        }
    }

    // Every setpoint's targets must be new on every drive, or the matching is ambiguous.
    for i in 0..m {
        let mut values: Vec<i32> = published.iter().map(|(_, c)| c[i]).collect();
        values.sort_unstable();
        if values.windows(2).any(|w| w[0] == w[1]) {
            return Err(format!("drive {i}: two setpoints with the same target counts").into());
        }
    }

    // SYNC intervals on can0, and why the short ones are short.
    let s0 = &seen[0].syncs;
    let (sync_sd_us, sync_min_us, sync_max_us, short_intervals, intervals) = interval_figures(s0);
    // drive-io's n-th SYNC on can0 is the n-th on the wire (one FIFO queue, one SYNC per
    // instant) if the listener lost none; drive-io sends a few more after the listener stopped
    // (every SYNC sent 10 ms before that must have been seen).
    let mut sync_sends: Vec<&Sent> = sent[0].iter().filter(|f| f.id == 0x080).collect();
    let surely_seen = sync_sends
        .iter()
        .filter(|f| f.at_ns + 10 * P_NS < listen_stop_ns)
        .count();
    let paired = surely_seen <= s0.len()
        && sync_sends.len() >= s0.len()
        && sync_sends.iter().zip(s0).all(|(a, eof)| *eof > a.at_ns);
    sync_sends.truncate(s0.len());
    let mut causes = ShortCauses::default();
    let mut neighbourhoods = Vec::new();
    if paired {
        let mut short: Vec<(u64, usize)> = s0
            .windows(2)
            .enumerate()
            .filter(|(_, w)| w[1] - w[0] < P_NS - P_NS / 10)
            .map(|(k, w)| (w[1] - w[0], k + 1))
            .collect();
        for &(_, k) in &short {
            let (a, b) = (sync_sends[k - 1], sync_sends[k]);
            if b.at_ns - a.at_ns < P_NS - P_NS / 10 {
                causes.sent_closer += 1;
            } else if a.depth > 0 {
                causes.queued_behind_own += 1;
            } else {
                causes.other += 1;
            }
        }
        short.sort_unstable();
        let us = |v: i64| v as f64 / 1000.0;
        for &(iv, k) in short.iter().take(args.show_short) {
            let base = sync_sends[k.saturating_sub(2)].at_ns;
            let mut text = format!(
                "  interval {:.1} µs on the wire ({:.1} µs between drive-io's sends); times from \
                 the send of SYNC n−2, µs:",
                iv as f64 / 1000.0,
                us((sync_sends[k].at_ns - sync_sends[k - 1].at_ns) as i64)
            );
            // drive-io's frames on can0 from SYNC n−2 to SYNC n, SYNCs with their end of frame.
            for f in sent[0]
                .iter()
                .filter(|f| f.at_ns >= base && f.at_ns <= sync_sends[k].at_ns)
            {
                let eof = if f.id == 0x080 {
                    let j = sync_sends.partition_point(|s| s.at_ns < f.at_ns);
                    format!(
                        ", off the wire {:.1} (queue + wire {:.1})",
                        us((s0[j] - base) as i64),
                        us((s0[j] - f.at_ns) as i64)
                    )
                } else {
                    String::new()
                };
                text.push_str(&format!(
                    "\n    sent {:8.1}  id {:#05x}  drive-io's frames not yet off the wire {}{eof}",
                    us((f.at_ns - base) as i64),
                    f.id,
                    f.depth
                ));
            }
            // What else was on the wire while SYNC n−1 waited.
            let (from, to) = (sync_sends[k - 1].at_ns, s0[k - 1]);
            let mut by_kind = [0usize; 5];
            for (id, _) in seen[0].all.iter().filter(|(_, e)| *e > from && *e <= to) {
                by_kind[match id {
                    0x080 => 0,
                    0x181..=0x1FF => 1,
                    0x201..=0x27F => 2,
                    0x281..=0x2FF | 0x381..=0x3FF | 0x481..=0x4FF => 3,
                    _ => 4,
                }] += 1;
            }
            text.push_str(&format!(
                "\n    off the wire while SYNC n−1 waited ({:.1} µs): {} SYNC, {} TPDO1, {} RPDO, \
                 {} TPDO2-4, {} other (heartbeats, EMCY, SDO)",
                us((to - from) as i64),
                by_kind[0],
                by_kind[1],
                by_kind[2],
                by_kind[3],
                by_kind[4]
            ));
            neighbourhoods.push(text);
        }
    } else {
        causes.unpaired = true;
        neighbourhoods.push(format!(
            "  SYNCs on can0: {} sent by drive-io, {} seen by the listener: not paired",
            sync_sends.len(),
            s0.len()
        ));
    }

    // Per setpoint: when drive-io wrote each drive's RPDO carrying it, when that RPDO was off
    // the wire, and the first SYNC after its publication on that drive's bus. Targets are
    // unique per drive (checked above), so the first occurrence is the setpoint's.
    let first_seen: Vec<HashMap<(usize, i32), u64>> = seen
        .iter()
        .map(|s| {
            let mut h = HashMap::with_capacity(s.rpdos.len());
            for (d, t, at) in &s.rpdos {
                h.entry((*d, *t)).or_insert(*at);
            }
            h
        })
        .collect();
    let first_sent: Vec<HashMap<(u16, i32), u64>> = sent
        .iter()
        .map(|log| {
            let mut h = HashMap::with_capacity(log.len());
            for f in log {
                if let Some(v) = f.value {
                    h.entry((f.id, v)).or_insert(f.at_ns);
                }
            }
            h
        })
        .collect();
    let mut lat = Vec::new();
    let mut written = Vec::new();
    let (mut missed, mut superseded, mut lost) = (0, 0, 0);
    let guard_ns = u64::from(cfg.bus.rpdo_guard_us) * 1000;
    // Isochronous: each setpoint's publisher lateness (published − planned) and whether it
    // came after the guard time of the SYNC it was planned for; (lateness, after guard,
    // superseded).
    let mut timing: Vec<(u64, bool, bool)> = Vec::new();
    for (j, (t_pub, counts)) in published.iter().enumerate() {
        let mut last: Option<u64> = None;
        let mut last_sent: Option<u64> = None;
        let mut late = false;
        let (mut on_wire, mut was_sent) = (0, 0);
        for (i, c) in counts.iter().enumerate().take(m) {
            let (b, id) = drive_of[i];
            if let Some(&w) = first_sent[b].get(&(id, *c)) {
                was_sent += 1;
                last_sent = Some(last_sent.map_or(w, |l: u64| l.max(w)));
            }
            let Some(&off) = first_seen[b].get(&(i, *c)) else {
                continue;
            };
            on_wire += 1;
            let k = seen[b].syncs.partition_point(|s| *s <= *t_pub);
            late |= seen[b].syncs.get(k).is_none_or(|s| off > *s);
            last = Some(last.map_or(off, |l: u64| l.max(off)));
        }
        if let Some(sync_at) = planned.get(j).and_then(|p| p.sync_at_ns) {
            timing.push((
                t_pub.saturating_sub(planned[j].publish_at_ns),
                *t_pub > sync_at - guard_ns,
                was_sent == 0,
            ));
        }
        if was_sent == 0 {
            superseded += 1;
        } else if on_wire < m || was_sent < m {
            lost += 1;
        } else if let (Some(l), Some(w)) = (last, last_sent) {
            lat.push(l.saturating_sub(*t_pub));
            written.push(w.saturating_sub(*t_pub));
            missed += usize::from(late);
        }
    }
    lat.sort_unstable();
    written.sort_unstable();
    let supersede_text = (!timing.is_empty()).then(|| {
        let lateness = |sel: &dyn Fn(&(u64, bool, bool)) -> bool| {
            let mut v: Vec<u64> = timing.iter().filter(|t| sel(t)).map(|t| t.0).collect();
            v.sort_unstable();
            if v.is_empty() {
                "-".to_string()
            } else {
                format!(
                    "{:.1} / {:.1} / {:.1} / {:.1}",
                    quantile(&v, 0.5) as f64 / 1000.0,
                    quantile(&v, 0.99) as f64 / 1000.0,
                    quantile(&v, 0.999) as f64 / 1000.0,
                    *v.last().unwrap_or(&0) as f64 / 1000.0
                )
            }
        };
        let n_sup = timing.iter().filter(|t| t.2).count();
        let sup_after = timing.iter().filter(|t| t.2 && t.1).count();
        let after = timing.iter().filter(|t| t.1).count();
        let margin_us = (args.lead_us - args.publish_phase_us) as f64 - guard_ns as f64 / 1000.0;
        format!(
            "superseded setpoints (never written): {n_sup}; published after the guard ({} µs \
             before the SYNC they were planned for, i.e. more than {margin_us:.0} µs late): \
             {sup_after} of {n_sup}; all setpoints published after their guard: {after} of {}; \
             publisher lateness (published − planned) p50 / p99 / p99.9 / max, all: {} µs, \
             superseded: {} µs; schedule phase changes seen by the publisher: {phase_changes}",
            guard_ns / 1000,
            timing.len(),
            lateness(&|_| true),
            lateness(&|t| t.2),
        )
    });
    let us = |v: u64| v as f64 / 1000.0;
    // RPDO wire time of one bus's cycle: its two RPDOs' exact lengths.
    let rpdo_wire_us = 2.0
        * can_transport::wire::bits::exact(&can_transport::CanFrame::new(
            0x201,
            &[0x0F, 0, 1, 2, 3, 4],
        )?)
        .total() as f64;
    Ok(ModeResult {
        supersede_text,
        fault,
        prio_syncs,
        hub_late_p99_ns,
        hub_late_max_ns,
        sync_sd_us,
        sync_min_us,
        sync_max_us,
        short_intervals,
        intervals,
        causes,
        neighbourhoods,
        lat: (!lat.is_empty()).then(|| {
            [
                us(quantile(&lat, 0.5)),
                us(quantile(&lat, 0.99)),
                us(quantile(&lat, 0.999)),
                us(*lat.last().unwrap_or(&0)),
            ]
        }),
        written: (!written.is_empty())
            .then(|| [us(quantile(&written, 0.5)), us(quantile(&written, 0.99))]),
        measured: lat.len(),
        missed,
        superseded,
        lost,
        published: published.len(),
        rpdo_wire_us,
        violations,
        violation_max_ns,
        rx_dropped,
        hub_cpu_s: stats["hub"]["cpu_s"].as_f64().unwrap_or(f64::NAN),
        steal,
        summary,
    })
}
