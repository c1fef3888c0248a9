//! Trip causes and the trip log (cause, cable, Δq / value, time), fixed capacity.

use std::fmt;

/// Why the monitor trips. The numeric code is sent in `StateEvent::detail` and in byte 1 of the
/// safety heartbeat.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Cause {
    /// |Δq_i| = |φ*_i(x) − q_θ,i| above the limit (sec. 5.6).
    DqLimit = 1,
    /// NaN/inf in the setpoint's pose or cable lengths.
    NonFinite = 2,
    /// Setpoint pose outside the configured workspace box.
    OutsideWorkspace = 3,
    /// Too many lost setpoints / sequence gaps within the gap window.
    SequenceGaps = 4,
    /// No new setpoint for N cycles (frozen or dead motion loop).
    SetpointSilence = 5,
    /// The motion core announces another platform identity than the monitor computed.
    IdentityMismatch = 6,
    /// Setpoints arrive but no platform identity was announced within the grace time.
    IdentityMissing = 7,
    /// Drive feedback contradicts the setpoints beyond the following-error bound.
    FollowingError = 8,
    /// drive-io stopped publishing feedback (dead or hung drive adapter).
    FeedbackSilence = 9,
    /// An RPDO target on the bus is farther than the limit from φ*(x) of every recent setpoint.
    RpdoMismatch = 10,
    /// A setpoint for another cable count.
    CableCount = 11,
    /// A setpoint whose sequence number did not increase (second publisher, restart, replay).
    SequenceRegression = 12,
    /// The process bus failed (receive error, foreign contract version): nothing can be checked.
    IpcError = 13,
    /// A drive's measured cable force stayed below f_min − margin longer than the filter time
    /// (slack cable; seed §5.1, table 5.1).
    ForceSlack = 14,
    /// A measured cable force stayed above f_max + margin longer than the filter time, or one
    /// reading exceeded the absolute hard limit (the winches' rating).
    ForceOverload = 15,
    /// An operational drive sent no force reading (TPDO2) for N cycles, or a reading that is not
    /// a number: the force check cannot be evaluated, so it fails closed.
    ForceSilence = 16,
    /// The pose moved faster than the platform's velocity limit (table 5.1): between two
    /// consecutive setpoints (one stream period per sequence number), or between the last
    /// setpoints of two monitor cycles timed by the monitor's own clock.
    MotionVelocity = 17,
    /// The velocity of consecutive setpoint steps changed faster than the acceleration limit.
    MotionAcceleration = 18,
    /// drive-io's feedback could not be checked for N cycles in a row (the setpoint it reports
    /// as applied is not among those the monitor saw): the following-error check fails closed.
    FollowingUnchecked = 19,
    /// The monitor's own bus observation failed: reader thread dead or stalled, receive
    /// errors, or observations dropped (queue overflow) — RPDO, heartbeat and force checks
    /// would run blind.
    BusObservation = 20,
    /// Another process (the operator console's stop button, an e-stop input) published an
    /// e-stop. The monitor latches it too, so that the stop it caused in motion-core and
    /// drive-io ends only with the monitor's verified reset (ISO 13849-1 §5.2.2).
    EStopEvent = 21,
    /// A state event claiming the monitor's own source that this monitor did not publish (a
    /// second publisher impersonating the monitor, e.g. a forged Reset): the process bus can
    /// no longer be trusted.
    ForgedEvent = 22,
    /// The drive bus's controller reported bus-off or error-passive (a CAN error frame on the
    /// monitor's own socket; value = 1 bus-off, 2 error-passive): frames to and from the drives,
    /// the monitor's stop frames among them, may no longer get through.
    CanBusError = 23,
    /// A frame on the monitor's own identifiers (the doubled heartbeat and configuration
    /// signature, `safety_cob_id` .. + 3) that this monitor did not send: another node speaks
    /// for the monitor on the bus (value = the COB-ID).
    Impersonation = 24,
    /// The safety I/O node reports its e-stop circuit open (the operator's e-stop button, a
    /// broken wire): the node has removed the drives' torque; the monitor latches it so that
    /// closing the circuit again releases nothing without the operator's reset.
    EStopCircuit = 25,
    /// The safety I/O node sent no TPDO1 for N cycles after it reported: its inputs (e-stop
    /// circuit, reset key) and its STO output can no longer be read (fail closed).
    SafetyIoSilence = 26,
    /// RPDOs that enable operation arrived on the bus but none could be checked for N cycles in
    /// a row (no setpoint the monitor saw could have preceded them): the RPDO check fails closed
    /// (value = cycles).
    RpdoUnchecked = 27,
    /// The setpoint producer announced the end of its stream (STOPPING) before the end of the
    /// plan it announced, while the stream was not holding, or without any plan announced: a
    /// forged or premature end that would disarm the silence and sequence checks.
    UnplannedStreamEnd = 28,
    /// A single-owner stream (setpoints, drive feedback, platform identity) has more than one
    /// publisher, or its publisher is not the process the stack expects (iceoryx2's service
    /// introspection: publisher count, owning node's process id and executable).
    ForeignPublisher = 29,
    /// drive-io's feedback keeps arriving but no sample advances its timestamp and SYNC cycle
    /// (or each lies in the monitor's future) for N cycles: a hung adapter whose publisher
    /// republishes its last sample while the plant may move (value = cycles).
    FeedbackStale = 30,
}

