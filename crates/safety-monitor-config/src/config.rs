//! `config/safety-monitor.toml`: the monitor's own settings, plus the platform TOML and the
//! drives TOML it points to (read with the monitor's own parsers). Everything is validated
//! before anything runs; errors name the file, the key and (for TOML syntax errors) the line.

use crate::bus_layout::{BusLayout, ForceLayout, RpdoLayout, Value, object_value, parse_object};
use crate::platform::{PlatformError, PlatformParams, load_platform};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The spec's limit for |Δq| (sec. 5.6: 100 mm). A configuration above it is refused.
pub use crs_limits::DELTA_Q_LIMIT_M;

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{file}: cannot read: {source}")]
    Read {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}{}: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
    Parse {
        file: String,
        line: Option<usize>,
        message: String,
    },
    #[error("{file}: `{key}`: {reason}")]
    Invalid {
        file: String,
        key: String,
        reason: String,
    },
    #[error(transparent)]
    Platform(#[from] PlatformError),
}

/// `[monitor]`
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MonitorSection {
    /// Platform TOML, relative to the config file.
    pub platform: PathBuf,
    /// SHA-256 (hex) of the platform file's bytes as accepted by the operator
    /// (`safety-monitor accept`): a platform file that differs (a calibration wrote
    /// it, someone edited it) is refused at start. Required in the robot profile.
    #[serde(default)]
    pub platform_sha256: String,
    /// `"robot"` (default) or `"bench"`: only the bench profile may switch a check off
    /// (check_* = false, require_ready = false, feedback.silence_cycles = 0) or run a platform
    /// without an accepted hash.
    #[serde(default = "d_profile")]
    pub profile: String,
    /// Cycle period (ms); sec. 5.6: 15 ms.
    #[serde(default = "d_cycle")]
    pub cycle_ms: u32,
    /// |Δq_i| limit (mm); at most 100 mm (sec. 5.6, eq. 5.27).
    #[serde(default = "d_dq")]
    pub dq_limit_mm: f64,
    /// E-stop after this many consecutive cycles without a new setpoint (armed by the first).
    #[serde(default = "d_silence")]
    pub silence_cycles: u32,
    /// E-stop when more setpoints than this were lost (sequence gaps, buffer overflow) within
    /// the last `gap_window_cycles` cycles.
    #[serde(default = "d_missing")]
    pub max_missing_setpoints: u32,
    #[serde(default = "d_gap_window")]
    pub gap_window_cycles: u32,
    /// Setpoints without a verified platform identity for this many cycles => e-stop.
    #[serde(default = "d_identity_grace")]
    pub identity_grace_cycles: u32,
    /// The workspace box of the platform TOML is widened by this (m / deg) for the check.
    #[serde(default)]
    pub workspace_margin_m: f64,
    #[serde(default)]
    pub workspace_margin_deg: f64,
    /// A reset is accepted only after this many consecutive cycles without any fault.
    #[serde(default = "d_reset_clear")]
    pub reset_clear_cycles: u32,
    /// Optional file every trip is appended to (one line per trip); empty = none.
    #[serde(default)]
    pub trip_log: String,
    /// Begin in a not-ready state (STOP heartbeat, motion not permitted) until every drive is
    /// operational and sends force readings.
    #[serde(default = "d_true")]
    pub require_ready: bool,
    /// SCHED_FIFO priority of the cycle thread (1..=99; 0 = SCHED_OTHER). Degrades with a
    /// warning when not permitted.
    #[serde(default)]
    pub rt_priority: i32,
    /// CPU to pin the cycle thread to (-1 = none).
    #[serde(default = "d_cpu")]
    pub cpu: i32,
}

/// `[feedback]`: drive-io's DriveFeedback against the setpoints it applied.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FeedbackSection {
    /// Check the following error (only while drive-io reports Running).
    #[serde(default = "d_true")]
    pub check_following_error: bool,
    /// |measured − commanded| bound (mm), against the closest of the last `window_setpoints`
    /// setpoints up to the one drive-io reports as applied (the drives lag a few cycles).
    #[serde(default = "d_following")]
    pub following_error_mm: f64,
    #[serde(default = "d_window")]
    pub window_setpoints: u32,
    /// E-stop after this many cycles without feedback once feedback was seen (dead drive-io);
    /// 0 = off.
    #[serde(default = "d_fb_silence")]
    pub silence_cycles: u32,
    /// E-stop after this many cycles in a row in which feedback arrived but none of it could
    /// be checked (its applied setpoint unknown to the monitor); must be >= 1 while the
    /// following error is checked (fail closed).
    #[serde(default = "d_unchecked")]
    pub unchecked_cycles: u32,
}

/// `[can]`
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CanSection {
    /// Optional: the transport of a drives file with ONE interface (overridden by --transport).
    /// Absent: every interface's transport as the drives file gives it (`bus.transport` or
    /// `[[bus.interface]]`); the monitor observes every interface the drives are on.
    #[serde(default)]
    pub transport: Option<String>,
    /// drives TOML (node ids and length <-> counts scaling), relative to the config file.
    pub drives: PathBuf,
    /// COB-ID of the safety heartbeat's normal frame; the inverse uses `+ 1` (CiA 304 SRDO 1).
    #[serde(default = "d_cob")]
    pub safety_cob_id: u16,
    /// Also check the RPDO1 target positions the drives receive on the bus.
    #[serde(default = "d_true")]
    pub check_rpdo: bool,
    /// How long to wait after an accepted reset (NMT start) for every drive's operational
    /// heartbeat before the Reset event is published (ms).
    #[serde(default = "d_reset_wait")]
    pub reset_wait_ms: u32,
    /// Monitor cycles without a completed batch of the bus reader thread (it drains its socket
    /// every 3 ms) before the reader counts as dead and the monitor trips.
    #[serde(default = "d_reader_stall")]
    pub reader_stall_cycles: u32,
    /// The consumers' validation time (CiA 304 SCT, ms) and pair window (SRVT, ms) this
    /// producer is configured for: with `safety_cob_id` and `monitor.cycle_ms` (refresh time)
    /// they form the SRDO configuration whose CRC the monitor announces every cycle; drives and
    /// drive-io refuse to permit motion when their own configuration's CRC differs.
    #[serde(default = "d_sct")]
    pub safety_validation_time_ms: u32,
    #[serde(default = "d_srvt")]
    pub safety_pair_window_ms: u32,
    /// Monitor cycles the safety I/O node (`[safety_io]` of the drives file) may go without a
    /// TPDO1 once it has reported, before the monitor trips (`safety_io_silence`): its e-stop
    /// circuit and reset key could no longer be read.
    #[serde(default = "d_io_silence")]
    pub safety_io_silence_cycles: u32,
}

/// `[reset]`: the channels an operator's reset may come from (see
/// [`crate::operator`]). Every other reset request — in particular one published on the process
/// bus — is refused and logged with its sender.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ResetSection {
    /// The reset key of the safety I/O node (turned and released), read from its TPDO1 on the
    /// monitor's own socket. Needs `[safety_io]` in the drives file.
    #[serde(default = "d_true")]
    pub key: bool,
    /// A unix socket for `safety-monitor reset`, relative to this file; empty = none. Its
    /// peer's credentials (SO_PEERCRED) must show membership of `operator_group`.
    #[serde(default)]
    pub socket: String,
    /// The operator group (name, or a numeric gid) whose members may reset through `socket`.
    #[serde(default)]
    pub operator_group: String,
}

fn d_reset() -> ResetSection {
    ResetSection {
        key: true,
        socket: String::new(),
        operator_group: String::new(),
    }
}

