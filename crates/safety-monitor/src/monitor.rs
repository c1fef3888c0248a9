//! The monitor's core: every check of one 15 ms cycle and the latched state machine. Pure logic
//! (inputs in, decisions out), no I/O, no allocation after construction, never panics on any
//! payload: the process ([`crate::daemon`]) feeds it from iceoryx2 and CAN.
//!
//! Per cycle, for EVERY setpoint published since the last cycle (sec. 5.6):
//! * Δq_i = φ*_i(x) − q_θ,i with the monitor's own standard kinematics; |Δq_i| > limit
//!   (≤ 100 mm) ⇒ trip. q_θ is the setpoint's `cable_length_m`, i.e. the drive signal INCLUDING
//!   the surrogate offset: sec. 5.6 compares the drive signal with the redundant computation,
//!   and eq. (5.27) bounds the offset below the same limit, so the offset is what consumes the
//!   budget (it is NOT subtracted: a faulty offset must trip the monitor too);
//! * NaN/inf anywhere in the pose or the lengths, a wrong cable count, a pose outside the
//!   workspace box, a sequence number that does not increase;
//! * lost setpoints (sequence gaps, including subscriber-buffer overflow) counted over a sliding
//!   window of cycles; more than the configured count ⇒ trip.
//!
//! Per cycle: no new setpoint for N cycles (frozen/dead loop), no platform identity (or a
//! different one) than the monitor computed, drive-io feedback silent or its measured lengths
//! farther than the following-error bound from the setpoints it applied, RPDO targets on the bus
//! farther than the limit from φ*(x) of every recent setpoint.
//!
//! The first fault latches [`MonitorState::Tripped`], which carries its [`TripRecord`], and is logged
//! ([`TripLog`]); the checks keep running while tripped, and every cause seen while tripped is
//! latched too (per-cause latches).
//! [`Monitor::request_reset`] (the operator's manual reset, ISO 13849-1 §5.2.2) is accepted
//! only when no fault was seen for `reset_clear_cycles` consecutive cycles AND every latched
//! cause was POSITIVELY shown cleared for as many cycles (see [`evidence`]): absence of a fault
//! is not enough for causes that cannot recur while stopped. Only the acceptance mints a
//! [`authority::ResetToken`], the one value that leaves the latch, and advances the reset
//! epoch carried in the safety heartbeat (drives and drive-io leave their inhibit/latch only on
//! a newer epoch).

use crate::config::MonitorConfig;
use crate::kinematics::StandardKinematics;
use crate::platform::WorkspaceBox;
use crate::trip::{Cause, CauseSet, Fault, TripLog, TripRecord};
use can_transport::safety_frame::{SafetyHeartbeat, SafetyState};
use crs_ipc::{
    BusState, CONTRACT_VERSION, DriveFeedback, JointSetpoint, MAX_CABLES, PlatformId,
    PlatformIdentity,
};
use glam::{DMat3, DQuat, DVec3};

/// `value <= limit`, false for NaN: every comparison with a limit is written so that a NaN
/// fails the check (trips) instead of passing it.
#[inline]
fn within(value: f64, limit: f64) -> bool {
    value <= limit
}

/// Setpoints remembered for matching drive feedback and RPDO targets (256 ms at 1 kHz).
pub const HISTORY: usize = 256;
/// Largest gap window (cycles).
pub const MAX_GAP_WINDOW: usize = 10_000;

/// The thresholds of every check (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub dq_limit_m: f64,
    pub silence_cycles: u32,
    pub max_missing_setpoints: u32,
    pub gap_window_cycles: u32,
    pub identity_grace_cycles: u32,
    pub workspace: WorkspaceBox,
    pub reset_clear_cycles: u32,
    pub check_following_error: bool,
    pub following_error_m: f64,
    pub window_setpoints: u32,
    /// 0 = off.
    pub feedback_silence_cycles: u32,
    /// Cycles in a row with feedback but none of it checkable before the check trips.
    pub unchecked_cycles: u32,
    pub check_rpdo: bool,
    /// Start in [`MonitorState::NotReady`] (STOP) until [`Readiness::ready`].
    pub require_ready: bool,
    pub forces: ForceLimits,
    pub motion: MotionCheck,
}

/// Plausibility of consecutive setpoint poses (table 5.1 limits × (1 + margin)), SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionCheck {
    pub check: bool,
    /// Stream time per sequence number, s.
    pub period_s: f64,
    pub linear_velocity: f64,
    pub angular_velocity: f64,
    pub linear_acceleration: f64,
    pub angular_acceleration: f64,
}

/// The previous setpoint's pose (for the step, velocity and acceleration checks).
#[derive(Debug, Clone, Copy)]
struct PrevPose {
    sequence: u64,
    r: DVec3,
    rot: DMat3,
    /// Linear and angular velocity of the step that led here (None: a hold, a gap or the first).
    vel: Option<(DVec3, DVec3)>,
}

/// Thresholds of the measured-force supervision (seed §5.1, table 5.1), N.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceLimits {
    pub check: bool,
    /// Slack below this (f_min − margin) ...
    pub slack_below_n: f64,
    /// ... overload above this (f_max + margin) ...
    pub overload_above_n: f64,
    /// ... for at least this long (by the readings' receive times).
    pub filter_ns: u64,
    /// A single reading above this trips at once (the winches' rating).
    pub hard_limit_n: f64,
    /// Cycles an operational drive may go without a force reading.
    pub silence_cycles: u32,
}

impl Limits {
    pub fn from_config(c: &MonitorConfig) -> Self {
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
                filter_ns: (c.forces.filter_ms * 1e6) as u64,
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
        }
    }
}

/// Per-cable state of the force supervision.
#[derive(Debug, Clone, Copy, Default)]
struct ForceWatch {
    /// The drive reports NMT operational (it runs and sends PDOs).
    operational: bool,
    /// Readings this cycle.
    readings: u32,
    /// Cycles in a row without a reading while operational.
    silent: u32,
    /// Receive time of the first reading of the current slack / overload episode.
    slack_since_ns: Option<u64>,
    over_since_ns: Option<u64>,
}

