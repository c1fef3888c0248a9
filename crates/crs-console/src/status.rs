//! What the console shows: the JSON status the page and `GET /api/status` receive, and the trip
//! log of `GET /api/trips`, assembled from the iceoryx2 samples by [`Collector`].

use crate::ride::{ControlSeen, LoadedRide, RideSetup};
use crs_ipc::{
    BusState, DriveFeedback, EventKind, FaultCode, Heartbeat, JointSetpoint, LoopStatsSample,
    MAX_CABLES, MonitorCode, MonitorState, MotionState, PlantState, PlantTruth, ProcessId,
    StateEvent, TripCause,
};
use serde::Serialize;
use std::collections::VecDeque;
use std::path::PathBuf;

/// A process counts as alive while its last heartbeat is younger than this (s). The slowest
/// heartbeat of the stack is the monitor's 15 ms cycle; 1 s leaves room for a stalled host.
pub const ALIVE_S: f64 = 1.0;
/// Entries kept in the trip log.
pub const TRIP_LOG_LEN: usize = 200;
/// An answer of motion-core's control socket older than this (s) says nothing about the loop.
pub const CONTROL_FRESH_S: f64 = 2.0;
/// motion-core's control-socket phase in which a ride may start.
pub const IDLE_PHASE: &str = "idle, holding";

/// Static facts about the platform the page draws (from the operator TOML).
#[derive(Debug, Clone, Serialize, Default)]
pub struct PlatformView {
    pub name: String,
    /// Frame anchors a_i (world, m).
    pub frame_anchors_m: Vec<[f64; 3]>,
    /// Platform anchors b_i (platform frame, m).
    pub platform_anchors_m: Vec<[f64; 3]>,
    pub f_min_n: f64,
    pub f_max_n: f64,
}

/// The running plan, for the progress bar: its duration and the time each waypoint is reached.
#[derive(Debug, Clone, Serialize, Default)]
pub struct PlanView {
    /// Period of motion-core's loop (s): one setpoint per period while the plan runs.
    pub period_s: f64,
    pub total_s: f64,
    /// Plan time (s) at which waypoint k is reached.
    pub waypoint_end_s: Vec<f64>,
}

/// A pose for people: position in m, rotation in degrees, and the platform anchors in the world.
#[derive(Debug, Clone, Serialize, Default)]
pub struct PoseView {
    pub position_m: [f64; 3],
    pub rotation_deg: [f64; 3],
    /// r + R b_i (m), R = R_x R_y R_z (eq. 2.2).
    pub anchors_world_m: Vec<[f64; 3]>,
}

#[derive(Debug, Clone, Serialize, Default)]
pub struct LoopView {
    pub state: String,
    pub cycles: u64,
    pub overruns: u64,
    pub rejected: u64,
    pub lateness_p50_us: f64,
    pub lateness_p99_us: f64,
    pub lateness_max_us: f64,
    pub compute_p50_us: f64,
    pub compute_p99_us: f64,
    pub compute_max_us: f64,
    pub age_s: f64,
}

#[derive(Debug, Clone, Serialize, Default)]
pub struct DrivesView {
    pub bus_state: String,
    pub fault: String,
    pub fault_node: u32,
    pub setpoint_age_cycles: u32,
    pub overruns: u32,
    /// CiA 402 statusword 0x6041 per drive, and its state name.
    pub statusword: Vec<u16>,
    pub drive_state: Vec<String>,
    pub cable_length_m: Vec<f64>,
    /// The pulley force sensors (N).
    pub sensor_force_n: Vec<f64>,
    pub age_s: f64,
}

#[derive(Debug, Clone, Serialize, Default)]
pub struct ProcessView {
    pub name: String,
    pub state: String,
    pub heartbeats: u64,
    pub overruns: u32,
    pub age_s: f64,
    pub alive: bool,
}

#[derive(Debug, Clone, Serialize, Default)]
pub struct ProgressView {
    pub elapsed_s: f64,
    pub total_s: f64,
    pub fraction: f64,
    /// Waypoint being approached (1-based) of `waypoints`.
    pub waypoint: usize,
    pub waypoints: usize,
}

/// One entry of the trip log.
#[derive(Debug, Clone, Serialize)]
pub struct TripEntry {
    /// Seconds since the console started (CLOCK_MONOTONIC of the event).
    pub t_s: f64,
    pub source: String,
    pub kind: String,
    /// The cause in words (the monitor's trip cause, a drive fault code, a motion state).
    pub cause: String,
}