/// `[forces]`: the drives' measured cable forces (TPDO2 pulley force, read from the bus on the
/// monitor's own socket) against the platform's limits (seed §5.1, table 5.1).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ForcesSection {
    /// Supervise the measured forces of every operational drive.
    #[serde(default = "d_true")]
    pub check: bool,
    /// Slack: f < f_min_n − slack_margin_n for longer than `filter_ms`.
    #[serde(default = "d_slack_margin")]
    pub slack_margin_n: f64,
    /// Overload: f > f_max_n + overload_margin_n for longer than `filter_ms`.
    #[serde(default = "d_overload_margin")]
    pub overload_margin_n: f64,
    /// Slack or overload trips when at least `window_violations` of a cable's last
    /// `window_readings` force readings are beyond a limit (sensor noise and short transients
    /// pass; a steady or a fluttering violation trips).
    #[serde(default = "d_force_window")]
    pub window_readings: u32,
    #[serde(default = "d_force_violations")]
    pub window_violations: u32,
    /// Any single reading beyond ± this trips at once: the winches' rating (seed: 14 kN).
    #[serde(default = "d_hard_limit")]
    pub hard_limit_n: f64,
    /// An operational drive without a force reading for this many cycles => e-stop.
    #[serde(default = "d_force_silence")]
    pub silence_cycles: u32,
}

/// `[motion]`: plausibility of consecutive setpoint poses against the platform's `[limits]`
/// (table 5.1), timed by the stream's sequence numbers and the monitor's own clock.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MotionSection {
    #[serde(default = "d_true")]
    pub check: bool,
    /// Nominal period of the setpoint stream (motion-core's loop; sec. 5.6: 1 ms), ms: one
    /// sequence number is this much time.
    #[serde(default = "d_sp_period")]
    pub setpoint_period_ms: f64,
    /// Relative tolerance on the limits (finite differences of the trajectory, filter overshoot).
    #[serde(default = "d_motion_margin")]
    pub margin: f64,
}

/// `[ipc]`: who may own the single-owner streams of the process bus. Each list
/// names the executables (basename of `/proc/<pid>/exe` of the publisher's process) allowed to
/// publish that stream; any other publisher, or more than one, trips `foreign_publisher`. An
/// empty list switches the check off (bench profile only).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct IpcSection {
    #[serde(default = "d_motion_core")]
    pub setpoint_owners: Vec<String>,
    #[serde(default = "d_drive_io")]
    pub feedback_owners: Vec<String>,
    #[serde(default = "d_motion_core")]
    pub identity_owners: Vec<String>,
}

fn d_motion_core() -> Vec<String> {
    vec!["motion-core".into()]
}
fn d_drive_io() -> Vec<String> {
    vec!["drive-io".into()]
}
fn d_ipc() -> IpcSection {
    IpcSection {
        setpoint_owners: d_motion_core(),
        feedback_owners: d_drive_io(),
        identity_owners: d_motion_core(),
    }
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    monitor: MonitorSection,
    #[serde(default = "d_ipc")]
    ipc: IpcSection,
    #[serde(default = "d_feedback")]
    feedback: FeedbackSection,
    #[serde(default = "d_forces")]
    forces: ForcesSection,
    #[serde(default = "d_motion")]
    motion: MotionSection,
    can: CanSection,
    #[serde(default = "d_reset")]
    reset: ResetSection,
}

fn d_cycle() -> u32 {
    15
}
fn d_dq() -> f64 {
    100.0
}
fn d_silence() -> u32 {
    2
}
fn d_missing() -> u32 {
    5
}
fn d_gap_window() -> u32 {
    67
}
fn d_identity_grace() -> u32 {
    10
}
fn d_reset_clear() -> u32 {
    3
}
fn d_cpu() -> i32 {
    -1
}
fn d_true() -> bool {
    true
}
fn d_following() -> f64 {
    100.0
}
fn d_window() -> u32 {
    50
}
fn d_fb_silence() -> u32 {
    4
}
fn d_unchecked() -> u32 {
    10
}
fn d_cob() -> u16 {
    can_transport::safety_frame::DEFAULT_COB_ID
}
fn d_reset_wait() -> u32 {
    1000
}
fn d_reader_stall() -> u32 {
    10
}
fn d_sct() -> u32 {
    50
}
fn d_srvt() -> u32 {
    10
}
fn d_profile() -> String {
    PROFILE_ROBOT.into()
}

/// The default profile: every check on, the platform accepted by hash.
pub const PROFILE_ROBOT: &str = "robot";
/// Bench profile: checks may be switched off, an unaccepted platform runs (logged).
pub const PROFILE_BENCH: &str = "bench";
/// Upper bound of the consumers' validation time the monitor may announce (ms): 200 ms is the
/// largest SCT for which a dead monitor still stops the robot within the spec's reaction budget
/// of a few safety cycles (sec. 5.6: 15 ms cycle).
pub const MAX_SAFETY_VALIDATION_MS: u32 = 200;
fn d_sp_period() -> f64 {
    1.0
}
fn d_motion_margin() -> f64 {
    0.25
}
fn d_motion() -> MotionSection {
    MotionSection {
        check: true,
        setpoint_period_ms: d_sp_period(),
        margin: d_motion_margin(),
    }
}
fn d_slack_margin() -> f64 {
    500.0
}
fn d_overload_margin() -> f64 {
    1000.0
}
fn d_force_window() -> u32 {
    16
}
fn d_force_violations() -> u32 {
    8
}
fn d_io_silence() -> u32 {
    4
}
/// Upper bound of `forces.hard_limit_n`: the seed's winches are rated 14 kN (f_abs_max); a
/// hard limit far beyond any winch's rating would never fire before the winch is overloaded.
pub const MAX_HARD_LIMIT_N: f64 = 20_000.0;
/// Upper bound of `motion.setpoint_period_ms`: a longer nominal period would loosen the
/// per-step velocity and acceleration checks by the same factor (spec sec. 5.6: 1 ms; the
/// emulated test guest runs 4 ms).
pub const MAX_SETPOINT_PERIOD_MS: f64 = 10.0;
fn d_hard_limit() -> f64 {
    14_000.0
}
fn d_force_silence() -> u32 {
    4
}
fn d_forces() -> ForcesSection {
    ForcesSection {
        check: true,
        slack_margin_n: d_slack_margin(),
        overload_margin_n: d_overload_margin(),
        window_readings: d_force_window(),
        window_violations: d_force_violations(),
        hard_limit_n: d_hard_limit(),
        silence_cycles: d_force_silence(),
    }
}
fn d_feedback() -> FeedbackSection {
    FeedbackSection {
        check_following_error: true,
        following_error_mm: d_following(),
        window_setpoints: d_window(),
        silence_cycles: d_fb_silence(),
        unchecked_cycles: d_unchecked(),
    }
}

/// One winch as the monitor needs it: its interface, node id and the counts -> length scaling.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Winch {
    /// Index into [`MonitorConfig::interfaces`].
    pub interface: usize,
    pub node_id: u8,
    /// counts per metre of cable (gear · counts/rev / (π · drum diameter)).
    pub counts_per_m: f64,
    pub sign: f64,
    pub offset_counts: f64,
}

impl Winch {
    /// Encoder counts -> cable length (m).
    pub fn counts_to_length_m(&self, counts: i32) -> f64 {
        (f64::from(counts) - self.offset_counts) * self.sign / self.counts_per_m
    }
}

/// One CAN interface of the drives (the drives file's `bus.transport` or `[[bus.interface]]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Interface {
    pub name: String,
    pub transport: String,
}