impl Cause {
    pub const ALL: [Cause; 30] = [
        Cause::DqLimit,
        Cause::NonFinite,
        Cause::OutsideWorkspace,
        Cause::SequenceGaps,
        Cause::SetpointSilence,
        Cause::IdentityMismatch,
        Cause::IdentityMissing,
        Cause::FollowingError,
        Cause::FeedbackSilence,
        Cause::RpdoMismatch,
        Cause::CableCount,
        Cause::SequenceRegression,
        Cause::IpcError,
        Cause::ForceSlack,
        Cause::ForceOverload,
        Cause::ForceSilence,
        Cause::MotionVelocity,
        Cause::MotionAcceleration,
        Cause::FollowingUnchecked,
        Cause::BusObservation,
        Cause::EStopEvent,
        Cause::ForgedEvent,
        Cause::CanBusError,
        Cause::Impersonation,
        Cause::EStopCircuit,
        Cause::SafetyIoSilence,
        Cause::RpdoUnchecked,
        Cause::UnplannedStreamEnd,
        Cause::ForeignPublisher,
        Cause::FeedbackStale,
    ];

    pub fn code(self) -> u8 {
        self as u8
    }

    pub fn from_code(c: u32) -> Option<Cause> {
        Cause::ALL
            .iter()
            .copied()
            .find(|x| u32::from(x.code()) == c)
    }

    pub fn name(self) -> &'static str {
        match self {
            Cause::DqLimit => "dq_limit",
            Cause::NonFinite => "non_finite",
            Cause::OutsideWorkspace => "outside_workspace",
            Cause::SequenceGaps => "sequence_gaps",
            Cause::SetpointSilence => "setpoint_silence",
            Cause::IdentityMismatch => "identity_mismatch",
            Cause::IdentityMissing => "identity_missing",
            Cause::FollowingError => "following_error",
            Cause::FeedbackSilence => "feedback_silence",
            Cause::RpdoMismatch => "rpdo_mismatch",
            Cause::CableCount => "cable_count",
            Cause::SequenceRegression => "sequence_regression",
            Cause::IpcError => "ipc_error",
            Cause::ForceSlack => "force_slack",
            Cause::ForceOverload => "force_overload",
            Cause::ForceSilence => "force_silence",
            Cause::MotionVelocity => "motion_velocity",
            Cause::MotionAcceleration => "motion_acceleration",
            Cause::FollowingUnchecked => "following_unchecked",
            Cause::BusObservation => "bus_observation",
            Cause::EStopEvent => "estop_event",
            Cause::ForgedEvent => "forged_event",
            Cause::CanBusError => "can_bus_error",
            Cause::Impersonation => "impersonation",
            Cause::EStopCircuit => "estop_circuit",
            Cause::SafetyIoSilence => "safety_io_silence",
            Cause::RpdoUnchecked => "rpdo_unchecked",
            Cause::UnplannedStreamEnd => "unplanned_stream_end",
            Cause::ForeignPublisher => "foreign_publisher",
            Cause::FeedbackStale => "feedback_stale",
        }
    }

    fn bit(self) -> u32 {
        1 << self.code()
    }
}

