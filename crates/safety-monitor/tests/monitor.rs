//! The monitor core ([`safety_monitor::Monitor`]) against the shipped configuration
//! (config/safety-monitor.toml -> config/icosahedron.toml, config/drives.toml). Setpoints are
//! generated with motion-core's kinematics (dev-dependency), so Δq is the difference of two
//! independent implementations plus the injected offset.

use crs_ipc::{BusState, DriveFeedback, JointSetpoint, MAX_CABLES, PlatformId, PlatformIdentity};
use proptest::prelude::*;
use safety_monitor::config::{self, MonitorConfig};
use safety_monitor::identity::platform_identity;
use safety_monitor::kinematics::StandardKinematics;
use safety_monitor::monitor::{HISTORY, Limits};
use safety_monitor::{Cause, Monitor, MonitorState, ResetDecision, StateCode};
use std::path::PathBuf;
use std::sync::OnceLock;

/// An operator's reset the way the safety I/O node's key gives one: turned, then released.
fn key_reset() -> safety_monitor::operator::OperatorReset {
    use safety_monitor::operator::{INPUT_ESTOP_CLOSED, INPUT_RESET_KEY, KeyEvent, KeyWatch};
    let mut k = KeyWatch::new();
    k.on_inputs(INPUT_ESTOP_CLOSED | INPUT_RESET_KEY, 0);
    match k.on_inputs(INPUT_ESTOP_CLOSED, 100_000_000) {
        KeyEvent::Reset(r) => r,
        other => panic!("the key gave no reset: {other:?}"),
    }
}

fn cfg() -> &'static MonitorConfig {
    static C: OnceLock<MonitorConfig> = OnceLock::new();
    C.get_or_init(|| {
        let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/safety-monitor.toml");
        config::load(&p).unwrap()
    })
}

fn mc() -> &'static cdpr_model::Model {
    static M: OnceLock<cdpr_model::Model> = OnceLock::new();
    M.get_or_init(|| {
        cdpr_model::config::load_platform(&cfg().platform_file)
            .unwrap()
            .model
    })
}

/// A monitor for the checks: started ready (the start-up state has its own tests below).
fn monitor_with(f: impl FnOnce(&mut Limits)) -> Monitor {
    let c = cfg();
    let mut lim = Limits::from(c);
    lim.require_ready = false;
    f(&mut lim);
    let mut m = Monitor::new(
        lim,
        StandardKinematics::new(&c.platform),
        platform_identity(&c.platform),
    );
    m.on_identity(&PlatformIdentity::new(platform_identity(&c.platform), 8));
    m
}

fn monitor() -> Monitor {
    monitor_with(|_| {})
}

const HOME: [f64; 6] = [0.0, 0.0, 2.0, 0.0, 0.0, 0.0];

/// A consistent setpoint (motion-core's φ(x)) with `offset` (m) added to cable `cable`.
fn sp(seq: u64, pose: [f64; 6], cable: usize, offset: f64) -> JointSetpoint {
    let model = mc();
    let mut data = cdpr_model::Data::new(model);
    let mut q = vec![0.0; 8];
    cdpr_model::kinematics::lengths(
        model,
        &mut data,
        &cdpr_model::Pose::from_array(pose),
        &mut q,
    )
    .unwrap();
    let mut s = JointSetpoint {
        cable_count: 8,
        sequence: seq,
        timestamp_ns: seq * 1_000_000,
        pose,
        ..JointSetpoint::default()
    };
    s.cable_length_m[..8].copy_from_slice(&q);
    s.cable_length_m[cable] += offset;
    s
}

/// One 15 ms cycle of 15 consistent setpoints starting at `seq`; returns the next sequence.
fn good_cycle(m: &mut Monitor, seq: u64, now: u64) -> u64 {
    for k in 0..15 {
        m.on_setpoint(&sp(seq + k, HOME, 0, 0.0));
    }
    m.end_cycle(now);
    seq + 15
}

#[test]
fn offset_101_mm_trips_99_mm_does_not_on_every_cable() {
    for cable in 0..8 {
        for sign in [1.0, -1.0] {
            let mut m = monitor();
            m.on_setpoint(&sp(1, HOME, cable, sign * 0.099));
            let r = m.end_cycle(1);
            assert_eq!(r.state, StateCode::Armed, "99 mm on cable {cable}");
            assert!(r.faults.is_empty());
            m.on_setpoint(&sp(2, HOME, cable, sign * 0.101));
            let r = m.end_cycle(2);
            let t = r.new_trip.expect("101 mm must trip");
            assert_eq!(t.fault.cause, Cause::DqLimit);
            assert_eq!(t.fault.cable, Some(cable as u8));
            assert_eq!(t.fault.sequence, 2);
            // Δq = φ* − q_θ = −offset.
            assert!(
                (t.fault.value + sign * 0.101).abs() < 1e-9,
                "{}",
                t.fault.value
            );
            assert_eq!(t.fault.limit, 0.1);
            assert_eq!(m.state_code(), StateCode::Tripped);
        }
    }
}

#[test]
fn every_setpoint_since_the_last_cycle_is_checked() {
    let mut m = monitor();
    let seq = good_cycle(&mut m, 1, 15);
    // One bad setpoint in the middle of a cycle, followed by good ones: still a trip.
    for k in 0..15 {
        let off = if k == 7 { 0.2 } else { 0.0 };
        m.on_setpoint(&sp(seq + k, HOME, 3, off));
    }
    let t = m.end_cycle(30).new_trip.expect("trip");
    assert_eq!(t.fault.sequence, seq + 7);
    assert_eq!(t.fault.cable, Some(3));
}

#[test]
fn non_finite_inputs_trip() {
    for (what, f) in [
        (
            "nan pose",
            Box::new(|s: &mut JointSetpoint| s.pose[4] = f64::NAN)
                as Box<dyn Fn(&mut JointSetpoint)>,
        ),
        (
            "inf pose",
            Box::new(|s: &mut JointSetpoint| s.pose[0] = f64::INFINITY),
        ),
        (
            "nan length",
            Box::new(|s: &mut JointSetpoint| s.cable_length_m[5] = f64::NAN),
        ),
        (
            "-inf length",
            Box::new(|s: &mut JointSetpoint| s.cable_length_m[0] = f64::NEG_INFINITY),
        ),
    ] {
        let mut m = monitor();
        let mut s = sp(1, HOME, 0, 0.0);
        f(&mut s);
        m.on_setpoint(&s);
        let t = m
            .end_cycle(1)
            .new_trip
            .unwrap_or_else(|| panic!("{what} must trip"));
        assert_eq!(t.fault.cause, Cause::NonFinite, "{what}");
    }
}

#[test]
fn pose_outside_the_workspace_box_trips() {
    // [workspace] of icosahedron.toml: x in [-1.5, 1.5], rot_x in [-4°, 4°].
    let mut m = monitor();
    m.on_setpoint(&sp(1, [1.49, 0.0, 2.0, 0.0, 0.0, 0.0], 0, 0.0));
    assert!(m.end_cycle(1).faults.is_empty());
    m.on_setpoint(&sp(2, [1.51, 0.0, 2.0, 0.0, 0.0, 0.0], 0, 0.0));
    assert_eq!(
        m.end_cycle(2).new_trip.unwrap().fault.cause,
        Cause::OutsideWorkspace
    );
    let mut m = monitor();
    m.on_setpoint(&sp(
        1,
        [0.0, 0.0, 2.0, 4.1f64.to_radians(), 0.0, 0.0],
        0,
        0.0,
    ));
    assert_eq!(
        m.end_cycle(1).new_trip.unwrap().fault.cause,
        Cause::OutsideWorkspace
    );
}

#[test]
fn sequence_gaps_are_counted_over_the_window() {
    // Default: more than 5 lost within 67 cycles trips.
    let mut m = monitor();
    let mut seq = 1;
    for _ in 0..5 {
        // One lost setpoint per cycle.
        seq = good_cycle(&mut m, seq, 0) + 1;
    }
    assert_eq!(m.state_code(), StateCode::Armed, "5 lost: tolerated");
    good_cycle(&mut m, seq, 0);
    assert_eq!(m.state_code(), StateCode::Armed);
    let r = {
        m.on_setpoint(&sp(seq + 15 + 1, HOME, 0, 0.0));
        m.end_cycle(0)
    };
    let t = r.new_trip.expect("the 6th lost setpoint trips");
    assert_eq!(t.fault.cause, Cause::SequenceGaps);
    assert_eq!(t.fault.value, 6.0);

    // The same losses spread wider than the window never trip.
    let mut m = monitor();
    let mut seq = 1;
    for _ in 0..10 {
        seq = good_cycle(&mut m, seq, 0) + 1;
        for _ in 0..20 {
            seq = good_cycle(&mut m, seq, 0);
        }
    }
    assert_eq!(m.state_code(), StateCode::Armed);
}

#[test]
fn a_sequence_that_does_not_increase_trips() {
    let mut m = monitor();
    m.on_setpoint(&sp(10, HOME, 0, 0.0));
    m.on_setpoint(&sp(10, HOME, 0, 0.0));
    assert_eq!(
        m.end_cycle(0).new_trip.unwrap().fault.cause,
        Cause::SequenceRegression
    );
}

#[test]
fn silence_for_n_cycles_trips_only_after_the_first_setpoint() {
    let mut m = monitor();
    for _ in 0..100 {
        assert!(
            m.end_cycle(0).faults.is_empty(),
            "no setpoint yet: not armed"
        );
    }
    good_cycle(&mut m, 1, 0);
    // silence_cycles = 2: the first empty cycle is tolerated, the second trips.
    assert!(m.end_cycle(0).new_trip.is_none());
    let t = m.end_cycle(0).new_trip.expect("2 silent cycles trip");
    assert_eq!(t.fault.cause, Cause::SetpointSilence);
}

#[test]
fn an_announced_end_of_stream_disarms_silence_and_a_new_stream_rearms() {
    let mut m = monitor();
    // The producer's plan ends at its setpoint 10; the stream holds at HOME.
    m.on_plan_announced(10);
    let seq = good_cycle(&mut m, 1, 0);
    m.on_setpoint(&sp(seq, HOME, 0, 0.0));
    m.on_stream_end();
    assert!(m.end_cycle(0).faults.is_empty());
    for _ in 0..100 {
        let f = m.end_cycle(0).faults;
        assert!(f.is_empty(), "a clean end is not a frozen loop: {f:?}");
    }
    // A restarted producer numbers from 1 again: not a regression. It must announce its
    // identity again (the grace applies), and silence is armed again.
    let c = cfg();
    let mut seq = good_cycle(&mut m, 1, 0);
    m.on_identity(&PlatformIdentity::new(platform_identity(&c.platform), 8));
    seq = good_cycle(&mut m, seq, 0);
    assert_eq!(m.state_code(), StateCode::Armed);
    let _ = seq;
    m.end_cycle(0);
    assert_eq!(
        m.end_cycle(0).new_trip.map(|t| t.fault.cause),
        Some(Cause::SetpointSilence)
    );
}