/// What the monitor reads from the drives file: the interfaces and the winches on them.
#[derive(Debug, Clone, PartialEq)]
pub struct Drives {
    pub interfaces: Vec<Interface>,
    /// Interfaces of the doubled safety frames: the safety I/O node's (`[safety_io]`), else
    /// every interface (indices into `interfaces`).
    pub safety_interfaces: Vec<usize>,
    /// The safety I/O node (interface index, node id), if the drives have one.
    pub safety_io: Option<(usize, u8)>,
    /// In cable order (cable i = i-th `[[winch]]`).
    pub winches: Vec<Winch>,
    /// Where each drive's RPDO and each cable's force travel.
    pub layout: crate::bus_layout::BusLayout,
}

/// Name of the single interface a drives file with only `bus.transport` describes (drive-io's
/// name for it, so `--transport can0=…` means the same in every process).
pub const SINGLE_INTERFACE_NAME: &str = "can0";

#[derive(Deserialize)]
struct RawDrives {
    #[serde(default)]
    bus: RawBus,
    #[serde(default)]
    safety_io: Option<RawSafetyIo>,
    #[serde(default, rename = "force_sensor")]
    force_sensors: Vec<RawForceSensor>,
    #[serde(rename = "winch")]
    winches: Vec<RawWinch>,
}

#[derive(Deserialize, Default)]
struct RawBus {
    #[serde(default)]
    transport: Option<String>,
    #[serde(default, rename = "interface")]
    interfaces: Vec<RawInterface>,
}

#[derive(Deserialize)]
struct RawSafetyIo {
    interface: String,
    node_id: i64,
}

#[derive(Deserialize)]
struct RawInterface {
    name: String,
    transport: String,
}

/// A `[[force_sensor]]` as the monitor needs it (CiA 404 load cell: its TPDO and scaling).
#[derive(Deserialize)]
struct RawForceSensor {
    node_id: i64,
    cable: i64,
    #[serde(default)]
    interface: Option<String>,
    #[serde(default)]
    object: Option<String>,
    n_per_unit: f64,
    #[serde(default)]
    tpdo: Option<i64>,
    #[serde(default)]
    cob_id: Option<i64>,
    #[serde(default)]
    mapping: Option<String>,
}

/// `[[winch.rpdo]]` / `[[winch.tpdo]]` of a custom mapping.
#[derive(Deserialize)]
struct RawPdo {
    number: i64,
    objects: Vec<String>,
    #[serde(default)]
    cob_id: Option<i64>,
}

/// `force = "drive"` or the node id of a `[[force_sensor]]`.
#[derive(Deserialize)]
#[serde(untagged)]
enum RawForce {
    Node(i64),
    Name(String),
}

#[derive(Deserialize)]
struct RawWinch {
    #[serde(default)]
    interface: Option<String>,
    #[serde(default)]
    mapping: Option<String>,
    #[serde(default)]
    rpdo: Vec<RawPdo>,
    #[serde(default)]
    tpdo: Vec<RawPdo>,
    #[serde(default)]
    force: Option<RawForce>,
    #[serde(default)]
    force_object: Option<String>,
    #[serde(default)]
    force_n_per_unit: Option<f64>,
    node_id: i64,
    drum_diameter_m: f64,
    gear_ratio: f64,
    counts_per_rev: f64,
    sign: i64,
    #[serde(default)]
    offset_counts: i64,
}

/// Everything the monitor runs with, validated.
#[derive(Debug, Clone)]
pub struct MonitorConfig {
    pub file: PathBuf,
    pub monitor: MonitorSection,
    pub feedback: FeedbackSection,
    pub forces: ForcesSection,
    pub motion: MotionSection,
    pub can: CanSection,
    pub ipc: IpcSection,
    pub reset: ResetSection,
    /// The reset socket (absolute) and the operator group's gid, if the socket is configured.
    pub reset_socket: Option<(PathBuf, u32)>,
    pub platform_file: PathBuf,
    pub platform: PlatformParams,
    pub drives_file: PathBuf,
    /// The CAN interfaces the drives are on (the monitor observes and stops every one).
    pub interfaces: Vec<Interface>,
    /// Where the doubled safety frames travel (see [`Drives::safety_interfaces`]).
    pub safety_interfaces: Vec<usize>,
    /// The safety I/O node (interface index, node id), if any.
    pub safety_io: Option<(usize, u8)>,
    /// Where each drive's RPDO and each cable's force travel.
    pub layout: crate::bus_layout::BusLayout,
    /// In cable order (cable i = i-th `[[winch]]`).
    pub winches: Vec<Winch>,
    /// CRC-32 of the safety parameter set: the bytes of this file, the platform file and the
    /// drives file, in that order (logged at start, announced on the bus every cycle).
    pub safety_params_crc: u32,
    /// SHA-256 of the platform file's bytes (compared with `monitor.platform_sha256`).
    pub platform_sha256: String,
}

impl MonitorConfig {
    /// The SRDO configuration of the monitor's heartbeat (its CRC goes on the bus).
    pub fn srdo(&self) -> can_transport::safety_frame::SrdoParams {
        can_transport::safety_frame::SrdoParams {
            cob_id: self.can.safety_cob_id,
            refresh_time_ms: self.monitor.cycle_ms,
            validation_time_ms: self.can.safety_validation_time_ms,
            pair_window_ms: self.can.safety_pair_window_ms,
        }
    }
    pub fn is_bench(&self) -> bool {
        self.monitor.profile == PROFILE_BENCH
    }
    pub fn dq_limit_m(&self) -> f64 {
        self.monitor.dq_limit_mm * 1e-3
    }
    pub fn cycle_ns(&self) -> u64 {
        u64::from(self.monitor.cycle_ms) * 1_000_000
    }
    pub fn trip_log(&self) -> Option<PathBuf> {
        (!self.monitor.trip_log.is_empty()).then(|| relative_to(&self.file, &self.monitor.trip_log))
    }
}

fn relative_to(file: &Path, p: impl AsRef<Path>) -> PathBuf {
    let p = p.as_ref();
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        file.parent().unwrap_or(Path::new(".")).join(p)
    }
}

fn read(path: &Path) -> Result<String, ConfigError> {
    let bytes = std::fs::read(path).map_err(|source| ConfigError::Read {
        file: path.display().to_string(),
        source,
    })?;
    // Not UTF-8: say on which line, as for any other syntax error.
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        ConfigError::Parse {
            file: path.display().to_string(),
            line: Some(e.as_bytes()[..at].iter().filter(|b| **b == b'\n').count() + 1),
            message: "not UTF-8 text".into(),
        }
    })
}

fn parse_err(file: &Path, text: &str, e: toml::de::Error) -> ConfigError {
    ConfigError::Parse {
        file: file.display().to_string(),
        line: e
            .span()
            .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1),
        message: e.message().trim().to_string(),
    }
}

/// Builds a [`ConfigError::Invalid`] of one file: the file and the key it names.
struct At<'a>(&'a str);

impl At<'_> {
    fn err(&self, key: &str, reason: impl Into<String>) -> ConfigError {
        ConfigError::Invalid {
            file: self.0.to_string(),
            key: key.to_string(),
            reason: reason.into(),
        }
    }
}

