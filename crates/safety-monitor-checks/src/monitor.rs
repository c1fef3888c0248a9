//! The monitor's core: every check of one 15 ms cycle and the latched state machine. Pure logic
//! (inputs in, decisions out), no I/O, no allocation after construction, never panics on any
//! payload: the process (the `safety-monitor` crate's daemon) feeds it from iceoryx2 and CAN.
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

pub use crate::capacity::{HISTORY, MAX_FORCE_WINDOW, MAX_GAP_WINDOW};

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
    /// The safety I/O node is configured (drives file `[safety_io]`): its TPDO1 (e-stop circuit,
    /// reset key, STO output) is supervised and part of the start-up conditions.
    pub safety_io: bool,
    /// Cycles the safety I/O node may go without a TPDO1 once it reported (it sends one at
    /// least every `inputs_period_ms`).
    pub safety_io_silence_cycles: u32,
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
    /// Linear and angular velocity of the step that led here: zero for a hold and for the first
    /// setpoint of a stream (the platform starts at rest), the mean velocity over a gap.
    vel: (DVec3, DVec3),
}

/// Thresholds of the measured-force supervision (seed §5.1, table 5.1), N.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceLimits {
    pub check: bool,
    /// Slack below this (f_min − margin) ...
    pub slack_below_n: f64,
    /// ... overload above this (f_max + margin) ...
    pub overload_above_n: f64,
    /// ... in at least `window_violations` of a cable's last `window_readings` readings (a
    /// fluttering force trips as well as a steady one; one in-range reading does not restart
    /// anything).
    pub window_readings: u32,
    pub window_violations: u32,
    /// A single reading beyond ± this trips at once (the winches' rating; a reading below
    /// −limit is a broken sensor or a cable pushed, and trips as well).
    pub hard_limit_n: f64,
    /// Cycles an operational drive may go without a force reading.
    pub silence_cycles: u32,
}

/// Per-cable state of the force supervision.
#[derive(Debug, Clone, Copy, Default)]
struct ForceWatch {
    /// The drive reports NMT operational (it runs and sends PDOs).
    operational: bool,
    /// Supervised whatever its NMT state from now on: the drive was operational while (or when)
    /// the monitor left its start-up state.
    supervised: bool,
    /// Readings this cycle.
    readings: u32,
    /// Cycles in a row without a reading while supervised.
    silent: u32,
    /// The verdicts of the last `window_readings` readings, newest in bit 0: below the slack
    /// limit, above the overload limit.
    slack_bits: u64,
    over_bits: u64,
}

/// The monitor's state, with the data each state has: a trip cannot exist without its
/// record, and the record cannot be read while the monitor is not tripped. Private
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
/// code on the process bus (`Heartbeat::state` / `StateEvent::state`): the contract's
/// [`crs_ipc::MonitorState`], which crs-console decodes.
pub use crs_ipc::MonitorState as StateCode;

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
    /// The safety I/O node (if configured) reported its inputs recently with the e-stop
    /// circuit closed (its reset key and e-stop can be read).
    pub safety_io_ok: bool,
}

impl Readiness {
    /// Every drive operational with live feedback, the safety I/O node (if any) reporting with
    /// its e-stop circuit closed (the identity is reported, not required: see
    /// [`MonitorState::NotReady`]).
    pub fn ready(&self) -> bool {
        self.not_operational == 0 && self.no_feedback == 0 && self.safety_io_ok
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
    /// This monitor instance has accepted 65 535 resets: its epoch cannot advance without
    /// wrapping (which would make an old reset look new). Restart the monitor (a new instance,
    /// which then needs an operator reset of its own).
    InstanceExhausted,
}

/// The reset authority (type-state): the latch of [`Monitor`] is left only with a
/// [`authority::ResetToken`], and the only code that can make one is [`authority::verify`],
/// the monitor's check of the per-cause evidence. Minting a token advances the reset epoch.
pub mod authority {
    use super::{Cause, CauseSet};
    use can_transport::safety_frame::epoch_newer;

