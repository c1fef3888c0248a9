//! The CAN buses of a run of the stack: by default the wire model — a `can-wire` hub with one
//! bus per interface of the drives config, so every run carries the wire's bit time,
//! arbitration and transmit queues (docs/can-protocol.md "The wire model") — or real vcan
//! ports with the hub forwarding between them (the QEMU guest), or explicit transports.

use crate::supervisor::{SpawnError, Supervisor};
use drives_config::DrivesConfig;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// `--transport` names no bus layout this run can use.
#[derive(Debug, thiserror::Error)]
pub enum BadTransport {
    #[error(
        "--transport {0:?}: expected `wire` (default: the wire model on unix sockets), `vcan` \
         (one vcan port per process and interface, forwarded by the hub: the QEMU guest), \
         `udpbus` (no bus physics: every frame in no time, for comparison only), or NAME=SPEC \
         per interface / a bare SPEC with one interface"
    )]
    Unknown(String),
    #[error("--transport {arg:?}: {reason}")]
    Invalid { arg: String, reason: String },
    #[error("creating vcan port {port}: {detail}")]
    Vcan { port: String, detail: String },
    #[error(transparent)]
    Spawn(#[from] SpawnError),
    #[error("the wire hub (can-wire) did not get ready within {secs} s: {log_tail}")]
    HubNotReady { secs: u64, log_tail: String },
    #[error("the wire hub (can-wire) exited before it was ready ({status}): {log_tail}")]
    HubExited {
        status: std::process::ExitStatus,
        log_tail: String,
    },
}

/// SCHED_FIFO priority of a run's wire hub (above the daemons').
pub const HUB_RT_PRIORITY: i32 = 85;

/// Frames a node's transmit queue holds in the runs' wire model (the control PC's txqueuelen).
pub const TX_QUEUE_FRAMES: usize = 100;

/// How this run's processes reach the buses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BusMode {
    /// The wire model over unix sockets (host and guest).
    Wire,
    /// The wire model over vcan: one port per process and interface (needs vcan and `ip`).
    Vcan,
    /// The multicast UDP bus of earlier runs: no bus physics.
    Udp,
    /// Given transports (`NAME=SPEC` per interface or one bare SPEC), used as they are.
    Explicit(Vec<String>),
}

impl BusMode {
    pub fn parse(arg: &str) -> Result<Self, BadTransport> {
        match arg {
            "auto" | "wire" => Ok(Self::Wire),
            "vcan" => Ok(Self::Vcan),
            "udpbus" => Ok(Self::Udp),
            other => {
                let list: Vec<String> = other.split(' ').map(str::to_string).collect();
                for t in &list {
                    let spec = t
                        .split_once('=')
                        .filter(|(n, _)| !n.contains(':'))
                        .map_or(t.as_str(), |x| x.1);
                    spec.parse::<can_transport::TransportSpec>()
                        .map_err(|_| BadTransport::Unknown(arg.to_string()))?;
                }
                Ok(Self::Explicit(list))
            }
        }
    }

    pub fn describe(&self) -> String {
        match self {
            Self::Wire => "the wire model (can-wire, unix sockets)".into(),
            Self::Vcan => "the wire model over vcan ports (can-wire forwarding)".into(),
            Self::Udp => "the UDP loopback bus (no bus physics)".into(),
            Self::Explicit(t) => t.join(" "),
        }
    }
}

/// The buses of a started run: what each process is given as `--transport`, and the hub.
#[derive(Debug)]
pub struct StackBuses {
    /// Per process name: its `NAME=SPEC` per interface.
    per_process: Vec<(String, Vec<String>)>,
    /// The hub's statistics file (wire modes).
    pub stats: Option<PathBuf>,
    pub mode: BusMode,
}

impl StackBuses {
    /// `--transport NAME=SPEC` arguments of `process`.
    pub fn args(&self, process: &str) -> Vec<String> {
        self.per_process
            .iter()
            .find(|(p, _)| p == process)
            .map(|(_, t)| {
                t.iter()
                    .flat_map(|x| ["--transport".to_string(), x.clone()])
                    .collect()
            })
            .unwrap_or_default()
    }

