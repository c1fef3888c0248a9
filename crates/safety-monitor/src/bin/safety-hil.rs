//! `safety-hil`: the safety monitor's fault-injection matrix, every process separate, on a real
//! CAN bus (vcan in the QEMU guest of tools/safety-hil.sh; any transport on a host).
//!
//! Per scenario: `winch-emulator` (test double of the 8 drives, validating the safety heartbeat,
//! writing its true state to a status file), `safety-monitor`, `drive-io` (also validating the
//! heartbeat), then either `motion-core` or a fake setpoint publisher (this process) to inject
//! offsets, NaN poses, sequence gaps, a wrong platform identity. Each scenario injects one
//! fault and requires braked drives with NO motion afterwards (true lengths unchanged over
//! 0.5 s, velocities zero, no drive following), plus the expected monitor trip cause. The
//! measured detection and stop times are printed: inside the emulator they are NOT real time
//! (assert behaviour, never latency).
//!
//! The platform is a generated symmetric test cabin whose 8 cable lengths are equal at the home
//! pose, so the winch emulator (one initial length for all drives) starts exactly there.
//! Output: `SAFETY-HIL PASS|FAIL <scenario> ...` lines, a table, `SAFETY-HIL-RESULT PASS|FAIL`.

use clap::Parser;
use crs_ipc::{
    BusState, DriveFeedback, EventKind, Heartbeat, IpcNode, JointSetpoint, PlatformIdentity,
    ProcessId, StateEvent, monotonic_ns,
};
use safety_monitor::Cause;
use safety_monitor::identity::platform_identity;
use safety_monitor::kinematics::StandardKinematics;
use safety_monitor::platform::load_platform;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU32, AtomicU64, Ordering};
use std::time::{Duration, Instant};

#[derive(Parser)]
#[command(about = "Fault-injection matrix of the safety monitor (multi-process, on a CAN bus)")]
struct Args {
    /// Bus of every process (socketcan:vcan0 in the VM; udpbus:... on a host without CAN).
    #[arg(long, default_value = "socketcan:vcan0")]
    transport: String,
    /// Run only scenarios whose name contains this.
    #[arg(long)]
    only: Option<String>,
    /// Directory for generated configs, status files and logs.
    #[arg(long, default_value = "/tmp/safety-hil")]
    workdir: PathBuf,
    /// Directory of the binaries (default: found on PATH).
    #[arg(long)]
    bin_dir: Option<PathBuf>,
    /// Safety-heartbeat validation time of the drives and drive-io (ms). The emulated guest is
    /// not real time: lenient by default, the 50 ms of the spec is tested on the host.
    #[arg(long, default_value_t = 50)]
    validation_ms: u32,
    /// Monitor: cycles without a new setpoint before the e-stop (spec-like default 2).
    #[arg(long, default_value_t = 2)]
    silence_cycles: u32,
    /// Monitor: cycles without drive-io feedback, and without a drive's force reading, before
    /// the e-stop (default 4; also the reader stall limit where above its default 10).
    #[arg(long, default_value_t = 4)]
    feedback_silence_cycles: u32,
    /// Inside the emulated guest (as root): enlarge the default socket receive buffers so a
    /// process the emulator stalls for tens of ms does not lose CAN frames (a lost half of a
    /// safety pair stops the drives, correctly, but is an artefact of the emulator).
    #[arg(long)]
    guest_tuning: bool,
    /// SYNC period of drive-io and the period of motion-core / the fake publisher (µs). The
    /// spec's 1000 on a host; the script uses 4000 in the emulated guest, which cannot run
    /// five 1 kHz processes (assert behaviour there, not timing).
    #[arg(long, default_value_t = 1000)]
    period_us: u32,
    /// Instead of the scenarios: run the stack with a 1 kHz setpoint stream for this many
    /// seconds and report the monitor process's CPU share (getrusage via wait4 over its whole
    /// life, /proc/<pid>/stat over the window).
    #[arg(long)]
    cpu_share_s: Option<f64>,
}

type Res<T> = Result<T, String>;

/// Equal cable length of every cable at home: |(4.5, 4.5, 3.5)|.
fn home_length() -> f64 {
    (4.5f64 * 4.5 + 4.5 * 4.5 + 3.5 * 3.5).sqrt()
}
const HOME: [f64; 6] = [0.0, 0.0, 2.0, 0.0, 0.0, 0.0];

