//! Deterministic master <-> slave tests without a bus: frames are passed directly in virtual time.

use can_transport::RxFrame;
use cia402_drive::slave::{DriveSlave, MotionDemand, SlaveEvent, WinchAxis};
use crs_ipc::{BusState, FaultCode, JointSetpoint};
use drive_bus::canopen::{self, BusFrames, Ds402State, FrameBuf, Message};
use drive_bus::eds::{BUILTIN_WINCH_EDS, Eds};
use drive_io::Master;
use drives_config::DrivesConfig;

struct Sim {
    cfg: DrivesConfig,
    master: Master,
    slaves: Vec<DriveSlave>,
    axes: Vec<WinchAxis>,
    now: u64,
    mute: Option<usize>,
    /// A drive that neither receives nor sends (dead controller).
    dead: Option<usize>,
    log: Vec<Message>,
    /// Pulley force each drive reports in TPDO2, mN.
    force_mn: Vec<i32>,
    /// For this many more cycles the drives' TPDO2 (velocity, force) does not reach drive-io.
    tpdo2_late: u32,
}

impl Sim {
    fn new() -> Self {
        Self::with_eds(Eds::builtin_winch().clone(), Eds::builtin_winch())
    }

    /// drive-io configured from `master_eds`, drives implementing `drive_eds`.
    fn with_eds(master_eds: Eds, drive_eds: &Eds) -> Self {
        let cfg = rig_config();
        let master = Master::with_eds(&cfg, master_eds).unwrap();
        let slaves = cfg
            .winches
            .iter()
            .map(|w| DriveSlave::with_eds(w.node_id, drive_eds, 20))
            .collect();
        let axes = (0..cfg.winches.len())
            .map(|i| WinchAxis::new(3.0 + i as f64, 5.0, 14.0))
            .collect();
        let mut s = Self {
            cfg,
            master,
            slaves,
            axes,
            now: 1_000_000_000,
            mute: None,
            dead: None,
            log: Vec::new(),
            force_mn: vec![1000; 8],
            tpdo2_late: 0,
        };
        let mut out = FrameBuf::default();
        for (i, sl) in s.slaves.iter_mut().enumerate() {
            let c = s.cfg.winches[i]
                .length_to_counts(s.axes[i].length_m)
                .unwrap();
            sl.set_actual(c, 0, 1000);
            sl.start(s.now, &mut out);
        }
        s.deliver_to_master(&out);
        s
    }

    fn deliver_to_master(&mut self, out: &FrameBuf) {
        for f in out.as_slice() {
            self.master.on_frame(
                0,
                &RxFrame {
                    frame: *f,
                    rx_monotonic_ns: self.now,
                    kernel_rx_realtime_ns: None,
                    own: false,
                },
            );
        }
    }

    /// One 1 ms cycle: master -> slaves -> physics -> slaves -> master.
    fn step(&mut self, sp: Option<&JointSetpoint>) {
        self.step_after(sp, 1_000_000);
    }

    /// One cycle `dt_ns` after the previous one (a cycle started early or late; the drives'
    /// physics still advance one period).
    fn step_after(&mut self, sp: Option<&JointSetpoint>, dt_ns: u64) {
        self.now += dt_ns;
        let mut out = BusFrames::new(1);
        self.master.cycle(self.now, sp, &mut out);
        self.master.mark_written(self.now);
        // One interface: its frames, then the SYNC the cycle asks for (as the runner sends).
        let mut m_out: Vec<can_transport::CanFrame> = out.on(0).to_vec();
        if out.sync_requested() {
            m_out.push(canopen::sync());
        }
        let mut s_out = FrameBuf::default();
        for f in &m_out {
            self.log.push(canopen::decode(f));
            for i in 0..self.slaves.len() {
                if self.dead == Some(i) {
                    continue;
                }
                if self.slaves[i].handle_frame(f, self.now, &mut s_out) == SlaveEvent::Sync {
                    let w = &self.cfg.winches[i];
                    match self.slaves[i].demand() {
                        MotionDemand::Follow { target_counts } => {
                            self.axes[i].step(Some(w.counts_to_length(target_counts)), 1e-3)
                        }
                        MotionDemand::QuickStop => self.axes[i].step(None, 1e-3),
                        MotionDemand::Hold => self.axes[i].hold(),
                    }
                    let c = w.length_to_counts(self.axes[i].length_m).unwrap();
                    self.slaves[i].set_actual(
                        c,
                        w.m_per_s_to_counts_per_s(self.axes[i].velocity_m_per_s),
                        self.force_mn[i],
                    );
                    self.slaves[i].transmit_pdos(&mut s_out);
                }
            }
        }
        for (i, sl) in self.slaves.iter_mut().enumerate() {
            if self.dead == Some(i) {
                continue;
            }
            sl.set_heartbeat_muted(self.mute == Some(i));
            sl.poll(self.now, &mut s_out);
        }
        if self.tpdo2_late > 0 {
            self.tpdo2_late -= 1;
            let mut kept = FrameBuf::default();
            for f in s_out.as_slice() {
                if !(0x281..=0x2FF).contains(&f.id()) {
                    kept.push(*f);
                }
            }
            s_out = kept;
        }
        self.deliver_to_master(&s_out);
    }

    fn boot(&mut self) {
        for _ in 0..200 {
            self.step(None);
            if self.master.state() == BusState::Ready {
                return;
            }
        }
        panic!("not Ready after 200 cycles: {:?}", self.master.state());
    }

    fn setpoint(&self, seq: u64, lengths: &[f64]) -> JointSetpoint {
        let mut sp = JointSetpoint {
            sequence: seq,
            cable_count: lengths.len() as u32,
            timestamp_ns: self.now,
            ..Default::default()
        };
        sp.cable_length_m[..lengths.len()].copy_from_slice(lengths);
        sp
    }
}