    /// Proof that the monitor's verification accepted an operator reset; carries the new
    /// epoch. No public constructor (private field), not `Clone`: used once.
    ///
    /// ```compile_fail,E0451
    /// let forged = safety_monitor_checks::monitor::authority::ResetToken { epoch: 1 };
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

    /// Why [`verify`] did not mint a token.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Blocked {
        /// This cause was seen, or not shown cleared, within the last `need` cycles.
        Cause(Cause),
        /// The instance's reset count is at its maximum (see
        /// [`super::ResetDecision::InstanceExhausted`]).
        Exhausted,
    }

    /// Accepts the reset if no fault was seen for `need` cycles (`clean`) and every latched
    /// cause was shown cleared for `need` cycles; then advances `epoch` (the reset count of
    /// this instance, [`crs_limits::reset_epoch`]) and mints the token. Otherwise what blocks
    /// it. The operator's request itself ([`crate::operator::OperatorReset`]) is checked by the
    /// caller.
    pub(super) fn verify(
        latched: CauseSet,
        streaks: &Streaks,
        clean: u32,
        need: u32,
        epoch: &mut u32,
    ) -> Result<ResetToken, Blocked> {
        if let Some(c) = latched
            .iter()
            .find(|c| u32::from(streaks[usize::from(c.code())]) < need)
        {
            return Err(Blocked::Cause(c));
        }
        if clean < need {
            return Err(Blocked::Cause(latched.first().unwrap_or(Cause::IpcError)));
        }
        let count = crs_limits::reset_epoch::count(*epoch);
        if count == u16::MAX {
            return Err(Blocked::Exhausted);
        }
        let next =
            crs_limits::reset_epoch::new(crs_limits::reset_epoch::instance(*epoch), count + 1);
        debug_assert!(epoch_newer(next, *epoch) && crs_limits::reset_epoch::releases(next, *epoch));
        *epoch = next;
        Ok(ResetToken { epoch: next })
    }
}

/// Which causes this cycle's inputs POSITIVELY show cleared (not merely absent), for the
/// per-cause reset evidence. Evaluated while tripped (drives NMT-stopped and
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
/// * the safety I/O node's causes (e-stop circuit, silence): the node reported this cycle with
///   its e-stop circuit closed;
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
            FollowingError | FeedbackSilence | FeedbackStale | RpdoMismatch
            | FollowingUnchecked | RpdoUnchecked => Class::Feedback,
            ForceSlack | ForceOverload | ForceSilence => Class::Forces,
            EStopCircuit | SafetyIoSilence => Class::SafetyIo,
            IpcError | BusObservation | EStopEvent | ForgedEvent | CanBusError
            | ForeignPublisher | Impersonation => Class::Receive,
        }
    }

    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Class {
        Stream,
        Identity,
        Feedback,
        Forces,
        /// The safety I/O node reported this cycle, with its e-stop circuit closed.
        SafetyIo,
        Receive,
    }
}

/// Armed cycles in a row a consumer must be seen waiting (see [`Monitor::request_reset`])
/// before an operator reset while armed is taken as the reset of this instance: more than a
/// validation time (50 ms) plus the release pairs (3 cycles), so a consumer that is merely
/// releasing on the current epoch is not mistaken for one that waits.
pub const CONSUMER_WAIT_CYCLES: u32 = 10;