fn write_configs(dir: &Path, args: &Args) -> Res<()> {
    let (transport, validation_ms) = (args.transport.as_str(), args.validation_ms);
    let period_us = args.period_us;
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut a = String::new();
    let mut b = String::new();
    for sx in [1.0, -1.0] {
        for sy in [1.0, -1.0] {
            for sz in [1.0, -1.0] {
                a.push_str(&format!(
                    "  [{:.1}, {:.1}, {:.1}],\n",
                    5.0 * sx,
                    5.0 * sy,
                    2.0 + 4.0 * sz
                ));
                b.push_str(&format!(
                    "  [{:.1}, {:.1}, {:.1}],\n",
                    0.5 * sx,
                    0.5 * sy,
                    0.5 * sz
                ));
            }
        }
    }
    let platform = format!(
        "# Generated by safety-hil: symmetric test cabin, all cable lengths equal at home.\n\
         [platform]\nname = \"hil-cube\"\ndescription = \"safety HIL test cabin\"\n\
         [geometry]\nframe_anchors_m = [\n{a}]\nplatform_anchors_m = [\n{b}]\n\
         [elasticity]\nk_f_n = 2.0e6\n[load]\nwrench_n_nm = [0.0, 0.0, -5500.0, 0.0, 0.0, 0.0]\n\
         [forces]\nf_min_n = 1000.0\nf_max_n = 9000.0\nf_abs_max_n = 14000.0\n\
         [limits]\nlinear_velocity_max_m_per_s = 5.0\nangular_velocity_max_deg_per_s = 100.0\n\
         linear_acceleration_max_m_per_s2 = 14.0\nangular_acceleration_max_deg_per_s2 = 100.0\n\
         [winch]\ndrum_diameter_m = 0.305\nrope_diameter_m = 0.014\n\
         [workspace]\nposition_min_m = [-1.5, -1.5, 1.25]\nposition_max_m = [1.5, 1.5, 2.75]\n\
         rotation_min_deg = [-5.0, -5.0, -5.0]\nrotation_max_deg = [5.0, 5.0, 5.0]\n\
         [home]\nposition_m = [0.0, 0.0, 2.0]\nrotation_deg = [0.0, 0.0, 0.0]\n"
    );
    let mut drives = format!(
        "# Generated by safety-hil: lenient timeouts (the emulated guest is not real time).\n\
         [bus]\ntransport = \"{transport}\"\nsync_period_us = {period_us}\nstale_setpoint_cycles = 100\n\
         heartbeat_producer_ms = 20\nheartbeat_timeout_ms = 300\nboot_timeout_ms = 20000\n\
         sdo_timeout_ms = 500\nmax_cable_speed_m_per_s = 5.0\n\
         [safety_heartbeat]\ncob_id = 0x101\nvalidation_time_ms = {validation_ms}\n\
         pair_window_ms = {}\nrelease_pairs = 3\n",
        (validation_ms / 2).max(1)
    );
    for i in 0..8 {
        let sign = if i % 2 == 0 { 1 } else { -1 };
        drives.push_str(&format!(
            "[[winch]]\nnode_id = {}\ndrum_diameter_m = 0.305\ngear_ratio = 10.0\n\
             counts_per_rev = 1048576\nsign = {sign}\noffset_counts = {}\nmax_cable_length_m = 20.0\n",
            i + 1,
            if sign > 0 { 0 } else { 200_000_000 }
        ));
    }
    let monitor = format!(
        "# Generated by safety-hil (spec values except where the emulated guest needs slack).\n\
         [monitor]\nplatform = \"platform.toml\"\ncycle_ms = 15\ndq_limit_mm = 100.0\n\
         silence_cycles = {}\nmax_missing_setpoints = 5\ngap_window_cycles = 67\n\
         identity_grace_cycles = 20\nreset_clear_cycles = 3\ntrip_log = \"trips.log\"\n\
         rt_priority = 50\n\
         [feedback]\nfollowing_error_mm = 100.0\nwindow_setpoints = 200\nsilence_cycles = {}\n\
         [can]\ntransport = \"{transport}\"\ndrives = \"drives.toml\"\nsafety_cob_id = 0x101\n\
         check_rpdo = true\nreset_wait_ms = 2000\nreader_stall_cycles = {}\n\
         safety_validation_time_ms = {validation_ms}\nsafety_pair_window_ms = {}\n\
         [motion]\nsetpoint_period_ms = {}\n\
         [forces]\nsilence_cycles = {}\n",
        args.silence_cycles,
        args.feedback_silence_cycles,
        // Stall-related like the feedback silence: the guest stalls processes for tens of ms.
        args.feedback_silence_cycles.max(10),
        (validation_ms / 2).max(1),
        f64::from(period_us) * 1e-3,
        args.feedback_silence_cycles
    );
    // The harness accepts its own generated platform (the operator's `safety-monitor accept`).
    let monitor = monitor.replace(
        "platform = \"platform.toml\"\n",
        &format!(
            "platform = \"platform.toml\"\nplatform_sha256 = \"{}\"\n",
            safety_monitor::identity::hex(&safety_monitor::config::sha256_of(platform.as_bytes()))
        ),
    );
    let motion = format!(
        "# Generated by safety-hil.\n[daemon]\nplatform = \"platform.toml\"\n\
         check_wrench_feasibility = false\nstats_interval_s = 0.0\n\
         [realtime]\nperiod_us = {period_us}\npriority = 0\ncpu = -1\nlock_memory = false\n\
         [trajectory]\nvelocity_scale = 0.05\nacceleration_scale = 0.05\n\
         linear_jerk_max_m_per_s3 = 5.0\nangular_jerk_max_deg_per_s3 = 50.0\n\
         waypoints = \"waypoints.csv\"\n"
    );
    let waypoints = "t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg\n\
         0.0,0.2,0.0,2.0,0.0,0.0,0.0\n0.0,-0.2,0.1,2.1,0.0,0.0,1.0\n\
         0.0,0.2,-0.1,1.9,1.0,0.0,0.0\n0.0,-0.2,0.0,2.0,0.0,0.0,0.0\n0.0,0.0,0.0,2.0,0.0,0.0,0.0\n";
    // Stream owners (issue 16): this harness's fake motion core publishes setpoints and the
    // identity in most scenarios, and its replacement adapter publishes drive feedback in
    // `unknown_applied_sequence`; `foreign_publisher` runs the strict (shipped) owners.
    let strict = format!(
        "{monitor}[ipc]\nsetpoint_owners = [\"motion-core\"]\nfeedback_owners = [\"drive-io\"]\n\
         identity_owners = [\"motion-core\"]\n"
    );
    let monitor = format!(
        "{monitor}[ipc]\nsetpoint_owners = [\"motion-core\", \"safety-hil\"]\n\
         feedback_owners = [\"drive-io\", \"safety-hil\"]\n\
         identity_owners = [\"motion-core\", \"safety-hil\"]\n"
    );
    // The drives (winch emulator) of `heartbeat_config_crc_mismatch`: one SRDO parameter (their
    // validation time) differs from what the monitor announces.
    let drives_mismatch = drives.replace(
        &format!("validation_time_ms = {validation_ms}\n"),
        &format!("validation_time_ms = {}\n", validation_ms + 10),
    );
    if drives_mismatch == drives {
        return Err("drives-crc-mismatch.toml: could not change validation_time_ms".into());
    }
    for (name, text) in [
        ("platform.toml", platform.as_str()),
        ("drives.toml", drives.as_str()),
        ("drives-crc-mismatch.toml", drives_mismatch.as_str()),
        ("safety-monitor.toml", monitor.as_str()),
        ("safety-monitor-strict.toml", strict.as_str()),
        ("motion-core.toml", motion.as_str()),
        ("waypoints.csv", waypoints),
    ] {
        let p = dir.join(name);
        std::fs::write(&p, text).map_err(|e| format!("{}: {e}", p.display()))?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Fake motion core: setpoints at 1 kHz with injectable faults.

#[derive(Default)]
struct FakeCtl {
    stop: AtomicBool,
    /// Stop publishing (frozen) while set.
    paused: AtomicBool,
    /// Offset target on cable `cable` in µm; the offset ramps towards it at 0.1 m/s.
    offset_target_um: AtomicI64,
    cable: AtomicU32,
    /// Publish NaN poses while set.
    nan: AtomicBool,
    /// Skip one sequence number every this many setpoints (0 = none).
    skip_every: AtomicU32,
    /// Announce a wrong platform identity while set.
    wrong_identity: AtomicBool,
    /// Publish the pose moved this far in x (µm) with CONSISTENT cable lengths, at once.
    pose_jump_um: AtomicI64,
    /// Add this (µm) to cable `cable` at once (no ramp) ...
    step_um: AtomicI64,
    /// ... and claim this much more time (ns) per setpoint in the timestamps from then on.
    timestamp_lie_ns: AtomicU64,
    /// First time the published |offset| exceeded 100 mm (CLOCK_MONOTONIC ns; 0 = never).
    crossed_ns: AtomicU64,
    /// Current offset (µm) and setpoints published.
    offset_um: AtomicI64,
    published: AtomicU64,
}

struct Fake {
    ctl: Arc<FakeCtl>,
    handle: Option<std::thread::JoinHandle<Res<()>>>,
}

impl Fake {
    fn start(prefix: &str, platform: &Path, period_ns: u64) -> Res<Fake> {
        let ctl = Arc::new(FakeCtl::default());
        let p = load_platform(platform).map_err(|e| e.to_string())?;
        let (c, prefix) = (ctl.clone(), prefix.to_string());
        let handle = std::thread::spawn(move || -> Res<()> {
            let node = IpcNode::with_prefix("shil-fake-motion-core", &prefix)
                .map_err(|e| e.to_string())?;
            let sp_pub = node
                .publisher::<JointSetpoint>()
                .map_err(|e| e.to_string())?;
            let id_pub = node
                .publisher::<PlatformIdentity>()
                .map_err(|e| e.to_string())?;
            let id = platform_identity(&p);
            let kin = StandardKinematics::new(&p);
            let mut q = [0.0; crs_ipc::MAX_CABLES];
            kin.lengths(&HOME, &mut q);
            let mut seq = 0u64;
            let mut lie_total = 0u64;
            let mut offset_um = 0i64;
            let mut next = monotonic_ns();
            let mut n = 0u64;
            while !c.stop.load(Ordering::Relaxed) {
                next += period_ns;
                crs_rt::sleep_until(next);
                let now = monotonic_ns();
                if now > next + 50_000_000 {
                    next = now; // the guest stalled: no burst
                }
                if c.paused.load(Ordering::Relaxed) {
                    continue;
                }
                if n.is_multiple_of(100) {
                    let mut h = *id.as_bytes();
                    if c.wrong_identity.load(Ordering::Relaxed) {
                        h[31] ^= 0x5A;
                    }
                    let _ = id_pub.publish(&PlatformIdentity::new(crs_ipc::PlatformId::new(h), 8));
                }
                n += 1;
                let target = c.offset_target_um.load(Ordering::Relaxed);
                // 0.1 m/s: 100 µm per ms.
                let step = (period_ns / 10_000) as i64;
                offset_um += (target - offset_um).clamp(-step, step);
                seq += 1;
                let skip = c.skip_every.load(Ordering::Relaxed);
                if skip > 0 && seq.is_multiple_of(u64::from(skip)) {
                    seq += 1;
                }
                lie_total += c.timestamp_lie_ns.load(Ordering::Relaxed);
                let mut s = JointSetpoint {
                    cable_count: 8,
                    sequence: seq,
                    timestamp_ns: now + lie_total,
                    pose: HOME,
                    cable_length_m: q,
                    ..JointSetpoint::default()
                };
                let jump = c.pose_jump_um.load(Ordering::Relaxed);
                if jump != 0 {
                    s.pose[0] += jump as f64 * 1e-6;
                    kin.lengths(&s.pose, &mut s.cable_length_m);
                }
                let cable = (c.cable.load(Ordering::Relaxed) as usize).min(7);
                s.cable_length_m[cable] +=
                    (offset_um + c.step_um.load(Ordering::Relaxed)) as f64 * 1e-6;
                if c.nan.load(Ordering::Relaxed) {
                    s.pose[3] = f64::NAN;
                }
                // The spec's 100 mm (the harness's monitor runs with dq_limit_mm = 100).
                let limit_um = (safety_monitor::config::DELTA_Q_LIMIT_M * 1e6).round() as i64;
                if offset_um.abs() > limit_um && c.crossed_ns.load(Ordering::Relaxed) == 0 {
                    c.crossed_ns.store(now, Ordering::Relaxed);
                }
                sp_pub.publish(&s).map_err(|e| e.to_string())?;
                c.offset_um.store(offset_um, Ordering::Relaxed);
                c.published.fetch_add(1, Ordering::Relaxed);
            }
            Ok(())
        });
        Ok(Fake {
            ctl,
            handle: Some(handle),
        })
    }

    fn stop(&mut self) -> Res<()> {
        self.ctl.stop.store(true, Ordering::Relaxed);
        match self.handle.take() {
            Some(h) => h
                .join()
                .map_err(|_| "fake publisher panicked".to_string())?,
            None => Ok(()),
        }
    }
}

impl Drop for Fake {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}

// ---------------------------------------------------------------------------------------------
// The process stack of one scenario.

#[derive(Debug, Clone, Copy, Default)]
struct DriveStatus {
    length_m: f64,
    velocity_m_per_s: f64,
    nmt: u8,
    statusword: u16,
    demand: u8,
    left_follow_ns: u64,
}

#[derive(Debug, Clone, Default)]
struct EmuStatus {
    time_ns: u64,
    syncs: u64,
    inhibit: bool,
    safety_trips: u64,
    safety_tripped_ns: u64,
    drives: Vec<DriveStatus>,
}

fn parse_status(text: &str) -> Option<EmuStatus> {
    let mut s = EmuStatus::default();
    let mut header = false;
    for line in text.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.first() {
            Some(&"emulator") if f.len() == 6 => {
                s.time_ns = f[1].parse().ok()?;
                s.syncs = f[2].parse().ok()?;
                s.inhibit = f[3] == "1";
                s.safety_trips = f[4].parse().ok()?;
                s.safety_tripped_ns = f[5].parse().ok()?;
                header = true;
            }
            Some(&"drive") if f.len() == 8 => s.drives.push(DriveStatus {
                length_m: f[2].parse().ok()?,
                velocity_m_per_s: f[3].parse().ok()?,
                nmt: f[4].parse().ok()?,
                statusword: f[5].parse().ok()?,
                demand: f[6].parse().ok()?,
                left_follow_ns: f[7].parse().ok()?,
            }),
            _ => {}
        }
    }
    (header && s.drives.len() == 8).then_some(s)
}

const DEMAND_HOLD: u8 = 0;
const DEMAND_QUICK_STOP: u8 = 1;
const DEMAND_FOLLOW: u8 = 2;

struct Stack {
    name: &'static str,
    dir: PathBuf,
    cfg: PathBuf,
    bin_dir: Option<PathBuf>,
    transport: String,
    period_us: u32,
    prefix: String,
    procs: BTreeMap<&'static str, Child>,
    _node: IpcNode,
    feedback: crs_ipc::TopicSubscriber<DriveFeedback>,
    events: crs_ipc::TopicSubscriber<StateEvent>,
    heartbeats: crs_ipc::TopicSubscriber<Heartbeat>,
    last_feedback: Option<DriveFeedback>,
    /// Monitor e-stop events (kind EStop from the monitor).
    monitor_estops: Vec<StateEvent>,
    monitor_resets: u32,
    monitor_state: Option<u32>,
    /// Monitor heartbeats (one per monitor cycle) and drive-io feedback samples (one per SYNC
    /// cycle) received: scenarios pace their observations by these, never by sleeps.
    monitor_heartbeats: u64,
    feedback_count: u64,
    /// motion-core's loop state (its heartbeat), if it runs.
    motion_state: Option<u32>,
    fake: Option<Fake>,
}

impl Stack {
    fn exe(&self, name: &str) -> PathBuf {
        match &self.bin_dir {
            Some(d) => d.join(name),
            None => PathBuf::from(name),
        }
    }

    fn spawn(&mut self, name: &'static str, args: &[String]) -> Res<()> {
        let log = self.dir.join(format!("{name}.log"));
        let f = std::fs::File::create(&log).map_err(|e| format!("{}: {e}", log.display()))?;
        let f2 = f.try_clone().map_err(|e| e.to_string())?;
        let child = Command::new(self.exe(name))
            .args(args)
            .env("CRS_IPC_PREFIX", &self.prefix)
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(f)
            .stderr(f2)
            .spawn()
            .map_err(|e| format!("starting {name}: {e}"))?;
        self.procs.insert(name, child);
        Ok(())
    }

    fn pid(&self, name: &str) -> Res<i32> {
        self.procs
            .get(name)
            .map(|c| c.id() as i32)
            .ok_or_else(|| format!("{name} not running"))
    }

    fn signal_pid(&self, pid: i32, sig: i32) -> Res<()> {
        // SAFETY: kill(2) on our own child's pid.
        if unsafe { libc::kill(pid, sig) } != 0 {
            return Err(format!("kill({pid}, {sig}) failed"));
        }
        Ok(())
    }

    fn signal(&self, name: &str, sig: i32) -> Res<()> {
        // SAFETY: kill(2) on our own child's pid.
        if unsafe { libc::kill(self.pid(name)?, sig) } != 0 {
            return Err(format!("kill({name}, {sig}) failed"));
        }
        Ok(())
    }

    fn start(
        name: &'static str,
        dir: &Path,
        bin_dir: Option<PathBuf>,
        transport: &str,
        period_us: u32,
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
        let prefix = format!("shil-{name}-{}/", std::process::id());
        let node = IpcNode::with_prefix("safety-hil", &prefix).map_err(|e| e.to_string())?;
        let mut st = Stack {
            name,
            dir: sdir,
            cfg: dir.to_path_buf(),
            bin_dir,
            transport: transport.to_string(),
            period_us,
            prefix,
            procs: BTreeMap::new(),
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
            fake: None,
        };
        let cfg_dir = st.cfg.clone();
        let c = |f: &str| cfg_dir.join(f).display().to_string();
        let status = st.dir.join("emulator.status").display().to_string();
        let emu_args = vec![
            "--config".into(),
            c(integrity::emulator_drives(name)),
            "--transport".into(),
            st.transport.clone(),
            "--initial-length-m".into(),
            format!("{}", home_length()),
            "--status-file".into(),
            status,
            "--control-file".into(),
            st.dir.join("emulator.control").display().to_string(),
        ];
        st.spawn("winch-emulator", &emu_args)?;
        let mon_args: Vec<String> = vec![
            "--config".into(),
            c(integrity::monitor_config(name)),
            "--transport".into(),
            st.transport.clone(),
            "--ipc-prefix".into(),
            st.prefix.clone(),
        ]
        .into_iter()
        .chain(monitor_fault_injection(name).iter().map(|a| a.to_string()))
        .collect();
        st.spawn("safety-monitor", &mon_args)?;
        // The monitor starts not ready (STOP) until every drive is operational and sends forces
        // (after drive-io's NMT start): the drives release only after its RUN pairs, then
        // drive-io can enable them.
        st.wait("the monitor's heartbeat", 20.0, |s| {
            Ok(s.monitor_state.is_some())
        })?;
        let dio_args = vec![
            "--config".into(),
            c("drives.toml"),
            "--transport".into(),
            st.transport.clone(),
            "--ipc-prefix".into(),
            st.prefix.clone(),
        ];
        st.spawn("drive-io", &dio_args)?;
        if integrity::drives_never_ready(name) {
            return Ok(st);
        }
        st.wait("drive-io Ready (boot, SDO, CiA 402 enable)", 40.0, |s| {
            Ok(s.bus_state() == Some(BusState::Ready))
        })?;
        Ok(st)
    }

    fn bus_state(&self) -> Option<BusState> {
        self.last_feedback
            .and_then(|f| BusState::from_u32(f.bus_state))
    }

    fn poll(&mut self) -> Res<()> {
        while let Ok(Some(f)) = self.feedback.receive() {
            self.last_feedback = Some(f);
            self.feedback_count += 1;
        }
        while let Ok(Some(e)) = self.events.receive() {
            if e.source == ProcessId::SafetyMonitor as u32 {
                if e.kind == EventKind::EStop as u32 {
                    self.monitor_estops.push(e);
                } else if e.kind == EventKind::Reset as u32 {
                    self.monitor_resets += 1;
                }
            }
        }
        while let Ok(Some(h)) = self.heartbeats.receive() {
            if h.source == ProcessId::SafetyMonitor as u32 {
                self.monitor_state = Some(h.state);
                self.monitor_heartbeats += 1;
            } else if h.source == ProcessId::MotionCore as u32 {
                self.motion_state = Some(h.state);
            }
        }
        for (name, c) in &mut self.procs {
            if let Ok(Some(st)) = c.try_wait() {
                return Err(format!("{name} exited unexpectedly ({st})"));
            }
        }
        Ok(())
    }

    /// Forget a process we killed on purpose.
    fn reap(&mut self, name: &str) {
        if let Some(mut c) = self.procs.remove(name) {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    fn wait(
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

    fn emu(&self) -> Res<EmuStatus> {
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

    fn fake(&mut self) -> Res<&Arc<FakeCtl>> {
        if self.fake.is_none() {
            self.fake = Some(Fake::start(
                &self.prefix,
                &self.cfg.join("platform.toml"),
                u64::from(self.period_us) * 1000,
            )?);
        }
        Ok(&self.fake.as_ref().ok_or("no fake publisher")?.ctl)
    }

    fn start_motion_core(&mut self) -> Res<()> {
        let c = self.cfg.join("motion-core.toml").display().to_string();
        self.spawn("motion-core", &["--config".into(), c])
    }

    /// drive-io Running and the drives following (some cable moved by > 1 mm).
    fn wait_following(&mut self, moving: bool) -> Res<()> {
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
        Ok(())
    }

    /// Waits for braked drives (none following, all at rest), then requires NO motion over
    /// 0.5 s. Returns the time the last drive stopped following (CLOCK_MONOTONIC ns).
    fn require_braked(&mut self) -> Res<u64> {
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
    fn monitor_trip_any(&mut self, causes: &[Cause], secs: f64) -> Res<StateEvent> {
        self.wait(&format!("the monitor's e-stop ({causes:?})"), secs, |s| {
            Ok(!s.monitor_estops.is_empty())
        })?;
        let e = self.monitor_estops[0];
        if !causes.iter().any(|c| e.detail == u32::from(c.code())) {
            return Err(format!(
                "monitor tripped with cause {:?} (cable {}), expected one of {causes:?}",
                Cause::from_code(e.detail),
                e.detail_node
            ));
        }
        Ok(e)
    }

    fn monitor_trip(&mut self, cause: Cause, secs: f64) -> Res<StateEvent> {
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

    /// `safety-monitor reset` as the operator would run it; true if accepted.
    fn operator_reset(&mut self) -> Res<(bool, String)> {
        let out = Command::new(self.exe("safety-monitor"))
            .args([
                "reset",
                "--ipc-prefix",
                &self.prefix,
                "--timeout-ms",
                "5000",
            ])
            .env("RUST_LOG", "warn")
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

    fn log_tail(&self, lines: usize) -> String {
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

impl Drop for Stack {
    fn drop(&mut self) {
        if let Some(mut f) = self.fake.take() {
            let _ = f.stop();
        }
        for (_, c) in self.procs.iter_mut() {
            let _ = c.kill();
        }
        for (_, c) in self.procs.iter_mut() {
            let _ = c.wait();
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Scenarios.

/// What a scenario measured (ms; None if not applicable).
#[derive(Debug, Default, Clone)]
struct Outcome {
    cause: String,
    detect_ms: Option<f64>,
    stop_ms: Option<f64>,
    note: String,
}

fn ms(from_ns: u64, to_ns: u64) -> Option<f64> {
    (from_ns > 0 && to_ns >= from_ns).then(|| (to_ns - from_ns) as f64 * 1e-6)
}

fn offset_101mm(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    c.cable.store(2, Ordering::Relaxed);
    st.wait_following(false)?;
    c.offset_target_um.store(101_000, Ordering::Relaxed);
    let ev = st.monitor_trip(Cause::DqLimit, 10.0)?;
    if ev.detail_node != 3 {
        return Err(format!("tripped on cable {}, expected 3", ev.detail_node));
    }
    let t_cross = c.crossed_ns.load(Ordering::Relaxed);
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "dq_limit cable 3".into(),
        detect_ms: ms(t_cross, ev.timestamp_ns),
        stop_ms: ms(t_cross, stopped),
        note: "ramp 0.1 m/s; t0 = first setpoint > 100 mm".into(),
    })
}

fn offset_99mm(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    c.cable.store(5, Ordering::Relaxed);
    st.wait_following(false)?;
    c.offset_target_um.store(99_000, Ordering::Relaxed);
    st.wait("the 99 mm offset reached", 10.0, |_| {
        Ok(c.offset_um.load(Ordering::Relaxed) == 99_000)
    })?;
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(1500) {
        st.poll()?;
        std::thread::sleep(Duration::from_millis(5));
    }
    if !st.monitor_estops.is_empty() || st.monitor_state != Some(1) {
        return Err(format!(
            "99 mm tripped the monitor: {:?}",
            st.monitor_estops
        ));
    }
    let e = st.emu()?;
    let moved = (e.drives[5].length_m - home_length()).abs();
    if e.drives.iter().any(|d| d.demand != DEMAND_FOLLOW) || moved < 0.098 {
        return Err(format!(
            "the drives should follow the 99 mm offset (cable 6 moved {moved:.4} m)"
        ));
    }
    // End of the scenario: the publisher stops => silence trip => braked.
    c.paused.store(true, Ordering::Relaxed);
    let t_pause = monotonic_ns();
    let ev = st.monitor_trip(Cause::SetpointSilence, 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "none at 99 mm (1.5 s held, cable 6 followed); then setpoint_silence".into(),
        detect_ms: ms(t_pause, ev.timestamp_ns),
        stop_ms: ms(t_pause, stopped),
        note: "times: from the publisher's stop".into(),
    })
}

fn motion_core_fault(st: &mut Stack, sig: i32) -> Res<Outcome> {
    st.start_motion_core()?;
    st.wait_following(true)?;
    // Let it run a little.
    std::thread::sleep(Duration::from_millis(300));
    st.poll()?;
    let t0 = monotonic_ns();
    st.signal("motion-core", sig)?;
    if sig == libc::SIGKILL {
        st.reap("motion-core");
    }
    let ev = st.monitor_trip(Cause::SetpointSilence, 10.0)?;
    let stopped = st.require_braked()?;
    if sig == libc::SIGSTOP {
        // Thawing the loop does not restart motion: the latch holds.
        st.signal("motion-core", libc::SIGCONT)?;
        std::thread::sleep(Duration::from_millis(300));
        st.require_braked()?;
    }
    Ok(Outcome {
        cause: "setpoint_silence".into(),
        detect_ms: ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: if sig == libc::SIGSTOP {
            "SIGSTOP; after SIGCONT still braked".into()
        } else {
            "SIGKILL".into()
        },
    })
}

fn frozen_motion_core(st: &mut Stack) -> Res<Outcome> {
    motion_core_fault(st, libc::SIGSTOP)
}

fn kill_motion_core(st: &mut Stack) -> Res<Outcome> {
    motion_core_fault(st, libc::SIGKILL)
}

fn kill_drive_io(st: &mut Stack) -> Res<Outcome> {
    st.start_motion_core()?;
    st.wait_following(true)?;
    let t0 = monotonic_ns();
    st.signal("drive-io", libc::SIGKILL)?;
    st.reap("drive-io");
    // Two independent detections race: drive-io's feedback topic goes silent, and without its
    // SYNC the drives stop sending TPDO2, so the force readings go silent too. Whichever of
    // the two silence limits is shorter trips first (on the host both are 4 cycles and the
    // feedback check runs first; the guest's feedback limit is 20).
    let ev = st.monitor_trip_any(&[Cause::FeedbackSilence, Cause::ForceSilence], 10.0)?;
    let stopped = st.require_braked()?;
    let e = st.emu()?;
    if e.drives.iter().any(|d| d.nmt != 4) {
        return Err("the drives should be NMT-stopped by the monitor".into());
    }
    Ok(Outcome {
        cause: Cause::from_code(ev.detail).map_or("?".into(), |c| c.to_string()),
        detect_ms: ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: "drives NMT-stopped by the monitor's own socket".into(),
    })
}

fn kill_monitor(st: &mut Stack) -> Res<Outcome> {
    st.start_motion_core()?;
    st.wait_following(true)?;
    let t0 = monotonic_ns();
    st.signal("safety-monitor", libc::SIGKILL)?;
    st.reap("safety-monitor");
    st.wait("the drives' safety watch to trip", 10.0, |s| {
        Ok(s.emu()?.safety_trips > 0)
    })?;
    let stopped = st.require_braked()?;
    let e = st.emu()?;
    st.wait("drive-io e-stopped by its own watch", 10.0, |s| {
        Ok(s.bus_state() == Some(BusState::EStop))
    })?;
    Ok(Outcome {
        cause: "drives: safety heartbeat timeout".into(),
        detect_ms: ms(t0, e.safety_tripped_ns),
        stop_ms: ms(t0, stopped),
        note: "no monitor: drives + drive-io brake by themselves".into(),
    })
}

/// One fault switched on in the fake publisher while the drives follow; the monitor must trip
/// with `cause` and the drives brake.
fn publisher_fault(
    st: &mut Stack,
    inject: impl FnOnce(&FakeCtl),
    cause: Cause,
    name: &str,
    note: &str,
) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let t0 = monotonic_ns();
    inject(&c);
    let ev = st.monitor_trip(cause, 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: name.into(),
        detect_ms: ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: note.into(),
    })
}

fn sequence_gaps(st: &mut Stack) -> Res<Outcome> {
    publisher_fault(
        st,
        |c| c.skip_every.store(4, Ordering::Relaxed),
        Cause::SequenceGaps,
        "sequence_gaps",
        "every 4th sequence number skipped; > 5 lost within 67 cycles",
    )
}

fn nan_pose(st: &mut Stack) -> Res<Outcome> {
    publisher_fault(
        st,
        |c| c.nan.store(true, Ordering::Relaxed),
        Cause::NonFinite,
        "non_finite",
        "NaN in φ_x, cable lengths valid (drive-io would forward them)",
    )
}

fn identity_mismatch(st: &mut Stack) -> Res<Outcome> {
    publisher_fault(
        st,
        |c| c.wrong_identity.store(true, Ordering::Relaxed),
        Cause::IdentityMismatch,
        "identity_mismatch",
        "re-announced identity with one byte changed",
    )
}

fn open_bus(st: &Stack) -> Res<Box<dyn can_transport::CanBus>> {
    let spec: can_transport::TransportSpec = st.transport.parse().map_err(|e| format!("{e}"))?;
    can_transport::open(&spec).map_err(|e| e.to_string())
}

fn corrupted_safety_frame(st: &mut Stack) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let mut bus = open_bus(st)?;
    use can_transport::safety_frame::{SafetyHeartbeat, SafetyState, encode};
    let [a, b] = encode(
        &SafetyHeartbeat {
            state: SafetyState::Run,
            cause: 0,
            counter: 0x1234,
            epoch: 0,
        },
        0x101,
    );
    let mut d = [0u8; 8];
    d.copy_from_slice(b.data());
    d[4] ^= 0x08; // one bit of the inverted copy flipped
    let b = can_transport::CanFrame::new(0x102, &d).map_err(|e| e.to_string())?;
    let t0 = monotonic_ns();
    bus.send(&a).map_err(|e| e.to_string())?;
    bus.send(&b).map_err(|e| e.to_string())?;
    st.wait("the drives' safety watch to trip", 10.0, |s| {
        Ok(s.emu()?.safety_trips > 0)
    })?;
    let stopped = st.require_braked()?;
    let e = st.emu()?;
    st.wait("drive-io e-stopped by its own watch", 10.0, |s| {
        Ok(s.bus_state() == Some(BusState::EStop))
    })?;
    Ok(Outcome {
        cause: "drives: invalid pair (inverse mismatch)".into(),
        detect_ms: ms(t0, e.safety_tripped_ns),
        stop_ms: ms(t0, stopped),
        note: "one injected pair with 1 bit flipped".into(),
    })
}

fn forged_rpdo(st: &mut Stack) -> Res<Outcome> {
    forged_rpdo_with(st, 0x000F)
}

/// Bits 4–6 and 8–15 of the controlword are mode/manufacturer bits: the drive still enables
/// operation and follows the target, so the monitor must check this RPDO too.
fn forged_rpdo_other_enabling_controlword(st: &mut Stack) -> Res<Outcome> {
    forged_rpdo_with(st, 0x001F)
}

fn forged_rpdo_with(st: &mut Stack, controlword: u16) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let mut bus = open_bus(st)?;
    // A faulty drive adapter: RPDO1 to node 4 (sign -1, offset 200e6) 300 mm off.
    let counts_per_m = 10.0 * 1_048_576.0 / (std::f64::consts::PI * 0.305);
    let target = 200_000_000.0 - (home_length() + 0.3) * counts_per_m;
    let f = safety_monitor::bus_frames::rpdo1(4, controlword, target.round() as i32);
    let t0 = monotonic_ns();
    bus.send(&f).map_err(|e| e.to_string())?;
    let ev = st.monitor_trip(Cause::RpdoMismatch, 10.0)?;
    if ev.detail_node != 4 {
        return Err(format!("tripped on cable {}, expected 4", ev.detail_node));
    }
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "rpdo_mismatch cable 4".into(),
        detect_ms: ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!("forged RPDO1 (controlword {controlword:#06x}) 300 mm off φ*(x)"),
    })
}

/// The pose jumps 200 mm inside the workspace box with cable lengths that agree with it: Δq
/// stays 0, only the monitor's motion plausibility can see it.
fn pose_jump_inside_box(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let t0 = monotonic_ns();
    c.pose_jump_um.store(200_000, Ordering::Relaxed);
    let ev = st.monitor_trip(Cause::MotionVelocity, 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "motion_velocity".into(),
        detect_ms: ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: "consistent pose + lengths jump 200 mm in one period".into(),
    })
}

/// A 90 mm step on one cable in one setpoint (4.5 periods of motion at 5 m/s on the guest's 4 ms
/// SYNC; Δq 90 mm passes the monitor's 100 mm) whose timestamp claims 100 ms more: drive-io
/// judges the step on its own clock and the sequence numbers, refuses it and stops the drives.
/// Why 90 and not less: drive-io rightly allows a stream that resumes after k silent SYNC
/// periods a step of k periods of motion, and the emulated guest starves this publisher for 3
/// periods often enough that a 60 mm (3-period) step was let through (a guest flake); 5 silent
/// periods in a row are rare there, and the step stays below the monitor's Δq limit.
fn lying_timestamps(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    c.cable.store(1, Ordering::Relaxed);
    st.wait_following(false)?;
    let t0 = monotonic_ns();
    c.timestamp_lie_ns.store(100_000_000, Ordering::Relaxed);
    c.step_um.store(90_000, Ordering::Relaxed);
    st.wait("drive-io faulted on the setpoint step", 10.0, |s| {
        Ok(s.bus_state() == Some(BusState::Fault))
    })?;
    let fc = st.last_feedback.map(|f| f.fault_code).unwrap_or(0);
    if fc != crs_ipc::fault_code::SETPOINT_STEP {
        return Err(format!(
            "drive-io faulted with code {fc}, expected SETPOINT_STEP"
        ));
    }
    let t_fault = st.last_feedback.map(|f| f.timestamp_ns).unwrap_or(0);
    let stopped = st.require_braked()?;
    let moved = (st.emu()?.drives[1].length_m - home_length()).abs();
    if moved > 0.045 {
        return Err(format!("cable 2 moved {moved:.3} m: the step was applied"));
    }
    Ok(Outcome {
        cause: "drive-io SETPOINT_STEP (monitor: none, Δq 90 mm)".into(),
        detect_ms: ms(t0, t_fault),
        stop_ms: ms(t0, stopped),
        note: "timestamps +100 ms per setpoint, 90 mm step".into(),
    })
}

fn reset_refused_then_accepted(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    c.nan.store(true, Ordering::Relaxed);
    st.monitor_trip(Cause::NonFinite, 10.0)?;
    st.require_braked()?;
    let (ok, text) = st.operator_reset()?;
    if ok || !text.contains("non_finite") {
        return Err(format!(
            "reset while NaN poses persist must be refused: {text:?}"
        ));
    }
    st.poll()?;
    st.require_braked()?;
    c.nan.store(false, Ordering::Relaxed);
    std::thread::sleep(Duration::from_millis(200));
    let t_reset = monotonic_ns();
    let (ok, text2) = st.operator_reset()?;
    if !ok {
        return Err(format!(
            "reset after the fault cleared must be accepted: {text2:?}"
        ));
    }
    st.wait("the monitor's Reset event", 10.0, |s| {
        Ok(s.monitor_resets > 0)
    })?;
    st.wait("drive-io re-enabled and following", 30.0, |s| {
        let e = s.emu()?;
        Ok(matches!(s.bus_state(), Some(BusState::Running))
            && e.drives.iter().all(|d| d.demand == DEMAND_FOLLOW)
            && !e.inhibit)
    })?;
    let back_ms = (monotonic_ns() - t_reset) as f64 * 1e-6;
    // End of the scenario: the publisher stops => braked again.
    c.paused.store(true, Ordering::Relaxed);
    st.wait("the second trip", 10.0, |s| Ok(s.monitor_estops.len() >= 2))?;
    st.require_braked()?;
    Ok(Outcome {
        cause: "non_finite; reset refused, then accepted".into(),
        detect_ms: None,
        stop_ms: None,
        note: format!(
            "refused: {text:?}; accepted: drives following again {back_ms:.0} ms after the reset"
        ),
    })
}

// ---------------------------------------------------------------------------------------------
// Reset authority (issue 16).

/// The safety pairs on the bus: the last decoded heartbeat, and NMT start frames seen.
#[derive(Default)]
struct BusSpy {
    rx: Option<can_transport::safety_frame::PairReceiver>,
    last: Option<can_transport::safety_frame::SafetyHeartbeat>,
    pairs: u64,
    nmt_starts: u64,
    /// Raw safety frames (0x101/0x102) in arrival order, up to `keep`.
    recorded: Vec<can_transport::CanFrame>,
    keep: usize,
}

impl BusSpy {
    fn drain(&mut self, bus: &mut dyn can_transport::CanBus) -> Res<()> {
        let rx = self.rx.get_or_insert_with(|| {
            can_transport::safety_frame::PairReceiver::new(0x101, 1_000_000_000)
        });
        while let Some(f) = bus.try_recv().map_err(|e| e.to_string())? {
            let frame = f.frame;
            if frame.id() == 0 && frame.data().first() == Some(&0x01) {
                self.nmt_starts += 1;
            }
            if rx.is_safety_frame(&frame) && self.recorded.len() < self.keep {
                self.recorded.push(frame);
            }
            if let Some(Ok(hb)) = rx.on_frame(&frame, f.rx_monotonic_ns) {
                self.last = Some(hb);
                self.pairs += 1;
            }
        }
        Ok(())
    }
}

/// Waits for `n` more safety pairs from the monitor on the bus.
fn spy_pairs(
    st: &mut Stack,
    bus: &mut dyn can_transport::CanBus,
    spy: &mut BusSpy,
    n: u64,
) -> Res<()> {
    spy.drain(bus)?;
    let p0 = spy.pairs;
    st.wait(&format!("{n} safety pairs on the bus"), 20.0, |_| {
        spy.drain(bus)?;
        Ok(spy.pairs >= p0 + n)
    })?;
    Ok(())
}

/// drive-io, the drives' watch and the drives after a forged release attempt: drive-io must
/// still be latched (not Ready/Running), the watch inhibiting, the drives braked.
fn require_still_latched(st: &mut Stack, what: &str) -> Res<()> {
    // drive-io reads the state events every SYNC cycle before it publishes its feedback:
    // 1.2 s worth of samples cover its 1 s window for a reset waiting for the watch's epoch.
    let n0 = st.feedback_count;
    let n = 1_200_000 / u64::from(st.period_us.max(1)) + 1;
    st.wait(
        &format!("{n} drive-io cycles after the forgery"),
        60.0,
        |s| Ok(s.feedback_count >= n0 + n),
    )?;
    if matches!(st.bus_state(), Some(BusState::Ready | BusState::Running)) {
        return Err(format!(
            "{what}: drive-io left its latch ({:?})",
            st.bus_state()
        ));
    }
    if !st.emu()?.inhibit {
        return Err(format!("{what}: the drives' safety watch released"));
    }
    st.require_braked()?;
    Ok(())
}

/// Issue 16: Reset events forged by another process release nothing. From any other source
/// they are ignored by motion-core and drive-io (and the tripped monitor re-asserts its
/// e-stop); even with the monitor's source and a newer epoch (which motion-core cannot tell
/// from the real thing: iceoryx2 0.10 does not authenticate publishers) drive-io stays latched
/// and the drives braked, because the epoch is not in the monitor's doubled heartbeat on CAN.
fn forged_reset_ignored(st: &mut Stack) -> Res<Outcome> {
    st.start_motion_core()?;
    st.wait_following(true)?;
    let mut bus = open_bus(st)?;
    let mut spy = BusSpy::default();
    // The operator's e-stop (the console's stop button): every process stops, the monitor
    // latches it.
    let node = IpcNode::with_prefix("shil-forger", &st.prefix).map_err(|e| e.to_string())?;
    let publ = node.publisher::<StateEvent>().map_err(|e| e.to_string())?;
    publ.publish(&StateEvent::new(ProcessId::Operator, EventKind::EStop, 1))
        .map_err(|e| e.to_string())?;
    st.monitor_trip(Cause::EStopEvent, 10.0)?;
    st.require_braked()?;
    st.wait("motion-core latched (E-STOPPED)", 10.0, |s| {
        Ok(s.motion_state == Some(crs_ipc::motion_state::ESTOPPED))
    })?;
    spy_pairs(st, bus.as_mut(), &mut spy, 3)?;
    let epoch = spy.last.map(|h| h.epoch).ok_or("no safety pair seen")?;
    let forged = |src: ProcessId, seq: u64| {
        let mut ev = StateEvent::new(src, EventKind::Reset, seq);
        ev.detail = epoch.wrapping_add(1);
        ev
    };
    for (k, src) in [
        ProcessId::Operator,
        ProcessId::Test,
        ProcessId::DriveIo,
        ProcessId::MotionCore,
    ]
    .into_iter()
    .enumerate()
    {
        publ.publish(&forged(src, 100 + k as u64))
            .map_err(|e| e.to_string())?;
    }
    // The monitor saw them: it answers a foreign reset while tripped with its e-stop again.
    st.wait("the monitor re-asserting its e-stop", 10.0, |s| {
        Ok(s.monitor_estops.len() >= 2)
    })?;
    require_still_latched(st, "reset forged with another source")?;
    // motion-core's heartbeat after the forgeries (its stage publishes every few cycles).
    let h0 = st.monitor_heartbeats;
    st.motion_state = None;
    st.wait("motion-core's heartbeat", 10.0, |s| {
        Ok(s.motion_state.is_some() && s.monitor_heartbeats > h0)
    })?;
    if st.motion_state != Some(crs_ipc::motion_state::ESTOPPED) {
        return Err(format!(
            "motion-core left its latch on a forged reset (state {:?})",
            st.motion_state
        ));
    }
    // The monitor's source claimed, with a newer epoch: not on the bus, so drive-io and the
    // drives stay stopped; the monitor recognises an event it did not publish and re-asserts
    // its e-stop, which latches motion-core again.
    let n_estops = st.monitor_estops.len();
    publ.publish(&forged(ProcessId::SafetyMonitor, 200))
        .map_err(|e| e.to_string())?;
    st.wait(
        "the monitor re-asserting its e-stop on the impersonation",
        10.0,
        |s| Ok(s.monitor_estops.len() > n_estops),
    )?;
    require_still_latched(st, "reset forged with the monitor's source")?;
    let h0 = st.monitor_heartbeats;
    st.motion_state = None;
    st.wait("motion-core's heartbeat", 10.0, |s| {
        Ok(s.motion_state.is_some() && s.monitor_heartbeats > h0)
    })?;
    if st.motion_state != Some(crs_ipc::motion_state::ESTOPPED) {
        return Err(format!(
            "motion-core should be e-stopped again after the monitor's answer (state {:?})",
            st.motion_state
        ));
    }
    spy_pairs(st, bus.as_mut(), &mut spy, 3)?;
    let on_bus = spy.last.map(|h| h.epoch);
    if on_bus != Some(epoch) || spy.nmt_starts > 0 {
        return Err(format!(
            "the monitor's epoch moved ({epoch} -> {on_bus:?}) or NMT start sent ({})",
            spy.nmt_starts
        ));
    }
    let trips = std::fs::read_to_string(st.dir.join("safety-monitor.log")).unwrap_or_default();
    if !trips.contains("did not publish") {
        return Err("the monitor did not log the impersonation".into());
    }
    Ok(Outcome {
        cause: "estop_event; forged resets ignored".into(),
        detect_ms: None,
        stop_ms: None,
        note: format!(
            "Operator/Test/DriveIo/MotionCore resets: all latched; 'SafetyMonitor' reset with \
             epoch {}: recognised by the monitor (e-stop re-asserted, motion-core e-stopped \
             again), drive-io latched, drives braked",
            epoch.wrapping_add(1)
        ),
    })
}

/// Issue 16: an operator reset while the monitor is armed changes nothing anywhere: no NMT
/// start, no Reset event, the same epoch, the drives keep following.
fn reset_while_armed_changes_nothing(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let mut bus = open_bus(st)?;
    let mut spy = BusSpy::default();
    spy_pairs(st, bus.as_mut(), &mut spy, 3)?;
    let epoch = spy.last.map(|h| h.epoch).ok_or("no safety pair seen")?;
    spy.nmt_starts = 0;
    let (ok, text) = st.operator_reset()?;
    if !ok || !text.contains("nothing changed") {
        return Err(format!("unexpected answer while armed: {text:?}"));
    }
    // Ten monitor cycles after the answer.
    spy_pairs(st, bus.as_mut(), &mut spy, 10)?;
    st.poll()?;
    let on_bus = spy.last.map(|h| h.epoch);
    if spy.nmt_starts > 0 || st.monitor_resets > 0 || on_bus != Some(epoch) {
        return Err(format!(
            "a reset while armed changed something: {} NMT start(s), {} Reset event(s), epoch \
             {epoch} -> {on_bus:?}",
            spy.nmt_starts, st.monitor_resets
        ));
    }
    let e = st.emu()?;
    if st.bus_state() != Some(BusState::Running)
        || e.drives.iter().any(|d| d.demand != DEMAND_FOLLOW)
        || st.monitor_state != Some(1)
    {
        return Err("the stack should still run".into());
    }
    // End of the scenario: the publisher stops => silence trip => braked.
    c.paused.store(true, Ordering::Relaxed);
    let t0 = monotonic_ns();
    let ev = st.monitor_trip(Cause::SetpointSilence, 10.0)?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "none (reset while armed); then setpoint_silence".into(),
        detect_ms: ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!("answer {text:?}; no NMT start, no Reset event, epoch {epoch} unchanged"),
    })
}

/// Issue 16 (no self-release): after the monitor died, its recorded heartbeats replayed
/// verbatim, then continued with fresh counters and the same epoch, never release the drives'
/// watch or drive-io.
fn replayed_heartbeat_after_monitor_death(st: &mut Stack) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let mut bus = open_bus(st)?;
    let mut spy = BusSpy {
        keep: 40,
        ..BusSpy::default()
    };
    spy_pairs(st, bus.as_mut(), &mut spy, 20)?;
    let last = spy.last.ok_or("no safety pair seen")?;
    let t0 = monotonic_ns();
    st.signal("safety-monitor", libc::SIGKILL)?;
    st.reap("safety-monitor");
    st.wait("the drives' safety watch to trip", 10.0, |s| {
        Ok(s.emu()?.safety_trips > 0)
    })?;
    st.wait("drive-io e-stopped by its own watch", 10.0, |s| {
        Ok(s.bus_state() == Some(BusState::EStop))
    })?;
    let stopped = st.require_braked()?;
    // A release would show as the watch permitting during the replay, and afterwards as one
    // more Permit -> Inhibit transition (the replay ends, the validation time runs out).
    let trips0 = st.emu()?.safety_trips;
    let mut released = 0u32;
    // 1. The recorded frames verbatim, one pair per monitor cycle (the stimulus is paced like
    //    the monitor; the observations below are paced by the emulator's status time).
    let cycle = Duration::from_millis(15);
    for f in &spy.recorded {
        bus.send(f).map_err(|e| e.to_string())?;
        if f.id() == 0x102 {
            std::thread::sleep(cycle);
            released += u32::from(!st.emu()?.inhibit);
        }
    }
    // 2. The last pair continued: fresh counters, the same epoch, RUN.
    let mut hb = last;
    hb.state = can_transport::safety_frame::SafetyState::Run;
    for _ in 0..60 {
        hb.counter = hb.counter.wrapping_add(1);
        for f in can_transport::safety_frame::encode(&hb, 0x101) {
            bus.send(&f).map_err(|e| e.to_string())?;
        }
        std::thread::sleep(cycle);
        released += u32::from(!st.emu()?.inhibit);
    }
    let t_sent = monotonic_ns();
    // The emulator handled every frame sent before its status time.
    st.wait("the emulator past the replay", 10.0, |s| {
        Ok(s.emu()?.time_ns > t_sent)
    })?;
    require_still_latched(st, "replayed heartbeat")?;
    let trips1 = st.emu()?.safety_trips;
    if released > 0 || trips1 != trips0 {
        return Err(format!(
            "the replay released the drives' safety watch ({released} samples permitting, \
             {} more trips)",
            trips1 - trips0
        ));
    }
    Ok(Outcome {
        cause: "drives: safety heartbeat timeout; replay ignored".into(),
        detect_ms: None,
        stop_ms: ms(t0, stopped),
        note: format!(
            "{} recorded frames replayed + 60 continued pairs of epoch {}: still inhibited",
            spy.recorded.len(),
            last.epoch
        ),
    })
}