/// The monitor's state, with the data each state has: a trip cannot exist without its
/// record, and the record cannot be read while the monitor is not tripped (issue 14). Private
/// to [`Monitor`], read through [`Monitor::state`]; the only transition out of
/// [`MonitorState::Tripped`] consumes an [`authority::ResetToken`]. [`StateCode`] is the same
/// state without its data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MonitorState {
    /// Start-up: no fault, but the drives may not be enabled (the safety heartbeat says STOP)
    /// until every drive is operational with live force readings (see
    /// [`Monitor::readiness`]); the configuration was verified when it was loaded. Every check
    /// runs; a fault trips.
    NotReady,
    /// No fault latched: the safety heartbeat says RUN, the drives may enable and hold.
    /// MOTION is permitted only once the platform identity is verified as well: a setpoint
    /// that moves the pose without it trips `identity_missing` at once (the stack starts
    /// motion-core after the drives are enabled, which needs this RUN, so the identity cannot
    /// be a condition of RUN itself without a deadlock; docs/safety-monitor.md "Start-up").
    Armed,
    /// E-stop latched until an accepted reset: the safety heartbeat says STOP. Carries the
    /// first fault that latched it (cause, cable, value, limit, sequence, cycle, time).
    Tripped(TripRecord),
}

impl MonitorState {
    /// The state without its data (for comparisons; its [`StateCode::code`] is what the
    /// heartbeat and the state events carry).
    pub fn state_code(&self) -> StateCode {
        match self {
            MonitorState::NotReady => StateCode::NotReady,
            MonitorState::Armed => StateCode::Armed,
            MonitorState::Tripped(_) => StateCode::Tripped,
        }
    }

    /// Code in `Heartbeat::state` / `StateEvent::state`: [`StateCode::code`] of
    /// [`MonitorState::state_code`].
    pub fn code(&self) -> u32 {
        self.state_code().code()
    }

    /// The trip that latched the e-stop; None unless tripped.
    pub fn trip(&self) -> Option<&TripRecord> {
        match self {
            MonitorState::Tripped(rec) => Some(rec),
            MonitorState::NotReady | MonitorState::Armed => None,
        }
    }

    pub fn is_tripped(&self) -> bool {
        matches!(self, MonitorState::Tripped(_))
    }
}

/// The state as a code: [`MonitorState`] without its data, for comparisons and for the state
/// code on the process bus (`Heartbeat::state` / `StateEvent::state`,
/// [`crs_ipc::monitor_state`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StateCode {
    /// See [`MonitorState::NotReady`].
    NotReady,
    /// See [`MonitorState::Armed`].
    Armed,
    /// See [`MonitorState::Tripped`].
    Tripped,
}

impl StateCode {
    /// Code in `Heartbeat::state` / `StateEvent::state` (the contract's
    /// [`crs_ipc::monitor_state`] codes; crs-console decodes the same constants).
    pub fn code(self) -> u32 {
        match self {
            StateCode::Armed => crs_ipc::monitor_state::ARMED,
            StateCode::Tripped => crs_ipc::monitor_state::TRIPPED,
            StateCode::NotReady => crs_ipc::monitor_state::NOT_READY,
        }
    }

    /// The state of a code received on the process bus; None for a code the contract does
    /// not define.
    pub fn from_code(code: u32) -> Option<StateCode> {
        match code {
            crs_ipc::monitor_state::ARMED => Some(StateCode::Armed),
            crs_ipc::monitor_state::TRIPPED => Some(StateCode::Tripped),
            crs_ipc::monitor_state::NOT_READY => Some(StateCode::NotReady),
            _ => None,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum IdentityState {
    Unknown,
    Verified,
    Mismatch,
}

#[derive(Debug, Clone, Copy)]
struct Entry {
    sequence: u64,
    timestamp_ns: u64,
    q_cmd: [f64; MAX_CABLES],
    q_star: [f64; MAX_CABLES],
}

const EMPTY: Entry = Entry {
    sequence: 0,
    timestamp_ns: 0,
    q_cmd: [0.0; MAX_CABLES],
    q_star: [0.0; MAX_CABLES],
};

/// Outcome of [`Monitor::end_cycle`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleReport {
    pub state: StateCode,
    /// Set in the cycle that latched the e-stop.
    pub new_trip: Option<TripRecord>,
    /// Every cause seen this cycle (also while tripped).
    pub faults: CauseSet,
    pub setpoints: u32,
    pub missing: u32,
    /// Set in the cycle that left [`MonitorState::NotReady`] for `Armed`.
    pub became_ready: bool,
    /// The start-up conditions as this cycle saw them (what a not-ready monitor waits for).
    pub readiness: Readiness,
}

/// What the monitor still waits for before it permits motion (bit i = cable i).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Readiness {
    pub identity_verified: bool,
    /// Drives whose heartbeat does not say operational.
    pub not_operational: u32,
    /// Drives that sent no force reading (TPDO2) in the last cycle.
    pub no_feedback: u32,
}

impl Readiness {
    /// Every drive operational with live feedback (the identity is reported, not required:
    /// see [`MonitorState::NotReady`]).
    pub fn ready(&self) -> bool {
        self.not_operational == 0 && self.no_feedback == 0
    }
}

/// Answer to a reset request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetDecision {
    /// Nothing was latched: nothing changes anywhere (no epoch, no NMT start, no Reset event).
    NotTripped,
    /// The latch is released; the reset epoch advanced to this value.
    Accepted { epoch: u32 },
    /// Refused: this cause was seen, or not positively shown cleared, within the last
    /// `reset_clear_cycles` cycles.
    Refused(Cause),
    /// Nothing to reset: the monitor has not verified its start-up conditions yet.
    NotReady,
}

/// The reset authority (issue 16, type-state): the latch of [`Monitor`] is left only with a
/// [`authority::ResetToken`], and the only code that can make one is [`authority::verify`],
/// the monitor's check of the per-cause evidence. Minting a token advances the reset epoch.
pub mod authority {
    use super::{Cause, CauseSet};
    use can_transport::safety_frame::epoch_newer;

    /// Proof that the monitor's verification accepted an operator reset; carries the new
    /// epoch. No public constructor (private field), not `Clone`: used once.
    ///
    /// ```compile_fail
    /// let forged = safety_monitor::monitor::authority::ResetToken { epoch: 1 };
    /// ```
    #[derive(Debug, PartialEq, Eq)]
    pub struct ResetToken {
        epoch: u32,
    }

    impl ResetToken {
        pub fn epoch(&self) -> u32 {
            self.epoch
        }
    }

    /// Per-cause evidence streaks (cycles in a row a latched cause was positively shown
    /// cleared), indexed by cause code.
    pub type Streaks = [u16; 32];

