//! `loop-jitter`: wake-up lateness of the daemon's real 1 ms loop next to a bare
//! `clock_nanosleep(TIMER_ABSTIME)` loop, in the same process, same thread, same settings
//! (the loop-timing bench on 2 cores).
//!
//! The daemon side is the real thing: `HardLoop` (trajectory sampler fed by the ruckig planner
//! thread, checks, IK, surrogate offset) driven by `daemon::run_timed`, with the `[realtime]`
//! settings of `config/motion-core.toml` applied by `realtime::apply`, exactly as `motion-core`
//! does. Only the sink differs: a preallocated ring instead of the outbox + iceoryx2 publish
//! stage (the stage is another thread, a fixed phase later; it is not on the loop's path).
//!
//! Why alternate blocks on one thread rather than two threads: the two loops must see the same
//! settings and the same disturbances. Two threads on the loop CPU at the same priority would
//! delay each other (the figure would measure their interaction); the bare loop on the other
//! CPU would not have the same settings, and that CPU is the one stress-ng loads. So one thread,
//! pinned and prioritised once, runs the daemon loop and the bare loop in alternating blocks
//! (default 250 ms each) on ONE continuous absolute-deadline timeline: both sample the same
//! host steal and load, interleaved finely enough that slow drifts hit both alike. What differs
//! is only what the daemon loop does between wake-ups (its compute, its cache footprint, the
//! planner thread's catch-up work) — which is what the ratio is meant to show.
//!
//! Lateness = time read right after `sleep_until` returns − the deadline, per cycle, stored
//! exactly (ns, preallocated buffers, no allocation while looping) for both loops. For the
//! daemon loop the deadline is mirrored from `run_timed`'s rule (next period, missed periods
//! skipped) and the wake time is the setpoint's timestamp, which `HardLoop::step` sets to the
//! time `run_timed` read after waking. The daemon's own coarse `LoopStats` histograms are
//! printed too, as a cross-check.

use cdpr_model::Pose;
use cdpr_model::config::{Platform, load_platform};
use cdpr_model::offset_target::{OffsetTarget, region_box};
use clap::Parser;
use crs_ipc::JointSetpoint;
use crs_limits::quantile::quantile_sorted;
use motion_core::daemon::config::DaemonConfig;
use motion_core::daemon::lifecycle::Configured;
use motion_core::daemon::realtime::{self, RealtimeSettings, monotonic_ns, sleep_until};
use motion_core::daemon::stats::LoopStats;
use motion_core::daemon::trajectory::{self, Waypoint};
use motion_core::daemon::{
    self, Command, CommandSource, HardLoop, LoopState, SetpointSink, lifecycle,
};
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