// ---------------------------------------------------------------------------------------------
// Issue 15 scenarios: measured forces, unknown applied sequence, CAN error frames, a lost stop
// frame.

/// Extra monitor arguments of a scenario (fault injection inside the monitor process).
fn monitor_fault_injection(scenario: &str) -> &'static [&'static str] {
    match scenario {
        "stop_frame_lost" => &["--inject-nmt-stop-unsent"],
        _ => &[],
    }
}

/// The winch emulator reports `force_n` as cable `cable`'s (1-based) measured force from its
/// next SYNC on (its `--control-file`; the emulator has no physics, its force is a constant
/// pretension otherwise).
fn inject_force(st: &Stack, cable: usize, force_n: f64) -> Res<()> {
    let p = st.dir.join("emulator.control");
    let tmp = st.dir.join("emulator.control.tmp");
    std::fs::write(&tmp, format!("force {cable} {force_n}\n"))
        .and_then(|_| std::fs::rename(&tmp, &p))
        .map_err(|e| format!("{}: {e}", p.display()))
}

/// One cable's measured force leaves [f_min − 500 N, f_max + 1000 N] (test cabin: 1000 /
/// 9000 N) and stays there: the monitor's filtered force check (45 ms) trips on that cable.
fn force_fault(st: &mut Stack, cable: usize, force_n: f64, cause: Cause) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let t0 = monotonic_ns();
    inject_force(st, cable, force_n)?;
    let ev = st.monitor_trip(cause, 10.0)?;
    if ev.detail_node as usize != cable {
        return Err(format!(
            "tripped on cable {}, expected {cable}",
            ev.detail_node
        ));
    }
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: format!("{cause} cable {cable}"),
        detect_ms: ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!(
            "emulated drive reports {force_n} N (t0 = control file written; filter 45 ms)"
        ),
    })
}

