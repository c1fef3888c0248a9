//! The monitor PROCESS LOOP ([`safety_monitor::daemon::run`]) on the host: iceoryx2 under a
//! unique service prefix, the CAN-over-UDP multicast bus on a unique port (this kernel has no
//! CAN; the same code runs on vcan in tools/safety-hil.sh). The test plays motion-core (identity
//! and 1 kHz setpoints) and listens on the bus like the drives do. Conditions are awaited with
//! deadlines; timing is printed, never asserted tightly (performance lives in benches/).

use can_transport::safety_frame::{PairReceiver, SafetyState};
use can_transport::{CanBus, TransportSpec};
use crs_ipc::{EventKind, IpcNode, JointSetpoint, PlatformIdentity, ProcessId, StateEvent};
use safety_monitor::daemon::{self, ResetReply};
use safety_monitor::identity::platform_identity;
use safety_monitor::kinematics::StandardKinematics;
use safety_monitor::{Cause, config};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

const HOME: [f64; 6] = [0.0, 0.0, 2.0, 0.0, 0.0, 0.0];

struct Rig {
    stop: Arc<AtomicBool>,
    monitor: Option<std::thread::JoinHandle<Result<daemon::Summary, String>>>,
    ipc: IpcNode,
    setpoints: crs_ipc::TopicPublisher<JointSetpoint>,
    /// Kept alive: iceoryx2 keeps the history (the announced identity) in the publisher.
    _identity: crs_ipc::TopicPublisher<PlatformIdentity>,
    events: crs_ipc::TopicSubscriber<StateEvent>,
    bus: Box<dyn CanBus>,
    pairs: PairReceiver,
    kin: StandardKinematics,
    id: crs_ipc::PlatformId,
    seq: u64,
    /// The monitor's reset socket (this test process is in the operator group: its own gid).
    reset_socket: PathBuf,
    /// (state, time) of the last valid safety pair; NMT commands seen (command, time).
    last_pair: Option<(SafetyState, Instant)>,
    /// Valid pairs received so far: the monitor sends one per cycle, so a count of them is a
    /// count of its cycles (the tests wait on these, not on wall-clock windows).
    valid_pairs: u64,
    invalid_pairs: u32,
    nmt: Vec<(u8, Instant)>,
    /// Play the drives too: NMT-operational heartbeats and a TPDO2 force reading per drive
    /// every millisecond (the monitor's start-up conditions and force supervision need them).
    drives: bool,
    node_ids: Vec<u8>,
    /// The bus's UDP port, reserved for this rig (no other test or run can get it).
    _port: crs_test_support::ports::UdpPort,
}

/// The shipped configuration reduced to what this test plays on ONE UDP bus: every drive on
/// it, each reporting its force in TPDO2 (velocity, then force in mN: the simulated winch's
/// layout), the monitor's doubled frames on the same bus.
fn one_bus_with_drive_forces(cfg: &mut config::MonitorConfig, transport: &TransportSpec) {
    use safety_monitor::bus_layout::{BusLayout, ForceLayout, RpdoLayout, Value};
    cfg.interfaces = vec![config::Interface {
        name: "can0".into(),
        transport: transport.to_string(),
    }];
    cfg.safety_interfaces = vec![0];
    cfg.safety_io = None;
    for w in &mut cfg.winches {
        w.interface = 0;
    }
    cfg.layout = BusLayout {
        rpdo: cfg
            .winches
            .iter()
            .map(|w| RpdoLayout::default_for(0, w.node_id))
            .collect(),
        force: cfg
            .winches
            .iter()
            .map(|w| ForceLayout {
                interface: 0,
                cob_id: 0x280 + u16::from(w.node_id),
                len: 8,
                at: 4,
                value: Value::I32,
                n_per_unit: 0.001,
                node: w.node_id,
            })
            .collect(),
        safety_io: None,
    };
}

impl Rig {
    fn start(name: &str) -> Rig {
        Self::start_with(name, false)
    }