/// Everything the page shows, as sent 25 times a second.
#[derive(Debug, Clone, Serialize, Default)]
pub struct Status {
    /// Snapshot number (increases with every update).
    pub seq: u64,
    /// Seconds since the console started.
    pub t_s: f64,
    /// Any process of the stack sent a heartbeat within [`ALIVE_S`].
    pub stack_running: bool,
    /// iceoryx2 service prefix the console listens on.
    pub prefix: String,
    pub platform: Option<PlatformView>,
    pub plan: Option<PlanView>,
    pub reference: Option<PoseView>,
    pub setpoint_sequence: u64,
    pub actual: Option<PoseView>,
    /// Plant truth cable forces (N); on a real robot the force sensors.
    pub force_n: Vec<f64>,
    pub force_source: String,
    pub loop_stats: Option<LoopView>,
    pub motion_state: String,
    pub monitor_state: String,
    pub drives: Option<DrivesView>,
    pub processes: Vec<ProcessView>,
    pub progress: Option<ProgressView>,
    pub trips: usize,
    /// The last entries of the trip log, in time order (oldest first, newest last; the page
    /// lists them newest first).
    pub recent_trips: Vec<TripEntry>,
    /// Stop requests sent from a console.
    pub stop_requests: u64,
    /// The start button: the ride loaded and the pre-ride checks.
    pub ride: RideView,
}

/// One pre-ride check.
#[derive(Debug, Clone, Serialize, Default, PartialEq)]
pub struct CheckView {
    pub name: String,
    pub ok: bool,
    /// What was seen, in words.
    pub detail: String,
}

/// The start button's state: enabled only when every check passes.
#[derive(Debug, Clone, Serialize, Default)]
pub struct RideView {
    /// motion-core's control socket (None: the console cannot start rides).
    pub control_socket: Option<PathBuf>,
    /// The control socket's last answer, or why there is none.
    pub control: String,
    /// The ride the button starts (`NAME (N waypoints, plan T s)`).
    pub loaded: Option<String>,
    pub checks: Vec<CheckView>,
    pub start_allowed: bool,
}

/// A process id's name.
pub fn process_name(code: u32) -> &'static str {
    match code {
        x if x == ProcessId::MotionCore as u32 => "motion-core",
        x if x == ProcessId::DriveIo as u32 => "drive-io",
        x if x == ProcessId::SafetyMonitor as u32 => "safety-monitor",
        x if x == ProcessId::SimPlant as u32 => "sim-plant",
        x if x == ProcessId::Operator as u32 => "operator",
        x if x == ProcessId::Test as u32 => "test",
        _ => "unknown",
    }
}

/// motion-core's state code in words.
pub fn motion_state_name(code: u32) -> String {
    match MotionState::try_from(code) {
        Ok(MotionState::Running) => "running".into(),
        Ok(MotionState::EStopped) => "E-STOPPED (latched)".into(),
        Ok(MotionState::Refused) => "REFUSED a reference (latched)".into(),
        Ok(MotionState::Holding) => "idle, holding".into(),
        Ok(MotionState::Stopping) => "stream ended".into(),
        Ok(MotionState::Plan) => "plan announced".into(),
        Err(e) => format!("state {}", e.code),
    }
}

/// The safety monitor's state code in words.
pub fn monitor_state_name(code: u32) -> String {
    match MonitorState::try_from(code) {
        Ok(MonitorState::Armed) => "armed".into(),
        Ok(MonitorState::Tripped) => "TRIPPED".into(),
        Ok(MonitorState::NotReady) => "not ready".into(),
        Err(e) => format!("state {}", e.code),
    }
}

/// drive-io's bus state code in words.
pub fn bus_state_name(code: u32) -> String {
    BusState::try_from(code).map_or(format!("state {code}"), |b| format!("{b:?}"))
}

