//! Hand-off from the hard loop to the IPC publish stage.
//!
//! Why a separate stage: iceoryx2 0.10's `Publisher::loan_uninit` heap-allocates a 48-byte `Rc`
//! per sample (`ChunkMutSharedState::new`, measured by `crates/crs-ipc/examples/alloc_probe.rs`),
//! so publishing from the loop thread would break the rule that the hard loop allocates nothing.
//! The loop therefore pushes each setpoint into a preallocated lock-free queue
//! ([`crossbeam::queue::ArrayQueue`]: bounded, no allocation, no lock, never waits) and a publish
//! stage thread, woken on the same absolute timeline a fixed phase later, moves them to
//! iceoryx2. The added latency is that phase (default 200 µs), constant, not jitter of the loop.
//!
//! The stage also publishes the loop's heartbeat — only when the loop's cycle counter advanced,
//! so a frozen loop goes silent to the safety monitor even though this thread keeps running —
//! and a state event on every loop state change.

use super::LoopState;
use super::SetpointSink;
use super::stats::LoopStats;
use crossbeam::queue::ArrayQueue;
use crs_ipc::{JointSetpoint, MotionState};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

/// A [`MotionState`] shared between threads: the loop stores, the stage and the reporter load.
/// One atomic word (the state's wire code); only [`MotionStateCell::store`] writes it.
#[derive(Debug)]
pub struct MotionStateCell(AtomicU32);

impl MotionStateCell {
    pub fn new(state: MotionState) -> Self {
        Self(AtomicU32::new(state.into()))
    }

    #[inline]
    pub fn store(&self, state: MotionState, order: Ordering) {
        self.0.store(state.into(), order);
    }

    /// The stored state. Only `store` writes the word, with a valid code, so the fallback
    /// never applies; were it to, a latched state is the reading that permits nothing.
    #[inline]
    pub fn load(&self, order: Ordering) -> MotionState {
        MotionState::try_from(self.0.load(order)).unwrap_or(MotionState::EStopped)
    }
}

/// Phase of the publish stage after the loop's tick: the loop's compute is ~1-3 µs, its wake-up
/// lateness under load up to ~100 µs (benches/RESULTS.md), so 200 µs leaves the setpoint ready.
pub const PUBLISH_PHASE_NS: u64 = 200_000;

/// Shared between the loop (producer) and the publish stage (consumer). Allocated once at start.
pub struct Outbox {
    setpoints: ArrayQueue<JointSetpoint>,
    /// Loop state after the last cycle ([`super::HardLoop::state_code`]).
    pub state: MotionStateCell,
    /// Setpoints the loop could not hand over because the queue was full (stage stalled).
    pub dropped: AtomicU64,
    /// Setpoints the stage failed to publish over IPC.
    pub publish_failures: AtomicU64,
}

impl Outbox {
    /// `capacity` setpoints may wait for the stage; 64 = 64 ms at 1 kHz.
    pub fn new(capacity: usize) -> Self {
        Self {
            setpoints: ArrayQueue::new(capacity.max(1)),
            state: MotionStateCell::new(LoopState::Running.code()),
            dropped: AtomicU64::new(0),
            publish_failures: AtomicU64::new(0),
        }
    }

    /// Takes the oldest waiting setpoint (publish stage side).
    pub fn pop(&self) -> Option<JointSetpoint> {
        self.setpoints.pop()
    }

    pub fn len(&self) -> usize {
        self.setpoints.len()
    }

    pub fn is_empty(&self) -> bool {
        self.setpoints.is_empty()
    }
}

/// The loop's sink: a non-blocking, allocation-free push.
pub struct OutboxSink<'a>(pub &'a Outbox);

impl SetpointSink for OutboxSink<'_> {
    #[inline]
    fn publish(&mut self, sp: &JointSetpoint) -> bool {
        if self.0.setpoints.push(*sp).is_err() {
            self.0.dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        }
        true
    }
}