    /// `fail_nmt`: the monitor's sending socket fails every NMT frame with a full TX queue
    /// (ENOBUFS), as `safety-monitor --inject-nmt-stop-unsent` does.
    fn start_with(name: &str, fail_nmt: bool) -> Rig {
        let prefix = format!("sm-test-{}-{name}/", std::process::id());
        let port = crs_test_support::ports::reserve_udp_port();
        let transport: TransportSpec = port.udpbus(7).parse().unwrap();
        let cfg_path =
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/safety-monitor.toml");
        let mut cfg = config::load(&cfg_path).unwrap();
        one_bus_with_drive_forces(&mut cfg, &transport);
        cfg.monitor.rt_priority = 0;
        // The test process itself publishes the setpoints and the identity (the
        // stream owners are checked by executable).
        let me = std::env::current_exe().unwrap();
        let me = me.file_name().unwrap().to_string_lossy().to_string();
        cfg.ipc.setpoint_owners = vec![me.clone()];
        cfg.ipc.identity_owners = vec![me];
        cfg.can.reset_wait_ms = 200;
        // The operator's reset through the reset socket; this test process's own group is the
        // operator group (no safety I/O node on this bus, so no reset key).
        let reset_socket =
            std::env::temp_dir().join(format!("{}reset.sock", prefix.replace('/', "-")));
        // SAFETY: getgid has no preconditions.
        cfg.reset_socket = Some((reset_socket.clone(), unsafe { libc::getgid() }));
        cfg.reset.key = false;
        let kin = StandardKinematics::new(&cfg.platform);
        let id = platform_identity(&cfg.platform);
        let node_ids: Vec<u8> = cfg.winches.iter().map(|w| w.node_id).collect();
        let bus = can_transport::open(&transport).unwrap();
        let ipc = IpcNode::with_prefix("sm-test", &prefix).unwrap();
        let setpoints = ipc.publisher::<JointSetpoint>().unwrap();
        let identity = ipc.publisher::<PlatformIdentity>().unwrap();
        let events = ipc.subscriber::<StateEvent>().unwrap();
        identity.publish(&PlatformIdentity::new(id, 8)).unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let monitor = {
            let (stop, prefix, t) = (stop.clone(), prefix.clone(), transport.clone());
            std::thread::spawn(move || {
                let ipc =
                    IpcNode::with_prefix("safety-monitor", &prefix).map_err(|e| e.to_string())?;
                if fail_nmt {
                    let tx = can_transport::open(&t).map_err(|e| e.to_string())?;
                    let rx = can_transport::open(&t).map_err(|e| e.to_string())?;
                    let tx: Box<dyn can_transport::CanBus> =
                        Box::new(safety_monitor::stop_path::FailingSends::new(tx, 0));
                    daemon::run_on(&cfg, vec![tx], vec![rx], &ipc, &stop).map_err(|e| e.to_string())
                } else {
                    daemon::run(&cfg, &ipc, &stop).map_err(|e| e.to_string())
                }
            })
        };
        Rig {
            stop,
            monitor: Some(monitor),
            ipc,
            setpoints,
            _identity: identity,
            events,
            bus,
            pairs: PairReceiver::new(0x101, 10_000_000),
            kin,
            id,
            seq: 0,
            reset_socket,
            last_pair: None,
            valid_pairs: 0,
            invalid_pairs: 0,
            nmt: Vec::new(),
            drives: true,
            node_ids,
            _port: port,
        }
    }

    /// One millisecond of the drives' traffic: heartbeat (operational) and TPDO2 (4 kN).
    fn drive_frames(&mut self) {
        if !self.drives {
            return;
        }
        for &n in &self.node_ids {
            let hb = can_transport::CanFrame::new(0x700 + u16::from(n), &[0x05]).unwrap();
            let mut d = [0u8; 8];
            d[4..].copy_from_slice(&4_000_000i32.to_le_bytes());
            let tpdo2 = can_transport::CanFrame::new(0x280 + u16::from(n), &d).unwrap();
            self.bus.send(&hb).unwrap();
            self.bus.send(&tpdo2).unwrap();
        }
    }

    fn setpoint(&mut self, cable: usize, offset: f64, nan_pose: bool) -> JointSetpoint {
        self.seq += 1;
        let mut s = JointSetpoint {
            cable_count: 8,
            sequence: self.seq,
            timestamp_ns: crs_ipc::monotonic_ns(),
            pose: HOME,
            ..JointSetpoint::default()
        };
        let mut q = [0.0; crs_ipc::MAX_CABLES];
        self.kin.lengths(&HOME, &mut q);
        s.cable_length_m = q;
        s.cable_length_m[cable] += offset;
        if nan_pose {
            s.pose[3] = f64::NAN;
        }
        s
    }

    fn poll_bus(&mut self) {
        while let Ok(Some(rx)) = self.bus.try_recv() {
            let f = rx.frame;
            if f.id() == 0 && f.len() == 2 {
                self.nmt.push((f.data()[0], Instant::now()));
            }
            match self.pairs.on_frame(&f, rx.rx_monotonic_ns) {
                Some(Ok(m)) => {
                    self.last_pair = Some((m.state, Instant::now()));
                    self.valid_pairs += 1;
                }
                Some(Err(_)) => self.invalid_pairs += 1,
                None => {}
            }
        }
    }

