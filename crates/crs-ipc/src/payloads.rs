//! `#[repr(C)]`, heap-free payloads. All lengths in m, angles in rad, forces in N, times in ns of
//! CLOCK_MONOTONIC ([`crate::monotonic_ns`]). Arrays have fixed capacity [`MAX_CABLES`] and a
//! `cable_count`; entries at index >= `cable_count` are unspecified (zero by convention).

use crate::codes::{
    FaultCode, MonitorCode, MonitorState, MotionState, PlantState, TripCause, UnknownCode,
};
use iceoryx2::prelude::ZeroCopySend;

/// Version of this contract; bump on any layout or meaning change (also part of the type names).
pub const CONTRACT_VERSION: u32 = 1;
/// Capacity of every per-cable array.
pub use crs_limits::MAX_CABLES;

/// Pose vector x = [x, y, z, phi_x, phi_y, phi_z] in m / rad.
pub type Pose6 = [f64; 6];

/// Joint setpoint of one 1 ms cycle, published by motion-core.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("crs_ipc::JointSetpoint.v1")]
#[repr(C)]
pub struct JointSetpoint {
    pub version: u32,
    /// Number of valid entries in the per-cable arrays (<= MAX_CABLES).
    pub cable_count: u32,
    /// Strictly increasing per publisher; a repeated sequence number is not a new setpoint.
    pub sequence: u64,
    /// When the setpoint was computed (CLOCK_MONOTONIC ns).
    pub timestamp_ns: u64,
    /// Desired platform pose x (m, rad).
    pub pose: Pose6,
    /// Desired platform twist (m/s, rad/s).
    pub pose_velocity: Pose6,
    /// Commanded cable lengths q_theta (m), INCLUDING the surrogate offset.
    pub cable_length_m: [f64; MAX_CABLES],
    /// The surrogate offset contained in `cable_length_m` (m), for diagnosis.
    pub surrogate_offset_m: [f64; MAX_CABLES],
    /// Commanded cable speeds (m/s).
    pub cable_velocity_m_per_s: [f64; MAX_CABLES],
}

impl Default for JointSetpoint {
    fn default() -> Self {
        Self {
            version: CONTRACT_VERSION,
            cable_count: 0,
            sequence: 0,
            timestamp_ns: 0,
            pose: [0.0; 6],
            pose_velocity: [0.0; 6],
            cable_length_m: [0.0; MAX_CABLES],
            surrogate_offset_m: [0.0; MAX_CABLES],
            cable_velocity_m_per_s: [0.0; MAX_CABLES],
        }
    }
}

/// State of the drive bus as seen by drive-io (`DriveFeedback::bus_state`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum BusState {
    /// NMT/SDO boot and CiA 402 enable sequence in progress.
    Booting = 0,
    /// All drives in Operation Enabled, waiting for the first setpoint (drives hold position).
    Ready = 1,
    /// Following setpoints.
    Running = 2,
    /// Quick stop commanded because setpoints went stale; drives hold.
    StaleStop = 3,
    /// Quick stop commanded because of an e-stop event; drives hold.
    EStop = 4,
    /// A drive faulted / lost heartbeat / sent EMCY; all drives quick-stopped and held.
    Fault = 5,
}

impl BusState {
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::Booting,
            1 => Self::Ready,
            2 => Self::Running,
            3 => Self::StaleStop,
            4 => Self::EStop,
            5 => Self::Fault,
            _ => return None,
        })
    }
}

/// Drive feedback of one SYNC cycle, published by drive-io.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("crs_ipc::DriveFeedback.v1")]
#[repr(C)]
pub struct DriveFeedback {
    pub version: u32,
    pub cable_count: u32,
    /// SYNC cycle counter of drive-io.
    pub cycle: u64,
    /// When this feedback was assembled (CLOCK_MONOTONIC ns).
    pub timestamp_ns: u64,
    /// Sequence number of the last setpoint written to the drives (0 = none yet).
    pub applied_setpoint_sequence: u64,
    /// When the RPDOs carrying that setpoint were written to the bus (CLOCK_MONOTONIC ns).
    pub applied_setpoint_write_ns: u64,
    /// [`BusState`] as u32.
    pub bus_state: u32,
    /// A [`FaultCode`] value.
    pub fault_code: u32,
    /// Node id of the drive that caused the fault (0 = none).
    pub fault_node: u32,
    /// Last EMCY error code received (0 = none).
    pub last_emcy_code: u32,
    /// SYNC cycles since the last NEW setpoint was applied (stale detection counter).
    pub setpoint_age_cycles: u32,
    /// SYNC ticks the drive-io loop missed so far (overruns).
    pub overruns: u32,
    /// Measured cable lengths (m), converted from position actual 0x6064.
    pub cable_length_m: [f64; MAX_CABLES],
    /// Measured cable speeds (m/s), from velocity actual 0x606C.
    pub cable_velocity_m_per_s: [f64; MAX_CABLES],
    /// Pulley force sensors (N).
    pub cable_force_n: [f64; MAX_CABLES],
    /// Receive time of the TPDO carrying the position (CLOCK_MONOTONIC ns; 0 = never).
    pub rx_timestamp_ns: [u64; MAX_CABLES],
    /// CiA 402 statusword 0x6041 per drive.
    pub statusword: [u16; MAX_CABLES],
}