#[derive(Parser, Debug)]
#[command(
    name = "loop-jitter",
    about = "Wake-up lateness of the motion-core 1 ms loop vs a bare clock_nanosleep loop (same thread, same settings, alternating blocks)"
)]
struct Args {
    /// Daemon TOML: platform, surrogate, [realtime] and [trajectory] are taken from it.
    #[arg(long, default_value = "config/motion-core.toml")]
    config: PathBuf,
    /// Total measuring time, s (split evenly between the two loops).
    #[arg(long, default_value_t = 20.0)]
    seconds: f64,
    /// Length of one block of either loop, ms.
    #[arg(long, default_value_t = 250)]
    block_ms: u64,
    /// Override [realtime].priority (0 = SCHED_OTHER).
    #[arg(long)]
    priority: Option<i32>,
    /// Override [realtime].cpu (-1 = no pinning).
    #[arg(long, allow_hyphen_values = true)]
    cpu: Option<i64>,
    /// Run the loop without a surrogate offset (default: the configured surrogate file, or a
    /// degree-3 surrogate fitted at start-up when none is configured).
    #[arg(long)]
    no_surrogate: bool,
    /// Scenario label for the report (e.g. "idle", "stress-ng on cpu0").
    #[arg(long, default_value = "run")]
    label: String,
    /// Write the figures as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Print the two markdown table rows (scenario | loop | n | p50 | p99 | p99.9 | max | ratio).
    #[arg(long)]
    markdown: bool,
    /// Fail (exit 2) if any real-time setting degraded (not root / no RT).
    #[arg(long)]
    require_rt: bool,
    /// Fail (exit 3) when daemon p99 / bare p99 exceeds this (off by default: timing on a
    /// shared VM is reported, not asserted).
    #[arg(long)]
    max_p99_ratio: Option<f64>,
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("loop-jitter: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Exact per-cycle values (ns) in a buffer allocated before the loop starts.
struct Samples {
    values: Vec<u64>,
    len: usize,
    /// Cycles that did not fit (the buffer is sized for the run; should stay 0).
    lost: u64,
}

impl Samples {
    fn with_capacity(n: usize) -> Self {
        Self {
            values: vec![0; n],
            len: 0,
            lost: 0,
        }
    }

    #[inline]
    fn record(&mut self, v: u64) {
        if let Some(slot) = self.values.get_mut(self.len) {
            *slot = v;
            self.len += 1;
        } else {
            self.lost += 1;
        }
    }

    fn summary(&mut self) -> Summary {
        let v = &mut self.values[..self.len];
        v.sort_unstable();
        // The stack's one quantile definition (nearest rank), on the preallocated buffer.
        let q = |q: f64| -> u64 { quantile_sorted(v, q).unwrap_or(0) };
        Summary {
            n: v.len() as u64,
            p50_ns: q(0.5),
            p99_ns: q(0.99),
            p999_ns: q(0.999),
            max_ns: v.last().copied().unwrap_or(0),
            mean_ns: if v.is_empty() {
                0.0
            } else {
                v.iter().sum::<u64>() as f64 / v.len() as f64
            },
        }
    }
}

#[derive(Clone, Copy, Debug, serde::Serialize)]
struct Summary {
    n: u64,
    p50_ns: u64,
    p99_ns: u64,
    p999_ns: u64,
    max_ns: u64,
    mean_ns: f64,
}

/// The loop's sink: a preallocated ring of setpoints (the daemon pushes into a lock-free queue
/// instead; both are a copy into preallocated memory). It also records the wake-up lateness:
/// `sp.timestamp_ns` is the time `run_timed` read right after waking, `deadline` the deadline it
/// slept to (mirrored by the `after_cycle` hook).
struct RingSink<'a> {
    ring: Vec<JointSetpoint>,
    next: usize,
    deadline: &'a Cell<u64>,
    woke: &'a Cell<u64>,
    lateness: Samples,
}

impl SetpointSink for RingSink<'_> {
    #[inline]
    fn publish(&mut self, sp: &JointSetpoint) -> bool {
        let n = self.ring.len();
        self.ring[self.next % n] = *sp;
        self.next += 1;
        self.woke.set(sp.timestamp_ns);
        self.lateness
            .record(sp.timestamp_ns.saturating_sub(self.deadline.get()));
        true
    }
}

/// No operator or safety events in this measurement.
struct NoCommands;
impl CommandSource for NoCommands {
    #[inline]
    fn poll(&mut self) -> Option<Command> {
        None
    }
}

/// `run_timed`'s deadline rule: next period; when the cycle ended after it, skip the missed
/// periods. Returns the next deadline and whether this cycle overran.
#[inline]
fn next_deadline(deadline: u64, done: u64, period_ns: u64) -> (u64, bool) {
    let mut d = deadline + period_ns;
    let overrun = done > d;
    if overrun {
        d += ((done - d) / period_ns + 1) * period_ns;
    }
    (d, overrun)
}

/// The bare loop: sleep to the absolute deadline, read the clock, record, nothing else.
/// Returns the deadline following the block and the number of overruns. It sleeps with the
/// same `sleep_until` (crs-rt's) as `run_timed`: the baseline must differ from the daemon loop
/// only in the work between wake-ups, not in the timer.
fn bare_block(mut deadline: u64, period_ns: u64, end_ns: u64, out: &mut Samples) -> (u64, u64) {
    let mut overruns = 0;
    loop {
        sleep_until(deadline);
        let woke = monotonic_ns();
        out.record(woke.saturating_sub(deadline));
        let (d, over) = next_deadline(deadline, monotonic_ns(), period_ns);
        deadline = d;
        overruns += u64::from(over);
        if woke >= end_ns {
            return (deadline, overruns);
        }
    }
}

