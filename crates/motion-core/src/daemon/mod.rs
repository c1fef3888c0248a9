//! The 1 ms hard-loop daemon (spec sec. 5.6): standard inverse kinematics plus the precomputed
//! polynomial surrogate offset, q_θ = φ(x) + φ_sg(x) (eq. 5.26), published as joint setpoints.
//!
//! Per cycle: sleep to the absolute deadline, poll e-stop/reset events, take the next reference
//! (ruckig plan sampled off-loop, see [`trajectory`]), check it ([`cycle`]), publish the
//! setpoint, record lateness/compute time in lock-free histograms ([`stats`]). On an e-stop or
//! a rejected reference the loop stops moving, keeps publishing the last safe setpoint and
//! latches until an explicit reset.

pub mod config;
pub mod cueing;
pub mod cycle;
pub mod lifecycle;
pub mod outbox;
pub mod realtime;
pub mod ride;
pub mod ride_socket;
pub mod stats;
pub mod timeline;
pub mod trajectory;

use crs_ipc::JointSetpoint;
use cycle::{Cycle, Reference, Rejection};
use ride::{RidePhase, RideSlot};
use stats::LoopStats;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use trajectory::{PlannerLimits, Sampler};

/// Where the loop sends setpoints (iceoryx2 in the daemon, a buffer in tests).
pub trait SetpointSink {
    fn publish(&mut self, sp: &JointSetpoint) -> bool;
}

/// Operator/safety events the loop polls once per cycle (non-blocking). Not `Clone`: a reset
/// is used once.
#[derive(Debug, PartialEq, Eq)]
pub enum Command {
    EStop,
    /// Leaves a latched state; only a [`ResetAuthority`] value can ask for it.
    Reset(ResetAuthority),
}

/// The right to clear the loop's latch (e-stop or refused reference). It has no public
/// constructor: [`ResetGate::check`] is the single place that decides which events may reset
/// the loop (only the CURRENT safety monitor's fresh reset, of the epoch it announced, that this
/// loop has not acted on). Not `Clone` or `Copy`: consumed by the loop.
///
/// Forging one fails with E0603 (private constructor); `tools/test.sh` checks the code, so a
/// renamed path (another error) fails the test instead of passing it.
///
/// ```compile_fail,E0603
/// let forged = motion_core::daemon::ResetAuthority(());
/// ```
///
/// ```compile_fail,E0382
/// fn twice(a: motion_core::daemon::ResetAuthority) -> (motion_core::daemon::ResetAuthority, motion_core::daemon::ResetAuthority) {
///     (a, a)
/// }
/// ```
#[derive(Debug, PartialEq, Eq)]
pub struct ResetAuthority(());

/// Why a state event did not yield a [`ResetAuthority`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResetIgnored {
    /// Not a well-formed reset event of this contract version.
    NotAReset,
    /// A reset event from another process than the safety monitor (raw source code).
    Source(u32),
    /// The monitor's reset epoch (`detail`) is not a reset this loop has not acted on
    /// ([`crs_limits::reset_epoch::releases`]): a replay, or a copy of an old event.
    NotNewer { epoch: u32, last: u32 },
    /// The epoch is a monitor instance's start epoch (count 0): no operator reset.
    StartEpoch { epoch: u32 },
    /// Stamped outside [now − [`RESET_MAX_AGE_NS`], now + tolerance] of the loop's clock.
    Stale,
    /// Not the epoch the current monitor announced (announcement missing, older than the
    /// event, stale, or of another epoch): never "any epoch first".
    NotAnnounced { epoch: u32, announced: Option<u32> },
}

/// A reset event (and the announcement it needs) older than this is stale (ns).
pub const RESET_MAX_AGE_NS: u64 = 2_000_000_000;
/// An announcement counts this long (the monitor re-announces about once a second).
pub const ANNOUNCEMENT_MAX_AGE_NS: u64 = 3_000_000_000;
/// How far in the loop's future an event's stamp may lie (same CLOCK_MONOTONIC host).
pub const EVENT_FUTURE_TOLERANCE_NS: u64 = 50_000_000;