fn overload_one_cable(st: &mut Stack) -> Res<Outcome> {
    // Above f_max + margin (10 kN), below drive-io's own hard limit (14 kN): the monitor's
    // filtered overload check is what stops it.
    force_fault(st, 4, 10_500.0, Cause::ForceOverload)
}

fn slack_one_cable(st: &mut Stack) -> Res<Outcome> {
    force_fault(st, 2, 200.0, Cause::ForceSlack)
}

/// drive-io dies and a faulty adapter takes its place at once: it keeps the drives
/// synchronised (SYNC, so they keep sending forces) and publishes Running feedback whose
/// applied setpoint the monitor never saw. The following-error check cannot be evaluated:
/// after `unchecked_cycles` (10) it trips instead of skipping.
fn unknown_applied_sequence(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let fb0 = st.last_feedback.ok_or("no drive-io feedback")?;
    // Everything that takes time is prepared before drive-io dies: the node (its creation
    // sweeps dead nodes) and the SYNC thread that keeps the drives sending forces.
    let node =
        IpcNode::with_prefix("shil-faulty-drive-io", &st.prefix).map_err(|e| e.to_string())?;
    let mut bus = open_bus(st)?;
    let period = u64::from(st.period_us) * 1000;
    let sync_stop = Arc::new(AtomicBool::new(false));
    let sync = {
        let stop = sync_stop.clone();
        std::thread::spawn(move || {
            let f = can_transport::CanFrame::new_std_lossy(0x080, &[]);
            let mut next = monotonic_ns();
            while !stop.load(Ordering::Relaxed) {
                next += period;
                crs_rt::sleep_until(next);
                let _ = bus.send(&f);
            }
        })
    };
    // The feedback topic has one publisher: the replacement takes it once drive-io's is gone.
    st.signal("drive-io", libc::SIGKILL)?;
    st.reap("drive-io");
    let t0 = monotonic_ns();
    let fb_pub = loop {
        match node.publisher::<DriveFeedback>() {
            Ok(p) => break p,
            Err(e) if monotonic_ns() - t0 > 5_000_000_000 => {
                sync_stop.store(true, Ordering::Relaxed);
                return Err(format!("replacing drive-io's feedback publisher: {e}"));
            }
            Err(_) => {
                crs_ipc::cleanup_dead_nodes(&crs_ipc::iceoryx_config());
            }
        }
    };
    let t_replaced = monotonic_ns();
    let mut next = t_replaced;
    let mut cycle = fb0.cycle;
    let r = loop {
        next += period;
        crs_rt::sleep_until(next);
        cycle += 1;
        let mut fb = fb0;
        fb.cycle = cycle;
        fb.timestamp_ns = monotonic_ns();
        fb.bus_state = BusState::Running as u32;
        fb.applied_setpoint_sequence = c.published.load(Ordering::Relaxed) + 1_000_000;
        let _ = fb_pub.publish(&fb);
        st.poll()?;
        if !st.monitor_estops.is_empty() {
            break st.monitor_trip(Cause::FollowingUnchecked, 1.0);
        }
        if monotonic_ns() - t0 > 10_000_000_000 {
            break Err("no trip within 10 s".into());
        }
    };
    sync_stop.store(true, Ordering::Relaxed);
    let _ = sync.join();
    let ev = r?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "following_unchecked".into(),
        detect_ms: ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!(
            "drive-io replaced ({:.0} ms gap): Running feedback, applied sequence never published",
            (t_replaced - t0) as f64 * 1e-6
        ),
    })
}