impl MonitorSection {
    fn validate(&self, at: &At) -> Result<(), ConfigError> {
        if !(1..=100).contains(&self.cycle_ms) {
            return Err(at.err("monitor.cycle_ms", "must be in 1..=100"));
        }
        if !(self.dq_limit_mm.is_finite() && self.dq_limit_mm > 0.0) {
            return Err(at.err("monitor.dq_limit_mm", "must be a number > 0"));
        }
        if self.dq_limit_mm > DELTA_Q_LIMIT_M * 1e3 {
            return Err(at.err(
                "monitor.dq_limit_mm",
                format!(
                    "{} mm is above the 100 mm limit of the spec (sec. 5.6, eq. 5.27): refused",
                    self.dq_limit_mm
                ),
            ));
        }
        if self.silence_cycles == 0 {
            return Err(at.err("monitor.silence_cycles", "must be >= 1"));
        }
        if self.gap_window_cycles == 0 || self.gap_window_cycles > 10_000 {
            return Err(at.err("monitor.gap_window_cycles", "must be in 1..=10000"));
        }
        if self.identity_grace_cycles == 0 {
            return Err(at.err("monitor.identity_grace_cycles", "must be >= 1"));
        }
        for (key, v) in [
            ("monitor.workspace_margin_m", self.workspace_margin_m),
            ("monitor.workspace_margin_deg", self.workspace_margin_deg),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(at.err(key, "must be a finite number >= 0"));
            }
        }
        if self.reset_clear_cycles == 0 {
            return Err(at.err("monitor.reset_clear_cycles", "must be >= 1"));
        }
        if !(0..=99).contains(&self.rt_priority) {
            return Err(at.err("monitor.rt_priority", "must be in 0..=99"));
        }
        if self.cpu < -1 {
            return Err(at.err("monitor.cpu", "must be -1 (none) or a CPU index"));
        }
        Ok(())
    }

    /// The profile: false for the robot, true for the bench.
    fn is_bench(&self, at: &At) -> Result<bool, ConfigError> {
        match self.profile.as_str() {
            PROFILE_ROBOT => Ok(false),
            PROFILE_BENCH => Ok(true),
            other => Err(at.err(
                "monitor.profile",
                format!("{other:?}: must be \"{PROFILE_ROBOT}\" or \"{PROFILE_BENCH}\""),
            )),
        }
    }
}

impl FeedbackSection {
    fn validate(&self, at: &At) -> Result<(), ConfigError> {
        if !(self.following_error_mm.is_finite() && self.following_error_mm > 0.0) {
            return Err(at.err("feedback.following_error_mm", "must be a number > 0"));
        }
        if self.check_following_error && self.unchecked_cycles == 0 {
            return Err(at.err(
                "feedback.unchecked_cycles",
                "must be >= 1 while check_following_error is on (an unverifiable check must trip)",
            ));
        }
        if !(1..=crate::capacity::HISTORY as u32).contains(&self.window_setpoints) {
            return Err(at.err(
                "feedback.window_setpoints",
                format!("must be in 1..={}", crate::capacity::HISTORY),
            ));
        }
        Ok(())
    }
}

impl ForcesSection {
    /// The reading window (checked before the safety I/O node's silence, as it always was).
    fn validate_window(&self, at: &At) -> Result<(), ConfigError> {
        if self.window_readings == 0 {
            return Err(at.err("forces.window_readings", "must be >= 1"));
        }
        if !(1..=self.window_readings).contains(&self.window_violations) {
            return Err(at.err(
                "forces.window_violations",
                format!(
                    "must be in 1..=forces.window_readings ({}), got {}",
                    self.window_readings, self.window_violations
                ),
            ));
        }
        Ok(())
    }

    fn validate(&self, at: &At) -> Result<(), ConfigError> {
        for (key, v) in [
            ("forces.slack_margin_n", self.slack_margin_n),
            ("forces.overload_margin_n", self.overload_margin_n),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(at.err(key, format!("must be a number >= 0, got {v}")));
            }
        }
        if !(self.hard_limit_n.is_finite() && self.hard_limit_n > 0.0) {
            return Err(at.err("forces.hard_limit_n", "must be a number > 0"));
        }
        if self.check && self.silence_cycles == 0 {
            return Err(at.err(
                "forces.silence_cycles",
                "must be >= 1: a drive without force readings must trip (fail closed)",
            ));
        }
        Ok(())
    }

    /// Against the platform's force limits (table 5.1).
    fn validate_for(
        &self,
        at: &At,
        platform: &PlatformParams,
        platform_file: &Path,
    ) -> Result<(), ConfigError> {
        if self.slack_margin_n > platform.f_min_n {
            return Err(at.err(
                "forces.slack_margin_n",
                format!(
                    "{} N is above the platform's f_min_n ({} N): the slack limit would be below 0 N",
                    self.slack_margin_n, platform.f_min_n
                ),
            ));
        }
        if self.check && self.hard_limit_n < platform.f_max_n {
            return Err(at.err(
                "forces.hard_limit_n",
                format!(
                    "{} N is below the platform's f_max_n ({} N of {}): every allowed force would trip",
                    self.hard_limit_n,
                    platform.f_max_n,
                    platform_file.display()
                ),
            ));
        }
        Ok(())
    }
}

impl MotionSection {
    fn validate(&self, at: &At) -> Result<(), ConfigError> {
        if !(self.setpoint_period_ms.is_finite() && self.setpoint_period_ms > 0.0) {
            return Err(at.err("motion.setpoint_period_ms", "must be a number > 0"));
        }
        if !(self.margin.is_finite() && (0.0..=1.0).contains(&self.margin)) {
            return Err(at.err(
                "motion.margin",
                "must be in 0..=1 (a fraction of the limit)",
            ));
        }
        Ok(())
    }
}

impl CanSection {
    fn validate_safety_io(&self, at: &At) -> Result<(), ConfigError> {
        if self.safety_io_silence_cycles == 0 {
            return Err(at.err("can.safety_io_silence_cycles", "must be >= 1"));
        }
        Ok(())
    }

    /// `cycle_ms`: the monitor's cycle, below the consumers' validation time.
    fn validate(&self, at: &At, cycle_ms: u32) -> Result<(), ConfigError> {
        if let Some(t) = &self.transport {
            t.parse::<can_transport::TransportSpec>()
                .map_err(|e| at.err("can.transport", e.to_string()))?;
        }
        if self.safety_cob_id == 0
            || self.safety_cob_id >= 0x7FC
            || self.safety_cob_id.is_multiple_of(2)
        {
            return Err(at.err(
                "can.safety_cob_id",
                "must be an odd 11-bit id below 0x7FC (the heartbeat pair uses id and id + 1, \
                 the configuration signature id + 2 and id + 3)",
            ));
        }
        if self.safety_validation_time_ms <= cycle_ms
            || self.safety_validation_time_ms > MAX_SAFETY_VALIDATION_MS
        {
            return Err(at.err(
                "can.safety_validation_time_ms",
                format!(
                    "{} ms must be above monitor.cycle_ms ({} ms) and at most {MAX_SAFETY_VALIDATION_MS} ms",
                    self.safety_validation_time_ms, cycle_ms
                ),
            ));
        }
        if self.safety_pair_window_ms == 0
            || self.safety_pair_window_ms > self.safety_validation_time_ms
        {
            return Err(at.err(
                "can.safety_pair_window_ms",
                "must be >= 1 and <= can.safety_validation_time_ms",
            ));
        }
        Ok(())
    }
}

impl IpcSection {
    fn validate(&self, at: &At) -> Result<(), ConfigError> {
        for (key, names) in [
            ("ipc.setpoint_owners", &self.setpoint_owners),
            ("ipc.feedback_owners", &self.feedback_owners),
            ("ipc.identity_owners", &self.identity_owners),
        ] {
            if let Some(n) = names
                .iter()
                .find(|n| n.is_empty() || n.contains('/') || n.len() > 255)
            {
                return Err(at.err(
                    key,
                    format!("{n:?}: an executable's file name (no path, 1..=255 bytes)"),
                ));
            }
        }
        Ok(())
    }
}

