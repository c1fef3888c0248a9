//! Drive bus configuration (config/drives.toml): transport, timing, per-winch scaling. One
//! reader for every process on the drive bus: drive-io's master, the simulated plant, the
//! winch emulator and the stack.

mod winch;

pub use winch::{Parameter, ParameterValue, validate_winch, winch_mapping_mode};

use can_transport::TransportSpec;
use crs_limits::MAX_CABLES;
use drive_bus::force_sensor::{ForceSensorConfig, ForceSource};
use drive_bus::identity::Identity;
use drive_bus::mapping::{MappingMode, ObjectRef, PdoSpec};
use serde::Deserialize;
use std::f64::consts::PI;

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: {source}")]
    Read {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("drives TOML: {0}")]
    Parse(String),
    #[error("drives TOML: field `{field}`: {reason}")]
    Invalid { field: String, reason: String },
}

fn invalid(field: impl Into<String>, reason: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        field: field.into(),
        reason: reason.into(),
    }
}

pub use drive_bus::canopen::MAX_INTERFACES;

/// One CAN interface of the drive bus system (`[[bus.interface]]`): its transport, bit rate and
/// load budget. The drives on it are the `[[winch]]` entries naming it.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct InterfaceConfig {
    /// Name the `[[winch]]` entries refer to (`interface = "can0"`), unique.
    pub name: String,
    /// `socketcan:<iface>`, `udpbus:<group>:<port>`, `udp:<local>-><remote>`, `wire:<socket>`.
    pub transport: String,
    /// Nominal bit rate of the interface (classic CAN: at most 1 Mbit/s), bit/s.
    #[serde(default = "d_bitrate")]
    pub bitrate_bit_per_s: u32,
    /// Load budget: the configuration's frames may fill at most this share of the bus
    /// (worst-case bit stuffing, [`drive_commissioning::budget`]); may be set below the default, never above.
    #[serde(default = "d_budget")]
    pub budget_percent: f64,
}

fn d_bitrate() -> u32 {
    1_000_000
}
/// The largest load budget any interface may have, percent of the bit rate.
pub const MAX_BUDGET_PERCENT: f64 = 70.0;
fn d_budget() -> f64 {
    MAX_BUDGET_PERCENT
}