fn fault_name(code: u32) -> String {
    match FaultCode::try_from(code) {
        Ok(FaultCode::None) => "none".into(),
        Ok(FaultCode::HeartbeatLost) => "drive heartbeat lost".into(),
        Ok(FaultCode::Emcy) => "EMCY".into(),
        Ok(FaultCode::DriveFaultBit) => "drive fault bit".into(),
        Ok(FaultCode::BootTimeout) => "boot timeout".into(),
        Ok(FaultCode::SetpointInvalid) => "invalid setpoint".into(),
        Ok(FaultCode::SetpointStep) => "setpoint step".into(),
        Ok(FaultCode::UnexpectedState) => "unexpected drive state".into(),
        Ok(FaultCode::BusError) => "bus error".into(),
        Ok(FaultCode::PdoTimeout) => "PDO timeout".into(),
        Ok(FaultCode::ForceLimit) => "cable force beyond the hard limit".into(),
        Err(e) => format!("fault code {}", e.code),
    }
}

/// CiA 402 state from the statusword (object 0x6041, table of the power state machine).
pub fn cia402_state(sw: u16) -> &'static str {
    match sw & 0x6f {
        x if x & 0x4f == 0x00 => "not ready",
        x if x & 0x4f == 0x40 => "switch on disabled",
        0x21 => "ready to switch on",
        0x23 => "switched on",
        0x27 => "operation enabled",
        0x07 => "quick stop active",
        x if x & 0x4f == 0x0f => "fault reaction",
        x if x & 0x4f == 0x08 => "fault",
        _ => "unknown",
    }
}

/// Who stopped a run and why, in words (`"console: stop requested by an operator"`), for an
/// e-stop event; None for other events.
pub fn estop_in_words(e: &StateEvent) -> Option<String> {
    if e.kind != EventKind::EStop as u32 {
        return None;
    }
    describe_event(e).map(|(_, cause)| format!("{}: {cause}", process_name(e.source)))
}

/// The trip-log text of a state event (what happened, its cause in words), or None for
/// routine state changes.
pub fn describe_event(e: &StateEvent) -> Option<(String, String)> {
    let cause_name =
        |c: u32| TripCause::try_from(c).map_or(format!("cause {c}"), |c| c.to_string());
    if e.kind == EventKind::EStop as u32 {
        let cause = if e.source == ProcessId::SafetyMonitor as u32 {
            let mut s = cause_name(e.detail);
            if e.detail_node > 0 {
                s.push_str(&format!(" (cable {})", e.detail_node));
            }
            s
        } else if e.source == ProcessId::Operator as u32 {
            "stop requested by an operator".into()
        } else if e.source == ProcessId::DriveIo as u32 {
            fault_name(e.detail)
        } else {
            format!("detail {}", e.detail)
        };
        return Some(("E-STOP".into(), cause));
    }
    if e.kind == EventKind::Fault as u32 {
        let cause = if e.source == ProcessId::MotionCore as u32 {
            motion_state_name(e.state)
        } else if e.source == ProcessId::DriveIo as u32 {
            let mut s = fault_name(e.detail);
            if e.detail_node > 0 {
                s.push_str(&format!(" (node {})", e.detail_node));
            }
            s
        } else {
            format!("detail {}", e.detail)
        };
        return Some(("fault".into(), cause));
    }
    if e.kind == EventKind::Reset as u32 {
        return Some(("reset".into(), "stack released".into()));
    }
    if e.source() == ProcessId::SafetyMonitor {
        return match e.monitor_code() {
            Some(MonitorCode::ResetAccepted) => Some(("reset request".into(), "accepted".into())),
            Some(MonitorCode::ResetNotTripped) => {
                Some(("reset request".into(), "not tripped".into()))
            }
            Some(MonitorCode::ResetNotReady) => {
                Some(("reset request".into(), "REFUSED: monitor not ready".into()))
            }
            Some(MonitorCode::ResetRefused) => Some((
                "reset request".into(),
                format!("REFUSED: {} persists", cause_name(e.detail_node)),
            )),
            _ => None,
        };
    }
    None
}

#[derive(Debug, Clone, Copy, Default)]
struct ProcessSeen {
    state: u32,
    overruns: u32,
    heartbeats: u64,
    last_ns: u64,
}