impl ResetSection {
    /// The reset channels (ISO 13849-1 §5.2.2: the operator's manual reset at the safety
    /// function): the socket and its operator group, if any. `config`: this file (the socket
    /// path is relative to it); `has_safety_io`: the drives file has the node with the key.
    fn channels(
        &self,
        at: &At,
        config: &Path,
        has_safety_io: bool,
        drives_file: &Path,
    ) -> Result<Option<(PathBuf, u32)>, ConfigError> {
        if self.key && !has_safety_io {
            return Err(at.err(
                "reset.key",
                format!(
                    "the reset key is read from the safety I/O node, but the drives file {} has \
                     no [safety_io] (set reset.key = false and configure reset.socket)",
                    drives_file.display()
                ),
            ));
        }
        let reset_socket = if self.socket.is_empty() {
            if !self.operator_group.is_empty() {
                return Err(at.err(
                    "reset.operator_group",
                    "given without reset.socket (the group is checked on the socket's peers)",
                ));
            }
            None
        } else {
            if self.operator_group.is_empty() {
                return Err(at.err(
                    "reset.operator_group",
                    "missing: the reset socket accepts only members of this group (name or gid)",
                ));
            }
            let gid = crate::group::resolve_group(&self.operator_group)
                .map_err(|e| at.err("reset.operator_group", e))?;
            Some((relative_to(config, &self.socket), gid))
        };
        if !self.key && reset_socket.is_none() {
            return Err(at.err(
                "reset",
                "no reset channel: enable reset.key (the safety I/O node's key) or configure \
                 reset.socket; without one a trip can never be reset",
            ));
        }
        Ok(reset_socket)
    }
}

impl RawConfig {
    /// Every section on its own, in the order the errors have always been reported; returns
    /// whether the profile is the bench's.
    fn validate(&self, at: &At) -> Result<bool, ConfigError> {
        self.monitor.validate(at)?;
        self.validate_bounds(at)?;
        self.feedback.validate(at)?;
        self.forces.validate_window(at)?;
        self.can.validate_safety_io(at)?;
        self.forces.validate(at)?;
        self.motion.validate(at)?;
        self.can.validate(at, self.monitor.cycle_ms)?;
        self.ipc.validate(at)?;
        let bench = self.monitor.is_bench(at)?;
        if !bench {
            self.validate_robot_profile(at)?;
        }
        Ok(bench)
    }

    /// Upper bounds: a setting beyond them would switch its check off in practice (a silence
    /// of minutes, a margin of metres). Cycles are monitor cycles (15 ms: 67 ≈ 1 s).
    fn validate_bounds(&self, at: &At) -> Result<(), ConfigError> {
        let (m, fo) = (&self.monitor, &self.forces);
        let counts: [(&str, u32, u32); 10] = [
            ("monitor.silence_cycles", m.silence_cycles, 67),
            (
                "monitor.max_missing_setpoints",
                m.max_missing_setpoints,
                100,
            ),
            (
                "monitor.identity_grace_cycles",
                m.identity_grace_cycles,
                200,
            ),
            ("monitor.reset_clear_cycles", m.reset_clear_cycles, 1000),
            ("feedback.silence_cycles", self.feedback.silence_cycles, 67),
            (
                "feedback.unchecked_cycles",
                self.feedback.unchecked_cycles,
                67,
            ),
            ("forces.silence_cycles", fo.silence_cycles, 67),
            (
                "can.reader_stall_cycles",
                self.can.reader_stall_cycles,
                crate::capacity::MAX_READER_STALL_CYCLES,
            ),
            (
                "can.safety_io_silence_cycles",
                self.can.safety_io_silence_cycles,
                67,
            ),
            (
                "forces.window_readings",
                fo.window_readings,
                crate::capacity::MAX_FORCE_WINDOW,
            ),
        ];
        for (key, v, max) in counts {
            if v > max {
                return Err(at.err(key, format!("{v} is above the bound {max}: refused")));
            }
        }
        let reals: [(&str, f64, f64); 7] = [
            ("monitor.workspace_margin_m", m.workspace_margin_m, 0.5),
            ("monitor.workspace_margin_deg", m.workspace_margin_deg, 5.0),
            (
                "feedback.following_error_mm",
                self.feedback.following_error_mm,
                100.0,
            ),
            ("forces.overload_margin_n", fo.overload_margin_n, 5000.0),
            ("forces.hard_limit_n", fo.hard_limit_n, MAX_HARD_LIMIT_N),
            (
                "motion.setpoint_period_ms",
                self.motion.setpoint_period_ms,
                MAX_SETPOINT_PERIOD_MS,
            ),
            ("motion.margin", self.motion.margin, 1.0),
        ];
        for (key, v, max) in reals {
            if v > max {
                return Err(at.err(key, format!("{v} is above the bound {max}: refused")));
            }
        }
        Ok(())
    }

    /// Outside the bench profile no switch may disable a check.
    fn validate_robot_profile(&self, at: &At) -> Result<(), ConfigError> {
        let off: [(&str, bool); 9] = [
            ("monitor.require_ready", !self.monitor.require_ready),
            (
                "feedback.check_following_error",
                !self.feedback.check_following_error,
            ),
            ("feedback.silence_cycles", self.feedback.silence_cycles == 0),
            ("forces.check", !self.forces.check),
            ("motion.check", !self.motion.check),
            ("can.check_rpdo", !self.can.check_rpdo),
            ("ipc.setpoint_owners", self.ipc.setpoint_owners.is_empty()),
            ("ipc.feedback_owners", self.ipc.feedback_owners.is_empty()),
            ("ipc.identity_owners", self.ipc.identity_owners.is_empty()),
        ];
        if let Some((key, _)) = off.iter().find(|(_, is_off)| *is_off) {
            return Err(at.err(
                key,
                "switches a check off: only allowed with monitor.profile = \"bench\"",
            ));
        }
        Ok(())
    }
}

/// A file the configuration names but that cannot be opened is the configuration's error, at
/// the key that names it; what is wrong inside it is reported by its own parser, with its own
/// lines.
fn named(at: &At, key: &str, f: &Path) -> Result<(), ConfigError> {
    match std::fs::metadata(f) {
        Ok(md) if md.is_file() => Ok(()),
        Ok(_) => Err(at.err(key, format!("{} is not a file", f.display()))),
        Err(e) => Err(at.err(key, format!("{}: cannot open: {e}", f.display()))),
    }
}

fn read_bytes(file: &Path) -> Result<Vec<u8>, ConfigError> {
    std::fs::read(file).map_err(|source| ConfigError::Read {
        file: file.display().to_string(),
        source,
    })
}

/// The platform the configuration names, its bytes and their SHA-256 (hex), checked against
/// the accepted one: the file's bytes must hash to what the operator accepted; a calibration
/// writes a new file and never changes the accepted one.
fn accepted_platform(
    at: &At,
    platform_file: &Path,
    m: &MonitorSection,
    bench: bool,
) -> Result<(PlatformParams, Vec<u8>, String), ConfigError> {
    named(at, "monitor.platform", platform_file)?;
    let platform = load_platform(platform_file)?;
    let platform_bytes = read_bytes(platform_file)?;
    let platform_sha256 = crate::identity::hex(&sha256_of(&platform_bytes));
    match (m.platform_sha256.is_empty(), bench) {
        (true, false) => {
            return Err(at.err(
                "monitor.platform_sha256",
                format!(
                    "missing: the robot profile runs only an accepted platform (run \
                     `safety-monitor accept {}`)",
                    platform_file.display()
                ),
            ));
        }
        (false, _) if !m.platform_sha256.eq_ignore_ascii_case(&platform_sha256) => {
            return Err(at.err(
                "monitor.platform_sha256",
                format!(
                    "{} has SHA-256 {platform_sha256}, not the accepted {}: the platform file \
                     changed since it was accepted (review it with `safety-monitor accept`)",
                    platform_file.display(),
                    m.platform_sha256
                ),
            ));
        }
        _ => {}
    }
    Ok((platform, platform_bytes, platform_sha256))
}