/// The bus controller reports `error` (injected: an error frame with CAN_ERR_FLAG, which
/// vcan and the UDP bus forward to every subscribed socket, as cansend would send it): the
/// monitor trips `can_bus_error`, drive-io stops every drive on its own (Fault BUS_ERROR).
fn can_bus_error(st: &mut Stack, error: can_transport::BusErrorFrame) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let mut bus = open_bus(st)?;
    let t0 = monotonic_ns();
    bus.send_bus_error(&error).map_err(|e| e.to_string())?;
    let ev = st.monitor_trip(Cause::CanBusError, 10.0)?;
    st.wait(
        "drive-io stopped on the error frame (Fault BUS_ERROR)",
        10.0,
        |s| Ok(s.last_feedback.map(|f| f.fault_code) == Some(crs_ipc::fault_code::BUS_ERROR)),
    )?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: format!(
            "can_bus_error ({}); drive-io BUS_ERROR",
            error.condition().name()
        ),
        detect_ms: ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!("injected error frame {error}"),
    })
}

fn can_bus_off(st: &mut Stack) -> Res<Outcome> {
    can_bus_error(st, can_transport::BusErrorFrame::bus_off())
}

fn can_error_passive(st: &mut Stack) -> Res<Outcome> {
    can_bus_error(st, can_transport::BusErrorFrame::error_passive(128, 0))
}