/// Folds the samples of the topics into the console's view. Owned by the poller thread; the
/// server gets clones of [`Status`].
pub struct Collector {
    t0_ns: u64,
    prefix: String,
    platform: Option<PlatformView>,
    plan: Option<PlanView>,
    seq: u64,
    setpoint: Option<JointSetpoint>,
    truth: Option<PlantTruth>,
    feedback: Option<(DriveFeedback, u64)>,
    loop_stats: Option<(LoopStatsSample, u64)>,
    processes: [ProcessSeen; 8],
    motion_state: Option<u32>,
    monitor_state: Option<u32>,
    trips: VecDeque<TripEntry>,
    trip_count: usize,
    stop_requests: u64,
    rides: Option<RideSetup>,
    control: ControlSeen,
}

fn to_deg(r: [f64; 3]) -> [f64; 3] {
    r.map(f64::to_degrees)
}

/// r + R b_i with R = R_x(φx) R_y(φy) R_z(φz), eq. (2.2).
pub fn anchors_world(pose: &[f64; 6], b: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let (sx, cx) = pose[3].sin_cos();
    let (sy, cy) = pose[4].sin_cos();
    let (sz, cz) = pose[5].sin_cos();
    let r = [
        [cy * cz, -cy * sz, sy],
        [cx * sz + sx * sy * cz, cx * cz - sx * sy * sz, -sx * cy],
        [sx * sz - cx * sy * cz, sx * cz + cx * sy * sz, cx * cy],
    ];
    b.iter()
        .map(|b| {
            let mut w = [0.0; 3];
            for (i, wi) in w.iter_mut().enumerate() {
                *wi = pose[i] + r[i][0] * b[0] + r[i][1] * b[1] + r[i][2] * b[2];
            }
            w
        })
        .collect()
}

impl Collector {
    pub fn new(prefix: &str, platform: Option<PlatformView>, plan: Option<PlanView>) -> Self {
        Self {
            t0_ns: crs_ipc::monotonic_ns(),
            prefix: prefix.to_string(),
            platform,
            plan,
            seq: 0,
            setpoint: None,
            truth: None,
            feedback: None,
            loop_stats: None,
            processes: [ProcessSeen::default(); 8],
            motion_state: None,
            monitor_state: None,
            trips: VecDeque::new(),
            trip_count: 0,
            stop_requests: 0,
            rides: None,
            control: ControlSeen::default(),
        }
    }

    /// Rides from the start button (motion-core's control socket, the ride loaded).
    pub fn with_rides(mut self, rides: Option<RideSetup>) -> Self {
        self.rides = rides;
        self
    }

    /// motion-core's newest answer on its control socket.
    pub fn control(&mut self, seen: &ControlSeen) {
        if &self.control != seen {
            self.control = seen.clone();
        }
    }

    /// The pre-ride checks as of now.
    pub fn pre_ride_checks(&self) -> Vec<CheckView> {
        let now = crs_ipc::monotonic_ns();
        let alive = |p: &ProcessSeen| {
            p.heartbeats > 0 && (now.saturating_sub(p.last_ns) as f64 * 1e-9) < ALIVE_S
        };
        let stack_running = self.processes.iter().any(alive);
        let check = |name: &str, ok: bool, detail: String| CheckView {
            name: name.into(),
            ok,
            detail,
        };
        let fresh = self
            .control
            .at
            .is_some_and(|t| t.elapsed().as_secs_f64() < CONTROL_FRESH_S);
        let phase = if fresh {
            self.control.phase.as_deref()
        } else {
            None
        };
        let idle = match (&self.rides, phase) {
            (None, _) => check(
                "motion-core idle and holding",
                false,
                "no control socket given to the console: rides start from `crs ride`".into(),
            ),
            (Some(_), Some(p)) => check("motion-core idle and holding", p == IDLE_PHASE, p.into()),
            (Some(_), None) if self.control.at.is_none() => check(
                "motion-core idle and holding",
                false,
                "not asked yet".into(),
            ),
            (Some(_), None) => check(
                "motion-core idle and holding",
                false,
                if fresh {
                    self.control.reply.clone()
                } else {
                    format!("no answer on the control socket for {CONTROL_FRESH_S} s")
                },
            ),
        };
        let monitor = &self.processes[ProcessId::SafetyMonitor as usize];
        let monitor_state = self
            .monitor_state
            .and_then(|s| MonitorState::try_from(s).ok());
        let armed = monitor_state == Some(MonitorState::Armed) && alive(monitor);
        let monitor_words = match (self.monitor_state, alive(monitor)) {
            (None, _) => "no data from the safety monitor".to_string(),
            (Some(s), true) => monitor_state_name(s),
            (Some(s), false) => format!("no heartbeat (last state: {})", monitor_state_name(s)),
        };
        let mut latched = Vec::new();
        if monitor_state == Some(MonitorState::Tripped) {
            latched.push("the safety monitor is TRIPPED (reset at the monitor)".to_string());
        }
        if let Some(m) = self
            .motion_state
            .filter(|m| MotionState::try_from(*m).is_ok_and(MotionState::is_latched))
        {
            latched.push(format!("motion-core: {}", motion_state_name(m)));
        }
        if let Some(p) = phase.filter(|p| p.starts_with("latched")) {
            latched.push(format!("motion-core: {p}"));
        }
        let loaded = self.rides.as_ref().and_then(|r| r.ride.as_ref());
        vec![
            check(
                "stack running",
                stack_running,
                if stack_running {
                    "heartbeats within the last second".into()
                } else {
                    "no heartbeat from any process".into()
                },
            ),
            idle,
            check("safety monitor armed", armed, monitor_words),
            check(
                "no latched trip",
                latched.is_empty(),
                if latched.is_empty() {
                    "none".into()
                } else {
                    latched.join("; ")
                },
            ),
            check(
                "a validated ride loaded",
                loaded.is_some(),
                loaded.map_or(
                    "none (`crs console --ride FILE`, verified when the console starts)".into(),
                    LoadedRide::describe,
                ),
            ),
        ]
    }