/// The drives file the configuration names, with `can.transport` (a single interface's
/// transport) applied.
fn drives_with_transport(
    at: &At,
    drives_file: &Path,
    transport: Option<&String>,
) -> Result<Drives, ConfigError> {
    named(at, "can.drives", drives_file)?;
    let mut drives = load_drives(drives_file)?;
    if let Some(t) = transport {
        if drives.interfaces.len() != 1 {
            return Err(at.err(
                "can.transport",
                format!(
                    "the drives file {} has {} interfaces: the monitor takes their transports \
                     from it (remove can.transport; override with --transport NAME=SPEC)",
                    drives_file.display(),
                    drives.interfaces.len()
                ),
            ));
        }
        drives.interfaces[0].transport = t.clone();
    }
    Ok(drives)
}

/// Loads `config/safety-monitor.toml` and the files it names.
pub fn load(path: &Path) -> Result<MonitorConfig, ConfigError> {
    let text = read(path)?;
    let raw: RawConfig = toml::from_str(&text).map_err(|e| parse_err(path, &text, e))?;
    let file = path.display().to_string();
    let at = At(&file);
    let bench = raw.validate(&at)?;
    let platform_file = relative_to(path, &raw.monitor.platform);
    let (platform, platform_bytes, platform_sha256) =
        accepted_platform(&at, &platform_file, &raw.monitor, bench)?;
    let drives_file = relative_to(path, &raw.can.drives);
    let Drives {
        interfaces,
        safety_interfaces,
        safety_io,
        winches,
        layout,
    } = drives_with_transport(&at, &drives_file, raw.can.transport.as_ref())?;
    let reset_socket = raw
        .reset
        .channels(&at, path, safety_io.is_some(), &drives_file)?;
    if winches.len() != platform.cables() {
        return Err(ConfigError::Invalid {
            file: drives_file.display().to_string(),
            key: "winch".into(),
            reason: format!(
                "{} [[winch]] entries but the platform {} has {} cables",
                winches.len(),
                platform_file.display(),
                platform.cables()
            ),
        });
    }
    raw.forces.validate_for(&at, &platform, &platform_file)?;
    // The safety parameter set the consumers check: this file, the platform, the drives.
    let drives_bytes = read_bytes(&drives_file)?;
    let mut set = Vec::with_capacity(text.len() + platform_bytes.len() + drives_bytes.len());
    set.extend_from_slice(text.as_bytes());
    set.extend_from_slice(&platform_bytes);
    set.extend_from_slice(&drives_bytes);
    let safety_params_crc = can_transport::safety_frame::crc32_ieee(&set);
    Ok(MonitorConfig {
        safety_params_crc,
        platform_sha256,
        file: path.to_path_buf(),
        monitor: raw.monitor,
        feedback: raw.feedback,
        forces: raw.forces,
        motion: raw.motion,
        can: raw.can,
        ipc: raw.ipc,
        reset: raw.reset,
        reset_socket,
        platform_file,
        platform,
        drives_file,
        interfaces,
        safety_interfaces,
        safety_io,
        winches,
        layout,
    })
}

impl MonitorConfig {
    /// Replaces interface transports from command-line overrides: `NAME=SPEC` per interface,
    /// or a bare SPEC when there is one interface.
    pub fn override_transports(&mut self, overrides: &[String]) -> Result<(), ConfigError> {
        let bad = |reason: String| ConfigError::Invalid {
            file: "command line".into(),
            key: "--transport".into(),
            reason,
        };
        for o in overrides {
            let (idx, spec) = match o.split_once('=') {
                Some((name, spec)) if !name.contains(':') => (
                    self.interfaces
                        .iter()
                        .position(|i| i.name == name)
                        .ok_or_else(|| bad(format!("{name:?}: no such interface")))?,
                    spec,
                ),
                _ if self.interfaces.len() == 1 => (0, o.as_str()),
                _ => {
                    return Err(bad(format!(
                        "{o:?}: with several interfaces give NAME=SPEC for each"
                    )));
                }
            };
            spec.parse::<can_transport::TransportSpec>()
                .map_err(|e| bad(format!("{o:?}: {e}")))?;
            self.interfaces[idx].transport = spec.to_string();
        }
        Ok(())
    }

    /// The transport of every interface, in order.
    pub fn transports(&self) -> Result<Vec<can_transport::TransportSpec>, ConfigError> {
        self.interfaces
            .iter()
            .enumerate()
            .map(|(i, itf)| {
                itf.transport
                    .parse()
                    .map_err(|e: can_transport::SpecError| ConfigError::Invalid {
                        file: self.drives_file.display().to_string(),
                        key: format!("bus.interface[{i}].transport"),
                        reason: e.to_string(),
                    })
            })
            .collect()
    }
}

/// Reads the interfaces, node ids and scaling from a drives TOML (`bus.transport` or
/// `[[bus.interface]]`, the `[[winch]]` entries; everything else is drive-io's business and
/// ignored here).
pub fn load_drives(path: &Path) -> Result<Drives, ConfigError> {
    let text = read(path)?;
    let raw: RawDrives = toml::from_str(&text).map_err(|e| parse_err(path, &text, e))?;
    let file = path.display().to_string();
    let invalid = |key: String, reason: String| ConfigError::Invalid {
        file: file.clone(),
        key,
        reason,
    };
    let interfaces = drive_interfaces(&raw.bus, &invalid)?;
    let out = drive_winches(&raw.winches, &interfaces, &invalid)?;
    if out.is_empty() || out.len() > crs_ipc::MAX_CABLES {
        return Err(invalid(
            "winch".into(),
            format!("need 1..={} [[winch]] entries", crs_ipc::MAX_CABLES),
        ));
    }
    let safety_io = match &raw.safety_io {
        None => None,
        Some(io) => {
            let iface = interfaces
                .iter()
                .position(|i| i.name == io.interface)
                .ok_or_else(|| {
                    invalid(
                        "safety_io.interface".into(),
                        format!("{:?}: no such interface", io.interface),
                    )
                })?;
            if !(1..=127).contains(&io.node_id) {
                return Err(invalid(
                    "safety_io.node_id".into(),
                    "must be in 1..=127".into(),
                ));
            }
            Some((iface, io.node_id as u8))
        }
    };
    let safety_interfaces = match safety_io {
        Some((iface, _)) => vec![iface],
        None => (0..interfaces.len()).collect(),
    };
    let mut layout = bus_layout(&raw, &interfaces, &out, &invalid)?;
    layout.safety_io = safety_io.map(|(iface, node)| (iface, 0x180 + u16::from(node)));
    Ok(Drives {
        interfaces,
        safety_interfaces,
        safety_io,
        winches: out,
        layout,
    })
}

