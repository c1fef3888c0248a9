//! The hard loop: zero allocation on the loop thread over many cycles (setpoints reach the
//! real iceoryx2 publisher through the outbox and publish stage), e-stop latch and reset, refusal of bad references, input-file errors.
mod common;

use cdpr_model::Pose;
use crs_ipc::{IpcNode, JointSetpoint, MotionState};
use motion_core::daemon::cycle::{Cycle, Reference, Rejection};
use motion_core::daemon::outbox::{
    Outbox, OutboxSink, StagePorts, publish_pass, run_publish_stage,
};
use motion_core::daemon::stats::LoopStats;
use motion_core::daemon::trajectory::{self, PlannerLimits, Waypoint};
use motion_core::daemon::{
    Command, CommandSource, HardLoop, LoopState, ResetAuthority, ResetGate, ResetIgnored,
    SetpointSink, config, lifecycle,
};
use nalgebra::Vector3;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);
thread_local!(static COUNT_HERE: Cell<bool> = const { Cell::new(false) });

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if COUNT_HERE.with(|c| c.get()) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        if COUNT_HERE.with(|c| c.get()) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        if COUNT_HERE.with(|c| c.get()) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

const NOW: u64 = 100_000_000_000;

/// The monitor's epoch announcement of `epoch`, stamped `t`.
fn announcement(epoch: u32, t: u64) -> crs_ipc::StateEvent {
    let mut ev = crs_ipc::StateEvent::new(
        crs_ipc::ProcessId::SafetyMonitor,
        crs_ipc::EventKind::StateChanged,
        1,
    );
    ev.detail = crs_ipc::MonitorCode::EpochAnnounce.into();
    ev.detail_node = epoch;
    ev.timestamp_ns = t;
    ev
}

/// The monitor's Reset event of `epoch`, stamped `t`.
fn reset_event(epoch: u32, t: u64) -> crs_ipc::StateEvent {
    let mut ev = crs_ipc::StateEvent::new(
        crs_ipc::ProcessId::SafetyMonitor,
        crs_ipc::EventKind::Reset,
        2,
    );
    ev.detail = epoch;
    ev.timestamp_ns = t;
    ev
}

/// A reset minted the one way there is: the gate, from the monitor's announcement and reset
/// event.
fn reset() -> ResetAuthority {
    let mut gate = ResetGate::new();
    assert_eq!(
        gate.check(&announcement(1, NOW), NOW),
        Err(ResetIgnored::NotAReset)
    );
    gate.check(&reset_event(1, NOW), NOW)
        .expect("the monitor's reset event carries a reset")
}

fn limits() -> PlannerLimits {
    PlannerLimits {
        linear_velocity: 1.0,
        angular_velocity: 0.5,
        linear_acceleration: 2.0,
        angular_acceleration: 1.0,
        linear_jerk: 20.0,
        angular_jerk: 5.0,
    }
}

fn setup(waypoints: Vec<Waypoint>) -> HardLoop {
    let pf = common::platform("icosahedron.toml");
    let cycle = Cycle::new(pf.model.clone(), pf.limits, pf.region, true);
    let sampler = trajectory::spawn_planner(pf.home, waypoints, limits(), 1e-3, |e| panic!("{e}"));
    HardLoop::new(cycle, sampler)
}