impl Default for DriveFeedback {
    fn default() -> Self {
        Self {
            version: CONTRACT_VERSION,
            cable_count: 0,
            cycle: 0,
            timestamp_ns: 0,
            applied_setpoint_sequence: 0,
            applied_setpoint_write_ns: 0,
            bus_state: BusState::Booting.into(),
            fault_code: FaultCode::None.into(),
            fault_node: 0,
            last_emcy_code: 0,
            setpoint_age_cycles: 0,
            overruns: 0,
            cable_length_m: [0.0; MAX_CABLES],
            cable_velocity_m_per_s: [0.0; MAX_CABLES],
            cable_force_n: [0.0; MAX_CABLES],
            rx_timestamp_ns: [0; MAX_CABLES],
            statusword: [0; MAX_CABLES],
        }
    }
}

/// Who publishes a [`StateEvent`] / [`Heartbeat`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ProcessId {
    Unknown = 0,
    MotionCore = 1,
    DriveIo = 2,
    SafetyMonitor = 3,
    SimPlant = 4,
    Operator = 5,
    Test = 6,
}

/// Kind of a [`StateEvent`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum EventKind {
    /// Emergency stop: every motion process stops (drive-io: quick stop + hold, latched).
    EStop = 1,
    /// Operator acknowledged / reset after an e-stop or fault.
    Reset = 2,
    /// A process changed state (`state` holds the process-specific state code).
    StateChanged = 3,
    /// A process detected a fault (`detail` holds a [`FaultCode`]).
    Fault = 4,
}

/// E-stop / state events (any process -> all).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("crs_ipc::StateEvent.v1")]
#[repr(C)]
pub struct StateEvent {
    pub version: u32,
    /// [`ProcessId`] as u32.
    pub source: u32,
    /// [`EventKind`] as u32.
    pub kind: u32,
    /// Process-specific state code (drive-io: [`BusState`]).
    pub state: u32,
    /// Detail code (e.g. [`FaultCode`], [`MonitorCode`], [`TripCause`]), node id in
    /// `detail_node`.
    pub detail: u32,
    pub detail_node: u32,
    pub sequence: u64,
    pub timestamp_ns: u64,
}

impl StateEvent {
    pub fn new(source: ProcessId, kind: EventKind, sequence: u64) -> Self {
        Self {
            version: CONTRACT_VERSION,
            source: source as u32,
            kind: kind as u32,
            state: 0,
            detail: 0,
            detail_node: 0,
            sequence,
            timestamp_ns: crate::monotonic_ns(),
        }
    }
}

/// A [`StateEvent`] decoded: the kind as a type, the source as a [`ProcessId`]. Readers
/// match on this instead of comparing raw `kind` codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    EStop {
        source: ProcessId,
        detail: u32,
    },
    Reset {
        source: ProcessId,
    },
    StateChanged {
        source: ProcessId,
        state: u32,
    },
    Fault {
        source: ProcessId,
        state: u32,
        detail: u32,
        node: u32,
    },
}

/// A [`StateEvent`] that is not of this contract version or carries an unknown kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("state event of contract version {0}, expected {CONTRACT_VERSION}")]
    Version(u32),
    #[error("state event of unknown kind {0}")]
    Kind(u32),
}

impl ProcessId {
    /// The process of a raw code; unknown codes are [`ProcessId::Unknown`].
    pub fn from_code(code: u32) -> Self {
        match code {
            1 => Self::MotionCore,
            2 => Self::DriveIo,
            3 => Self::SafetyMonitor,
            4 => Self::SimPlant,
            5 => Self::Operator,
            6 => Self::Test,
            _ => Self::Unknown,
        }
    }
}