/// 3 t² − 2 t³: a rest-to-rest profile (zero speed at both ends, bounded acceleration), as a
/// planner's stream starts and ends.
fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Accelerates every cable from rest (`l0`, holding as setpoint `seq`) at 40 m/s² (within the
/// default 50 m/s² of `bus.max_cable_acceleration_m_per_s2`) up to `v` m/s; returns the last
/// lengths and the next sequence number.
fn ramp_up(s: &mut Sim, l0: &[f64], v: f64, mut seq: u64) -> (Vec<f64>, u64) {
    let (mut l, mut vel) = (l0.to_vec(), 0.0);
    while vel < v {
        vel = (vel + 40.0 * 1e-3).min(v);
        seq += 1;
        for x in &mut l {
            *x += vel * 1e-3;
        }
        let sp = s.setpoint(seq, &l);
        s.step(Some(&sp));
        assert_eq!(
            s.master.state(),
            BusState::Running,
            "{:?}",
            s.master.feedback().fault_code
        );
    }
    (l, seq + 1)
}

#[test]
fn boot_sequence_uses_nmt_sdo_and_ds402() {
    let mut s = Sim::new();
    s.boot();
    // NMT reset comm first (after drive-io's own heartbeat), addressed to each drive (never
    // broadcast), the SDO start-up script from the EDS (PDO mapping, 0x1017, 0x6060=8,
    // read-backs), NMT start per drive, then RPDO/SYNC.
    let first = s
        .log
        .iter()
        .find(|m| !matches!(m, Message::Heartbeat { node: 0x7F, .. }))
        .unwrap();
    assert!(matches!(
        first,
        Message::Nmt {
            command: canopen::NMT_RESET_COMM,
            node: 1
        }
    ));
    let nmt_nodes = |command| {
        s.log
            .iter()
            .filter_map(|m| match m {
                Message::Nmt { command: c, node } if *c == command => Some(*node),
                _ => None,
            })
            .collect::<Vec<u8>>()
    };
    assert_eq!(nmt_nodes(canopen::NMT_RESET_COMM), vec![1, 2, 3, 4]);
    assert_eq!(nmt_nodes(canopen::NMT_START), vec![1, 2, 3, 4]);
    let sdo_mode = s.log.iter().filter(|m| matches!(m, Message::SdoRequest { data, .. } if data[0] == 0x2F && data[1] == 0x60 && data[2] == 0x60 && data[4] == 8)).count();
    assert_eq!(sdo_mode, 4, "one 0x6060 = 8 write per drive");
    // TPDO2 mapping entry 2 = 0x2110 (pulley force, 32 bit) written and read back per drive.
    let map_write = s.log.iter().filter(|m| matches!(m, Message::SdoRequest { data, .. } if data[0] == 0x23 && data[1..4] == [0x01, 0x1A, 2] && data[4..8] == [0x20, 0, 0x10, 0x21])).count();
    let map_read = s.log.iter().filter(|m| matches!(m, Message::SdoRequest { data, .. } if data[0] == 0x40 && data[1..4] == [0x01, 0x1A, 2])).count();
    assert_eq!((map_write, map_read), (4, 4));
    for sl in &s.slaves {
        assert_eq!(sl.od_value(0x6007, 0), Some(2), "0x6007 = disable voltage");
        assert_eq!(
            sl.od_value(0x605A, 0),
            Some(6),
            "0x605A = stay in quick stop"
        );
        assert_eq!(sl.od_value(0x1016, 1), Some((0x7F << 16) | 600));
    }
    let start = s
        .log
        .iter()
        .position(|m| {
            matches!(
                m,
                Message::Nmt {
                    command: canopen::NMT_START,
                    ..
                }
            )
        })
        .unwrap();
    let first_sync = s
        .log
        .iter()
        .position(|m| matches!(m, Message::Sync))
        .unwrap();
    assert!(start < first_sync);
    for sl in &s.slaves {
        assert_eq!(sl.ds402_state(), Ds402State::OperationEnabled);
        assert_eq!(sl.mode_of_operation(), 8);
    }
}

#[test]
fn follows_setpoints_and_reports_feedback() {
    let mut s = Sim::new();
    s.boot();
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    let mut seq = 0;
    for k in 1..=400 {
        seq += 1;
        let l: Vec<f64> = l0
            .iter()
            .map(|x| x + 0.1 * smoothstep(k as f64 / 400.0))
            .collect();
        let sp = s.setpoint(seq, &l);
        s.step(Some(&sp));
        assert_eq!(s.master.state(), BusState::Running);
    }
    for _ in 0..50 {
        seq += 1;
        let l: Vec<f64> = l0.iter().map(|x| x + 0.1).collect();
        let sp = s.setpoint(seq, &l);
        s.step(Some(&sp));
    }
    let fb = s.master.feedback();
    #[allow(clippy::needless_range_loop)] // indexes three parallel arrays
    for i in 0..4 {
        assert!(
            (fb.cable_length_m[i] - (l0[i] + 0.1)).abs() < 1e-6,
            "winch {i}: {}",
            fb.cable_length_m[i]
        );
        assert!((s.axes[i].length_m - fb.cable_length_m[i]).abs() < 1e-6);
        assert!((fb.cable_force_n[i] - 1.0).abs() < 1e-9);
    }
    assert_eq!(fb.applied_setpoint_sequence, seq);
}

#[test]
fn stale_setpoints_quick_stop_after_exactly_the_configured_cycles() {
    let mut s = Sim::new();
    s.boot();
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    let sp = s.setpoint(1, &l0);
    s.step(Some(&sp));
    let limit = s.cfg.bus.stale_setpoint_cycles;
    // Re-sending the SAME sequence number is not a new setpoint.
    for _ in 0..limit {
        s.step(Some(&sp));
        assert_eq!(s.master.state(), BusState::Running);
    }
    s.step(Some(&sp));
    assert_eq!(s.master.state(), BusState::StaleStop);
    s.step(None);
    assert!(
        s.slaves
            .iter()
            .all(|sl| sl.ds402_state() == Ds402State::QuickStopActive)
    );
    // New setpoints after the stop are ignored: latched until a Reset event.
    let far: Vec<f64> = l0.iter().map(|x| x + 0.001).collect();
    let before: Vec<f64> = s.axes.iter().map(|a| a.length_m).collect();
    for k in 0..20 {
        let sp = s.setpoint(2 + k, &far);
        s.step(Some(&sp));
    }
    assert_eq!(s.master.state(), BusState::StaleStop);
    for (a, b) in s.axes.iter().zip(before) {
        assert_eq!(a.length_m, b);
    }
}

#[test]
fn heartbeat_loss_faults_and_stops_all() {
    let mut s = Sim::new();
    s.boot();
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    s.mute = Some(1);
    let timeout_cycles = s.cfg.bus.heartbeat_timeout_ms as u64;
    let mut seq = 0;
    let mut faulted_at = None;
    for k in 0..(timeout_cycles + 100) {
        seq += 1;
        let sp = s.setpoint(seq, &l0);
        s.step(Some(&sp));
        if s.master.state() == BusState::Fault {
            faulted_at = Some(k);
            break;
        }
    }
    let k = faulted_at.expect("fault after heartbeat loss");
    // Last heartbeat <= 20 ms before muting; fault strictly after the timeout, within one period.
    assert!(
        k + 20 >= timeout_cycles && k <= timeout_cycles + 1,
        "fault after {k} cycles"
    );
    let fb = s.master.feedback();
    assert_eq!(fb.fault().unwrap(), FaultCode::HeartbeatLost);
    assert_eq!(fb.fault_node, u32::from(s.cfg.winches[1].node_id));
    s.step(None);
    assert!(
        s.slaves
            .iter()
            .all(|sl| sl.ds402_state() == Ds402State::QuickStopActive)
    );
}

#[test]
fn invalid_setpoints_fault_without_moving() {
    for bad in [f64::NAN, -1.0, 1e9] {
        let mut s = Sim::new();
        s.boot();
        let mut l: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
        l[2] = bad;
        let sp = s.setpoint(1, &l);
        s.step(Some(&sp));
        assert_eq!(s.master.state(), BusState::Fault);
        assert_eq!(
            s.master.feedback().fault().unwrap(),
            FaultCode::SetpointInvalid,
            "{bad}"
        );
    }
    // A jump larger than max speed * period is refused, too: first setpoint away from the hold
    // position, and later a step implying > 5 m/s on the stream's own clock.
    let mut s = Sim::new();
    s.boot();
    let l: Vec<f64> = s.master.feedback().cable_length_m[..4]
        .iter()
        .map(|x| x + 0.0055)
        .collect();
    let sp = s.setpoint(1, &l);
    s.step(Some(&sp));
    assert_eq!(
        s.master.feedback().fault().unwrap(),
        FaultCode::SetpointStep
    );
    let mut s = Sim::new();
    s.boot();
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    let sp = s.setpoint(1, &l0);
    s.step(Some(&sp));
    // At 4.5 m/s (reached at the allowed acceleration) 4.5 mm in 1 ms is accepted; a step of
    // 5.5 mm (5.5 m/s, within the acceleration limit of one period? no matter) is not.
    let (l1, seq) = ramp_up(&mut s, &l0, 4.5, 1);
    let l: Vec<f64> = l1.iter().map(|x| x + 0.0045).collect();
    let sp = s.setpoint(seq, &l);
    s.step(Some(&sp));
    assert_eq!(s.master.state(), BusState::Running);
    let l: Vec<f64> = l.iter().map(|x| x + 0.0055).collect();
    let sp = s.setpoint(seq + 1, &l); // stamped 1 ms after the previous one
    s.step(Some(&sp));
    assert_eq!(
        s.master.feedback().fault().unwrap(),
        FaultCode::SetpointStep
    );
    // Wrong cable count.
    let mut s = Sim::new();
    s.boot();
    let sp = s.setpoint(1, &[5.0; 3]);
    s.step(Some(&sp));
    assert_eq!(
        s.master.feedback().fault().unwrap(),
        FaultCode::SetpointInvalid
    );
}

#[test]
fn emcy_and_drive_fault_stop_all() {
    let mut s = Sim::new();
    s.boot();
    let mut out = FrameBuf::default();
    s.slaves[3].raise_fault(0x2310, &mut out);
    s.deliver_to_master(&out);
    s.step(None);
    assert_eq!(s.master.state(), BusState::Fault);
    let fb = s.master.feedback();
    assert_eq!(
        (fb.fault().unwrap(), fb.fault_node, fb.last_emcy_code),
        (FaultCode::Emcy, 4, 0x2310)
    );
    s.step(None);
    for (i, sl) in s.slaves.iter().enumerate() {
        let want = if i == 3 {
            Ds402State::Fault
        } else {
            Ds402State::QuickStopActive
        };
        assert_eq!(sl.ds402_state(), want);
    }
}

#[test]
fn a_force_beyond_the_hard_limit_stops_all_drives_on_drive_ios_own() {
    let mut s = Sim::new();
    assert_eq!(s.cfg.bus.force_hard_limit_n, 14_000.0);
    s.boot();
    let l: Vec<f64> = s.axes.iter().map(|a| a.length_m).collect();
    // Just below the rating on every cable, and a large sensor reading while booting: no fault.
    s.force_mn = vec![13_999_000; 8];
    for k in 1..20 {
        let sp = s.setpoint(k, &l);
        s.step(Some(&sp));
    }
    assert_eq!(s.master.state(), BusState::Running);
    let n = s.slaves.len();
    assert_eq!(
        &s.master.feedback().cable_force_n[..n],
        &vec![13_999.0; n][..],
        "drive-io reports what the drives measure"
    );
    s.force_mn[2] = 14_000_001;
    let sp = s.setpoint(20, &l);
    s.step(Some(&sp));
    s.step(None);
    assert_eq!(s.master.state(), BusState::Fault);
    let fb = s.master.feedback();
    assert_eq!(
        (fb.fault().unwrap(), fb.fault_node),
        (FaultCode::ForceLimit, 3)
    );
    s.step(None);
    assert!(
        s.slaves
            .iter()
            .all(|sl| sl.ds402_state() == Ds402State::QuickStopActive),
        "every drive quick-stopped"
    );
    // A broken sensor reading a huge negative force stops too.
    let mut s = Sim::new();
    s.boot();
    s.force_mn[0] = -20_000_000;
    let sp = s.setpoint(1, &l);
    s.step(Some(&sp));
    s.step(None);
    assert_eq!(s.master.feedback().fault().unwrap(), FaultCode::ForceLimit);
}

#[test]
fn the_step_limit_runs_on_drive_ios_own_clock_not_the_senders_timestamps() {
    let start = |s: &mut Sim| {
        s.boot();
        let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
        let sp = s.setpoint(1, &l0);
        s.step(Some(&sp));
        assert_eq!(s.master.state(), BusState::Running);
        l0
    };
    // A setpoint claiming to be 100 ms newer (timestamp lies) with a 50 mm step: refused —
    // before, the sender's timestamps allowed up to 100 periods (0.5 m) in one SYNC.
    let mut s = Sim::new();
    let l0 = start(&mut s);
    let l: Vec<f64> = l0.iter().map(|x| x + 0.05).collect();
    let mut sp = s.setpoint(2, &l);
    sp.timestamp_ns += 100_000_000;
    s.step(Some(&sp));
    assert_eq!(
        s.master.feedback().fault().unwrap(),
        FaultCode::SetpointStep
    );
    // Sequence numbers that jump by 100 do not buy more than drive-io's own time + 1 period.
    let mut s = Sim::new();
    let l0 = start(&mut s);
    let mut sp = s.setpoint(101, &l);
    sp.timestamp_ns += 100_000_000;
    s.step(Some(&sp));
    assert_eq!(
        s.master.feedback().fault().unwrap(),
        FaultCode::SetpointStep
    );
    let _ = l0;
    // Two setpoints within one SYNC (phase slip): 2 periods of motion (9 mm at 4.5 m/s) pass.
    let mut s = Sim::new();
    let l0 = start(&mut s);
    let (l1, seq) = ramp_up(&mut s, &l0, 4.5, 1);
    let l: Vec<f64> = l1.iter().map(|x| x + 0.009).collect();
    let sp = s.setpoint(seq + 1, &l);
    s.step(Some(&sp));
    assert_eq!(s.master.state(), BusState::Running);
    // After 10 SYNCs without a new setpoint the drives held; a setpoint 10 periods of motion
    // away (45 mm, sequence +10) passes on drive-io's own elapsed time.
    for _ in 0..9 {
        s.step(None);
    }
    let l: Vec<f64> = l.iter().map(|x| x + 0.045).collect();
    let sp = s.setpoint(seq + 11, &l);
    s.step(Some(&sp));
    assert_eq!(
        s.master.state(),
        BusState::Running,
        "{:?}",
        s.master.feedback().fault_code
    );
}

/// A hold is zero speed: the first step out of it may change the cable's speed by at most
/// max_cable_acceleration × one period — a stream that jumps from rest to 4.5 m/s (within the
/// speed limit, the "violent start from rest") faults SETPOINT_STEP without moving;
/// the same speed reached at the allowed acceleration runs; braking to a hold at once is
/// allowed.
#[test]
fn a_step_out_of_a_hold_is_acceleration_checked() {
    // From Ready (enabled, holding): 4.5 mm in the first period.
    let mut s = Sim::new();
    s.boot();
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    let sp = s.setpoint(1, &l0);
    s.step(Some(&sp));
    let l: Vec<f64> = l0.iter().map(|x| x + 0.0045).collect();
    let sp = s.setpoint(2, &l);
    s.step(Some(&sp));
    assert_eq!(
        s.master.feedback().fault().unwrap(),
        FaultCode::SetpointStep
    );
    for _ in 0..20 {
        s.step(None);
    }
    let moved: f64 = s
        .axes
        .iter()
        .zip(&l0)
        .map(|(a, l)| (a.length_m - l).abs())
        .fold(0.0, f64::max);
    assert!(moved < 1e-4, "the jump was applied: {moved} m");
    // Out of a hold while running (the stream stood still for 30 periods, then jumps).
    let mut s = Sim::new();
    s.boot();
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    for k in 1..=30 {
        let sp = s.setpoint(k, &l0);
        s.step(Some(&sp));
    }
    assert_eq!(s.master.state(), BusState::Running);
    let l: Vec<f64> = l0.iter().map(|x| x + 0.0045).collect();
    let sp = s.setpoint(31, &l);
    s.step(Some(&sp));
    assert_eq!(
        s.master.feedback().fault().unwrap(),
        FaultCode::SetpointStep
    );
    // The same speed reached at the allowed acceleration, then an abrupt hold: fine.
    let mut s = Sim::new();
    s.boot();
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    let sp = s.setpoint(1, &l0);
    s.step(Some(&sp));
    let (l1, seq) = ramp_up(&mut s, &l0, 4.5, 1);
    for k in 0..10 {
        let sp = s.setpoint(seq + k, &l1);
        s.step(Some(&sp));
        assert_eq!(s.master.state(), BusState::Running);
    }
}

/// The acceleration check takes the step's speed over its sequence numbers (bounded by
/// drive-io's own time + 2 periods): at constant speed, a setpoint superseded before drive-io
/// read it leaves a step of two sequence numbers, and its successor may be read a fraction of
/// a period after the previous one. That is no speed jump and must run on; the same step with
/// one sequence number (twice the speed at once) faults SETPOINT_STEP.
#[test]
fn a_superseded_setpoints_successor_read_early_is_no_speed_jump() {
    for (gap, faults) in [(2u64, false), (1, true)] {
        let mut s = Sim::new();
        s.boot();
        let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
        let sp = s.setpoint(1, &l0);
        s.step(Some(&sp));
        let v = 2.0;
        let (mut l, mut seq) = ramp_up(&mut s, &l0, v, 1);
        for _ in 0..10 {
            for x in &mut l {
                *x += v * 1e-3;
            }
            let sp = s.setpoint(seq, &l);
            s.step(Some(&sp));
            seq += 1;
        }
        assert_eq!(s.master.state(), BusState::Running);
        let superseded = s.master.superseded_setpoints();
        // Two periods of motion at v, read 0.2 periods after the previous setpoint.
        for x in &mut l {
            *x += 2.0 * v * 1e-3;
        }
        seq += gap - 1;
        let sp = s.setpoint(seq, &l);
        s.step_after(Some(&sp), 200_000);
        if faults {
            assert_eq!(
                s.master.feedback().fault().unwrap(),
                FaultCode::SetpointStep,
                "a doubled speed within one sequence number must fault"
            );
            continue;
        }
        assert_eq!(
            s.master.state(),
            BusState::Running,
            "fault {:#x}",
            s.master.feedback().fault_code
        );
        assert_eq!(s.master.superseded_setpoints(), superseded + 1);
        // The stream goes on at v, one setpoint per period.
        for _ in 0..10 {
            seq += 1;
            for x in &mut l {
                *x += v * 1e-3;
            }
            let sp = s.setpoint(seq, &l);
            s.step(Some(&sp));
            assert_eq!(s.master.state(), BusState::Running);
        }
    }
}

#[test]
fn bus_off_or_error_passive_stops_every_drive_and_latches() {
    use can_transport::BusErrorFrame;
    use can_transport::bus_error::{class, crtl};
    for (what, e) in [
        ("bus-off", BusErrorFrame::bus_off()),
        ("error-passive", BusErrorFrame::error_passive(128, 0)),
    ] {
        let mut s = Sim::new();
        s.boot();
        let l: Vec<f64> = s.axes.iter().map(|a| a.length_m).collect();
        for k in 1..5 {
            let sp = s.setpoint(k, &l);
            s.step(Some(&sp));
        }
        assert_eq!(s.master.state(), BusState::Running);
        // A warning level is only logged.
        s.master
            .on_bus_error(&BusErrorFrame::new(class::CRTL, &[0, crtl::TX_WARNING]));
        let sp = s.setpoint(5, &l);
        s.step(Some(&sp));
        assert_eq!(s.master.state(), BusState::Running, "{what}");
        s.master.on_bus_error(&e);
        for k in 6..10 {
            let sp = s.setpoint(k, &l);
            s.step(Some(&sp));
        }
        assert_eq!(s.master.state(), BusState::Fault, "{what}");
        assert!(s.master.is_latched());
        assert_eq!(s.master.feedback().fault().unwrap(), FaultCode::BusError);
        assert!(
            s.slaves
                .iter()
                .all(|sl| sl.ds402_state() == Ds402State::QuickStopActive),
            "{what}: every drive quick-stopped"
        );
    }
}

/// A vendor EDS whose defaults differ from drive-io's layout: RPDO1 maps the controlword only,
/// TPDO1 the statusword only, TPDO2 is disabled and maps the error code; no heartbeat.
fn other_vendor_defaults() -> Eds {
    let text = BUILTIN_WINCH_EDS
        .replace(
            "[1600sub0]\nParameterName=Number of mapped objects\nObjectType=0x7\nDataType=0x0005\nAccessType=rw\nDefaultValue=2",
            "[1600sub0]\nParameterName=Number of mapped objects\nObjectType=0x7\nDataType=0x0005\nAccessType=rw\nDefaultValue=1",
        )
        .replace(
            "[1A00sub0]\nParameterName=Number of mapped objects\nObjectType=0x7\nDataType=0x0005\nAccessType=rw\nDefaultValue=2",
            "[1A00sub0]\nParameterName=Number of mapped objects\nObjectType=0x7\nDataType=0x0005\nAccessType=rw\nDefaultValue=1",
        )
        .replace("DefaultValue=$NODEID+0x280", "DefaultValue=$NODEID+0x80000280")
        .replace("DefaultValue=0x606C0020", "DefaultValue=0x603F0010");
    assert_ne!(text, BUILTIN_WINCH_EDS);
    Eds::parse(&text, "other-vendor.eds").unwrap()
}

#[test]
fn drives_with_other_default_mappings_are_configured_from_the_eds_and_run() {
    let eds = other_vendor_defaults();
    // Unconfigured, such a drive sends a 2-byte TPDO1 and no TPDO2: useless to drive-io.
    let mut raw = DriveSlave::with_eds(1, &eds, 0);
    let mut out = FrameBuf::default();
    raw.start(0, &mut out);
    raw.handle_frame(&canopen::nmt(canopen::NMT_START, 0), 0, &mut out);
    out.clear();
    raw.transmit_pdos(&mut out);
    assert_eq!(out.len(), 1);
    assert_eq!(out.as_slice()[0].data().len(), 2);

    let mut s = Sim::with_eds(eds.clone(), &eds);
    s.boot();
    for sl in &s.slaves {
        assert_eq!(sl.od_value(0x1A01, 1), Some(0x606C_0020));
        assert_eq!(
            sl.od_value(0x1801, 1),
            Some(0x280 + u32::from(sl.node_id()))
        );
    }
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    for k in 1..=200u64 {
        let l: Vec<f64> = l0
            .iter()
            .map(|x| x + 0.05 * smoothstep(k as f64 / 200.0))
            .collect();
        let sp = s.setpoint(k, &l);
        s.step(Some(&sp));
        assert_eq!(s.master.state(), BusState::Running);
    }
    for k in 201..=250u64 {
        let l: Vec<f64> = l0.iter().map(|x| x + 0.05).collect();
        let sp = s.setpoint(k, &l);
        s.step(Some(&sp));
    }
    for (i, l) in l0.iter().enumerate() {
        let fb = s.master.feedback().cable_length_m[i];
        assert!(
            (fb - (l + 0.05)).abs() < 1e-6,
            "winch {i}: {fb} l0 {} axis {} {:?} {:?}",
            l,
            s.axes[i].length_m,
            s.master.state(),
            s.master.feedback().fault_code
        );
        // Velocity and force arrive through the TPDO2 drive-io mapped.
        assert_eq!(s.master.feedback().cable_force_n[i], 1.0);
    }
}

#[test]
fn a_drive_refusing_an_object_stops_start_up_naming_drive_object_and_abort_code() {
    // drive-io's EDS lists the following error window; the drives do not implement it.
    let drive_eds = Eds::parse(
        &BUILTIN_WINCH_EDS.replace("[6065]", "[2065]"),
        "drive-without-6065.eds",
    )
    .unwrap();
    let mut s = Sim::with_eds(Eds::builtin_winch().clone(), &drive_eds);
    for _ in 0..300 {
        s.step(None);
    }
    assert_eq!(s.master.state(), BusState::Fault);
    let msg = s.master.describe_commissioning_fault().unwrap();
    for want in [
        "drive node 1",
        "0x6065sub0 (Following error window)",
        "0x06020000",
        "object does not exist in the object dictionary",
        "write",
    ] {
        assert!(msg.contains(want), "`{want}` missing in: {msg}");
    }
    assert!(
        !s.log.iter().any(|m| matches!(
            m,
            Message::Nmt {
                command: canopen::NMT_START,
                ..
            }
        )),
        "start-up went on"
    );
}

fn estop(s: &mut Sim) {
    let ev = crs_ipc::StateEvent::new(crs_ipc::ProcessId::Test, crs_ipc::EventKind::EStop, 1);
    s.master.on_event(&ev, s.now);
}

fn count(log: &[Message], f: impl Fn(&Message) -> bool) -> usize {
    log.iter().filter(|m| f(m)).count()
}

#[test]
fn quick_stop_acknowledged_by_statusword_and_rest_needs_no_escalation() {
    let mut s = Sim::new();
    s.boot();
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    for k in 1..=100u64 {
        let l: Vec<f64> = l0.iter().map(|x| x + 0.025 * (k as f64 / 100.0)).collect();
        let sp = s.setpoint(k, &l);
        s.step(Some(&sp));
    }
    estop(&mut s);
    s.log.clear();
    for _ in 0..3000 {
        s.step(None);
    }
    assert_eq!(s.master.quick_stop_stage(), 3, "acknowledged");
    for sl in &s.slaves {
        assert_eq!(sl.ds402_state(), Ds402State::QuickStopActive);
    }
    assert_eq!(
        count(&s.log, |m| matches!(
            m,
            Message::Nmt {
                command: canopen::NMT_STOP,
                ..
            }
        )),
        0
    );
    // drive-io's heartbeat keeps coming.
    assert!(
        count(&s.log, |m| matches!(
            m,
            Message::Heartbeat { node: 0x7F, .. }
        )) >= 290
    );
}

#[test]
fn an_unacknowledged_quick_stop_escalates_to_nmt_stop_then_heartbeat_inhibit() {
    let mut s = Sim::new();
    s.boot();
    s.dead = Some(1); // drive 2 stops answering (no TPDO, no heartbeat)
    estop(&mut s);
    s.log.clear();
    let timeout = u64::from(s.cfg.bus.quick_stop_timeout_ms);
    for _ in 0..timeout - 5 {
        s.step(None);
    }
    assert_eq!(s.master.quick_stop_stage(), 0);
    for _ in 0..10 {
        s.step(None);
    }
    // Stage 1: NMT stop of every drive (addressed to each); the live ones act per 0x6007 = 2
    // (disable voltage).
    assert_eq!(s.master.quick_stop_stage(), 1);
    for node in 1..=4 {
        assert_eq!(
            count(&s.log, |m| *m
                == Message::Nmt {
                    command: canopen::NMT_STOP,
                    node
                }),
            1
        );
    }
    assert_eq!(
        count(&s.log, |m| *m
            == Message::Nmt {
                command: canopen::NMT_STOP,
                node: 0
            }),
        0,
        "no broadcast"
    );
    assert_eq!(s.slaves[0].nmt_state(), canopen::NmtState::Stopped);
    assert_eq!(s.slaves[0].ds402_state(), Ds402State::SwitchOnDisabled);
    assert_eq!(s.slaves[0].demand(), MotionDemand::Hold);
    // Stage 2: drive 2 never reports NMT stopped => drive-io withholds its heartbeat.
    for _ in 0..timeout + 10 {
        s.step(None);
    }
    assert_eq!(s.master.quick_stop_stage(), 2);
    s.log.clear();
    for _ in 0..100 {
        s.step(None);
    }
    assert_eq!(
        count(&s.log, |m| matches!(
            m,
            Message::Heartbeat { node: 0x7F, .. }
        )),
        0
    );
}

#[test]
fn reset_after_an_escalation_restarts_the_drives_and_the_heartbeat() {
    let mut s = Sim::new();
    s.boot();
    // A drive that does not acknowledge (muted TPDOs would be the same): its TPDO is stale.
    s.dead = Some(3);
    estop(&mut s);
    for _ in 0..2 * s.cfg.bus.quick_stop_timeout_ms + 20 {
        s.step(None);
    }
    assert_eq!(s.master.quick_stop_stage(), 2);
    // The drive comes back; the monitor's reset (a grant) re-enables everything.
    s.dead = None;
    for _ in 0..50 {
        s.step(None);
    }
    s.log.clear();
    let mut ev = crs_ipc::StateEvent::new(
        crs_ipc::ProcessId::SafetyMonitor,
        crs_ipc::EventKind::Reset,
        2,
    );
    ev.detail = 1;
    ev.timestamp_ns = s.now;
    let grant = drive_io::reset::ResetGate::new()
        .check_unauthenticated(&ev, s.now)
        .unwrap();
    assert_eq!(s.master.reset(grant, s.now).ok(), Some(1));
    for _ in 0..200 {
        s.step(None);
        if s.master.state() == BusState::Ready {
            break;
        }
    }
    assert_eq!(s.master.state(), BusState::Ready);
    for node in 1..=4 {
        assert_eq!(
            count(&s.log, |m| *m
                == Message::Nmt {
                    command: canopen::NMT_START,
                    node
                }),
            1
        );
    }
    assert!(
        count(&s.log, |m| matches!(
            m,
            Message::Heartbeat { node: 0x7F, .. }
        )) > 0
    );
    for sl in &s.slaves {
        assert_eq!(sl.ds402_state(), Ds402State::OperationEnabled);
        assert_eq!(sl.nmt_state(), canopen::NmtState::Operational);
    }
}

/// After a reset the drives' velocity and force TPDOs come back some cycles after their
/// statusword: drive-io waits for fresh ones before Ready, as at start-up, instead of judging
/// the stamps from before the stop (a TPDO timeout right after the reset).
#[test]
fn reset_waits_for_fresh_tpdos_before_ready() {
    let mut s = Sim::new();
    s.boot();
    estop(&mut s);
    // Stopped for longer than the TPDO timeout (300 ms): the last stamps are stale.
    for _ in 0..2 * s.cfg.bus.quick_stop_timeout_ms + 400 {
        s.step(None);
    }
    let mut ev = crs_ipc::StateEvent::new(
        crs_ipc::ProcessId::SafetyMonitor,
        crs_ipc::EventKind::Reset,
        2,
    );
    ev.detail = 1;
    ev.timestamp_ns = s.now;
    let grant = drive_io::reset::ResetGate::new()
        .check_unauthenticated(&ev, s.now)
        .unwrap();
    assert_eq!(s.master.reset(grant, s.now).ok(), Some(1));
    s.tpdo2_late = 30;
    let mut ready_at = None;
    for k in 0..300 {
        s.step(None);
        assert_ne!(
            s.master.state(),
            BusState::Fault,
            "cycle {k} after the reset: fault {:?} node {}",
            s.master.feedback().fault(),
            s.master.feedback().fault_node
        );
        if ready_at.is_none() && s.master.state() == BusState::Ready {
            ready_at = Some(k);
        }
    }
    let k = ready_at.expect("Ready after the reset");
    assert!(
        k >= 30,
        "Ready in cycle {k}, before any fresh TPDO2 arrived"
    );
}

/// Four winches on one interface, lenient timeouts (virtual time needs none of them tight).
fn rig_config() -> DrivesConfig {
    let mut text = String::from(
        "[bus]\ntransport = \"udpbus:239.255.0.1:1\"\nsync_period_us = 1000\n\
         stale_setpoint_cycles = 50\nheartbeat_producer_ms = 20\nheartbeat_timeout_ms = 300\n\
         boot_timeout_ms = 20000\nsdo_timeout_ms = 500\nmax_cable_speed_m_per_s = 5.0\n\
         drive_heartbeat_consumer_ms = 600\nfollowing_error_window_m = 0.5\n",
    );
    for i in 0..4 {
        let sign = if i % 2 == 0 { 1 } else { -1 };
        text.push_str(&format!(
            "[[winch]]\nnode_id = {}\ndrum_diameter_m = 0.305\ngear_ratio = 10.0\n\
             counts_per_rev = 1048576\nsign = {sign}\noffset_counts = {}\n",
            i + 1,
            if sign > 0 { 0 } else { 200_000_000 }
        ));
    }
    DrivesConfig::parse(&text).unwrap()
}

/// motion-core's end-of-stream announcement from `source`.
fn stream_end(source: crs_ipc::ProcessId) -> crs_ipc::StateEvent {
    let mut ev = crs_ipc::StateEvent::new(source, crs_ipc::EventKind::StateChanged, 9);
    ev.state = u32::from(crs_ipc::MotionState::Stopping);
    ev
}

#[test]
fn a_planned_end_at_rest_holds_the_drives_enabled_without_a_quick_stop() {
    let mut s = Sim::new();
    s.boot();
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    for seq in 1..=10 {
        let sp = s.setpoint(seq, &l0);
        s.step(Some(&sp));
    }
    assert_eq!(s.master.state(), BusState::Running);
    let now = s.now;
    s.master
        .on_event(&stream_end(crs_ipc::ProcessId::MotionCore), now);
    for _ in 0..(s.cfg.bus.stale_setpoint_cycles + 20) {
        s.step(None);
    }
    assert_eq!(s.master.state(), BusState::Ready);
    assert!(
        s.slaves
            .iter()
            .all(|sl| sl.ds402_state() == Ds402State::OperationEnabled),
        "a planned end quick-stopped the drives"
    );
    // A new stream (sequence numbers from 1 again) is followed.
    let sp = s.setpoint(1, &l0);
    s.step(Some(&sp));
    assert_eq!(s.master.state(), BusState::Running);
    // ... and its silence without a new announcement is stale again.
    for _ in 0..(s.cfg.bus.stale_setpoint_cycles + 2) {
        s.step(None);
    }
    assert_eq!(s.master.state(), BusState::StaleStop);
}

#[test]
fn an_announced_end_in_motion_or_from_another_process_is_still_a_stale_stop() {
    for (moving, source) in [
        (true, crs_ipc::ProcessId::MotionCore),
        (false, crs_ipc::ProcessId::Operator),
    ] {
        let mut s = Sim::new();
        s.boot();
        let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
        for seq in 1..=10 {
            let mut sp = s.setpoint(seq, &l0);
            if moving {
                sp.cable_velocity_m_per_s[0] = 0.01;
            }
            s.step(Some(&sp));
        }
        let now = s.now;
        s.master.on_event(&stream_end(source), now);
        for _ in 0..(s.cfg.bus.stale_setpoint_cycles + 2) {
            s.step(None);
        }
        assert_eq!(
            s.master.state(),
            BusState::StaleStop,
            "moving {moving}, source {source:?}"
        );
    }
}

/// The log lines a test's code emits: level and message of every event of one closure on
/// this thread. One process-wide subscriber routes each event to the capture of its thread:
/// a subscriber set per thread (`with_default`) lost events now and then while tests ran in
/// parallel (tracing caches a call site's interest process-wide, and a site first reached
/// on a thread without that subscriber can be cached as uninteresting).
#[derive(Clone, Default)]
struct Capture(Lines);

type Lines = std::sync::Arc<std::sync::Mutex<Vec<(tracing::Level, String)>>>;

thread_local! {
    static CAPTURING: std::cell::RefCell<Option<Lines>> = const { std::cell::RefCell::new(None) };
}

impl Capture {
    fn run<R>(&self, f: impl FnOnce() -> R) -> R {
        static ROUTER: std::sync::Once = std::sync::Once::new();
        ROUTER.call_once(|| {
            tracing::subscriber::set_global_default(Router).expect("the only global subscriber");
        });
        tracing::callsite::rebuild_interest_cache();
        CAPTURING.with(|c| *c.borrow_mut() = Some(self.0.clone()));
        let r = f();
        CAPTURING.with(|c| *c.borrow_mut() = None);
        r
    }
    fn take(&self) -> Vec<(tracing::Level, String)> {
        std::mem::take(&mut *self.0.lock().unwrap())
    }
}

/// The process-wide subscriber of [`Capture`].
struct Router;

impl tracing::Subscriber for Router {
    fn enabled(&self, _: &tracing::Metadata<'_>) -> bool {
        true
    }
    fn new_span(&self, _: &tracing::span::Attributes<'_>) -> tracing::span::Id {
        tracing::span::Id::from_u64(1)
    }
    fn record(&self, _: &tracing::span::Id, _: &tracing::span::Record<'_>) {}
    fn record_follows_from(&self, _: &tracing::span::Id, _: &tracing::span::Id) {}
    fn event(&self, e: &tracing::Event<'_>) {
        struct Message(String);
        impl tracing::field::Visit for Message {
            fn record_debug(&mut self, f: &tracing::field::Field, v: &dyn std::fmt::Debug) {
                if f.name() == "message" {
                    self.0 = format!("{v:?}");
                }
            }
        }
        CAPTURING.with(|c| {
            if let Some(lines) = &*c.borrow() {
                let mut m = Message(String::new());
                e.record(&mut m);
                lines.lock().unwrap().push((*e.metadata().level(), m.0));
            }
        });
    }
    fn enter(&self, _: &tracing::span::Id) {}
    fn exit(&self, _: &tracing::span::Id) {}
}

fn errors(lines: &[(tracing::Level, String)]) -> Vec<&str> {
    lines
        .iter()
        .filter(|(l, _)| *l == tracing::Level::ERROR)
        .map(|(_, m)| m.as_str())
        .collect()
}

/// The safety monitor's cycle on the bus: its configuration signature and a RUN pair.
fn monitor_cycle(w: &mut drive_bus::safety_watch::SafetyWatch, counter: u16, t: u64) {
    use can_transport::safety_frame::{ConfigSignature, SafetyHeartbeat, SafetyState, encode};
    let cob = w.config().cob_id;
    let sig = ConfigSignature {
        srdo_crc: w.config().srdo_crc(),
        safety_params_crc: 0x1234_5678,
    }
    .encode(cob);
    let hb = encode(
        &SafetyHeartbeat {
            state: SafetyState::Run,
            cause: 0,
            counter,
            epoch: 1,
        },
        cob,
    );
    for f in sig.iter().chain(&hb) {
        w.on_frame(f, t);
    }
}

/// Booted, the watch permitting on three monitor cycles, the drives following a slow ramp
/// (Running); returns the watch, the last lengths, the next sequence number and the counter.
fn running_with_watch(s: &mut Sim) -> (drive_bus::safety_watch::SafetyWatch, Vec<f64>, u64, u16) {
    use drive_bus::safety_watch::{SafetyWatch, SafetyWatchConfig};
    s.boot();
    let mut w = SafetyWatch::new(SafetyWatchConfig::default());
    for k in 0..3u16 {
        monitor_cycle(&mut w, k + 1, s.now - u64::from(2 - k) * 15_000_000);
    }
    assert!(s.master.supervise_safety_heartbeat(&mut w, s.now));
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    let (l, seq) = ramp_up(s, &l0, 0.02, 1);
    (w, l, seq, 3)
}

/// One runner cycle: the watch's verdict, then the master's cycle with a setpoint that holds
/// the cable speed (`l` advanced by `v` m per ms).
fn runner_cycle(
    s: &mut Sim,
    w: &mut drive_bus::safety_watch::SafetyWatch,
    l: &mut [f64],
    seq: &mut u64,
) -> bool {
    let permit = s.master.supervise_safety_heartbeat(w, s.now + 1_000_000);
    for x in l.iter_mut() {
        *x += 0.02e-3;
    }
    let sp = s.setpoint(*seq, l);
    *seq += 1;
    s.step(Some(&sp));
    permit
}

/// The monitor dies mid-ride: the safety I/O node's STO (on the same missing heartbeat)
/// reaches the drives before drive-io's validation time runs out. That is the safety stop,
/// not a fault of every drive: one error line (the trip, naming the overdue heartbeat and the
/// drives off), the quick stop at warning, bus state EStop; nothing more while it holds.
#[test]
fn drives_torque_off_under_a_missing_heartbeat_is_one_e_stop_line() {
    use drive_bus::safety_watch::{InhibitReason, WatchState};
    let cap = Capture::default();
    let mut s = Sim::new();
    let (mut w, mut l, mut seq) = cap.run(|| {
        let (w, l, seq, _) = running_with_watch(&mut s);
        (w, l, seq)
    });
    assert_eq!(s.master.state(), BusState::Running);
    let silent_from = s.now;
    cap.take();
    cap.run(|| {
        // No pair from here on; 35 ms later (overdue, within the 50 ms validation time) the
        // I/O node removes the drives' torque.
        while s.now < silent_from + 35_000_000 {
            assert!(runner_cycle(&mut s, &mut w, &mut l, &mut seq));
            assert_eq!(s.master.state(), BusState::Running);
        }
        for sl in &mut s.slaves {
            sl.set_sto(true);
        }
        for _ in 0..300 {
            runner_cycle(&mut s, &mut w, &mut l, &mut seq);
        }
    });
    let lines = cap.take();
    assert_eq!(
        errors(&lines),
        ["safety heartbeat invalid or missing: e-stop"],
        "{lines:#?}"
    );
    assert!(
        lines.iter().any(|(lv, m)| *lv == tracing::Level::WARN
            && m == "drive bus stopping: quick stop all drives (e-stop)"),
        "{lines:#?}"
    );
    assert_eq!(s.master.state(), BusState::EStop);
    assert_eq!(s.master.feedback().fault().unwrap(), FaultCode::None);
    assert!(
        matches!(
            w.state(),
            WatchState::Inhibit(InhibitReason::Overdue { drives_off: 4, silent_ms }) if silent_ms < 50
        ),
        "{:?}",
        w.state()
    );
    assert_eq!(w.trips(), 1);
}

/// The same drives' stop while the monitor's pairs keep arriving on time: no stop was
/// commanded, so a drive that leaves Operation Enabled is still a fault of that drive.
#[test]
fn a_drive_leaving_operation_under_a_live_heartbeat_is_still_a_fault() {
    use drive_bus::safety_watch::WatchState;
    let cap = Capture::default();
    let mut s = Sim::new();
    let (mut w, mut l, mut seq, mut counter) = cap.run(|| running_with_watch(&mut s));
    cap.take();
    cap.run(|| {
        for k in 0..200u64 {
            if k % 15 == 0 {
                counter += 1;
                monitor_cycle(&mut w, counter, s.now);
            }
            if k == 40 {
                s.slaves[2].set_sto(true);
            }
            assert!(runner_cycle(&mut s, &mut w, &mut l, &mut seq), "cycle {k}");
        }
    });
    let lines = cap.take();
    assert_eq!(w.state(), WatchState::Permit);
    assert_eq!(s.master.state(), BusState::Fault);
    let fb = s.master.feedback();
    assert_eq!(
        (fb.fault().unwrap(), fb.fault_node),
        (FaultCode::UnexpectedState, 3)
    );
    let e = errors(&lines);
    assert_eq!(e.len(), 2, "{lines:#?}");
    assert!(e[0].starts_with("drive left Operation Enabled"), "{e:?}");
    assert_eq!(e[1], "drive bus stopping: quick stop all drives");
}

/// Every drive switching its torque off at once (no safety watch involved): one event, one
/// line for its cause (the first drive, and how many) and the stop — not one line per drive
/// (it was: "drive ignores the target position" per drive, bit 12 of a statusword in which
/// it is undefined).
#[test]
fn every_drive_switching_off_is_one_fault_line_not_one_per_drive() {
    let cap = Capture::default();
    let mut s = Sim::new();
    s.boot();
    let l0: Vec<f64> = s.master.feedback().cable_length_m[..4].to_vec();
    let (l, mut seq) = ramp_up(&mut s, &l0, 0.02, 1);
    cap.run(|| {
        for sl in &mut s.slaves {
            sl.set_sto(true);
        }
        for _ in 0..100 {
            let sp = s.setpoint(seq, &l);
            seq += 1;
            s.step(Some(&sp));
        }
    });
    let lines = cap.take();
    assert_eq!(s.master.state(), BusState::Fault);
    assert_eq!(
        s.master.feedback().fault().unwrap(),
        FaultCode::UnexpectedState
    );
    assert_eq!(errors(&lines).len(), 2, "{lines:#?}");
}

/// A stall that silences every drive at once (drive-io, or the drives, descheduled): one
/// heartbeat-loss line naming the first node and how many, and the stop — not one per node.
#[test]
fn a_stall_that_silences_every_drive_is_one_heartbeat_line_and_one_stop() {
    let cap = Capture::default();
    let mut s = Sim::new();
    s.boot();
    cap.run(|| {
        let mut out = BusFrames::new(1);
        for k in 1..=400u64 {
            out.clear();
            s.master.cycle(s.now + k * 1_000_000, None, &mut out);
        }
    });
    let lines = cap.take();
    assert_eq!(s.master.state(), BusState::Fault);
    assert_eq!(
        s.master.feedback().fault().unwrap(),
        FaultCode::HeartbeatLost
    );
    assert_eq!(
        errors(&lines),
        [
            "heartbeat lost",
            "drive bus stopping: quick stop all drives"
        ],
        "{lines:#?}"
    );
}