/// motion-core's reset gate (ISO 13849-1 §5.2.2: only the safety function's manual reset ends
/// a stop). Accepts only `StateEvent { kind: Reset, source: SafetyMonitor, detail: epoch }`
/// that is
/// * fresh: stamped within [`RESET_MAX_AGE_NS`] before the loop's clock, not in its future;
/// * a reset: count >= 1 of its monitor instance ([`crs_limits::reset_epoch`]) — a restarted
///   monitor's start epoch is none;
/// * of the epoch the CURRENT monitor announced (`crs_ipc::MonitorCode::EpochAnnounce`,
///   fresh, stamped no later than the event): never "any epoch first";
/// * one this loop has not acted on ([`crs_limits::reset_epoch::releases`] against the last
///   accepted epoch).
///
/// What this does NOT authenticate: iceoryx2 0.10 does not tell a subscriber which process
/// published a sample, and `source` is self-declared, so a local process that reads the
/// monitor's announcement and forges its source with that epoch passes here (see
/// docs/safety-monitor.md, threat model). The loop's release alone moves nothing: it holds its
/// position, and the drives stay braked until drive-io leaves its latch, which needs the same
/// epoch verified in the monitor's doubled heartbeat on CAN.
#[derive(Clone, Copy, Debug, Default)]
pub struct ResetGate {
    last_epoch: Option<u32>,
    /// The epoch the monitor announced last, and the announcement's stamp.
    announced: Option<(u32, u64)>,
}

impl ResetGate {
    pub fn new() -> Self {
        Self::default()
    }

    /// The last accepted epoch.
    pub fn last_epoch(&self) -> Option<u32> {
        self.last_epoch
    }

    /// The epoch the monitor announced last (None: none yet).
    pub fn announced_epoch(&self) -> Option<u32> {
        self.announced.map(|(e, _)| e)
    }

    /// The reset a state event carries (see the type's docs); the monitor's epoch
    /// announcements are recorded here (and are `NotAReset`). Strict: only a well-formed reset
    /// event of this contract version (an e-stop, by contrast, is honoured on its kind code
    /// alone). `now_ns`: the loop's clock. Allocation-free (called in the 1 ms loop).
    pub fn check(
        &mut self,
        ev: &crs_ipc::StateEvent,
        now_ns: u64,
    ) -> Result<ResetAuthority, ResetIgnored> {
        let fresh = |stamp: u64, age: u64| {
            stamp <= now_ns.saturating_add(EVENT_FUTURE_TOLERANCE_NS)
                && now_ns.saturating_sub(stamp) <= age
        };
        if ev.version == crs_ipc::CONTRACT_VERSION
            && ev.source() == crs_ipc::ProcessId::SafetyMonitor
            && ev.monitor_code() == Some(crs_ipc::MonitorCode::EpochAnnounce)
        {
            if fresh(ev.timestamp_ns, ANNOUNCEMENT_MAX_AGE_NS)
                && self.announced.is_none_or(|(_, t)| ev.timestamp_ns >= t)
            {
                self.announced = Some((ev.detail_node, ev.timestamp_ns));
            }
            return Err(ResetIgnored::NotAReset);
        }
        match ev.decode() {
            Ok(crs_ipc::Event::Reset {
                source: crs_ipc::ProcessId::SafetyMonitor,
            }) => {}
            Ok(crs_ipc::Event::Reset { .. }) => return Err(ResetIgnored::Source(ev.source)),
            _ => return Err(ResetIgnored::NotAReset),
        }
        if !fresh(ev.timestamp_ns, RESET_MAX_AGE_NS) {
            return Err(ResetIgnored::Stale);
        }
        let epoch = ev.detail;
        if crs_limits::reset_epoch::count(epoch) == 0 {
            return Err(ResetIgnored::StartEpoch { epoch });
        }
        match self.announced {
            Some((a, t))
                if a == epoch && t <= ev.timestamp_ns && fresh(t, ANNOUNCEMENT_MAX_AGE_NS) => {}
            other => {
                return Err(ResetIgnored::NotAnnounced {
                    epoch,
                    announced: other.map(|(a, _)| a),
                });
            }
        }
        if let Some(last) = self.last_epoch
            && !crs_limits::reset_epoch::releases(epoch, last)
        {
            return Err(ResetIgnored::NotNewer { epoch, last });
        }
        self.last_epoch = Some(epoch);
        Ok(ResetAuthority(()))
    }
}