    /// Accepts the reset if no fault was seen for `need` cycles (`clean`) and every latched
    /// cause was shown cleared for `need` cycles; then advances `epoch` and mints the token.
    /// Otherwise the cause that blocks it.
    pub(super) fn verify(
        latched: CauseSet,
        streaks: &Streaks,
        clean: u32,
        need: u32,
        epoch: &mut u32,
    ) -> Result<ResetToken, Cause> {
        if let Some(c) = latched
            .iter()
            .find(|c| u32::from(streaks[usize::from(c.code())]) < need)
        {
            return Err(c);
        }
        if clean < need {
            return Err(latched.first().unwrap_or(Cause::IpcError));
        }
        let next = epoch.wrapping_add(1);
        debug_assert!(epoch_newer(next, *epoch));
        *epoch = next;
        Ok(ResetToken { epoch: next })
    }
}

/// Which causes this cycle's inputs POSITIVELY show cleared (not merely absent), for the
/// per-cause reset evidence (issue 16). Evaluated while tripped (drives NMT-stopped and
/// braked, motion-core holding):
/// * setpoint stream causes (Δq, NaN, box, cable count, sequence, gaps, silence, motion):
///   setpoints arrived this cycle and all passed, or the stream is ended (no producer);
/// * identity: the announced identity is verified, or the stream is ended (a new stream must
///   announce it before its grace);
/// * drive-io causes (following error, feedback silence/unchecked, RPDO mismatch): drive-io's
///   feedback arrived this cycle and every measured length is finite and within the
///   following-error bound of the newest (held) setpoint;
/// * force causes: every drive reported its NMT state within the last second and the
///   readings of the operational ones are finite and within [f_min − margin, f_max + margin]
///   this cycle (drives NMT-stopped send no forces: their forces are checked again, within the
///   filter time, after the NMT start that follows an accepted reset);
/// * process-bus and bus-observation causes: this cycle's receives and the reader's batches
///   completed without error; an e-stop event of another process: it is a one-shot command,
///   acknowledged by the operator's reset itself (the stop it caused is verified through the
///   other classes' evidence).
pub mod evidence {
    use super::Cause;

    pub fn class(c: Cause) -> Class {
        use Cause::*;
        match c {
            DqLimit | NonFinite | OutsideWorkspace | SequenceGaps | SetpointSilence
            | CableCount | SequenceRegression | MotionVelocity | MotionAcceleration
            | UnplannedStreamEnd => Class::Stream,
            IdentityMismatch | IdentityMissing => Class::Identity,
            FollowingError | FeedbackSilence | RpdoMismatch | FollowingUnchecked => Class::Feedback,
            ForceSlack | ForceOverload | ForceSilence => Class::Forces,
            IpcError | BusObservation | EStopEvent | ForgedEvent | CanBusError
            | ForeignPublisher => Class::Receive,
        }
    }

    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Class {
        Stream,
        Identity,
        Feedback,
        Forces,
        Receive,
    }
}

/// A drive's heartbeat older than this is not evidence of a reporting drive (ns).
const DRIVE_REPORT_MAX_AGE_NS: u64 = 1_000_000_000;

/// Running statistics (for the heartbeat, logs and the bench).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Stats {
    pub cycles: u64,
    pub setpoints_checked: u64,
    pub setpoints_missing: u64,
    pub feedback_checked: u64,
    pub rpdo_checked: u64,
    /// Force readings checked.
    pub forces_checked: u64,
    /// Largest |Δq| seen on any cable (m).
    pub max_abs_dq_m: f64,
}

/// The monitor core. Construct once (allocates the gap window), then per cycle: `on_*` for every
/// input, [`Monitor::end_cycle`] once.
pub struct Monitor {
    lim: Limits,
    kin: StandardKinematics,
    m: usize,
    identity: PlatformId,
    /// NotReady / Armed / Tripped with its record: written only by [`Monitor::end_cycle`]
    /// (NotReady → Armed, any → Tripped) and [`Monitor::release`] (the verified reset).
    state: MonitorState,
    log: TripLog,
    stats: Stats,
    // This cycle.
    faults: CauseSet,
    first: Option<Fault>,
    new_setpoints: u32,
    missing: u32,
    feedback_count: u32,
    // Across cycles.
    last_faults: CauseSet,
    clear_streak: u32,
    /// Every cause seen since the trip (per-cause latches) and their evidence streaks.
    latched: CauseSet,
    evidence: authority::Streaks,
    /// The reset epoch (heartbeat bytes 4..8): advanced only by [`authority::verify`].
    epoch: u32,
    /// This cycle's evidence inputs: drive-io feedback following the held setpoint, force
    /// readings out of range, drives' last NMT report (receive clock).
    fb_following: bool,
    fb_not_following: bool,
    force_out_of_range: bool,
    drive_report_ns: [u64; MAX_CABLES],
    last_sequence: Option<u64>,
    seen_setpoint: bool,
    silent_cycles: u32,
    gap_ring: Vec<u32>,
    gap_pos: usize,
    gap_sum: u64,
    identity_state: IdentityState,
    unverified_cycles: u32,
    seen_feedback: bool,
    feedback_silent: u32,
    stream_end: bool,
    hist: Box<[Entry; HISTORY]>,
    hist_len: usize,
    hist_next: usize,
    q: [f64; MAX_CABLES],
    force: [ForceWatch; MAX_CABLES],
    /// Feedback samples of this cycle that were / could not be checked, and the streak of
    /// cycles in which none could.
    fb_checked: u32,
    fb_unchecked: u32,
    unchecked_streak: u32,
    prev_pose: Option<PrevPose>,
    /// The last setpoint's pose of this stream (start-up: motion needs a verified identity).
    last_pose: Option<[f64; 6]>,
    /// The monitor's clock at the end of the last cycle that brought setpoints, and the last
    /// pose of that cycle (the own-clock velocity check).
    cycle_ref: Option<(u64, DVec3, DMat3)>,
    /// The plan the producer announced (sequence of its last setpoint) and whether the stream
    /// holds (issue 16: STOPPING only at the end of an announced plan).
    plan: PlanWatch,
}

/// What the monitor knows about the producer's plan: its announced end and the newest
/// setpoints (a stream holds when consecutive setpoints carry exactly the same pose).
#[derive(Debug, Clone, Copy, Default)]
struct PlanWatch {
    end: Option<u64>,
    last_pose: Option<[f64; 6]>,
    hold_run: u32,
}

/// Consecutive identical setpoint poses that make a hold (the stream stands still).
pub const PLAN_HOLD_SETPOINTS: u32 = 2;

/// Consecutive identical poses before a stream without a planned end (motion cueing) may end:
/// 50 setpoints (50 ms at the spec's 1 ms loop) of standing still.
pub const OPEN_END_HOLD_SETPOINTS: u32 = 50;

