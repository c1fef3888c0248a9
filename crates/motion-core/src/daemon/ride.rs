//! Rides started on purpose: the loop comes up holding the home pose and runs a ride only when
//! an operator hands it one (`crs ride start FILE`), verified with the loop's own checks before
//! anything moves; `abort` brakes the running ride to a stop, `home` returns from where the
//! platform holds.
//!
//! The operator's side (a control thread of the daemon, [`RideControl`]) plans and verifies off
//! the loop and passes a ready [`Sampler`] through a one-slot lock-free queue; the loop takes it
//! only while idle (the previous plan delivered, or braked to rest). Samplers the loop no longer
//! needs go back through a second queue and are dropped by the control thread, so the loop
//! neither allocates nor frees.

use super::cycle::Reference;
use super::lifecycle::{Configured, PlanRefused, RideRefused, VerifiedPlan};
use super::trajectory::{self, PlannerLimits, PlanningFailed, RideFile, Sampler, Waypoint};
use cdpr_model::Pose;
use crossbeam::queue::ArrayQueue;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

/// What the loop is doing with rides (published through [`RideSlot::phase`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum RidePhase {
    /// Holding at rest, ready for a ride (or for `home`).
    Idle = 0,
    /// Following a ride's plan.
    Riding = 1,
    /// Braking an aborted ride to a stop.
    Braking = 2,
    /// Latched (e-stop or refused reference): only the safety monitor's reset leaves it.
    Latched = 3,
}

impl RidePhase {
    fn from_code(c: u32) -> Self {
        match c {
            1 => Self::Riding,
            2 => Self::Braking,
            3 => Self::Latched,
            _ => Self::Idle,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Idle => "idle, holding",
            Self::Riding => "riding",
            Self::Braking => "braking an aborted ride",
            Self::Latched => "latched (e-stop or refused reference)",
        }
    }
}

/// Shared between the loop and the control thread; every field lock-free.
pub struct RideSlot {
    pending: ArrayQueue<(Sampler, u64)>,
    retired: ArrayQueue<Sampler>,
    abort: AtomicBool,
    phase: AtomicU32,
    /// The pose the loop's reference is at (f64 bits), consistent while idle.
    pose_bits: [AtomicU64; 6],
    /// Sequence number of the last setpoint of the current (or last) ride: the end of the
    /// stream the safety monitor is told about (`crs_ipc::MotionState::Plan`).
    plan_end: AtomicU64,
    /// Rides the loop has taken.
    started: AtomicU64,
}

impl RideSlot {
    /// A slot for a loop that starts at `home` with a plan ending at setpoint `plan_end`.
    pub fn new(home: Pose, plan_end: u64) -> Self {
        let s = Self {
            pending: ArrayQueue::new(1),
            retired: ArrayQueue::new(4),
            abort: AtomicBool::new(false),
            phase: AtomicU32::new(RidePhase::Idle as u32),
            pose_bits: Default::default(),
            plan_end: AtomicU64::new(plan_end),
            started: AtomicU64::new(0),
        };
        s.store_pose(&home);
        s
    }

    pub fn phase(&self) -> RidePhase {
        RidePhase::from_code(self.phase.load(Ordering::Acquire))
    }

    pub fn pose(&self) -> Pose {
        Pose::from_array(std::array::from_fn(|k| {
            f64::from_bits(self.pose_bits[k].load(Ordering::Acquire))
        }))
    }

    pub fn plan_end(&self) -> u64 {
        self.plan_end.load(Ordering::Acquire)
    }

    pub fn rides_started(&self) -> u64 {
        self.started.load(Ordering::Acquire)
    }

    fn store_pose(&self, p: &Pose) {
        for (k, v) in p.to_array().into_iter().enumerate() {
            self.pose_bits[k].store(v.to_bits(), Ordering::Release);
        }
    }

    /// Loop side, once per cycle: the phase and reference pose.
    #[inline]
    pub(crate) fn publish(&self, phase: RidePhase, pose: &Pose) {
        self.phase.store(phase as u32, Ordering::Release);
        self.store_pose(pose);
    }

    /// Loop side: a ride handed in, with its number of samples.
    #[inline]
    pub(crate) fn take(&self) -> Option<(Sampler, u64)> {
        self.pending.pop()
    }

    /// Loop side: the ride's last setpoint will go out as `end`.
    #[inline]
    pub(crate) fn set_plan_end(&self, end: u64) {
        self.plan_end.store(end, Ordering::Release);
        self.started.fetch_add(1, Ordering::AcqRel);
    }

    /// Loop side: the end of the stream after an abort (the loop holds from here).
    #[inline]
    pub(crate) fn stopped_at(&self, end: u64) {
        self.plan_end.store(end, Ordering::Release);
    }

    /// Loop side: hands a sampler back to be dropped off the loop.
    #[inline]
    pub(crate) fn retire(&self, s: Sampler) {
        s.cancel();
        // Never full: the control thread drains it before handing in a new ride.
        let _ = self.retired.push(s);
    }

    #[inline]
    pub(crate) fn abort_requested(&self) -> bool {
        self.abort.swap(false, Ordering::AcqRel)
    }
}

