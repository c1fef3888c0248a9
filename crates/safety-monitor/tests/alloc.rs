//! The monitor's per-cycle work (every check of a cycle, including a trip, the latch and a reset
//! decision) allocates nothing: a counting global allocator observes a whole run of cycles.

use crs_ipc::{BusState, DriveFeedback, JointSetpoint, PlatformIdentity};
use crs_test_support::alloc::{CountingAlloc, count_allocations};
use safety_monitor::config;
use safety_monitor::identity::platform_identity;
use safety_monitor::kinematics::StandardKinematics;
use safety_monitor::{Limits, Monitor, StateCode};
use std::path::PathBuf;

#[global_allocator]
static A: CountingAlloc = CountingAlloc;

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

#[test]
fn a_cycle_allocates_nothing() {
    let cfg = config::load(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/safety-monitor.toml"),
    )
    .unwrap();
    let kin = StandardKinematics::new(&cfg.platform);
    let id = platform_identity(&cfg.platform);
    let mut m = Monitor::new(Limits::from(&cfg), kin, id);
    let ident = PlatformIdentity::new(id, 8);
    let mut base = JointSetpoint {
        cable_count: 8,
        pose: [0.1, 0.0, 2.0, 0.0, 0.0, 0.0],
        ..JointSetpoint::default()
    };
    kin.lengths(&base.pose, &mut base.cable_length_m);
    let mut seq = 0;
    let ((), n) = count_allocations(|| {
        for cycle in 0..1000u64 {
            m.begin_cycle(cycle * 15_000_000 + 1);
            m.on_identity(&ident);
            for _ in 0..15 {
                seq += 1;
                let mut s = base;
                s.sequence = seq;
                s.timestamp_ns = seq * 1_000_000;
                if cycle == 500 {
                    s.cable_length_m[2] += 0.2; // one trip in the middle
                }
                m.on_setpoint(&s);
                let mut f = DriveFeedback {
                    cable_count: 8,
                    applied_setpoint_sequence: seq,
                    cycle: seq,
                    timestamp_ns: s.timestamp_ns,
                    bus_state: BusState::Running as u32,
                    ..DriveFeedback::default()
                };
                f.cable_length_m = s.cable_length_m;
                m.on_feedback(&f);
                m.on_rpdo(1, base.cable_length_m[1], s.timestamp_ns);
                for i in 0..8 {
                    m.on_drive_state(i, true);
                    m.on_force(i, 4000.0, s.timestamp_ns);
                }
            }
            m.end_cycle(cycle * 15_000_000);
            if cycle > 510 && m.state().is_tripped() {
                m.request_reset(key_reset());
            }
        }
    });
    assert_eq!(m.trip_log().total(), 1);
    assert_eq!(m.state_code(), StateCode::Armed);
    assert_eq!(n, 0, "{n} allocations in 1000 cycles");
}
