//! The console's only contact with iceoryx2: a plain thread that drains the topics at
//! [`POLL_HZ`], publishes a [`Status`] into a `watch` channel and sends the stop requests.

use crate::ConsoleError;
use crate::ride::{self, ControlSeen, LoadedRide, RideSetup};
use crate::status::{Collector, PlanView, PlatformView, Status, TripEntry};
use crs_ipc::{
    DriveFeedback, EventKind, Heartbeat, IpcNode, JointSetpoint, LoopStatsSample, PlantTruth,
    ProcessId, StateEvent,
};
use std::sync::Arc as SharedJson;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};
use tokio::sync::{oneshot, watch};

/// Updates per second sent to the page (the issue asks for >= 20).
pub const POLL_HZ: u32 = 25;

fn to_json(s: &Status) -> SharedJson<str> {
    // Status holds only numbers and strings: serialization cannot fail.
    serde_json::to_string(s)
        .unwrap_or_else(|_| "{}".into())
        .into()
}

/// A request from the web side to the poller thread.
pub enum Request {
    /// Publish an operator e-stop; answer with the event's sequence number.
    /// The error is iceoryx2's (publishing the event or waking the listeners).
    Stop(oneshot::Sender<Result<u64, crs_ipc::IpcError>>),
    /// The trip log.
    Trips(oneshot::Sender<Vec<TripEntry>>),
    /// The start button: where to send which ride if every pre-ride check passes now, else the
    /// checks that fail.
    StartRide(oneshot::Sender<Result<(std::path::PathBuf, LoadedRide), Vec<String>>>),
}

/// The running poller.
pub struct Poller {
    /// The newest status as JSON text: serialized once per update in the poller thread, so any
    /// number of clients costs one serialization.
    pub status: watch::Receiver<SharedJson<str>>,
    pub requests: mpsc::Sender<Request>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
    control_watch: Option<std::thread::JoinHandle<()>>,
}

impl Poller {
    /// Setting this flag ends the thread; its `watch` sender drops, which ends every live stream.
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }
}

impl Drop for Poller {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        if let Some(t) = self.control_watch.take() {
            let _ = t.join();
        }
    }
}

/// Opens the subscribers (and the stop publisher) on `prefix` and starts the thread; with
/// `rides`, a second thread asks motion-core's control socket what the loop does.
pub fn start(
    prefix: &str,
    platform: Option<PlatformView>,
    plan: Option<PlanView>,
    avoid_cpu: Option<usize>,
    rides: Option<RideSetup>,
) -> Result<Poller, ConsoleError> {
    let (ready_tx, ready_rx) = mpsc::channel::<Result<(), ConsoleError>>();
    let stop = Arc::new(AtomicBool::new(false));
    let control_seen = Arc::new(std::sync::Mutex::new(ControlSeen::default()));
    let control_watch = match &rides {
        Some(r) => Some(ride::spawn_control_watch(
            r.socket.clone(),
            stop.clone(),
            control_seen.clone(),
            avoid_cpu,
        )?),
        None => None,
    };
    let mut collector = Collector::new(prefix, platform, plan).with_rides(rides);
    let (status_tx, status_rx) = watch::channel(to_json(&collector.status()));
    let (req_tx, req_rx) = mpsc::channel::<Request>();
    let stop2 = stop.clone();
    let prefix = prefix.to_string();
    let thread = std::thread::Builder::new()
        .name("crs-console-iox".into())
        .spawn(move || {
            crate::background_thread(avoid_cpu);
            // iceoryx2 ports are not Send: everything lives on this thread.
            let node_name = format!("crs-console-{}", std::process::id());
            let ports = (|| -> Result<_, ConsoleError> {
                let node = IpcNode::with_prefix(&node_name, &prefix)?;
                let sp = node.subscriber::<JointSetpoint>()?;
                let truth = node.subscriber::<PlantTruth>()?;
                let fb = node.subscriber::<DriveFeedback>()?;
                let stats = node.subscriber::<LoopStatsSample>()?;
                let hb = node.subscriber::<Heartbeat>()?;
                let ev = node.subscriber::<StateEvent>()?;
                let ev_pub = node.publisher::<StateEvent>()?;
                let wake = node.wakeup_notifier()?;
                Ok((node, sp, truth, fb, stats, hb, ev, ev_pub, wake))
            })();
            let (_node, sp, truth, fb, stats, hb, ev, ev_pub, wake) = match ports {
                Ok(p) => {
                    let _ = ready_tx.send(Ok(()));
                    p
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                    return;
                }
            };
            let period = Duration::from_secs(1) / POLL_HZ;
            let mut next = Instant::now();
            let mut stop_seq = 0u64;
            while !stop2.load(Ordering::Relaxed) {
                // Requests wake the thread at once; otherwise it sleeps to the next update.
                let wait = next.saturating_duration_since(Instant::now());
                match req_rx.recv_timeout(wait) {
                    Ok(Request::Stop(answer)) => {
                        stop_seq += 1;
                        let e = StateEvent::new(ProcessId::Operator, EventKind::EStop, stop_seq);
                        let r = ev_pub
                            .publish(&e)
                            .and_then(|_| wake.notify())
                            .map(|_| stop_seq);
                        match &r {
                            Ok(_) => tracing::warn!("STOP requested from the operator console: e-stop published"),
                            Err(e) => tracing::error!(error = %e, "STOP request from the console could not be published"),
                        }
                        collector.stop_requested();
                        let _ = answer.send(r);
                        continue;
                    }
                    Ok(Request::Trips(answer)) => {
                        let _ = answer.send(collector.trips());
                        continue;
                    }
                    Ok(Request::StartRide(answer)) => {
                        if let Ok(seen) = control_seen.lock() {
                            collector.control(&seen);
                        }
                        let _ = answer.send(collector.start_check());
                        continue;
                    }
                    Err(mpsc::RecvTimeoutError::Timeout) => {}
                    Err(mpsc::RecvTimeoutError::Disconnected) => break,
                }
                next += period;
                let now = Instant::now();
                if next < now {
                    next = now + period;
                }
                // A receive error (foreign contract version) is skipped: the console shows
                // what it can read and never stops the stack for it.
                let _ = sp.drain(|s| collector.setpoint(s));
                let _ = truth.drain(|t| collector.truth(t));
                let _ = fb.drain(|f| collector.feedback(f));
                let _ = stats.drain(|s| collector.loop_stats(s));
                let _ = hb.drain(|h| collector.heartbeat(h));
                let _ = ev.drain(|e| collector.event(e));
                if let Ok(seen) = control_seen.lock() {
                    collector.control(&seen);
                }
                if status_tx.send(to_json(&collector.status())).is_err() {
                    break;
                }
            }
        })?;
    match ready_rx.recv() {
        Ok(Ok(())) => Ok(Poller {
            status: status_rx,
            requests: req_tx,
            stop,
            thread: Some(thread),
            control_watch,
        }),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(ConsoleError::PollerGone),
    }
}
