//! The hub on a thread of the calling process: for tests and benches that run the stack's
//! nodes as threads (the drive adapter's HIL rig, the bus latency bench) and still want the
//! wire's physics. The daemons and `crs sim` run the `can-wire` binary instead.

use crate::config::{BusSpec, Endpoint, HubConfig};
use crate::hub::{Hub, HubError};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

/// A running in-process hub (see the module docs); stopped on [`HubThread::stop`] or drop.
pub struct HubThread {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<Result<(), HubError>>>,
    stats: PathBuf,
}

impl HubThread {
    /// One bus per `(name, bit rate)`, each a unix socket `<dir>/<name>.sock`; statistics in
    /// `<dir>/wire.json`. Returns the hub and each bus's transport (`wire:<socket>`), in order.
    /// `lookahead_us` / `coalesce_us`: the hub's timing (the binary's defaults are 50 / 50);
    /// `queue_len`: each node's transmit queue, frames (the binary's default is 10, a CAN
    /// netdev's default txqueuelen).
    pub fn start(
        dir: &Path,
        buses: &[(&str, u32)],
        lookahead_us: u64,
        coalesce_us: u64,
        queue_len: usize,
    ) -> Result<(Self, Vec<String>), HubError> {
        std::fs::create_dir_all(dir).map_err(|source| HubError::Io {
            bus: "*".into(),
            what: format!("creating {}", dir.display()),
            source,
        })?;
        let specs: Vec<BusSpec> = buses
            .iter()
            .map(|(name, bitrate)| BusSpec {
                name: (*name).to_string(),
                bitrate_bps: *bitrate,
                endpoint: Endpoint::Socket(dir.join(format!("{name}.sock"))),
                queue_len,
                max_nodes: 32,
                max_ids: 128,
            })
            .collect();
        let transports = specs
            .iter()
            .map(|b| match &b.endpoint {
                Endpoint::Socket(p) => format!("wire:{}", p.display()),
                Endpoint::Ports(_) => unreachable!("sockets only here"),
            })
            .collect();
        let stats = dir.join("wire.json");
        let cfg = HubConfig {
            buses: specs,
            lookahead_ns: lookahead_us * 1000,
            coalesce_ns: coalesce_us * 1000,
            stats_path: Some(stats.clone()),
            stats_period_ns: 1_000_000_000,
            ready_file: None,
        };
        let hub = Hub::open(cfg, "in-process thread".into())?;
        let stop = Arc::new(AtomicBool::new(false));
        let s2 = stop.clone();
        let handle = std::thread::Builder::new()
            .name("can-wire".into())
            .spawn(move || hub.run(&s2))
            .map_err(|source| HubError::Io {
                bus: "*".into(),
                what: "spawning the hub thread".into(),
                source,
            })?;
        Ok((
            Self {
                stop,
                handle: Some(handle),
                stats,
            },
            transports,
        ))
    }

    /// Stops the hub and returns its final statistics (the JSON text of `wire.json`).
    pub fn stop(mut self) -> Result<String, HubError> {
        self.halt()?;
        std::fs::read_to_string(&self.stats).map_err(|source| HubError::Io {
            bus: "*".into(),
            what: format!("reading {}", self.stats.display()),
            source,
        })
    }

    fn halt(&mut self) -> Result<(), HubError> {
        self.stop.store(true, Ordering::Release);
        match self.handle.take() {
            Some(h) => h.join().map_err(|_| HubError::Setup {
                bus: "*".into(),
                what: "the hub thread panicked".into(),
            })?,
            None => Ok(()),
        }
    }
}

impl Drop for HubThread {
    fn drop(&mut self) {
        let _ = self.halt();
    }
}