/// The monitor's NMT stop cannot be sent (its process runs with the injected ENOBUFS on every
/// NMT frame): the stop escalates to the safety heartbeat's STOP, and the drives brake through
/// their watch, NOT through NMT (they stay NMT operational).
fn stop_frame_lost(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    c.cable.store(2, Ordering::Relaxed);
    st.wait_following(false)?;
    c.offset_target_um.store(101_000, Ordering::Relaxed);
    let ev = st.monitor_trip(Cause::DqLimit, 10.0)?;
    let t_cross = c.crossed_ns.load(Ordering::Relaxed);
    let stopped = st.require_braked()?;
    let e = st.emu()?;
    if e.drives.iter().any(|d| d.nmt == 4) {
        return Err("a drive is NMT-stopped: the NMT stop was not lost".into());
    }
    if e.safety_trips == 0 {
        return Err("the drives' safety watch did not trip".into());
    }
    let log = std::fs::read_to_string(st.dir.join("safety-monitor.log")).unwrap_or_default();
    if !log.contains("stop path ESCALATED") {
        return Err("the monitor did not log the escalation".into());
    }
    Ok(Outcome {
        cause: "dq_limit; NMT stop unsent → heartbeat inhibit".into(),
        detect_ms: ms(t_cross, ev.timestamp_ns),
        stop_ms: ms(t_cross, stopped),
        note: "every NMT frame of the monitor fails (ENOBUFS injected); drives stay NMT operational, brake on the STOP pair".into(),
    })
}

