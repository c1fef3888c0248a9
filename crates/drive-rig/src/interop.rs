//! Interoperability scenarios: drive-io against CiA 402 drives that are NOT this project's
//! code (python `canopen` LocalNodes from the same EDS, `tools/canopen_interop.py drive`), on
//! a bus python-can speaks (`pycan-udp:GROUP:PORT`). Run by `drive-io-interop` from
//! `tools/canopen-interop.sh`; the python side runs the matching scenario.
//!
//! Only what drive-io publishes is observed (feedback, bus state, fault codes, the start-up
//! error); the drives are another process.

use crs_ipc::{
    BusState, DriveFeedback, EventKind, FaultCode, IpcNode, JointSetpoint, ProcessId, StateEvent,
    TopicPublisher, TopicSubscriber, monotonic_ns,
};
use drive_bus::canopen::Ds402State;
use drive_io::runner;
use drives_config::DrivesConfig;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

type Res<T> = Result<T, String>;

/// drive-io (a thread running [`runner::run`]) and the test's iceoryx2 ports.
pub struct External {
    pub cfg: DrivesConfig,
    stop: Arc<AtomicBool>,
    dio: Option<JoinHandle<Res<runner::RunSummary>>>,
    _node: IpcNode,
    setpoints: TopicPublisher<JointSetpoint>,
    feedback: TopicSubscriber<DriveFeedback>,
    events: TopicPublisher<StateEvent>,
    seq: u64,
}

impl External {
    pub fn start(cfg: DrivesConfig, prefix: &str) -> Res<Self> {
        let spec = cfg.transport().map_err(|e| e.to_string())?;
        let bus = can_transport::open(&spec).map_err(|e| format!("drive-io bus: {e}"))?;
        let node = IpcNode::with_prefix("interop-test", prefix).map_err(|e| e.to_string())?;
        let setpoints = node
            .publisher::<JointSetpoint>()
            .map_err(|e| e.to_string())?;
        let feedback = node
            .subscriber::<DriveFeedback>()
            .map_err(|e| e.to_string())?;
        let events = node.publisher::<StateEvent>().map_err(|e| e.to_string())?;
        let stop = Arc::new(AtomicBool::new(false));
        let (s2, cfg2, p2) = (stop.clone(), cfg.clone(), prefix.to_string());
        let dio = std::thread::Builder::new()
            .name("drive-io".into())
            .spawn(move || {
                let ipc = IpcNode::with_prefix("drive-io", &p2).map_err(|e| e.to_string())?;
                match &cfg2.bus.candump_log {
                    Some(path) => {
                        let b = can_transport::LoggingBus::create(bus, path.as_ref())
                            .map_err(|e| e.to_string())?;
                        runner::run(&cfg2, vec![b], &ipc, &s2)
                    }
                    None => runner::run(&cfg2, vec![bus], &ipc, &s2),
                }
                .map_err(|e| e.to_string())
            })
            .map_err(|e| e.to_string())?;
        Ok(Self {
            cfg,
            stop,
            dio: Some(dio),
            _node: node,
            setpoints,
            feedback,
            events,
            seq: 0,
        })
    }

    fn m(&self) -> usize {
        self.cfg.winches.len()
    }

    /// drive-io's result if its thread ended.
    fn ended(&mut self) -> Option<Res<runner::RunSummary>> {
        if self.dio.as_ref().is_some_and(|h| h.is_finished()) {
            let h = self.dio.take()?;
            return Some(h.join().unwrap_or_else(|_| Err("drive-io panicked".into())));
        }
        None
    }