pub trait CommandSource {
    fn poll(&mut self) -> Option<Command>;
}

/// Loop state visible to heartbeats and logs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LoopState {
    /// Following the reference.
    Running,
    /// Holding the last safe setpoint after an e-stop (latched).
    EStopped,
    /// Holding after the checks refused a reference (latched).
    Refused(Rejection),
    /// Reset after a latch: holding position, no plan active.
    Holding,
}

impl LoopState {
    /// True in the latched states, which only a [`Command::Reset`] leaves.
    pub fn is_latched(&self) -> bool {
        matches!(self, LoopState::EStopped | LoopState::Refused(_))
    }

    /// The state on the process bus.
    pub fn code(&self) -> crs_ipc::MotionState {
        match self {
            LoopState::Running => crs_ipc::MotionState::Running,
            LoopState::EStopped => crs_ipc::MotionState::EStopped,
            LoopState::Refused(_) => crs_ipc::MotionState::Refused,
            LoopState::Holding => crs_ipc::MotionState::Holding,
        }
    }
}

/// The loop without its timer: one call per period. Separated so tests can drive many
/// cycles under a counting allocator. Built by [`lifecycle::Configured::activate`]; its state
/// changes only inside [`HardLoop::step`], and a latch only on a [`Command::Reset`].
pub struct HardLoop {
    cycle: Cycle,
    sampler: Sampler,
    /// Motion-cueing input; when set it replaces the planned trajectory as the reference.
    cueing: Option<(cueing::CueingFilter, Box<dyn cueing::CueingSource>)>,
    /// Loop time of the last cueing target received (for the end of a finite stream).
    cueing_last_ns: Option<u64>,
    state: LoopState,
    setpoint: JointSetpoint,
    last_safe: Option<JointSetpoint>,
    sequence: u64,
    /// Rides handed in by an operator ([`ride`]); `None`: the plan given at activation only.
    rides: Option<RideRides>,
}

/// The loop's side of rides started on purpose.
struct RideRides {
    slot: Arc<RideSlot>,
    limits: PlannerLimits,
    period_s: f64,
    /// The last reference the checks accepted (where an abort brakes from).
    last_reference: Reference,
    /// Braking an aborted ride: the reference, and whether it has come to rest.
    braking: Option<(Reference, bool)>,
}

impl HardLoop {
    pub fn new(cycle: Cycle, sampler: Sampler) -> Self {
        Self {
            cycle,
            sampler,
            cueing: None,
            cueing_last_ns: None,
            state: LoopState::Running,
            setpoint: JointSetpoint::default(),
            last_safe: None,
            sequence: 0,
            rides: None,
        }
    }

    /// Takes rides from an operator through `slot` ([`ride`]): a new plan only while idle, an
    /// abort brakes at the planner's acceleration `limits`.
    pub fn with_rides(
        mut self,
        slot: Arc<RideSlot>,
        limits: PlannerLimits,
        period_s: f64,
        home: cdpr_model::Pose,
    ) -> Self {
        self.rides = Some(RideRides {
            slot,
            limits,
            period_s,
            last_reference: Reference {
                pose: home,
                ..Reference::default()
            },
            braking: None,
        });
        self
    }