    /// What the start button sends where, when every pre-ride check passes; otherwise the
    /// checks that fail, in words.
    pub fn start_check(&self) -> Result<(PathBuf, LoadedRide), Vec<String>> {
        let failed: Vec<String> = self
            .pre_ride_checks()
            .into_iter()
            .filter(|c| !c.ok)
            .map(|c| format!("{}: {}", c.name, c.detail))
            .collect();
        match &self.rides {
            Some(RideSetup {
                socket,
                ride: Some(ride),
            }) if failed.is_empty() => Ok((socket.clone(), ride.clone())),
            _ => Err(failed),
        }
    }

    fn ride_view(&self) -> RideView {
        let checks = self.pre_ride_checks();
        RideView {
            control_socket: self.rides.as_ref().map(|r| r.socket.clone()),
            control: match &self.rides {
                None => "no control socket".into(),
                Some(_) if self.control.at.is_none() => "not asked yet".into(),
                Some(_) => self.control.reply.clone(),
            },
            loaded: self
                .rides
                .as_ref()
                .and_then(|r| r.ride.as_ref())
                .map(LoadedRide::describe),
            start_allowed: checks.iter().all(|c| c.ok),
            checks,
        }
    }

    fn t_s(&self, ns: u64) -> f64 {
        ns.saturating_sub(self.t0_ns) as f64 * 1e-9
    }

    pub fn setpoint(&mut self, s: &JointSetpoint) {
        self.setpoint = Some(*s);
    }
    pub fn truth(&mut self, t: &PlantTruth) {
        self.truth = Some(*t);
    }
    pub fn feedback(&mut self, f: &DriveFeedback) {
        self.feedback = Some((*f, crs_ipc::monotonic_ns()));
    }
    pub fn loop_stats(&mut self, s: &LoopStatsSample) {
        self.loop_stats = Some((*s, crs_ipc::monotonic_ns()));
    }
    pub fn heartbeat(&mut self, h: &Heartbeat) {
        if let Some(p) = self.processes.get_mut(h.source as usize) {
            p.state = h.state;
            p.overruns = h.overruns;
            p.heartbeats += 1;
            // Arrival time: a stalled publisher's old timestamps must not look fresh.
            p.last_ns = crs_ipc::monotonic_ns();
        }
        if h.source == ProcessId::MotionCore as u32 {
            self.motion_state = Some(h.state);
        } else if h.source == ProcessId::SafetyMonitor as u32 {
            self.monitor_state = Some(h.state);
        }
    }
    pub fn event(&mut self, e: &StateEvent) {
        if e.source == ProcessId::MotionCore as u32 && e.kind != EventKind::EStop as u32 {
            self.motion_state = Some(e.state);
        }
        if e.source == ProcessId::SafetyMonitor as u32 && e.kind == EventKind::EStop as u32 {
            self.monitor_state = Some(e.state);
        }
        if let Some((kind, cause)) = describe_event(e) {
            let entry = TripEntry {
                t_s: self.t_s(e.timestamp_ns),
                source: process_name(e.source).into(),
                kind,
                cause,
            };
            tracing::info!(source = %entry.source, kind = %entry.kind, cause = %entry.cause, "console: event");
            // In time order: the events of several processes arrive interleaved (one queue
            // per publisher), so a later-drained event can be the older one.
            let at = self
                .trips
                .iter()
                .rposition(|t| t.t_s <= entry.t_s)
                .map_or(0, |k| k + 1);
            self.trips.insert(at, entry);
            if self.trips.len() > TRIP_LOG_LEN {
                self.trips.pop_front();
            }
            self.trip_count += 1;
        }
    }
    pub fn stop_requested(&mut self) {
        self.stop_requests += 1;
    }