    fn latest(&mut self, timeout: Duration) -> Res<DriveFeedback> {
        let t0 = Instant::now();
        loop {
            if let Some(f) = self.feedback.latest().map_err(|e| e.to_string())? {
                return Ok(f);
            }
            if let Some(r) = self.ended() {
                return Err(format!("drive-io ended: {r:?}"));
            }
            if t0.elapsed() > timeout {
                return Err("no drive feedback published".into());
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    fn wait(
        &mut self,
        want: BusState,
        timeout: Duration,
        allowed: &[BusState],
    ) -> Res<DriveFeedback> {
        let t0 = Instant::now();
        loop {
            let f = self.latest(timeout)?;
            let s = BusState::from_u32(f.bus_state);
            if s == Some(want) {
                return Ok(f);
            }
            if !s.is_some_and(|s| allowed.contains(&s)) || t0.elapsed() > timeout {
                return Err(format!(
                    "expected {want:?}, got {s:?} (fault_code {} node {} emcy {:#06x})",
                    f.fault_code, f.fault_node, f.last_emcy_code
                ));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Publishes `lengths` with sequence number `seq` (at least the last one + 1).
    fn publish(&mut self, lengths: &[f64], seq: u64) -> Res<()> {
        self.seq = seq.max(self.seq + 1);
        let mut sp = JointSetpoint {
            cable_count: lengths.len() as u32,
            sequence: self.seq,
            timestamp_ns: monotonic_ns(),
            ..Default::default()
        };
        sp.cable_length_m[..lengths.len()].copy_from_slice(lengths);
        self.setpoints.publish(&sp).map_err(|e| e.to_string())
    }

    /// Streams `profile(t)` at ~1 kHz for `d`, or until drive-io leaves Ready/Running.
    fn stream(
        &mut self,
        d: Duration,
        mut profile: impl FnMut(f64) -> Vec<f64>,
    ) -> Res<DriveFeedback> {
        let t0 = Instant::now();
        let base = self.seq;
        let period_s = self.cfg.sync_period_ns() as f64 * 1e-9;
        loop {
            let t = t0.elapsed().as_secs_f64();
            // One sequence number per SYNC period of profile time, as motion-core numbers its
            // setpoints: a publisher stalled for two periods moves two periods' worth, and
            // drive-io's step check allows exactly that.
            // Once per period (the publisher wakes more often than a SYNC period longer than
            // 1 ms): a second setpoint in the same period would carry the next sequence number
            // with half a period's motion, a false acceleration in drive-io's step check.
            // The profile at the period's instant, not at the wake-up: wake-up jitter would
            // otherwise be a velocity ripple of ± v per period.
            let k = (t / period_s) as u64;
            let seq = base + 1 + k;
            if seq > self.seq {
                self.publish(&profile(k as f64 * period_s), seq)?;
            }
            let f = self.latest(Duration::from_secs(1))?;
            let s = BusState::from_u32(f.bus_state);
            if t0.elapsed() >= d || !matches!(s, Some(BusState::Ready | BusState::Running)) {
                return Ok(f);
            }
            std::thread::sleep(Duration::from_micros(900));
        }
    }

    fn shutdown(mut self) -> Res<runner::RunSummary> {
        self.stop.store(true, Ordering::Release);
        match self.dio.take() {
            Some(h) => h.join().map_err(|_| "drive-io panicked".to_string())?,
            None => Err("drive-io not running".into()),
        }
    }
}

impl Drop for External {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
    }
}

fn boot(x: &mut External) -> Res<Vec<f64>> {
    let f = x.wait(
        BusState::Ready,
        Duration::from_secs(30),
        &[BusState::Booting],
    )?;
    for i in 0..x.m() {
        let st = Ds402State::from_statusword(f.statusword[i]);
        if st != Ds402State::OperationEnabled {
            return Err(format!(
                "drive {i}: statusword {:#06x} ({st:?})",
                f.statusword[i]
            ));
        }
    }
    Ok(f.cable_length_m[..x.m()].to_vec())
}

/// Boot (NMT, SDO start-up script + read-back, CiA 402 enable), follow 50 mm in 0.5 s through
/// the PDOs, then an e-stop: every drive acknowledges the quick stop in its statusword and
/// reports velocity 0.
pub fn scenario_run(cfg: DrivesConfig, prefix: &str) -> Res<String> {
    let x_cells = cfg.force_sensors.len();
    let mut x = External::start(cfg, prefix)?;
    let l0 = boot(&mut x)?;
    let goal: Vec<f64> = l0.iter().map(|l| l + 0.05).collect();
    // A raised cosine (at most 1 m/s²): drive-io refuses a step that accelerates a cable
    // beyond bus.max_cable_acceleration_m_per_s2, as it would a jump out of a hold.
    x.stream(Duration::from_millis(500), |t| {
        let s = 0.5 - 0.5 * (std::f64::consts::PI * (t / 0.5).min(1.0)).cos();
        l0.iter().map(|l| l + 0.05 * s).collect()
    })?;
    let f = x.stream(Duration::from_millis(100), |_| goal.clone())?;
    // Forces from the load cells where the configuration has them: the python CiA 404 nodes
    // report 3000 N + 100 N × cable (in 0.1 N), drive-io scales them with n_per_unit.
    for s in &x.cfg.force_sensors {
        let i = s.cable - 1;
        let want = 3000.0 + 100.0 * s.cable as f64;
        if (f.cable_force_n[i] - want).abs() > 0.05 {
            return Err(format!(
                "cable {}: force {} N from load cell node {}, the cell reports {want} N",
                s.cable, f.cable_force_n[i], s.node_id
            ));
        }
    }
    if BusState::from_u32(f.bus_state) != Some(BusState::Running) {
        return Err(format!(
            "not Running after the stream: {:?}",
            BusState::from_u32(f.bus_state)
        ));
    }
    for (i, g) in goal.iter().enumerate() {
        let e = (f.cable_length_m[i] - g).abs();
        if e > 1e-6 {
            return Err(format!(
                "drive {i}: feedback {} m, goal {} m",
                f.cable_length_m[i], g
            ));
        }
    }
    x.events
        .publish(&StateEvent::new(ProcessId::Test, EventKind::EStop, 1))
        .map_err(|e| e.to_string())?;
    let t0 = Instant::now();
    loop {
        let f = x.latest(Duration::from_secs(1))?;
        let acked = (0..x.m()).all(|i| {
            Ds402State::from_statusword(f.statusword[i]) == Ds402State::QuickStopActive
                && f.cable_velocity_m_per_s[i] == 0.0
        });
        if BusState::from_u32(f.bus_state) == Some(BusState::EStop) && acked {
            break;
        }
        if t0.elapsed() > Duration::from_secs(5) {
            return Err(format!(
                "quick stop not acknowledged: statuswords {:x?}",
                &f.statusword[..x.m()]
            ));
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    x.shutdown()?;
    Ok(format!(
        "{} drives configured, followed 50 mm to < 1 um, quick stop acknowledged{}",
        goal.len(),
        if x_cells > 0 {
            format!(", forces from {x_cells} load cells")
        } else {
            String::new()
        }
    ))
}

/// A python drive raises EMCY `code` (the script's `emcy` scenario): drive-io faults naming it.
pub fn scenario_emcy(cfg: DrivesConfig, prefix: &str, node: u8, code: u16) -> Res<String> {
    let mut x = External::start(cfg, prefix)?;
    let l0 = boot(&mut x)?;
    let f = x.stream(Duration::from_secs(10), |_| l0.clone())?;
    if f.fault() != Ok(FaultCode::Emcy)
        || f.fault_node != u32::from(node)
        || f.last_emcy_code != u32::from(code)
    {
        return Err(format!(
            "expected EMCY {code:#06x} from node {node}, got fault {} node {} emcy {:#06x}",
            f.fault_code, f.fault_node, f.last_emcy_code
        ));
    }
    x.shutdown()?;
    Ok(format!(
        "EMCY {code:#06x} ({}) from node {node} -> Fault",
        drive_bus::canopen::emcy_name(code)
    ))
}

/// A python drive stops its heartbeat (or reboots): drive-io faults with `want` naming it.
pub fn scenario_fault(cfg: DrivesConfig, prefix: &str, node: u8, want: FaultCode) -> Res<String> {
    let mut x = External::start(cfg, prefix)?;
    let l0 = boot(&mut x)?;
    let f = x.stream(Duration::from_secs(10), |_| l0.clone())?;
    let want = u32::from(want);
    if f.fault_code != want || f.fault_node != u32::from(node) {
        return Err(format!(
            "expected fault {want} from node {node}, got fault {} node {}",
            f.fault_code, f.fault_node
        ));
    }
    x.shutdown()?;
    Ok(format!("node {node} -> Fault code {want}"))
}

/// The drives lack an object drive-io writes: start-up stops with an error naming drive,
/// object and abort code (python canopen's SDO server answers the abort).
pub fn scenario_refused(cfg: DrivesConfig, prefix: &str, must_contain: &[&str]) -> Res<String> {
    let mut x = External::start(cfg, prefix)?;
    let t0 = Instant::now();
    loop {
        if let Some(r) = x.ended() {
            return match r {
                Err(msg) if must_contain.iter().all(|w| msg.contains(w)) => Ok(msg),
                r => Err(format!(
                    "expected a start-up error containing {must_contain:?}, got {r:?}"
                )),
            };
        }
        if t0.elapsed() > Duration::from_secs(30) {
            return Err("drive-io did not stop start-up".into());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}