    /// Follow a motion-cueing stream instead of the planned trajectory (see [`cueing`]).
    pub fn with_cueing(
        mut self,
        filter: cueing::CueingFilter,
        source: Box<dyn cueing::CueingSource>,
    ) -> Self {
        self.cueing = Some((filter, source));
        self
    }

    /// The state after the last cycle.
    pub fn state(&self) -> LoopState {
        self.state
    }

    /// True while the loop follows nothing: no plan, ride or cueing stream under way (the
    /// plan delivered, or an aborted ride braked to rest), so it holds where that ended.
    pub fn is_idle(&self) -> bool {
        match self.state {
            LoopState::Holding => true,
            LoopState::Running if self.cueing.is_none() => match self.rides.as_ref() {
                Some(RideRides {
                    braking: Some((_, at_rest)),
                    ..
                }) => *at_rest,
                _ => self.sampler.finished(),
            },
            _ => false,
        }
    }

    /// The state heartbeats and state events carry ([`crs_ipc::MotionState`]): what the
    /// loop does, so an idle loop says HOLDING, never RUNNING. [`Self::state`] stays
    /// `Running` while idle: the loop still computes and checks the held reference each cycle.
    pub fn state_code(&self) -> crs_ipc::MotionState {
        match self.state {
            LoopState::Running if self.is_idle() => crs_ipc::MotionState::Holding,
            s => s.code(),
        }
    }

    /// True once the planner has delivered the whole plan and the loop has read it.
    pub fn plan_finished(&self) -> bool {
        self.sampler.finished()
    }

    /// True once the planner has filled its look-ahead queue or delivered the whole plan
    /// ([`trajectory::Sampler::look_ahead_full`]).
    pub fn plan_look_ahead_full(&self) -> bool {
        self.sampler.look_ahead_full()
    }

    pub fn cycle(&self) -> &Cycle {
        &self.cycle
    }

    /// Deactivates: the final state and the last safe setpoint (the planner thread is
    /// detached; it only ever fills its bounded queue).
    pub fn deactivate(self) -> (LoopState, Option<JointSetpoint>) {
        (self.state, self.last_safe)
    }

    /// True while following a cueing stream.
    pub fn is_cueing(&self) -> bool {
        self.cueing.is_some()
    }

    /// Loop time (ns) of the last cueing target received, `None` before the first.
    pub fn cueing_last_ns(&self) -> Option<u64> {
        self.cueing_last_ns
    }