/// What the publish stage sends; the daemon implements it with iceoryx2 ports.
pub trait StagePorts {
    fn setpoint(&mut self, sp: &JointSetpoint) -> bool;
    /// Heartbeat of the loop: its `state`, `overruns` so far.
    fn heartbeat(&mut self, state: MotionState, overruns: u64);
    /// The loop changed state (`from` → `to`).
    fn state_changed(&mut self, from: MotionState, to: MotionState);
    /// Periodic loop statistics (about once per second; the stage may allocate, the loop not).
    fn loop_stats(&mut self, _stats: &LoopStats, _outbox: &Outbox) {}
    /// About once per second: re-announce what late subscribers need (the platform identity).
    fn announce(&mut self) {}
    /// After the last setpoint of a graceful stop has been sent: the end of the stream.
    fn stream_end(&mut self) {}
    /// After a pass that sent setpoints: tell the readers that follow the stream (drive-io's
    /// phase-locked SYNC). Here in the stage, not the hard loop: a notify is
    /// a syscall (10–30 µs).
    fn setpoints_sent(&mut self) {}
    /// Once per pass: the drive bus's newest SYNC schedule, if one was announced, into
    /// `timeline` (the loop ticks its lead before each SYNC, [`super::timeline`]).
    fn sync_schedule(&mut self, _timeline: &super::timeline::Timeline) {}
}

/// One pass of the publish stage: drains the outbox, then heartbeat/state bookkeeping.
/// `last_cycles`/`last_state` carry the stage's memory between passes. Returns setpoints sent.
pub fn publish_pass(
    outbox: &Outbox,
    stats: &LoopStats,
    ports: &mut impl StagePorts,
    last_cycles: &mut u64,
    last_state: &mut MotionState,
    heartbeat_every_cycles: u64,
) -> usize {
    let mut n = 0;
    while let Some(sp) = outbox.pop() {
        if !ports.setpoint(&sp) {
            outbox.publish_failures.fetch_add(1, Ordering::Relaxed);
        }
        n += 1;
    }
    if n > 0 {
        ports.setpoints_sent();
    }
    let state = outbox.state.load(Ordering::Relaxed);
    if state != *last_state {
        ports.state_changed(*last_state, state);
        *last_state = state;
    }
    let cycles = stats.cycles.load(Ordering::Relaxed);
    // Heartbeat only on progress: a frozen loop must look silent to the safety monitor.
    if cycles >= *last_cycles + heartbeat_every_cycles.max(1) {
        ports.heartbeat(state, stats.overruns.load(Ordering::Relaxed));
        *last_cycles = cycles;
    }
    n
}

/// Runs the publish stage on the loop's timeline shifted by `phase_ns` until `stop` is set.
/// Drains once more after `stop` so the last setpoints are not lost. Each pass also lets the
/// ports learn the drive bus's SYNC schedule into `timeline` ([`StagePorts::sync_schedule`]).
#[allow(clippy::too_many_arguments)]
pub fn run_publish_stage(
    outbox: &Outbox,
    stats: &LoopStats,
    ports: &mut impl StagePorts,
    start_ns: u64,
    timeline: &super::timeline::Timeline,
    phase_ns: u64,
    heartbeat_every_cycles: u64,
    stop: &AtomicBool,
) {
    let period_ns = timeline.period_ns();
    let mut last_cycles = 0;
    // The state the loop starts in (set before the stage starts): a change is announced
    // only when the loop leaves it.
    let mut last_state = outbox.state.load(Ordering::Relaxed);
    let mut deadline = start_ns + phase_ns;
    let stats_every = (1_000_000_000 / period_ns.max(1)).max(1);
    let mut passes = 0u64;
    while !stop.load(Ordering::Relaxed) {
        super::realtime::sleep_until(deadline);
        publish_pass(
            outbox,
            stats,
            ports,
            &mut last_cycles,
            &mut last_state,
            heartbeat_every_cycles,
        );
        passes += 1;
        if passes.is_multiple_of(stats_every) {
            ports.loop_stats(stats, outbox);
            ports.announce();
        }
        ports.sync_schedule(timeline);
        deadline += period_ns;
        let now = super::realtime::monotonic_ns();
        if now > deadline {
            deadline += (now - deadline) / period_ns * period_ns + period_ns;
        }
        deadline = timeline.align(deadline, phase_ns);
    }
    publish_pass(
        outbox,
        stats,
        ports,
        &mut last_cycles,
        &mut last_state,
        heartbeat_every_cycles,
    );
    ports.loop_stats(stats, outbox);
    // Only after the final drain: the monitor must have every setpoint before it disarms.
    ports.stream_end();
}