impl Monitor {
    /// `identity`: the platform identity the monitor computed itself
    /// ([`crate::identity::platform_identity`]).
    pub fn new(lim: Limits, kin: StandardKinematics, identity: PlatformId) -> Self {
        let window = (lim.gap_window_cycles.max(1) as usize).min(MAX_GAP_WINDOW);
        Self {
            m: kin.cables(),
            lim,
            kin,
            identity,
            state: if lim.require_ready {
                MonitorState::NotReady
            } else {
                MonitorState::Armed
            },
            log: TripLog::default(),
            stats: Stats::default(),
            faults: CauseSet::default(),
            first: None,
            new_setpoints: 0,
            missing: 0,
            feedback_count: 0,
            last_faults: CauseSet::default(),
            clear_streak: 0,
            latched: CauseSet::default(),
            evidence: [0; 32],
            epoch: 0,
            fb_following: false,
            fb_not_following: false,
            force_out_of_range: false,
            drive_report_ns: [0; MAX_CABLES],
            last_sequence: None,
            seen_setpoint: false,
            silent_cycles: 0,
            gap_ring: vec![0; window],
            gap_pos: 0,
            gap_sum: 0,
            identity_state: IdentityState::Unknown,
            unverified_cycles: 0,
            seen_feedback: false,
            feedback_silent: 0,
            stream_end: false,
            hist: Box::new([EMPTY; HISTORY]),
            hist_len: 0,
            hist_next: 0,
            q: [0.0; MAX_CABLES],
            force: [ForceWatch::default(); MAX_CABLES],
            fb_checked: 0,
            fb_unchecked: 0,
            unchecked_streak: 0,
            prev_pose: None,
            last_pose: None,
            cycle_ref: None,
            plan: PlanWatch::default(),
        }
    }

    /// The producer announced its plan: `end` is the sequence number of its last planned
    /// setpoint (`crs_ipc::motion_state::PLAN`; [`crs_ipc::motion_state::PLAN_OPEN_END`] for a
    /// stream without a planned end).
    pub fn on_plan_announced(&mut self, end: u64) {
        self.plan.end = Some(end);
    }

    /// True when an end of the stream announced now would be accepted: a plan was announced,
    /// the stream has reached its last setpoint and holds.
    pub fn stream_end_planned(&self) -> bool {
        match (self.plan.end, self.last_sequence) {
            // A stream without a planned end (motion cueing, the ride source) ends when the
            // operator ends the ride: accepted only while the platform holds, as at a plan's
            // end; while it moves, an end is refused (a forged STOPPING cannot disarm the
            // checks of a moving platform).
            (Some(end), Some(_)) if end == crs_ipc::motion_state::PLAN_OPEN_END => {
                self.plan.hold_run >= OPEN_END_HOLD_SETPOINTS
            }
            (Some(end), Some(last)) => last >= end && self.plan.hold_run >= PLAN_HOLD_SETPOINTS,
            // No setpoint at all since the last end: nothing to disarm.
            (_, None) => !self.seen_setpoint,
            (None, Some(_)) => false,
        }
    }

    /// Hold tracking for [`Monitor::stream_end_planned`] (every setpoint, in order).
    fn track_plan(&mut self, sp: &JointSetpoint) {
        self.plan.hold_run = match self.plan.last_pose {
            Some(p) if p == sp.pose => self.plan.hold_run.saturating_add(1),
            _ => 1,
        };
        self.plan.last_pose = Some(sp.pose);
    }

    /// Consumes this cycle's end-of-stream announcement: accepted only at the end of the
    /// announced plan (issue 16); otherwise `unplanned_stream_end` and the checks stay armed.
    fn take_stream_end(&mut self) -> bool {
        if !std::mem::take(&mut self.stream_end) {
            return false;
        }
        if self.stream_end_planned() {
            return true;
        }
        let end = self.plan.end;
        self.fault(Fault {
            sequence: self.last_sequence.unwrap_or(0),
            value: end.map_or(-1.0, |e| e as f64),
            limit: f64::from(self.plan.hold_run),
            ..Fault::new(Cause::UnplannedStreamEnd)
        });
        false
    }

    /// A single-owner stream has a second or a foreign publisher (the daemon's service
    /// introspection; `value` = number of publishers seen).
    pub fn on_foreign_publisher(&mut self, publishers: u32) {
        self.fault(Fault {
            value: f64::from(publishers),
            ..Fault::new(Cause::ForeignPublisher)
        });
    }

    /// Sets the initial reset epoch (construction only). The daemon starts from its wall clock
    /// in seconds, so a restarted monitor's epoch is newer than the last one of its previous
    /// run (unless that run accepted more than one reset per second on average: then the
    /// watches stay inhibited until enough resets, which fails safe).
    pub fn with_reset_epoch(mut self, epoch: u32) -> Self {
        self.epoch = epoch;
        self
    }

    /// The current reset epoch.
    pub fn reset_epoch(&self) -> u32 {
        self.epoch
    }

    /// The causes latched since the trip (empty while not tripped).
    pub fn latched(&self) -> CauseSet {
        self.latched
    }

    /// The state with its data (the trip record while tripped).
    pub fn state(&self) -> &MonitorState {
        &self.state
    }
    /// The state without its data.
    pub fn state_code(&self) -> StateCode {
        self.state.state_code()
    }
    /// The trip that latched the current e-stop (None while not tripped).
    pub fn trip(&self) -> Option<&TripRecord> {
        self.state.trip()
    }
    pub fn trip_log(&self) -> &TripLog {
        &self.log
    }
    pub fn stats(&self) -> &Stats {
        &self.stats
    }
    pub fn limits(&self) -> &Limits {
        &self.lim
    }
    /// Causes seen in the last completed cycle.
    pub fn last_faults(&self) -> CauseSet {
        self.last_faults
    }
    /// True once a platform identity equal to the monitor's own was announced (and no other
    /// since).
    pub fn identity_verified(&self) -> bool {
        self.identity_state == IdentityState::Verified
    }

    /// The safety heartbeat to send this cycle (`counter` +1 per pair sent).
    pub fn heartbeat(&self, counter: u16) -> SafetyHeartbeat {
        let (state, cause) = match &self.state {
            MonitorState::Tripped(t) => (SafetyState::Stop, t.fault.cause.code()),
            MonitorState::NotReady => (SafetyState::Stop, 0),
            MonitorState::Armed => (SafetyState::Run, 0),
        };
        SafetyHeartbeat {
            state,
            cause,
            counter,
            epoch: self.epoch,
        }
    }