/// `[bus]`: one `transport` or `[[bus.interface]]` tables with distinct names.
fn drive_interfaces(bus: &RawBus, invalid: &Invalid<'_>) -> Result<Vec<Interface>, ConfigError> {
    let interfaces: Vec<Interface> = match (&bus.transport, bus.interfaces.is_empty()) {
        (Some(t), true) => vec![Interface {
            name: SINGLE_INTERFACE_NAME.into(),
            transport: t.clone(),
        }],
        (None, false) => bus
            .interfaces
            .iter()
            .map(|i| Interface {
                name: i.name.clone(),
                transport: i.transport.clone(),
            })
            .collect(),
        (None, true) => {
            return Err(invalid(
                "bus.transport".into(),
                "missing: bus.transport or [[bus.interface]] tables".into(),
            ));
        }
        (Some(_), false) => {
            return Err(invalid(
                "bus.transport".into(),
                "give either bus.transport or [[bus.interface]] tables, not both".into(),
            ));
        }
    };
    for (i, itf) in interfaces.iter().enumerate() {
        if interfaces[..i].iter().any(|o| o.name == itf.name) {
            return Err(invalid(
                format!("bus.interface[{i}].name"),
                format!("{:?} used twice", itf.name),
            ));
        }
    }
    Ok(interfaces)
}

/// The `[[winch]]` entries: interface, node id (unique per interface), the counts-to-length
/// scaling.
fn drive_winches(
    raw: &[RawWinch],
    interfaces: &[Interface],
    invalid: &Invalid<'_>,
) -> Result<Vec<Winch>, ConfigError> {
    let mut out: Vec<Winch> = Vec::with_capacity(raw.len());
    for (i, w) in raw.iter().enumerate() {
        let bad = |k: &str, r: &str| invalid(format!("winch[{i}].{k}"), r.to_string());
        let interface = match &w.interface {
            None if interfaces.len() == 1 => 0,
            None => {
                return Err(bad(
                    "interface",
                    "missing (the drives have several interfaces)",
                ));
            }
            Some(n) => interfaces
                .iter()
                .position(|itf| &itf.name == n)
                .ok_or_else(|| bad("interface", "no [[bus.interface]] of that name"))?,
        };
        if !(1..=127).contains(&w.node_id) {
            return Err(bad("node_id", "must be in 1..=127"));
        }
        if out
            .iter()
            .any(|o: &Winch| i64::from(o.node_id) == w.node_id && o.interface == interface)
        {
            return Err(bad("node_id", "used twice on one interface"));
        }
        for (k, v) in [
            ("drum_diameter_m", w.drum_diameter_m),
            ("gear_ratio", w.gear_ratio),
            ("counts_per_rev", w.counts_per_rev),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(k, "must be finite and > 0"));
            }
        }
        if w.sign != 1 && w.sign != -1 {
            return Err(bad("sign", "must be 1 or -1"));
        }
        out.push(Winch {
            interface,
            node_id: w.node_id as u8,
            counts_per_m: w.gear_ratio * w.counts_per_rev
                / (std::f64::consts::PI * w.drum_diameter_m),
            sign: w.sign as f64,
            offset_counts: w.offset_counts as f64,
        });
    }
    Ok(out)
}

/// An error of the drives file at a key.
type Invalid<'a> = dyn Fn(String, String) -> ConfigError + 'a;

/// The bytes of a PDO's objects in frame order: (index, sub, offset, value type); the error
/// names the object the monitor cannot decode.
fn pdo_objects(objects: &[String]) -> Result<Vec<(u16, u8, usize, Value)>, String> {
    let mut at = 0;
    let mut out = Vec::with_capacity(objects.len());
    for o in objects {
        let (i, sub) = parse_object(o)
            .ok_or_else(|| format!("{o:?}: not an object (0xIIII or 0xIIIIsubS)"))?;
        let v = object_value(i, sub).ok_or_else(|| {
            format!("{o:?}: the monitor decodes only drive-io's CSP and CiA 404 objects")
        })?;
        out.push((i, sub, at, v));
        at += v.bytes();
    }
    if at > 8 {
        return Err(format!("{at} bytes: more than a CAN frame carries"));
    }
    Ok(out)
}

/// A drive's force in its own TPDO: (COB-ID, frame length, offset, type).
type DriveForce = (u16, usize, usize, Value);

/// Each drive's RPDO (controlword + target) and each cable's force frame, as drive-io
/// configures them (docs/can-protocol.md), from the drives file's own keys.
fn bus_layout(
    raw: &RawDrives,
    interfaces: &[Interface],
    winches: &[Winch],
    invalid: &Invalid<'_>,
) -> Result<BusLayout, ConfigError> {
    let mut layout = BusLayout::default();
    for (i, (rw, w)) in raw.winches.iter().zip(winches).enumerate() {
        let (rpdo, drive_force) = drive_pdos(raw, i, rw, w, invalid)?;
        layout.rpdo.push(rpdo);
        if let Some((cob_id, len, at, value)) = drive_force {
            layout.force.push(ForceLayout {
                interface: w.interface,
                cob_id,
                len,
                at,
                value,
                n_per_unit: rw.force_n_per_unit.unwrap_or(0.001),
                node: w.node_id,
            });
            continue;
        }
        layout
            .force
            .push(load_cell(raw, i, rw, interfaces, invalid)?);
    }
    Ok(layout)
}

/// Winch `i`'s RPDO and, if the drive measures the cable's force, the TPDO carrying it.
fn drive_pdos(
    raw: &RawDrives,
    i: usize,
    rw: &RawWinch,
    w: &Winch,
    invalid: &Invalid<'_>,
) -> Result<(RpdoLayout, Option<DriveForce>), ConfigError> {
    let key = |k: &str| format!("winch[{i}].{k}");
    let n = u16::from(w.node_id);
    let mode = rw
        .mapping
        .as_deref()
        .unwrap_or(if rw.rpdo.is_empty() && rw.tpdo.is_empty() {
            "default"
        } else {
            "custom"
        });
    // The drive's force, if it measures it: (TPDO COB-ID, frame length, offset, type).
    let force_obj = match &rw.force_object {
        None => (0x2110, 0),
        Some(o) => parse_object(o)
            .ok_or_else(|| invalid(key("force_object"), format!("{o:?}: not an object")))?,
    };
    let force_by_drive = match &rw.force {
        Some(RawForce::Name(s)) if s == "drive" => true,
        Some(RawForce::Name(s)) => {
            return Err(invalid(
                key("force"),
                format!("{s:?}: \"drive\" or a node id"),
            ));
        }
        Some(RawForce::Node(_)) => false,
        None => !raw.force_sensors.iter().any(|s| s.cable == i as i64 + 1),
    };
    match mode {
        "default" => {
            let fv = object_value(force_obj.0, force_obj.1).ok_or_else(|| {
                invalid(key("force_object"), "the monitor cannot decode it".into())
            })?;
            Ok((
                RpdoLayout::default_for(w.interface, w.node_id),
                // TPDO2: velocity actual (i32), then the force object.
                force_by_drive.then_some((0x280 + n, 4 + fv.bytes(), 4, fv)),
            ))
        }
        "custom" => {
            let rpdo = custom_rpdo(i, rw, w, invalid)?;
            let force = if force_by_drive {
                Some(custom_force_tpdo(i, rw, n, force_obj, invalid)?)
            } else {
                None
            };
            Ok((rpdo, force))
        }
        other => Err(invalid(
            key("mapping"),
            format!(
                "{other:?}: the monitor decodes \"default\" and \"custom\" mappings only \
                 (a fixed mapping is in the drive's EDS, which the monitor does not read: \
                 write it out as mapping = \"custom\")"
            ),
        )),
    }
}