/// Why the control thread refused an operator's ride command.
#[derive(Debug, thiserror::Error)]
pub enum RideCommandError {
    #[error("ride refused: {0}")]
    Refused(#[from] RideRefused),
    #[error("return home refused: {0}")]
    HomeRefused(PlanRefused),
    #[error("not idle ({}): abort or wait for the end of the ride first", .0.name())]
    NotIdle(RidePhase),
    #[error(
        "the platform holds away from home at [{:.3}, {:.3}, {:.3}] m: run `crs ride home` first",
        .0.r.x, .0.r.y, .0.r.z
    )]
    NotAtHome(Pose),
    #[error("the loop is latched (e-stop or refused reference): reset at the safety monitor first")]
    Latched,
    #[error("no ride to abort ({})", .0.name())]
    NothingToAbort(RidePhase),
    #[error("a ride is already waiting to start")]
    Busy,
}

/// Tolerance of "at home" per pose coordinate (m, rad): the planner ends a plan on its target
/// to rounding.
pub const AT_HOME_TOLERANCE: f64 = 1e-6;

/// The control thread's side: checks, plans and verifies rides off the loop.
pub struct RideControl {
    configured: Configured,
    home: Pose,
    limits: PlannerLimits,
    period_s: f64,
}

impl RideControl {
    /// `configured` is a second [`Configured`] of the daemon (the loop owns the first).
    pub fn new(configured: Configured) -> Self {
        let home = configured.platform().home;
        let limits = configured.planner_limits();
        let period_s = configured.period_s();
        Self {
            configured,
            home,
            limits,
            period_s,
        }
    }

    fn drain(&self, slot: &RideSlot) {
        while slot.retired.pop().is_some() {}
    }

    /// Starts a ride: only idle at home; the whole plan verified before it is handed in.
    pub fn start(
        &self,
        slot: &RideSlot,
        ride: &RideFile,
        on_error: impl Fn(PlanningFailed) + Send + 'static,
    ) -> Result<VerifiedPlan, RideCommandError> {
        self.drain(slot);
        let plan = self.configured.verify_ride(ride)?;
        match slot.phase() {
            RidePhase::Idle => {}
            RidePhase::Latched => return Err(RideCommandError::Latched),
            p => return Err(RideCommandError::NotIdle(p)),
        }
        let at = slot.pose();
        let off = at
            .to_array()
            .iter()
            .zip(self.home.to_array())
            .any(|(a, h)| (a - h).abs() > AT_HOME_TOLERANCE);
        if off {
            return Err(RideCommandError::NotAtHome(at));
        }
        self.hand_in(slot, self.home, ride.waypoints.clone(), plan, on_error)
    }

    /// Returns home from where the platform holds (also after a reset of a latched loop).
    pub fn home(
        &self,
        slot: &RideSlot,
        on_error: impl Fn(PlanningFailed) + Send + 'static,
    ) -> Result<VerifiedPlan, RideCommandError> {
        self.drain(slot);
        match slot.phase() {
            RidePhase::Idle => {}
            RidePhase::Latched => return Err(RideCommandError::Latched),
            p => return Err(RideCommandError::NotIdle(p)),
        }
        let from = slot.pose();
        let wps = vec![Waypoint {
            pose: self.home,
            not_before_s: 0.0,
        }];
        let plan = self
            .configured
            .verify_plan_from(from, &wps)
            .map_err(RideCommandError::HomeRefused)?;
        self.hand_in(slot, from, wps, plan, on_error)
    }

    /// Asks the loop to brake the running ride to a stop.
    pub fn abort(&self, slot: &RideSlot) -> Result<(), RideCommandError> {
        match slot.phase() {
            RidePhase::Riding => {
                slot.abort.store(true, Ordering::Release);
                Ok(())
            }
            p => Err(RideCommandError::NothingToAbort(p)),
        }
    }

    fn hand_in(
        &self,
        slot: &RideSlot,
        from: Pose,
        waypoints: Vec<Waypoint>,
        plan: VerifiedPlan,
        on_error: impl Fn(PlanningFailed) + Send + 'static,
    ) -> Result<VerifiedPlan, RideCommandError> {
        let sampler =
            trajectory::spawn_planner(from, waypoints, self.limits, self.period_s, on_error);
        slot.pending
            .push((sampler, plan.samples as u64))
            .map_err(|(s, _)| {
                s.cancel();
                RideCommandError::Busy
            })?;
        Ok(plan)
    }
}

/// One cycle of braking an aborted ride: every pose coordinate's velocity brought to zero at
/// the planner's acceleration limit for that axis (the per-axis limit the plans use, norm/√3),
/// the pose integrated with the mean velocity of the cycle. Returns true once at rest.
#[inline]
pub fn brake_step(r: &mut Reference, limits: &PlannerLimits, dt: f64) -> bool {
    let s3 = 3f64.sqrt();
    let mut pose = r.pose.to_array();
    let mut at_rest = true;
    for k in 0..6 {
        let a_max = if k < 3 {
            limits.linear_acceleration
        } else {
            limits.angular_acceleration
        } / s3;
        let v = r.velocity[k];
        let dv = v.abs().min(a_max * dt);
        let v_new = v - v.signum() * dv;
        pose[k] += 0.5 * (v + v_new) * dt;
        r.velocity[k] = v_new;
        r.acceleration[k] = if dv > 0.0 { -v.signum() * dv / dt } else { 0.0 };
        at_rest &= v_new == 0.0;
    }
    r.pose = Pose::from_array(pose);
    at_rest
}