    fn fault(&mut self, f: Fault) {
        self.faults.insert(f.cause);
        if self.first.is_none() {
            self.first = Some(f);
        }
    }

    /// The setpoint producer announced a graceful end of its stream (it is stopping): at the
    /// end of this cycle the silence and sequence checks are disarmed and the identity must be
    /// announced again; the next setpoint (e.g. of a restarted producer, numbering from 1)
    /// re-arms them. A frozen or killed producer cannot announce, so it still trips.
    pub fn on_stream_end(&mut self) {
        self.stream_end = true;
    }

    /// Another process published an e-stop (operator console, e-stop input): latched like
    /// every fault, so only the monitor's verified reset ends the stop everywhere.
    pub fn on_estop_event(&mut self, source: u32) {
        self.fault(Fault {
            value: f64::from(source),
            ..Fault::new(Cause::EStopEvent)
        });
    }

    /// A state event claiming the monitor's source that this monitor did not publish.
    pub fn on_forged_event(&mut self, kind: u32) {
        self.fault(Fault {
            value: f64::from(kind),
            ..Fault::new(Cause::ForgedEvent)
        });
    }

    /// A process-bus failure (receive error, foreign contract version).
    pub fn on_ipc_error(&mut self) {
        self.fault(Fault::new(Cause::IpcError));
    }

    /// The platform identity motion-core announces.
    pub fn on_identity(&mut self, id: &PlatformIdentity) {
        self.identity_state = if id.version == CONTRACT_VERSION
            && id.hash == self.identity
            && id.cable_count as usize == self.m
        {
            IdentityState::Verified
        } else {
            IdentityState::Mismatch
        };
    }

    /// Checks one setpoint (call for every setpoint received, in order).
    pub fn on_setpoint(&mut self, sp: &JointSetpoint) {
        self.new_setpoints += 1;
        self.seen_setpoint = true;
        self.stats.setpoints_checked += 1;
        self.track_plan(sp);
        let at = |cause: Cause| Fault {
            sequence: sp.sequence,
            ..Fault::new(cause)
        };
        if let Some(last) = self.last_sequence {
            if sp.sequence <= last {
                self.fault(Fault {
                    value: sp.sequence as f64,
                    limit: last as f64,
                    ..at(Cause::SequenceRegression)
                });
            } else {
                let lost = (sp.sequence - last - 1).min(u64::from(u32::MAX)) as u32;
                self.missing = self.missing.saturating_add(lost);
            }
        }
        self.last_sequence = Some(sp.sequence);
        if sp.version != CONTRACT_VERSION {
            self.fault(at(Cause::IpcError));
            return;
        }
        if sp.cable_count as usize != self.m {
            self.fault(Fault {
                value: f64::from(sp.cable_count),
                limit: self.m as f64,
                ..at(Cause::CableCount)
            });
            return;
        }
        let m = self.m;
        if !sp.pose.iter().all(|v| v.is_finite()) {
            self.fault(at(Cause::NonFinite));
            return;
        }
        if let Some(i) = sp.cable_length_m[..m].iter().position(|v| !v.is_finite()) {
            self.fault(Fault {
                cable: Some(i as u8),
                ..at(Cause::NonFinite)
            });
            return;
        }
        if !self.lim.workspace.contains(&sp.pose) {
            self.fault(at(Cause::OutsideWorkspace));
        }
        // Motion is permitted only with a verified platform identity (start-up, issue 15):
        // the RUN heartbeat lets the drives enable and HOLD; a setpoint that moves the pose
        // while the identity is not verified trips at once. Holding setpoints are tolerated
        // for `identity_grace_cycles` (the identity of a producer the monitor subscribed to
        // late arrives with its next announcement).
        if self.identity_state != IdentityState::Verified
            && self.last_pose.is_some_and(|p| p != sp.pose)
        {
            self.fault(Fault {
                value: f64::from(self.unverified_cycles),
                limit: 0.0,
                ..at(Cause::IdentityMissing)
            });
        }
        self.last_pose = Some(sp.pose);
        if self.lim.motion.check {
            self.check_motion(sp);
        }
        self.kin.lengths(&sp.pose, &mut self.q);
        // The worst cable of this setpoint is the one reported.
        let mut worst: Option<(usize, f64)> = None;
        for i in 0..m {
            let dq = self.q[i] - sp.cable_length_m[i];
            let a = dq.abs();
            if a > self.stats.max_abs_dq_m {
                self.stats.max_abs_dq_m = a;
            }
            if !within(a, self.lim.dq_limit_m) && worst.is_none_or(|(_, w)| !within(a, w.abs())) {
                worst = Some((i, dq));
            }
        }
        if let Some((i, dq)) = worst {
            self.fault(Fault {
                cable: Some(i as u8),
                value: dq,
                limit: self.lim.dq_limit_m,
                ..at(Cause::DqLimit)
            });
        }
        let e = &mut self.hist[self.hist_next];
        e.sequence = sp.sequence;
        e.timestamp_ns = sp.timestamp_ns;
        e.q_cmd[..m].copy_from_slice(&sp.cable_length_m[..m]);
        e.q_star[..m].copy_from_slice(&self.q[..m]);
        self.hist_next = (self.hist_next + 1) % HISTORY;
        self.hist_len = (self.hist_len + 1).min(HISTORY);
    }

    /// Velocity and acceleration implied by consecutive setpoints: one sequence number is one
    /// stream period (the sender's timestamps are not used). A step to exactly the same pose
    /// is a hold (motion-core holding after an e-stop or refusal; the drives decelerate on
    /// their own), which ends the acceleration chain instead of counting as a deceleration.
    fn check_motion(&mut self, sp: &JointSetpoint) {
        let mc = self.lim.motion;
        let p = &sp.pose;
        let r = DVec3::new(p[0], p[1], p[2]);
        let rot = StandardKinematics::rotation(p[3], p[4], p[5]);
        let mut vel = None;
        if let Some(prev) = self.prev_pose
            && sp.sequence > prev.sequence
        {
            let n = sp.sequence - prev.sequence;
            let dt = n as f64 * mc.period_s;
            let dr = r - prev.r;
            // World-frame incremental rotation R_k R_{k-1}^T as axis × angle.
            let (axis, angle) = DQuat::from_mat3(&(rot * prev.rot.transpose())).to_axis_angle();
            let (v, w) = (dr / dt, axis * (angle / dt));
            let at = |value: f64, limit: f64, cause: Cause| Fault {
                sequence: sp.sequence,
                value,
                limit,
                ..Fault::new(cause)
            };
            if !within(v.length(), mc.linear_velocity) {
                self.fault(at(v.length(), mc.linear_velocity, Cause::MotionVelocity));
            } else if !within(w.length(), mc.angular_velocity) {
                self.fault(at(w.length(), mc.angular_velocity, Cause::MotionVelocity));
            }
            let hold = dr == DVec3::ZERO && angle == 0.0;
            if !hold && n == 1 {
                vel = Some((v, w));
                if let Some((pv, pw)) = prev.vel {
                    let (a, alpha) = ((v - pv).length() / dt, (w - pw).length() / dt);
                    if !within(a, mc.linear_acceleration) {
                        self.fault(at(a, mc.linear_acceleration, Cause::MotionAcceleration));
                    } else if !within(alpha, mc.angular_acceleration) {
                        self.fault(at(
                            alpha,
                            mc.angular_acceleration,
                            Cause::MotionAcceleration,
                        ));
                    }
                }
            }
        }
        self.prev_pose = Some(PrevPose {
            sequence: sp.sequence,
            r,
            rot,
            vel,
        });
    }

