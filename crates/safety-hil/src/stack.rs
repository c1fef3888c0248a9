//! The processes of one scenario and their observation: `winch-emulator`, `safety-monitor` and
//! `drive-io` (then `motion-core` or the fake publisher), started under the stack's one process
//! supervisor with per-process logs in the scenario's directory and the scenario's own iceoryx2
//! prefix; the drive-io feedback, the state events and the heartbeats on that prefix, and the
//! emulator's status file. Waits are bounded and end on an observed condition (monitor
//! heartbeats, feedback samples, the emulator's status); the fixed 0.5 s of `require_braked` is
//! the no-motion window the check itself requires.

use crate::Res;
use crate::configs::{
    drives_never_ready, emulator_drives, home_length, monitor_config, monitor_executable,
};
use crate::emulator::{
    Control, DEMAND_FOLLOW, DEMAND_HOLD, DEMAND_QUICK_STOP, EmuStatus, parse_status,
};
use crate::fake_motion::{Fake, FakeCtl};
use crs_ipc::{
    BusState, DriveFeedback, EventKind, Heartbeat, IpcNode, MonitorCode, MonitorState, MotionState,
    ProcessId, StateEvent, monotonic_ns,
};
use crs_supervisor::supervisor::{Supervisor, Usage};
use safety_monitor::Cause;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Finite setpoints the producer publishes after a non-finite fault before an operator turns
/// the key: ten times the shipped `reset_clear_cycles` (3).
pub const CLEAN_SETPOINTS_BEFORE_KEY: u64 = 30;

/// Monitor cycles (its heartbeats) after those setpoints before the key: twice the shipped
/// `reset_clear_cycles`.
pub const MONITOR_CYCLES_BEFORE_KEY: u64 = 6;

pub struct Stack {
    pub name: &'static str,
    pub dir: PathBuf,
    pub cfg: PathBuf,
    bin_dir: Option<PathBuf>,
    /// The scenario's CAN buses (each process's transports, the wire hub).
    pub buses: crs_supervisor::transport::StackBuses,
    pub period_us: u32,
    pub prefix: String,
    procs: Supervisor,
    _node: IpcNode,
    feedback: crs_ipc::TopicSubscriber<DriveFeedback>,
    events: crs_ipc::TopicSubscriber<StateEvent>,
    heartbeats: crs_ipc::TopicSubscriber<Heartbeat>,
    pub last_feedback: Option<DriveFeedback>,
    /// Monitor e-stop events (kind EStop from the monitor).
    pub monitor_estops: Vec<StateEvent>,
    pub monitor_resets: u32,
    pub monitor_state: Option<MonitorState>,
    /// Monitor heartbeats (one per monitor cycle) and drive-io feedback samples (one per SYNC
    /// cycle) received: scenarios pace their observations by these, never by sleeps.
    pub monitor_heartbeats: u64,
    pub feedback_count: u64,
    /// motion-core's loop state (its heartbeat), if it runs.
    pub motion_state: Option<MotionState>,
    /// The monitor's answers to reset requests (StateChanged with a reset answer
    /// [`MonitorCode`] in `detail`), in order.
    pub reset_answers: Vec<StateEvent>,
    /// The scenario's fault was injected (or its stack was up and following): a failure from
    /// here on is the scenario's verdict, never retried; before it, a stall of the stack.
    pub injected: bool,
    /// The winch emulator's control file as this harness last wrote it (forces, the safety
    /// I/O node's reset key and e-stop).
    control: Control,
    /// The monitor's command line (to start it again: `monitor_restart_reset`).
    mon_args: Vec<String>,
    fake: Option<Fake>,
}

impl Stack {
    pub fn exe(&self, name: &str) -> PathBuf {
        match &self.bin_dir {
            Some(d) => d.join(name),
            None => PathBuf::from(name),
        }
    }

