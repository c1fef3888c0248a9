//! Hardware-in-the-loop scenarios: drive-io (the real [`runner`](drive_io::runner)) and the winch
//! emulator run as threads on a real bus; the scenario plays motion-core over iceoryx2.
//!
//! The rig is two CAN interfaces with two drives each, on the wire model: the SAME functions
//! run on the host over the `can-wire` hub (`cargo test -p drive-rig`, tests/hil_wire.rs; the
//! hub on a thread) and inside the QEMU guest over real vcan (binary `drive-io-hil`, started by
//! tools/hil-run.sh: every node on its own vcan port, the `can-wire` hub forwarding between
//! them with the bus's bit time and arbitration). Inside the emulator time is not real time, so
//! the scenarios assert behaviour (states, cycle counts, positions), never latencies; time
//! limits are generous "give up" bounds only.

use crate::emulator::{self, EmulatorConfig, EmulatorControl};
use crs_ipc::{
    BusState, DriveFeedback, EventKind, FaultCode, IpcNode, JointSetpoint, ProcessId, StateEvent,
    TopicPublisher, TopicSubscriber, WakeupNotifier, monotonic_ns,
};
use drive_bus::canopen::{Ds402State, NmtState};
use drive_io::runner;
use drives_config::{DrivesConfig, SyncSource};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Number of winches in the HIL rig.
pub const HIL_WINCHES: usize = 4;
/// Its CAN interfaces (two drives each).
pub const HIL_INTERFACES: usize = 2;

/// Where a scenario's interfaces are for each of its two nodes: drive-io's transports and the
/// emulator's, interface by interface. On the host both are the hub's `wire:` sockets; in the
/// guest each node has its own vcan port of each bus (the hub forwards).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RigBuses {
    pub drive_io: Vec<String>,
    pub emulator: Vec<String>,
}

impl RigBuses {
    /// Both nodes on the same transports (the host's `wire:` sockets, or a UDP bus).
    pub fn shared(transports: &[String]) -> Self {
        Self {
            drive_io: transports.to_vec(),
            emulator: transports.to_vec(),
        }
    }

    /// `dio=T0,T1;emu=T2,T3` (per node) or `T0,T1` (shared).
    pub fn parse(arg: &str) -> Res<Self> {
        let list = |s: &str| s.split(',').map(str::to_string).collect::<Vec<_>>();
        let r = match arg.split_once(';') {
            Some((d, e)) => Self {
                drive_io: list(d.strip_prefix("dio=").ok_or("expected dio=…;emu=…")?),
                emulator: list(e.strip_prefix("emu=").ok_or("expected dio=…;emu=…")?),
            },
            None => Self::shared(&list(arg)),
        };
        if r.drive_io.len() != HIL_INTERFACES || r.emulator.len() != HIL_INTERFACES {
            return fail(format!(
                "{arg:?}: the rig has {HIL_INTERFACES} interfaces per node"
            ));
        }
        Ok(r)
    }

    pub fn describe(&self) -> String {
        if self.drive_io == self.emulator {
            self.drive_io.join(",")
        } else {
            format!(
                "dio={};emu={}",
                self.drive_io.join(","),
                self.emulator.join(",")
            )
        }
    }
}

/// The HIL drives configuration on `transports` (one per interface): two drives per
/// interface, velocity and force (the simulated winch's 0x2110) every 5th SYNC, so each bus
/// stays within its budget. Timeouts are lenient because the VM is not real time, and so is the
/// acceleration check (the bound, 200 m/s²): the VM's stalls bunch the rig's setpoints.
pub fn hil_config(transports: &[String]) -> DrivesConfig {
    let mut text = String::from(
        "[bus]\nsync_period_us = 1000\nstale_setpoint_cycles = 50\n\
         heartbeat_producer_ms = 20\nheartbeat_timeout_ms = 300\nboot_timeout_ms = 20000\n\
         sdo_timeout_ms = 500\nmax_cable_speed_m_per_s = 5.0\n\
         drive_heartbeat_consumer_ms = 600\n\
         following_error_window_m = 0.5\n\
         max_cable_acceleration_m_per_s2 = 200.0\n",
    );
    for (k, t) in transports.iter().enumerate() {
        text.push_str(&format!(
            "[[bus.interface]]\nname = \"can{k}\"\ntransport = \"{t}\"\n"
        ));
    }
    let per = HIL_WINCHES.div_ceil(transports.len().max(1));
    for i in 0..HIL_WINCHES {
        let sign = if i % 2 == 0 { 1 } else { -1 };
        text.push_str(&format!(
            "[[winch]]\ninterface = \"can{}\"\nnode_id = {}\ndrum_diameter_m = 0.305\n\
             gear_ratio = 10.0\ncounts_per_rev = 1048576\nsign = {sign}\noffset_counts = {}\n\
             force = \"drive\"\nfeedback_every_n_syncs = 5\n",
            i / per,
            i + 1,
            if sign > 0 { 0 } else { 200_000_000 }
        ));
    }
    // The HIL config is a constant of this crate: failing to parse it is a bug, reported as such.
    DrivesConfig::parse(&text).unwrap_or_else(|e| panic!("built-in HIL config invalid: {e}"))
}