/// Degree-3 surrogate of the platform's elastostatic offset, fitted as `crs surrogate fit`
/// does (fewer validation samples, to keep the start-up short).
fn fit_surrogate(pf: &Platform) -> Result<surrogate::Surrogate, String> {
    let m = pf.model.m();
    let (lower, upper) = region_box(&pf.region);
    let mut target = OffsetTarget::new(&pf.model);
    let opts = surrogate::FitOptions {
        degree: 3,
        validation_samples: 1000,
        ..surrogate::FitOptions::default()
    };
    let (sg, _) = surrogate::fit(
        &surrogate::Region { lower, upper },
        &opts,
        m,
        &pf.model.identity_hex(),
        |x: &[f64; 6]| {
            let mut out = vec![0.0; m];
            target.offset(&Pose::from_array(*x), &mut out).map(|_| out)
        },
    )
    .map_err(|e| format!("surrogate fit: {e}"))?;
    Ok(sg)
}

/// The bench as its steps: check the flags, configure the daemon's loop as `motion-core`
/// does, plan the tour, measure both loops, report, judge.
fn run(args: Args) -> Result<ExitCode, String> {
    check_args(&args)?;
    let cfg = daemon::config::load(&args.config).map_err(|e| e.to_string())?;
    let platform = load_platform(&cfg.platform).map_err(|e| e.to_string())?;
    let rt = realtime_settings(&args, cfg.realtime)?;
    let (configured, surrogate_note) = configure(&args, &cfg, &platform)?;
    let waypoints = repeated_tour(&args, &cfg, &configured, &platform, rt.period_ns)?;
    let mut hard_loop = configured.activate(waypoints, |e| eprintln!("loop-jitter: planner: {e}"));
    let stats = LoopStats::default();
    let Some(m) = measure(&args, &rt, &mut hard_loop, &stats) else {
        eprintln!("loop-jitter: a real-time setting degraded and --require-rt was given");
        return Ok(ExitCode::from(2));
    };
    let state = hard_loop.state();
    print_report(&args, &m, &stats, state, &surrogate_note);
    if let Some(path) = &args.json {
        write_json(path, &args, &m, &stats, state, &surrogate_note)?;
    }
    Ok(verdict(&args, &m, &stats, state))
}

/// The flags' ranges, before anything is loaded.
fn check_args(args: &Args) -> Result<(), String> {
    if !(args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 3600.0) {
        return Err(format!(
            "--seconds must lie in (0, 3600], got {}",
            args.seconds
        ));
    }
    if !(10..=10_000).contains(&args.block_ms) {
        return Err(format!(
            "--block-ms must lie in 10..=10000, got {}",
            args.block_ms
        ));
    }
    Ok(())
}

/// The TOML's `[realtime]` with `--priority` and `--cpu` applied.
fn realtime_settings(args: &Args, mut rt: RealtimeSettings) -> Result<RealtimeSettings, String> {
    if let Some(p) = args.priority {
        if !(0..=99).contains(&p) {
            return Err(format!("--priority must lie in 0..=99, got {p}"));
        }
        rt.priority = p;
    }
    if let Some(c) = args.cpu {
        if c < -1 {
            return Err(format!("--cpu must be -1 or a CPU number, got {c}"));
        }
        rt.cpu = (c >= 0).then_some(c as usize);
    }
    Ok(rt)
}