    /// One cycle at monotonic time `now_ns`. Returns the state after the cycle.
    #[inline]
    pub fn step(
        &mut self,
        now_ns: u64,
        sink: &mut impl SetpointSink,
        commands: &mut impl CommandSource,
        stats: &LoopStats,
    ) -> LoopState {
        while let Some(c) = commands.poll() {
            match (c, self.state) {
                (Command::EStop, _) => self.state = LoopState::EStopped,
                (Command::Reset(ResetAuthority(())), s) if s.is_latched() => {
                    self.state = LoopState::Holding
                }
                (Command::Reset(_), _) => {}
            }
        }
        if let Some(r) = &mut self.rides {
            let abort = r.slot.abort_requested();
            let idle = match self.state {
                LoopState::Holding => true,
                LoopState::Running => {
                    matches!(r.braking, Some((_, true)))
                        || (r.braking.is_none() && self.sampler.finished())
                }
                _ => false,
            };
            if idle && let Some((sampler, samples)) = r.slot.take() {
                let old = std::mem::replace(&mut self.sampler, sampler);
                r.slot.retire(old);
                r.braking = None;
                self.state = LoopState::Running;
                r.slot.set_plan_end(self.sequence + samples);
            } else if abort && self.state == LoopState::Running && r.braking.is_none() && !idle {
                self.sampler.cancel();
                r.braking = Some((r.last_reference, false));
            }
        }
        if self.state == LoopState::Running {
            let braking = self.rides.as_mut().and_then(|r| {
                let (b, rest) = r.braking.as_mut()?;
                if !*rest && ride::brake_step(b, &r.limits, r.period_s) {
                    *rest = true;
                    // The stream's planned end is now: the loop holds from the next setpoint.
                    r.slot.stopped_at(self.sequence + 1);
                }
                Some(*b)
            });
            let reference: Reference = match (&mut self.cueing, braking) {
                (_, Some(b)) => b,
                (Some((filter, source)), None) => {
                    if let Some(t) = source.latest() {
                        filter.set_target(&t);
                        self.cueing_last_ns = Some(now_ns);
                    }
                    filter.step()
                }
                (None, None) => self.sampler.next_reference().0,
            };
            match self.cycle.compute(&reference, &mut self.setpoint) {
                Ok(()) => {
                    self.last_safe = Some(self.setpoint);
                    if let Some(r) = &mut self.rides {
                        r.last_reference = reference;
                    }
                }
                Err(r) => {
                    stats.rejected.fetch_add(1, Ordering::Relaxed);
                    self.state = LoopState::Refused(r);
                }
            }
        }
        let out = match (self.state, &self.last_safe) {
            (LoopState::Running, _) => Some(self.setpoint),
            // Hold: the last safe setpoint, not moving.
            (_, Some(held)) => {
                let mut h = *held;
                h.pose_velocity = [0.0; 6];
                h.cable_velocity_m_per_s = [0.0; crs_ipc::MAX_CABLES];
                Some(h)
            }
            (_, None) => None,
        };
        if let Some(mut sp) = out {
            self.sequence += 1;
            sp.sequence = self.sequence;
            sp.timestamp_ns = now_ns;
            if sink.publish(&sp) {
                stats.published.fetch_add(1, Ordering::Relaxed);
            }
        }
        if let Some(r) = &self.rides {
            let phase = match (self.state, r.braking) {
                (s, _) if s.is_latched() => RidePhase::Latched,
                (_, Some((_, false))) => RidePhase::Braking,
                (LoopState::Holding, _) | (_, Some((_, true))) => RidePhase::Idle,
                _ if self.sampler.finished() => RidePhase::Idle,
                _ => RidePhase::Riding,
            };
            r.slot.publish(phase, &r.last_reference.pose);
        }
        stats.cycles.fetch_add(1, Ordering::Relaxed);
        self.state
    }

    pub fn last_setpoint(&self) -> Option<&JointSetpoint> {
        self.last_safe.as_ref()
    }
}

/// Runs `hard_loop` on the absolute-deadline timer until `stop` is set or `until` returns true.
/// The first cycle runs at `start_ns` (CLOCK_MONOTONIC), so other stages can share the timeline;
/// each next deadline follows `timeline`'s phase when one is announced (the drive bus's SYNC
/// less the lead, [`timeline`]).
#[allow(clippy::too_many_arguments)]
pub fn run_timed(
    hard_loop: &mut HardLoop,
    start_ns: u64,
    timeline: &timeline::Timeline,
    sink: &mut impl SetpointSink,
    commands: &mut impl CommandSource,
    stats: &LoopStats,
    stop: &AtomicBool,
    mut after_cycle: impl FnMut(&HardLoop, u64),
) {
    let period_ns = timeline.period_ns();
    let mut deadline = start_ns;
    while !stop.load(Ordering::Relaxed) {
        realtime::sleep_until(deadline);
        let woke = realtime::monotonic_ns();
        stats.lateness.record(woke.saturating_sub(deadline));
        hard_loop.step(woke, sink, commands, stats);
        let done = realtime::monotonic_ns();
        stats.compute.record(done - woke);
        after_cycle(hard_loop, done);
        deadline += period_ns;
        if done > deadline {
            stats.overruns.fetch_add(1, Ordering::Relaxed);
            // Skip the missed deadlines instead of bursting to catch up.
            let missed = (done - deadline) / period_ns + 1;
            deadline += missed * period_ns;
        }
        deadline = timeline.align(deadline, 0);
    }
}