/// utime + stime of `pid` from /proc (s).
fn proc_cpu_s(pid: i32) -> Res<f64> {
    let t = std::fs::read_to_string(format!("/proc/{pid}/stat")).map_err(|e| e.to_string())?;
    // Fields after the command name (which may contain spaces) start after the last ')'.
    let rest = &t[t.rfind(')').ok_or("bad /proc stat")? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| -> Res<f64> {
        f.get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .ok_or_else(|| "bad /proc stat field".to_string())
    };
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Ok((ticks(11)? + ticks(12)?) / hz)
}

/// Per-thread (name, utime + stime s) of `pid` from /proc/<pid>/task.
fn threads_cpu_s(pid: i32) -> Res<BTreeMap<String, f64>> {
    let mut out = BTreeMap::new();
    let dir = format!("/proc/{pid}/task");
    for e in std::fs::read_dir(&dir).map_err(|e| format!("{dir}: {e}"))? {
        let p = e.map_err(|e| e.to_string())?.path();
        let Ok(t) = std::fs::read_to_string(p.join("stat")) else {
            continue;
        };
        let (Some(a), Some(b)) = (t.find('('), t.rfind(')')) else {
            continue;
        };
        let name = t[a + 1..b].to_string();
        let f: Vec<&str> = t[b + 2..].split_whitespace().collect();
        let v = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok()).unwrap_or(0.0);
        // SAFETY: sysconf has no preconditions.
        let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
        *out.entry(name).or_insert(0.0) += (v(11) + v(12)) / hz;
    }
    Ok(out)
}