/// The daemon's own configure step (surrogate of the TOML, identity- and bound-checked);
/// without one in the TOML a degree-3 surrogate is fitted here so the bench measures the loop
/// with an offset model, as the daemon runs it. Returns the configured loop and what the
/// report says of its surrogate.
fn configure(
    args: &Args,
    cfg: &DaemonConfig,
    platform: &Platform,
) -> Result<(Configured, String), String> {
    let mut daemon_cfg = cfg.clone();
    if args.no_surrogate {
        daemon_cfg.surrogate = None;
    }
    let mut configured = lifecycle::configure(&daemon_cfg, platform).map_err(|e| e.to_string())?;
    let surrogate_note = if args.no_surrogate {
        "none (--no-surrogate)".to_string()
    } else if let Some(s) = configured.surrogate() {
        format!("{}", s.path.display())
    } else {
        let sg = fit_surrogate(platform)?;
        let n = sg.n_cables();
        configured
            .install_surrogate(Box::new(sg), n)
            .map_err(|e| e.to_string())?;
        "degree 3, fitted at start-up".to_string()
    };
    Ok((configured, surrogate_note))
}

/// The demo tour, repeated so the plan outlasts the daemon's share of the run (it starts and
/// ends at home, so the repeats join up). A refused reference would latch the loop and
/// shorten its cycles: checked after the run ([`verdict`]).
fn repeated_tour(
    args: &Args,
    cfg: &DaemonConfig,
    configured: &Configured,
    platform: &Platform,
    period_ns: u64,
) -> Result<Vec<Waypoint>, String> {
    let t = &cfg.trajectory;
    let lim = configured.planner_limits();
    let period_s = period_ns as f64 * 1e-9;
    let tour: Vec<Waypoint> = match &t.waypoints {
        Some(p) => trajectory::read_waypoints(p).map_err(|e| e.to_string())?,
        None => Vec::new(),
    };
    let mut tour_samples = 0usize;
    trajectory::plan_samples::<String>(platform.home, &tour, lim, period_s, |_, _| {
        tour_samples += 1;
        Ok(())
    })?;
    let daemon_s = args.seconds / 2.0;
    let repeats = if tour_samples == 0 {
        0
    } else {
        (daemon_s / (tour_samples as f64 * period_s)).ceil() as usize + 1
    };
    Ok(tour
        .iter()
        .copied()
        .cycle()
        .take(tour.len() * repeats)
        .collect())
}

/// What one run measured.
struct Measurement {
    period_ns: u64,
    /// Pairs of blocks (daemon, bare).
    pairs: u64,
    /// The real-time settings as applied (`name: outcome`).
    applied: Vec<String>,
    realtime_degraded: bool,
    loadavg_before: String,
    loadavg_after: String,
    /// Wake-up lateness of the daemon loop.
    daemon: Summary,
    /// Wake-up lateness of the bare loop.
    bare: Summary,
    /// The daemon's compute per cycle (wake → setpoint in the sink).
    compute: Summary,
    bare_overruns: u64,
    /// Samples that did not fit the preallocated buffers (should stay 0).
    lost_samples: u64,
}

impl Measurement {
    /// Daemon over bare at p50, p99, p99.9 and max (NaN where the bare loop has no sample).
    fn ratios(&self) -> [f64; 4] {
        let ratio = |x: u64, y: u64| {
            if y == 0 {
                f64::NAN
            } else {
                x as f64 / y as f64
            }
        };
        let (d, b) = (&self.daemon, &self.bare);
        [
            ratio(d.p50_ns, b.p50_ns),
            ratio(d.p99_ns, b.p99_ns),
            ratio(d.p999_ns, b.p999_ns),
            ratio(d.max_ns, b.max_ns),
        ]
    }
}