type Res<T> = Result<T, String>;

fn fail<T>(msg: impl Into<String>) -> Res<T> {
    Err(msg.into())
}

/// A running rig: emulator + drive-io threads and the test's own iceoryx2 ports.
pub struct Rig {
    pub cfg: DrivesConfig,
    pub control: Arc<EmulatorControl>,
    stop_drive_io: Arc<AtomicBool>,
    emu: Option<JoinHandle<Res<()>>>,
    dio: Option<JoinHandle<Res<runner::RunSummary>>>,
    _node: IpcNode,
    pub setpoints: TopicPublisher<JointSetpoint>,
    pub feedback: TopicSubscriber<DriveFeedback>,
    pub events: TopicPublisher<StateEvent>,
    /// "setpoint published", notified after every setpoint as motion-core's publish stage does.
    ready: WakeupNotifier,
    pub seq: u64,
    pub initial: [f64; HIL_WINCHES],
}

impl Rig {
    /// Starts the emulator and drive-io on `buses`, with iceoryx2 services under `prefix`;
    /// drive-io's SYNC isochronous (the default `sync_source`).
    pub fn start(buses: &RigBuses, prefix: &str) -> Res<Rig> {
        Self::start_with(buses, prefix, SyncSource::Isochronous)
    }

    /// [`Rig::start`] with drive-io's cycle started by `sync`.
    pub fn start_with(buses: &RigBuses, prefix: &str, sync: SyncSource) -> Res<Rig> {
        let mut cfg = hil_config(&buses.drive_io);
        cfg.bus.sync_source = sync;
        let ecfg_drives = hil_config(&buses.emulator);
        let open = |cfg: &DrivesConfig, who: &str| -> Res<Vec<Box<dyn can_transport::CanBus>>> {
            cfg.transports()
                .map_err(|e| e.to_string())?
                .iter()
                .map(|spec| can_transport::open(spec).map_err(|e| format!("{who} bus {spec}: {e}")))
                .collect()
        };
        let mut ecfg = EmulatorConfig::from_drives(&ecfg_drives, 5.0).map_err(|e| e.to_string())?;
        ecfg.initial_length_m = (0..HIL_WINCHES).map(|i| 4.0 + 0.5 * i as f64).collect();
        let control = EmulatorControl::new();
        // Both ends open their buses before either thread runs: no frame is lost to a late join.
        let emu_bus = open(&ecfg_drives, "emulator")?;
        let dio_bus = open(&cfg, "drive-io")?;
        let c2 = control.clone();
        let emu = std::thread::Builder::new()
            .name("winch-emulator".into())
            .spawn(move || emulator::run(emu_bus, &ecfg, &c2).map_err(|e| format!("emulator: {e}")))
            .map_err(|e| e.to_string())?;
        let node = IpcNode::with_prefix("hil-test", prefix).map_err(|e| e.to_string())?;
        let setpoints = node
            .publisher::<JointSetpoint>()
            .map_err(|e| e.to_string())?;
        let feedback = node
            .subscriber::<DriveFeedback>()
            .map_err(|e| e.to_string())?;
        let events = node.publisher::<StateEvent>().map_err(|e| e.to_string())?;
        let ready = node.setpoint_ready_notifier().map_err(|e| e.to_string())?;
        let stop = Arc::new(AtomicBool::new(false));
        let (s2, cfg2, prefix2) = (stop.clone(), cfg.clone(), prefix.to_string());
        let dio = std::thread::Builder::new()
            .name("drive-io".into())
            .spawn(move || {
                let ipc = IpcNode::with_prefix("drive-io", &prefix2).map_err(|e| e.to_string())?;
                runner::run(&cfg2, dio_bus, &ipc, &s2).map_err(|e| format!("drive-io: {e}"))
            })
            .map_err(|e| e.to_string())?;
        Ok(Rig {
            cfg,
            control,
            stop_drive_io: stop,
            emu: Some(emu),
            dio: Some(dio),
            _node: node,
            setpoints,
            feedback,
            events,
            ready,
            seq: 0,
            initial: [0.0; HIL_WINCHES],
        })
    }

