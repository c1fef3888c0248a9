//! Cost of the monitor's work per 15 ms cycle (criterion). Reported in
//! benches/RESULTS.md ("Safety monitor"):
//! * `phi_star_8_cables`: the monitor's own standard inverse kinematics (glam);
//! * `cycle_15_setpoints`: one cycle at 1 kHz input: 15 setpoints checked + end of cycle;
//! * `cycle_full`: 15 setpoints, 15 drive feedback samples, 120 RPDO targets (8 drives x 15),
//!   120 force readings and the end of cycle, i.e. everything the monitor computes per cycle on
//!   the default config (Δq, box, motion plausibility, identity before motion, following
//!   error, RPDO, forces) plus one CAN error frame of warning level (reported, no trip);
//! * `cycle_full_without_force_and_motion`: the same input with the force and motion checks
//!   off (the monitor's scope before it supervised forces and motion), side by side;
//! * `safety_pair_encode_decode`: the doubled heartbeat, producer + consumer side.

use can_transport::safety_frame::{self, PairReceiver, SafetyHeartbeat, SafetyState};
use criterion::{Criterion, criterion_group, criterion_main};
use crs_ipc::{BusState, DriveFeedback, JointSetpoint, PlatformIdentity};
use safety_monitor::config;
use safety_monitor::identity::platform_identity;
use safety_monitor::kinematics::StandardKinematics;
use safety_monitor::{Limits, Monitor};
use std::hint::black_box;
use std::path::PathBuf;

fn bench(c: &mut Criterion) {
    let cfg = config::load(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/safety-monitor.toml"),
    )
    .expect("config/safety-monitor.toml");
    let kin = StandardKinematics::new(&cfg.platform);
    let id = platform_identity(&cfg.platform);
    let pose = [0.3, -0.2, 2.1, 0.02, -0.01, 0.03];
    let mut q = [0.0; crs_ipc::MAX_CABLES];
    c.bench_function("phi_star_8_cables", |b| {
        b.iter(|| {
            kin.lengths(black_box(&pose), &mut q);
            black_box(&q);
        })
    });

    // A continuous periodic path (0.05 m sine in x, 2 s period: 0.16 m/s, 0.5 m/s²), so the
    // ring of setpoints wraps without a jump the motion checks would (rightly) trip on.
    const RING: usize = 2000;
    let ring: Vec<JointSetpoint> = (0..RING)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / RING as f64;
            let p = [0.3 + 0.05 * a.sin(), -0.2, 2.1, 0.02, -0.01, 0.03];
            let mut s = JointSetpoint {
                cable_count: 8,
                pose: p,
                ..JointSetpoint::default()
            };
            kin.lengths(&p, &mut s.cable_length_m);
            s
        })
        .collect();
    let mut m = Monitor::new(Limits::from(&cfg), kin, id);
    m.on_identity(&PlatformIdentity::new(id, 8));
    let mut seq = 0u64;
    let mut now = 0u64;
    c.bench_function("cycle_15_setpoints", |b| {
        b.iter(|| {
            for _ in 0..15 {
                let mut s = ring[seq as usize % RING];
                seq += 1;
                s.sequence = seq;
                m.on_setpoint(&s);
            }
            now += 15_000_000;
            black_box(m.end_cycle(now))
        })
    });

    let winches = cfg.winches.clone();
    for (name, checks) in [
        ("cycle_full", true),
        ("cycle_full_without_force_and_motion", false),
    ] {
        let mut lim = Limits::from(&cfg);
        lim.forces.check = checks;
        lim.motion.check = checks;
        let mut m = Monitor::new(lim, kin, id);
        m.on_identity(&PlatformIdentity::new(id, 8));
        let (mut seq, mut now) = (0u64, 0u64);
        c.bench_function(name, |b| {
            b.iter(|| {
                for _ in 0..15 {
                    let mut s = ring[seq as usize % RING];
                    seq += 1;
                    s.sequence = seq;
                    s.timestamp_ns = now;
                    m.on_setpoint(&s);
                    let mut f = DriveFeedback {
                        cable_count: 8,
                        applied_setpoint_sequence: seq,
                        bus_state: BusState::Running as u32,
                        ..DriveFeedback::default()
                    };
                    f.cable_length_m = s.cable_length_m;
                    m.on_feedback(&f);
                    for (i, w) in winches.iter().enumerate() {
                        let counts = (s.cable_length_m[i] * w.counts_per_m * w.sign
                            + w.offset_counts)
                            .round() as i32;
                        m.on_rpdo(i, w.counts_to_length_m(counts), now + 1);
                        if checks {
                            m.on_drive_state(i, true);
                            m.on_force(i, 4000.0 + i as f64, now + 1);
                        }
                    }
                    now += 1_000_000;
                }
                if checks {
                    m.on_bus_error(black_box(can_transport::BusCondition::Other));
                }
                black_box(m.end_cycle(now))
            })
        });
        assert_eq!(
            m.trip_log().total(),
            0,
            "{name}: the bench input must not trip"
        );
    }

    let mut rx = PairReceiver::new(safety_frame::DEFAULT_COB_ID, 10_000_000);
    let mut counter = 0u16;
    c.bench_function("safety_pair_encode_decode", |b| {
        b.iter(|| {
            counter = counter.wrapping_add(1);
            let [a, bb] = safety_frame::encode(
                &SafetyHeartbeat {
                    state: SafetyState::Run,
                    cause: 0,
                    counter,
                    epoch: 1,
                },
                safety_frame::DEFAULT_COB_ID,
            );
            rx.on_frame(&a, 1);
            black_box(rx.on_frame(&bb, 2))
        })
    });
    assert_eq!(m.trip_log().total(), 0, "the bench input must not trip");
}

criterion_group!(benches, bench);
criterion_main!(benches);