#[test]
fn identity_mismatch_and_missing_identity_trip() {
    let c = cfg();
    let mut lim = Limits::from(c);
    lim.require_ready = false;
    let own = platform_identity(&c.platform);
    let mut m = Monitor::new(lim, StandardKinematics::new(&c.platform), own);
    let mut other = *own.as_bytes();
    other[0] ^= 1;
    m.on_identity(&PlatformIdentity::new(PlatformId::new(other), 8));
    assert_eq!(
        m.end_cycle(0).new_trip.unwrap().fault.cause,
        Cause::IdentityMismatch
    );
    // Right hash, wrong cable count.
    let mut m = Monitor::new(lim, StandardKinematics::new(&c.platform), own);
    m.on_identity(&PlatformIdentity::new(own, 7));
    assert_eq!(
        m.end_cycle(0).new_trip.unwrap().fault.cause,
        Cause::IdentityMismatch
    );
    // No identity at all: setpoints are tolerated for identity_grace_cycles (10) cycles.
    let mut m = Monitor::new(lim, StandardKinematics::new(&c.platform), own);
    let mut seq = 1;
    for _ in 0..10 {
        seq = good_cycle(&mut m, seq, 0);
        assert_eq!(m.state_code(), StateCode::Armed);
    }
    good_cycle(&mut m, seq, 0);
    assert_eq!(m.trip().unwrap().fault.cause, Cause::IdentityMissing);
}

#[test]
fn motion_needs_a_verified_identity_holding_does_not() {
    let c = cfg();
    let own = platform_identity(&c.platform);
    let mut lim = Limits::from(c);
    lim.require_ready = false;
    let mut m = Monitor::new(lim, StandardKinematics::new(&c.platform), own);
    // Holding setpoints without an identity: within the grace, no trip.
    let seq = good_cycle(&mut m, 1, 15_000_000);
    assert_eq!(m.state_code(), StateCode::Armed);
    // The first setpoint that moves (5 µm in x: 5 mm/s out of the hold, well within the
    // acceleration limit) trips in this very cycle, not after the grace.
    let mut moved = HOME;
    moved[0] += 5e-6;
    m.on_setpoint(&sp(seq, moved, 0, 0.0));
    let t = m.end_cycle(30_000_000).new_trip.expect("trip");
    assert_eq!(t.fault.cause, Cause::IdentityMissing);
    assert_eq!(t.fault.sequence, seq);
    // With the identity announced before the motion the same motion passes.
    let mut m = Monitor::new(lim, StandardKinematics::new(&c.platform), own);
    let seq = good_cycle(&mut m, 1, 15_000_000);
    m.on_identity(&PlatformIdentity::new(own, 8));
    m.on_setpoint(&sp(seq, moved, 0, 0.0));
    assert!(m.end_cycle(30_000_000).new_trip.is_none());
    // The identity and the setpoints are two topics: an identity announced before the first
    // moving setpoint may be read after it in the same cycle (the daemon drains identities
    // after the setpoints). Judged at the end of the cycle, the motion passes...
    let mut m = Monitor::new(lim, StandardKinematics::new(&c.platform), own);
    let seq = good_cycle(&mut m, 1, 15_000_000);
    m.on_setpoint(&sp(seq, moved, 0, 0.0));
    m.on_identity(&PlatformIdentity::new(own, 8));
    assert!(m.end_cycle(30_000_000).new_trip.is_none());
    // ...but not into the next cycle: an identity that comes a cycle late does not excuse it.
    let mut m = Monitor::new(lim, StandardKinematics::new(&c.platform), own);
    let seq = good_cycle(&mut m, 1, 15_000_000);
    m.on_setpoint(&sp(seq, moved, 0, 0.0));
    let t = m.end_cycle(30_000_000).new_trip.expect("trip");
    assert_eq!(t.fault.cause, Cause::IdentityMissing);
    m.on_identity(&PlatformIdentity::new(own, 8));
    assert_eq!(m.trip().unwrap().fault.cause, Cause::IdentityMissing);
    // A wrong identity read after the motion: mismatch and missing both trip.
    let mut other = *own.as_bytes();
    other[3] ^= 1;
    let mut m = Monitor::new(lim, StandardKinematics::new(&c.platform), own);
    let seq = good_cycle(&mut m, 1, 15_000_000);
    m.on_setpoint(&sp(seq, moved, 0, 0.0));
    m.on_identity(&PlatformIdentity::new(PlatformId::new(other), 8));
    let t = m.end_cycle(30_000_000).new_trip.expect("trip");
    assert!(
        matches!(
            t.fault.cause,
            Cause::IdentityMissing | Cause::IdentityMismatch
        ),
        "{:?}",
        t.fault.cause
    );
}

/// A fresh drive-io sample (its SYNC cycle and timestamp advance with every call, as drive-io's
/// do: a sample that does not advance is stale).
fn feedback(applied: u64, lengths: &[f64]) -> DriveFeedback {
    static CYCLE: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    let cycle = CYCLE.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut f = DriveFeedback {
        cable_count: 8,
        cycle,
        timestamp_ns: cycle * 1_000_000,
        applied_setpoint_sequence: applied,
        bus_state: BusState::Running as u32,
        ..DriveFeedback::default()
    };
    f.cable_length_m[..8].copy_from_slice(lengths);
    f
}

#[test]
fn following_error_and_feedback_silence_trip() {
    let mut m = monitor();
    good_cycle(&mut m, 1, 0);
    let q = sp(10, HOME, 0, 0.0).cable_length_m;
    let mut meas = q[..8].to_vec();
    meas[6] += 0.099;
    m.on_feedback(&feedback(10, &meas));
    m.on_setpoint(&sp(16, HOME, 0, 0.0));
    assert!(m.end_cycle(0).faults.is_empty());
    meas[6] += 0.002;
    m.on_feedback(&feedback(10, &meas));
    m.on_setpoint(&sp(17, HOME, 0, 0.0));
    let t = m.end_cycle(0).new_trip.expect("following error");
    assert_eq!(t.fault.cause, Cause::FollowingError);
    assert_eq!(t.fault.cable, Some(6));
    // Not judged while drive-io is not Running and applies nothing new (e.g. quick-stopping
    // after applying setpoint 10)...
    let mut m = monitor();
    good_cycle(&mut m, 1, 0);
    m.on_feedback(&feedback(10, &q[..8]));
    let mut fb = feedback(10, &meas);
    fb.bus_state = BusState::EStop as u32;
    m.on_feedback(&fb);
    m.on_setpoint(&sp(16, HOME, 0, 0.0));
    assert!(m.end_cycle(0).faults.is_empty());
    // ... but judged whenever the applied setpoint advances, whatever state drive-io claims
    // (a drive adapter that applies setpoints while reporting Ready is checked too).
    let mut m2 = monitor();
    good_cycle(&mut m2, 1, 0);
    let mut fb = feedback(12, &meas);
    fb.bus_state = BusState::Ready as u32;
    m2.on_feedback(&fb);
    m2.on_setpoint(&sp(16, HOME, 0, 0.0));
    let t = m2
        .end_cycle(0)
        .new_trip
        .expect("applied while claiming Ready");
    assert_eq!(t.fault.cause, Cause::FollowingError);
    // drive-io silent for silence_cycles (4) after its first feedback.
    let mut seq = 17;
    for k in 0..4 {
        seq = good_cycle(&mut m, seq, 0);
        assert_eq!(m.state_code() == StateCode::Tripped, k == 3, "cycle {k}");
    }
    assert_eq!(m.trip().unwrap().fault.cause, Cause::FeedbackSilence);
}

#[test]
fn rpdo_targets_far_from_the_kinematics_trip() {
    let mut m = monitor();
    for k in 1..=15 {
        m.on_setpoint(&sp(k, HOME, 0, 0.0));
    }
    m.end_cycle(0);
    let q = sp(1, HOME, 0, 0.0).cable_length_m;
    // What drive-io forwards: one of the recent setpoints (rounded to counts).
    m.on_rpdo(2, q[2] + 1e-7, 15_000_000);
    m.on_rpdo(2, q[2] + 0.0995, 15_000_000);
    m.on_setpoint(&sp(16, HOME, 0, 0.0));
    assert!(m.end_cycle(0).faults.is_empty());
    m.on_rpdo(4, q[4] - 0.15, 15_000_000);
    m.on_setpoint(&sp(17, HOME, 0, 0.0));
    let t = m.end_cycle(0).new_trip.expect("rpdo");
    assert_eq!(t.fault.cause, Cause::RpdoMismatch);
    assert_eq!(t.fault.cable, Some(4));
    assert!((t.fault.value - 0.15).abs() < 1e-9);
}

#[test]
fn reset_is_refused_while_the_cause_persists_and_accepted_after() {
    let mut m = monitor();
    assert_eq!(m.request_reset(key_reset()), ResetDecision::NotTripped);
    let mut seq = good_cycle(&mut m, 1, 0);
    let mut s = sp(seq, HOME, 0, 0.0);
    s.pose[2] = f64::NAN;
    m.on_setpoint(&s);
    seq += 1;
    assert!(m.end_cycle(0).new_trip.is_some());
    // The NaN poses keep coming: refused, naming the cause.
    for _ in 0..5 {
        let mut s = sp(seq, HOME, 0, 0.0);
        s.pose[2] = f64::NAN;
        m.on_setpoint(&s);
        seq += 1;
        let r = m.end_cycle(0);
        assert!(r.new_trip.is_none(), "latched: no second trip");
        assert_eq!(
            m.request_reset(key_reset()),
            ResetDecision::Refused(Cause::NonFinite)
        );
    }
    // Good again, but fewer than reset_clear_cycles (3) clean cycles: still refused.
    for _ in 0..2 {
        seq = good_cycle(&mut m, seq, 0);
        assert!(matches!(
            m.request_reset(key_reset()),
            ResetDecision::Refused(_)
        ));
    }
    seq = good_cycle(&mut m, seq, 0);
    let e0 = m.reset_epoch();
    assert_eq!(m.heartbeat(1).epoch, e0);
    assert_eq!(
        m.request_reset(key_reset()),
        ResetDecision::Accepted { epoch: e0 + 1 }
    );
    assert_eq!(m.reset_epoch(), e0 + 1);
    assert_eq!(m.heartbeat(2).epoch, e0 + 1);
    assert_eq!(m.state_code(), StateCode::Armed);
    assert!(m.trip().is_none());
    // Leaving the latch drops its record with it (the log keeps it).
    assert_eq!(*m.state(), MonitorState::Armed);
    good_cycle(&mut m, seq, 0);
    assert_eq!(m.state_code(), StateCode::Armed);
    assert_eq!(m.trip_log().total(), 1);
    let rec = m.trip_log().last().unwrap();
    assert_eq!(rec.fault.cause, Cause::NonFinite);
    assert!(rec.to_string().contains("cause=non_finite"), "{rec}");
}