impl StateEvent {
    /// motion-core's plan announcement: the stream's last planned setpoint is `end_sequence`
    /// ([`MotionState::Plan`]).
    pub fn plan(end_sequence: u64, sequence: u64) -> Self {
        let mut ev = Self::new(ProcessId::MotionCore, EventKind::StateChanged, sequence);
        ev.state = MotionState::Plan.into();
        ev.detail = end_sequence as u32;
        ev.detail_node = (end_sequence >> 32) as u32;
        ev
    }

    /// The announced plan end if this is a plan announcement (any source: the receiver decides
    /// whom it believes).
    pub fn plan_end(&self) -> Option<u64> {
        (self.is_state_changed() && self.state == MotionState::Plan.code())
            .then(|| u64::from(self.detail) | (u64::from(self.detail_node) << 32))
    }

    /// motion-core's state change (source MotionCore, kind StateChanged).
    pub fn motion(state: MotionState, sequence: u64) -> Self {
        let mut ev = Self::new(ProcessId::MotionCore, EventKind::StateChanged, sequence);
        ev.state = state.into();
        ev
    }

    /// The safety monitor's state change with a [`MonitorCode`] in `detail` (source
    /// SafetyMonitor, kind StateChanged); `detail_node` stays 0.
    pub fn monitor(state: MonitorState, detail: MonitorCode, sequence: u64) -> Self {
        let mut ev = Self::new(ProcessId::SafetyMonitor, EventKind::StateChanged, sequence);
        ev.state = state.into();
        ev.detail = detail.into();
        ev
    }

    /// An operator's reset request on the process bus (source Operator, kind StateChanged,
    /// state [`MonitorCode::ResetRequest`]): the monitor never accepts one from there.
    pub fn reset_request(sequence: u64) -> Self {
        let mut ev = Self::new(ProcessId::Operator, EventKind::StateChanged, sequence);
        ev.state = MonitorCode::ResetRequest.into();
        ev
    }

    /// Kind StateChanged.
    pub fn is_state_changed(&self) -> bool {
        self.kind == EventKind::StateChanged as u32
    }

    /// The publisher (unknown codes are [`ProcessId::Unknown`]).
    pub fn source(&self) -> ProcessId {
        ProcessId::from_code(self.source)
    }

    /// `state` read as motion-core's state code.
    pub fn motion_state(&self) -> Result<MotionState, UnknownCode> {
        MotionState::try_from(self.state)
    }

    /// `state` read as the safety monitor's state code.
    pub fn monitor_state(&self) -> Result<MonitorState, UnknownCode> {
        MonitorState::try_from(self.state)
    }

    /// `state` read as drive-io's bus state.
    pub fn bus_state(&self) -> Result<BusState, UnknownCode> {
        BusState::try_from(self.state)
    }

    /// The [`MonitorCode`] in `detail` of a StateChanged event (any source: the receiver
    /// decides whom it believes); None for another kind or a code that is none of them.
    pub fn monitor_code(&self) -> Option<MonitorCode> {
        self.is_state_changed()
            .then(|| MonitorCode::try_from(self.detail).ok())
            .flatten()
    }

    /// A reset request: kind StateChanged with `state` [`MonitorCode::ResetRequest`] (any
    /// source).
    pub fn is_reset_request(&self) -> bool {
        self.is_state_changed() && self.state == MonitorCode::ResetRequest.code()
    }

    /// The end of motion-core's setpoint stream: source MotionCore, kind StateChanged, state
    /// [`MotionState::Stopping`].
    pub fn is_stream_end(&self) -> bool {
        self.source == ProcessId::MotionCore as u32
            && self.is_state_changed()
            && self.state == MotionState::Stopping.code()
    }

    /// `detail` read as the safety monitor's trip cause (its EStop events).
    pub fn trip_cause(&self) -> Result<TripCause, UnknownCode> {
        TripCause::try_from(self.detail)
    }