impl fmt::Display for Cause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A set of causes (bit set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CauseSet(u32);

impl CauseSet {
    pub fn insert(&mut self, c: Cause) {
        self.0 |= c.bit();
    }
    pub fn contains(&self, c: Cause) -> bool {
        self.0 & c.bit() != 0
    }
    pub fn is_empty(&self) -> bool {
        self.0 == 0
    }
    pub fn clear(&mut self) {
        self.0 = 0;
    }
    /// The causes in code order.
    pub fn iter(&self) -> impl Iterator<Item = Cause> + '_ {
        Cause::ALL.into_iter().filter(|c| self.contains(*c))
    }
    /// The first cause in code order.
    pub fn first(&self) -> Option<Cause> {
        self.iter().next()
    }
}

/// One detected fault: what, where, how much, when.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    pub cause: Cause,
    /// 0-based cable index, if the fault concerns one cable.
    pub cable: Option<u8>,
    /// The offending value: Δq (m) for dq_limit / rpdo_mismatch / following_error, the force (N)
    /// for force_slack / force_overload, m/s or rad/s (m/s², rad/s²) for motion_velocity
    /// (motion_acceleration), a count for sequence_gaps / *_silence, NaN if not applicable.
    pub value: f64,
    /// The limit it was compared with (same unit), NaN if not applicable.
    pub limit: f64,
    /// Sequence number of the setpoint concerned (0 = none).
    pub sequence: u64,
}

impl Fault {
    pub fn new(cause: Cause) -> Self {
        Self {
            cause,
            cable: None,
            value: f64::NAN,
            limit: f64::NAN,
            sequence: 0,
        }
    }
}

/// A trip: the first fault that latched the e-stop, and when.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TripRecord {
    pub fault: Fault,
    /// CLOCK_MONOTONIC ns of the monitor cycle that detected it.
    pub detected_ns: u64,
    /// Monitor cycle number.
    pub cycle: u64,
}

impl fmt::Display for TripRecord {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let fl = &self.fault;
        write!(f, "cause={}", fl.cause)?;
        match fl.cable {
            Some(c) => write!(f, " cable={}", u32::from(c) + 1)?,
            None => write!(f, " cable=-")?,
        }
        if fl.cause.is_length() {
            write!(
                f,
                " dq_mm={:.3} limit_mm={:.3}",
                fl.value * 1e3,
                fl.limit * 1e3
            )?;
        } else {
            write!(f, " value={} limit={}", fl.value, fl.limit)?;
        }
        write!(
            f,
            " sequence={} cycle={} t_ns={}",
            fl.sequence, self.cycle, self.detected_ns
        )
    }
}

impl Cause {
    /// True if the fault's value is a length (m).
    pub fn is_length(self) -> bool {
        matches!(
            self,
            Cause::DqLimit | Cause::RpdoMismatch | Cause::FollowingError
        )
    }
}

/// The last [`TripLog::CAPACITY`] trips, oldest overwritten (no allocation).
#[derive(Debug, Clone)]
pub struct TripLog {
    entries: [Option<TripRecord>; Self::CAPACITY],
    next: usize,
    total: u64,
}

impl Default for TripLog {
    fn default() -> Self {
        Self {
            entries: [None; Self::CAPACITY],
            next: 0,
            total: 0,
        }
    }
}

impl TripLog {
    pub const CAPACITY: usize = 64;

    pub fn push(&mut self, r: TripRecord) {
        self.entries[self.next] = Some(r);
        self.next = (self.next + 1) % Self::CAPACITY;
        self.total += 1;
    }

    /// Trips ever recorded.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// The most recent trip.
    pub fn last(&self) -> Option<&TripRecord> {
        self.entries[(self.next + Self::CAPACITY - 1) % Self::CAPACITY].as_ref()
    }

    /// Oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &TripRecord> {
        (0..Self::CAPACITY)
            .map(move |k| &self.entries[(self.next + k) % Self::CAPACITY])
            .filter_map(Option::as_ref)
    }
}