/// Waits until the planner thread has filled its look-ahead queue (or delivered the whole
/// plan), so the loop stepped by the test cannot starve before it has read that much. The
/// deadline only stops a hung planner; nothing depends on how long the wait takes.
fn wait_for_planner(hl: &HardLoop) {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    while !hl.plan_look_ahead_full() {
        assert!(
            std::time::Instant::now() < deadline,
            "the planner never filled its queue"
        );
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
}

/// Largest per-cable difference of two setpoints' lengths, m.
fn length_change(a: &JointSetpoint, b: &JointSetpoint) -> f64 {
    a.cable_length_m
        .iter()
        .zip(&b.cable_length_m)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn tour() -> Vec<Waypoint> {
    [
        [0.3, 0.0, 2.0],
        [0.3, 0.3, 1.9],
        [-0.2, 0.3, 2.0],
        [0.0, 0.0, 2.0],
    ]
    .iter()
    .map(|p| Waypoint {
        pose: Pose::new(Vector3::from(*p), Vector3::zeros()),
        not_before_s: 0.0,
    })
    .collect()
}

struct Ring(Vec<JointSetpoint>, usize);
impl SetpointSink for Ring {
    fn publish(&mut self, sp: &JointSetpoint) -> bool {
        let n = self.0.len();
        self.0[self.1 % n] = *sp;
        self.1 += 1;
        true
    }
}

/// The publish stage's ports in the test: real iceoryx2 setpoint publisher, counted events.
struct StageIox {
    setpoints: crs_ipc::TopicPublisher<JointSetpoint>,
    heartbeats: u64,
}
impl StagePorts for StageIox {
    fn setpoint(&mut self, sp: &JointSetpoint) -> bool {
        self.setpoints.publish(sp).is_ok()
    }
    fn heartbeat(&mut self, _state: MotionState, _overruns: u64) {
        self.heartbeats += 1;
    }
    fn state_changed(&mut self, _from: MotionState, _to: MotionState) {}
}

struct Script(VecDeque<(u64, Command)>, u64);
impl CommandSource for Script {
    /// `self.1` is the current step, set by the test before each step.
    fn poll(&mut self) -> Option<Command> {
        match self.0.front() {
            Some((at, _)) if *at <= self.1 => self.0.pop_front().map(|(_, c)| c),
            _ => None,
        }
    }
}

#[test]
fn loop_thread_allocates_nothing_over_many_cycles() {
    // The loop hands setpoints to the publish stage through the outbox; the stage (another
    // thread, real iceoryx2) publishes them. Only the loop thread is counted.
    let prefix = format!("alloc{}/", std::process::id());
    let outbox = Arc::new(Outbox::new(64));
    let stats = Arc::new(LoopStats::default());
    let stop = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let stage = {
        let (outbox, stats, stop, prefix) =
            (outbox.clone(), stats.clone(), stop.clone(), prefix.clone());
        std::thread::spawn(move || {
            let node = IpcNode::with_prefix("alloc_stage", &prefix).unwrap();
            let mut ports = StageIox {
                setpoints: node.publisher::<JointSetpoint>().unwrap(),
                heartbeats: 0,
            };
            ready_tx.send(()).unwrap();
            let (mut c, mut s) = (0, LoopState::Running.code());
            let mut sent = 0;
            while !stop.load(Ordering::Relaxed) {
                sent += publish_pass(&outbox, &stats, &mut ports, &mut c, &mut s, 10);
                std::thread::sleep(std::time::Duration::from_micros(200));
            }
            sent += publish_pass(&outbox, &stats, &mut ports, &mut c, &mut s, 10);
            (sent, ports.heartbeats)
        })
    };
    ready_rx.recv().unwrap();
    let node = IpcNode::with_prefix("alloc_test", &prefix).unwrap();
    let sub = node.subscriber::<JointSetpoint>().unwrap();
    let mut hl = setup(tour());
    let mut cmds = Script(VecDeque::new(), 0);
    // The planner's queue full before the loop starts (it keeps ahead of the paced loop).
    wait_for_planner(&hl);
    let cycles = 5000u64;
    let mut received = 0;
    for k in 0..cycles {
        COUNT_HERE.with(|c| c.set(true));
        hl.step(k * 1_000_000, &mut OutboxSink(&outbox), &mut cmds, &stats);
        COUNT_HERE.with(|c| c.set(false));
        // Paced by the data, not by time: every 16 cycles wait (bounded) until the stage has
        // delivered every setpoint so far, so neither the outbox (64) nor the subscriber
        // buffer (32) can overflow however the host schedules the stage. Receiving is not the
        // loop's job (not counted).
        if k % 16 == 15 {
            let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
            while received < k + 1 && std::time::Instant::now() < deadline {
                match sub.receive() {
                    Ok(Some(_)) => received += 1,
                    _ => std::thread::sleep(std::time::Duration::from_micros(100)),
                }
            }
        }
    }
    let n = ALLOCS.load(Ordering::Relaxed);
    stop.store(true, Ordering::Relaxed);
    let (sent, heartbeats) = stage.join().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(5));
    while let Ok(Some(_)) = sub.receive() {
        received += 1;
    }
    assert_eq!(hl.state(), LoopState::Running);
    assert_eq!(stats.cycles.load(Ordering::Relaxed), cycles);
    assert_eq!(n, 0, "{n} heap operations on the loop thread");
    // Every setpoint went through the outbox and over iceoryx2 (subscriber buffer 64: the test
    // drains every 16 cycles, so nothing is overwritten).
    assert_eq!(outbox.dropped.load(Ordering::Relaxed), 0);
    assert_eq!(sent as u64, cycles);
    assert_eq!(received, cycles);
    // At most one heartbeat per 10 loop cycles, and some while the loop advanced.
    assert!(
        heartbeats > 0 && heartbeats <= cycles / 10,
        "heartbeats {heartbeats}"
    );
    // The counter does see allocations on this thread.
    COUNT_HERE.with(|c| c.set(true));
    drop(std::hint::black_box(vec![0u8; 32]));
    COUNT_HERE.with(|c| c.set(false));
    assert!(ALLOCS.load(Ordering::Relaxed) > 0);
}

#[test]
fn publish_stage_heartbeats_only_while_the_loop_advances() {
    #[derive(Default)]
    struct Count {
        heartbeats: u64,
        changes: Vec<(MotionState, MotionState)>,
    }
    impl StagePorts for Count {
        fn setpoint(&mut self, _: &JointSetpoint) -> bool {
            true
        }
        fn heartbeat(&mut self, _: MotionState, _: u64) {
            self.heartbeats += 1;
        }
        fn state_changed(&mut self, from: MotionState, to: MotionState) {
            self.changes.push((from, to));
        }
    }
    let outbox = Outbox::new(4);
    let stats = LoopStats::default();
    let mut p = Count::default();
    let (mut c, mut s) = (0, LoopState::Running.code());
    for _ in 0..100 {
        stats.cycles.fetch_add(1, Ordering::Relaxed);
        publish_pass(&outbox, &stats, &mut p, &mut c, &mut s, 10);
    }
    assert_eq!(p.heartbeats, 10);
    // The loop freezes: the stage keeps running but the heartbeat stops.
    for _ in 0..100 {
        publish_pass(&outbox, &stats, &mut p, &mut c, &mut s, 10);
    }
    assert_eq!(p.heartbeats, 10);
    outbox
        .state
        .store(LoopState::EStopped.code(), Ordering::Relaxed);
    publish_pass(&outbox, &stats, &mut p, &mut c, &mut s, 10);
    assert_eq!(
        p.changes,
        vec![(MotionState::Running, MotionState::EStopped)]
    );
    assert_eq!(
        p.changes
            .iter()
            .map(|&(a, b)| (u32::from(a), u32::from(b)))
            .collect::<Vec<_>>(),
        vec![(1, 2)]
    );
    // A full outbox drops (counted) instead of blocking the loop.
    let mut sink = OutboxSink(&outbox);
    let ok: Vec<bool> = (0..6)
        .map(|_| sink.publish(&JointSetpoint::default()))
        .collect();
    assert_eq!(ok, vec![true, true, true, true, false, false]);
    assert_eq!(outbox.dropped.load(Ordering::Relaxed), 2);
}

#[test]
fn publish_stage_ends_the_stream_after_the_last_setpoint() {
    // The safety monitor disarms its silence watch on the stream-end event, so that event must
    // follow every setpoint the loop queued.
    #[derive(Default)]
    struct Log(Vec<&'static str>);
    impl StagePorts for Log {
        fn setpoint(&mut self, _: &JointSetpoint) -> bool {
            self.0.push("setpoint");
            true
        }
        fn heartbeat(&mut self, _: MotionState, _: u64) {}
        fn state_changed(&mut self, _: MotionState, _: MotionState) {}
        fn announce(&mut self) {
            self.0.push("announce");
        }
        fn stream_end(&mut self) {
            self.0.push("end");
        }
        fn setpoints_sent(&mut self) {
            self.0.push("notify");
        }
    }
    let outbox = Outbox::new(8);
    let stats = LoopStats::default();
    let stop = AtomicBool::new(true);
    let mut sink = OutboxSink(&outbox);
    for _ in 0..3 {
        assert!(sink.publish(&JointSetpoint::default()));
    }
    let mut log = Log::default();
    // Stop already set: the stage runs no periodic pass, only the final drain.
    let timeline = motion_core::daemon::timeline::Timeline::new(1_000_000);
    run_publish_stage(&outbox, &stats, &mut log, 0, &timeline, 0, 10, &stop);
    // One "setpoint published" notification per pass, after its setpoints (drive-io's
    // phase-locked cycle reads them when woken), none for a pass without setpoints.
    assert_eq!(
        log.0,
        vec!["setpoint", "setpoint", "setpoint", "notify", "end"]
    );
}

#[test]
fn estop_latches_and_holds_until_reset() {
    // The same plan twice: `hl` is e-stopped at step 500 and reset at step 1500, `free` runs on.
    let mut hl = setup(tour());
    let mut free = setup(tour());
    wait_for_planner(&hl);
    wait_for_planner(&free);
    let mut sink = Ring(vec![JointSetpoint::default(); 1], 0);
    let mut free_sink = Ring(vec![JointSetpoint::default(); 1], 0);
    let (stats, free_stats) = (LoopStats::default(), LoopStats::default());
    let mut cmds = Script(
        VecDeque::from([(500, Command::EStop), (1500, Command::Reset(reset()))]),
        0,
    );
    let mut no_cmds = Script(VecDeque::new(), 0);
    let (mut first, mut before) = (None, None);
    for k in 0..2000u64 {
        cmds.1 = k;
        let st = hl.step(k, &mut sink, &mut cmds, &stats);
        assert_eq!(
            free.step(k, &mut free_sink, &mut no_cmds, &free_stats),
            LoopState::Running
        );
        let sp = sink.0[0];
        match k {
            0 => first = Some(sp),
            1..=498 => assert_eq!(st, LoopState::Running),
            499 => before = Some(sp),
            500..=1499 => {
                assert_eq!(st, LoopState::EStopped);
                let b = before.unwrap();
                assert_eq!(
                    sp.cable_length_m, b.cable_length_m,
                    "no motion while e-stopped"
                );
                assert!(sp.cable_velocity_m_per_s.iter().all(|v| *v == 0.0));
                assert_eq!(
                    sp.sequence,
                    k + 1,
                    "setpoints keep flowing (held), numbered"
                );
            }
            _ => {
                // Reset releases the latch but does not resume the old plan.
                assert_eq!(st, LoopState::Holding);
                assert_eq!(sp.cable_length_m, before.unwrap().cable_length_m);
            }
        }
    }
    let (first, before) = (first.unwrap(), before.unwrap());
    // The plan was moving when the e-stop came: the cables had left their home lengths and
    // still had velocity.
    let moved = length_change(&before, &first);
    assert!(
        moved > 0.01,
        "the plan had moved the cables only {moved} m by the e-stop"
    );
    assert!(
        before.cable_velocity_m_per_s.iter().any(|v| v.abs() > 0.01),
        "not moving at the e-stop: {:?}",
        before.cable_velocity_m_per_s
    );
    // ... and had more to go: the same plan left running moved on from there, so holding after
    // the reset is the loop refusing to resume it, not a plan that had ended.
    let would_have = length_change(&free_sink.0[0], &before);
    assert!(
        would_have > 0.01,
        "the plan left running moved only {would_have} m past the e-stop point"
    );
    assert!(
        !hl.plan_finished(),
        "the held loop read the rest of its plan"
    );
}

#[test]
fn bad_references_are_refused_and_latch() {
    let pf = common::platform("icosahedron.toml");
    let mut c = Cycle::new(pf.model.clone(), pf.limits, pf.region, true);
    let mut sp = JointSetpoint::default();
    let ok = Reference {
        pose: pf.home,
        ..Reference::default()
    };
    c.compute(&ok, &mut sp).unwrap();
    assert_eq!(sp.cable_count, 8);
    let mut r = ok;
    r.pose.r.x = f64::NAN;
    assert_eq!(c.compute(&r, &mut sp), Err(Rejection::NonFinite));
    let mut r = ok;
    r.pose.r.z = 5.0;
    assert_eq!(c.compute(&r, &mut sp), Err(Rejection::OutsideRegion));
    let mut r = ok;
    r.velocity[0] = 6.0; // table 5.1: 5 m/s
    assert!(matches!(
        c.compute(&r, &mut sp),
        Err(Rejection::LinearVelocity { .. })
    ));
    let mut r = ok;
    r.acceleration[2] = 15.0; // 14 m/s²
    assert!(matches!(
        c.compute(&r, &mut sp),
        Err(Rejection::LinearAcceleration { .. })
    ));
    // Inside the box but not wrench feasible (rotation the cabin cannot hold).
    let mut r = ok;
    r.pose = Pose::new(
        Vector3::new(-1.4, 1.4, 2.7),
        Vector3::new(-0.06, 0.0, -0.08),
    );
    assert!(matches!(
        c.compute(&r, &mut sp),
        Err(Rejection::NotWrenchFeasible { .. })
    ));
    // Without a surrogate the offset is zero and q_θ = φ(x).
    c.compute(&ok, &mut sp).unwrap();
    assert!(sp.surrogate_offset_m.iter().all(|o| *o == 0.0));
}

#[test]
fn a_plan_through_infeasible_poses_is_refused_before_it_runs() {
    let pf = common::platform("icosahedron.toml");
    let mut c = Cycle::new(pf.model.clone(), pf.limits, pf.region, true);
    let mut sp = JointSetpoint::default();
    let bad = vec![Waypoint {
        pose: Pose::new(
            Vector3::new(-1.4, 1.4, 2.7),
            Vector3::new(-0.06, 0.0, -0.08),
        ),
        not_before_s: 0.0,
    }];
    let err = trajectory::plan_samples::<String>(pf.home, &bad, limits(), 1e-3, |_, r| {
        c.compute(&r, &mut sp).map_err(|e| e.to_string())
    })
    .unwrap_err();
    assert!(
        err.contains("wrench feasible") || err.contains("workspace"),
        "{err}"
    );
    // The tour passes.
    trajectory::plan_samples::<String>(pf.home, &tour(), limits(), 1e-3, |_, r| {
        c.compute(&r, &mut sp).map_err(|e| e.to_string())
    })
    .unwrap();
}

#[test]
fn waypoint_and_daemon_config_errors_name_the_line() {
    let e = trajectory::parse_waypoints(
        "t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg\n0,0,0,2,0,0,0\n1,0,zero,2,0,0,0\n",
        "w.csv",
    )
    .unwrap_err()
    .to_string();
    assert!(e.starts_with("w.csv:3:") && e.contains("y_m"), "{e}");
    let e = trajectory::parse_waypoints("t,x\n", "w.csv")
        .unwrap_err()
        .to_string();
    assert!(e.contains("w.csv:1"), "{e}");
    let e = trajectory::parse_waypoints(
        "t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg\n2,0,0,2,0,0,0\n1,0,0,2,0,0,0\n",
        "w.csv",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("w.csv:3") && e.contains("decrease"), "{e}");
    let base = std::fs::read_to_string(common::config_path("motion-core.toml")).unwrap();
    let dir = std::path::Path::new(".");
    motion_core::daemon::config::parse(&base, "mc.toml", dir).unwrap();
    let e = motion_core::daemon::config::parse(
        &base.replace("period_us = 1000", "period_us = 10"),
        "mc.toml",
        dir,
    )
    .unwrap_err();
    assert_eq!(e.key, "realtime.period_us", "{e}");
    assert!(e.line.is_some());
    let e = motion_core::daemon::config::parse(
        &base.replace("priority = 80", "priority = 80\nprio = 3"),
        "mc.toml",
        dir,
    )
    .unwrap_err();
    assert!(e.to_string().contains("prio"), "{e}");
    let e = motion_core::daemon::config::parse(
        &base.replace("velocity_scale = 0.3", "velocity_scale = 1.5"),
        "mc.toml",
        dir,
    )
    .unwrap_err();
    assert_eq!(e.key, "trajectory.velocity_scale", "{e}");
}

/// A cueing stream: a new target at given steps (the test sets the step in `.1`).
struct CueScript(VecDeque<(u64, [f64; 6])>, std::rc::Rc<Cell<u64>>);
impl motion_core::daemon::cueing::CueingSource for CueScript {
    fn latest(&mut self) -> Option<[f64; 6]> {
        let mut newest = None;
        while let Some((at, _)) = self.0.front() {
            if *at > self.1.get() {
                break;
            }
            newest = self.0.pop_front().map(|(_, t)| t);
        }
        newest
    }
}

#[test]
fn cueing_stream_is_followed_and_a_target_outside_the_region_latches() {
    use motion_core::daemon::cueing::{CueingFilter, CueingLimits};
    let pf = common::platform("icosahedron.toml");
    let limits = CueingLimits {
        linear_velocity: 1.0,
        linear_acceleration: 2.0,
        angular_velocity: 0.5,
        angular_acceleration: 1.0,
    };
    let step = std::rc::Rc::new(Cell::new(0u64));
    let target = [0.3, -0.2, 2.1, 0.0, 0.02, 0.0];
    let outside = [0.0, 0.0, 5.0, 0.0, 0.0, 0.0];
    let cues = CueScript(
        VecDeque::from([(10, target), (3000, outside)]),
        step.clone(),
    );
    let filter = CueingFilter::new(&pf.home, limits, 1e-3);
    let mut hl = setup(Vec::new()).with_cueing(filter, Box::new(cues));
    assert!(hl.is_cueing());
    let mut sink = Ring(vec![JointSetpoint::default(); 1], 0);
    let mut cmds = Script(VecDeque::new(), 0);
    let stats = LoopStats::default();
    for k in 0..3000u64 {
        step.set(k);
        assert_eq!(hl.step(k, &mut sink, &mut cmds, &stats), LoopState::Running);
    }
    // Arrived at the target; the setpoint carries the IK of that pose.
    let sp = sink.0[0];
    for (p, t) in sp.pose.iter().zip(&target) {
        assert!((p - t).abs() < 1e-9, "{:?}", sp.pose);
    }
    let mut d = cdpr_model::Data::new(&pf.model);
    cdpr_model::kinematics::inverse(&pf.model, &mut d, &Pose::from_array(target)).unwrap();
    for i in 0..pf.model.m() {
        assert!((sp.cable_length_m[i] - d.q[i]).abs() < 1e-9);
    }
    // A target far outside: the tracker moves towards it and the checks refuse the first pose
    // that leaves the region; the loop latches and holds.
    let mut latched = None;
    for k in 3000..8000u64 {
        step.set(k);
        if let LoopState::Refused(r) = hl.step(k, &mut sink, &mut cmds, &stats) {
            latched = Some(r);
            break;
        }
    }
    assert!(latched.is_some(), "never refused");
    let held = sink.0[0];
    assert!(held.pose[2] <= pf.region.position.max.z + 1e-9);
    for k in 0..100u64 {
        step.set(8000 + k);
        assert!(matches!(
            hl.step(8000 + k, &mut sink, &mut cmds, &stats),
            LoopState::Refused(_)
        ));
        assert_eq!(sink.0[0].cable_length_m, held.cable_length_m);
    }
}

fn shipped_daemon_config() -> config::DaemonConfig {
    config::load(common::config_path("motion-core.toml").as_ref()).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn only_a_reset_event_mints_a_reset_and_other_commands_do_not_clear_the_latch() {
    for kind in [
        crs_ipc::EventKind::EStop,
        crs_ipc::EventKind::StateChanged,
        crs_ipc::EventKind::Fault,
    ] {
        let ev = crs_ipc::StateEvent::new(crs_ipc::ProcessId::SafetyMonitor, kind, 1);
        assert_eq!(
            ResetGate::new().check(&ev, NOW),
            Err(ResetIgnored::NotAReset),
            "{kind:?}"
        );
    }
    let mut foreign = crs_ipc::StateEvent::new(
        crs_ipc::ProcessId::SafetyMonitor,
        crs_ipc::EventKind::Reset,
        1,
    );
    foreign.version = crs_ipc::CONTRACT_VERSION + 1;
    assert_eq!(
        ResetGate::new().check(&foreign, NOW),
        Err(ResetIgnored::NotAReset),
        "other contract version"
    );
    // Only the safety monitor's reset, and only of an epoch it announced and this loop has
    // not acted on.
    let mut gate = ResetGate::new();
    for src in [
        crs_ipc::ProcessId::Operator,
        crs_ipc::ProcessId::DriveIo,
        crs_ipc::ProcessId::MotionCore,
        crs_ipc::ProcessId::Test,
    ] {
        let mut ev = crs_ipc::StateEvent::new(src, crs_ipc::EventKind::Reset, 1);
        ev.detail = 5;
        ev.timestamp_ns = NOW;
        assert_eq!(gate.check(&ev, NOW), Err(ResetIgnored::Source(src as u32)));
    }
    // Never "any epoch first": without the monitor's announcement nothing is accepted.
    assert_eq!(
        gate.check(&reset_event(5, NOW), NOW),
        Err(ResetIgnored::NotAnnounced {
            epoch: 5,
            announced: None
        })
    );
    let _ = gate.check(&announcement(5, NOW), NOW);
    assert_eq!(gate.announced_epoch(), Some(5));
    assert!(gate.check(&reset_event(5, NOW), NOW).is_ok());
    // The same event again (a replay), or an older epoch: ignored.
    assert_eq!(
        gate.check(&reset_event(5, NOW), NOW),
        Err(ResetIgnored::NotNewer { epoch: 5, last: 5 })
    );
    let _ = gate.check(&announcement(6, NOW + 1), NOW + 1);
    // A reset of another epoch than the announced one, or stamped before the announcement.
    assert!(matches!(
        gate.check(&reset_event(7, NOW + 1), NOW + 1),
        Err(ResetIgnored::NotAnnounced { .. })
    ));
    assert!(matches!(
        gate.check(&reset_event(6, NOW), NOW + 1),
        Err(ResetIgnored::NotAnnounced { .. })
    ));
    // Stale, or stamped in the loop's future.
    assert_eq!(
        gate.check(&reset_event(6, NOW + 1), NOW + 3_000_000_000),
        Err(ResetIgnored::Stale)
    );
    assert_eq!(
        gate.check(&reset_event(6, NOW + 1_000_000_000), NOW + 1),
        Err(ResetIgnored::Stale)
    );
    assert!(gate.check(&reset_event(6, NOW + 2), NOW + 2).is_ok());
    assert_eq!(gate.last_epoch(), Some(6));
    // A restarted monitor (a new instance): its start epoch is no reset even when announced;
    // its first accepted reset is.
    use crs_limits::reset_epoch::new;
    let t = NOW + 10;
    let _ = gate.check(&announcement(new(0x7777, 0), t), t);
    assert_eq!(
        gate.check(&reset_event(new(0x7777, 0), t), t),
        Err(ResetIgnored::StartEpoch {
            epoch: new(0x7777, 0)
        })
    );
    let _ = gate.check(&announcement(new(0x7777, 1), t + 1), t + 1);
    assert!(
        gate.check(&reset_event(new(0x7777, 1), t + 1), t + 1)
            .is_ok()
    );
    let mut hl = setup(tour());
    let mut sink = Ring(vec![JointSetpoint::default(); 1], 0);
    let stats = LoopStats::default();
    let mut cmds = Script(
        VecDeque::from([(0, Command::EStop), (5, Command::EStop)]),
        0,
    );
    for k in 0..20u64 {
        cmds.1 = k;
        assert_eq!(
            hl.step(k, &mut sink, &mut cmds, &stats),
            LoopState::EStopped
        );
    }
    // A reset while running is a no-op, not a state change.
    let mut hl = setup(tour());
    let mut cmds = Script(VecDeque::from([(0, Command::Reset(reset()))]), 0);
    assert_eq!(hl.step(0, &mut sink, &mut cmds, &stats), LoopState::Running);
    let (state, last) = hl.deactivate();
    assert_eq!(state, LoopState::Running);
    assert!(last.is_some());
}

#[test]
fn configure_scales_the_planner_limits_and_verifies_the_shipped_demo_plan() {
    let cfg = shipped_daemon_config();
    let pf = common::platform("icosahedron.toml");
    let c = lifecycle::configure(&cfg, &pf).unwrap_or_else(|e| panic!("{e}"));
    let l = c.planner_limits();
    // motion-core.toml: velocity_scale 0.3, acceleration_scale 0.2 of table 5.1, the
    // accelerations scaled to what the dynamic wrench keeps feasible (eq. 5.13-5.16).
    assert_eq!(l.linear_velocity, pf.limits.linear_velocity_max * 0.3);
    let factor = c
        .dynamic_limits()
        .expect("dynamic wrench on")
        .acceleration_factor;
    assert!(factor > 0.0 && factor <= 1.0, "{factor}");
    assert_eq!(
        l.angular_acceleration,
        pf.limits.angular_acceleration_max * 0.2 * factor
    );
    println!("icosahedron acceleration factor {factor:.3}");
    assert_eq!(l.linear_jerk, 20.0);
    assert!(!c.has_surrogate());
    let wps = trajectory::read_waypoints(cfg.trajectory.waypoints.as_ref().unwrap()).unwrap();
    let plan = c.verify_plan(&wps).unwrap_or_else(|e| panic!("{e}"));
    assert!(plan.samples > 1000, "{plan:?}");
    assert!((plan.duration_s - plan.samples as f64 * 1e-3).abs() < 1e-12);
}

#[test]
fn configure_refuses_plans_that_leave_the_workspace_or_the_feasible_set() {
    let cfg = shipped_daemon_config();
    let pf = common::platform("icosahedron.toml");
    let c = lifecycle::configure(&cfg, &pf).unwrap();
    let infeasible = Waypoint {
        pose: Pose::new(
            Vector3::new(-1.4, 1.4, 2.7),
            Vector3::new(-0.06, 0.0, -0.08),
        ),
        not_before_s: 0.0,
    };
    match c.verify_plan(&[infeasible]) {
        Err(lifecycle::PlanRefused::Rejected {
            segment: 0,
            rejection,
            ..
        }) => {
            assert!(
                matches!(rejection, Rejection::NotWrenchFeasible { .. }),
                "{rejection}"
            )
        }
        other => panic!("{other:?}"),
    }
    let outside = Waypoint {
        pose: Pose::new(Vector3::new(0.0, 0.0, 50.0), Vector3::zeros()),
        not_before_s: 0.0,
    };
    match c.verify_plan(&tour().into_iter().chain([outside]).collect::<Vec<_>>()) {
        Err(lifecycle::PlanRefused::WaypointOutside { index: 4, outside }) => {
            assert_eq!(outside.axis, "z_m");
            assert_eq!(outside.value, 50.0);
            assert_eq!(outside.max, pf.region.position.max.z);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn configure_refuses_a_missing_surrogate_file_naming_it() {
    let mut cfg = shipped_daemon_config();
    cfg.surrogate = Some("/nonexistent/surrogate.json".into());
    let pf = common::platform("icosahedron.toml");
    let e = lifecycle::configure(&cfg, &pf).err().expect("refused");
    assert!(matches!(e, lifecycle::ConfigureError::SurrogateFile { .. }));
    assert!(e.to_string().contains("/nonexistent/surrogate.json"), "{e}");
}

#[test]
fn home_command_is_the_inverse_kinematics_at_home_without_a_surrogate() {
    let cfg = shipped_daemon_config();
    let pf = common::platform("icosahedron.toml");
    let mut c = lifecycle::configure(&cfg, &pf).unwrap();
    let q = c.home_command().unwrap();
    let mut data = cdpr_model::Data::new(&pf.model);
    cdpr_model::kinematics::inverse(&pf.model, &mut data, &pf.home).unwrap();
    assert_eq!(q.len(), 8);
    for (i, qi) in q.iter().enumerate() {
        assert_eq!(*qi, data.q[i]);
    }
}