    /// The pose may not move faster than the velocity limit in the MONITOR's time either: a
    /// producer running fast (more setpoints than time allows, each step plausible) is caught
    /// here. Allowance: the monitor's elapsed time plus two stream periods (the boundary
    /// setpoints of the two cycles are not sampled at the cycle ends).
    fn check_motion_own_clock(&mut self, now_ns: u64) {
        let mc = self.lim.motion;
        if !mc.check || self.new_setpoints == 0 {
            return;
        }
        let Some(last) = self.prev_pose else { return };
        if let Some((t0, r0, rot0)) = self.cycle_ref {
            let elapsed = now_ns.saturating_sub(t0) as f64 * 1e-9 + 2.0 * mc.period_s;
            let d = (last.r - r0).length();
            let (_, angle) = DQuat::from_mat3(&(last.rot * rot0.transpose())).to_axis_angle();
            let fault = |value: f64, limit: f64| Fault {
                sequence: last.sequence,
                value,
                limit,
                ..Fault::new(Cause::MotionVelocity)
            };
            if !within(d, mc.linear_velocity * elapsed) {
                self.fault(fault(d / elapsed, mc.linear_velocity));
            } else if !within(angle, mc.angular_velocity * elapsed) {
                self.fault(fault(angle / elapsed, mc.angular_velocity));
            }
        }
        self.cycle_ref = Some((now_ns, last.r, last.rot));
    }

    /// History entries, newest first.
    fn recent(&self) -> impl Iterator<Item = &Entry> {
        (1..=self.hist_len).map(move |k| &self.hist[(self.hist_next + HISTORY - k) % HISTORY])
    }

    /// drive-io's feedback (call for every sample received).
    pub fn on_feedback(&mut self, fb: &DriveFeedback) {
        self.feedback_count += 1;
        self.seen_feedback = true;
        self.stats.feedback_checked += 1;
        if self.state.is_tripped() {
            self.reset_evidence_feedback(fb);
        }
        if !self.lim.check_following_error
            || BusState::from_u32(fb.bus_state) != Some(BusState::Running)
        {
            return;
        }
        let m = self.m;
        if fb.cable_count as usize != m {
            self.fault(Fault {
                value: f64::from(fb.cable_count),
                limit: m as f64,
                ..Fault::new(Cause::FollowingError)
            });
            return;
        }
        let applied = fb.applied_setpoint_sequence;
        let lo = applied.saturating_sub(u64::from(self.lim.window_setpoints));
        for i in 0..m {
            let meas = fb.cable_length_m[i];
            let mut best = f64::INFINITY;
            let mut any = false;
            for e in self.recent() {
                if e.sequence > applied {
                    continue;
                }
                if e.sequence <= lo {
                    break;
                }
                any = true;
                let d = (meas - e.q_cmd[i]).abs();
                if d < best {
                    best = d;
                    if within(best, self.lim.following_error_m) {
                        break; // within the bound: no need for the exact minimum
                    }
                }
            }
            // The applied setpoint is not among those seen (the monitor just started, or
            // drive-io applies setpoints the monitor never saw): counted, and N such cycles in
            // a row trip (end_cycle) instead of skipping the check for good.
            if !any {
                self.fb_unchecked += 1;
                return;
            }
            if !within(best, self.lim.following_error_m) {
                self.fault(Fault {
                    cable: Some(i as u8),
                    value: if meas.is_finite() { best } else { f64::NAN },
                    limit: self.lim.following_error_m,
                    sequence: applied,
                    ..Fault::new(Cause::FollowingError)
                });
                return;
            }
        }
        self.fb_checked += 1;
    }

    /// Reset evidence: drive-io's measured lengths follow the newest (held) setpoint.
    fn reset_evidence_feedback(&mut self, fb: &DriveFeedback) {
        let m = self.m;
        let newest = self.recent().next().map(|e| e.q_cmd);
        let ok = fb.cable_count as usize == m
            && fb.cable_length_m[..m].iter().enumerate().all(|(i, l)| {
                l.is_finite()
                    && newest.is_none_or(|q| within((l - q[i]).abs(), self.lim.following_error_m))
            });
        if ok {
            self.fb_following = true;
        } else {
            self.fb_not_following = true;
        }
    }

    /// The monitor's own bus observation failed (dead or stalled reader thread, receive
    /// errors, dropped observations): the checks that read the bus would run blind.
    pub fn on_bus_observation_failed(&mut self, value: f64) {
        self.fault(Fault {
            value,
            ..Fault::new(Cause::BusObservation)
        });
    }

    /// An error frame of the drive bus's controller (the monitor's own socket subscribes to
    /// them): bus-off and error-passive trip (`can_bus_error`, value = the condition's code);
    /// an RX/TX overflow lost frames, so the bus checks ran blind (`bus_observation`). Other
    /// conditions (warning level, protocol errors, missing ACK, tx timeout) are counted by the
    /// process, not tripped on.
    pub fn on_bus_error(&mut self, condition: can_transport::BusCondition) {
        use can_transport::BusCondition;
        let value = f64::from(condition.code());
        match condition {
            BusCondition::BusOff | BusCondition::ErrorPassive => self.fault(Fault {
                value,
                ..Fault::new(Cause::CanBusError)
            }),
            BusCondition::Overflow => self.fault(Fault {
                value,
                ..Fault::new(Cause::BusObservation)
            }),
            BusCondition::TxTimeout | BusCondition::Other => {}
        }
    }