/// Name of the one interface of a configuration that gives only `bus.transport`.
pub const SINGLE_INTERFACE_NAME: &str = "can0";

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BusConfig {
    /// Shorthand for a single interface: `socketcan:<iface>`, `udpbus:<group>:<port>`,
    /// `udp:<local>-><remote>`, `wire:<socket>` (named [`SINGLE_INTERFACE_NAME`], 1 Mbit/s).
    /// Exactly one of `transport` and `[[bus.interface]]` is given.
    #[serde(default)]
    pub transport: Option<String>,
    /// The CAN interfaces (`[[bus.interface]]`), when there are several.
    #[serde(default, rename = "interface")]
    pub interfaces: Vec<InterfaceConfig>,
    /// SYNC period (µs); 1000 = the 1 ms loop of thesis §5.6.
    #[serde(default = "d_sync")]
    pub sync_period_us: u32,
    /// Quick stop if no new setpoint arrived for more than this many SYNC cycles.
    #[serde(default = "d_stale")]
    pub stale_setpoint_cycles: u32,
    /// Heartbeat producer time written to every drive's 0x1017 (ms).
    #[serde(default = "d_hb_prod")]
    pub heartbeat_producer_ms: u16,
    /// Heartbeat consumer timeout (ms): a drive silent this long faults the bus.
    #[serde(default = "d_hb_timeout")]
    pub heartbeat_timeout_ms: u32,
    /// Time allowed for NMT boot, SDO configuration and the CiA 402 enable sequence (ms).
    #[serde(default = "d_boot")]
    pub boot_timeout_ms: u32,
    /// Time allowed per SDO transfer (ms); retried up to 3 times.
    #[serde(default = "d_sdo")]
    pub sdo_timeout_ms: u32,
    /// Largest accepted cable speed implied by consecutive setpoints (m/s); faster = fault.
    #[serde(default = "d_vmax")]
    pub max_cable_speed_m_per_s: f64,
    /// Largest accepted change of a cable's speed between consecutive setpoint steps (m/s²),
    /// from rest too: a hold is zero speed, so a stream that jumps from rest to a plausible
    /// speed faults (`SETPOINT_STEP`) instead of jerking the cabin at the drives' torque limit.
    /// Braking (towards zero, without reversing) is never limited. Above the platform's cable
    /// accelerations at the table 5.1 limits (|a| + |α| r + ω² r + v²/L: about 30 m/s² on the
    /// CRS) with margin.
    #[serde(default = "d_amax")]
    pub max_cable_acceleration_m_per_s2: f64,
    /// Hard limit of a drive's measured cable force (TPDO2 pulley force), N: one reading above
    /// it (or below −limit, a broken sensor) quick-stops all drives — drive-io's own channel,
    /// independent of the safety monitor's force supervision (the winches' rating, 14 kN).
    #[serde(default = "d_force_limit")]
    pub force_hard_limit_n: f64,
    /// Optional candump log of every frame.
    #[serde(default)]
    pub candump_log: Option<String>,
    /// The drives' EDS (CiA 306), one model for all winches of the bus; relative to the
    /// drives TOML's directory. Absent = the simulated winch's (config/eds/crs-winch.eds).
    #[serde(default)]
    pub eds: Option<String>,
    /// Optional directory for the DCF of every configured drive (`node<NN>.dcf`).
    #[serde(default)]
    pub dcf_dir: Option<String>,
    /// drive-io's own node id: its heartbeat (0x700 + id) is what the drives consume.
    #[serde(default = "d_master_id")]
    pub master_node_id: u8,
    /// drive-io's heartbeat producer period (ms).
    #[serde(default = "d_master_hb")]
    pub master_heartbeat_ms: u16,
    /// Written to each drive's 0x1016 sub 1: the drive acts per 0x6007 when drive-io's
    /// heartbeat is silent this long (ms). 0 = not configured; absent = twice
    /// `heartbeat_timeout_ms` (the drives are as patient with drive-io as it is with them,
    /// plus the producer's jitter) — see [`BusConfig::drive_consumer_ms`].
    #[serde(default)]
    pub drive_heartbeat_consumer_ms: Option<u16>,
    /// Written to each drive's 0x6007 (CiA 402 abort connection option code: 0 no action,
    /// 1 fault, 2 disable voltage (the brake holds), 3 quick stop). Acts on NMT stop (the
    /// safety monitor's e-stop) and on the loss of drive-io's heartbeat.
    #[serde(default = "d_abort")]
    pub abort_connection_option: i16,
    /// Written to each drive's 0x6065 (following error window), in metres of cable.
    #[serde(default = "d_following")]
    pub following_error_window_m: f64,
    /// A commanded quick stop must be acknowledged (statusword Quick Stop Active) and the
    /// drives at rest within this time (ms), else drive-io escalates (NMT stop, then stops
    /// its heartbeat).
    #[serde(default = "d_qs_timeout")]
    pub quick_stop_timeout_ms: u32,
    /// What times the cycle (docs/can-protocol.md "Cycle timing"): `isochronous` (default) =
    /// drive-io's SYNC is the bus clock, strictly periodic; it announces its schedule, motion-core
    /// ticks `sync_lead_us` before each SYNC and drive-io sends the RPDOs as soon as the setpoint
    /// arrives (at the latest `rpdo_guard_us` before the SYNC, holding); `setpoint` = RPDOs and
    /// SYNC start on motion-core's "setpoint published" notification (own clock as fallback after
    /// `setpoint_wait_us`); `clock` = drive-io's free-running timer sends RPDOs then SYNC.
    #[serde(default)]
    pub sync_source: SyncSource,
    /// With `sync_source = "setpoint"`: how long past its nominal tick drive-io waits for the
    /// setpoint before it sends SYNC on its own clock (µs, < sync_period_us / 2).
    #[serde(default = "d_setpoint_wait")]
    pub setpoint_wait_us: u32,
    /// With `sync_source = "isochronous"`: the RPDOs of a cycle are sent at the latest this long
    /// before the SYNC they belong to (µs) — holding the last target if no new setpoint came —
    /// so they are off the wire before it (the bus budget's worst-case RPDO window must fit).
    #[serde(default = "d_rpdo_guard")]
    pub rpdo_guard_us: u32,
    /// With `sync_source = "isochronous"`: drive-io sleeps until this long before each SYNC and
    /// then waits actively, so the SYNC leaves at its instant (timer wake-up jitter is tens of
    /// µs even with SCHED_FIFO). 0 = no active wait.
    #[serde(default = "d_sync_spin")]
    pub sync_spin_us: u32,
    /// The cable deceleration of a quick stop (m/s²), written to every drive's 0x6085 in
    /// counts/s² (0x605A = 6 ramps down on it). Default: the CRS's 14 m/s² (thesis table 5.1).
    #[serde(default = "d_qs_decel")]
    pub quick_stop_deceleration_m_per_s2: f64,
}

fn d_qs_decel() -> f64 {
    14.0
}

/// What starts drive-io's cycle ([`BusConfig::sync_source`], [`drive_io::sync_clock`]).
#[derive(Debug, Clone, Copy, Default, Deserialize, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SyncSource {
    /// drive-io's SYNC is the bus clock (strictly periodic, announced); RPDOs on the setpoint.
    #[default]
    Isochronous,
    /// Phase-locked to motion-core's setpoint stream (own clock as fallback).
    Setpoint,
    /// drive-io's own free-running timer.
    Clock,
}

impl SyncSource {
    pub fn name(self) -> &'static str {
        match self {
            Self::Isochronous => "isochronous",
            Self::Setpoint => "setpoint",
            Self::Clock => "clock",
        }
    }
}

impl std::str::FromStr for SyncSource {
    type Err = UnknownSyncSource;
    fn from_str(s: &str) -> Result<Self, UnknownSyncSource> {
        match s {
            "isochronous" => Ok(Self::Isochronous),
            "setpoint" => Ok(Self::Setpoint),
            "clock" => Ok(Self::Clock),
            _ => Err(UnknownSyncSource(s.to_string())),
        }
    }
}

/// A `sync_source` name that is not one of the three (the name as given).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0:?}: expected \"isochronous\", \"setpoint\" or \"clock\"")]
pub struct UnknownSyncSource(pub String);

fn d_rpdo_guard() -> u32 {
    // Two drives' RPDOs (2 × 115 bit) plus a frame in transmission (135 bit) at 1 Mbit/s is
    // 365 µs; 400 µs leaves the cycle's RPDOs off the wire before the SYNC.
    400
}

