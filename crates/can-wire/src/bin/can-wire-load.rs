//! `can-wire-load`: the hub's CPU cost at a given load, alternatives side by side in one run.
//!
//! Starts the hub (`--hub`, a release build) with `--buses` buses of `--nodes` `wire:` clients
//! each; every 1 ms each bus carries `--frames-per-ms` frames (a SYNC and 4-byte frames spread
//! over its nodes), every frame delivered to every other node of its bus. After `--seconds`
//! the hub is stopped and its statistics read: CPU of the hub's loop thread and of the whole
//! process (/proc) per frame and as a share of one core, wake-ups per frame, delivery lateness.
//! Each `--coalesce-us` value is one configuration; they alternate for `--rounds` rounds.

use can_transport::{CanBus, CanError, CanFrame};
use clap::Parser;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

#[derive(Parser)]
struct Args {
    /// The can-wire binary to measure.
    #[arg(long)]
    hub: PathBuf,
    #[arg(long, default_value_t = 5)]
    buses: usize,
    #[arg(long, default_value_t = 3)]
    nodes: usize,
    #[arg(long, default_value_t = 10)]
    frames_per_ms: usize,
    #[arg(long, default_value_t = 10)]
    seconds: u64,
    /// Coalescing windows to compare, µs (comma separated).
    #[arg(long, default_value = "0,60", value_delimiter = ',')]
    coalesce_us: Vec<u64>,
    #[arg(long, default_value_t = 50)]
    lookahead_us: u64,
    #[arg(long, default_value_t = 2)]
    rounds: usize,
    /// The hub's SCHED_FIFO priority (0: SCHED_OTHER).
    #[arg(long, default_value_t = 0)]
    rt_priority: i32,
    #[arg(long, default_value = "target/can-wire-load")]
    dir: PathBuf,
}

/// utime + stime of a process, ns (/proc/<pid>/stat, clock ticks).
fn process_cpu_ns(pid: u32) -> u64 {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = s.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: u64 = f.get(11).and_then(|v| v.parse().ok()).unwrap_or(0)
        + f.get(12).and_then(|v| v.parse().ok()).unwrap_or(0);
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as u64;
    ticks * 1_000_000_000 / hz
}

struct Outcome {
    frames: u64,
    loop_cpu_s: f64,
    process_cpu_s: f64,
    wakeups: u64,
    lateness_p50_ns: u64,
    lateness_p99_ns: u64,
    dropped: u64,
    violations: u64,
    load: f64,
}