    /// An RPDO1 target seen on the bus for cable `cable` (converted to metres), received at
    /// `rx_ns`. Compared with φ*(x) of the recent setpoints computed before it (the drive
    /// adapter forwards one of them).
    pub fn on_rpdo(&mut self, cable: usize, length_m: f64, rx_ns: u64) {
        if !self.lim.check_rpdo || cable >= self.m || self.hist_len == 0 {
            return;
        }
        self.stats.rpdo_checked += 1;
        let limit = self.lim.dq_limit_m;
        let mut best = f64::INFINITY;
        let mut any = false;
        for e in self.recent() {
            if e.timestamp_ns > rx_ns {
                continue;
            }
            any = true;
            let d = (length_m - e.q_star[cable]).abs();
            if d < best {
                best = d;
                if best <= limit {
                    return;
                }
            }
        }
        if any {
            self.fault(Fault {
                cable: Some(cable as u8),
                value: if length_m.is_finite() { best } else { f64::NAN },
                limit,
                ..Fault::new(Cause::RpdoMismatch)
            });
        }
    }

    /// NMT state of the drive of `cable` (from its heartbeat): only operational drives send
    /// PDOs, so only their forces are supervised and their silence counted.
    pub fn on_drive_state(&mut self, cable: usize, operational: bool) {
        self.on_drive_report(cable, operational, 0);
    }

    /// As [`Monitor::on_drive_state`], with the receive time of the heartbeat (reset evidence:
    /// the drive is reporting).
    pub fn on_drive_report(&mut self, cable: usize, operational: bool, rx_ns: u64) {
        if let Some(t) = self.drive_report_ns.get_mut(cable) {
            *t = rx_ns;
        }
        if let Some(w) = self.force.get_mut(cable) {
            if !operational {
                *w = ForceWatch::default();
            }
            w.operational = operational;
        }
    }

    /// A measured cable force (the drive's TPDO2 pulley force, N) received at `rx_ns`. Slack
    /// and overload are timed by the monitor's receive clock, not by the sender.
    pub fn on_force(&mut self, cable: usize, force_n: f64, rx_ns: u64) {
        let fl = self.lim.forces;
        if cable >= self.m {
            return;
        }
        let w = &mut self.force[cable];
        // Counted also with the check off: a live reading is a start-up condition.
        w.readings += 1;
        if !fl.check || !w.operational {
            return;
        }
        self.stats.forces_checked += 1;
        let at = |cause: Cause, limit: f64| Fault {
            cable: Some(cable as u8),
            value: force_n,
            limit,
            ..Fault::new(cause)
        };
        if !force_n.is_finite() {
            self.force_out_of_range = true;
            self.fault(at(Cause::ForceSilence, f64::NAN));
            return;
        }
        if force_n < fl.slack_below_n || force_n > fl.overload_above_n {
            self.force_out_of_range = true;
        }
        let mut fault = None;
        if force_n < fl.slack_below_n {
            let since = *w.slack_since_ns.get_or_insert(rx_ns);
            if rx_ns.saturating_sub(since) >= fl.filter_ns {
                fault = Some(at(Cause::ForceSlack, fl.slack_below_n));
            }
        } else {
            w.slack_since_ns = None;
        }
        if force_n > fl.overload_above_n {
            let since = *w.over_since_ns.get_or_insert(rx_ns);
            if rx_ns.saturating_sub(since) >= fl.filter_ns {
                fault = Some(at(Cause::ForceOverload, fl.overload_above_n));
            }
        } else {
            w.over_since_ns = None;
        }
        // The hard limit needs no filter: one reading above the winches' rating trips.
        if !within(force_n, fl.hard_limit_n) {
            fault = Some(at(Cause::ForceOverload, fl.hard_limit_n));
        }
        if let Some(f) = fault {
            self.fault(f);
        }
    }