    /// The event as a typed [`Event`].
    pub fn decode(&self) -> Result<Event, DecodeError> {
        if self.version != CONTRACT_VERSION {
            return Err(DecodeError::Version(self.version));
        }
        let source = ProcessId::from_code(self.source);
        Ok(match self.kind {
            k if k == EventKind::EStop as u32 => Event::EStop {
                source,
                detail: self.detail,
            },
            k if k == EventKind::Reset as u32 => Event::Reset { source },
            k if k == EventKind::StateChanged as u32 => Event::StateChanged {
                source,
                state: self.state,
            },
            k if k == EventKind::Fault as u32 => Event::Fault {
                source,
                state: self.state,
                detail: self.detail,
                node: self.detail_node,
            },
            k => return Err(DecodeError::Kind(k)),
        })
    }
}

/// Liveness of a process.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("crs_ipc::Heartbeat.v1")]
#[repr(C)]
pub struct Heartbeat {
    pub version: u32,
    /// [`ProcessId`] as u32.
    pub source: u32,
    /// Process-specific state code.
    pub state: u32,
    /// Overruns of the process's cyclic loop so far.
    pub overruns: u32,
    pub sequence: u64,
    pub timestamp_ns: u64,
}

impl Heartbeat {
    /// A heartbeat with a raw state code: for drive-io until it is converted, and for tests
    /// of foreign codes. The stack's processes use the typed constructors below.
    pub fn new(source: ProcessId, state: u32, sequence: u64) -> Self {
        Self {
            version: CONTRACT_VERSION,
            source: source as u32,
            state,
            overruns: 0,
            sequence,
            timestamp_ns: crate::monotonic_ns(),
        }
    }
}

impl Heartbeat {
    /// motion-core's heartbeat.
    pub fn motion(state: MotionState, sequence: u64) -> Self {
        Self::new(ProcessId::MotionCore, state.into(), sequence)
    }

    /// The safety monitor's heartbeat.
    pub fn monitor(state: MonitorState, sequence: u64) -> Self {
        Self::new(ProcessId::SafetyMonitor, state.into(), sequence)
    }

    /// drive-io's heartbeat.
    pub fn bus(state: BusState, sequence: u64) -> Self {
        Self::new(ProcessId::DriveIo, state.into(), sequence)
    }

    /// The simulated plant's heartbeat.
    pub fn plant(state: PlantState, sequence: u64) -> Self {
        Self::new(ProcessId::SimPlant, state.into(), sequence)
    }

    /// The publisher (unknown codes are [`ProcessId::Unknown`]).
    pub fn source(&self) -> ProcessId {
        ProcessId::from_code(self.source)
    }

    /// `state` read as motion-core's state code.
    pub fn motion_state(&self) -> Result<MotionState, UnknownCode> {
        MotionState::try_from(self.state)
    }

    /// `state` read as the safety monitor's state code.
    pub fn monitor_state(&self) -> Result<MonitorState, UnknownCode> {
        MonitorState::try_from(self.state)
    }
}

impl DriveFeedback {
    /// `bus_state` as drive-io's [`BusState`].
    pub fn bus(&self) -> Result<BusState, UnknownCode> {
        BusState::try_from(self.bus_state)
    }

    /// `fault_code` as a [`FaultCode`].
    pub fn fault(&self) -> Result<FaultCode, UnknownCode> {
        FaultCode::try_from(self.fault_code)
    }
}

/// True platform pose as reported by the simulated plant (or a tracker).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("crs_ipc::TrackerPose.v1")]
#[repr(C)]
pub struct TrackerPose {
    pub version: u32,
    /// 1 if the pose is valid (tracker sees the platform).
    pub valid: u32,
    pub sequence: u64,
    pub timestamp_ns: u64,
    pub pose: Pose6,
    pub pose_velocity: Pose6,
}

impl Default for TrackerPose {
    fn default() -> Self {
        Self {
            version: CONTRACT_VERSION,
            valid: 0,
            sequence: 0,
            timestamp_ns: 0,
            pose: [0.0; 6],
            pose_velocity: [0.0; 6],
        }
    }
}

/// The 32-byte platform identity hash (SHA-256 over the canonical serialisation of the model,
/// the workspace box and the motion limits, `"crs-platform-v2"`; see [`crate::identity_golden`]).
/// motion-core computes it through the model library, the safety monitor with its own code;
/// the monitor trips when they differ. A type of its own so that a platform identity is not
/// confused with any other 32-byte hash (e.g. the SHA-256 of a file's bytes); `Display` is
/// lower-case hex for logs and errors.
///
/// Layout: one `[u8; 32]` field under `#[repr(C)]` (size 32, alignment 1, as the bare array),
/// so [`PlatformIdentity`] is binary-identical to the contract before the newtype (checked at
/// compile time below); its type name `crs_ipc::PlatformIdentity.v1` is unchanged.
#[derive(Clone, Copy, PartialEq, Eq, Hash, ZeroCopySend)]
#[repr(C)]
pub struct PlatformId([u8; 32]);