    /// Publishes at ~1 kHz for `dur` (offset on cable 2), polling the bus.
    fn run_for(&mut self, dur: Duration, offset: f64, nan_pose: bool) {
        let t0 = Instant::now();
        while t0.elapsed() < dur {
            // Re-announce the identity often: iceoryx2 hands a publisher's history to a late
            // subscriber only when that publisher sends again, and the monitor tolerates only
            // `identity_grace_cycles` (10) of unverified setpoints (a monitor thread that
            // subscribed after an announcement must see the next one within them).
            if self.seq.is_multiple_of(5) {
                self._identity
                    .publish(&PlatformIdentity::new(self.id, 8))
                    .unwrap();
            }
            let s = self.setpoint(2, offset, nan_pose);
            self.setpoints.publish(&s).unwrap();
            self.drive_frames();
            self.poll_bus();
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Publishes until `cond` holds (or panics after `limit`); returns the time it took.
    fn until(
        &mut self,
        limit: Duration,
        offset: f64,
        nan_pose: bool,
        mut cond: impl FnMut(&mut Rig) -> bool,
    ) -> Duration {
        let t0 = Instant::now();
        loop {
            self.run_for(Duration::from_millis(1), offset, nan_pose);
            if cond(self) {
                return t0.elapsed();
            }
            assert!(
                t0.elapsed() < limit,
                "condition not reached within {limit:?}"
            );
        }
    }

    /// Publishes until the monitor has sent `n` more valid pairs (`n` more of its cycles) and
    /// returns the state of the last one: what the monitor says NOW, judged by its cycles.
    fn next_pairs(&mut self, n: u64, offset: f64, nan_pose: bool) -> SafetyState {
        let n0 = self.valid_pairs;
        self.until(Duration::from_secs(10), offset, nan_pose, |r| {
            r.valid_pairs >= n0 + n
        });
        self.last_pair.expect("a pair was counted").0
    }

    fn estop_events(&mut self) -> Vec<StateEvent> {
        let mut v = Vec::new();
        while let Ok(Some(e)) = self.events.receive() {
            if e.source == ProcessId::SafetyMonitor as u32 && e.kind == EventKind::EStop as u32 {
                v.push(e);
            }
        }
        v
    }

    fn finish(mut self) -> daemon::Summary {
        self.stop.store(true, Ordering::Relaxed);
        self.monitor.take().unwrap().join().unwrap().unwrap()
    }
}

/// The reset CLI's request from another thread (through the monitor's reset socket), while
/// this thread keeps publishing setpoints (`offset`, `nan_pose`) like a live motion core.
fn reset(rig: &mut Rig, offset: f64, nan_pose: bool) -> ResetReply {
    let p = rig.reset_socket.clone();
    let h = std::thread::spawn(move || daemon::request_reset(&p, Duration::from_secs(2)).unwrap());
    while !h.is_finished() {
        rig.run_for(Duration::from_millis(1), offset, nan_pose);
    }
    h.join().unwrap()
}

#[test]
fn offset_101_mm_trips_and_stops_the_bus_99_mm_does_not() {
    let mut rig = Rig::start("offset");
    // Armed: RUN pairs every cycle while consistent setpoints flow.
    rig.until(Duration::from_secs(3), 0.0, false, |r| {
        matches!(r.last_pair, Some((SafetyState::Run, _)))
    });
    // The monitor is subscribed and checking from here on (setpoints published before its
    // thread subscribed never reach it, and how many those are depends on the host's load).
    let seq_armed = rig.seq;
    rig.run_for(Duration::from_millis(300), 0.099, false);
    let ev = rig.estop_events();
    assert!(ev.is_empty(), "99 mm must not trip: {ev:?}");
    assert!(rig.nmt.is_empty());
    assert_eq!(rig.next_pairs(10, 0.099, false), SafetyState::Run);

    let t_inject = Instant::now();
    let took = rig.until(Duration::from_secs(2), 0.101, false, |r| {
        r.nmt.iter().any(|(c, _)| *c == 0x02)
    });
    let (_, t_nmt) = rig.nmt.iter().find(|(c, _)| *c == 0x02).copied().unwrap();
    rig.run_for(Duration::from_millis(50), 0.101, false);
    let ev = rig.estop_events();
    assert_eq!(ev.len(), 1, "one latched e-stop event: {ev:?}");
    assert_eq!(ev[0].detail, u32::from(Cause::DqLimit.code()));
    assert_eq!(ev[0].detail_node, 3, "cable 3 (1-based)");
    assert!(matches!(rig.last_pair, Some((SafetyState::Stop, _))));
    println!(
        "101 mm offset: NMT stop on the bus {:.1} ms after the first bad setpoint (host, udpbus; polled {took:?})",
        (t_nmt - t_inject).as_secs_f64() * 1e3
    );

    // Refused while the offset persists, accepted once it is gone for reset_clear_cycles.
    assert_eq!(
        reset(&mut rig, 0.101, false),
        ResetReply::Refused(Some(Cause::DqLimit))
    );
    assert!(matches!(rig.last_pair, Some((SafetyState::Stop, _))));
    // The offset gone for 20 of the monitor's cycles (reset_clear_cycles = 3).
    rig.next_pairs(20, 0.0, false);
    let n_before = rig.nmt.len();
    assert_eq!(reset(&mut rig, 0.0, false), ResetReply::Accepted);
    rig.until(Duration::from_secs(1), 0.0, false, |r| {
        r.nmt[n_before..].iter().any(|(c, _)| *c == 0x01)
            && matches!(r.last_pair, Some((SafetyState::Run, _)))
    });
    // No drives answer on this bus: the Reset event follows after reset_wait_ms.
    let mut saw_reset = false;
    rig.until(Duration::from_secs(2), 0.0, false, |r| {
        while let Ok(Some(e)) = r.events.receive() {
            saw_reset |=
                e.source == ProcessId::SafetyMonitor as u32 && e.kind == EventKind::Reset as u32;
        }
        saw_reset
    });
    assert_eq!(rig.invalid_pairs, 0);
    // Every setpoint the rig published once the monitor was armed was checked or counted
    // missing (up to the subscriber buffer still queued at shutdown): how MANY were published
    // depends on how the host schedules the rig's 1 ms pacing, so that is not asserted.
    let published = rig.seq - seq_armed;
    let s = rig.finish();
    assert_eq!(s.trips, 1);
    assert!(
        published > 100,
        "the rig published only {published} setpoints"
    );
    assert!(
        s.setpoints_checked
            + s.setpoints_missing
            + <crs_ipc::JointSetpoint as crs_ipc::Topic>::SUBSCRIBER_BUFFER as u64
            >= published,
        "published {published}: {s:?}"
    );
    println!("summary: {s:?}");
}

#[test]
fn frozen_publisher_and_nan_pose_trip() {
    let mut rig = Rig::start("silence");
    rig.until(Duration::from_secs(3), 0.0, false, |r| {
        matches!(r.last_pair, Some((SafetyState::Run, _)))
    });
    rig.run_for(Duration::from_millis(100), 0.0, false);
    // Freeze: stop publishing, keep listening.
    let t0 = Instant::now();
    while !rig.nmt.iter().any(|(c, _)| *c == 0x02) {
        rig.poll_bus();
        std::thread::sleep(Duration::from_millis(1));
        assert!(
            t0.elapsed() < Duration::from_secs(2),
            "silence not detected"
        );
    }
    let ev = rig.estop_events();
    assert_eq!(ev[0].detail, u32::from(Cause::SetpointSilence.code()));
    println!(
        "frozen publisher: NMT stop {:.1} ms after the last setpoint (silence_cycles = 2 x 15 ms)",
        t0.elapsed().as_secs_f64() * 1e3
    );
    // NaN while latched keeps the reset refused.
    rig.run_for(Duration::from_millis(100), 0.0, true);
    assert_eq!(
        reset(&mut rig, 0.0, true),
        ResetReply::Refused(Some(Cause::NonFinite))
    );
    rig.finish();
}

#[test]
fn a_foreign_reset_while_tripped_is_countered() {
    let mut rig = Rig::start("foreign");
    rig.run_for(Duration::from_millis(100), 0.0, false);
    rig.until(Duration::from_secs(2), 0.2, false, |r| !r.nmt.is_empty());
    assert_eq!(rig.estop_events().len(), 1);
    // Someone else publishes Reset (e.g. a tool): the monitor re-asserts its e-stop.
    let tool = rig.ipc.publisher::<StateEvent>().unwrap();
    tool.publish(&StateEvent::new(ProcessId::Test, EventKind::Reset, 1))
        .unwrap();
    let mut n = 0;
    rig.until(Duration::from_secs(1), 0.2, false, |r| {
        n += r.estop_events().len();
        n >= 1
    });
    rig.finish();
}

#[test]
fn the_monitor_permits_motion_only_after_every_drives_feedback() {
    let mut rig = Rig::start("startup");
    rig.drives = false;
    // Identity and setpoints flow, but no drive is heard: STOP pairs, never RUN.
    rig.until(Duration::from_secs(3), 0.0, false, |r| {
        matches!(r.last_pair, Some((SafetyState::Stop, _)))
    });
    rig.run_for(Duration::from_millis(300), 0.0, false);
    assert_eq!(
        rig.next_pairs(10, 0.0, false),
        SafetyState::Stop,
        "not ready must send STOP"
    );
    // A reset cannot skip the start-up conditions.
    assert_eq!(reset(&mut rig, 0.0, false), ResetReply::NotReady);
    // The drives appear (operational, sending forces): RUN within a few cycles, no trip.
    rig.drives = true;
    let took = rig.until(Duration::from_secs(3), 0.0, false, |r| {
        matches!(r.last_pair, Some((SafetyState::Run, _)))
    });
    println!("RUN {took:?} after the drives appeared");
    assert!(rig.estop_events().is_empty());
    assert!(rig.nmt.is_empty(), "no NMT stop at start-up: {:?}", rig.nmt);
    rig.finish();
}

#[test]
fn bus_off_and_error_passive_trip_warnings_do_not() {
    use can_transport::BusErrorFrame;
    use can_transport::bus_error::{class, crtl};
    for (k, e) in [
        BusErrorFrame::bus_off(),
        BusErrorFrame::error_passive(128, 0),
    ]
    .into_iter()
    .enumerate()
    {
        let mut rig = Rig::start(&format!("buserr{k}"));
        rig.until(Duration::from_secs(3), 0.0, false, |r| {
            matches!(r.last_pair, Some((SafetyState::Run, _)))
        });
        // A warning level and a missing ACK are reported, not tripped on.
        rig.bus
            .send_bus_error(&BusErrorFrame::new(class::CRTL, &[0, crtl::RX_WARNING]))
            .unwrap();
        rig.bus
            .send_bus_error(&BusErrorFrame::new(class::ACK, &[]))
            .unwrap();
        rig.run_for(Duration::from_millis(100), 0.0, false);
        assert!(rig.estop_events().is_empty());
        let t0 = Instant::now();
        rig.bus.send_bus_error(&e).unwrap();
        rig.until(Duration::from_secs(2), 0.0, false, |r| {
            r.nmt.iter().any(|(c, _)| *c == 0x02)
        });
        let ev = rig.estop_events();
        assert_eq!(ev[0].detail, u32::from(Cause::CanBusError.code()), "{e}");
        println!(
            "{e}: NMT stop after {:.1} ms",
            t0.elapsed().as_secs_f64() * 1e3
        );
        rig.run_for(Duration::from_millis(50), 0.0, false);
        assert!(matches!(rig.last_pair, Some((SafetyState::Stop, _))));
        let s = rig.finish();
        assert_eq!(s.bus_errors, 3, "{s:?}");
    }
}

#[test]
fn an_unsent_nmt_stop_escalates_to_the_heartbeat_inhibit() {
    let mut rig = Rig::start_with("nmtfail", true);
    rig.until(Duration::from_secs(3), 0.0, false, |r| {
        matches!(r.last_pair, Some((SafetyState::Run, _)))
    });
    // Trip (101 mm): the NMT stop cannot be sent; the STOP pairs must go out instead.
    rig.until(Duration::from_secs(2), 0.101, false, |r| {
        matches!(r.last_pair, Some((SafetyState::Stop, _)))
    });
    rig.run_for(Duration::from_millis(100), 0.101, false);
    assert_eq!(
        rig.estop_events()[0].detail,
        u32::from(Cause::DqLimit.code())
    );
    assert!(
        rig.nmt.is_empty(),
        "the injected failure must keep every NMT frame off the bus: {:?}",
        rig.nmt
    );
    // Six more tripped cycles of the monitor (one pair each), all STOP.
    assert_eq!(rig.next_pairs(6, 0.101, false), SafetyState::Stop);
    assert_eq!(rig.invalid_pairs, 0);
    let s = rig.finish();
    // On the trip and every tripped cycle after it (>= the 6 counted above), each counted once
    // after its retries, and each cycle escalated to the heartbeat's inhibit.
    assert!(s.stop.nmt_stop_unsent >= 6, "{s:?}");
    assert_eq!(s.stop.escalated_heartbeat, s.stop.nmt_stop_unsent, "{s:?}");
    assert_eq!((s.stop.heartbeat_unsent, s.stop.escalated_watch), (0, 0));
}