#[test]
fn the_latch_holds_the_first_cause_and_logs_every_trip() {
    let mut m = monitor();
    m.on_setpoint(&sp(1, HOME, 5, 0.3));
    m.end_cycle(7);
    m.on_setpoint(&sp(2, HOME, 1, f64::NAN));
    let r = m.end_cycle(8);
    assert!(r.faults.contains(Cause::NonFinite));
    let t = m.trip().unwrap();
    assert_eq!(
        (t.fault.cause, t.fault.cable, t.detected_ns),
        (Cause::DqLimit, Some(5), 7)
    );
    // The record lives in the state: the tripped state carries the same record.
    match m.state() {
        MonitorState::Tripped(rec) => assert_eq!(rec, t),
        other => panic!("not tripped: {other:?}"),
    }
    assert_eq!(m.state().state_code(), StateCode::Tripped);
    assert_eq!(m.state().code(), u32::from(crs_ipc::MonitorState::Tripped));
    let hb = m.heartbeat(3);
    assert_eq!(hb.state, can_transport::safety_frame::SafetyState::Stop);
    assert_eq!(hb.cause, Cause::DqLimit.code());
    // Per-cause latches: both causes stay latched.
    assert!(m.latched().contains(Cause::DqLimit));
    assert!(m.latched().contains(Cause::NonFinite));
}

/// A reset request while armed (or not ready) changes nothing, not even the epoch;
/// refused requests do not advance it; only an accepted one does, by exactly one.
#[test]
fn only_an_accepted_reset_advances_the_epoch() {
    let mut m = monitor().with_reset_epoch(41);
    let mut seq = good_cycle(&mut m, 1, 0);
    for _ in 0..5 {
        assert_eq!(m.request_reset(key_reset()), ResetDecision::NotTripped);
    }
    assert_eq!(m.reset_epoch(), 41);
    assert_eq!(m.heartbeat(0).epoch, 41);
    let mut s = sp(seq, HOME, 0, 0.0);
    s.pose[0] = f64::NAN;
    m.on_setpoint(&s);
    seq += 1;
    m.end_cycle(0);
    for _ in 0..3 {
        assert!(matches!(
            m.request_reset(key_reset()),
            ResetDecision::Refused(_)
        ));
    }
    assert_eq!(m.reset_epoch(), 41);
    for _ in 0..3 {
        seq = good_cycle(&mut m, seq, 0);
    }
    assert_eq!(
        m.request_reset(key_reset()),
        ResetDecision::Accepted { epoch: 42 }
    );
    assert_eq!(m.request_reset(key_reset()), ResetDecision::NotTripped);
    assert_eq!(m.reset_epoch(), 42);
    // Not ready: nothing either.
    let c = cfg();
    let mut n = Monitor::new(
        Limits::from(c),
        StandardKinematics::new(&c.platform),
        platform_identity(&c.platform),
    )
    .with_reset_epoch(7);
    assert_eq!(n.request_reset(key_reset()), ResetDecision::NotReady);
    assert_eq!(n.reset_epoch(), 7);
}

/// Clean cycles are not enough for a cause that cannot recur while stopped: a
/// following-error latch needs drive-io's feedback following the held setpoint, a feedback
/// silence needs feedback back; a force latch needs every drive reporting.
#[test]
fn a_latched_cause_must_be_positively_shown_cleared() {
    let mut m = monitor();
    let mut seq = good_cycle(&mut m, 1, 0);
    let q = sp(10, HOME, 0, 0.0).cable_length_m;
    let mut meas = q[..8].to_vec();
    meas[3] += 0.15;
    m.on_feedback(&feedback(10, &meas));
    m.on_setpoint(&sp(seq, HOME, 0, 0.0));
    seq += 1;
    assert_eq!(
        m.end_cycle(0).new_trip.map(|t| t.fault.cause),
        Some(Cause::FollowingError)
    );
    // drive-io silent after the trip (it is e-stopped, its lengths unknown): clean cycles for
    // the setpoint checks, but no evidence for the following error. (feedback_silence latches
    // too after its count.)
    for _ in 0..10 {
        seq = good_cycle(&mut m, seq, 0);
        assert!(matches!(
            m.request_reset(key_reset()),
            ResetDecision::Refused(_)
        ));
    }
    assert!(m.latched().contains(Cause::FeedbackSilence));
    // Feedback back, but its lengths do not follow the held setpoint: still refused.
    for _ in 0..5 {
        let mut fb = feedback(seq - 1, &meas);
        fb.bus_state = BusState::EStop as u32;
        m.on_feedback(&fb);
        seq = good_cycle(&mut m, seq, 0);
        assert_eq!(
            m.request_reset(key_reset()),
            ResetDecision::Refused(Cause::FollowingError)
        );
    }
    // Feedback following the held setpoint for reset_clear_cycles (3) cycles: accepted.
    for k in 0..3 {
        let mut fb = feedback(seq - 1, &q[..8]);
        fb.bus_state = BusState::EStop as u32;
        m.on_feedback(&fb);
        seq = good_cycle(&mut m, seq, 0);
        if k < 2 {
            assert!(matches!(
                m.request_reset(key_reset()),
                ResetDecision::Refused(_)
            ));
        }
    }
    assert!(matches!(
        m.request_reset(key_reset()),
        ResetDecision::Accepted { .. }
    ));

    // A force latch: drives that stopped reporting give no evidence.
    let mut m = monitor();
    let (mut seq, _) = force_cycle(&mut m, 1, 0, 0, 4000.0);
    let (s2, r) = force_cycle(&mut m, seq, 15 * MS, 2, 20_000.0);
    seq = s2;
    assert_eq!(
        r.new_trip.map(|t| t.fault.cause),
        Some(Cause::ForceOverload)
    );
    let mut t = 30 * MS;
    // NMT-stopped drives, but cable 8's drive stopped reporting (its last word: operational,
    // so its force silence latches too): refused for 100 clean-looking cycles.
    for _ in 0..100 {
        for i in 0..7 {
            m.on_drive_report(i, false, t);
        }
        seq = good_cycle(&mut m, seq, t);
        t += 15 * MS;
        assert!(matches!(
            m.request_reset(key_reset()),
            ResetDecision::Refused(_)
        ));
    }
    assert!(m.latched().contains(Cause::ForceOverload));
    assert!(m.latched().contains(Cause::ForceSilence));
    for _ in 0..3 {
        for i in 0..8 {
            m.on_drive_report(i, false, t);
        }
        seq = good_cycle(&mut m, seq, t);
        t += 15 * MS;
    }
    assert!(matches!(
        m.request_reset(key_reset()),
        ResetDecision::Accepted { .. }
    ));
}