fn d_sync_spin() -> u32 {
    100
}

fn d_setpoint_wait() -> u32 {
    // A quarter period: past motion-core's usual lateness on a loaded host (loop lateness p99
    // 150-200 µs in `crs sim`), short enough that a stalled stream costs the drives at most
    // that much SYNC jitter once.
    250
}

fn d_master_id() -> u8 {
    0x7F
}
fn d_master_hb() -> u16 {
    10
}
fn d_abort() -> i16 {
    2
}
fn d_following() -> f64 {
    // 100 mm: far beyond a healthy CSP drive's lag (one period of motion, ≤ 5 mm at 5 m/s),
    // tolerant of irregular setpoint arrival on a non-real-time host.
    0.1
}
fn d_qs_timeout() -> u32 {
    1000
}

impl BusConfig {
    /// The consumer heartbeat time written to the drives' 0x1016 (ms; 0 = none).
    pub fn drive_consumer_ms(&self) -> u16 {
        self.drive_heartbeat_consumer_ms.unwrap_or_else(|| {
            u16::try_from(self.heartbeat_timeout_ms.saturating_mul(2)).unwrap_or(u16::MAX)
        })
    }
}

fn d_sync() -> u32 {
    1000
}
fn d_stale() -> u32 {
    10
}
fn d_hb_prod() -> u16 {
    10
}
fn d_hb_timeout() -> u32 {
    100
}
fn d_boot() -> u32 {
    5000
}
fn d_sdo() -> u32 {
    100
}
fn d_vmax() -> f64 {
    5.0
}
fn d_amax() -> f64 {
    50.0
}
/// Upper bounds of the adapter's safety-relevant limits (a value beyond them switches its check
/// off in practice): cable speed (the CRS winches: 5 m/s), cable acceleration, the force hard
/// limit (the seed's winches are rated 14 kN), the stale-setpoint time.
pub const MAX_CABLE_SPEED_BOUND_M_PER_S: f64 = 10.0;
pub const MAX_CABLE_ACCELERATION_BOUND_M_PER_S2: f64 = 200.0;
pub const FORCE_HARD_LIMIT_BOUND_N: f64 = 20_000.0;
pub const STALE_SETPOINT_BOUND_MS: u64 = 500;
fn d_force_limit() -> f64 {
    14_000.0
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WinchConfig {
    /// The `[[bus.interface]]` the drive is on (may be omitted with a single interface).
    #[serde(default)]
    pub interface: Option<String>,
    /// CANopen node id (1..=127), unique on its interface.
    pub node_id: u8,
    /// Drum diameter (m); one drum revolution winds π·d of cable.
    pub drum_diameter_m: f64,
    /// Motor revolutions per drum revolution.
    pub gear_ratio: f64,
    /// Encoder counts per motor revolution.
    pub counts_per_rev: f64,
    /// +1 if counts increase when the cable gets longer, -1 otherwise.
    pub sign: i8,
    /// Encoder counts at cable length 0 m.
    #[serde(default)]
    pub offset_counts: i64,
    /// Largest cable length this winch may be commanded to (m); also bounds the i32 count range.
    #[serde(default = "d_lmax")]
    pub max_cable_length_m: f64,
    /// This drive's EDS (relative to the TOML); absent = `bus.eds`, else the simulated winch's.
    #[serde(default)]
    pub eds: Option<String>,
    /// Device type / identity / device name the drive must report before it is configured.
    #[serde(default)]
    pub identity: Identity,
    /// `"default"` (drive-io writes its CSP mapping), `"fixed"` (the drive's, from its EDS) or
    /// `"custom"` (the `rpdo` / `tpdo` lists). Absent: custom with lists, else default.
    #[serde(default)]
    pub mapping: Option<MappingMode>,
    /// `[[winch.rpdo]]`: a custom RPDO mapping (controlword 0x6040, target 0x607A).
    #[serde(default)]
    pub rpdo: Vec<PdoSpec>,
    /// `[[winch.tpdo]]`: a custom TPDO mapping (0x6041, 0x6064, 0x606C, the force object).
    #[serde(default)]
    pub tpdo: Vec<PdoSpec>,
    /// Where the cable force comes from: `"drive"` (its `force_object`) or the node id of a
    /// `[[force_sensor]]`. Absent: the force sensor of this cable if there is one, else the drive.
    #[serde(default)]
    pub force: Option<ForceSource>,
    /// The drive's force object (with `force = "drive"`); default 0x2110sub0.
    #[serde(default)]
    pub force_object: Option<ObjectRef>,
    /// Newtons per unit of `force_object` (default 0.001: mN).
    #[serde(default)]
    pub force_n_per_unit: Option<f64>,
    /// Default mapping: velocity actual (TPDO2) every n-th SYNC. Default 10, or 1 when TPDO2
    /// also carries the drive's force (drive-io's hard force limit needs it every SYNC).
    #[serde(default)]
    pub feedback_every_n_syncs: Option<u8>,
    /// Vendor parameters written at start-up (after the PDOs, before the mode) and read back.
    #[serde(default)]
    pub parameters: Vec<Parameter>,
}

fn d_lmax() -> f64 {
    30.0
}

impl WinchConfig {
    pub fn counts_per_m(&self) -> f64 {
        self.gear_ratio * self.counts_per_rev / (PI * self.drum_diameter_m)
    }
    /// Cable length (m) -> encoder counts (rounded). `None` if out of [0, max] or not finite.
    pub fn length_to_counts(&self, length_m: f64) -> Option<i32> {
        if !length_m.is_finite() || length_m < 0.0 || length_m > self.max_cable_length_m {
            return None;
        }
        let c = self.offset_counts as f64 + f64::from(self.sign) * length_m * self.counts_per_m();
        let c = c.round();
        (c >= f64::from(i32::MIN) && c <= f64::from(i32::MAX)).then_some(c as i32)
    }
    pub fn counts_to_length(&self, counts: i32) -> f64 {
        (f64::from(counts) - self.offset_counts as f64) * f64::from(self.sign) / self.counts_per_m()
    }
    pub fn counts_per_s_to_m_per_s(&self, v: i32) -> f64 {
        f64::from(v) * f64::from(self.sign) / self.counts_per_m()
    }
    pub fn m_per_s_to_counts_per_s(&self, v: f64) -> i32 {
        (v * f64::from(self.sign) * self.counts_per_m())
            .round()
            .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
    }
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DrivesConfig {
    pub bus: BusConfig,
    #[serde(rename = "winch")]
    pub winches: Vec<WinchConfig>,
    /// `[safety_heartbeat]`: validate the safety monitor's doubled heartbeat and its
    /// configuration signature, and stop without them (see [`drive_bus::safety_watch`]). Parsed as
    /// optional so the drive side and tests can run without it, but the drive-io daemon refuses
    /// to start without it ([`DrivesConfig::require_safety_heartbeat`]).
    #[serde(default)]
    pub safety_heartbeat: Option<drive_bus::safety_watch::SafetyWatchConfig>,
    /// `[[force_sensor]]`: force-measuring nodes (one per pulley load cell, CiA 404).
    #[serde(default, rename = "force_sensor")]
    pub force_sensors: Vec<ForceSensorConfig>,
    /// `[safety_io]`: the safety I/O node that removes the drives' torque (STO) when the
    /// monitor's heartbeat is missing or says STOP (see [`SafetyIoConfig`]).
    #[serde(default)]
    pub safety_io: Option<SafetyIoConfig>,
    /// Directory of the TOML file (set by [`DrivesConfig::load`]): relative paths resolve here.
    #[serde(skip)]
    pub base_dir: Option<std::path::PathBuf>,
}

impl DrivesConfig {
    pub fn load(path: &std::path::Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        let mut cfg = Self::parse(&text)?;
        cfg.base_dir = path.parent().map(std::path::Path::to_path_buf);
        Ok(cfg)
    }

    /// A path from the TOML, relative to the TOML's directory.
    pub fn resolve(&self, p: &str) -> std::path::PathBuf {
        let p = std::path::Path::new(p);
        match &self.base_dir {
            Some(d) if p.is_relative() => d.join(p),
            _ => p.to_path_buf(),
        }
    }

    /// The drives' EDS (`bus.eds`, else the simulated winch's built-in one).
    pub fn load_eds(&self) -> Result<drive_bus::eds::Eds, drive_bus::eds::EdsError> {
        match &self.bus.eds {
            Some(p) => drive_bus::eds::Eds::load(&self.resolve(p)),
            None => Ok(drive_bus::eds::Eds::builtin_winch().clone()),
        }
    }

    /// The EDS of winch `i` (`winch[i].eds`, else `bus.eds`, else the simulated winch's).
    pub fn load_winch_eds(
        &self,
        i: usize,
    ) -> Result<drive_bus::eds::Eds, drive_bus::eds::EdsError> {
        match self.winches.get(i).and_then(|w| w.eds.as_ref()) {
            Some(p) => drive_bus::eds::Eds::load(&self.resolve(p)),
            None => self.load_eds(),
        }
    }

    /// The EDS of force sensor `j` (`force_sensor[j].eds`, else the built-in CiA 404 load cell).
    pub fn load_sensor_eds(
        &self,
        j: usize,
    ) -> Result<drive_bus::eds::Eds, drive_bus::eds::EdsError> {
        match self.force_sensors.get(j).and_then(|s| s.eds.as_ref()) {
            Some(p) => drive_bus::eds::Eds::load(&self.resolve(p)),
            None => Ok(drive_bus::eds::Eds::builtin_load_cell().clone()),
        }
    }

    /// Where cable `i`'s (0-based) force comes from: the index of its `[[force_sensor]]`, or
    /// None for the drive's own force object.
    pub fn force_sensor_of(&self, i: usize) -> Option<usize> {
        match self.winches.get(i)?.force {
            Some(ForceSource::Drive) => None,
            Some(ForceSource::Sensor(n)) => self.force_sensors.iter().position(|s| s.node_id == n),
            None => self.force_sensors.iter().position(|s| s.cable == i + 1),
        }
    }

    /// Parses and validates; nothing is returned unless everything is valid.
    pub fn parse(text: &str) -> Result<Self, ConfigError> {
        let cfg: Self = toml::from_str(text).map_err(|e| ConfigError::Parse(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The CAN interfaces: `[[bus.interface]]`, or the one named [`SINGLE_INTERFACE_NAME`]
    /// that `bus.transport` describes.
    pub fn interfaces(&self) -> Vec<InterfaceConfig> {
        match &self.bus.transport {
            Some(t) if self.bus.interfaces.is_empty() => vec![InterfaceConfig {
                name: SINGLE_INTERFACE_NAME.to_string(),
                transport: t.clone(),
                bitrate_bit_per_s: d_bitrate(),
                budget_percent: d_budget(),
            }],
            _ => self.bus.interfaces.clone(),
        }
    }

    /// The transport of every interface, in `interfaces()` order.
    pub fn transports(&self) -> Result<Vec<TransportSpec>, ConfigError> {
        let single = self.bus.interfaces.is_empty();
        self.interfaces()
            .iter()
            .enumerate()
            .map(|(i, itf)| {
                itf.transport
                    .parse()
                    .map_err(|e: can_transport::SpecError| {
                        let key = if single {
                            "bus.transport".to_string()
                        } else {
                            format!("bus.interface[{i}].transport")
                        };
                        invalid(key, e.to_string())
                    })
            })
            .collect()
    }

    /// The transport of a configuration with exactly one interface (test rigs that run one bus).
    pub fn transport(&self) -> Result<TransportSpec, ConfigError> {
        let mut t = self.transports()?;
        if t.len() != 1 {
            return Err(invalid(
                "bus.interface",
                format!(
                    "this tool runs one CAN interface, the configuration has {}",
                    t.len()
                ),
            ));
        }
        Ok(t.remove(0))
    }

    /// Index (in `interfaces()` order) of the interface of winch `i`.
    pub fn winch_interface(&self, i: usize) -> usize {
        let itfs = self.interfaces();
        self.winches
            .get(i)
            .and_then(|w| w.interface.as_deref())
            .and_then(|n| itfs.iter().position(|itf| itf.name == n))
            .unwrap_or(0)
    }

    /// Index (in `interfaces()` order) of the interface of force sensor `j`.
    pub fn sensor_interface(&self, j: usize) -> usize {
        let itfs = self.interfaces();
        self.force_sensors
            .get(j)
            .and_then(|s| s.interface.as_deref())
            .and_then(|n| itfs.iter().position(|itf| itf.name == n))
            .unwrap_or(0)
    }

    /// Interfaces on which the safety monitor's doubled frames travel: the safety I/O node's
    /// with `[safety_io]`, else every interface (indices into `interfaces()`).
    pub fn safety_frame_interfaces(&self) -> Vec<usize> {
        let itfs = self.interfaces();
        match &self.safety_io {
            Some(io) => itfs
                .iter()
                .position(|i| i.name == io.interface)
                .into_iter()
                .collect(),
            None => (0..itfs.len()).collect(),
        }
    }

    /// Index of the safety I/O node's interface.
    pub fn safety_io_interface(&self) -> Option<usize> {
        let io = self.safety_io.as_ref()?;
        self.interfaces()
            .iter()
            .position(|i| i.name == io.interface)
    }

    /// Replaces interface transports from command-line overrides: `NAME=SPEC` per interface,
    /// or a bare `SPEC` when the configuration has a single interface. Validates the result.
    pub fn override_transports(&mut self, overrides: &[String]) -> Result<(), ConfigError> {
        if overrides.is_empty() {
            return Ok(());
        }
        for o in overrides {
            match o.split_once('=') {
                Some((name, spec)) if !name.contains(':') => {
                    if self.bus.interfaces.is_empty() {
                        if name != SINGLE_INTERFACE_NAME {
                            return Err(invalid(
                                "--transport",
                                format!(
                                    "{name:?}: the configuration has one interface, named \
                                     {SINGLE_INTERFACE_NAME:?}"
                                ),
                            ));
                        }
                        self.bus.transport = Some(spec.to_string());
                    } else {
                        let itf = self
                            .bus
                            .interfaces
                            .iter_mut()
                            .find(|i| i.name == name)
                            .ok_or_else(|| {
                                invalid(
                                    "--transport",
                                    format!("{name:?}: no [[bus.interface]] of that name"),
                                )
                            })?;
                        itf.transport = spec.to_string();
                    }
                }
                _ if self.interfaces().len() == 1 => {
                    if self.bus.interfaces.is_empty() {
                        self.bus.transport = Some(o.clone());
                    } else {
                        self.bus.interfaces[0].transport = o.clone();
                    }
                }
                _ => {
                    return Err(invalid(
                        "--transport",
                        format!(
                            "{o:?}: with several interfaces give NAME=SPEC for each (names: {})",
                            self.interfaces()
                                .iter()
                                .map(|i| i.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    ));
                }
            }
        }
        self.validate()
    }

    fn validate_interfaces(&self) -> Result<(), ConfigError> {
        let b = &self.bus;
        match (&b.transport, b.interfaces.is_empty()) {
            (None, true) => {
                return Err(invalid(
                    "bus.transport",
                    "missing: give bus.transport (one interface) or [[bus.interface]] tables",
                ));
            }
            (Some(_), false) => {
                return Err(invalid(
                    "bus.transport",
                    "give either bus.transport (one interface) or [[bus.interface]] tables, not both",
                ));
            }
            _ => {}
        }
        let itfs = self.interfaces();
        if itfs.len() > MAX_INTERFACES {
            return Err(invalid(
                "bus.interface",
                format!("at most {MAX_INTERFACES} interfaces, got {}", itfs.len()),
            ));
        }
        let specs = self.transports()?;
        for (i, itf) in itfs.iter().enumerate() {
            let key = |k: &str| {
                if b.interfaces.is_empty() {
                    format!("bus.{k}")
                } else {
                    format!("bus.interface[{i}].{k}")
                }
            };
            if itf.name.is_empty()
                || !itf
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
            {
                return Err(invalid(
                    key("name"),
                    format!("{:?}: must be non-empty letters, digits, - or _", itf.name),
                ));
            }
            if itfs[..i].iter().any(|o| o.name == itf.name) {
                return Err(invalid(key("name"), format!("{:?} used twice", itf.name)));
            }
            if specs[..i].contains(&specs[i]) {
                return Err(invalid(
                    key("transport"),
                    format!("{} is also the transport of another interface", specs[i]),
                ));
            }
            if !(10_000..=1_000_000).contains(&itf.bitrate_bit_per_s) {
                return Err(invalid(
                    key("bitrate_bit_per_s"),
                    "must be in 10000..=1000000 (classic CAN)",
                ));
            }
            if !(itf.budget_percent.is_finite()
                && itf.budget_percent > 0.0
                && itf.budget_percent <= MAX_BUDGET_PERCENT)
            {
                return Err(invalid(
                    key("budget_percent"),
                    format!(
                        "must be > 0 and <= {MAX_BUDGET_PERCENT} (it may be set below the \
                         default, never above)"
                    ),
                ));
            }
        }
        for (i, w) in self.winches.iter().enumerate() {
            match &w.interface {
                None if itfs.len() > 1 => {
                    return Err(invalid(
                        format!("winch[{i}].interface"),
                        "missing: with several [[bus.interface]] tables every winch names its interface",
                    ));
                }
                Some(n) if !itfs.iter().any(|itf| &itf.name == n) => {
                    return Err(invalid(
                        format!("winch[{i}].interface"),
                        format!(
                            "{n:?}: no such interface (interfaces: {})",
                            itfs.iter()
                                .map(|i| i.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    ));
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Every section checked, in this order (the first error found is reported).
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.validate_interfaces()?;
        self.validate_bus_timing()?;
        self.validate_bus_limits()?;
        if self.winches.is_empty() || self.winches.len() > MAX_CABLES {
            return Err(invalid(
                "winch",
                format!(
                    "need 1..={MAX_CABLES} [[winch]] entries, got {}",
                    self.winches.len()
                ),
            ));
        }
        self.validate_safety()?;
        self.validate_winches()?;
        let b = &self.bus;
        if !(b.quick_stop_deceleration_m_per_s2.is_finite()
            && b.quick_stop_deceleration_m_per_s2 > 0.0)
        {
            return Err(invalid(
                "bus.quick_stop_deceleration_m_per_s2",
                "must be finite and > 0",
            ));
        }
        self.validate_force_sensors()
    }

    /// `[bus]`: the SYNC period and what is timed in it, heartbeats, boot and SDO timeouts.
    fn validate_bus_timing(&self) -> Result<(), ConfigError> {
        let b = &self.bus;
        if !(250..=100_000).contains(&b.sync_period_us) {
            return Err(invalid("bus.sync_period_us", "must be in 250..=100000"));
        }
        if b.rpdo_guard_us == 0 || b.rpdo_guard_us > b.sync_period_us / 2 {
            return Err(invalid(
                "bus.rpdo_guard_us",
                "must be > 0 and <= bus.sync_period_us / 2",
            ));
        }
        if b.sync_spin_us >= b.sync_period_us / 4 {
            return Err(invalid(
                "bus.sync_spin_us",
                "must be < bus.sync_period_us / 4",
            ));
        }
        if b.setpoint_wait_us == 0 || b.setpoint_wait_us >= b.sync_period_us / 2 {
            return Err(invalid(
                "bus.setpoint_wait_us",
                "must be > 0 and < bus.sync_period_us / 2",
            ));
        }
        if b.stale_setpoint_cycles == 0
            || u64::from(b.stale_setpoint_cycles) * u64::from(b.sync_period_us)
                > STALE_SETPOINT_BOUND_MS * 1000
        {
            return Err(invalid(
                "bus.stale_setpoint_cycles",
                format!(
                    "must be >= 1 and at most {STALE_SETPOINT_BOUND_MS} ms of SYNC periods \
                     (a longer stale time lets a dead motion loop's last setpoint stand)"
                ),
            ));
        }
        if b.heartbeat_producer_ms == 0 {
            return Err(invalid("bus.heartbeat_producer_ms", "must be >= 1"));
        }
        if b.heartbeat_timeout_ms <= u32::from(b.heartbeat_producer_ms) {
            return Err(invalid(
                "bus.heartbeat_timeout_ms",
                "must exceed bus.heartbeat_producer_ms",
            ));
        }
        if b.boot_timeout_ms == 0 || b.sdo_timeout_ms == 0 {
            return Err(invalid(
                "bus.boot_timeout_ms/sdo_timeout_ms",
                "must be >= 1",
            ));
        }
        Ok(())
    }

    /// `[bus]`: force, speed and acceleration bounds, drive-io's node and heartbeat, the drives' safety functions (0x1016 consumer, 0x6007), following error, quick stop timeout.
    fn validate_bus_limits(&self) -> Result<(), ConfigError> {
        let b = &self.bus;
        if !(b.force_hard_limit_n > 0.0 && b.force_hard_limit_n <= FORCE_HARD_LIMIT_BOUND_N) {
            return Err(invalid(
                "bus.force_hard_limit_n",
                format!("must be in (0, {FORCE_HARD_LIMIT_BOUND_N}] N"),
            ));
        }
        if !(b.max_cable_speed_m_per_s > 0.0
            && b.max_cable_speed_m_per_s <= MAX_CABLE_SPEED_BOUND_M_PER_S)
        {
            return Err(invalid(
                "bus.max_cable_speed_m_per_s",
                format!("must be in (0, {MAX_CABLE_SPEED_BOUND_M_PER_S}] m/s"),
            ));
        }
        if !(b.max_cable_acceleration_m_per_s2 > 0.0
            && b.max_cable_acceleration_m_per_s2 <= MAX_CABLE_ACCELERATION_BOUND_M_PER_S2)
        {
            return Err(invalid(
                "bus.max_cable_acceleration_m_per_s2",
                format!("must be in (0, {MAX_CABLE_ACCELERATION_BOUND_M_PER_S2}] m/s²"),
            ));
        }
        if !(1..=127).contains(&b.master_node_id)
            || self.winches.iter().any(|w| w.node_id == b.master_node_id)
        {
            return Err(invalid(
                "bus.master_node_id",
                "must be in 1..=127 and not a winch's node id",
            ));
        }
        if b.master_heartbeat_ms == 0 {
            return Err(invalid("bus.master_heartbeat_ms", "must be >= 1"));
        }
        // The drives' watch of drive-io's heartbeat (0x1016) and their action on its loss or
        // an NMT stop (0x6007) are safety functions: off (0 = no consumer, 0 = no action) is
        // refused.
        if b.drive_consumer_ms() <= b.master_heartbeat_ms {
            return Err(invalid(
                "bus.drive_heartbeat_consumer_ms",
                "must exceed bus.master_heartbeat_ms (0 = off is refused: a drive must act \
                 when drive-io's heartbeat stops)",
            ));
        }
        if !(1..=3).contains(&b.abort_connection_option) {
            return Err(invalid(
                "bus.abort_connection_option",
                "must be 1 (fault), 2 (disable voltage) or 3 (quick stop); 0 (no action) is \
                 refused: the monitor's NMT stop and the loss of drive-io's heartbeat must act",
            ));
        }
        if !(b.following_error_window_m.is_finite() && b.following_error_window_m > 0.0) {
            return Err(invalid(
                "bus.following_error_window_m",
                "must be finite and > 0",
            ));
        }
        if b.quick_stop_timeout_ms == 0 {
            return Err(invalid("bus.quick_stop_timeout_ms", "must be >= 1"));
        }
        Ok(())
    }

    /// `[safety_heartbeat]` and `[safety_io]`.
    fn validate_safety(&self) -> Result<(), ConfigError> {
        let b = &self.bus;
        if let Some(sh) = &self.safety_heartbeat {
            sh.validate()
                .map_err(|(field, reason)| invalid(field, reason))?;
        }
        if let Some(io) = &self.safety_io {
            let Some(itf) = self.safety_io_interface() else {
                return Err(invalid(
                    "safety_io.interface",
                    format!("{:?}: no such interface", io.interface),
                ));
            };
            if self.safety_heartbeat.is_none() {
                return Err(invalid(
                    "safety_io",
                    "needs [safety_heartbeat]: the node validates the monitor's heartbeat with it",
                ));
            }
            if !(1..=127).contains(&io.node_id)
                || io.node_id == b.master_node_id
                || (0..self.winches.len()).any(|i| {
                    self.winches[i].node_id == io.node_id && self.winch_interface(i) == itf
                })
            {
                return Err(invalid(
                    "safety_io.node_id",
                    "must be in 1..=127, not drive-io's node id nor a drive's on its interface",
                ));
            }
            if io.inputs_period_ms == 0 || io.heartbeat_ms == 0 {
                return Err(invalid(
                    "safety_io.inputs_period_ms/heartbeat_ms",
                    "must be >= 1",
                ));
            }
        }
        Ok(())
    }

    /// Every `[[winch]]`: node id, scaling, position range, mapping, force source, parameters.
    fn validate_winches(&self) -> Result<(), ConfigError> {
        for (i, w) in self.winches.iter().enumerate() {
            let f = |name: &str| format!("winch[{i}].{name}");
            if !(1..=127).contains(&w.node_id) {
                return Err(invalid(f("node_id"), "must be in 1..=127"));
            }
            let itf = self.winch_interface(i);
            if (0..i)
                .any(|o| self.winches[o].node_id == w.node_id && self.winch_interface(o) == itf)
            {
                return Err(invalid(
                    f("node_id"),
                    format!("node id {} used twice on one interface", w.node_id),
                ));
            }
            for (name, v) in [
                ("drum_diameter_m", w.drum_diameter_m),
                ("gear_ratio", w.gear_ratio),
                ("counts_per_rev", w.counts_per_rev),
                ("max_cable_length_m", w.max_cable_length_m),
            ] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(invalid(f(name), "must be finite and > 0"));
                }
            }
            if w.sign != 1 && w.sign != -1 {
                return Err(invalid(f("sign"), "must be 1 or -1"));
            }
            let span = w.max_cable_length_m * w.counts_per_m();
            let lo = w.offset_counts as f64 - span;
            let hi = w.offset_counts as f64 + span;
            if lo < f64::from(i32::MIN) || hi > f64::from(i32::MAX) {
                return Err(invalid(
                    f("max_cable_length_m"),
                    "0..max cable length does not fit the i32 position range (0x607A) with this scaling/offset",
                ));
            }
            winch::validate_winch(self, i).map_err(|(k, r)| invalid(k, r))?;
        }
        Ok(())
    }

    /// Every `[[force_sensor]]`: its table, interface, node id and cable.
    fn validate_force_sensors(&self) -> Result<(), ConfigError> {
        let b = &self.bus;
        for (j, s) in self.force_sensors.iter().enumerate() {
            s.validate(
                j,
                self.winches.len(),
                b.sync_period_us,
                b.heartbeat_timeout_ms,
            )
            .map_err(|(k, r)| invalid(k, r))?;
            let itfs = self.interfaces();
            match &s.interface {
                None if itfs.len() > 1 => {
                    return Err(invalid(
                        format!("force_sensor[{j}].interface"),
                        "missing: with several [[bus.interface]] tables every force sensor names \
                         its interface",
                    ));
                }
                Some(n) if !itfs.iter().any(|itf| &itf.name == n) => {
                    return Err(invalid(
                        format!("force_sensor[{j}].interface"),
                        format!("{n:?}: no such interface"),
                    ));
                }
                _ => {}
            }
            let k = self.sensor_interface(j);
            if s.node_id == b.master_node_id
                || (0..self.winches.len())
                    .any(|i| self.winch_interface(i) == k && self.winches[i].node_id == s.node_id)
                || (0..j).any(|o| {
                    self.sensor_interface(o) == k && self.force_sensors[o].node_id == s.node_id
                })
            {
                return Err(invalid(
                    format!("force_sensor[{j}].node_id"),
                    format!("node id {} used twice on one interface", s.node_id),
                ));
            }
            if self.force_sensors[..j].iter().any(|o| o.cable == s.cable) {
                return Err(invalid(
                    format!("force_sensor[{j}].cable"),
                    format!("cable {} has two force sensors", s.cable),
                ));
            }
        }
        Ok(())
    }

    pub fn sync_period_ns(&self) -> u64 {
        u64::from(self.bus.sync_period_us) * 1000
    }

    /// The safety heartbeat is mandatory for the drive adapter. Without `[safety_heartbeat]`
    /// drive-io refuses to start; only the bench executable ([`BENCH_EXECUTABLE`], never in
    /// config/ or systemd/: a test checks the shipped files) passes `bench_override`.
    /// `Ok(true)`: running without the heartbeat on the bench (the caller logs that loudly).
    pub fn require_safety_heartbeat(&self, bench_override: bool) -> Result<bool, ConfigError> {
        match (&self.safety_heartbeat, bench_override) {
            (Some(_), _) => Ok(false),
            (None, true) => Ok(true),
            (None, false) => Err(invalid(
                "safety_heartbeat",
                format!(
                    "missing: the safety monitor's fail-safe heartbeat is mandatory (nothing may \
                     move without the monitor). For a bench without a monitor only, run the \
                     test rigs' {BENCH_EXECUTABLE} instead of drive-io"
                ),
            )),
        }
    }
}

/// `[safety_io]`: the safety I/O node — a CiA 401 digital I/O module that is a CiA 304 SRDO
/// consumer of the safety monitor's doubled heartbeat — on its own interface. It validates the
/// heartbeat as the drives' watch does (`[safety_heartbeat]`: validation time, pair window,
/// configuration signature) and drives the safe-torque-off (STO) input of every drive: without
/// a valid RUN pair, or on STOP, torque is removed and the brakes close, whatever the drives'
/// CANopen state (real CiA 402 drives do not consume 0x101/0x102; their STO input is wired).
/// Its inputs — the operator's e-stop button and reset key — are reported in its TPDO1.
/// With this table the monitor's frames travel only on `interface` and the drives do not
/// validate them; without it (a bench, the old simulated drives) they go on every interface.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SafetyIoConfig {
    /// The `[[bus.interface]]` of the node (and of the monitor's doubled frames).
    pub interface: String,
    /// CANopen node id of the I/O module (1..=127; unique on its interface).
    pub node_id: u8,
    /// TPDO1 (inputs and STO output states, 2 bytes) is sent on every change and at least this
    /// often (event timer, ms).
    #[serde(default = "d_io_inputs")]
    pub inputs_period_ms: u16,
    /// The node's heartbeat producer time (ms).
    #[serde(default = "d_io_heartbeat")]
    pub heartbeat_ms: u16,
}

fn d_io_inputs() -> u16 {
    10
}
fn d_io_heartbeat() -> u16 {
    10
}

/// COB-ID of the safety I/O node's TPDO1: [inputs, STO outputs] (bit 0 of the inputs: e-stop
/// button circuit closed (released), bit 1: reset key turned; outputs: bit 0 = STO released).
pub fn safety_io_tpdo_cob_id(node_id: u8) -> u16 {
    0x180 + u16::from(node_id)
}

/// The bench-only executable that may start without `[safety_heartbeat]` (no monitor on the
/// bus): crates/drive-rig's `drive-io-bench`. The production `drive-io` has no switch for it.
/// Must never appear in config/ or systemd/.
pub const BENCH_EXECUTABLE: &str = "drive-io-bench";
