//! The process-bus codes as types: the `u32` state, detail and fault codes the `#[repr(C)]`
//! payloads carry ([`crate::Heartbeat::state`], [`crate::StateEvent::state`] / `detail`,
//! [`crate::DriveFeedback::fault_code`]) as `#[repr(u32)]` enums. The payloads keep their `u32`
//! fields (the wire layout and every numeric value are the contract's); a reader turns a field
//! into its enum with `TryFrom<u32>` — an unknown code is an [`UnknownCode`] naming it, never a
//! panic — and a writer turns an enum into its code with `u32::from` (or `code()`).

/// A code on the process bus that the contract does not define for its field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} code {code} ({code:#x})")]
pub struct UnknownCode {
    /// Which code set the value was read as (e.g. "motion state").
    pub what: &'static str,
    /// The value received.
    pub code: u32,
}

/// Defines a wire-code enum: the variants with their values, `ALL`, `code()`, `From<Enum> for
/// u32`, `TryFrom<u32>` (unknown: [`UnknownCode`] named `$what`).
macro_rules! wire_codes {
    (
        $(#[$meta:meta])*
        pub enum $name:ident ($what:literal, $repr:ty) {
            $( $(#[$vmeta:meta])* $var:ident = $val:expr, )+
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[repr($repr)]
        pub enum $name {
            $( $(#[$vmeta])* $var = $val, )+
        }

        impl $name {
            /// Every variant, in declaration order.
            pub const ALL: &'static [$name] = &[$($name::$var,)+];

            /// The code on the wire.
            pub const fn code(self) -> $repr {
                self as $repr
            }
        }

        impl From<$name> for u32 {
            fn from(v: $name) -> u32 {
                u32::from(v.code())
            }
        }

        impl TryFrom<u32> for $name {
            type Error = UnknownCode;

            fn try_from(code: u32) -> Result<Self, UnknownCode> {
                $(
                    if code == u32::from($name::$var.code()) {
                        return Ok($name::$var);
                    }
                )+
                Err(UnknownCode { what: $what, code })
            }
        }
    };
}

wire_codes! {
    /// motion-core's `StateEvent::state` / `Heartbeat::state` codes (source MotionCore).
    pub enum MotionState ("motion state", u32) {
        /// Following a plan, a ride or a cueing stream (the setpoints move).
        Running = 1,
        /// Latched e-stop (kind Fault).
        EStopped = 2,
        /// Refused a reference (latched, kind Fault).
        Refused = 3,
        /// Idle and holding: nothing to follow (before the first ride, after a plan or ride
        /// ended or an abort braked to rest, after a reset of a latch); the setpoints stand still.
        Holding = 4,
        /// Graceful end of the setpoint stream: published (kind StateChanged) AFTER the last
        /// setpoint, so the safety monitor disarms its silence watch instead of tripping.
        Stopping = 5,
        /// motion-core announces its plan (kind StateChanged): the sequence number of
        /// the plan's LAST setpoint, low 32 bits in `detail`, high 32 bits in `detail_node`
        /// ([`crate::StateEvent::plan`], [`crate::StateEvent::plan_end`]). Re-announced about
        /// once per second. The safety monitor accepts [`MotionState::Stopping`] only once the
        /// stream has reached that setpoint and holds. Not a loop state: it never appears in a
        /// heartbeat.
        Plan = 6,
    }
}

impl MotionState {
    /// A latched state that only a reset of the monitor's current epoch ends.
    pub fn is_latched(self) -> bool {
        matches!(self, MotionState::EStopped | MotionState::Refused)
    }
}

/// [`MotionState::Plan`] end of a stream without a planned end (the motion-cueing input).
pub const PLAN_OPEN_END: u64 = u64::MAX;

wire_codes! {
    /// The safety monitor's `StateEvent::state` / `Heartbeat::state` codes (source
    /// SafetyMonitor).
    pub enum MonitorState ("monitor state", u32) {
        /// No fault latched: the safety heartbeat says RUN.
        Armed = 1,
        /// E-stop latched until the monitor accepts an operator reset.
        Tripped = 2,
        /// Start-up: not every drive verified yet, the safety heartbeat says STOP.
        NotReady = 3,
    }
}

wire_codes! {
    /// The `detail` of the safety monitor's StateChanged events (source SafetyMonitor) and the
    /// `state` of an operator's reset request (source Operator). Values 0x5AFE_00xx so that
    /// none of them is a small state or cause code.
    pub enum MonitorCode ("monitor event", u32) {
        /// `StateEvent::state` of an operator's reset request (kind StateChanged, source
        /// Operator). On the process bus it is never authorised: the monitor answers
        /// [`MonitorCode::ResetDenied`].
        ResetRequest = 0x5AFE_0001,
        /// Answer: the reset was accepted (every latched cause shown cleared).
        ResetAccepted = 0x5AFE_0002,
        /// Answer: refused, a cause persists (`detail_node` = the cause's code).
        ResetRefused = 0x5AFE_0003,
        /// Answer: nothing to reset.
        ResetNotTripped = 0x5AFE_0004,
        /// Answer: refused because the monitor has not verified its start-up conditions yet.
        ResetNotReady = 0x5AFE_0005,
        /// Answer: denied, the request did not come from an authorised channel (the reset
        /// key, the reset socket); a request on the process bus is never authorised.
        ResetDenied = 0x5AFE_0006,
        /// Answer: refused, this monitor instance cannot count further resets (restart it).
        ResetExhausted = 0x5AFE_0007,
        /// The monitor's epoch announcement (kind StateChanged, `state` = the monitor's state
        /// code, `detail_node` = its current reset epoch): published about once a second and
        /// right before each of its Reset events, so a consumer without CAN access
        /// (motion-core) knows which epoch the CURRENT monitor announces and accepts only a
        /// Reset of that epoch.
        EpochAnnounce = 0x5AFE_0010,
    }
}

impl MonitorCode {
    /// An answer to a reset request (accepted, refused, not tripped, not ready, denied,
    /// exhausted): neither the request itself nor the epoch announcement.
    pub fn is_reset_answer(self) -> bool {
        !matches!(self, MonitorCode::ResetRequest | MonitorCode::EpochAnnounce)
    }
}

wire_codes! {
    /// Reason codes in `DriveFeedback::fault_code` / `StateEvent::detail` (drive-io).
    pub enum FaultCode ("drive fault", u32) {
        None = 0,
        HeartbeatLost = 1,
        Emcy = 2,
        DriveFaultBit = 3,
        BootTimeout = 4,
        SetpointInvalid = 5,
        SetpointStep = 6,
        UnexpectedState = 7,
        BusError = 8,
        PdoTimeout = 9,
        /// A drive's measured cable force beyond drive-io's hard limit.
        ForceLimit = 10,
    }
}

wire_codes! {
    /// The simulated plant's `Heartbeat::state` (source SimPlant).
    pub enum PlantState ("plant state", u32) {
        /// The winches follow their drives.
        Free = 0,
        /// The drives hold (brake engaged / not operation enabled).
        Braked = 1,
    }
}

wire_codes! {
    /// Why the safety monitor trips: `StateEvent::detail` of its EStop event, `detail_node`
    /// of a refused reset, byte 1 of the safety heartbeat on CAN (hence `u8`). The names are
    /// the monitor's log and report words.
    pub enum TripCause ("trip cause", u8) {
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
        /// An RPDO target on the bus is farther than the limit from φ*(x) of every recent
        /// setpoint.
        RpdoMismatch = 10,
        /// A setpoint for another cable count.
        CableCount = 11,
        /// A setpoint whose sequence number did not increase (second publisher, restart,
        /// replay).
        SequenceRegression = 12,
        /// The process bus failed (receive error, foreign contract version): nothing can be
        /// checked.
        IpcError = 13,
        /// A drive's measured cable force stayed below f_min − margin longer than the filter
        /// time (slack cable; seed §5.1, table 5.1).
        ForceSlack = 14,
        /// A measured cable force stayed above f_max + margin longer than the filter time, or
        /// one reading exceeded the absolute hard limit (the winches' rating).
        ForceOverload = 15,
        /// An operational drive sent no force reading (TPDO2) for N cycles, or a reading that
        /// is not a number: the force check cannot be evaluated, so it fails closed.
        ForceSilence = 16,
        /// The pose moved faster than the platform's velocity limit (table 5.1): between two
        /// consecutive setpoints (one stream period per sequence number), or between the last
        /// setpoints of two monitor cycles timed by the monitor's own clock.
        MotionVelocity = 17,
        /// The velocity of consecutive setpoint steps changed faster than the acceleration
        /// limit.
        MotionAcceleration = 18,
        /// drive-io's feedback could not be checked for N cycles in a row (the setpoint it
        /// reports as applied is not among those the monitor saw): the following-error check
        /// fails closed.
        FollowingUnchecked = 19,
        /// The monitor's own bus observation failed: reader thread dead or stalled, receive
        /// errors, or observations dropped (queue overflow) — RPDO, heartbeat and force checks
        /// would run blind.
        BusObservation = 20,
        /// Another process (the operator console's stop button, an e-stop input) published an
        /// e-stop. The monitor latches it too, so that the stop it caused in motion-core and
        /// drive-io ends only with the monitor's verified reset (ISO 13849-1 §5.2.2).
        EStopEvent = 21,
        /// A state event claiming the monitor's own source that this monitor did not publish
        /// (a second publisher impersonating the monitor, e.g. a forged Reset): the process
        /// bus can no longer be trusted.
        ForgedEvent = 22,
        /// The drive bus's controller reported bus-off or error-passive (a CAN error frame on
        /// the monitor's own socket; value = 1 bus-off, 2 error-passive): frames to and from
        /// the drives, the monitor's stop frames among them, may no longer get through.
        CanBusError = 23,
        /// A frame on the monitor's own identifiers (the doubled heartbeat and configuration
        /// signature, `safety_cob_id` .. + 3) that this monitor did not send: another node
        /// speaks for the monitor on the bus (value = the COB-ID).
        Impersonation = 24,
        /// The safety I/O node reports its e-stop circuit open (the operator's e-stop button,
        /// a broken wire): the node has removed the drives' torque; the monitor latches it so
        /// that closing the circuit again releases nothing without the operator's reset.
        EStopCircuit = 25,
        /// The safety I/O node sent no TPDO1 for N cycles after it reported: its inputs
        /// (e-stop circuit, reset key) and its STO output can no longer be read (fail closed).
        SafetyIoSilence = 26,
        /// RPDOs that enable operation arrived on the bus but none could be checked for N
        /// cycles in a row (no setpoint the monitor saw could have preceded them): the RPDO
        /// check fails closed (value = cycles).
        RpdoUnchecked = 27,
        /// The setpoint producer announced the end of its stream (STOPPING) before the end of
        /// the plan it announced, while the stream was not holding, or without any plan
        /// announced: a forged or premature end that would disarm the silence and sequence
        /// checks.
        UnplannedStreamEnd = 28,
        /// A single-owner stream (setpoints, drive feedback, platform identity) has more than
        /// one publisher, or its publisher is not the process the stack expects (iceoryx2's
        /// service introspection: publisher count, owning node's process id and executable).
        ForeignPublisher = 29,
        /// drive-io's feedback keeps arriving but no sample advances its timestamp and SYNC
        /// cycle (or each lies in the monitor's future) for N cycles: a hung adapter whose
        /// publisher republishes its last sample while the plant may move (value = cycles).
        FeedbackStale = 30,
    }
}

impl TripCause {
    /// The cause of a code; None for a code the contract does not define.
    pub fn from_code(c: u32) -> Option<TripCause> {
        TripCause::try_from(c).ok()
    }

    /// The cause's word in logs, reports and the console.
    pub fn name(self) -> &'static str {
        match self {
            TripCause::DqLimit => "dq_limit",
            TripCause::NonFinite => "non_finite",
            TripCause::OutsideWorkspace => "outside_workspace",
            TripCause::SequenceGaps => "sequence_gaps",
            TripCause::SetpointSilence => "setpoint_silence",
            TripCause::IdentityMismatch => "identity_mismatch",
            TripCause::IdentityMissing => "identity_missing",
            TripCause::FollowingError => "following_error",
            TripCause::FeedbackSilence => "feedback_silence",
            TripCause::RpdoMismatch => "rpdo_mismatch",
            TripCause::CableCount => "cable_count",
            TripCause::SequenceRegression => "sequence_regression",
            TripCause::IpcError => "ipc_error",
            TripCause::ForceSlack => "force_slack",
            TripCause::ForceOverload => "force_overload",
            TripCause::ForceSilence => "force_silence",
            TripCause::MotionVelocity => "motion_velocity",
            TripCause::MotionAcceleration => "motion_acceleration",
            TripCause::FollowingUnchecked => "following_unchecked",
            TripCause::BusObservation => "bus_observation",
            TripCause::EStopEvent => "estop_event",
            TripCause::ForgedEvent => "forged_event",
            TripCause::CanBusError => "can_bus_error",
            TripCause::Impersonation => "impersonation",
            TripCause::EStopCircuit => "estop_circuit",
            TripCause::SafetyIoSilence => "safety_io_silence",
            TripCause::RpdoUnchecked => "rpdo_unchecked",
            TripCause::UnplannedStreamEnd => "unplanned_stream_end",
            TripCause::ForeignPublisher => "foreign_publisher",
            TripCause::FeedbackStale => "feedback_stale",
        }
    }
}

impl std::fmt::Display for TripCause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The drive bus state ([`crate::BusState`]) of drive-io's feedback and heartbeat.
impl From<crate::BusState> for u32 {
    fn from(v: crate::BusState) -> u32 {
        v as u32
    }
}

impl TryFrom<u32> for crate::BusState {
    type Error = UnknownCode;

    fn try_from(code: u32) -> Result<Self, UnknownCode> {
        crate::BusState::from_u32(code).ok_or(UnknownCode {
            what: "bus state",
            code,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BusState;

    fn round_trip<T>(all: &[T])
    where
        T: Copy + PartialEq + std::fmt::Debug + Into<u32> + TryFrom<u32, Error = UnknownCode>,
    {
        for &v in all {
            let code: u32 = v.into();
            assert_eq!(T::try_from(code), Ok(v), "{v:?} = {code}");
        }
    }

    #[test]
    fn every_variant_round_trips() {
        round_trip(MotionState::ALL);
        round_trip(MonitorState::ALL);
        round_trip(MonitorCode::ALL);
        round_trip(FaultCode::ALL);
        round_trip(PlantState::ALL);
        round_trip(TripCause::ALL);
        round_trip(&[
            BusState::Booting,
            BusState::Ready,
            BusState::Running,
            BusState::StaleStop,
            BusState::EStop,
            BusState::Fault,
        ]);
    }

    #[test]
    fn an_unknown_code_is_an_error_naming_it() {
        assert_eq!(
            MotionState::try_from(0),
            Err(UnknownCode {
                what: "motion state",
                code: 0
            })
        );
        assert_eq!(
            MonitorState::try_from(4).unwrap_err().to_string(),
            "unknown monitor state code 4 (0x4)"
        );
        assert!(MonitorCode::try_from(0x5AFE_0008).is_err());
        assert!(MonitorCode::try_from(0).is_err());
        assert!(FaultCode::try_from(11).is_err());
        assert!(PlantState::try_from(2).is_err());
        assert!(TripCause::try_from(0).is_err());
        assert!(TripCause::try_from(31).is_err());
        // A u32 whose low byte is a cause is not that cause.
        assert!(TripCause::try_from(0x100 + 1).is_err());
        assert_eq!(
            BusState::try_from(6),
            Err(UnknownCode {
                what: "bus state",
                code: 6
            })
        );
        assert_eq!(TripCause::from_code(u32::MAX), None);
    }

    /// The numbers are the wire contract: renumbering one breaks every process of another
    /// build (and the logs and evidence that quote them).
    #[test]
    fn the_numeric_values_are_pinned() {
        let motion: Vec<u32> = MotionState::ALL.iter().map(|&v| v.into()).collect();
        assert_eq!(motion, [1, 2, 3, 4, 5, 6]);
        assert_eq!(MotionState::Running.code(), 1);
        assert_eq!(MotionState::EStopped.code(), 2);
        assert_eq!(MotionState::Refused.code(), 3);
        assert_eq!(MotionState::Holding.code(), 4);
        assert_eq!(MotionState::Stopping.code(), 5);
        assert_eq!(MotionState::Plan.code(), 6);
        assert_eq!(PLAN_OPEN_END, u64::MAX);
        assert_eq!(MonitorState::Armed.code(), 1);
        assert_eq!(MonitorState::Tripped.code(), 2);
        assert_eq!(MonitorState::NotReady.code(), 3);
        assert_eq!(MonitorState::ALL.len(), 3);
        assert_eq!(MonitorCode::ResetRequest.code(), 0x5AFE_0001);
        assert_eq!(MonitorCode::ResetAccepted.code(), 0x5AFE_0002);
        assert_eq!(MonitorCode::ResetRefused.code(), 0x5AFE_0003);
        assert_eq!(MonitorCode::ResetNotTripped.code(), 0x5AFE_0004);
        assert_eq!(MonitorCode::ResetNotReady.code(), 0x5AFE_0005);
        assert_eq!(MonitorCode::ResetDenied.code(), 0x5AFE_0006);
        assert_eq!(MonitorCode::ResetExhausted.code(), 0x5AFE_0007);
        assert_eq!(MonitorCode::EpochAnnounce.code(), 0x5AFE_0010);
        assert_eq!(MonitorCode::ALL.len(), 8);
        let faults: Vec<u32> = FaultCode::ALL.iter().map(|&v| v.into()).collect();
        assert_eq!(faults, (0..=10).collect::<Vec<u32>>());
        assert_eq!(FaultCode::Emcy.code(), 2);
        assert_eq!(FaultCode::SetpointStep.code(), 6);
        assert_eq!(FaultCode::BusError.code(), 8);
        assert_eq!(FaultCode::ForceLimit.code(), 10);
        assert_eq!(PlantState::Free.code(), 0);
        assert_eq!(PlantState::Braked.code(), 1);
        let causes: Vec<u32> = TripCause::ALL.iter().map(|&v| v.into()).collect();
        assert_eq!(causes, (1..=30).collect::<Vec<u32>>());
        assert_eq!(TripCause::DqLimit.code(), 1);
        assert_eq!(TripCause::IpcError.code(), 13);
        assert_eq!(TripCause::EStopEvent.code(), 21);
        assert_eq!(TripCause::FeedbackStale.code(), 30);
        assert_eq!(TripCause::DqLimit.to_string(), "dq_limit");
        let bus: Vec<u32> = [
            BusState::Booting,
            BusState::Ready,
            BusState::Running,
            BusState::StaleStop,
            BusState::EStop,
            BusState::Fault,
        ]
        .iter()
        .map(|&v| v.into())
        .collect();
        assert_eq!(bus, [0, 1, 2, 3, 4, 5]);
    }

    #[test]
    fn the_reset_answers_are_the_answers() {
        let answers: Vec<MonitorCode> = MonitorCode::ALL
            .iter()
            .copied()
            .filter(|c| c.is_reset_answer())
            .collect();
        assert_eq!(
            answers,
            [
                MonitorCode::ResetAccepted,
                MonitorCode::ResetRefused,
                MonitorCode::ResetNotTripped,
                MonitorCode::ResetNotReady,
                MonitorCode::ResetDenied,
                MonitorCode::ResetExhausted,
            ]
        );
        assert!(MotionState::EStopped.is_latched() && MotionState::Refused.is_latched());
        assert!(!MotionState::Holding.is_latched());
    }
}