#[test]
fn the_limit_is_configurable_but_never_above_100_mm() {
    let dir = std::env::temp_dir().join(format!("sm-cfg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let base = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/safety-monitor.toml"),
    )
    .unwrap();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config");
    let write = |name: &str, text: String| {
        let text = text
            .replace(
                "platform = \"icosahedron.toml\"",
                &format!("platform = {:?}", root.join("icosahedron.toml")),
            )
            .replace(
                "drives = \"drives.toml\"",
                &format!("drives = {:?}", root.join("drives.toml")),
            );
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let p = write(
        "a.toml",
        base.replace("dq_limit_mm = 100.0", "dq_limit_mm = 100.5"),
    );
    let e = config::load(&p).unwrap_err().to_string();
    assert!(
        e.contains("monitor.dq_limit_mm") && e.contains("100 mm"),
        "{e}"
    );
    let p = write(
        "b.toml",
        base.replace("dq_limit_mm = 100.0", "dq_limit_mm = 50.0"),
    );
    let c = config::load(&p).unwrap();
    assert_eq!(c.dq_limit_m(), 0.05);
    let mut m = Monitor::new(
        Limits::from(&c),
        StandardKinematics::new(&c.platform),
        platform_identity(&c.platform),
    );
    m.on_setpoint(&sp(1, HOME, 0, 0.051));
    assert_eq!(m.end_cycle(0).new_trip.unwrap().fault.cause, Cause::DqLimit);
    let p = write(
        "c.toml",
        base.replace("cycle_ms = 15", "cycle_ms = 15\nbogus = 1"),
    );
    let e = config::load(&p).unwrap_err().to_string();
    assert!(e.contains("bogus") && e.contains(":"), "{e}");
    let p = write(
        "d.toml",
        base.replace("safety_cob_id = 0x101", "safety_cob_id = 0x100"),
    );
    assert!(
        config::load(&p)
            .unwrap_err()
            .to_string()
            .contains("can.safety_cob_id")
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn platform_errors_name_the_key_and_line() {
    let text = std::fs::read_to_string(&cfg().platform_file).unwrap();
    let bad = text.replace("[-5.380,  7.677,  6.524]", "[-5.380,  7.677,  nan]");
    let e = safety_monitor::platform::parse_platform(&bad, "x.toml").unwrap_err();
    // The element itself: row 0, component 2, at its line and column in the file (line 13 of
    // config/icosahedron.toml; the key was once the flattened index `[2]`, which read as row 2).
    assert_eq!(e.key, "geometry.frame_anchors_m[0][2]");
    assert_eq!((e.line, e.column), (Some(13), Some(21)), "{e}");
    assert!(e.to_string().starts_with("x.toml:13:21: "), "{e}");
    let bad = text.replace(
        "platform_anchors_m = [\n  [-1.383,  0.528, -0.747],\n",
        "platform_anchors_m = [\n",
    );
    let e = safety_monitor::platform::parse_platform(&bad, "x.toml").unwrap_err();
    assert_eq!(e.key, "geometry.platform_anchors_m");
    assert!(e.to_string().contains("x.toml:"), "{e}");
}

fn arb_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        any::<f64>(),
        Just(f64::NAN),
        Just(f64::INFINITY),
        -3.0f64..3.0,
        0.0f64..20.0
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Any offset strictly below the limit never trips; any above always trips, naming the cable.
    #[test]
    fn threshold_holds_over_the_workspace(
        x in -1.4f64..1.4, y in -1.4f64..1.4, z in 1.3f64..2.7,
        ax in -0.06f64..0.06, ay in -0.08f64..0.08, az in -0.08f64..0.08,
        cable in 0usize..8, below in -0.0999f64..0.0999, above in 0.1001f64..2.0, neg in any::<bool>(),
    ) {
        let pose = [x, y, z, ax, ay, az];
        let mut m = monitor();
        m.on_setpoint(&sp(1, pose, cable, below));
        prop_assert!(m.end_cycle(0).faults.is_empty());
        m.on_setpoint(&sp(2, pose, cable, if neg { -above } else { above }));
        let t = m.end_cycle(0).new_trip;
        prop_assert!(t.is_some());
        let t = t.unwrap();
        prop_assert_eq!(t.fault.cause, Cause::DqLimit);
        prop_assert_eq!(t.fault.cable, Some(cable as u8));
    }

    /// No panic on any payload, in any order; a trip always names a cause.
    #[test]
    fn no_panic_on_any_payload(
        inputs in proptest::collection::vec(
            (0u8..5, any::<u64>(), any::<u32>(), proptest::collection::vec(arb_f64(), 6 + MAX_CABLES), any::<u32>(), any::<[u8; 32]>()),
            1..40)
    ) {
        let mut m = monitor();
        for (kind, seq, count, vals, state, hash) in inputs {
            match kind {
                0 => {
                    let mut s = JointSetpoint { cable_count: count % 20, sequence: seq, ..JointSetpoint::default() };
                    s.pose.copy_from_slice(&vals[..6]);
                    s.cable_length_m.copy_from_slice(&vals[6..]);
                    m.on_setpoint(&s);
                }
                1 => {
                    let mut f = DriveFeedback { cable_count: count % 20, applied_setpoint_sequence: seq, bus_state: state % 8, ..DriveFeedback::default() };
                    f.cable_length_m.copy_from_slice(&vals[6..]);
                    m.on_feedback(&f);
                }
                2 => m.on_identity(&PlatformIdentity { version: state % 3, cable_count: count, timestamp_ns: seq, hash: PlatformId::new(hash) }),
                3 => m.on_rpdo(count as usize % 20, vals[0], seq),
                _ => {
                    let r = m.end_cycle(seq);
                    if let Some(t) = r.new_trip {
                        prop_assert!(r.faults.contains(t.fault.cause));
                    }
                    let _ = m.request_reset(key_reset());
                }
            }
        }
        m.end_cycle(0);
    }
}

#[test]
fn history_is_large_enough_for_the_feedback_window() {
    assert!(cfg().feedback.window_setpoints as usize <= HISTORY);
}

// ---- measured-force supervision (seed §5.1, table 5.1) ----------------------------------

const MS: u64 = 1_000_000;

/// One 15 ms cycle starting at `t0` with every drive operational and a force reading per ms,
/// cable `cable` reading `f_n`, the others 4 kN.
fn force_cycle(
    m: &mut Monitor,
    seq: u64,
    t0: u64,
    cable: usize,
    f_n: f64,
) -> (u64, safety_monitor::monitor::CycleReport) {
    for k in 0..15 {
        m.on_setpoint(&sp(seq + k, HOME, 0, 0.0));
        for i in 0..8 {
            m.on_drive_state(i, true);
            m.on_force(i, if i == cable { f_n } else { 4000.0 }, t0 + k * MS);
        }
    }
    (seq + 15, m.end_cycle(t0 + 15 * MS))
}

#[test]
fn slack_and_overload_trip_after_k_of_n_readings_with_the_cable_and_force() {
    let c = cfg();
    let fl = Limits::from(c).forces;
    assert!(fl.check, "the shipped configuration supervises forces");
    assert_eq!(
        fl.slack_below_n,
        c.platform.f_min_n - c.forces.slack_margin_n
    );
    for (f_bad, cause, limit) in [
        (fl.slack_below_n - 1.0, Cause::ForceSlack, fl.slack_below_n),
        (0.0, Cause::ForceSlack, fl.slack_below_n),
        (
            fl.overload_above_n + 1.0,
            Cause::ForceOverload,
            fl.overload_above_n,
        ),
    ] {
        for cable in [0, 5, 7] {
            let mut m = monitor();
            let (mut seq, mut t) = (1, 0);
            let mut tripped_at = None;
            for cyc in 0..10u64 {
                let r;
                (seq, r) = force_cycle(&mut m, seq, t, cable, f_bad);
                t += 15 * MS;
                if let Some(tr) = r.new_trip {
                    tripped_at = Some((cyc, tr));
                    break;
                }
            }
            let (cyc, tr) =
                tripped_at.unwrap_or_else(|| panic!("{f_bad} N on cable {cable} never tripped"));
            assert_eq!(tr.fault.cause, cause);
            assert_eq!(tr.fault.cable, Some(cable as u8));
            assert_eq!(tr.fault.value, f_bad);
            assert_eq!(tr.fault.limit, limit);
            // k of n at one reading per ms (15 per cycle): the cycle of the k-th reading.
            assert_eq!(
                cyc,
                u64::from(fl.window_violations - 1) / 15,
                "tripped in cycle {cyc}"
            );
        }
    }
}

/// One in-range reading does not restart anything (issue: a cable alternating 200 N and
/// 3 kN at 20 Hz was never caught by a filter that every in-range reading restarted): a
/// fluttering force trips once k of the last n readings are out of range, k - 1 do not.
#[test]
fn a_fluttering_force_trips_k_minus_one_violations_do_not() {
    let fl = Limits::from(cfg()).forces;
    assert!(fl.window_violations * 2 <= fl.window_readings, "{fl:?}");
    // 200 N <-> 3 kN at 20 Hz with one reading per 5 ms (the shipped load cells): 5 low, 5
    // high, ...
    let mut m = monitor();
    let (mut seq, _) = force_cycle(&mut m, 1, 0, 0, 4000.0);
    let mut t = 15 * MS;
    let mut reading = 0u64;
    let mut trip = None;
    for cyc in 0..40u64 {
        for k in 0..15 {
            m.on_setpoint(&sp(seq + k, HOME, 0, 0.0));
            for i in 0..8 {
                m.on_drive_state(i, true);
            }
            if k % 5 == 0 {
                let f = if (reading / 5).is_multiple_of(2) {
                    200.0
                } else {
                    3000.0
                };
                reading += 1;
                for i in 0..8 {
                    m.on_force(i, if i == 5 { f } else { 4000.0 }, t + k * MS);
                }
            }
        }
        seq += 15;
        if let Some(tr) = m.end_cycle(t + 15 * MS).new_trip {
            trip = Some((cyc, tr));
            break;
        }
        t += 15 * MS;
    }
    let (_, tr) = trip.expect("a force fluttering between slack and in range must trip");
    assert_eq!(
        (tr.fault.cause, tr.fault.cable),
        (Cause::ForceSlack, Some(5))
    );
    // k - 1 violations spread over the window, in-range readings between them: no trip.
    let mut m = monitor();
    let (seq, _) = force_cycle(&mut m, 1, 0, 0, 4000.0);
    for k in 0..fl.window_readings {
        let bad = k % 2 == 1 && k >= fl.window_readings - 2 * (fl.window_violations - 1);
        m.on_force(3, if bad { 200.0 } else { 4000.0 }, 15 * MS + u64::from(k));
    }
    for i in (0..8).filter(|&i| i != 3) {
        m.on_force(i, 4000.0, 16 * MS);
    }
    m.on_setpoint(&sp(seq, HOME, 0, 0.0));
    assert!(m.end_cycle(30 * MS).new_trip.is_none());
    // One more violation within the window: trips.
    m.on_setpoint(&sp(seq + 1, HOME, 0, 0.0));
    for i in 0..8 {
        m.on_force(i, if i == 3 { 200.0 } else { 4000.0 }, 31 * MS);
    }
    let tr = m.end_cycle(45 * MS).new_trip.expect("k-th violation");
    assert_eq!(
        (tr.fault.cause, tr.fault.cable),
        (Cause::ForceSlack, Some(3))
    );
}

#[test]
fn forces_inside_the_limits_and_short_transients_do_not_trip() {
    let fl = Limits::from(cfg()).forces;
    let mut m = monitor();
    let (mut seq, mut t) = (1, 0);
    for cyc in 0..40u64 {
        // Every 5th cycle an excursion below the slack limit of k - 1 readings (one fewer than
        // the window trips on), and the limits themselves otherwise.
        let f = match cyc % 5 {
            0 => fl.slack_below_n,
            1 => fl.overload_above_n,
            _ => 4000.0,
        };
        let r;
        (seq, r) = force_cycle(&mut m, seq, t, 3, f);
        assert!(r.faults.is_empty(), "cycle {cyc}: {:?}", r.faults);
        if cyc % 5 == 0 {
            for k in 0..u64::from(fl.window_violations - 1) {
                m.on_force(2, fl.slack_below_n - 100.0, t + k * MS);
            }
        }
        for k in 0..u64::from(fl.window_readings) {
            m.on_force(2, 4000.0, t + 11 * MS + k);
        }
        t += 15 * MS;
    }
    assert_eq!(m.state_code(), StateCode::Armed);
    assert!(m.stats().forces_checked > 0);
}

#[test]
fn one_reading_beyond_the_hard_limit_of_either_sign_trips_at_once() {
    let fl = Limits::from(cfg()).forces;
    for f in [fl.hard_limit_n + 1.0, -fl.hard_limit_n - 1.0] {
        let mut m = monitor();
        let (seq, _) = force_cycle(&mut m, 1, 0, 2, 4000.0);
        m.on_force(2, f, 15 * MS + 1);
        let r = m.end_cycle(16 * MS);
        let tr = r.new_trip.expect("hard limit");
        assert_eq!(tr.fault.cause, Cause::ForceOverload, "{f} N");
        assert_eq!(tr.fault.limit, fl.hard_limit_n);
        assert_eq!(tr.fault.value, f);
        assert_eq!(tr.fault.cable, Some(2));
        let _ = seq;
    }
}

#[test]
fn a_silent_or_non_numeric_force_sensor_trips_fail_closed() {
    let fl = Limits::from(cfg()).forces;
    // Operational drive 4 stops sending force readings.
    let mut m = monitor();
    let (mut seq, _) = force_cycle(&mut m, 1, 0, 0, 4000.0);
    let mut trip = None;
    for cyc in 1..=fl.silence_cycles + 1 {
        for k in 0..15 {
            m.on_setpoint(&sp(seq + k, HOME, 0, 0.0));
            for i in (0..8).filter(|&i| i != 4) {
                m.on_force(i, 4000.0, u64::from(cyc) * 15 * MS + k * MS);
            }
        }
        seq += 15;
        if let Some(t) = m.end_cycle(u64::from(cyc + 1) * 15 * MS).new_trip {
            trip = Some((cyc, t));
            break;
        }
    }
    let (cyc, t) = trip.expect("silent force sensor must trip");
    assert_eq!(
        (t.fault.cause, t.fault.cable),
        (Cause::ForceSilence, Some(4))
    );
    assert_eq!(cyc, fl.silence_cycles);
    // NaN reading: cannot be evaluated => trips in the same cycle.
    let mut m = monitor();
    force_cycle(&mut m, 1, 0, 0, 4000.0);
    m.on_force(6, f64::NAN, 15 * MS + 1);
    let t = m.end_cycle(16 * MS).new_trip.expect("NaN force");
    assert_eq!(
        (t.fault.cause, t.fault.cable),
        (Cause::ForceSilence, Some(6))
    );
}

#[test]
fn not_operational_drives_are_force_supervised_only_once_the_monitor_was_ready() {
    // Before NMT start (pre-operational: no PDOs, cables may still be slack) the monitor is not
    // ready yet and only operational drives count.
    let mut m = monitor();
    for cyc in 0..10u64 {
        for k in 0..15 {
            m.on_setpoint(&sp(1 + cyc * 15 + k, HOME, 0, 0.0));
            m.on_force(1, 0.0, cyc * 15 * MS + k * MS);
        }
        assert!(m.end_cycle((cyc + 1) * 15 * MS).faults.is_empty());
    }
    // Operational: the same slack reading now trips.
    m.on_drive_state(1, true);
    let mut tripped = false;
    for cyc in 10..20u64 {
        for k in 0..15 {
            m.on_setpoint(&sp(1 + cyc * 15 + k, HOME, 0, 0.0));
            m.on_force(1, 0.0, cyc * 15 * MS + k * MS);
            for i in (0..8).filter(|&i| i != 1) {
                m.on_drive_state(i, true);
                m.on_force(i, 4000.0, cyc * 15 * MS + k * MS);
            }
        }
        tripped |= m.end_cycle((cyc + 1) * 15 * MS).new_trip.is_some();
    }
    assert!(tripped);
    assert_eq!(m.trip().unwrap().fault.cause, Cause::ForceSlack);

    // Once ready, a drive that leaves operational (stopped by anyone) keeps being supervised:
    // its load cell's slack reading trips, and so does its silence.
    for silent in [false, true] {
        let mut m = monitor();
        let (mut seq, _) = force_cycle(&mut m, 1, 0, 0, 4000.0);
        let mut t = 0;
        assert_eq!(m.state_code(), StateCode::Armed);
        m.on_drive_state(6, false);
        let mut trip = None;
        for _ in 0..10 {
            t += 15 * MS;
            for k in 0..15 {
                m.on_setpoint(&sp(seq + k, HOME, 0, 0.0));
                for i in 0..8 {
                    if i == 6 && silent {
                        continue;
                    }
                    m.on_force(i, if i == 6 { 0.0 } else { 4000.0 }, t + k * MS);
                }
            }
            seq += 15;
            if let Some(tr) = m.end_cycle(t + 15 * MS).new_trip {
                trip = Some(tr);
                break;
            }
        }
        let tr = trip.unwrap_or_else(|| panic!("not operational drive 7 (silent {silent})"));
        let want = if silent {
            Cause::ForceSilence
        } else {
            Cause::ForceSlack
        };
        assert_eq!((tr.fault.cause, tr.fault.cable), (want, Some(6)));
    }
}

#[test]
fn force_config_errors_name_the_key() {
    let dir = std::env::temp_dir().join(format!("sm-forces-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let base = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/safety-monitor.toml"),
    )
    .unwrap();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config");
    let base = base
        .replace(
            "platform = \"icosahedron.toml\"",
            &format!("platform = {:?}", root.join("icosahedron.toml")),
        )
        .replace(
            "drives = \"drives.toml\"",
            &format!("drives = {:?}", root.join("drives.toml")),
        );
    for (forces, key) in [
        ("[forces]\nhard_limit_n = 5000.0\n", "forces.hard_limit_n"),
        ("[forces]\nsilence_cycles = 0\n", "forces.silence_cycles"),
        (
            "[forces]\nwindow_violations = 0\n",
            "forces.window_violations",
        ),
        (
            "[forces]\nwindow_readings = 8\nwindow_violations = 9\n",
            "forces.window_violations",
        ),
        ("[forces]\nwindow_readings = 65\n", "forces.window_readings"),
        ("[forces]\nhard_limit_n = 25000.0\n", "forces.hard_limit_n"),
    ] {
        let p = dir.join("sm.toml");
        let text = if base.contains("[forces]") {
            let i = base.find("[forces]").unwrap();
            let j = base[i..]
                .find("\n[")
                .map(|j| i + j + 1)
                .unwrap_or(base.len());
            format!("{}{}\n{}", &base[..i], forces, &base[j..])
        } else {
            format!("{base}\n{forces}")
        };
        std::fs::write(&p, text).unwrap();
        let e = config::load(&p).unwrap_err().to_string();
        assert!(e.contains(key), "{forces}: {e}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

// ---- pose plausibility with the monitor's own clock -------------------------------------

/// Feeds `poses` as consecutive setpoints (consistent lengths), `per_cycle` per 15 ms monitor
/// cycle; returns the first trip.
fn run_poses(
    m: &mut Monitor,
    poses: &[[f64; 6]],
    per_cycle: usize,
) -> Option<safety_monitor::TripRecord> {
    let mut t = 0;
    for (k, chunk) in poses.chunks(per_cycle).enumerate() {
        for (j, p) in chunk.iter().enumerate() {
            m.on_setpoint(&sp((k * per_cycle + j + 1) as u64, *p, 0, 0.0));
        }
        t += 15 * MS;
        if let Some(tr) = m.end_cycle(t).new_trip {
            return Some(tr);
        }
    }
    None
}

/// A rest-to-rest move along x: constant acceleration `a` up to `v`, cruise, then hold.
fn ramp_path(v: f64, a: f64, n: usize) -> Vec<[f64; 6]> {
    let dt = 1e-3;
    let (mut x, mut vel) = (0.0, 0.0);
    let mut out = Vec::with_capacity(n + 1);
    // At rest first: the step out of it is acceleration-checked like any other.
    let mut rest = HOME;
    rest[0] = -0.5;
    out.push(rest);
    for _ in 0..n {
        vel = (vel + a * dt).min(v);
        x += vel * dt;
        let mut p = HOME;
        p[0] = x - 0.5;
        out.push(p);
    }
    out
}

#[test]
fn motion_within_the_limits_and_a_hold_do_not_trip() {
    let mc = Limits::from(cfg()).motion;
    assert!(mc.check);
    // 95 % of table 5.1 (5 m/s, 14 m/s²) before the margin, then an abrupt hold (same pose).
    let l = &cfg().platform.limits;
    let mut poses = ramp_path(
        0.95 * l.linear_velocity_m_per_s,
        0.95 * l.linear_acceleration_m_per_s2,
        300,
    );
    let last = *poses.last().unwrap();
    poses.extend(std::iter::repeat_n(last, 60));
    let mut m = monitor();
    assert_eq!(run_poses(&mut m, &poses, 15), None);
}

#[test]
fn a_consistent_pose_jump_inside_the_box_trips_motion_velocity() {
    // Lengths agree with the pose (Δq check passes) but the pose jumps 20 cm in one period.
    let mut poses = ramp_path(0.5, 2.0, 100);
    let mut jump = *poses.last().unwrap();
    jump[1] += 0.2;
    poses.push(jump);
    let mut m = monitor();
    let tr = run_poses(&mut m, &poses, 15).expect("a 200 m/s step must trip");
    assert_eq!(tr.fault.cause, Cause::MotionVelocity);
    assert_eq!(tr.fault.sequence, 102);
    assert!(tr.fault.value > 100.0 && tr.fault.limit < 10.0, "{tr}");
    // The same stream without the motion check passes the Δq check: this is what it adds.
    let mut m = monitor_with(|l| l.motion.check = false);
    assert_eq!(run_poses(&mut m, &poses, 15), None);
}

#[test]
fn an_acceleration_beyond_the_limit_trips() {
    let mc = Limits::from(cfg()).motion;
    // 1 m/s, then 2 m/s from one period to the next: 1000 m/s².
    let mut poses = ramp_path(1.0, 10.0, 150);
    let mut p = *poses.last().unwrap();
    for _ in 0..5 {
        p[0] += 0.002;
        poses.push(p);
    }
    let mut m = monitor();
    let tr = run_poses(&mut m, &poses, 15).expect("must trip");
    assert_eq!(tr.fault.cause, Cause::MotionAcceleration);
    assert_eq!(tr.fault.limit, mc.linear_acceleration);
    assert!((tr.fault.value - 1000.0).abs() < 1.0, "{tr}");
}

#[test]
fn rotation_faster_than_the_angular_limit_trips() {
    // 150 °/s about z (limit 100 °/s × 1.25) — steady, so no acceleration beyond the first step.
    let w = 150f64.to_radians();
    let poses: Vec<[f64; 6]> = (0..100)
        .map(|k| {
            let mut p = HOME;
            p[5] = w * 1e-3 * k as f64;
            p
        })
        .collect();
    let mut m = monitor_with(|l| l.motion.angular_acceleration = f64::INFINITY);
    let tr = run_poses(&mut m, &poses, 15).expect("must trip");
    assert_eq!(tr.fault.cause, Cause::MotionVelocity);
    assert!((tr.fault.value - w).abs() < 1e-6, "{tr}");
}

#[test]
fn a_producer_faster_than_real_time_trips_on_the_monitors_clock() {
    // Each step implies 4 m/s on the stream's clock (plausible), but 30 setpoints arrive per
    // 15 ms monitor cycle: 8 m/s in the monitor's time, beyond 5 m/s × 1.25.
    let poses: Vec<[f64; 6]> = (0..300)
        .map(|k| {
            let mut p = HOME;
            p[0] = -0.6 + 0.004 * k as f64;
            p
        })
        .collect();
    let mut m = monitor_with(|l| l.motion.linear_acceleration = f64::INFINITY);
    let tr = run_poses(&mut m, &poses, 30).expect("must trip");
    assert_eq!(tr.fault.cause, Cause::MotionVelocity);
    assert!(tr.fault.value > 7.0 && tr.fault.value < 8.0, "{tr}");
    // The same stream at its real rate (15 per cycle) passes.
    let mut m = monitor_with(|l| l.motion.linear_acceleration = f64::INFINITY);
    assert_eq!(run_poses(&mut m, &poses, 15), None);
}

// ---- checks that cannot be evaluated fail closed ----------------------------------------

#[test]
fn feedback_whose_applied_setpoint_is_unknown_trips_after_n_cycles() {
    let n = Limits::from(cfg()).unchecked_cycles;
    assert!(n >= 1);
    let q = sp(1, HOME, 0, 0.0).cable_length_m[..8].to_vec();
    let mut m = monitor();
    let mut seq = good_cycle(&mut m, 1, 0);
    // drive-io reports an applied sequence the monitor never saw (far ahead of its history).
    let mut trip = None;
    for k in 1..=n + 1 {
        m.on_feedback(&feedback(1_000_000 + u64::from(k), &q));
        seq = good_cycle(&mut m, seq, u64::from(k) * 15 * MS);
        if let Some(t) = m.trip() {
            trip = Some((k, *t));
            break;
        }
    }
    let (k, t) = trip.expect("unverifiable feedback must trip");
    assert_eq!(t.fault.cause, Cause::FollowingUnchecked);
    assert_eq!(k, n);
    // A checkable sample in between resets the streak (the monitor just started, say).
    let mut m = monitor();
    let mut seq = good_cycle(&mut m, 1, 0);
    for k in 0..3 * n {
        let applied = if k % (n - 1).max(1) == 0 {
            seq - 1
        } else {
            9_999_999
        };
        m.on_feedback(&feedback(applied, &q));
        seq = good_cycle(&mut m, seq, u64::from(k + 1) * 15 * MS);
    }
    assert_eq!(m.state_code(), StateCode::Armed, "{:?}", m.trip());
}

#[test]
fn bus_observation_failures_trip() {
    let mut m = monitor();
    good_cycle(&mut m, 1, 0);
    m.on_bus_observation_failed(3.0);
    let t = m
        .end_cycle(15 * MS)
        .new_trip
        .expect("blind bus checks must trip");
    assert_eq!((t.fault.cause, t.fault.value), (Cause::BusObservation, 3.0));
}

// ---- start-up: not ready until identity and every drive's feedback ----------------------

#[test]
fn the_monitor_starts_not_ready_and_arms_only_when_every_drive_is_verified() {
    use can_transport::safety_frame::SafetyState;
    let c = cfg();
    let lim = Limits::from(c);
    assert!(
        lim.require_ready,
        "the shipped configuration starts not ready"
    );
    let mut m = Monitor::new(
        lim,
        StandardKinematics::new(&c.platform),
        platform_identity(&c.platform),
    );
    assert_eq!(m.state_code(), StateCode::NotReady);
    assert_eq!(m.heartbeat(1).state, SafetyState::Stop);
    assert_eq!(m.request_reset(key_reset()), ResetDecision::NotReady);
    let mut t = 0;
    let mut cycle = |m: &mut Monitor, drives: usize, operational: bool| {
        for k in 0..15 {
            for i in 0..drives {
                m.on_drive_state(i, operational);
                m.on_force(i, 4000.0, t + k * MS);
            }
        }
        t += 15 * MS;
        m.end_cycle(t)
    };
    // Nothing heard from the drives yet: not ready.
    for _ in 0..5 {
        assert_eq!(cycle(&mut m, 0, true).state, StateCode::NotReady);
    }
    // One drive silent: not ready.
    assert_eq!(cycle(&mut m, 7, true).state, StateCode::NotReady);
    // Drives pre-operational (heartbeat, no NMT start yet): not ready.
    assert_eq!(cycle(&mut m, 8, false).state, StateCode::NotReady);
    // The identity is reported but not required (motion-core starts after the drives enable).
    assert!(!m.readiness().identity_verified);
    // Every drive operational with forces, but the safety I/O node (its e-stop circuit and
    // reset key) not heard: not ready; heard with the e-stop circuit open: not ready (and a
    // fault); heard with it closed: ready.
    assert!(lim.safety_io, "the shipped drives have a safety I/O node");
    assert_eq!(cycle(&mut m, 8, true).state, StateCode::NotReady);
    // Everything verified: armed, RUN.
    m.on_safety_io(0x01, 0x00, 0);
    let r = cycle(&mut m, 8, true);
    assert!(r.became_ready);
    assert_eq!(m.state_code(), StateCode::Armed);
    assert_eq!(m.heartbeat(2).state, SafetyState::Run);
}

#[test]
fn a_fault_while_not_ready_latches_and_readiness_names_what_is_missing() {
    let c = cfg();
    let mut m = Monitor::new(
        Limits::from(c),
        StandardKinematics::new(&c.platform),
        platform_identity(&c.platform),
    );
    m.on_identity(&PlatformIdentity::new(platform_identity(&c.platform), 8));
    for i in 0..8 {
        if i != 3 {
            m.on_drive_state(i, true);
        }
        if i != 5 {
            m.on_force(i, 4000.0, 1);
        }
    }
    let r = m.readiness();
    assert_eq!((r.not_operational, r.no_feedback), (1 << 3, 1 << 5));
    assert!(r.identity_verified && !r.ready());
    // A 101 mm setpoint while not ready trips (the checks run from the start).
    m.on_setpoint(&sp(1, HOME, 2, 0.101));
    let t = m
        .end_cycle(15 * MS)
        .new_trip
        .expect("trips while not ready");
    assert_eq!(t.fault.cause, Cause::DqLimit);
    assert_eq!(m.state_code(), StateCode::Tripped);
}

/// The shipped config with `key` of `[section]` set to `value` (platform and drives paths
/// made absolute), loaded from a temporary file.
fn load_with(section: &str, key: &str, value: &str) -> Result<MonitorConfig, String> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config");
    let text = std::fs::read_to_string(root.join("safety-monitor.toml")).unwrap();
    let mut out = Vec::new();
    let (mut cur, mut done) = (String::new(), false);
    for line in text.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            if cur == section && !done {
                out.push(format!("{key} = {value}"));
                done = true;
            }
            cur = t.trim_matches(|c| c == '[' || c == ']').to_string();
        }
        let line = if cur == section && !done && t.starts_with(&format!("{key} =")) {
            done = true;
            format!("{key} = {value}")
        } else if t.starts_with("platform = ") {
            format!("platform = {:?}", root.join("icosahedron.toml"))
        } else if t.starts_with("drives = ") {
            format!("drives = {:?}", root.join("drives.toml"))
        } else {
            line.to_string()
        };
        out.push(line);
    }
    if !done {
        out.push(format!("[{section}]\n{key} = {value}"));
    }
    let dir =
        std::env::temp_dir().join(format!("sm-bounds-{}-{section}-{key}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("sm.toml");
    std::fs::write(&p, out.join("\n") + "\n").unwrap();
    let r = config::load(&p).map_err(|e| e.to_string());
    std::fs::remove_dir_all(&dir).ok();
    r
}

#[test]
fn settings_beyond_their_bounds_are_refused_by_name() {
    // At the bound: accepted (the relaxed guest configs use up to 40 / 20 cycles).
    for (section, key, ok, too_big) in [
        ("monitor", "silence_cycles", "67", "68"),
        ("monitor", "max_missing_setpoints", "100", "101"),
        ("monitor", "identity_grace_cycles", "200", "201"),
        ("monitor", "reset_clear_cycles", "1000", "1001"),
        ("monitor", "workspace_margin_m", "0.5", "0.6"),
        ("monitor", "workspace_margin_deg", "5.0", "5.5"),
        ("feedback", "silence_cycles", "67", "68"),
        ("feedback", "unchecked_cycles", "67", "68"),
        ("feedback", "following_error_mm", "100.0", "100.5"),
        ("forces", "silence_cycles", "67", "68"),
        ("forces", "overload_margin_n", "5000.0", "5001.0"),
        ("forces", "window_readings", "64", "65"),
        ("forces", "hard_limit_n", "20000.0", "20001.0"),
        ("motion", "setpoint_period_ms", "10.0", "10.5"),
        ("can", "safety_io_silence_cycles", "67", "68"),
        ("forces", "slack_margin_n", "1000.0", "1001.0"),
        ("motion", "margin", "1.0", "1.01"),
        ("can", "reader_stall_cycles", "67", "68"),
    ] {
        let full = format!("{section}.{key}");
        if let Err(e) = load_with(section, key, ok) {
            panic!("{full} = {ok} must be accepted: {e}");
        }
        let e = load_with(section, key, too_big).expect_err(&full);
        assert!(e.contains(&full), "{full} = {too_big}: {e}");
    }
}

/// An e-stop published by another process (the console's stop button) latches the monitor, so
/// the stop it caused in motion-core and drive-io ends only with the monitor's reset.
#[test]
fn an_estop_event_of_another_process_latches_until_the_reset() {
    let mut m = monitor();
    let mut seq = good_cycle(&mut m, 1, 0);
    m.on_estop_event(crs_ipc::ProcessId::Operator as u32);
    m.on_setpoint(&sp(seq, HOME, 0, 0.0));
    seq += 1;
    let t = m.end_cycle(0).new_trip.expect("e-stop event");
    assert_eq!(t.fault.cause, Cause::EStopEvent);
    assert!(matches!(
        m.request_reset(key_reset()),
        ResetDecision::Refused(_)
    ));
    for _ in 0..3 {
        seq = good_cycle(&mut m, seq, 0);
    }
    assert!(matches!(
        m.request_reset(key_reset()),
        ResetDecision::Accepted { .. }
    ));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    /// The reset authority over random sequences of clean cycles, faulty cycles and reset
    /// requests: the epoch changes only with an accepted reset, by exactly one; a reset is
    /// accepted only while tripped and only after `reset_clear_cycles` clean cycles with
    /// evidence since the last fault; a request while armed changes nothing.
    #[test]
    fn the_epoch_advances_only_with_an_accepted_reset(ops in proptest::collection::vec(0u8..4, 1..40)) {
        let mut m = monitor().with_reset_epoch(1000);
        let mut seq = 1;
        let mut clean_since_fault = u32::MAX;
        for op in ops {
            let before = (m.state_code(), m.reset_epoch());
            match op {
                0 | 1 => {
                    seq = good_cycle(&mut m, seq, 0);
                    clean_since_fault = clean_since_fault.saturating_add(1);
                }
                2 => {
                    let mut s = sp(seq, HOME, 0, 0.0);
                    s.pose[1] = f64::NAN;
                    m.on_setpoint(&s);
                    seq += 1;
                    m.end_cycle(0);
                    clean_since_fault = 0;
                }
                _ => {
                    let d = m.request_reset(key_reset());
                    match d {
                        ResetDecision::Accepted { epoch } => {
                            prop_assert_eq!(before.0, StateCode::Tripped);
                            prop_assert!(clean_since_fault >= 3);
                            prop_assert_eq!(epoch, before.1 + 1);
                            prop_assert_eq!(m.reset_epoch(), epoch);
                            prop_assert_eq!(m.state_code(), StateCode::Armed);
                            prop_assert_eq!(m.heartbeat(0).epoch, epoch);
                        }
                        ResetDecision::NotTripped => {
                            prop_assert_eq!(before.0, StateCode::Armed);
                            prop_assert_eq!((m.state_code(), m.reset_epoch()), before);
                        }
                        _ => {
                            prop_assert_eq!((m.state_code(), m.reset_epoch()), before);
                            prop_assert!(before.0 == StateCode::Tripped && clean_since_fault < 3);
                        }
                    }
                    continue;
                }
            }
            // Cycles never change the epoch.
            prop_assert_eq!(m.reset_epoch(), before.1);
        }
    }
}

#[test]
fn bus_off_and_error_passive_trip_overflow_is_a_blind_reader_warnings_pass() {
    use can_transport::BusCondition;
    for (cond, cause) in [
        (BusCondition::BusOff, Some(Cause::CanBusError)),
        (BusCondition::ErrorPassive, Some(Cause::CanBusError)),
        (BusCondition::Overflow, Some(Cause::BusObservation)),
        (BusCondition::TxTimeout, None),
        (BusCondition::Other, None),
    ] {
        let mut m = monitor();
        let seq = good_cycle(&mut m, 1, 15_000_000);
        for k in 0..15 {
            m.on_setpoint(&sp(seq + k, HOME, 0, 0.0));
        }
        m.on_bus_error(cond);
        let r = m.end_cycle(30_000_000);
        match cause {
            Some(c) => {
                let t = r.new_trip.expect("trip");
                assert_eq!(t.fault.cause, c, "{cond:?}");
                assert_eq!(t.fault.value, f64::from(cond.code()));
                assert!(t.to_string().contains(c.name()), "trip log names the cause");
            }
            None => assert!(r.new_trip.is_none(), "{cond:?}"),
        }
    }
}

/// An end-of-stream announcement (STOPPING) is accepted only at the end of
/// the plan the producer announced, with the stream holding; otherwise it trips
/// `unplanned_stream_end` and the silence check stays armed (a forged STOPPING cannot disarm it).
#[test]
fn stopping_is_accepted_only_at_the_end_of_the_announced_plan() {
    let moving = |k: u64| [0.0, 0.0, 2.0 + 1e-5 * k as f64, 0.0, 0.0, 0.0];
    let stop_now = |m: &mut Monitor| {
        m.on_stream_end();
        m.end_cycle(0)
    };
    // No plan announced at all.
    let mut m = monitor();
    let seq = good_cycle(&mut m, 1, 0);
    assert!(!m.stream_end_planned());
    let r = stop_now(&mut m);
    assert_eq!(
        r.new_trip.map(|t| t.fault.cause),
        Some(Cause::UnplannedStreamEnd)
    );
    // Still armed: the silence that follows is also latched.
    m.end_cycle(0);
    assert!(m.last_faults().contains(Cause::SetpointSilence));
    let _ = seq;

    // A plan ending at 100 while the stream is at 16 (holding at a waypoint): refused.
    let mut m = monitor();
    m.on_plan_announced(100);
    good_cycle(&mut m, 1, 0);
    assert_eq!(
        stop_now(&mut m).new_trip.map(|t| t.fault.cause),
        Some(Cause::UnplannedStreamEnd)
    );

    // Past the plan's end but still moving: refused.
    let mut m = monitor_with(|l| l.motion.check = false);
    m.on_plan_announced(5);
    for k in 1..=15 {
        m.on_setpoint(&sp(k, moving(k), 0, 0.0));
    }
    assert!(!m.stream_end_planned());
    assert_eq!(
        stop_now(&mut m).new_trip.map(|t| t.fault.cause),
        Some(Cause::UnplannedStreamEnd)
    );

    // A stream without a planned end (motion cueing) while it moves: refused.
    let mut m = monitor_with(|l| l.motion.check = false);
    m.on_plan_announced(crs_ipc::PLAN_OPEN_END);
    for k in 1..=15 {
        m.on_setpoint(&sp(k, moving(k), 0, 0.0));
    }
    assert!(!m.stream_end_planned());
    assert_eq!(
        stop_now(&mut m).new_trip.map(|t| t.fault.cause),
        Some(Cause::UnplannedStreamEnd)
    );
    // ... and once it has held still long enough (the operator ended the ride): accepted.
    let mut m = monitor_with(|l| l.motion.check = false);
    m.on_plan_announced(crs_ipc::PLAN_OPEN_END);
    for k in 1..=15 {
        m.on_setpoint(&sp(k, moving(k), 0, 0.0));
    }
    for k in 16..=15 + 50 {
        m.on_setpoint(&sp(k, moving(15), 0, 0.0));
    }
    assert!(m.stream_end_planned());
    assert!(stop_now(&mut m).faults.is_empty());

    // At the plan's end and holding: accepted, nothing trips afterwards.
    let mut m = monitor_with(|l| l.motion.check = false);
    m.on_plan_announced(10);
    for k in 1..=10 {
        m.on_setpoint(&sp(k, moving(k), 0, 0.0));
    }
    m.end_cycle(0);
    assert!(!m.stream_end_planned(), "at the end but not yet holding");
    for k in 11..=12 {
        m.on_setpoint(&sp(k, moving(10), 0, 0.0));
    }
    assert!(m.stream_end_planned());
    assert!(stop_now(&mut m).faults.is_empty());
    for _ in 0..100 {
        assert!(m.end_cycle(0).faults.is_empty());
    }
    assert_eq!(m.state_code(), StateCode::Armed);
}

/// The state codes on the process bus are the contract's (crs_ipc::MonitorState, which
/// crs-console decodes) and decode back to the same state.
#[test]
fn state_codes_are_the_contract_constants() {
    for (s, code) in [
        (StateCode::Armed, 1),
        (StateCode::Tripped, 2),
        (StateCode::NotReady, 3),
    ] {
        assert_eq!(s.code(), code);
        assert_eq!(StateCode::try_from(code).ok(), Some(s));
    }
    assert_eq!(StateCode::try_from(0).ok(), None);
    assert_eq!(StateCode::try_from(4).ok(), None);
}

// ---- issue: the holes a reviewer finds ------------------------------------------------------

/// A hold is zero velocity: a stream that stands still, then jumps to a plausible speed (5 m/s
/// of table 5.1, below its 6.25 m/s with the margin) in one period trips `motion_acceleration`
/// at the step out of the hold — and so does the first moving step of a stream. Stopping into a
/// hold from speed does not trip (the safe direction).
#[test]
fn a_jump_from_rest_to_a_plausible_speed_trips_motion_acceleration() {
    let mc = Limits::from(cfg()).motion;
    let v = 5.0;
    assert!(v <= mc.linear_velocity && v / 1e-3 > mc.linear_acceleration);
    for (hold_first, what) in [(60usize, "out of a hold"), (1, "the stream's first step")] {
        let mut poses = vec![HOME; hold_first];
        let mut p = HOME;
        for _ in 0..20 {
            p[0] += v * 1e-3;
            poses.push(p);
        }
        let mut m = monitor();
        let tr = run_poses(&mut m, &poses, 15).unwrap_or_else(|| panic!("{what}: no trip"));
        assert_eq!(tr.fault.cause, Cause::MotionAcceleration, "{what}");
        assert_eq!(tr.fault.sequence, hold_first as u64 + 1, "{what}");
        assert!((tr.fault.value - v / 1e-3).abs() < 1.0, "{what}: {tr}");
    }
    // Decelerating into a hold at once is not checked.
    let mut poses = ramp_path(1.0, 10.0, 150);
    let last = *poses.last().unwrap();
    poses.extend(std::iter::repeat_n(last, 30));
    let mut m = monitor();
    assert_eq!(run_poses(&mut m, &poses, 15), None);
    // A sequence gap cannot restart the chain: rest, then two lost setpoints, then 5 m/s.
    let mut poses = vec![HOME; 30];
    let mut p = HOME;
    p[0] += 3.0 * v * 1e-3;
    let mut m = monitor();
    let mut seq = 1;
    for q in &poses {
        m.on_setpoint(&sp(seq, *q, 0, 0.0));
        seq += 1;
    }
    m.end_cycle(15 * MS);
    poses.clear();
    seq += 2;
    m.on_setpoint(&sp(seq, p, 0, 0.0));
    let tr = m.end_cycle(30 * MS).new_trip.expect("jump after a gap");
    assert_eq!(tr.fault.cause, Cause::MotionAcceleration);
}

/// The reset epoch is the instance's: a monitor instance starts at count 0 and each accepted
/// reset adds one to the count, never to the instance.
#[test]
fn the_epoch_carries_the_instance_and_counts_its_resets() {
    use crs_limits::reset_epoch::{count, instance, releases};
    let mut m = monitor().with_instance(0xBEEF);
    let e0 = m.reset_epoch();
    assert_eq!((instance(e0), count(e0)), (0xBEEF, 0));
    let mut seq = good_cycle(&mut m, 1, 0);
    m.on_estop_event(5);
    m.on_setpoint(&sp(seq, HOME, 0, 0.0));
    seq += 1;
    m.end_cycle(0);
    for _ in 0..3 {
        seq = good_cycle(&mut m, seq, 0);
    }
    let ResetDecision::Accepted { epoch } = m.request_reset(key_reset()) else {
        panic!("reset refused");
    };
    assert_eq!((instance(epoch), count(epoch)), (0xBEEF, 1));
    assert!(releases(epoch, e0));
    // An instance whose count is exhausted refuses (a wrap would make an old reset new).
    let mut m = monitor().with_reset_epoch(crs_limits::reset_epoch::new(7, u16::MAX));
    let mut seq = good_cycle(&mut m, 1, 0);
    m.on_estop_event(5);
    m.on_setpoint(&sp(seq, HOME, 0, 0.0));
    seq += 1;
    m.end_cycle(0);
    for _ in 0..3 {
        seq = good_cycle(&mut m, seq, 0);
    }
    assert_eq!(
        m.request_reset(key_reset()),
        ResetDecision::InstanceExhausted
    );
    assert!(m.state().is_tripped());
}

/// After a monitor restart the consumers stay stopped on the new instance's start epoch; while
/// armed, the monitor accepts the operator's reset only when a consumer is seen waiting (the
/// safety I/O node keeps the torque off although the monitor says RUN, or drive-io reports a
/// latched stop) for CONSUMER_WAIT_CYCLES cycles; otherwise a reset while armed changes
/// nothing.
#[test]
fn a_restarted_instance_resets_only_for_waiting_consumers() {
    use safety_monitor::monitor::CONSUMER_WAIT_CYCLES;
    let c = cfg();
    let own = platform_identity(&c.platform);
    for (waiting, sto_released, drive_io_latched) in [
        ("the safety I/O node", false, false),
        ("drive-io", true, true),
        ("nobody", true, false),
    ] {
        let mut m = Monitor::new(Limits::from(c), StandardKinematics::new(&c.platform), own)
            .with_instance(0x1234);
        let mut t = 0;
        let mut cycles = 0;
        let mut cycle = |m: &mut Monitor| {
            for k in 0..15 {
                for i in 0..8 {
                    m.on_drive_state(i, true);
                    m.on_force(i, 4000.0, t + k * MS);
                }
            }
            m.on_safety_io(0x01, u8::from(sto_released), t);
            let mut fb = feedback(0, &[0.0; 8]);
            fb.bus_state = if drive_io_latched {
                BusState::EStop as u32
            } else {
                BusState::Ready as u32
            };
            m.on_feedback(&fb);
            t += 15 * MS;
            cycles += 1;
            m.end_cycle(t)
        };
        cycle(&mut m);
        assert_eq!(m.state_code(), StateCode::Armed, "{waiting}");
        for _ in 1..CONSUMER_WAIT_CYCLES {
            cycle(&mut m);
        }
        // One cycle short of the wait: nothing.
        assert_eq!(
            m.request_reset(key_reset()),
            ResetDecision::NotTripped,
            "{waiting}"
        );
        cycle(&mut m);
        let d = m.request_reset(key_reset());
        if waiting == "nobody" {
            assert_eq!(d, ResetDecision::NotTripped);
            assert_eq!(m.reset_epoch(), crs_limits::reset_epoch::new(0x1234, 0));
        } else {
            assert_eq!(
                d,
                ResetDecision::Accepted {
                    epoch: crs_limits::reset_epoch::new(0x1234, 1)
                },
                "{waiting}"
            );
            assert_eq!(m.state_code(), StateCode::Armed);
            // The wait starts over: a second request right after changes nothing.
            assert_eq!(m.request_reset(key_reset()), ResetDecision::NotTripped);
        }
    }
}

/// The monitor's own identifiers spoken by another node, an open e-stop circuit and a silent
/// safety I/O node each trip; the node's causes need the node reporting with the circuit closed
/// before a reset.
#[test]
fn impersonation_estop_circuit_and_a_silent_safety_io_node_trip() {
    let mut m = monitor();
    let seq = good_cycle(&mut m, 1, 0);
    m.on_impersonation(0x101);
    m.on_setpoint(&sp(seq, HOME, 0, 0.0));
    let t = m.end_cycle(15 * MS).new_trip.expect("impersonation");
    assert_eq!(
        (t.fault.cause, t.fault.value),
        (Cause::Impersonation, 257.0)
    );

    let mut m = monitor();
    let mut seq = good_cycle(&mut m, 1, 0);
    m.on_safety_io(0x01, 0x01, 0);
    seq = good_cycle(&mut m, seq, 15 * MS);
    m.on_safety_io(0x00, 0x00, 0);
    m.on_setpoint(&sp(seq, HOME, 0, 0.0));
    seq += 1;
    let t = m.end_cycle(30 * MS).new_trip.expect("e-stop circuit open");
    assert_eq!(t.fault.cause, Cause::EStopCircuit);
    // Closed again but the node then silent: refused (no evidence), and the silence latches.
    m.on_safety_io(0x01, 0x00, 0);
    seq = good_cycle(&mut m, seq, 45 * MS);
    for _ in 0..6 {
        seq = good_cycle(&mut m, seq, 0);
    }
    assert!(m.latched().contains(Cause::SafetyIoSilence));
    assert!(matches!(
        m.request_reset(key_reset()),
        ResetDecision::Refused(_)
    ));
    // Reporting with the circuit closed: accepted after the clean cycles.
    for _ in 0..3 {
        m.on_safety_io(0x01, 0x00, 0);
        seq = good_cycle(&mut m, seq, 0);
    }
    assert!(matches!(
        m.request_reset(key_reset()),
        ResetDecision::Accepted { .. }
    ));
}

/// A hung drive adapter whose publisher keeps republishing its last sample (or stamps it in
/// the monitor's future) is as dead as a silent one, and the trip says which: `feedback_stale`.
#[test]
fn stale_or_future_feedback_is_not_a_live_drive_adapter() {
    let q = sp(1, HOME, 0, 0.0).cable_length_m[..8].to_vec();
    for future in [false, true] {
        let mut m = monitor();
        let mut seq = 1;
        let mut t = 0;
        let mut fb = feedback(0, &q);
        (fb.cycle, fb.timestamp_ns) = (1, 15 * MS);
        let mut trip = None;
        for k in 0..20u64 {
            t += 15 * MS;
            m.begin_cycle(t);
            let mut f = fb;
            if future {
                f.cycle += k;
                f.timestamp_ns = t + 10_000 * MS;
            }
            m.on_feedback(&f);
            seq = good_cycle(&mut m, seq, t);
            if let Some(tr) = m.trip() {
                trip = Some((k, *tr));
                break;
            }
        }
        let (k, tr) =
            trip.unwrap_or_else(|| panic!("future {future}: stale feedback never tripped"));
        assert_eq!(tr.fault.cause, Cause::FeedbackStale, "future {future}");
        // The first sample counts when fresh, then silence_cycles without a fresh one; a
        // future-stamped first sample arms the check without counting.
        let n = u64::from(Limits::from(cfg()).feedback_silence_cycles);
        assert_eq!(k, if future { n - 1 } else { n }, "future {future}");
        assert!(m.stats().feedback_stale > 0);
    }
}

/// Stale samples followed by a fresh one, then nothing: the silence after the fresh sample is
/// `feedback_silence` (the stale ones before it are not held against it).
#[test]
fn silence_after_a_fresh_sample_is_feedback_silence_not_stale() {
    let q = sp(1, HOME, 0, 0.0).cable_length_m[..8].to_vec();
    let mut m = monitor();
    let mut seq = 1;
    let mut t = 15 * MS;
    let mut fb = feedback(0, &q);
    (fb.cycle, fb.timestamp_ns) = (1, t);
    m.begin_cycle(t);
    m.on_feedback(&fb);
    m.on_feedback(&fb); // stale: republished
    seq = good_cycle(&mut m, seq, t);
    t += 15 * MS;
    m.begin_cycle(t);
    (fb.cycle, fb.timestamp_ns) = (2, t);
    m.on_feedback(&fb); // fresh again
    seq = good_cycle(&mut m, seq, t);
    let n = Limits::from(cfg()).feedback_silence_cycles;
    for _ in 0..n {
        t += 15 * MS;
        m.begin_cycle(t);
        seq = good_cycle(&mut m, seq, t);
    }
    let tr = m.trip().expect("silent drive-io tripped");
    assert_eq!(tr.fault.cause, Cause::FeedbackSilence);
}

/// A producer whose timestamps jump far into the future cannot blind the RPDO check: history
/// entries are stamped within the interval the monitor's clock saw them published in, so an
/// RPDO far from every setpoint still trips; RPDOs no setpoint can have preceded are counted
/// and trip `rpdo_unchecked` after `unchecked_cycles` cycles instead of being skipped.
#[test]
fn a_timestamp_jump_does_not_blind_the_rpdo_check() {
    let mut m = monitor();
    let q = sp(1, HOME, 0, 0.0).cable_length_m;
    let mut seq = 1;
    let mut t = 0;
    for _ in 0..30 {
        t += 15 * MS;
        m.begin_cycle(t);
        for _ in 0..15 {
            let mut s = sp(seq, HOME, 0, 0.0);
            s.timestamp_ns = t + 10_000_000 * MS; // 10 000 s ahead
            m.on_setpoint(&s);
            seq += 1;
        }
        // drive-io forwards what it got: checked and fine.
        m.on_rpdo(2, q[2], t + MS);
        assert!(m.end_cycle(t + 2 * MS).faults.is_empty());
    }
    t += 15 * MS;
    m.begin_cycle(t);
    // The setpoint before the forged RPDO is jumped too: no setpoint stamped by the producer's
    // own clock precedes the RPDO, only the monitor's clamp keeps it checked.
    let mut s = sp(seq, HOME, 0, 0.0);
    s.timestamp_ns = t + 10_000_000 * MS;
    m.on_setpoint(&s);
    m.on_rpdo(4, q[4] - 0.15, t + MS);
    let tr = m
        .end_cycle(t + 2 * MS)
        .new_trip
        .expect("forged RPDO after the jump");
    assert_eq!(
        (tr.fault.cause, tr.fault.cable),
        (Cause::RpdoMismatch, Some(4))
    );

    // Enabling RPDOs before any setpoint that hold where the drive was enabled: no motion,
    // checked, never a trip.
    let n = Limits::from(cfg()).unchecked_cycles;
    let mut m = monitor();
    for k in 1..=3 * n {
        m.begin_cycle(u64::from(k) * 15 * MS);
        m.on_rpdo(0, q[0], u64::from(k) * 15 * MS);
        assert!(m.end_cycle(u64::from(k) * 15 * MS + 1).faults.is_empty());
    }
    // Enabling RPDOs before any setpoint whose target moves: counted, and N such cycles trip
    // (the first one is where the drive was enabled).
    let mut m = monitor();
    let mut trip = None;
    for k in 1..=n + 2 {
        m.begin_cycle(u64::from(k) * 15 * MS);
        m.on_rpdo(0, q[0] + f64::from(k) * 1e-3, u64::from(k) * 15 * MS);
        if let Some(tr) = m.end_cycle(u64::from(k) * 15 * MS + 1).new_trip {
            trip = Some((k, tr));
            break;
        }
    }
    let (k, tr) = trip.expect("uncheckable RPDOs must trip");
    assert_eq!((k, tr.fault.cause), (n + 1, Cause::RpdoUnchecked));
}