    /// The transports of `process` (NAME=SPEC).
    pub fn transports(&self, process: &str) -> Vec<String> {
        self.per_process
            .iter()
            .find(|(p, _)| p == process)
            .map(|(_, t)| t.clone())
            .unwrap_or_default()
    }
}

/// Starts the buses of a run: for the wire modes the `can-wire` hub (as `can-wire` under
/// `stack`, waited on until ready) with one bus per interface of `drives` at its bit rate.
/// `processes` are the names of the run's CAN nodes (each gets its own vcan port per interface
/// in [`BusMode::Vcan`]). `run_tag` makes this run's sockets and ports its own.
pub fn start(
    mode: &BusMode,
    drives: &DrivesConfig,
    processes: &[&str],
    stack: &mut Supervisor,
    hub_exe: &Path,
    out: &Path,
    run_tag: &str,
) -> Result<StackBuses, BadTransport> {
    let itfs = drives.interfaces();
    let same_for_all = |t: Vec<String>| -> Vec<(String, Vec<String>)> {
        processes
            .iter()
            .map(|p| ((*p).to_string(), t.clone()))
            .collect()
    };
    match mode {
        BusMode::Explicit(t) => Ok(StackBuses {
            per_process: same_for_all(t.clone()),
            stats: None,
            mode: mode.clone(),
        }),
        BusMode::Udp => {
            // One multicast port per interface, derived from the run (runs in one process do
            // not share a bus).
            let base = 20000 + (std::process::id() % 2000) * 8;
            let t = itfs
                .iter()
                .enumerate()
                .map(|(k, i)| format!("{}=udpbus:239.255.70.9:{}", i.name, base as usize + k))
                .collect();
            Ok(StackBuses {
                per_process: same_for_all(t),
                stats: None,
                mode: mode.clone(),
            })
        }
        BusMode::Wire | BusMode::Vcan => {
            // Unix socket paths are limited to 108 bytes: the sockets live in a short
            // directory of their own, the statistics with the run's other outputs.
            let sock_dir = std::env::temp_dir().join(format!("crs-wire-{run_tag}"));
            let _ = std::fs::remove_dir_all(&sock_dir);
            std::fs::create_dir_all(&sock_dir).map_err(|e| BadTransport::Invalid {
                arg: "wire".into(),
                reason: format!("{}: {e}", sock_dir.display()),
            })?;
            let stats = out.join("wire.json");
            let ready = out.join("wire.ready");
            let _ = std::fs::remove_file(&ready);
            let mut args = Vec::new();
            let mut per_process: Vec<(String, Vec<String>)> = processes
                .iter()
                .map(|p| ((*p).to_string(), Vec::new()))
                .collect();
            for (k, itf) in itfs.iter().enumerate() {
                let endpoint = if *mode == BusMode::Wire {
                    let sock = sock_dir.join(format!("{}.sock", itf.name));
                    for (_, t) in &mut per_process {
                        t.push(format!("{}=wire:{}", itf.name, sock.display()));
                    }
                    format!("socket={}", sock.display())
                } else {
                    let mut ports = Vec::new();
                    for (p, (_, t)) in per_process.iter_mut().enumerate() {
                        // Interface names: at most 15 bytes. A port per (interface, process):
                        // the runs of one guest boot are sequential and reuse them.
                        let port = format!("vw{k}n{p}");
                        make_vcan(&port)?;
                        t.push(format!("{}=socketcan:{port}", itf.name));
                        ports.push(port);
                    }
                    format!("ports={}", ports.join("+"))
                };
                args.push("--bus".to_string());
                // Each node's transmit queue holds TX_QUEUE_FRAMES frames, as the control PC's
                // interfaces are set up (`ip link set canN txqueuelen 100`, docs/can-protocol.md):
                // the kernel's default of 10 also refuses sends while the HUB (a process on this
                // non-real-time host) is late, which the wire itself would not.
                args.push(format!(
                    "name={},bitrate={},queue={TX_QUEUE_FRAMES},{endpoint}",
                    itf.name, itf.bitrate_bit_per_s
                ));
            }
            args.extend([
                "--stats".to_string(),
                stats.display().to_string(),
                "--ready-file".to_string(),
                ready.display().to_string(),
                // The hub stands for the wire: it must not be starved by the nodes it carries
                // (a late delivery looks like a silent node to every watchdog). Above every
                // daemon's SCHED_FIFO priority (motion-core's loop 80); degrades with a
                // warning where not permitted.
                "--rt-priority".to_string(),
                HUB_RT_PRIORITY.to_string(),
            ]);
            stack.spawn("can-wire", hub_exe, &args, &[])?;
            let t0 = Instant::now();
            while !ready.exists() {
                if let Some(e) = stack.exited() {
                    return Err(BadTransport::HubExited {
                        status: e.status,
                        log_tail: crate::supervisor::log_tail(&e.log, 10),
                    });
                }
                if t0.elapsed() > Duration::from_secs(20) {
                    return Err(BadTransport::HubNotReady {
                        secs: 20,
                        log_tail: crate::supervisor::log_tail(&out.join("can-wire.log"), 10),
                    });
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            Ok(StackBuses {
                per_process,
                stats: Some(stats),
                mode: mode.clone(),
            })
        }
    }
}

/// Creates and brings up a vcan interface (the QEMU guest runs as root with `ip`).
fn make_vcan(port: &str) -> Result<(), BadTransport> {
    let run = |args: &[&str]| {
        std::process::Command::new("ip")
            .args(args)
            .output()
            .map_err(|e| BadTransport::Vcan {
                port: port.to_string(),
                detail: format!("running ip: {e}"),
            })
    };
    let exists = std::path::Path::new("/sys/class/net").join(port).exists();
    if !exists {
        let o = run(&["link", "add", "dev", port, "type", "vcan"])?;
        if !o.status.success() {
            return Err(BadTransport::Vcan {
                port: port.to_string(),
                detail: format!(
                    "ip link add: {} (this kernel needs vcan; on a host without CAN use \
                     --transport wire)",
                    String::from_utf8_lossy(&o.stderr).trim()
                ),
            });
        }
    }
    let o = run(&["link", "set", "up", port])?;
    if !o.status.success() {
        return Err(BadTransport::Vcan {
            port: port.to_string(),
            detail: format!(
                "ip link set up: {}",
                String::from_utf8_lossy(&o.stderr).trim()
            ),
        });
    }
    Ok(())
}

/// What the hub's statistics file says of each bus, for the run's summary.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct WireSummary {
    pub bus: String,
    pub frames: u64,
    /// Busy time over the run, percent of the bit rate.
    pub load_mean_percent: f64,
    /// The busiest 1 s window, percent (None before a whole window passed).
    pub load_max_percent: Option<f64>,
    /// Frames dropped at a full transmit queue (the sender's ENOBUFS), all nodes.
    pub dropped: u64,
    /// The longest time any frame took from its submission to its end of frame, µs.
    pub latency_max_us: f64,
    /// Submissions the hub learned of after an arbitration they should have joined.
    pub violations: u64,
}

/// Reads the hub's final statistics (`None` if the file is missing or not what the hub writes).
pub fn read_wire_stats(path: &Path) -> Option<Vec<WireSummary>> {
    let text = std::fs::read_to_string(path).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    let buses = v.get("buses")?.as_array()?;
    buses
        .iter()
        .map(|b| {
            Some(WireSummary {
                bus: b.get("name")?.as_str()?.to_string(),
                frames: b.get("frames")?.as_u64()?,
                load_mean_percent: 100.0 * b.get("load_mean")?.as_f64()?,
                load_max_percent: b
                    .get("load_window_max")
                    .and_then(serde_json::Value::as_f64)
                    .map(|x| 100.0 * x),
                dropped: b.get("dropped")?.as_u64()?,
                latency_max_us: b.get("latency_max_ns")?.as_f64()? / 1000.0,
                violations: b.get("violations")?.as_u64()?,
            })
        })
        .collect()
}