/// Runs the two loops in alternating blocks on one timeline. Everything the loops touch is
/// allocated first, then the real-time settings are applied; `None` when one degraded and
/// `--require-rt` was given (nothing measured).
fn measure(
    args: &Args,
    rt: &RealtimeSettings,
    hard_loop: &mut HardLoop,
    stats: &LoopStats,
) -> Option<Measurement> {
    let period_ns = rt.period_ns;
    let block_ns = args.block_ms * 1_000_000;
    let total_ns = (args.seconds * 1e9) as u64;
    // Pairs of blocks (daemon, bare); each block runs block/period cycles plus at most one.
    let pairs = total_ns.div_ceil(2 * block_ns);
    let cycles_per_loop = (pairs * (block_ns / period_ns + 2)) as usize;
    let deadline = Cell::new(0u64);
    let woke = Cell::new(0u64);
    let mut sink = RingSink {
        ring: vec![JointSetpoint::default(); 1024],
        next: 0,
        deadline: &deadline,
        woke: &woke,
        lateness: Samples::with_capacity(cycles_per_loop),
    };
    let mut compute = Samples::with_capacity(cycles_per_loop);
    let mut bare = Samples::with_capacity(cycles_per_loop);
    let stop = AtomicBool::new(false);
    let mut cmds = NoCommands;
    // Let the planner fill its look-ahead queue, as the daemon's 50 ms start offset does.
    std::thread::sleep(std::time::Duration::from_millis(300));

    let report = realtime::apply(rt);
    let applied: Vec<String> = report
        .lines()
        .iter()
        .map(|(name, a)| format!("{name}: {a}"))
        .collect();
    for line in &applied {
        println!("realtime {line}");
    }
    if args.require_rt && report.degraded() {
        return None;
    }
    let loadavg_before = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();

    // One continuous timeline, aligned to the period, a few periods ahead.
    let t0 = monotonic_ns() + 10 * period_ns;
    let mut next = t0 - t0 % period_ns + period_ns;
    let mut bare_overruns = 0u64;
    // Its own grid: no drive bus announces a SYNC schedule here.
    let timeline = motion_core::daemon::timeline::Timeline::new(period_ns);
    for _ in 0..pairs {
        // Daemon block: the real loop until `after_cycle` stops it at the block's end.
        let end = next + block_ns;
        deadline.set(next);
        stop.store(false, Ordering::Relaxed);
        daemon::run_timed(
            hard_loop,
            next,
            &timeline,
            &mut sink,
            &mut cmds,
            stats,
            &stop,
            |_, done| {
                compute.record(done.saturating_sub(woke.get()));
                deadline.set(next_deadline(deadline.get(), done, period_ns).0);
                if done >= end {
                    stop.store(true, Ordering::Relaxed);
                }
            },
        );
        // Bare block on the same timeline, from the daemon's next deadline.
        let (d, over) = bare_block(
            deadline.get(),
            period_ns,
            deadline.get() + block_ns,
            &mut bare,
        );
        bare_overruns += over;
        next = d;
    }
    let loadavg_after = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();

    Some(Measurement {
        period_ns,
        pairs,
        applied,
        realtime_degraded: report.degraded(),
        loadavg_before,
        loadavg_after,
        daemon: sink.lateness.summary(),
        bare: bare.summary(),
        compute: compute.summary(),
        bare_overruns,
        lost_samples: sink.lateness.lost + bare.lost + compute.lost,
    })
}

fn us(ns: u64) -> f64 {
    ns as f64 / 1e3
}