    /// Starts `name` from the binary directory (its log `<name>.log` in the scenario's
    /// directory, the scenario's iceoryx2 prefix, RUST_LOG=info whatever the harness has).
    fn spawn(&mut self, name: &'static str, args: &[String]) -> Res<()> {
        let exe = self.exe(name);
        self.procs
            .spawn(name, &exe, args, &[("RUST_LOG", "info")])
            .map(|_| ())
            .map_err(|e| e.to_string())
    }

    pub fn pid(&self, name: &str) -> Res<i32> {
        self.procs
            .pid(name)
            .map(|p| p as i32)
            .ok_or_else(|| format!("{name} not running"))
    }

    /// Sends `sig` to the running process `name` (it stays supervised).
    pub fn signal(&mut self, name: &str, sig: i32) -> Res<()> {
        self.procs.signal(name, sig).map_err(|e| e.to_string())
    }

    /// Stops `name` (SIGTERM, SIGKILL after the supervisor's grace period) and returns its
    /// whole-life resource usage.
    pub fn stop_with_usage(&mut self, name: &str) -> Res<Usage> {
        self.procs
            .stop_with_usage(name)
            .ok_or_else(|| format!("{name} not running"))
    }

    pub fn start(
        name: &'static str,
        dir: &Path,
        bin_dir: Option<PathBuf>,
        bus_mode: &crs_supervisor::transport::BusMode,
        period_us: u32,
        emulator_rt_priority: Option<u32>,
    ) -> Res<Stack> {
        let sdir = dir.join(name);
        std::fs::create_dir_all(&sdir).map_err(|e| e.to_string())?;
        // A fault injection left by an earlier run in the same --workdir would be read by the
        // new emulator at its start (a force fault before drive-io is Running trips the
        // monitor at start-up and the scenario times out): every scenario starts clean.
        for stale in ["emulator.control", "emulator.control.tmp"] {
            match std::fs::remove_file(sdir.join(stale)) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(format!("{}: {e}", sdir.join(stale).display()));
                }
                _ => {}
            }
        }
        // Every start its own iceoryx2 services: a second attempt of a scenario (--attempts)
        // must not meet the first attempt's dead nodes.
        static STARTS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = STARTS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let prefix = format!("shil-{name}-{}-{n}/", std::process::id());
        let node = IpcNode::with_prefix("safety-hil", &prefix).map_err(|e| e.to_string())?;
        // Quiet: this harness's stdout is parsed by the scripts. The grace period bounds the
        // graceful stop of `stop_with_usage` (the CPU measurement); killed processes and the
        // end of a scenario use SIGKILL without grace.
        let mut procs = Supervisor::new(&prefix, &sdir)
            .quiet()
            .with_grace(Duration::from_secs(10));
        // The buses first (the wire hub, or vcan ports it forwards between): every process of
        // the scenario, the harness itself included (its injections and spying), is a node.
        let drives = drives_config::DrivesConfig::load(&dir.join("drives.toml"))
            .map_err(|e| e.to_string())?;
        let hub = match &bin_dir {
            Some(d) => d.join("can-wire"),
            None => PathBuf::from("can-wire"),
        };
        let buses = crs_supervisor::transport::start(
            bus_mode,
            &drives,
            &["winch-emulator", "safety-monitor", "drive-io", "safety-hil"],
            &mut procs,
            &hub,
            &sdir,
            &format!("{}-{n}", std::process::id()),
        )
        .map_err(|e| e.to_string())?;
        let mut st = Stack {
            name,
            dir: sdir,
            cfg: dir.to_path_buf(),
            bin_dir,
            buses,
            period_us,
            prefix,
            procs,
            feedback: node.subscriber().map_err(|e| e.to_string())?,
            events: node.subscriber().map_err(|e| e.to_string())?,
            heartbeats: node.subscriber().map_err(|e| e.to_string())?,
            _node: node,
            last_feedback: None,
            monitor_estops: Vec::new(),
            monitor_resets: 0,
            monitor_state: None,
            monitor_heartbeats: 0,
            feedback_count: 0,
            motion_state: None,
            reset_answers: Vec::new(),
            injected: false,
            control: Control::default(),
            mon_args: Vec::new(),
            fake: None,
        };
        let cfg_dir = st.cfg.clone();
        let c = |f: &str| cfg_dir.join(f).display().to_string();
        let status = st.dir.join("emulator.status").display().to_string();
        let mut emu_args = vec![
            "--config".into(),
            c(emulator_drives(name)),
            "--initial-length-m".into(),
            format!("{}", home_length()),
            "--status-file".into(),
            status,
            "--control-file".into(),
            st.dir.join("emulator.control").display().to_string(),
        ];
        if let Some(p) = emulator_rt_priority {
            emu_args.extend(["--rt-priority".into(), p.to_string()]);
        }
        emu_args.extend(st.buses.args("winch-emulator"));
        st.spawn("winch-emulator", &emu_args)?;
        let mon_args: Vec<String> = vec![
            "--config".into(),
            c(monitor_config(name)),
            "--ipc-prefix".into(),
            st.prefix.clone(),
        ]
        .into_iter()
        .chain(st.buses.args("safety-monitor"))
        .collect();
        st.mon_args = mon_args.clone();
        st.spawn_monitor(monitor_executable(name))?;
        // The monitor starts not ready (STOP) until every drive is operational and sends forces
        // (after drive-io's NMT start): the drives release only after its RUN pairs, then
        // drive-io can enable them.
        st.wait("the monitor's heartbeat", 20.0, |s| {
            Ok(s.monitor_state.is_some())
        })?;
        let dio_args: Vec<String> = vec![
            "--config".into(),
            c("drives.toml"),
            "--ipc-prefix".into(),
            st.prefix.clone(),
        ]
        .into_iter()
        .chain(st.buses.args("drive-io"))
        .collect();
        st.spawn("drive-io", &dio_args)?;
        if drives_never_ready(name) {
            return Ok(st);
        }
        st.wait("drive-io Ready (boot, SDO, CiA 402 enable)", 40.0, |s| {
            Ok(s.bus_state() == Some(BusState::Ready))
        })?;
        Ok(st)
    }

    /// Starts the monitor (again) from `exe` (the production `safety-monitor`, or the HIL
    /// variant whose NMT frames fail to send) with this scenario's command line.
    pub fn spawn_monitor(&mut self, exe: &'static str) -> Res<()> {
        let path = self.exe(exe);
        let args = self.mon_args.clone();
        self.procs
            .spawn("safety-monitor", &path, &args, &[("RUST_LOG", "info")])
            .map(|_| ())
            .map_err(|e| e.to_string())
    }

    /// The scenario injects its fault now: failures from here on are its verdict (never
    /// retried). Returns the injection time (CLOCK_MONOTONIC ns).
    pub fn inject(&mut self) -> u64 {
        self.injected = true;
        monotonic_ns()
    }

    /// Writes the emulator's control file from `self.control` (atomically; the emulator
    /// re-reads it every 5 ms).
    fn write_control(&self) -> Res<()> {
        crate::emulator::write_control(&self.dir, &self.control)
    }

    /// Makes cable `cable` (1-based) report `force_n` as its measured force (None: the
    /// emulator's stand-in again).
    pub fn set_force(&mut self, cable: usize, force_n: Option<f64>) -> Res<()> {
        let slot = self
            .control
            .forces
            .get_mut(cable.wrapping_sub(1))
            .ok_or_else(|| format!("cable {cable} out of range"))?;
        *slot = force_n;
        self.write_control()
    }

    /// The operator's e-stop button on the safety I/O node.
    pub fn set_estop(&mut self, pressed: bool) -> Res<()> {
        self.control.estop = pressed;
        self.write_control()
    }

    /// The operator turns the safety I/O node's reset key and releases it: waits (on the
    /// safety bus) until the node reported the key turned, then released, then for the
    /// monitor's answer; returns it (its `detail`: [`MonitorCode::ResetAccepted`], ...).
    pub fn turn_reset_key(&mut self) -> Res<StateEvent> {
        let mut spy = open_bus(self, "safety")?;
        let cob = 0x180 + u16::from(crate::configs::SAFETY_IO_NODE);
        let answers0 = self.reset_answers.len();
        for turned in [true, false] {
            self.control.reset_key = turned;
            self.write_control()?;
            self.wait(
                &format!(
                    "the safety I/O node reporting its reset key {}",
                    if turned { "turned" } else { "released" }
                ),
                10.0,
                |_| {
                    let mut seen = false;
                    while let Some(f) = spy.try_recv().map_err(|e| e.to_string())? {
                        let d = f.frame.data();
                        if f.frame.id() as u16 == cob && !d.is_empty() {
                            seen = (d[0] & 0x02 != 0) == turned;
                        }
                    }
                    Ok(seen)
                },
            )?;
        }
        self.wait("the monitor's answer to the reset key", 10.0, |s| {
            Ok(s.reset_answers.len() > answers0)
        })?;
        Ok(self.reset_answers[answers0])
    }

    pub fn bus_state(&self) -> Option<BusState> {
        self.last_feedback.and_then(|f| f.bus().ok())
    }

    pub fn poll(&mut self) -> Res<()> {
        while let Ok(Some(f)) = self.feedback.receive() {
            self.last_feedback = Some(f);
            self.feedback_count += 1;
        }
        while let Ok(Some(e)) = self.events.receive() {
            if e.source() == ProcessId::SafetyMonitor {
                if e.kind == EventKind::EStop as u32 {
                    self.monitor_estops.push(e);
                } else if e.kind == EventKind::Reset as u32 {
                    self.monitor_resets += 1;
                } else if e.monitor_code().is_some_and(MonitorCode::is_reset_answer) {
                    self.reset_answers.push(e);
                }
            }
        }
        while let Ok(Some(h)) = self.heartbeats.receive() {
            if h.source() == ProcessId::SafetyMonitor {
                self.monitor_state = h.monitor_state().ok();
                self.monitor_heartbeats += 1;
            } else if h.source() == ProcessId::MotionCore {
                self.motion_state = h.motion_state().ok();
            }
        }
        if let Some(e) = self.procs.exited() {
            return Err(format!("{} exited unexpectedly ({})", e.name, e.status));
        }
        Ok(())
    }

    /// Forget a process we killed on purpose (SIGKILL if it still runs, reaped).
    pub fn reap(&mut self, name: &str) {
        self.procs.kill(name);
    }

    pub fn wait(
        &mut self,
        what: &str,
        secs: f64,
        mut cond: impl FnMut(&mut Stack) -> Res<bool>,
    ) -> Res<f64> {
        let t0 = Instant::now();
        loop {
            self.poll()?;
            if cond(self)? {
                return Ok(t0.elapsed().as_secs_f64());
            }
            if t0.elapsed().as_secs_f64() > secs {
                return Err(format!("timed out after {secs} s waiting for {what}"));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    pub fn emu(&self) -> Res<EmuStatus> {
        let p = self.dir.join("emulator.status");
        for _ in 0..50 {
            if let Some(s) = std::fs::read_to_string(&p)
                .ok()
                .and_then(|t| parse_status(&t))
            {
                return Ok(s);
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        Err(format!("{}: no valid emulator status", p.display()))
    }

    pub fn fake(&mut self) -> Res<&Arc<FakeCtl>> {
        if self.fake.is_none() {
            self.fake = Some(Fake::start(
                &self.prefix,
                &self.cfg.join("platform.toml"),
                u64::from(self.period_us) * 1000,
            )?);
        }
        Ok(&self.fake.as_ref().ok_or("no fake publisher")?.ctl)
    }

    pub fn start_motion_core(&mut self) -> Res<()> {
        let c = self.cfg.join("motion-core.toml").display().to_string();
        self.spawn("motion-core", &["--config".into(), c])
    }

    /// The fake producer's non-finite poses end, and this waits until it has published
    /// `CLEAN_SETPOINTS_BEFORE_KEY` finite setpoints since: the monitor's reset needs its clear
    /// streak (`reset_clear_cycles`) of fault-free cycles, which an emulated guest's stalled
    /// producer may not have given it yet when the harness is fast (a key turned then is
    /// rightly refused with "the cause persists"). A condition, not a sleep.
    pub fn clear_non_finite(&mut self, c: &FakeCtl) -> Res<()> {
        c.nan.store(false, std::sync::atomic::Ordering::Relaxed);
        let p0 = c.published.load(std::sync::atomic::Ordering::Relaxed);
        self.wait("finite setpoints after the non-finite ones", 20.0, |_| {
            Ok(c.published.load(std::sync::atomic::Ordering::Relaxed)
                >= p0 + CLEAN_SETPOINTS_BEFORE_KEY)
        })?;
        // Published is not yet seen: a monitor the emulated guest stalled may not have run
        // the cycles its clear evidence needs over them.
        let h0 = self.monitor_heartbeats;
        self.wait(
            "the monitor's cycles over the finite setpoints",
            20.0,
            |s| Ok(s.monitor_heartbeats >= h0 + MONITOR_CYCLES_BEFORE_KEY),
        )?;
        Ok(())
    }

    /// A faulty node's frames, sent every `period` from `t0` on until the monitor trips (at
    /// most 10 s): a single frame lost by the emulated guest's bus must not decide a scenario;
    /// on the host the timing bound still holds the monitor to the first one. Returns how
    /// many were sent.
    pub fn send_until_trip(
        &mut self,
        t0: u64,
        period: Duration,
        what: &str,
        mut send: impl FnMut() -> Res<()>,
    ) -> Res<u32> {
        let mut sent = 0u32;
        while self.monitor_estops.is_empty() {
            if monotonic_ns() - t0 > 10_000_000_000 {
                return Err(format!(
                    "no trip in 10 s of {what} ({sent} sent, one per {} us)",
                    period.as_micros()
                ));
            }
            send()?;
            sent += 1;
            std::thread::sleep(period);
            self.poll()?;
        }
        Ok(sent)
    }

    /// drive-io Running and the drives following (some cable moved by > 1 mm).
    pub fn wait_following(&mut self, moving: bool) -> Res<()> {
        self.wait("drive-io Running", 30.0, |s| {
            Ok(s.bus_state() == Some(BusState::Running))
        })?;
        let e0 = self.emu()?;
        self.wait("the drives following", 20.0, |s| {
            let e = s.emu()?;
            let follow = e.drives.iter().all(|d| d.demand == DEMAND_FOLLOW);
            let moved = e
                .drives
                .iter()
                .zip(&e0.drives)
                .any(|(a, b)| (a.length_m - b.length_m).abs() > 1e-3);
            Ok(follow && (moved || !moving))
        })?;
        if !self.monitor_estops.is_empty() {
            return Err(format!(
                "the monitor tripped before the fault was injected: {:?}",
                self.monitor_estops
            ));
        }
        // The stack is up and following: what fails from here on is the scenario's verdict.
        self.injected = true;
        Ok(())
    }

    /// The stop the drives' own safety watch makes (no monitor, or an invalid pair): their
    /// watch trips, they brake, and drive-io's own watch trips too (its log says so) with
    /// drive-io latched. Returns the emulator's status after the stop (its
    /// `safety_tripped_ns`) and the time the drives stopped.
    ///
    /// drive-io's bus state is EStop (its watch first) or Fault (the drives' STO first: the
    /// safety I/O node judges the same validation time at each frame's arrival, drive-io at
    /// its cycle, so either may see the silence first; in the guest a stalled drive-io read
    /// the drives' "switch on disabled" statuswords before its own watch expired, and faulted
    /// with "drive ignores the target position"). Both are the latched stop a reset leaves.
    pub fn stopped_by_the_drives_watch(&mut self) -> Res<(EmuStatus, u64)> {
        self.wait("the drives' safety watch to trip", 10.0, |s| {
            Ok(s.emu()?.safety_trips > 0)
        })?;
        let stopped = self.require_braked()?;
        let e = self.emu()?;
        let log = self.dir.join("drive-io.log");
        self.wait(
            "drive-io latched (EStop or Fault) and its own watch tripped",
            10.0,
            |s| {
                let latched = matches!(s.bus_state(), Some(BusState::EStop | BusState::Fault));
                Ok(latched
                    && std::fs::read_to_string(&log)
                        .is_ok_and(|t| t.contains("safety heartbeat invalid or missing: e-stop")))
            },
        )?;
        Ok((e, stopped))
    }

    /// motion-core's state from a heartbeat newer than the monitor's next one (its stage
    /// publishes every few cycles, so an older one may still describe the state before).
    pub fn fresh_motion_state(&mut self) -> Res<Option<MotionState>> {
        let h0 = self.monitor_heartbeats;
        self.motion_state = None;
        self.wait("motion-core's heartbeat", 10.0, |s| {
            Ok(s.motion_state.is_some() && s.monitor_heartbeats > h0)
        })?;
        Ok(self.motion_state)
    }

    /// Waits for braked drives (none following, all at rest), then requires NO motion over
    /// 0.5 s. Returns the time the last drive stopped following (CLOCK_MONOTONIC ns).
    pub fn require_braked(&mut self) -> Res<u64> {
        // Braked: the brake holds (demand Hold: NMT stopped / not enabled; the axis is never
        // stepped) or the quick stop has decelerated to rest.
        self.wait("braked drives (none following, all at rest)", 10.0, |s| {
            let e = s.emu()?;
            Ok(e.drives.iter().all(|d| {
                d.demand == DEMAND_HOLD
                    || (d.demand == DEMAND_QUICK_STOP && d.velocity_m_per_s == 0.0)
            }))
        })?;
        let a = self.emu()?;
        std::thread::sleep(Duration::from_millis(500));
        self.poll()?;
        let b = self.emu()?;
        for (i, (x, y)) in a.drives.iter().zip(&b.drives).enumerate() {
            if (x.length_m - y.length_m).abs() > 1e-9 || y.demand == DEMAND_FOLLOW {
                return Err(format!(
                    "cable {} moved after the stop: {:.9} -> {:.9} m (demand {}, NMT {:#04x}, \
                     statusword {:#06x})",
                    i + 1,
                    x.length_m,
                    y.length_m,
                    y.demand,
                    y.nmt,
                    y.statusword
                ));
            }
        }
        Ok(b.drives.iter().map(|d| d.left_follow_ns).max().unwrap_or(0))
    }

    /// The monitor's e-stop with one of `causes`.
    pub fn monitor_trip_any(&mut self, causes: &[Cause], secs: f64) -> Res<StateEvent> {
        self.wait(&format!("the monitor's e-stop ({causes:?})"), secs, |s| {
            Ok(!s.monitor_estops.is_empty())
        })?;
        let e = self.monitor_estops[0];
        if !causes.iter().any(|c| e.trip_cause() == Ok(*c)) {
            return Err(format!(
                "monitor tripped with cause {:?} (cable {}), expected one of {causes:?}",
                Cause::from_code(e.detail),
                e.detail_node
            ));
        }
        Ok(e)
    }

    pub fn monitor_trip(&mut self, cause: Cause, secs: f64) -> Res<StateEvent> {
        self.wait(&format!("the monitor's e-stop ({cause})"), secs, |s| {
            Ok(!s.monitor_estops.is_empty())
        })?;
        let e = self.monitor_estops[0];
        if e.detail != u32::from(cause.code()) {
            return Err(format!(
                "monitor tripped with cause {:?} (cable {}), expected {cause}",
                Cause::from_code(e.detail),
                e.detail_node
            ));
        }
        Ok(e)
    }

    /// The operator's reset: the safety I/O node's key turned and released. True if accepted
    /// (or nothing to reset); the text names the answer (and a refusal's cause).
    pub fn operator_reset(&mut self) -> Res<(bool, String)> {
        let a = self.turn_reset_key()?;
        Ok(describe_answer(&a))
    }

    /// `safety-monitor reset --socket S` as a process of `uid`:`gid` (None: this harness's
    /// own) would run it; true if accepted (or nothing to reset), with its output.
    pub fn socket_reset(&mut self, as_user: Option<(u32, u32)>) -> Res<(bool, String)> {
        use std::os::unix::process::CommandExt;
        let mut cmd = Command::new(self.exe("safety-monitor"));
        cmd.args(["reset", "--timeout-ms", "5000", "--socket"])
            .arg(self.cfg.join("reset.sock"))
            .env("RUST_LOG", "warn");
        if let Some((uid, gid)) = as_user {
            // std drops the supplementary groups (setgroups(0)) when root sets a uid.
            cmd.uid(uid).gid(gid);
        }
        let out = cmd
            .output()
            .map_err(|e| format!("running safety-monitor reset: {e}"))?;
        let text = String::from_utf8_lossy(&out.stdout).trim().to_string();
        match out.status.code() {
            Some(0) => Ok((true, text)),
            Some(1) => Ok((false, text)),
            _ => Err(format!(
                "safety-monitor reset failed: {} {}",
                text,
                String::from_utf8_lossy(&out.stderr)
            )),
        }
    }

    pub fn log_tail(&self, lines: usize) -> String {
        let mut out = format!(
            "==== logs of scenario {} ({})\n",
            self.name,
            self.dir.display()
        );
        for name in [
            "safety-monitor",
            "drive-io",
            "winch-emulator",
            "motion-core",
        ] {
            let p = self.dir.join(format!("{name}.log"));
            if let Ok(t) = std::fs::read_to_string(&p) {
                let v: Vec<&str> = t.lines().collect();
                out.push_str(&format!("---- {name} (last {lines} lines)\n"));
                for l in &v[v.len().saturating_sub(lines)..] {
                    out.push_str(l);
                    out.push('\n');
                }
            }
        }
        out
    }
}

/// (accepted or nothing to reset, the answer in words) of a monitor's reset answer event.
pub fn describe_answer(a: &StateEvent) -> (bool, String) {
    match a.monitor_code() {
        Some(MonitorCode::ResetAccepted) => (true, "reset accepted".into()),
        Some(MonitorCode::ResetNotTripped) => (
            true,
            "reset not needed: nothing was latched, nothing changed".into(),
        ),
        Some(MonitorCode::ResetNotReady) => {
            (false, "reset REFUSED: the monitor is not ready".into())
        }
        Some(MonitorCode::ResetDenied) => (false, "reset DENIED: not an authorised channel".into()),
        Some(MonitorCode::ResetExhausted) => (false, "reset REFUSED: instance exhausted".into()),
        _ => (
            false,
            format!(
                "reset REFUSED: the cause persists ({})",
                Cause::from_code(a.detail_node).map_or("unknown".into(), |c| c.to_string())
            ),
        ),
    }
}

impl Drop for Stack {
    fn drop(&mut self) {
        if let Some(mut f) = self.fake.take() {
            let _ = f.stop();
        }
        // Every process killed outright (the scenario's verdict is in; the next one starts on
        // a quiet bus).
        self.procs.kill_all();
    }
}

/// A socket of the harness's own on the scenario's interface `iface` (`can0`…`can3`,
/// `safety`): injections, spying.
pub fn open_bus(st: &Stack, iface: &str) -> Res<Box<dyn can_transport::CanBus>> {
    let t = st
        .buses
        .transports("safety-hil")
        .into_iter()
        .find_map(|t| t.strip_prefix(&format!("{iface}=")).map(str::to_string))
        .ok_or_else(|| format!("no interface {iface:?} in the scenario's buses"))?;
    let spec: can_transport::TransportSpec = t.parse().map_err(|e| format!("{e}"))?;
    can_transport::open(&spec).map_err(|e| e.to_string())
}