fn run_once(a: &Args, coalesce_us: u64, tag: &str) -> Result<Outcome, String> {
    let dir = a.dir.join(tag);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let socks: Vec<PathBuf> = (0..a.buses)
        .map(|b| dir.join(format!("can{b}.sock")))
        .collect();
    let mut cmd = Command::new(&a.hub);
    for (b, s) in socks.iter().enumerate() {
        cmd.arg("--bus").arg(format!(
            "name=can{b},bitrate=1000000,socket={}",
            s.display()
        ));
    }
    let stats = dir.join("wire.json");
    let ready = dir.join("ready");
    let mut hub = cmd
        .arg("--stats")
        .arg(&stats)
        .arg("--ready-file")
        .arg(&ready)
        .args(["--rt-priority", &a.rt_priority.to_string()])
        .args(["--lookahead-us", &a.lookahead_us.to_string()])
        .args(["--coalesce-us", &coalesce_us.to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("{}: {e}", a.hub.display()))?;
    let t = Instant::now();
    while !ready.exists() {
        if t.elapsed() > Duration::from_secs(30) {
            let _ = hub.kill();
            return Err("hub not ready".into());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut clients: Vec<Vec<Box<dyn CanBus>>> = socks
        .iter()
        .map(|s| {
            (0..a.nodes)
                .map(|_| {
                    can_transport::open(&format!("wire:{}", s.display()).parse().unwrap())
                        .expect("connecting")
                })
                .collect()
        })
        .collect();
    let cpu0 = process_cpu_ns(hub.id());
    let t0 = can_transport::monotonic_ns() + 5_000_000;
    let cycles = a.seconds * 1000;
    for c in 0..cycles {
        let tick = t0 + c * 1_000_000;
        crs_rt::sleep_until(tick);
        for bus in clients.iter_mut() {
            for k in 0..a.frames_per_ms {
                let node = k % a.nodes;
                let f = if k == 0 {
                    CanFrame::new(0x080, &[]).unwrap()
                } else {
                    CanFrame::new(0x180 + k as u16, &[k as u8, 0, c as u8, 0]).unwrap()
                };
                match bus[node].send(&f) {
                    Ok(()) => {}
                    Err(CanError::TxFull { .. }) => {} // counted by the hub
                    Err(e) => return Err(e.to_string()),
                }
            }
        }
        // Drain every client half-way through the cycle and before the next.
        for half in [500_000, 950_000] {
            crs_rt::sleep_until(tick + half);
            for bus in clients.iter_mut() {
                for n in bus.iter_mut() {
                    while let Ok(Some(_)) = n.try_recv() {}
                }
            }
        }
    }
    let cpu1 = process_cpu_ns(hub.id());
    drop(clients);
    // SAFETY: signalling our own child by its pid.
    unsafe { libc::kill(hub.id() as libc::pid_t, libc::SIGTERM) };
    hub.wait().map_err(|e| e.to_string())?;
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).map_err(|e| e.to_string())?)
            .map_err(|e| e.to_string())?;
    let buses = v["buses"].as_array().cloned().unwrap_or_default();
    let sum = |k: &str| {
        buses
            .iter()
            .map(|b| b[k].as_u64().unwrap_or(0))
            .sum::<u64>()
    };
    let worst = |k: &str| {
        buses
            .iter()
            .map(|b| b["delivery_lateness_ns"][k].as_u64().unwrap_or(0))
            .max()
            .unwrap_or(0)
    };
    Ok(Outcome {
        frames: sum("frames"),
        loop_cpu_s: v["hub"]["cpu_s"].as_f64().unwrap_or(0.0),
        process_cpu_s: (cpu1 - cpu0) as f64 * 1e-9,
        wakeups: v["hub"]["wakeups"].as_u64().unwrap_or(0),
        lateness_p50_ns: worst("p50"),
        lateness_p99_ns: worst("p99"),
        dropped: sum("dropped"),
        violations: sum("violations"),
        load: buses
            .iter()
            .map(|b| b["load_mean"].as_f64().unwrap_or(0.0))
            .sum::<f64>()
            / buses.len().max(1) as f64,
    })
}

fn main() {
    let a = Args::parse();
    println!(
        "| coalesce | round | frames | loop CPU µs/frame | process CPU µs/frame | process CPU % of a core | wake-ups/frame | delivery lateness p50 / p99 µs (worst bus) | mean load | dropped | violations |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for round in 0..a.rounds {
        for &c in &a.coalesce_us {
            match run_once(&a, c, &format!("c{c}-r{round}")) {
                Ok(o) => {
                    let f = o.frames.max(1) as f64;
                    println!(
                        "| {c} µs | {} | {} | {:.2} | {:.2} | {:.1} | {:.2} | {:.1} / {:.1} | {:.2} | {} | {} |",
                        round + 1,
                        o.frames,
                        o.loop_cpu_s * 1e6 / f,
                        o.process_cpu_s * 1e6 / f,
                        o.process_cpu_s / a.seconds as f64 * 100.0,
                        o.wakeups as f64 / f,
                        o.lateness_p50_ns as f64 / 1e3,
                        o.lateness_p99_ns as f64 / 1e3,
                        o.load,
                        o.dropped,
                        o.violations,
                    );
                }
                Err(e) => println!("| {c} µs | {} | FAILED: {e} | | | | | | | | |", round + 1),
            }
        }
    }
}