/// A custom mapping's RPDO: the one mapping both the controlword and the target position.
fn custom_rpdo(
    i: usize,
    rw: &RawWinch,
    w: &Winch,
    invalid: &Invalid<'_>,
) -> Result<RpdoLayout, ConfigError> {
    let n = u16::from(w.node_id);
    let mut rpdo = None;
    for (k, p) in rw.rpdo.iter().enumerate() {
        let objs = pdo_objects(&p.objects)
            .map_err(|r| invalid(format!("winch[{i}].rpdo[{k}].objects"), r))?;
        let cw = objs.iter().find(|o| (o.0, o.1) == (0x6040, 0));
        let t = objs.iter().find(|o| (o.0, o.1) == (0x607A, 0));
        if let (Some(cw), Some(t)) = (cw, t) {
            let cob = p
                .cob_id
                .map_or(0x200 + 0x100 * (p.number.clamp(1, 4) as u16 - 1) + n, |c| {
                    (c & 0x7FF) as u16
                });
            rpdo = Some(RpdoLayout {
                interface: w.interface,
                cob_id: cob,
                len: objs.iter().map(|o| o.3.bytes()).sum(),
                controlword_at: cw.2,
                target_at: t.2,
            });
        }
    }
    rpdo.ok_or_else(|| {
        invalid(
            format!("winch[{i}].rpdo"),
            "the monitor needs one RPDO mapping both 0x6040 and 0x607A".into(),
        )
    })
}

/// A custom mapping's TPDO carrying the drive's force object.
fn custom_force_tpdo(
    i: usize,
    rw: &RawWinch,
    n: u16,
    force_obj: (u16, u8),
    invalid: &Invalid<'_>,
) -> Result<DriveForce, ConfigError> {
    let mut force = None;
    for (k, p) in rw.tpdo.iter().enumerate() {
        let objs = pdo_objects(&p.objects)
            .map_err(|r| invalid(format!("winch[{i}].tpdo[{k}].objects"), r))?;
        if let Some(o) = objs.iter().find(|o| (o.0, o.1) == force_obj) {
            let cob = p
                .cob_id
                .map_or(0x180 + 0x100 * (p.number.clamp(1, 4) as u16 - 1) + n, |c| {
                    (c & 0x7FF) as u16
                });
            force = Some((cob, objs.iter().map(|o| o.3.bytes()).sum(), o.2, o.3));
        }
    }
    force.ok_or_else(|| {
        invalid(
            format!("winch[{i}].tpdo"),
            "force = \"drive\" but no [[winch.tpdo]] maps the force object".into(),
        )
    })
}

/// The load cell of winch `i`'s cable (a `[[force_sensor]]`, CiA 404).
fn load_cell(
    raw: &RawDrives,
    i: usize,
    rw: &RawWinch,
    interfaces: &[Interface],
    invalid: &Invalid<'_>,
) -> Result<ForceLayout, ConfigError> {
    let key = |k: &str| format!("winch[{i}].{k}");
    let (j, fs) = match &rw.force {
        Some(RawForce::Node(node)) => raw
            .force_sensors
            .iter()
            .enumerate()
            .find(|(_, s)| s.node_id == *node)
            .ok_or_else(|| {
                invalid(
                    key("force"),
                    format!("no [[force_sensor]] with node_id {node}"),
                )
            })?,
        _ => raw
            .force_sensors
            .iter()
            .enumerate()
            .find(|(_, s)| s.cable == i as i64 + 1)
            .ok_or_else(|| invalid(key("force"), "no force source".into()))?,
    };
    let skey = |k: &str| format!("force_sensor[{j}].{k}");
    if fs.mapping.as_deref().is_some_and(|m| m != "default") {
        return Err(invalid(
            skey("mapping"),
            "the monitor decodes the default mapping of a force sensor only".into(),
        ));
    }
    let (oi, os) = match &fs.object {
        None => (0x9130, 1),
        Some(o) => parse_object(o)
            .ok_or_else(|| invalid(skey("object"), format!("{o:?}: not an object")))?,
    };
    let value = object_value(oi, os)
        .ok_or_else(|| invalid(skey("object"), "not a CiA 404 process value".into()))?;
    if !(1..=127).contains(&fs.node_id) {
        return Err(invalid(skey("node_id"), "must be in 1..=127".into()));
    }
    if !(fs.n_per_unit.is_finite() && fs.n_per_unit != 0.0) {
        return Err(invalid(
            skey("n_per_unit"),
            "must be finite and not 0".into(),
        ));
    }
    let interface = match &fs.interface {
        None if interfaces.len() == 1 => 0,
        None => {
            return Err(invalid(
                skey("interface"),
                "missing (several interfaces)".into(),
            ));
        }
        Some(n) => interfaces
            .iter()
            .position(|i| &i.name == n)
            .ok_or_else(|| invalid(skey("interface"), format!("{n:?}: no such interface")))?,
    };
    let tpdo = fs.tpdo.unwrap_or(1).clamp(1, 4) as u16;
    Ok(ForceLayout {
        interface,
        cob_id: fs
            .cob_id
            .map_or(0x180 + 0x100 * (tpdo - 1) + fs.node_id as u16, |c| {
                (c & 0x7FF) as u16
            }),
        len: value.bytes(),
        at: 0,
        value,
        n_per_unit: fs.n_per_unit,
        node: fs.node_id as u8,
    })
}

/// SHA-256 of a file's bytes (the accepted-platform hash).
pub fn sha256_of(bytes: &[u8]) -> [u8; 32] {
    use sha2::Digest;
    sha2::Sha256::digest(bytes).into()
}

/// The monitor's limits from its configuration and its own reading of the platform.
impl From<&MonitorConfig> for safety_monitor_checks::Limits {
    fn from(c: &MonitorConfig) -> Self {
        use crate::capacity::{HISTORY, MAX_FORCE_WINDOW, MAX_GAP_WINDOW};
        use safety_monitor_checks::monitor::{ForceLimits, MotionCheck};
        let m = &c.monitor;
        Self {
            dq_limit_m: c.dq_limit_m(),
            silence_cycles: m.silence_cycles,
            max_missing_setpoints: m.max_missing_setpoints,
            gap_window_cycles: m.gap_window_cycles.min(MAX_GAP_WINDOW as u32),
            identity_grace_cycles: m.identity_grace_cycles,
            workspace: c
                .platform
                .workspace
                .widened(m.workspace_margin_m, m.workspace_margin_deg.to_radians()),
            reset_clear_cycles: m.reset_clear_cycles,
            check_following_error: c.feedback.check_following_error,
            following_error_m: c.feedback.following_error_mm * 1e-3,
            window_setpoints: c.feedback.window_setpoints.min(HISTORY as u32),
            feedback_silence_cycles: c.feedback.silence_cycles,
            unchecked_cycles: c.feedback.unchecked_cycles,
            check_rpdo: c.can.check_rpdo,
            require_ready: c.monitor.require_ready,
            forces: ForceLimits {
                check: c.forces.check,
                slack_below_n: c.platform.f_min_n - c.forces.slack_margin_n,
                overload_above_n: c.platform.f_max_n + c.forces.overload_margin_n,
                window_readings: c.forces.window_readings.clamp(1, MAX_FORCE_WINDOW),
                window_violations: c.forces.window_violations.max(1),
                hard_limit_n: c.forces.hard_limit_n,
                silence_cycles: c.forces.silence_cycles,
            },
            motion: {
                let k = 1.0 + c.motion.margin;
                let l = &c.platform.limits;
                MotionCheck {
                    check: c.motion.check,
                    period_s: c.motion.setpoint_period_ms * 1e-3,
                    linear_velocity: l.linear_velocity_m_per_s * k,
                    angular_velocity: l.angular_velocity_rad_per_s * k,
                    linear_acceleration: l.linear_acceleration_m_per_s2 * k,
                    angular_acceleration: l.angular_acceleration_rad_per_s2 * k,
                }
            },
            safety_io: c.safety_io.is_some(),
            safety_io_silence_cycles: c.can.safety_io_silence_cycles,
        }
    }
}