    /// The trip log in time order (oldest first).
    pub fn trips(&self) -> Vec<TripEntry> {
        self.trips.iter().cloned().collect()
    }

    /// The current view.
    pub fn status(&mut self) -> Status {
        let now = crs_ipc::monotonic_ns();
        self.seq += 1;
        let age = |ns: u64| now.saturating_sub(ns) as f64 * 1e-9;
        let b: &[[f64; 3]] = self
            .platform
            .as_ref()
            .map_or(&[], |p| p.platform_anchors_m.as_slice());
        let pose_view = |x: &[f64; 6]| PoseView {
            position_m: [x[0], x[1], x[2]],
            rotation_deg: to_deg([x[3], x[4], x[5]]),
            anchors_world_m: anchors_world(x, b),
        };
        let processes: Vec<ProcessView> = self
            .processes
            .iter()
            .enumerate()
            .filter(|(_, p)| p.heartbeats > 0)
            .map(|(i, p)| ProcessView {
                name: process_name(i as u32).into(),
                state: match i as u32 {
                    x if x == ProcessId::MotionCore as u32 => motion_state_name(p.state),
                    x if x == ProcessId::SafetyMonitor as u32 => monitor_state_name(p.state),
                    x if x == ProcessId::DriveIo as u32 => bus_state_name(p.state),
                    x if x == ProcessId::SimPlant as u32 => match PlantState::try_from(p.state) {
                        Ok(PlantState::Braked) => "braked".into(),
                        Ok(PlantState::Free) => "released".into(),
                        Err(e) => format!("state {}", e.code),
                    },
                    _ => format!("state {}", p.state),
                },
                heartbeats: p.heartbeats,
                overruns: p.overruns,
                age_s: age(p.last_ns),
                alive: age(p.last_ns) < ALIVE_S,
            })
            .collect();
        let stack_running = processes.iter().any(|p| p.alive);
        let m = |n: u32| (n as usize).min(MAX_CABLES);
        let progress = match (&self.plan, &self.setpoint) {
            (Some(plan), Some(sp)) if plan.total_s > 0.0 => {
                // motion-core numbers its setpoints 1, 2, ... one per period from the plan's start.
                let elapsed = (sp.sequence as f64 * plan.period_s).min(plan.total_s);
                let k = plan
                    .waypoint_end_s
                    .iter()
                    .position(|t| elapsed < *t)
                    .unwrap_or(plan.waypoint_end_s.len().saturating_sub(1));
                Some(ProgressView {
                    elapsed_s: elapsed,
                    total_s: plan.total_s,
                    fraction: elapsed / plan.total_s,
                    waypoint: k + 1,
                    waypoints: plan.waypoint_end_s.len(),
                })
            }
            _ => None,
        };
        Status {
            seq: self.seq,
            t_s: self.t_s(now),
            stack_running,
            prefix: self.prefix.clone(),
            platform: self.platform.clone(),
            plan: self.plan.clone(),
            reference: self.setpoint.as_ref().map(|s| pose_view(&s.pose)),
            setpoint_sequence: self.setpoint.map_or(0, |s| s.sequence),
            actual: self.truth.as_ref().map(|t| pose_view(&t.pose)),
            force_n: self
                .truth
                .as_ref()
                .map_or(Vec::new(), |t| t.force_n[..m(t.cable_count)].to_vec()),
            force_source: "plant truth".into(),
            loop_stats: self.loop_stats.as_ref().map(|(s, at)| LoopView {
                state: motion_state_name(s.state),
                cycles: s.cycles,
                overruns: s.overruns,
                rejected: s.rejected,
                lateness_p50_us: s.lateness_p50_ns as f64 * 1e-3,
                lateness_p99_us: s.lateness_p99_ns as f64 * 1e-3,
                lateness_max_us: s.lateness_max_ns as f64 * 1e-3,
                compute_p50_us: s.compute_p50_ns as f64 * 1e-3,
                compute_p99_us: s.compute_p99_ns as f64 * 1e-3,
                compute_max_us: s.compute_max_ns as f64 * 1e-3,
                age_s: age(*at),
            }),
            motion_state: self
                .motion_state
                .map_or("no data".into(), motion_state_name),
            monitor_state: self
                .monitor_state
                .map_or("no data".into(), monitor_state_name),
            drives: self.feedback.as_ref().map(|(f, at)| {
                let n = m(f.cable_count);
                DrivesView {
                    bus_state: bus_state_name(f.bus_state),
                    fault: fault_name(f.fault_code),
                    fault_node: f.fault_node,
                    setpoint_age_cycles: f.setpoint_age_cycles,
                    overruns: f.overruns,
                    statusword: f.statusword[..n].to_vec(),
                    drive_state: f.statusword[..n]
                        .iter()
                        .map(|s| cia402_state(*s).to_string())
                        .collect(),
                    cable_length_m: f.cable_length_m[..n].to_vec(),
                    sensor_force_n: f.cable_force_n[..n].to_vec(),
                    age_s: age(*at),
                }
            }),
            processes,
            progress,
            trips: self.trip_count,
            recent_trips: self.trips.iter().rev().take(20).rev().cloned().collect(),
            stop_requests: self.stop_requests,
            ride: self.ride_view(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cia402_states_from_statuswords() {
        assert_eq!(cia402_state(0x0237), "operation enabled");
        assert_eq!(cia402_state(0x0250), "switch on disabled");
        assert_eq!(cia402_state(0x0217), "quick stop active");
        assert_eq!(cia402_state(0x0218), "fault");
        assert_eq!(cia402_state(0x0221), "ready to switch on");
    }

    #[test]
    fn monitor_trip_names_its_cause() {
        let mut e = StateEvent::new(ProcessId::SafetyMonitor, EventKind::EStop, 1);
        e.detail = TripCause::DqLimit.into();
        e.detail_node = 3;
        let (kind, cause) = describe_event(&e).expect("an e-stop is logged");
        assert_eq!(kind, "E-STOP");
        assert!(cause.contains("cable 3"), "{cause}");
        assert!(cause.contains(&TripCause::DqLimit.to_string()), "{cause}");
    }

    #[test]
    fn the_trip_log_is_in_time_order_whatever_order_the_events_arrive_in() {
        let mut c = Collector::new("x/", None, None);
        let t0 = c.t0_ns;
        // Drained per publisher: the monitor's older trip after drive-io's newer fault.
        for (src, kind, dt_ms) in [
            (ProcessId::DriveIo, EventKind::Fault, 30u64),
            (ProcessId::Operator, EventKind::EStop, 40),
            (ProcessId::SafetyMonitor, EventKind::EStop, 10),
            (ProcessId::MotionCore, EventKind::Fault, 20),
        ] {
            let mut e = StateEvent::new(src, kind, 1);
            e.timestamp_ns = t0 + dt_ms * 1_000_000;
            c.event(&e);
        }
        let order: Vec<String> = c.trips().into_iter().map(|t| t.source).collect();
        assert_eq!(
            order,
            ["safety-monitor", "motion-core", "drive-io", "operator"]
        );
        let recent: Vec<f64> = c.status().recent_trips.iter().map(|t| t.t_s).collect();
        assert!(recent.windows(2).all(|w| w[0] <= w[1]), "{recent:?}");
    }

    #[test]
    fn anchors_rotate_with_eq_2_2() {
        // 90° about z maps b = (1, 0, 0) to (0, 1, 0).
        let w = anchors_world(
            &[1.0, 2.0, 3.0, 0.0, 0.0, std::f64::consts::FRAC_PI_2],
            &[[1.0, 0.0, 0.0]],
        );
        assert!((w[0][0] - 1.0).abs() < 1e-12 && (w[0][1] - 3.0).abs() < 1e-12);
    }
}