impl PlatformId {
    pub const fn new(bytes: [u8; 32]) -> Self {
        Self(bytes)
    }

    pub const fn as_bytes(&self) -> &[u8; 32] {
        &self.0
    }
}

impl From<[u8; 32]> for PlatformId {
    fn from(bytes: [u8; 32]) -> Self {
        Self(bytes)
    }
}

impl AsRef<[u8]> for PlatformId {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

/// Comparison with the bare bytes a library computes (the model library does not depend on
/// the IPC contract, so `cdpr_model::config::Platform::identity` returns `[u8; 32]`).
impl PartialEq<[u8; 32]> for PlatformId {
    fn eq(&self, other: &[u8; 32]) -> bool {
        &self.0 == other
    }
}

impl PartialEq<PlatformId> for [u8; 32] {
    fn eq(&self, other: &PlatformId) -> bool {
        self == &other.0
    }
}

impl std::fmt::Display for PlatformId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for b in &self.0 {
            write!(f, "{b:02x}")?;
        }
        Ok(())
    }
}

impl std::fmt::Debug for PlatformId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "PlatformId({self})")
    }
}

/// Identity of the platform model motion-core runs, so the safety monitor can check it uses
/// the same platform.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("crs_ipc::PlatformIdentity.v1")]
#[repr(C)]
pub struct PlatformIdentity {
    pub version: u32,
    pub cable_count: u32,
    pub timestamp_ns: u64,
    pub hash: PlatformId,
}

// The contract's layout of PlatformIdentity.v1 (before the newtype: `hash: [u8; 32]` at 16,
// 48 bytes, alignment 8): a change here must bump the type name and CONTRACT_VERSION.
const _: () = {
    assert!(std::mem::size_of::<PlatformId>() == 32);
    assert!(std::mem::align_of::<PlatformId>() == 1);
    assert!(std::mem::offset_of!(PlatformIdentity, hash) == 16);
    assert!(std::mem::size_of::<PlatformIdentity>() == 48);
    assert!(std::mem::align_of::<PlatformIdentity>() == 8);
};

impl PlatformIdentity {
    pub fn new(hash: PlatformId, cable_count: u32) -> Self {
        Self {
            version: CONTRACT_VERSION,
            cable_count,
            timestamp_ns: crate::monotonic_ns(),
            hash,
        }
    }
}

/// Motion-cueing input: a stream of reference poses for motion-core (e.g. from a driving or
/// flight simulator's washout filter). motion-core follows the newest one through its
/// jerk-limited filter; every sample is checked like any reference.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("crs_ipc::CueingPose.v1")]
#[repr(C)]
pub struct CueingPose {
    pub version: u32,
    pub _reserved: u32,
    /// Strictly increasing per publisher.
    pub sequence: u64,
    pub timestamp_ns: u64,
    /// Desired platform pose x (m, rad).
    pub pose: Pose6,
}

impl CueingPose {
    pub fn new(pose: Pose6, sequence: u64) -> Self {
        Self {
            version: CONTRACT_VERSION,
            _reserved: 0,
            sequence,
            timestamp_ns: crate::monotonic_ns(),
            pose,
        }
    }
}

/// motion-core's loop statistics (published about once per second by its publish stage).
/// Quantiles are upper bin edges of the lock-free histograms, ns.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("crs_ipc::LoopStatsSample.v1")]
#[repr(C)]
pub struct LoopStatsSample {
    pub version: u32,
    /// Loop state code ([`MotionState`]: running, e-stopped, refused, holding).
    pub state: u32,
    pub timestamp_ns: u64,
    pub cycles: u64,
    pub overruns: u64,
    pub rejected: u64,
    /// Setpoints the loop could not hand to the publish stage.
    pub dropped: u64,
    pub lateness_p50_ns: u64,
    pub lateness_p99_ns: u64,
    pub lateness_p999_ns: u64,
    pub lateness_max_ns: u64,
    pub compute_p50_ns: u64,
    pub compute_p99_ns: u64,
    pub compute_max_ns: u64,
}