fn cpu_share(args: &Args, secs: f64) -> Res<String> {
    let mut st = Stack::start(
        "cpu_share",
        &args.workdir,
        args.bin_dir.clone(),
        &args.transport,
        args.period_us,
    )?;
    let spawned = Instant::now();
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let pid = st.pid("safety-monitor")?;
    let cpu0 = proc_cpu_s(pid)?;
    let th0 = threads_cpu_s(pid)?;
    let t0 = Instant::now();
    while t0.elapsed().as_secs_f64() < secs {
        std::thread::sleep(Duration::from_millis(200));
        st.poll()?;
    }
    let window = t0.elapsed().as_secs_f64();
    let cpu1 = proc_cpu_s(pid)?;
    let th1 = threads_cpu_s(pid)?;
    let per_thread: Vec<String> = th1
        .iter()
        .map(|(n, c)| {
            let d = c - th0.get(n).copied().unwrap_or(0.0);
            format!("{n} {:.2} %", d / window * 100.0)
        })
        .collect();
    // A trip does not end the measurement (the monitor keeps checking while latched); it is
    // reported: on a loaded, non-real-time host a stall > 32 ms loses setpoints.
    let trips: Vec<String> = st
        .monitor_estops
        .iter()
        .map(|e| format!("{:?}", Cause::from_code(e.detail)))
        .collect();
    let mut child = st
        .procs
        .remove("safety-monitor")
        .ok_or("monitor not running")?;
    st.signal_pid(pid, libc::SIGTERM)?;
    let mut status = 0;
    // SAFETY: a zeroed rusage is a valid out-parameter; pid is our child.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: wait4 on our own child with valid out-pointers.
    let r = unsafe { libc::wait4(pid, &mut status, 0, &mut ru) };
    let life = spawned.elapsed().as_secs_f64();
    let _ = child.try_wait();
    if r != pid {
        return Err("wait4 failed".into());
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    let (user, sys) = (tv(ru.ru_utime), tv(ru.ru_stime));
    let summary = std::fs::read_to_string(st.dir.join("safety-monitor.log"))
        .ok()
        .and_then(|t| {
            t.lines()
                .rev()
                .find(|l| l.contains("stopped"))
                .map(str::to_string)
        })
        .unwrap_or_default();
    Ok(format!(
        "monitor CPU over the {window:.1} s window (/proc): {:.2} % of one core; getrusage over its \
         whole life ({life:.1} s incl. start-up): user {user:.3} s + sys {sys:.3} s = {:.2} %; \
         per thread over the window: {}; max RSS {} KiB; voluntary/involuntary context switches \
         {}/{}; trips {:?}\n{summary}",
        (cpu1 - cpu0) / window * 100.0,
        (user + sys) / life * 100.0,
        per_thread.join(", "),
        ru.ru_maxrss,
        ru.ru_nvcsw,
        ru.ru_nivcsw,
        trips
    ))
}

type Scenario = (&'static str, fn(&mut Stack) -> Res<Outcome>);

const SCENARIOS: [Scenario; 28] = [
    ("offset_101mm_trips", offset_101mm),
    ("offset_99mm_no_trip", offset_99mm),
    ("frozen_motion_core", frozen_motion_core),
    ("kill_motion_core", kill_motion_core),
    ("kill_drive_io", kill_drive_io),
    ("kill_monitor", kill_monitor),
    ("sequence_gaps", sequence_gaps),
    ("nan_pose", nan_pose),
    ("identity_mismatch", identity_mismatch),
    ("corrupted_safety_frame", corrupted_safety_frame),
    ("forged_rpdo", forged_rpdo),
    (
        "forged_rpdo_other_enabling_controlword",
        forged_rpdo_other_enabling_controlword,
    ),
    ("pose_jump_inside_box", pose_jump_inside_box),
    ("lying_timestamps", lying_timestamps),
    ("reset_refused_then_accepted", reset_refused_then_accepted),
    ("forged_reset_ignored", forged_reset_ignored),
    (
        "reset_while_armed_changes_nothing",
        reset_while_armed_changes_nothing,
    ),
    (
        "replayed_heartbeat_after_monitor_death",
        replayed_heartbeat_after_monitor_death,
    ),
    ("overload_one_cable", overload_one_cable),
    ("slack_one_cable", slack_one_cable),
    ("unknown_applied_sequence", unknown_applied_sequence),
    ("can_bus_off", can_bus_off),
    ("can_error_passive", can_error_passive),
    ("stop_frame_lost", stop_frame_lost),
    ("forged_stopping", integrity::forged_stopping),
    ("foreign_publisher", integrity::foreign_publisher),
    (
        "heartbeat_config_crc_mismatch",
        integrity::heartbeat_config_crc_mismatch,
    ),
    ("tampered_safety_config", integrity::tampered_safety_config),
];

fn main() -> ExitCode {
    let args = Args::parse();
    if args.guest_tuning {
        for (f, v) in [
            ("/proc/sys/net/core/rmem_default", "8388608"),
            ("/proc/sys/net/core/rmem_max", "8388608"),
        ] {
            if let Err(e) = std::fs::write(f, v) {
                println!("safety-hil: cannot set {f}: {e}");
            }
        }
    }
    if let Err(e) = write_configs(&args.workdir, &args) {
        println!("SAFETY-HIL FAIL setup: {e}");
        println!("SAFETY-HIL-RESULT FAIL");
        return ExitCode::FAILURE;
    }
    if let Some(secs) = args.cpu_share_s {
        return match cpu_share(&args, secs) {
            Ok(r) => {
                println!("SAFETY-CPU {r}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                println!("SAFETY-CPU FAIL: {e}");
                ExitCode::FAILURE
            }
        };
    }
    println!(
        "safety-hil: transport {}; drives' safety-heartbeat validation time {} ms; monitor \
         silence {} cycles, feedback silence {} cycles (15 ms cycles); 1 kHz loops at {} µs; \
         workdir {}",
        args.transport,
        args.validation_ms,
        args.silence_cycles,
        args.feedback_silence_cycles,
        args.period_us,
        args.workdir.display()
    );
    let mut rows = Vec::new();
    let mut all_ok = true;
    for (name, f) in SCENARIOS {
        if args.only.as_deref().is_some_and(|o| !name.contains(o)) {
            continue;
        }
        let t0 = Instant::now();
        let mut stack = None;
        let r = Stack::start(
            name,
            &args.workdir,
            args.bin_dir.clone(),
            &args.transport,
            args.period_us,
        )
        .and_then(|mut st| {
            let r = f(&mut st);
            stack = Some(st);
            r
        });
        let secs = t0.elapsed().as_secs_f64();
        match r {
            Ok(o) => {
                let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.1}"));
                println!(
                    "SAFETY-HIL PASS {name}: cause {}; detect {} ms; stop {} ms; {} ({secs:.1} s)",
                    o.cause,
                    f(o.detect_ms),
                    f(o.stop_ms),
                    o.note
                );
                rows.push((name, o, true));
            }
            Err(e) => {
                all_ok = false;
                println!("SAFETY-HIL FAIL {name}: {e} ({secs:.1} s)");
                match &stack {
                    Some(st) => print!("{}", st.log_tail(25)),
                    None => {
                        let d = args.workdir.join(name);
                        for p in ["safety-monitor", "drive-io", "winch-emulator"] {
                            if let Ok(t) = std::fs::read_to_string(d.join(format!("{p}.log"))) {
                                let v: Vec<&str> = t.lines().collect();
                                println!("---- {p}");
                                for l in &v[v.len().saturating_sub(25)..] {
                                    println!("{l}");
                                }
                            }
                        }
                    }
                }
                rows.push((
                    name,
                    Outcome {
                        cause: format!("FAIL: {e}"),
                        ..Outcome::default()
                    },
                    false,
                ));
            }
        }
        drop(stack);
    }
    println!("\n| scenario | result | cause | detection (ms) | fault to drives braked (ms) |");
    println!("|---|---|---|---|---|");
    for (name, o, ok) in &rows {
        let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.1}"));
        println!(
            "| {name} | {} | {} | {} | {} |",
            if *ok { "PASS" } else { "FAIL" },
            o.cause,
            f(o.detect_ms),
            f(o.stop_ms)
        );
    }
    if rows.is_empty() {
        all_ok = false;
        println!("no scenario matched --only");
    }
    println!("SAFETY-HIL-RESULT {}", if all_ok { "PASS" } else { "FAIL" });
    if all_ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

// ---------------------------------------------------------------------------------------------
// Issue 16: process-bus hardening and configuration integrity.
mod integrity {
    use super::*;

    /// The monitor configuration a scenario runs with.
    pub fn monitor_config(scenario: &str) -> &'static str {
        match scenario {
            "foreign_publisher" => "safety-monitor-strict.toml",
            _ => "safety-monitor.toml",
        }
    }

    /// The drives configuration of the winch emulator in a scenario.
    pub fn emulator_drives(scenario: &str) -> &'static str {
        match scenario {
            "heartbeat_config_crc_mismatch" => "drives-crc-mismatch.toml",
            _ => "drives.toml",
        }
    }

    /// Scenarios in which the drives must never become enabled (the start does not wait).
    pub fn drives_never_ready(scenario: &str) -> bool {
        scenario == "heartbeat_config_crc_mismatch"
    }

    /// A STOPPING announced by another process in motion-core's name while motion-core is in
    /// the middle of its plan: it would disarm the silence and sequence checks. The monitor
    /// trips `unplanned_stream_end`, everything brakes.
    pub fn forged_stopping(st: &mut Stack) -> Res<Outcome> {
        st.start_motion_core()?;
        st.wait_following(true)?;
        let node = IpcNode::with_prefix("shil-forger", &st.prefix).map_err(|e| e.to_string())?;
        let publ = node.publisher::<StateEvent>().map_err(|e| e.to_string())?;
        let mut ev = StateEvent::new(ProcessId::MotionCore, EventKind::StateChanged, 1);
        ev.state = crs_ipc::motion_state::STOPPING;
        let t0 = monotonic_ns();
        publ.publish(&ev).map_err(|e| e.to_string())?;
        let trip = st.monitor_trip(Cause::UnplannedStreamEnd, 10.0)?;
        let stopped = st.require_braked()?;
        st.wait("motion-core latched (E-STOPPED)", 10.0, |s| {
            Ok(s.motion_state == Some(crs_ipc::motion_state::ESTOPPED))
        })?;
        Ok(Outcome {
            cause: "unplanned_stream_end".into(),
            detect_ms: ms(t0, trip.timestamp_ns),
            stop_ms: ms(t0, stopped),
            note: "STOPPING forged mid-plan by another process; motion-core e-stopped".into(),
        })
    }

    /// Another process (this harness, not motion-core) owns the setpoint stream and publishes
    /// perfectly plausible setpoints at home with the right identity: only the owner check
    /// (publisher's process executable, iceoryx2 service introspection) can tell. The monitor
    /// trips `foreign_publisher`, the drives brake.
    pub fn foreign_publisher(st: &mut Stack) -> Res<Outcome> {
        let t0 = monotonic_ns();
        let c = st.fake()?.clone();
        let trip = st.monitor_trip(Cause::ForeignPublisher, 10.0)?;
        let stopped = st.require_braked()?;
        if c.published.load(Ordering::Relaxed) == 0 {
            return Err("the foreign publisher published nothing".into());
        }
        Ok(Outcome {
            cause: "foreign_publisher".into(),
            detect_ms: ms(t0, trip.timestamp_ns),
            stop_ms: ms(t0, stopped),
            note: "setpoint stream opened by safety-hil (valid setpoints, right identity)".into(),
        })
    }

    /// The drives (winch emulator) are configured with another SRDO validation time than the
    /// monitor announces: their configuration CRC differs, so their watch never permits; no
    /// drive is ever enabled although the monitor runs and drive-io tries; nothing moves, also
    /// not when motion-core starts.
    pub fn heartbeat_config_crc_mismatch(st: &mut Stack) -> Res<Outcome> {
        st.wait("the monitor RUN (every drive operational)", 30.0, |s| {
            Ok(s.monitor_state == Some(safety_monitor::StateCode::Armed.code()))
        })?;
        st.start_motion_core()?;
        // Watch for 3 s of monitor cycles: no drive enabled, none following, drive-io never
        // Ready / Running, the emulator's watch inhibiting throughout.
        let h0 = st.monitor_heartbeats;
        let e0 = st.emu()?;
        st.wait("3 s of monitor cycles", 30.0, |s| {
            let e = s.emu()?;
            if !e.inhibit || e.drives.iter().any(|d| d.demand == DEMAND_FOLLOW) {
                return Err("a drive was released or follows despite the CRC mismatch".into());
            }
            if matches!(s.bus_state(), Some(BusState::Ready | BusState::Running)) {
                return Err("drive-io enabled the drives despite the CRC mismatch".into());
            }
            Ok(s.monitor_heartbeats >= h0 + 200)
        })?;
        st.require_braked()?;
        let e1 = st.emu()?;
        for (i, (a, b)) in e0.drives.iter().zip(&e1.drives).enumerate() {
            if (a.length_m - b.length_m).abs() > 1e-9 {
                return Err(format!("cable {} moved", i + 1));
            }
        }
        Ok(Outcome {
            cause: "drives: SRDO configuration CRC mismatch".into(),
            detect_ms: None,
            stop_ms: None,
            note: "emulator's validation time 10 ms longer than the monitor's: its watch never \
                   permitted over 200 monitor cycles, drive-io never enabled"
                .into(),
        })
    }

    /// Runs `safety-monitor --config cfg` and requires it to refuse to start (exit != 0 within
    /// 10 s) with `expect` in its error output.
    fn refuses(st: &Stack, cfg: &Path, expect: &str) -> Res<()> {
        let mut child = Command::new(st.exe("safety-monitor"))
            .arg("--config")
            .arg(cfg)
            .arg("--transport")
            .arg(&st.transport)
            .env("CRS_IPC_PREFIX", format!("{}tampered/", st.prefix))
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| e.to_string())?;
        let t0 = Instant::now();
        let status = loop {
            if let Some(s) = child.try_wait().map_err(|e| e.to_string())? {
                break s;
            }
            if t0.elapsed() > Duration::from_secs(10) {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!("{}: the monitor STARTED", cfg.display()));
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let out = child.wait_with_output().map_err(|e| e.to_string())?;
        let err = String::from_utf8_lossy(&out.stderr);
        if status.success() || !err.contains(expect) {
            return Err(format!(
                "{}: exit {status}, expected a refusal naming {expect}: {err}",
                cfg.display()
            ));
        }
        Ok(())
    }

    /// The operator restarts the monitor on a tampered safety configuration: the platform file
    /// changed after it was accepted (one parameter edited), or a check switched off in the
    /// robot profile. The monitor refuses to start in both cases; without its heartbeat the
    /// drives and drive-io brake, and nothing moves.
    pub fn tampered_safety_config(st: &mut Stack) -> Res<Outcome> {
        st.start_motion_core()?;
        st.wait_following(true)?;
        let t0 = monotonic_ns();
        st.signal("safety-monitor", libc::SIGTERM)?;
        st.reap("safety-monitor");
        let mon = std::fs::read_to_string(st.cfg.join("safety-monitor.toml"))
            .map_err(|e| e.to_string())?;
        let plat =
            std::fs::read_to_string(st.cfg.join("platform.toml")).map_err(|e| e.to_string())?;
        // 1. The platform edited after acceptance (f_max 9000 -> 9900 N).
        let tampered = plat.replace("f_max_n = 9000.0", "f_max_n = 9900.0");
        if tampered == plat {
            return Err("could not tamper with the platform".into());
        }
        std::fs::write(st.dir.join("platform.toml"), tampered).map_err(|e| e.to_string())?;
        std::fs::copy(st.cfg.join("drives.toml"), st.dir.join("drives.toml"))
            .map_err(|e| e.to_string())?;
        let cfg1 = st.dir.join("safety-monitor-tampered-platform.toml");
        std::fs::write(&cfg1, &mon).map_err(|e| e.to_string())?;
        refuses(st, &cfg1, "monitor.platform_sha256")?;
        // 2. A check switched off outside the bench profile.
        let off = mon.replace("check_rpdo = true", "check_rpdo = false");
        if off == mon {
            return Err("could not switch check_rpdo off".into());
        }
        std::fs::write(st.dir.join("platform.toml"), &plat).map_err(|e| e.to_string())?;
        let cfg2 = st.dir.join("safety-monitor-check-off.toml");
        std::fs::write(&cfg2, off).map_err(|e| e.to_string())?;
        refuses(st, &cfg2, "can.check_rpdo")?;
        st.wait("the drives' safety watch to trip", 10.0, |s| {
            Ok(s.emu()?.safety_trips > 0)
        })?;
        let stopped = st.require_braked()?;
        st.wait("drive-io e-stopped by its own watch", 10.0, |s| {
            Ok(s.bus_state() == Some(BusState::EStop))
        })?;
        Ok(Outcome {
            cause: "monitor refused both tampered configs".into(),
            detect_ms: None,
            stop_ms: ms(t0, stopped),
            note: "platform edited after acceptance; check_rpdo off in the robot profile".into(),
        })
    }
}