/// The report on stdout: both loops' lateness and their ratio, the daemon's compute, overruns,
/// the daemon's own `LoopStats` as a cross-check and, with `--markdown`, the two table rows.
fn print_report(
    args: &Args,
    m: &Measurement,
    stats: &LoopStats,
    state: LoopState,
    surrogate_note: &str,
) {
    let (d, b, c) = (&m.daemon, &m.bare, &m.compute);
    let ratios = m.ratios();
    println!(
        "scenario `{}`: period {} µs, {} blocks of {} ms per loop, surrogate {surrogate_note}",
        args.label,
        m.period_ns / 1000,
        m.pairs,
        args.block_ms
    );
    println!("load average before: {}", m.loadavg_before.trim());
    println!("load average after:  {}", m.loadavg_after.trim());
    println!("wake-up lateness, µs     n       p50      p99    p99.9      max");
    for (name, s) in [("daemon loop", d), ("bare loop  ", b)] {
        println!(
            "  {name}   {:>7} {:>8.1} {:>8.1} {:>8.1} {:>8.1}",
            s.n,
            us(s.p50_ns),
            us(s.p99_ns),
            us(s.p999_ns),
            us(s.max_ns)
        );
    }
    println!(
        "  ratio daemon/bare            {:>8.2} {:>8.2} {:>8.2} {:>8.2}",
        ratios[0], ratios[1], ratios[2], ratios[3]
    );
    println!(
        "daemon compute per cycle (wake → setpoint in the sink), µs: p50 {:.2}, p99 {:.2}, p99.9 {:.2}, max {:.1}",
        us(c.p50_ns),
        us(c.p99_ns),
        us(c.p999_ns),
        us(c.max_ns)
    );
    println!(
        "overruns: daemon {} (LoopStats), bare {}; daemon cycles {}, rejected references {}, final state {state:?}",
        stats.overruns.load(Ordering::Relaxed),
        m.bare_overruns,
        stats.cycles.load(Ordering::Relaxed),
        stats.rejected.load(Ordering::Relaxed),
    );
    println!(
        "cross-check, the daemon's own LoopStats: lateness {}; compute {}",
        stats.lateness.snapshot().summary(),
        stats.compute.snapshot().summary()
    );
    if args.markdown {
        let row = |name: &str, s: &Summary, r: Option<&[f64; 4]>| {
            format!(
                "| {} | {name} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {} |",
                args.label,
                s.n,
                us(s.p50_ns),
                us(s.p99_ns),
                us(s.p999_ns),
                us(s.max_ns),
                match r {
                    Some(r) => format!("{:.2} / {:.2} / {:.2} / {:.2}", r[0], r[1], r[2], r[3]),
                    None => "1 (reference)".into(),
                }
            )
        };
        println!(
            "{}",
            row("motion-core loop (HardLoop + run_timed)", d, Some(&ratios))
        );
        println!(
            "{}",
            row("bare clock_nanosleep, same thread, interleaved", b, None)
        );
    }
}

/// The figures as JSON (`--json`).
fn write_json(
    path: &Path,
    args: &Args,
    m: &Measurement,
    stats: &LoopStats,
    state: LoopState,
    surrogate_note: &str,
) -> Result<(), String> {
    let ratios = m.ratios();
    let json = serde_json::json!({
        "label": args.label,
        "period_ns": m.period_ns,
        "block_ms": args.block_ms,
        "blocks_per_loop": m.pairs,
        "surrogate": surrogate_note,
        "realtime": m.applied,
        "realtime_degraded": m.realtime_degraded,
        "loadavg_before": m.loadavg_before.trim(),
        "loadavg_after": m.loadavg_after.trim(),
        "daemon_lateness": m.daemon,
        "bare_lateness": m.bare,
        "ratio_daemon_over_bare": {"p50": ratios[0], "p99": ratios[1], "p999": ratios[2], "max": ratios[3]},
        "daemon_compute": m.compute,
        "daemon_overruns": stats.overruns.load(Ordering::Relaxed),
        "bare_overruns": m.bare_overruns,
        "rejected": stats.rejected.load(Ordering::Relaxed),
        "final_state": format!("{state:?}"),
        "lost_samples": m.lost_samples,
    });
    std::fs::write(path, format!("{json:#}\n")).map_err(|e| format!("{}: {e}", path.display()))
}

/// Failure when the loop refused a reference (its cycles are not representative) or, with
/// `--max-p99-ratio`, when the daemon's p99 is too far above the bare loop's.
fn verdict(args: &Args, m: &Measurement, stats: &LoopStats, state: LoopState) -> ExitCode {
    let rejected = stats.rejected.load(Ordering::Relaxed);
    if state != LoopState::Running || rejected > 0 {
        eprintln!(
            "loop-jitter: the loop refused a reference (state {state:?}): its cycles are not representative"
        );
        return ExitCode::FAILURE;
    }
    // A NaN ratio (no bare samples) fails too.
    let p99_ratio = m.ratios()[1];
    if let Some(max) = args.max_p99_ratio
        && (p99_ratio.is_nan() || p99_ratio > max)
    {
        eprintln!(
            "loop-jitter: p99 ratio daemon/bare {p99_ratio:.2} exceeds --max-p99-ratio {max}"
        );
        return ExitCode::from(3);
    }
    ExitCode::SUCCESS
}