    fn threads_alive(&self) -> Res<()> {
        if self.dio.as_ref().is_some_and(|h| h.is_finished()) {
            return fail("drive-io thread ended early");
        }
        if self.emu.as_ref().is_some_and(|h| h.is_finished()) {
            return fail("emulator thread ended early");
        }
        Ok(())
    }

    /// Newest feedback, waiting up to `timeout` for one.
    pub fn latest_feedback(&self, timeout: Duration) -> Res<DriveFeedback> {
        let t0 = Instant::now();
        loop {
            if let Some(f) = self.feedback.latest().map_err(|e| e.to_string())? {
                return Ok(f);
            }
            self.threads_alive()?;
            if t0.elapsed() > timeout {
                return fail("no drive feedback published");
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Waits until drive-io reports `state`; fails early on an unexpected stop state.
    pub fn wait_state(
        &self,
        state: BusState,
        timeout: Duration,
        allowed: &[BusState],
    ) -> Res<DriveFeedback> {
        let t0 = Instant::now();
        loop {
            let f = self.latest_feedback(timeout)?;
            let s = BusState::from_u32(f.bus_state);
            if s == Some(state) {
                return Ok(f);
            }
            if !s.is_some_and(|s| allowed.contains(&s)) {
                return fail(format!(
                    "expected {state:?}, got {s:?} (fault_code {} node {} age {})",
                    f.fault_code, f.fault_node, f.setpoint_age_cycles
                ));
            }
            if t0.elapsed() > timeout {
                return fail(format!("timeout waiting for {state:?}; still {s:?}"));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Publishes one setpoint with the next sequence number, stamped now.
    pub fn publish(&mut self, lengths: &[f64; HIL_WINCHES]) -> Res<JointSetpoint> {
        self.publish_at(lengths, monotonic_ns())
    }

    /// Publishes one setpoint stamped `timestamp_ns`: the instant the lengths were computed for
    /// (drive-io judges the implied cable speed on these stamps, so they must match the profile).
    pub fn publish_at(
        &mut self,
        lengths: &[f64; HIL_WINCHES],
        timestamp_ns: u64,
    ) -> Res<JointSetpoint> {
        self.seq += 1;
        let mut sp = JointSetpoint {
            cable_count: HIL_WINCHES as u32,
            sequence: self.seq,
            timestamp_ns,
            ..Default::default()
        };
        sp.cable_length_m[..HIL_WINCHES].copy_from_slice(lengths);
        self.setpoints.publish(&sp).map_err(|e| e.to_string())?;
        self.ready.notify().map_err(|e| e.to_string())?;
        Ok(sp)
    }

    /// Boots to Ready and records the initial cable lengths from the feedback.
    pub fn boot(&mut self) -> Res<DriveFeedback> {
        let f = self.wait_state(
            BusState::Ready,
            Duration::from_secs(30),
            &[BusState::Booting],
        )?;
        for i in 0..HIL_WINCHES {
            if Ds402State::from_statusword(f.statusword[i]) != Ds402State::OperationEnabled {
                return fail(format!(
                    "winch {i} statusword {:#06x} is not Operation Enabled",
                    f.statusword[i]
                ));
            }
            if self.control.nmt_state(i) != Some(NmtState::Operational) {
                return fail(format!(
                    "winch {i} NMT state {:?} is not Operational",
                    self.control.nmt_state(i)
                ));
            }
            let truth = self.control.length_m(i);
            if (f.cable_length_m[i] - truth).abs() > 1e-6 {
                return fail(format!(
                    "winch {i}: feedback {} m != plant {truth} m",
                    f.cable_length_m[i]
                ));
            }
            self.initial[i] = f.cable_length_m[i];
        }
        Ok(f)
    }

    /// Streams `profile(t)` at ~1 kHz for `duration`; returns the published setpoints.
    pub fn stream(
        &mut self,
        duration: Duration,
        mut profile: impl FnMut(f64) -> [f64; HIL_WINCHES],
    ) -> Res<Vec<JointSetpoint>> {
        let dur = duration.as_nanos() as u64;
        let mut sent: Vec<JointSetpoint> = Vec::with_capacity(duration.as_millis() as usize + 8);
        let mut start = None;
        loop {
            // One clock reading gives both the profile time and the stamp: a stall between
            // computing and stamping must not make the stream look faster than it is. t = 0 is
            // the first sample, so the stream starts exactly at profile(0).
            let now = monotonic_ns();
            let start = *start.get_or_insert(now);
            if now - start >= dur {
                break;
            }
            // The profile advances one millisecond per published setpoint, not with the wall
            // clock: when this thread was not scheduled for k ms it continues where it was
            // instead of jumping k ms of motion at once. Such a jump is a velocity spike that
            // drive-io's acceleration limit rightly refuses; a real-time motion core never
            // produces one.
            let t = sent.len() as f64 * 1e-3;
            sent.push(self.publish_at(&profile(t), now)?);
            std::thread::sleep(Duration::from_micros(900));
        }
        Ok(sent)
    }

    /// Stops both threads and reports their errors.
    pub fn shutdown(mut self) -> Res<runner::RunSummary> {
        self.stop_drive_io.store(true, Ordering::Release);
        self.control.stop.store(true, Ordering::Release);
        let dio = self
            .dio
            .take()
            .map(|h| h.join().map_err(|_| "drive-io thread panicked".to_string()));
        let emu = self
            .emu
            .take()
            .map(|h| h.join().map_err(|_| "emulator thread panicked".to_string()));
        if let Some(e) = emu {
            e??;
        }
        match dio {
            Some(r) => r?,
            None => fail("drive-io not running"),
        }
    }
}

impl Drop for Rig {
    fn drop(&mut self) {
        self.stop_drive_io.store(true, Ordering::Release);
        self.control.stop.store(true, Ordering::Release);
    }
}

fn all_in(rig: &Rig, want: Ds402State, timeout: Duration) -> Res<()> {
    let t0 = Instant::now();
    loop {
        if (0..HIL_WINCHES).all(|i| rig.control.ds402_state(i) == want) {
            return Ok(());
        }
        if t0.elapsed() > timeout {
            let s: Vec<_> = (0..HIL_WINCHES)
                .map(|i| rig.control.ds402_state(i))
                .collect();
            return fail(format!("drives not all {want:?}: {s:?}"));
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// Lengths must not change while setpoints keep asking for motion: the drives hold.
fn assert_holds(rig: &mut Rig, state: BusState) -> Res<()> {
    // Let any quick-stop deceleration finish (14 m/s^2 from <= 0.5 m/s: < 40 ms of plant time).
    let t0 = Instant::now();
    while (0..HIL_WINCHES).any(|i| rig.control.velocity_m_per_s(i) != 0.0) {
        if t0.elapsed() > Duration::from_secs(10) {
            return fail("drives did not come to rest after quick stop");
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let before: Vec<f64> = (0..HIL_WINCHES).map(|i| rig.control.length_m(i)).collect();
    let syncs0 = rig.control.syncs.load(Ordering::Acquire);
    let away = [
        before[0] + 0.05,
        before[1] + 0.05,
        before[2] + 0.05,
        before[3] + 0.05,
    ];
    rig.stream(Duration::from_millis(200), |_| away)?;
    let syncs1 = rig.control.syncs.load(Ordering::Acquire);
    if syncs1 <= syncs0 {
        return fail("no SYNC while holding: drive-io stopped cycling");
    }
    for (i, b) in before.iter().enumerate() {
        let now = rig.control.length_m(i);
        if (now - b).abs() > 1e-9 {
            return fail(format!(
                "winch {i} moved while it should hold: {b} -> {now}"
            ));
        }
    }
    let f = rig.latest_feedback(Duration::from_secs(1))?;
    if BusState::from_u32(f.bus_state) != Some(state) {
        return fail(format!(
            "state left {state:?}: {:?}",
            BusState::from_u32(f.bus_state)
        ));
    }
    Ok(())
}

/// Whether the scenario may assert timing-dependent quantities (host: yes; emulator VM: no).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Timing {
    /// Real time (host over UDP): the tracking error during motion is asserted too.
    RealTime,
    /// Emulated time (QEMU TCG): only functional results are asserted; tracking is reported.
    Emulated,
}

/// Boot through NMT + CiA 402, follow a setpoint stream, feedback matches the plant.
pub fn scenario_follow(buses: &RigBuses, prefix: &str) -> Res<String> {
    scenario_follow_timed(buses, prefix, Timing::RealTime)
}

/// [`scenario_follow`] with explicit [`Timing`].
pub fn scenario_follow_timed(buses: &RigBuses, prefix: &str, timing: Timing) -> Res<String> {
    let mut rig = Rig::start(buses, prefix)?;
    rig.boot()?;
    let init = rig.initial;
    // Raised-cosine moves of 0.1 m, period 1 s: peak 0.31 m/s, 2 m/s^2 (within the drive limits).
    let profile = |t: f64| {
        let mut l = init;
        for (i, li) in l.iter_mut().enumerate() {
            let dir = if i % 2 == 0 { 1.0 } else { -1.0 };
            *li += dir * 0.05 * (1.0 - (2.0 * std::f64::consts::PI * t).cos());
        }
        l
    };
    // Stream and sample feedback during motion. The profile is clocked by drive-io's SYNC cycle
    // counter (as a motion core phase-locked to the bus would be), not by wall time: in the VM
    // cycles are irregular, and one SYNC is one period of plant time for the drives.
    let t0 = Instant::now();
    let mut sent: Vec<JointSetpoint> = Vec::new();
    let mut worst_track = 0.0f64;
    let mut samples = 0;
    let mut saw_motion = false;
    let mut peak = [0.0f64; HIL_WINCHES];
    // c0 = the cycle of the first feedback seen inside the loop, so the first setpoint is
    // profile(1 ms) whatever this thread's scheduling delay before the loop.
    let mut c0: Option<u64> = None;
    let mut prev: Option<DriveFeedback> = None;
    let mut elapsed_cycles = 0;
    while elapsed_cycles < 1500 {
        if t0.elapsed() > Duration::from_secs(120) {
            return fail(format!(
                "stream stalled at cycle {} of 1500",
                elapsed_cycles
            ));
        }
        let mut newest = None;
        rig.feedback
            .drain(|f| {
                newest = Some(*f);
                let consecutive = prev.filter(|p| p.cycle + 1 == f.cycle);
                prev = Some(*f);
                if BusState::from_u32(f.bus_state) != Some(BusState::Running) {
                    return;
                }
                for i in 0..HIL_WINCHES {
                    let d = f.cable_length_m[i] - init[i];
                    if d.abs() > peak[i].abs() {
                        peak[i] = d;
                    }
                    saw_motion |= f.cable_velocity_m_per_s[i].abs() > 0.1;
                }
                // The TPDO in feedback of cycle c answers the SYNC of cycle c-1, whose target
                // is the setpoint applied in cycle c-1 (sequence numbers index `sent` from 1).
                let Some(p) = consecutive else { return };
                let Some(sp) = (p.applied_setpoint_sequence as usize)
                    .checked_sub(1)
                    .and_then(|k| sent.get(k))
                else {
                    return;
                };
                for i in 0..HIL_WINCHES {
                    worst_track =
                        worst_track.max((f.cable_length_m[i] - sp.cable_length_m[i]).abs());
                }
                samples += 1;
            })
            .map_err(|e| e.to_string())?;
        match newest {
            Some(f) => {
                // For the next cycle: profile time and stamp both one period after cycle f.
                let c0 = *c0.get_or_insert(f.cycle);
                elapsed_cycles = f.cycle - c0;
                // One sequence number per SYNC period, as a phase-locked motion core numbers
                // them: samples for cycles this thread missed are lost, not renumbered (kept in
                // `sent` unpublished, so sequence numbers still index it).
                while (sent.len() as u64) < elapsed_cycles {
                    let t = (sent.len() + 1) as f64 * 1e-3;
                    rig.seq += 1;
                    let mut lost = JointSetpoint {
                        cable_count: HIL_WINCHES as u32,
                        sequence: rig.seq,
                        ..Default::default()
                    };
                    lost.cable_length_m[..HIL_WINCHES].copy_from_slice(&profile(t));
                    sent.push(lost);
                }
                let t = (elapsed_cycles + 1) as f64 * 1e-3;
                sent.push(rig.publish_at(&profile(t), f.timestamp_ns + 1_000_000)?);
            }
            None => std::thread::sleep(Duration::from_micros(200)),
        }
        rig.threads_alive()?;
    }
    let f = rig.wait_state(BusState::Running, Duration::from_secs(1), &[])?;
    if samples < 20 || !saw_motion {
        return fail(format!(
            "too little feedback during motion: {samples} samples, motion seen {saw_motion}"
        ));
    }
    // The emulator reaches each target within its SYNC when the stream keeps up (steps of
    // <= 0.3 mm here). When this thread misses cycles the target jumps several steps at once and
    // the drive catches up within its 14 m/s^2: a few mm of lag are physical then. 20 mm still
    // catches every scaling/sign/offset error (those give errors of the size of the 0.1 m move).
    if timing == Timing::RealTime && worst_track > 0.020 {
        return fail(format!("tracking error {worst_track} m > 20 mm"));
    }
    // Functional in any timing: every cable made the whole commanded excursion (+-0.1 m, sign
    // alternating per winch), which a sign, scaling or offset error would break.
    for (i, p) in peak.iter().enumerate() {
        let want = if i % 2 == 0 { 0.1 } else { -0.1 };
        if (p - want).abs() > 0.005 {
            return fail(format!(
                "winch {i}: peak excursion {p} m, commanded {want} m"
            ));
        }
    }
    // Hold the final pose (keep publishing: a real motion core publishes every cycle) until the
    // drives settle. In the VM plant time runs slower than wall time (one SYNC period per SYNC),
    // so wait for convergence with a generous give-up bound instead of a fixed time.
    let last = profile(1.5);
    let t_hold = Instant::now();
    loop {
        rig.stream(Duration::from_millis(20), |_| last)?;
        let f = rig.latest_feedback(Duration::from_secs(1))?;
        let settled = (0..HIL_WINCHES).all(|i| {
            (f.cable_length_m[i] - last[i]).abs() <= 1e-6 && rig.control.velocity_m_per_s(i) == 0.0
        });
        if settled {
            break;
        }
        if t_hold.elapsed() > Duration::from_secs(60) {
            return fail(format!(
                "drives did not settle at the final setpoint: feedback {:?}, setpoint {last:?}",
                &f.cable_length_m[..HIL_WINCHES]
            ));
        }
    }
    rig.stream(Duration::from_millis(20), |_| last)?;
    let f2 = rig.latest_feedback(Duration::from_secs(1))?;
    for (i, want) in last.iter().enumerate() {
        let truth = rig.control.length_m(i);
        if (f2.cable_length_m[i] - want).abs() > 1e-6 || (truth - want).abs() > 1e-6 {
            return fail(format!(
                "winch {i}: setpoint {want} feedback {} plant {truth}",
                f2.cable_length_m[i]
            ));
        }
        if (f2.cable_force_n[i] - 2000.0).abs() > 1.0 {
            return fail(format!(
                "winch {i}: force {} N, emulator reports 2000 N at rest",
                f2.cable_force_n[i]
            ));
        }
        if f2.rx_timestamp_ns[i] == 0 || f2.rx_timestamp_ns[i] > f2.timestamp_ns {
            return fail(format!("winch {i}: bad rx timestamp"));
        }
    }
    let n = sent.len();
    let summary = rig.shutdown()?;
    Ok(format!(
        "{n} setpoints, {samples} feedback samples, peak excursions {:?} m, worst tracking {:.3} mm ({timing:?} timing), final error < 1 um, cycles {} (feedback cycle {}), overruns {}",
        peak.map(|p| (p * 1e4).round() / 1e4),
        worst_track * 1e3,
        summary.cycles,
        f.cycle,
        summary.overruns
    ))
}

/// Setpoints stop -> quick stop after exactly `stale_setpoint_cycles` + 1 cycles, then hold.
pub fn scenario_stale(buses: &RigBuses, prefix: &str) -> Res<String> {
    let mut rig = Rig::start(buses, prefix)?;
    rig.boot()?;
    let init = rig.initial;
    rig.stream(Duration::from_millis(300), |t| {
        init.map(|l| l + ramp_m(0.2, t))
    })?;
    rig.wait_state(BusState::Running, Duration::from_secs(1), &[])?;
    // Stop publishing.
    let f = rig.wait_state(
        BusState::StaleStop,
        Duration::from_secs(30),
        &[BusState::Running],
    )?;
    let limit = rig.cfg.bus.stale_setpoint_cycles;
    if f.setpoint_age_cycles != limit + 1 {
        return fail(format!(
            "quick stop after {} cycles, configured {limit} (+1)",
            f.setpoint_age_cycles
        ));
    }
    all_in(&rig, Ds402State::QuickStopActive, Duration::from_secs(5))?;
    assert_holds(&mut rig, BusState::StaleStop)?;
    rig.shutdown()?;
    Ok(format!(
        "quick stop at setpoint age {} cycles (limit {limit}), drives QuickStopActive, holding",
        f.setpoint_age_cycles
    ))
}

/// A drive stops its heartbeat -> drive-io faults and quick-stops ALL drives.
pub fn scenario_heartbeat_loss(buses: &RigBuses, prefix: &str) -> Res<String> {
    let mut rig = Rig::start(buses, prefix)?;
    rig.boot()?;
    let init = rig.initial;
    let sent = rig.stream(Duration::from_millis(200), |t| {
        init.map(|l| l + ramp_m(0.1, t))
    })?;
    rig.wait_state(BusState::Running, Duration::from_secs(1), &[])?;
    // Hold where the stream ended (braking is free; a jump ahead would be a velocity step).
    let hold: [f64; HIL_WINCHES] = match sent.last() {
        Some(s) => std::array::from_fn(|i| s.cable_length_m[i]),
        None => init,
    };
    let victim = 2;
    rig.control.mute_heartbeat(victim);
    let t0 = Instant::now();
    // Keep streaming: the fault must come from the heartbeat consumer, not from stale setpoints.
    let mut f = None;
    while t0.elapsed() < Duration::from_secs(30) {
        let l = hold;
        rig.publish(&l)?;
        let fb = rig.latest_feedback(Duration::from_secs(1))?;
        match BusState::from_u32(fb.bus_state) {
            Some(BusState::Running) => {}
            Some(BusState::Fault) => {
                f = Some(fb);
                break;
            }
            s => return fail(format!("unexpected state {s:?} (fault {})", fb.fault_code)),
        }
        std::thread::sleep(Duration::from_micros(900));
    }
    let Some(f) = f else {
        return fail("no fault after heartbeat loss");
    };
    let node = rig.cfg.winches[victim].node_id;
    if f.fault() != Ok(FaultCode::HeartbeatLost) || f.fault_node != u32::from(node) {
        return fail(format!(
            "fault {} node {}, expected HEARTBEAT_LOST node {node}",
            f.fault_code, f.fault_node
        ));
    }
    let detect_ms = t0.elapsed().as_millis();
    all_in(&rig, Ds402State::QuickStopActive, Duration::from_secs(5))?;
    assert_holds(&mut rig, BusState::Fault)?;
    rig.shutdown()?;
    Ok(format!(
        "node {node} heartbeat muted -> Fault HEARTBEAT_LOST after ~{detect_ms} ms wall, all drives QuickStopActive, holding"
    ))
}

/// The position (m) after `t` s of a move at `v_m_per_s` that starts from rest at
/// [`RAMP_ACCEL_M_PER_S2`]: drive-io refuses a velocity step out of a hold (its
/// `max_cable_acceleration_m_per_s2`), as a real motion core never commands one.
pub fn ramp_m(v_m_per_s: f64, t: f64) -> f64 {
    let t1 = v_m_per_s.abs() / RAMP_ACCEL_M_PER_S2;
    if t < t1 {
        0.5 * RAMP_ACCEL_M_PER_S2 * t * t * v_m_per_s.signum()
    } else {
        v_m_per_s * (t - 0.5 * t1)
    }
}

/// The acceleration of [`ramp_m`]'s start (below drive-io's default limit of 50 m/s²).
pub const RAMP_ACCEL_M_PER_S2: f64 = 10.0;

/// An e-stop event on the process bus -> quick stop all, hold; Reset re-enables.
pub fn scenario_estop(buses: &RigBuses, prefix: &str) -> Res<String> {
    let mut rig = Rig::start(buses, prefix)?;
    rig.boot()?;
    let init = rig.initial;
    rig.stream(Duration::from_millis(200), |t| {
        init.map(|l| l + ramp_m(-0.1, t))
    })?;
    rig.wait_state(BusState::Running, Duration::from_secs(1), &[])?;
    let ev = StateEvent::new(ProcessId::Test, EventKind::EStop, 1);
    rig.events.publish(&ev).map_err(|e| e.to_string())?;
    // Keep streaming while waiting: the stop must come from the event, not from stale setpoints.
    let t0 = Instant::now();
    loop {
        let here: [f64; HIL_WINCHES] = std::array::from_fn(|i| rig.control.length_m(i));
        rig.publish(&here)?;
        let fb = rig.latest_feedback(Duration::from_secs(1))?;
        match BusState::from_u32(fb.bus_state) {
            Some(BusState::EStop) => break,
            Some(BusState::Running) if t0.elapsed() < Duration::from_secs(30) => {}
            s => return fail(format!("expected EStop, got {s:?}")),
        }
        std::thread::sleep(Duration::from_micros(900));
    }
    all_in(&rig, Ds402State::QuickStopActive, Duration::from_secs(5))?;
    assert_holds(&mut rig, BusState::EStop)?;
    // Reset: drives are walked back to Operation Enabled holding their position -> Ready.
    // Only the safety monitor's reset counts; this rig runs without the safety
    // heartbeat, so drive-io checks the event's source and a newer epoch (in `detail`).
    let mut reset = StateEvent::new(ProcessId::SafetyMonitor, EventKind::Reset, 2);
    reset.detail = 1;
    rig.events.publish(&reset).map_err(|e| e.to_string())?;
    rig.wait_state(
        BusState::Ready,
        Duration::from_secs(30),
        &[BusState::EStop, BusState::Booting],
    )?;
    all_in(&rig, Ds402State::OperationEnabled, Duration::from_secs(5))?;
    rig.shutdown()?;
    Ok("e-stop -> all QuickStopActive and holding; reset -> Ready, all Operation Enabled".into())
}

/// Phase lock: with `sync_source = "setpoint"` every published setpoint starts a drive-io cycle
/// (RPDOs + SYNC) of its own; with `"isochronous"` a setpoint published before the guard time
/// starts the RPDOs of the next SYNC (the SYNC itself stays on drive-io's grid), a later one
/// goes with the guard's cycle; with `"clock"` none does, the same stream
/// is applied on drive-io's own ticks. Setpoints 5 ms apart, so the count holds in emulated
/// time too (no latency is asserted here; bus-latency-bench measures it on the host).
pub fn scenario_phase_lock(buses: &RigBuses, prefix: &str) -> Res<String> {
    const N: u64 = 100;
    let mut report = Vec::new();
    for sync in [
        SyncSource::Isochronous,
        SyncSource::Setpoint,
        SyncSource::Clock,
    ] {
        let mut rig = Rig::start_with(buses, &format!("{prefix}{sync:?}/"), sync)?;
        rig.boot()?;
        let hold = rig.initial;
        let mut last = 0;
        for _ in 0..N {
            last = rig.publish(&hold)?.sequence;
            std::thread::sleep(Duration::from_millis(5));
        }
        let t0 = Instant::now();
        while rig
            .latest_feedback(Duration::from_secs(1))?
            .applied_setpoint_sequence
            < last
        {
            if t0.elapsed() > Duration::from_secs(10) {
                return fail(format!("{sync:?}: setpoint {last} never applied"));
            }
        }
        let s = rig.shutdown()?;
        let ok = match sync {
            // A notification is lost only when drive-io was not scheduled for a whole 5 ms.
            SyncSource::Setpoint => s.setpoint_cycles >= N * 9 / 10 && s.clock_cycles > 0,
            // A setpoint published between the guard time and its SYNC (0.4 + 0.1 of each
            // period, the stream's phase here is arbitrary) goes with the next guard's cycle,
            // not a cycle of its own (IsoClock: one cycle per SYNC): about half start one.
            // Each starts at most one, and all are applied (above).
            SyncSource::Isochronous => {
                (N * 3 / 10..=N).contains(&s.setpoint_cycles) && s.clock_cycles > 0
            }
            SyncSource::Clock => s.setpoint_cycles == 0,
        };
        if !ok {
            return fail(format!(
                "{sync:?}: {} cycles started by a setpoint, {} by the clock, for {N} setpoints",
                s.setpoint_cycles, s.clock_cycles
            ));
        }
        report.push(format!(
            "{sync:?}: {} by setpoint / {} by clock",
            s.setpoint_cycles, s.clock_cycles
        ));
    }
    Ok(format!(
        "{N} setpoints 5 ms apart, all applied; {}",
        report.join("; ")
    ))
}

/// All scenarios, one set of buses each (`buses[i]`, reused round robin), printing
/// `HIL PASS|FAIL <name>` markers.
pub fn run_all(buses: &[RigBuses], prefix: &str, timing: Timing) -> bool {
    type Scenario = fn(&RigBuses, &str) -> Res<String>;
    let follow: Scenario = match timing {
        Timing::RealTime => scenario_follow,
        Timing::Emulated => |t, p| scenario_follow_timed(t, p, Timing::Emulated),
    };
    let scenarios: [(&str, Scenario); 5] = [
        ("follow_setpoints", follow),
        ("stale_setpoints_quick_stop", scenario_stale),
        ("heartbeat_loss_faults_all", scenario_heartbeat_loss),
        ("estop_event_quick_stop_and_reset", scenario_estop),
        ("phase_lock", scenario_phase_lock),
    ];
    let mut ok = true;
    for (k, (name, f)) in scenarios.iter().enumerate() {
        let b = &buses[k % buses.len()];
        let t0 = Instant::now();
        match f(b, &format!("{prefix}{name}/")) {
            Ok(msg) => println!(
                "HIL PASS {name} [{}] ({:.1} s): {msg}",
                b.describe(),
                t0.elapsed().as_secs_f64()
            ),
            Err(msg) => {
                ok = false;
                println!(
                    "HIL FAIL {name} [{}] ({:.1} s): {msg}",
                    b.describe(),
                    t0.elapsed().as_secs_f64()
                );
            }
        }
    }
    ok
}