/// How far in the monitor's future a drive-io feedback timestamp may lie (same CLOCK_MONOTONIC
/// host; drive-io may stamp a sample just after the monitor's cycle began).
pub const FEEDBACK_FUTURE_TOLERANCE_NS: u64 = 50_000_000;

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
    /// drive-io feedback samples that did not advance (republished) or lay in the future.
    pub feedback_stale: u64,
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
    /// The first setpoint (its sequence) of this cycle that moved the pose while the identity was not verified. Judged at
    /// the end of the cycle, after every identity announced by then was read: the identity
    /// and the setpoints are two topics, so an identity published before the first moving
    /// setpoint can be read after it within one cycle.
    moved_unverified: Option<u64>,
    seen_feedback: bool,
    feedback_silent: u32,
    /// Stale samples (not advancing, or stamped in the future) arrived since the last fresh
    /// one: a feedback silence during which drive-io's topic still carried samples is
    /// `feedback_stale`, not `feedback_silence`.
    stale_since_fresh: bool,
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
    /// The monitor's clock at the start of this cycle and of the previous one
    /// ([`Monitor::begin_cycle`]; 0 = not given): a setpoint drained in this cycle was
    /// published between the two, whatever its own timestamp claims.
    clock_ns: u64,
    prev_clock_ns: u64,
    /// The monitor has left its start-up state: a drive operational from now on (every drive,
    /// at the transition) is force-supervised whatever its NMT state later says.
    supervising: bool,
    /// drive-io's last feedback sample (timestamp, cycle): a sample that does not advance both
    /// is stale (republished), not evidence of a live adapter.
    last_feedback: Option<(u64, u64)>,
    /// The setpoint drive-io reported as applied in its last fresh sample.
    last_applied: u64,
    /// drive-io's feedback this cycle reported a latched stop (e-stop, stale stop, fault).
    fb_latched: bool,
    /// RPDOs that enable operation, checked / not checkable this cycle, and the streak of
    /// cycles with only uncheckable ones.
    rpdo_checked: u32,
    rpdo_unchecked: u32,
    rpdo_unchecked_streak: u32,
    /// Per cable, the first enabling RPDO target before any setpoint (NaN: none yet): drive-io
    /// enables the drives holding where they stand before motion-core streams, and a target
    /// that stays there is checked (no motion); one that moves is not checkable.
    rpdo_hold_m: [f64; MAX_CABLES],
    /// The safety I/O node: TPDO1s this cycle, cycles without one after the first, whether it
    /// ever reported, its e-stop circuit and STO output as last reported.
    io_reports: u32,
    io_silent: u32,
    io_seen: bool,
    io_estop_closed: bool,
    io_sto_released: bool,
    /// Armed cycles in a row in which a consumer waits for this instance's reset: the safety
    /// I/O node keeps the STO on although the monitor says RUN (its watch stopped under another
    /// monitor instance or epoch), or drive-io reports a latched stop.
    waiting_streak: u32,
    /// The last setpoint's pose of this stream (start-up: motion needs a verified identity).
    last_pose: Option<[f64; 6]>,
    /// The monitor's clock at the end of the last cycle that brought setpoints, and the last
    /// pose of that cycle (the own-clock velocity check).
    cycle_ref: Option<(u64, DVec3, DMat3)>,
    /// The plan the producer announced (sequence of its last setpoint) and whether the stream
    /// holds (STOPPING only at the end of an announced plan).
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
            moved_unverified: None,
            seen_feedback: false,
            feedback_silent: 0,
            stale_since_fresh: false,
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
            clock_ns: 0,
            prev_clock_ns: 0,
            // A monitor that starts armed (require_ready off, bench) has been ready from the
            // start.
            supervising: !lim.require_ready,
            last_feedback: None,
            last_applied: 0,
            fb_latched: false,
            rpdo_checked: 0,
            rpdo_unchecked: 0,
            rpdo_unchecked_streak: 0,
            rpdo_hold_m: [f64::NAN; MAX_CABLES],
            io_reports: 0,
            io_silent: 0,
            io_seen: false,
            io_estop_closed: false,
            io_sto_released: false,
            waiting_streak: 0,
            last_pose: None,
            cycle_ref: None,
            plan: PlanWatch::default(),
        }
    }

    /// Opens a cycle at the monitor's clock `now_ns` (call before this cycle's inputs): the
    /// setpoints drained now were published after the previous cycle began and before now, so
    /// their history entries are stamped within that interval whatever their own timestamps
    /// claim (a producer's clock that jumps forward or back cannot blind the RPDO check).
    pub fn begin_cycle(&mut self, now_ns: u64) {
        self.prev_clock_ns = if self.clock_ns == 0 {
            now_ns
        } else {
            self.clock_ns
        };
        self.clock_ns = now_ns;
    }

    /// The safety I/O node's TPDO1 (inputs: bit 0 e-stop circuit closed, bit 1 reset key;
    /// outputs: bit 0 STO released), received at `rx_ns`. An open e-stop circuit trips
    /// (`estop_circuit`); the reset key is read by the process ([`crate::operator::KeyWatch`]).
    pub fn on_safety_io(&mut self, inputs: u8, outputs: u8, _rx_ns: u64) {
        self.io_reports += 1;
        self.io_seen = true;
        self.io_estop_closed = inputs & crate::operator::INPUT_ESTOP_CLOSED != 0;
        self.io_sto_released = outputs & crate::operator::OUTPUT_STO_RELEASED != 0;
        if !self.io_estop_closed {
            self.fault(Fault {
                value: f64::from(inputs),
                ..Fault::new(Cause::EStopCircuit)
            });
        }
    }

    /// A frame on the monitor's own identifiers (`cob_id` = its COB-ID) that it did not send.
    pub fn on_impersonation(&mut self, cob_id: u16) {
        self.fault(Fault {
            value: f64::from(cob_id),
            ..Fault::new(Cause::Impersonation)
        });
    }

    /// Sets the monitor instance (construction only): the reset epoch becomes the instance's
    /// start epoch (count 0, [`crs_limits::reset_epoch`]). The daemon draws the instance at
    /// random when it starts, so a restarted monitor is another instance whose start epoch
    /// releases none of the consumers that stopped under the previous one.
    pub fn with_instance(mut self, instance: u16) -> Self {
        self.epoch = crs_limits::reset_epoch::new(instance, 0);
        self
    }

    /// The producer announced its plan: `end` is the sequence number of its last planned
    /// setpoint (`crs_ipc::MotionState::Plan`; [`crs_ipc::PLAN_OPEN_END`] for a
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
            (Some(end), Some(_)) if end == crs_ipc::PLAN_OPEN_END => {
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
    /// announced plan; otherwise `unplanned_stream_end` and the checks stay armed.
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
        // Motion is permitted only with a verified platform identity (start-up):
        // the RUN heartbeat lets the drives enable and HOLD; a setpoint that moves the pose
        // while the identity is not verified trips at once. Holding setpoints are tolerated
        // for `identity_grace_cycles` (the identity of a producer the monitor subscribed to
        // late arrives with its next announcement).
        if self.identity_state != IdentityState::Verified
            && self.last_pose.is_some_and(|p| p != sp.pose)
        {
            // Judged in `check_identity` at the end of this cycle (same cycle, so no later).
            self.moved_unverified.get_or_insert(sp.sequence);
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
        // When the setpoint existed, for the RPDO check ("computed before the RPDO"): its own
        // timestamp, but never outside the interval in which it was published as the
        // monitor's clock knows it (begin_cycle), so a producer clock that jumps cannot put
        // every setpoint in the future (RPDO check blind) or far in the past.
        let stamped = if self.clock_ns == 0 {
            sp.timestamp_ns
        } else {
            sp.timestamp_ns.clamp(self.prev_clock_ns, self.clock_ns)
        };
        let e = &mut self.hist[self.hist_next];
        e.sequence = sp.sequence;
        e.timestamp_ns = stamped;
        e.q_cmd[..m].copy_from_slice(&sp.cable_length_m[..m]);
        e.q_star[..m].copy_from_slice(&self.q[..m]);
        self.hist_next = (self.hist_next + 1) % HISTORY;
        self.hist_len = (self.hist_len + 1).min(HISTORY);
    }

    /// Velocity and acceleration implied by consecutive setpoints: one sequence number is one
    /// stream period (the sender's timestamps are not used). A hold is zero velocity: the
    /// first setpoint of a stream (the platform starts at rest) and a step to exactly the same
    /// pose (motion-core holding after an e-stop or refusal) leave a velocity of zero, so the
    /// step OUT of a hold is acceleration-checked like any other — a stream that jumps from
    /// rest to a plausible speed trips here. The step INTO a hold is not checked (stopping the
    /// setpoints is the safe direction; the drives decelerate on their own). Over a sequence gap
    /// of n periods the mean velocity is compared with the previous step's over the time
    /// between their midpoints, (n + 1)/2 periods.
    fn check_motion(&mut self, sp: &JointSetpoint) {
        let mc = self.lim.motion;
        let p = &sp.pose;
        let r = DVec3::new(p[0], p[1], p[2]);
        let rot = StandardKinematics::rotation(p[3], p[4], p[5]);
        let mut vel = (DVec3::ZERO, DVec3::ZERO);
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
            if !hold {
                vel = (v, w);
                let (pv, pw) = prev.vel;
                let dt_mid = (n as f64 + 1.0) * 0.5 * mc.period_s;
                let (a, alpha) = ((v - pv).length() / dt_mid, (w - pw).length() / dt_mid);
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
    ///
    /// Only a FRESH sample counts as a live drive adapter (`feedback_silence`): its timestamp
    /// and SYNC cycle must both advance past the previous sample's, and the timestamp may not
    /// lie in the monitor's future ([`Monitor::begin_cycle`]) — a hung adapter whose publisher
    /// keeps republishing its last sample is as dead as a silent one. The following error is
    /// checked while drive-io reports Running, and also whenever the applied setpoint advanced
    /// (drive-io applies setpoints whatever state it claims).
    pub fn on_feedback(&mut self, fb: &DriveFeedback) {
        let fresh = self
            .last_feedback
            .is_none_or(|(ts, cycle)| fb.timestamp_ns > ts && fb.cycle > cycle)
            && (self.clock_ns == 0
                || fb.timestamp_ns <= self.clock_ns.saturating_add(FEEDBACK_FUTURE_TOLERANCE_NS));
        let previous_applied = self.last_applied;
        // Any sample arms the silence check (drive-io exists); only a fresh one feeds it.
        self.seen_feedback = true;
        if fresh {
            self.last_feedback = Some((fb.timestamp_ns, fb.cycle));
            self.feedback_count += 1;
            self.stale_since_fresh = false;
        } else {
            self.stats.feedback_stale += 1;
            self.stale_since_fresh = true;
            return;
        }
        self.last_applied = fb.applied_setpoint_sequence;
        self.stats.feedback_checked += 1;
        let state = fb.bus().ok();
        if matches!(
            state,
            Some(BusState::EStop | BusState::Fault | BusState::StaleStop)
        ) {
            self.fb_latched = true;
        }
        if self.state.is_tripped() {
            self.reset_evidence_feedback(fb);
        }
        let applying =
            state == Some(BusState::Running) || fb.applied_setpoint_sequence > previous_applied;
        if !self.lim.check_following_error || !applying {
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
    ///
    /// Before any setpoint, an RPDO that holds the cable's first enabling target is checked
    /// (the drive holds where it was enabled: no motion). An RPDO that no recent setpoint can
    /// have preceded (a moving target before any setpoint, or every setpoint stamped after
    /// it) cannot be checked: it is counted, and cycles with such RPDOs only trip
    /// `rpdo_unchecked` after `unchecked_cycles` in a row (fail closed, not skipped).
    pub fn on_rpdo(&mut self, cable: usize, length_m: f64, rx_ns: u64) {
        if !self.lim.check_rpdo || cable >= self.m {
            return;
        }
        if self.hist_len == 0 {
            let hold = &mut self.rpdo_hold_m[cable];
            if hold.is_nan() && length_m.is_finite() {
                *hold = length_m;
            }
            // The same encoder counts give the same metres: a hold compares exactly.
            if *hold == length_m {
                self.rpdo_checked += 1;
            } else {
                self.rpdo_unchecked += 1;
            }
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
                    break;
                }
            }
        }
        if any && best <= limit {
            self.rpdo_checked += 1;
        } else if !any {
            self.rpdo_unchecked += 1;
        } else {
            self.rpdo_checked += 1;
            self.fault(Fault {
                cable: Some(cable as u8),
                value: if length_m.is_finite() { best } else { f64::NAN },
                limit,
                ..Fault::new(Cause::RpdoMismatch)
            });
        }
    }

    /// NMT state of the drive of `cable` (from its heartbeat): a start-up condition (every
    /// drive operational); the forces are supervised whatever it says once the monitor has been
    /// ready.
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
            // The force window is NOT restarted when a drive leaves operational: a drive that
            // is stopped and started again (by anyone) keeps its history.
            w.operational = operational;
            w.supervised |= operational && self.supervising;
        }
    }

    /// A measured cable force (the drive's TPDO2 pulley force or its load cell's, N). Once the
    /// monitor has been ready, every reading is checked whatever the drive's NMT state: slack below f_min − margin or
    /// overload above f_max + margin in `window_violations` of the cable's last
    /// `window_readings` readings trips (a fluttering force as well as a steady one), one
    /// reading beyond ± the hard limit trips at once, a reading that is not a number trips
    /// `force_silence` (the check cannot be evaluated).
    pub fn on_force(&mut self, cable: usize, force_n: f64, _rx_ns: u64) {
        let fl = self.lim.forces;
        if cable >= self.m {
            return;
        }
        let w = &mut self.force[cable];
        // Counted also with the check off: a live reading is a start-up condition.
        w.readings += 1;
        // Before its drive was operational with the monitor ready, only an operational
        // drive's readings count (the cables may not be tensioned before the NMT start); after
        // that, every reading, whatever the drive's NMT state.
        if !fl.check || !(w.supervised || w.operational) {
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
        let slack = force_n < fl.slack_below_n;
        let over = force_n > fl.overload_above_n;
        if slack || over {
            self.force_out_of_range = true;
        }
        let mask = if fl.window_readings >= 64 {
            u64::MAX
        } else {
            (1u64 << fl.window_readings) - 1
        };
        w.slack_bits = ((w.slack_bits << 1) | u64::from(slack)) & mask;
        w.over_bits = ((w.over_bits << 1) | u64::from(over)) & mask;
        let (n_slack, n_over) = (w.slack_bits.count_ones(), w.over_bits.count_ones());
        let mut fault = None;
        // k of n: a cable alternating between slack and overload counts both.
        if n_slack + n_over >= fl.window_violations {
            fault = Some(if n_over > n_slack || (n_over == n_slack && over) {
                at(Cause::ForceOverload, fl.overload_above_n)
            } else {
                at(Cause::ForceSlack, fl.slack_below_n)
            });
        }
        // The hard limit needs no window: one reading beyond the winches' rating, of either
        // sign, trips.
        if !within(force_n.abs(), fl.hard_limit_n) {
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
        self.check_setpoint_silence(ending);
        self.check_sequence_gaps();
        self.check_identity();
        self.check_feedback_silence();
        self.check_motion_own_clock(now_ns);
        self.check_following_unchecked();
        self.check_rpdo_unchecked();
        self.check_safety_io_silence();
        // Start-up conditions, from this cycle's drive states and readings.
        let readiness = self.readiness();
        self.check_force_silence();
        self.count_waiting_consumer();
        let (new_trip, became_ready) = self.latch(now_ns, &readiness);
        if ending {
            self.disarm_at_stream_end();
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
        self.clear_cycle();
        report
    }

    /// Frozen / dead motion loop: no new setpoint for `silence_cycles` (not after the stream's
    /// announced end).
    fn check_setpoint_silence(&mut self, ending: bool) {
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
    }

    /// Lost setpoints over the sliding window.
    fn check_sequence_gaps(&mut self) {
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
    }

    /// The platform identity: a mismatch, or setpoints without an identity beyond the grace.
    fn check_identity(&mut self) {
        if let Some(sequence) = self.moved_unverified
            && self.identity_state != IdentityState::Verified
        {
            self.fault(Fault {
                value: f64::from(self.unverified_cycles),
                limit: 0.0,
                sequence,
                ..Fault::new(Cause::IdentityMissing)
            });
        }
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
    }

    /// Dead drive adapter: no (advancing) feedback for `feedback_silence_cycles`.
    fn check_feedback_silence(&mut self) {
        if self.seen_feedback && self.lim.feedback_silence_cycles > 0 {
            if self.feedback_count == 0 {
                self.feedback_silent = self.feedback_silent.saturating_add(1);
            } else {
                self.feedback_silent = 0;
            }
            if self.feedback_silent >= self.lim.feedback_silence_cycles {
                // Samples that arrived but did not advance: the adapter's publisher lives,
                // its loop does not (the operator must know which one to look at).
                let cause = if self.stale_since_fresh {
                    Cause::FeedbackStale
                } else {
                    Cause::FeedbackSilence
                };
                self.fault(Fault {
                    value: f64::from(self.feedback_silent),
                    limit: f64::from(self.lim.feedback_silence_cycles),
                    ..Fault::new(cause)
                });
            }
        }
    }

    /// Feedback that arrives but cannot be checked, cycle after cycle, fails closed.
    fn check_following_unchecked(&mut self) {
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
    }

    /// RPDOs that enable operation but cannot be checked, cycle after cycle, fail closed.
    fn check_rpdo_unchecked(&mut self) {
        if self.rpdo_unchecked > 0 && self.rpdo_checked == 0 {
            self.rpdo_unchecked_streak = self.rpdo_unchecked_streak.saturating_add(1);
        } else if self.rpdo_checked > 0 {
            self.rpdo_unchecked_streak = 0;
        }
        if self.lim.check_rpdo
            && self.lim.unchecked_cycles > 0
            && self.rpdo_unchecked_streak >= self.lim.unchecked_cycles
        {
            self.fault(Fault {
                value: f64::from(self.rpdo_unchecked_streak),
                limit: f64::from(self.lim.unchecked_cycles),
                ..Fault::new(Cause::RpdoUnchecked)
            });
        }
        self.rpdo_checked = 0;
        self.rpdo_unchecked = 0;
    }

    /// The safety I/O node: once it reported, a silence trips (its e-stop circuit, reset key
    /// and STO output can no longer be read).
    fn check_safety_io_silence(&mut self) {
        if self.lim.safety_io {
            if self.io_reports > 0 {
                self.io_silent = 0;
            } else if self.io_seen {
                self.io_silent = self.io_silent.saturating_add(1);
            }
            if self.io_silent >= self.lim.safety_io_silence_cycles.max(1) {
                self.fault(Fault {
                    value: f64::from(self.io_silent),
                    limit: f64::from(self.lim.safety_io_silence_cycles),
                    ..Fault::new(Cause::SafetyIoSilence)
                });
            }
        }
    }

    /// Cables without force readings: the force check cannot be evaluated. Once the monitor
    /// has been ready every cable is supervised whatever its drive's NMT state (a drive that
    /// someone stopped keeps being supervised: its load cell still reports, or its silence
    /// trips), except while tripped (the monitor itself NMT-stops the drives then).
    fn check_force_silence(&mut self) {
        let tripped = self.state.is_tripped();
        if self.lim.forces.check {
            for i in 0..self.m {
                let w = &mut self.force[i];
                let supervised = w.operational || (w.supervised && !tripped);
                if !supervised || w.readings > 0 {
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
    }

    /// A consumer waits for a reset of this instance: the safety I/O node keeps the torque
    /// off although the monitor says RUN (its watch stopped under another monitor instance
    /// or epoch), or drive-io reports a latched stop.
    fn count_waiting_consumer(&mut self) {
        let sto_off = self.lim.safety_io && self.io_reports > 0 && !self.io_sto_released;
        if self.state == MonitorState::Armed && (sto_off || self.fb_latched) {
            self.waiting_streak = self.waiting_streak.saturating_add(1);
        } else {
            self.waiting_streak = 0;
        }
    }

    /// The latch: the cycle's first fault trips (once), a clean cycle counts towards a reset
    /// and arms a monitor whose start-up conditions hold. Returns (the new trip, became
    /// ready).
    fn latch(&mut self, now_ns: u64, readiness: &Readiness) -> (Option<TripRecord>, bool) {
        let mut new_trip = None;
        let mut became_ready = false;
        if self.state.is_tripped() {
            self.update_evidence(now_ns, readiness);
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
                self.supervising = true;
                // Every drive is operational now (readiness): all are supervised from here on.
                for w in &mut self.force[..self.m] {
                    w.supervised = true;
                }
                became_ready = true;
            }
        }
        (new_trip, became_ready)
    }

    /// Clean end of the stream: disarm the stream's checks until the next setpoint.
    fn disarm_at_stream_end(&mut self) {
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

    /// Forgets this cycle's faults and per-cycle counts (after the report took them).
    fn clear_cycle(&mut self) {
        self.last_faults = self.faults;
        self.faults.clear();
        self.first = None;
        self.new_setpoints = 0;
        self.moved_unverified = None;
        self.missing = 0;
        self.feedback_count = 0;
        self.fb_following = false;
        self.fb_not_following = false;
        self.fb_latched = false;
        self.force_out_of_range = false;
        self.io_reports = 0;
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
                    Class::SafetyIo => self.io_reports > 0 && self.io_estop_closed,
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
            safety_io_ok: !self.lim.safety_io || (self.io_reports > 0 && self.io_estop_closed),
        }
    }

    /// Operator reset (ISO 13849-1 §5.2.2 manual reset), from an authorised channel only (the
    /// reset key, the reset socket: [`crate::operator::OperatorReset`]): accepted only if no
    /// fault was seen for `reset_clear_cycles` cycles and every latched cause was positively
    /// shown cleared for as many cycles ([`authority::verify`]). Accepting advances the reset
    /// epoch (the count of this instance).
    ///
    /// While armed nothing changes — unless a consumer waits for a reset of THIS instance (the
    /// safety I/O node keeps the torque off although the monitor says RUN, or drive-io reports
    /// a latched stop, for [`CONSUMER_WAIT_CYCLES`] cycles): after a monitor restart the
    /// drives, the node and drive-io stay stopped on the new instance's start epoch, and only
    /// this reset (with the same clean-cycle condition) releases them. While not ready nothing
    /// changes.
    pub fn request_reset(&mut self, request: crate::operator::OperatorReset) -> ResetDecision {
        let _consumed = request;
        let need = self.lim.reset_clear_cycles;
        match self.state {
            MonitorState::NotReady => ResetDecision::NotReady,
            MonitorState::Armed if self.waiting_streak < CONSUMER_WAIT_CYCLES => {
                ResetDecision::NotTripped
            }
            MonitorState::Armed => {
                match authority::verify(
                    CauseSet::default(),
                    &self.evidence,
                    self.clear_streak,
                    need,
                    &mut self.epoch,
                ) {
                    Ok(token) => {
                        let epoch = token.epoch();
                        self.waiting_streak = 0;
                        ResetDecision::Accepted { epoch }
                    }
                    Err(authority::Blocked::Exhausted) => ResetDecision::InstanceExhausted,
                    Err(authority::Blocked::Cause(c)) => {
                        ResetDecision::Refused(self.last_faults.first().unwrap_or(c))
                    }
                }
            }
            MonitorState::Tripped(_) => {
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
                    Err(authority::Blocked::Exhausted) => ResetDecision::InstanceExhausted,
                    Err(authority::Blocked::Cause(c)) => {
                        ResetDecision::Refused(self.last_faults.first().unwrap_or(c))
                    }
                }
            }
        }
    }

    /// Leaves the latch: the only transition out of [`MonitorState::Tripped`] (which drops the trip
    /// record with it), and it needs the token only [`authority::verify`] mints. The force
    /// windows start afresh (the operator's reset follows positive evidence of in-range
    /// forces), and the drives, which the monitor NMT-stopped, get their silence allowance
    /// again while the NMT start takes effect.
    fn release(&mut self, _token: authority::ResetToken) {
        self.state = MonitorState::Armed;
        self.latched.clear();
        self.evidence = [0; 32];
        for w in &mut self.force {
            w.slack_bits = 0;
            w.over_bits = 0;
            w.silent = 0;
        }
    }
}