impl Default for LoopStatsSample {
    fn default() -> Self {
        Self {
            version: CONTRACT_VERSION,
            state: 0,
            timestamp_ns: 0,
            cycles: 0,
            overruns: 0,
            rejected: 0,
            dropped: 0,
            lateness_p50_ns: 0,
            lateness_p99_ns: 0,
            lateness_p999_ns: 0,
            lateness_max_ns: 0,
            compute_p50_ns: 0,
            compute_p99_ns: 0,
            compute_max_ns: 0,
        }
    }
}

impl LoopStatsSample {
    /// `state` read as motion-core's state code.
    pub fn motion_state(&self) -> Result<MotionState, UnknownCode> {
        MotionState::try_from(self.state)
    }
}

/// The simulated plant's true state (ground truth for the launcher and tests; a real robot has
/// a tracker and force sensors instead).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("crs_ipc::PlantTruth.v1")]
#[repr(C)]
pub struct PlantTruth {
    pub version: u32,
    pub cable_count: u32,
    pub sequence: u64,
    pub timestamp_ns: u64,
    /// Actual platform pose x̂ (m, rad).
    pub pose: Pose6,
    /// Actual cable forces f̂ (N), slack = 0.
    pub force_n: [f64; MAX_CABLES],
    /// Controlled lengths the winches hold (m).
    pub cable_length_m: [f64; MAX_CABLES],
    /// 1 if the last equilibrium solve converged.
    pub converged: u32,
    /// 1 while the drives hold (brake engaged / not operation enabled).
    pub braked: u32,
}

impl Default for PlantTruth {
    fn default() -> Self {
        Self {
            version: CONTRACT_VERSION,
            cable_count: 0,
            sequence: 0,
            timestamp_ns: 0,
            pose: [0.0; 6],
            force_n: [0.0; MAX_CABLES],
            cable_length_m: [0.0; MAX_CABLES],
            converged: 0,
            braked: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn platform_id_displays_lower_case_hex_and_compares_with_its_bytes() {
        let mut b = [0u8; 32];
        b[0] = 0xAB;
        b[31] = 0x0F;
        let id = PlatformId::new(b);
        let s = id.to_string();
        assert_eq!(s.len(), 64);
        assert!(s.starts_with("ab00"), "{s}");
        assert!(s.ends_with("000f"), "{s}");
        assert_eq!(format!("{id:?}"), format!("PlatformId({s})"));
        assert_eq!(id, b);
        assert_eq!(b, id);
        b[5] ^= 1;
        assert_ne!(id, b);
        assert_eq!(id.as_bytes()[0], 0xAB);
        assert_eq!(PlatformId::from(*id.as_bytes()), id);
    }

    /// The golden platform identity in its contract form matches the bytes pinned before the
    /// newtype (the layout is checked at compile time above).
    #[test]
    fn golden_platform_identity_hex() {
        assert_eq!(
            crate::identity_golden::PLATFORM_IDENTITY.to_string(),
            "3b8d8c284c85bb378e5efa7613f73024426c4a7a789d49089d51dfe90d8016cb"
        );
    }
}

/// drive-io's SYNC schedule (`sync_source = "isochronous"`): the SYNC is the bus clock, sent at
/// `t0_ns + k · period_ns` (CLOCK_MONOTONIC; k ≥ 0, some k skipped after a stall, never an
/// interval below 0.9 periods). motion-core places its tick `sync_lead_us` before each SYNC so
/// the newest setpoint makes the next one. Announced at start and about once per second.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[type_name("crs_ipc::SyncSchedule.v1")]
#[repr(C)]
pub struct SyncSchedule {
    pub version: u32,
    pub _reserved: u32,
    /// A SYNC instant of the schedule, ns.
    pub t0_ns: u64,
    /// SYNC period, ns.
    pub period_ns: u64,
    /// Strictly increasing per announcement.
    pub sequence: u64,
}

impl SyncSchedule {
    pub fn new(t0_ns: u64, period_ns: u64, sequence: u64) -> Self {
        Self {
            version: CONTRACT_VERSION,
            _reserved: 0,
            t0_ns,
            period_ns,
            sequence,
        }
    }

    /// The phase of the schedule, shifted by `offset_ns` (may be negative), in [0, period).
    /// `None` for a zero period.
    pub fn phase_ns(&self, offset_ns: i64) -> Option<u64> {
        if self.period_ns == 0 {
            return None;
        }
        let p = i128::from(self.period_ns);
        Some((i128::from(self.t0_ns) + i128::from(offset_ns)).rem_euclid(p) as u64)
    }
}
