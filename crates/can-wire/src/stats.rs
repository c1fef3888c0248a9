//! The hub's statistics: the hub's own per-bus figures ([`HubBusStats`]), and the writer thread
//! that merges the blocks the hub hands over about once per second, rewrites the stats JSON
//! (atomically: a temporary file renamed over it) and logs one summary line per bus at exit.
//! The hub thread never formats or writes anything itself.

use crate::config::{Endpoint, HubConfig};
use can_bus_model::{BusStats, HISTOGRAM_MAX_NS, HISTOGRAM_SIGFIG, IdStats, WINDOW_NS};
use hdrhistogram::Histogram;
use serde::Serialize;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

/// The hub's own figures for one bus over an interval.
#[derive(Debug, Clone)]
pub struct HubBusStats {
    /// Real time of delivery − end of frame, ns: how late the hub handed frames out.
    pub lateness: Histogram<u32>,
    pub lateness_max_ns: u64,
    /// Error frames passed through.
    pub error_frames: u64,
    /// Malformed messages and records, stray handshakes.
    pub protocol_errors: u64,
    /// Connections refused (node slots or pending slots used up).
    pub refused_connections: u64,
    /// Per node: records that could not be delivered (its receive buffer was full).
    pub rx_dropped: Vec<u64>,
}

impl HubBusStats {
    pub fn new(nodes: usize) -> Self {
        Self {
            lateness: Histogram::new_with_bounds(1, HISTOGRAM_MAX_NS, HISTOGRAM_SIGFIG)
                .expect("constant histogram bounds are valid"),
            lateness_max_ns: 0,
            error_frames: 0,
            protocol_errors: 0,
            refused_connections: 0,
            rx_dropped: vec![0; nodes],
        }
    }
    pub fn reset(&mut self) {
        self.lateness.reset();
        self.lateness_max_ns = 0;
        self.error_frames = 0;
        self.protocol_errors = 0;
        self.refused_connections = 0;
        self.rx_dropped.fill(0);
    }
    pub fn merge(&mut self, o: &HubBusStats) {
        let _ = self.lateness.add(&o.lateness);
        self.lateness_max_ns = self.lateness_max_ns.max(o.lateness_max_ns);
        self.error_frames += o.error_frames;
        self.protocol_errors += o.protocol_errors;
        self.refused_connections += o.refused_connections;
        for (a, b) in self.rx_dropped.iter_mut().zip(&o.rx_dropped) {
            *a += b;
        }
    }
}

/// A node joined or left a bus.
#[derive(Debug, Clone)]
pub struct NodeEvent {
    pub bus: usize,
    pub node: usize,
    pub name: String,
    pub joined: bool,
}

/// Hub thread → writer.
pub enum ToWriter {
    Node(NodeEvent),
    Interval {
        bus: usize,
        model: Box<BusStats>,
        hub: Box<HubBusStats>,
    },
    /// All buses' blocks of this interval are sent: write the file (and, if `last`, finish).
    Tick {
        now_ns: u64,
        wakeups: u64,
        cpu_ns: u64,
        last: bool,
    },
}

type Spare = (usize, Box<BusStats>, Box<HubBusStats>);

/// The writer thread.
pub struct Writer {
    tx: SyncSender<ToWriter>,
    thread: Option<std::thread::JoinHandle<()>>,
}

struct BusAcc {
    name: String,
    endpoint: String,
    bitrate_bps: u32,
    queue_len: usize,
    model: BusStats,
    hub: HubBusStats,
    node_names: Vec<Option<String>>,
    connected: Vec<bool>,
}

impl Writer {
    /// Starts the writer; returns it, a sender for the hub thread and the channel on which
    /// emptied blocks come back.
    pub fn start(
        cfg: &HubConfig,
        t0_ns: u64,
        scheduler: String,
    ) -> (Self, SyncSender<ToWriter>, Receiver<Spare>) {
        let (tx, rx) = sync_channel::<ToWriter>(cfg.buses.len() * 4 + 64);
        let (spare_tx, spare_rx) = sync_channel::<Spare>(cfg.buses.len() * 4 + 4);
        let accs: Vec<BusAcc> = cfg
            .buses
            .iter()
            .map(|b| BusAcc {
                name: b.name.clone(),
                endpoint: match &b.endpoint {
                    Endpoint::Socket(p) => format!("socket {}", p.display()),
                    Endpoint::Ports(ps) => format!("ports {}", ps.join("+")),
                },
                bitrate_bps: b.bitrate_bps,
                queue_len: b.queue_len,
                model: BusStats::new(&b.model_config()),
                hub: HubBusStats::new(b.max_nodes),
                node_names: vec![None; b.max_nodes],
                connected: vec![false; b.max_nodes],
            })
            .collect();
        let path = cfg.stats_path.clone();
        let meta = Meta {
            lookahead_ns: cfg.lookahead_ns,
            coalesce_ns: cfg.coalesce_ns,
            scheduler,
            t0_ns,
        };
        let thread = std::thread::Builder::new()
            .name("can-wire-stats".into())
            .spawn(move || {
                let _ = crs_rt::set_thread_nice(10);
                run_writer(rx, spare_tx, accs, path, meta)
            })
            .expect("spawning the statistics thread");
        (
            Self {
                tx: tx.clone(),
                thread: Some(thread),
            },
            tx,
            spare_rx,
        )
    }