    /// Closes the cycle at `now_ns`: the per-cycle checks, then the latch.
    pub fn end_cycle(&mut self, now_ns: u64) -> CycleReport {
        self.stats.cycles += 1;
        let ending = self.take_stream_end();
        // Frozen / dead motion loop.
        if self.seen_setpoint && !ending {
            if self.new_setpoints == 0 {
                self.silent_cycles = self.silent_cycles.saturating_add(1);
            } else {
                self.silent_cycles = 0;
            }
            if self.silent_cycles >= self.lim.silence_cycles {
                self.fault(Fault {
                    value: f64::from(self.silent_cycles),
                    limit: f64::from(self.lim.silence_cycles),
                    ..Fault::new(Cause::SetpointSilence)
                });
            }
        }
        // Lost setpoints over the sliding window.
        self.stats.setpoints_missing += u64::from(self.missing);
        let old = std::mem::replace(&mut self.gap_ring[self.gap_pos], self.missing);
        self.gap_pos = (self.gap_pos + 1) % self.gap_ring.len();
        self.gap_sum = self.gap_sum + u64::from(self.missing) - u64::from(old);
        if self.gap_sum > u64::from(self.lim.max_missing_setpoints) {
            self.fault(Fault {
                value: self.gap_sum as f64,
                limit: f64::from(self.lim.max_missing_setpoints),
                ..Fault::new(Cause::SequenceGaps)
            });
        }
        // Platform identity.
        match self.identity_state {
            IdentityState::Mismatch => self.fault(Fault::new(Cause::IdentityMismatch)),
            IdentityState::Verified => self.unverified_cycles = 0,
            IdentityState::Unknown => {
                if self.new_setpoints > 0 || self.unverified_cycles > 0 {
                    self.unverified_cycles = self.unverified_cycles.saturating_add(1);
                }
                if self.unverified_cycles > self.lim.identity_grace_cycles {
                    self.fault(Fault {
                        value: f64::from(self.unverified_cycles),
                        limit: f64::from(self.lim.identity_grace_cycles),
                        ..Fault::new(Cause::IdentityMissing)
                    });
                }
            }
        }
        // Dead drive adapter.
        if self.seen_feedback && self.lim.feedback_silence_cycles > 0 {
            if self.feedback_count == 0 {
                self.feedback_silent = self.feedback_silent.saturating_add(1);
            } else {
                self.feedback_silent = 0;
            }
            if self.feedback_silent >= self.lim.feedback_silence_cycles {
                self.fault(Fault {
                    value: f64::from(self.feedback_silent),
                    limit: f64::from(self.lim.feedback_silence_cycles),
                    ..Fault::new(Cause::FeedbackSilence)
                });
            }
        }
        self.check_motion_own_clock(now_ns);
        // Feedback that arrives but cannot be checked, cycle after cycle, fails closed.
        if self.fb_unchecked > 0 && self.fb_checked == 0 {
            self.unchecked_streak = self.unchecked_streak.saturating_add(1);
        } else if self.fb_checked > 0 {
            self.unchecked_streak = 0;
        }
        if self.lim.unchecked_cycles > 0 && self.unchecked_streak >= self.lim.unchecked_cycles {
            self.fault(Fault {
                value: f64::from(self.unchecked_streak),
                limit: f64::from(self.lim.unchecked_cycles),
                ..Fault::new(Cause::FollowingUnchecked)
            });
        }
        self.fb_checked = 0;
        self.fb_unchecked = 0;
        // Start-up conditions, from this cycle's drive states and readings.
        let readiness = self.readiness();
        // Operational drives without force readings: the force check cannot be evaluated.
        if self.lim.forces.check {
            for i in 0..self.m {
                let w = &mut self.force[i];
                if !w.operational || w.readings > 0 {
                    w.silent = 0;
                } else {
                    w.silent = w.silent.saturating_add(1);
                }
                if w.silent >= self.lim.forces.silence_cycles {
                    let silent = w.silent;
                    self.fault(Fault {
                        cable: Some(i as u8),
                        value: f64::from(silent),
                        limit: f64::from(self.lim.forces.silence_cycles),
                        ..Fault::new(Cause::ForceSilence)
                    });
                }
            }
        }
        for w in &mut self.force[..self.m] {
            w.readings = 0;
        }
        let mut new_trip = None;
        let mut became_ready = false;
        if self.state.is_tripped() {
            self.update_evidence(now_ns, &readiness);
        }
        if let Some(first) = self.first {
            self.clear_streak = 0;
            if !self.state.is_tripped() {
                let rec = TripRecord {
                    fault: first,
                    detected_ns: now_ns,
                    cycle: self.stats.cycles,
                };
                self.state = MonitorState::Tripped(rec);
                self.log.push(rec);
                new_trip = Some(rec);
                self.latched = self.faults;
                self.evidence = [0; 32];
            }
        } else {
            self.clear_streak = self.clear_streak.saturating_add(1);
            if self.state == MonitorState::NotReady && readiness.ready() {
                self.state = MonitorState::Armed;
                became_ready = true;
            }
        }
        if ending {
            // Clean end of the stream: disarm until the next setpoint.
            self.seen_setpoint = false;
            self.silent_cycles = 0;
            self.last_sequence = None;
            self.identity_state = IdentityState::Unknown;
            self.unverified_cycles = 0;
            self.prev_pose = None;
            self.last_pose = None;
            self.cycle_ref = None;
            self.plan = PlanWatch::default();
        }
        let report = CycleReport {
            state: self.state.state_code(),
            new_trip,
            faults: self.faults,
            setpoints: self.new_setpoints,
            missing: self.missing,
            became_ready,
            readiness,
        };
        self.last_faults = self.faults;
        self.faults.clear();
        self.first = None;
        self.new_setpoints = 0;
        self.missing = 0;
        self.feedback_count = 0;
        self.fb_following = false;
        self.fb_not_following = false;
        self.force_out_of_range = false;
        report
    }

    /// While tripped: latch this cycle's causes and advance / reset each latched cause's
    /// evidence streak (see [`evidence`]).
    fn update_evidence(&mut self, now_ns: u64, readiness: &Readiness) {
        use evidence::Class;
        for c in self.faults.iter() {
            self.latched.insert(c);
        }
        let stream_ended = !self.seen_setpoint;
        let stream_clean = self.new_setpoints > 0;
        let identity_ok = self.identity_state == IdentityState::Verified
            || (stream_ended && self.identity_state != IdentityState::Mismatch);
        let feedback_ok = self.fb_following && !self.fb_not_following;
        let reporting = self.drive_report_ns[..self.m]
            .iter()
            .all(|&t| t > 0 && now_ns.saturating_sub(t) <= DRIVE_REPORT_MAX_AGE_NS);
        let operational = !0u32 >> (32 - self.m.max(1) as u32) & !readiness.not_operational;
        let forces_ok =
            reporting && !self.force_out_of_range && (operational & readiness.no_feedback) == 0;
        for c in self.latched.iter() {
            let shown = !self.faults.contains(c)
                && match evidence::class(c) {
                    Class::Stream => stream_ended || stream_clean,
                    Class::Identity => identity_ok,
                    Class::Feedback => feedback_ok,
                    Class::Forces => forces_ok,
                    Class::Receive => true,
                };
            let s = &mut self.evidence[usize::from(c.code())];
            *s = if shown { s.saturating_add(1) } else { 0 };
        }
    }

    /// The start-up conditions as of the readings of the current cycle (call before
    /// [`Monitor::end_cycle`]): every drive operational and sending forces (and, for the log,
    /// whether the identity is verified yet).
    pub fn readiness(&self) -> Readiness {
        let (mut not_operational, mut no_feedback) = (0u32, 0u32);
        for (i, w) in self.force[..self.m].iter().enumerate() {
            if !w.operational {
                not_operational |= 1 << i;
            }
            if w.readings == 0 {
                no_feedback |= 1 << i;
            }
        }
        Readiness {
            identity_verified: self.identity_state == IdentityState::Verified,
            not_operational,
            no_feedback,
        }
    }

    /// Operator reset (ISO 13849-1 §5.2.2 manual reset): accepted only if no fault was seen for
    /// `reset_clear_cycles` cycles and every latched cause was positively shown cleared for as
    /// many cycles ([`authority::verify`]). Accepting advances the reset epoch. While armed or
    /// not ready nothing changes.
    pub fn request_reset(&mut self) -> ResetDecision {
        match self.state {
            MonitorState::NotReady => ResetDecision::NotReady,
            MonitorState::Armed => ResetDecision::NotTripped,
            MonitorState::Tripped(_) => {
                let need = self.lim.reset_clear_cycles;
                match authority::verify(
                    self.latched,
                    &self.evidence,
                    self.clear_streak,
                    need,
                    &mut self.epoch,
                ) {
                    Ok(token) => {
                        let epoch = token.epoch();
                        self.release(token);
                        ResetDecision::Accepted { epoch }
                    }
                    Err(c) => ResetDecision::Refused(self.last_faults.first().unwrap_or(c)),
                }
            }
        }
    }

    /// Leaves the latch: the only transition out of [`MonitorState::Tripped`] (which drops the trip
    /// record with it), and it needs the token only [`authority::verify`] mints.
    fn release(&mut self, _token: authority::ResetToken) {
        self.state = MonitorState::Armed;
        self.latched.clear();
        self.evidence = [0; 32];
    }
}