    pub fn sender(&self) -> SyncSender<ToWriter> {
        self.tx.clone()
    }

    /// Waits for the writer to finish (after the last tick).
    pub fn finish(mut self) {
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Meta {
    lookahead_ns: u64,
    coalesce_ns: u64,
    scheduler: String,
    t0_ns: u64,
}

fn run_writer(
    rx: Receiver<ToWriter>,
    spare_tx: SyncSender<Spare>,
    mut accs: Vec<BusAcc>,
    path: Option<PathBuf>,
    meta: Meta,
) {
    while let Ok(msg) = rx.recv() {
        match msg {
            ToWriter::Node(e) => {
                if let Some(a) = accs.get_mut(e.bus)
                    && e.node < a.connected.len()
                {
                    a.connected[e.node] = e.joined;
                    if e.joined {
                        a.node_names[e.node] = Some(e.name);
                    }
                }
            }
            ToWriter::Interval { bus, model, hub } => {
                if let Some(a) = accs.get_mut(bus) {
                    a.model.merge(&model);
                    a.hub.merge(&hub);
                }
                let _ = spare_tx.try_send((bus, model, hub));
            }
            ToWriter::Tick {
                now_ns,
                wakeups,
                cpu_ns,
                last,
            } => {
                let file = snapshot(&accs, &meta, now_ns, wakeups, cpu_ns, last);
                if let Some(p) = &path
                    && let Err(e) = write_atomically(p, &file)
                {
                    tracing::warn!(path = %p.display(), error = %e, "writing the statistics failed");
                }
                if last {
                    for b in &file.buses {
                        tracing::info!("{}", summary_line(b));
                    }
                    return;
                }
            }
        }
    }
}

/// A delay distribution: count, p50, p99, max (ns).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Delays {
    pub count: u64,
    pub p50: Option<u64>,
    pub p99: Option<u64>,
    pub max: u64,
}

impl Delays {
    /// Quantiles from the histogram (bucket upper ends, 2 significant digits), never above
    /// the exact maximum.
    fn of(h: &Histogram<u32>, max: u64) -> Self {
        Self {
            count: h.len(),
            p50: IdStats::quantile(h, 0.5).map(|v| v.min(max)),
            p99: IdStats::quantile(h, 0.99).map(|v| v.min(max)),
            max,
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct NodeJson {
    pub node: usize,
    pub name: String,
    pub connected: bool,
    pub sent: u64,
    pub dropped: u64,
    pub lost_at_leave: u64,
    pub max_queue_depth: u32,
    pub rx_dropped: u64,
}

#[derive(Debug, Clone, Serialize)]
pub struct IdJson {
    /// `0x080` (standard), `0x18ff0001` (extended) or `other` (the pooled rest).
    pub id: String,
    pub extended: bool,
    pub count: u64,
    pub dropped: u64,
    pub queueing_ns: Delays,
    pub latency_ns: Delays,
}

#[derive(Debug, Clone, Serialize)]
pub struct BusJson {
    pub name: String,
    pub endpoint: String,
    pub bitrate_bps: u32,
    pub queue_len: usize,
    pub frames: u64,
    pub busy_s: f64,
    /// Busy time over the hub's run time.
    pub load_mean: f64,
    pub load_windows: u64,
    pub load_window_mean: Option<f64>,
    pub load_window_max: Option<f64>,
    pub violations: u64,
    pub violation_max_ns: u64,
    pub arbitration_ties: u64,
    pub dropped: u64,
    pub error_frames: u64,
    pub protocol_errors: u64,
    pub refused_connections: u64,
    pub delivery_lateness_ns: Delays,
    pub latency_max_ns: u64,
    pub nodes: Vec<NodeJson>,
    pub ids: Vec<IdJson>,
}

#[derive(Debug, Clone, Serialize)]
pub struct HubJson {
    pub lookahead_ns: u64,
    pub coalesce_ns: u64,
    pub scheduler: String,
    pub wakeups: u64,
    pub cpu_s: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct StatsFile {
    pub version: u32,
    #[serde(rename = "final")]
    pub is_final: bool,
    pub elapsed_s: f64,
    pub load_window_s: f64,
    pub hub: HubJson,
    pub buses: Vec<BusJson>,
}

fn snapshot(
    accs: &[BusAcc],
    meta: &Meta,
    now_ns: u64,
    wakeups: u64,
    cpu_ns: u64,
    last: bool,
) -> StatsFile {
    let elapsed = now_ns.saturating_sub(meta.t0_ns).max(1);
    let buses = accs
        .iter()
        .map(|a| {
            let m = &a.model;
            let nodes = a
                .node_names
                .iter()
                .enumerate()
                .filter_map(|(n, name)| {
                    let name = name.clone()?;
                    let s = m.nodes[n];
                    Some(NodeJson {
                        node: n,
                        name,
                        connected: a.connected[n],
                        sent: s.sent,
                        dropped: s.dropped,
                        lost_at_leave: s.lost_at_leave,
                        max_queue_depth: s.max_depth,
                        rx_dropped: a.hub.rx_dropped[n],
                    })
                })
                .collect();
            let pooled = m.ids.len() - 1;
            let ids = m
                .ids
                .iter()
                .enumerate()
                .filter(|(_, s)| s.count > 0 || s.dropped > 0)
                .map(|(slot, s)| {
                    let key = m.id_keys[slot];
                    IdJson {
                        id: match key {
                            _ if slot == pooled => "other".into(),
                            Some(k) if k.extended => format!("{:#010x}", k.id),
                            Some(k) => format!("{:#05x}", k.id),
                            None => "?".into(),
                        },
                        extended: key.is_some_and(|k| k.extended),
                        count: s.count,
                        dropped: s.dropped,
                        queueing_ns: Delays::of(&s.queueing, s.queueing_max_ns),
                        latency_ns: Delays::of(&s.latency, s.latency_max_ns),
                    }
                })
                .collect();
            BusJson {
                name: a.name.clone(),
                endpoint: a.endpoint.clone(),
                bitrate_bps: a.bitrate_bps,
                queue_len: a.queue_len,
                frames: m.frames,
                busy_s: m.busy_ns as f64 * 1e-9,
                load_mean: m.busy_ns as f64 / elapsed as f64,
                load_windows: m.windows,
                load_window_mean: m.window_load_mean(),
                load_window_max: (m.windows > 0).then_some(m.window_load_max),
                violations: m.violations,
                violation_max_ns: m.violation_max_ns,
                arbitration_ties: m.arbitration_ties,
                dropped: m.nodes.iter().map(|n| n.dropped).sum(),
                error_frames: a.hub.error_frames,
                protocol_errors: a.hub.protocol_errors,
                refused_connections: a.hub.refused_connections,
                delivery_lateness_ns: Delays::of(&a.hub.lateness, a.hub.lateness_max_ns),
                latency_max_ns: m.ids.iter().map(|s| s.latency_max_ns).max().unwrap_or(0),
                nodes,
                ids,
            }
        })
        .collect();
    StatsFile {
        version: 1,
        is_final: last,
        elapsed_s: elapsed as f64 * 1e-9,
        load_window_s: WINDOW_NS as f64 * 1e-9,
        hub: HubJson {
            lookahead_ns: meta.lookahead_ns,
            coalesce_ns: meta.coalesce_ns,
            scheduler: meta.scheduler.clone(),
            wakeups,
            cpu_s: cpu_ns as f64 * 1e-9,
        },
        buses,
    }
}

fn write_atomically(path: &std::path::Path, file: &StatsFile) -> std::io::Result<()> {
    let tmp = path.with_extension("json.tmp");
    let text = serde_json::to_string_pretty(file).map_err(std::io::Error::other)?;
    std::fs::write(&tmp, text + "\n")?;
    std::fs::rename(&tmp, path)
}

/// One line per bus for the log at exit.
pub fn summary_line(b: &BusJson) -> String {
    let us = |ns: Option<u64>| ns.map_or("-".to_string(), |v| format!("{:.1} µs", v as f64 / 1e3));
    let p99 = b.ids.iter().filter_map(|i| i.latency_ns.p99).max();
    format!(
        "bus {}: {} frames, load mean {:.1} % (max 1 s window {}), dropped {}, model violations {}, \
         latency p99 (worst id) {} max {}, delivery lateness p99 {} max {}",
        b.name,
        b.frames,
        b.load_mean * 100.0,
        b.load_window_max
            .map_or("-".to_string(), |l| format!("{:.1} %", l * 100.0)),
        b.dropped,
        b.violations,
        us(p99),
        us(Some(b.latency_max_ns)),
        us(b.delivery_lateness_ns.p99),
        us(Some(b.delivery_lateness_ns.max)),
    )
}
