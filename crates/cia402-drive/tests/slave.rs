//! Drive-side emulation (`cia402_drive::slave`): NMT, SDO, CiA 402 transitions, CSP latching.

use cia402_drive::bank::DriveBank;
use cia402_drive::slave::{DriveSlave, MotionDemand, SlaveEvent, WinchAxis};
use drive_bus::canopen::*;

fn frames(out: &FrameBuf) -> Vec<Message> {
    out.as_slice().iter().map(decode).collect()
}

fn operational(node: u8) -> DriveSlave {
    let mut s = DriveSlave::new(node, 10);
    let mut out = FrameBuf::default();
    s.start(0, &mut out);
    assert_eq!(frames(&out), vec![Message::Heartbeat { node, state: 0x00 }]);
    s.handle_frame(
        &sdo_download(node, OD_MODES_OF_OPERATION, 0, 8, 1),
        0,
        &mut out,
    );
    s.handle_frame(&nmt(NMT_START, node), 0, &mut out);
    assert_eq!(s.nmt_state(), NmtState::Operational);
    s
}

#[test]
fn enable_sequence_and_csp_latching_on_sync() {
    let mut s = operational(3);
    let mut out = FrameBuf::default();
    s.set_actual(1000, 0, 0);
    assert_eq!(s.ds402_state(), Ds402State::SwitchOnDisabled);
    for (cw, want) in [
        (CW_SHUTDOWN, Ds402State::ReadyToSwitchOn),
        (CW_SWITCH_ON, Ds402State::SwitchedOn),
        (CW_ENABLE_OPERATION, Ds402State::OperationEnabled),
    ] {
        s.handle_frame(&rpdo1(3, cw, 1000), 0, &mut out);
        assert_eq!(s.ds402_state(), want);
        assert_eq!(Ds402State::from_statusword(s.statusword()), want);
    }
    // The RPDO target becomes active only at SYNC (CSP).
    s.handle_frame(&rpdo1(3, CW_ENABLE_OPERATION, 5000), 0, &mut out);
    assert_eq!(
        s.demand(),
        MotionDemand::Follow {
            target_counts: 1000
        }
    );
    assert_eq!(s.handle_frame(&sync(), 0, &mut out), SlaveEvent::Sync);
    assert_eq!(
        s.demand(),
        MotionDemand::Follow {
            target_counts: 5000
        }
    );
    out.clear();
    s.set_actual(1234, -5, 777);
    s.transmit_pdos(&mut out);
    assert_eq!(
        frames(&out),
        vec![
            Message::Tpdo1 {
                node: 3,
                statusword: 0x1237,
                position_counts: 1234
            },
            Message::Tpdo2 {
                node: 3,
                velocity_counts_per_s: -5,
                force_mn: 777
            },
        ]
    );
    // Frames for other nodes are ignored.
    s.handle_frame(&rpdo1(4, CW_QUICK_STOP, 0), 0, &mut out);
    assert_eq!(s.ds402_state(), Ds402State::OperationEnabled);
    // Quick stop -> QuickStopActive, demand QuickStop; disable voltage -> SwitchOnDisabled.
    s.handle_frame(&rpdo1(3, CW_QUICK_STOP, 5000), 0, &mut out);
    assert_eq!(s.demand(), MotionDemand::QuickStop);
    s.handle_frame(&rpdo1(3, CW_DISABLE_VOLTAGE, 5000), 0, &mut out);
    assert_eq!(s.ds402_state(), Ds402State::SwitchOnDisabled);
    assert_eq!(s.demand(), MotionDemand::Hold);
}

#[test]
fn nmt_stop_acts_per_0x6007() {
    // EDS default 0x6007 = 0 (no action): the drive keeps following its last target, no brake.
    let mut s = operational(1);
    let mut out = FrameBuf::default();
    for cw in [CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION] {
        s.handle_frame(&rpdo1(1, cw, 0), 0, &mut out);
    }
    s.handle_frame(&nmt(NMT_STOP, 0), 0, &mut out);
    assert_eq!(s.demand(), MotionDemand::Follow { target_counts: 0 });
    // 3 = quick stop.
    let mut s = operational(1);
    s.handle_frame(&sdo_download(1, 0x6007, 0, 3, 2), 0, &mut out);
    for cw in [CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION] {
        s.handle_frame(&rpdo1(1, cw, 0), 0, &mut out);
    }
    s.handle_frame(&nmt(NMT_STOP, 0), 0, &mut out);
    assert_eq!(s.ds402_state(), Ds402State::QuickStopActive);
    assert_eq!(s.demand(), MotionDemand::QuickStop);
}

#[test]
fn nmt_stop_holds_and_silences_pdos() {
    let mut s = operational(1);
    let mut out = FrameBuf::default();
    // 0x6007 = 2 (disable voltage: the brake holds), what drive-io configures.
    s.handle_frame(&sdo_download(1, 0x6007, 0, 2, 2), 0, &mut out);
    for cw in [CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION] {
        s.handle_frame(&rpdo1(1, cw, 0), 0, &mut out);
    }
    out.clear();
    s.handle_frame(&nmt(NMT_STOP, 0), 0, &mut out);
    assert_eq!(s.demand(), MotionDemand::Hold);
    out.clear();
    assert_eq!(s.handle_frame(&sync(), 0, &mut out), SlaveEvent::None);
    s.transmit_pdos(&mut out);
    // RPDOs and SDOs are ignored in Stopped; heartbeats continue with state 0x04.
    s.handle_frame(&rpdo1(1, CW_QUICK_STOP, 99), 0, &mut out);
    s.handle_frame(&sdo_upload(1, OD_STATUSWORD, 0), 0, &mut out);
    assert!(out.is_empty());
    s.poll(20_000_000, &mut out);
    assert_eq!(
        frames(&out),
        vec![Message::Heartbeat {
            node: 1,
            state: 0x04
        }]
    );
    s.set_heartbeat_muted(true);
    out.clear();
    s.poll(40_000_000, &mut out);
    assert!(out.is_empty());
}

#[test]
fn sdo_server_answers_and_aborts() {
    let mut s = DriveSlave::new(2, 0);
    let mut out = FrameBuf::default();
    s.start(0, &mut out);
    out.clear();
    let ask = |s: &mut DriveSlave, f| {
        let mut o = FrameBuf::default();
        s.handle_frame(&f, 0, &mut o);
        match decode(&o.as_slice()[0]) {
            Message::SdoResponse { node: 2, data } => parse_sdo_response(&data),
            m => panic!("{m:?}"),
        }
    };
    assert_eq!(
        ask(&mut s, sdo_download(2, OD_MODES_OF_OPERATION, 0, 1, 1)),
        SdoResponse::Abort {
            index: 0x6060,
            sub: 0,
            code: SDO_ABORT_VALUE_RANGE
        }
    );
    assert_eq!(
        ask(&mut s, sdo_download(2, OD_MODES_OF_OPERATION, 0, 8, 1)),
        SdoResponse::DownloadOk {
            index: 0x6060,
            sub: 0
        }
    );
    assert_eq!(
        ask(&mut s, sdo_upload(2, OD_MODES_DISPLAY, 0)),
        SdoResponse::UploadOk {
            index: 0x6061,
            sub: 0,
            value: 8
        }
    );
    assert_eq!(
        ask(&mut s, sdo_download(2, OD_PRODUCER_HEARTBEAT_MS, 0, 25, 2)),
        SdoResponse::DownloadOk {
            index: 0x1017,
            sub: 0
        }
    );
    assert_eq!(
        ask(&mut s, sdo_upload(2, OD_PRODUCER_HEARTBEAT_MS, 0)),
        SdoResponse::UploadOk {
            index: 0x1017,
            sub: 0,
            value: 25
        }
    );
    assert_eq!(
        ask(&mut s, sdo_upload(2, OD_DEVICE_TYPE, 0)),
        SdoResponse::UploadOk {
            index: 0x1000,
            sub: 0,
            value: DEVICE_TYPE_SERVO
        }
    );
    assert_eq!(
        ask(&mut s, sdo_upload(2, 0x1234, 0)),
        SdoResponse::Abort {
            index: 0x1234,
            sub: 0,
            code: SDO_ABORT_NO_OBJECT
        }
    );
    assert_eq!(
        ask(&mut s, sdo_download(2, OD_STATUSWORD, 0, 0, 2)),
        SdoResponse::Abort {
            index: 0x6041,
            sub: 0,
            code: SDO_ABORT_READ_ONLY
        }
    );
    assert_eq!(
        ask(&mut s, sdo_download(2, OD_MODES_OF_OPERATION, 0, 8, 4)),
        SdoResponse::Abort {
            index: 0x6060,
            sub: 0,
            code: SDO_ABORT_LENGTH
        }
    );
}

#[test]
fn fault_needs_a_reset_edge_and_sends_emcy() {
    let mut bank = DriveBank::new(&[7], 10);
    bank.start(0);
    bank.handle_frame(&nmt(NMT_START, 0), 0);
    bank.raise_fault(0, 0x7300);
    let s = bank.slave_mut(0).unwrap();
    assert_eq!(s.ds402_state(), Ds402State::Fault);
    let mut out = FrameBuf::default();
    s.handle_frame(&rpdo1(7, CW_FAULT_RESET, 0), 0, &mut out);
    assert_eq!(s.ds402_state(), Ds402State::SwitchOnDisabled);
    struct Sink(Vec<can_transport::CanFrame>);
    impl can_transport::CanBus for Sink {
        fn send(&mut self, f: &can_transport::CanFrame) -> Result<(), can_transport::CanError> {
            self.0.push(*f);
            Ok(())
        }
        fn recv_timeout(
            &mut self,
            _: std::time::Duration,
        ) -> Result<Option<can_transport::RxFrame>, can_transport::CanError> {
            Ok(None)
        }
        fn interface(&self) -> &str {
            "sink"
        }
    }
    let mut sink = Sink(Vec::new());
    bank.flush(&mut sink).unwrap();
    let msgs: Vec<Message> = sink.0.iter().map(decode).collect();
    assert!(
        msgs.contains(&Message::Emcy {
            node: 7,
            code: 0x7300,
            error_register: 1
        }),
        "{msgs:?}"
    );
}

#[test]
fn winch_axis_respects_limits_and_stops() {
    let mut ax = WinchAxis::new(5.0, 5.0, 14.0);
    let mut vmax = 0.0f64;
    let mut prev_v = 0.0;
    for _ in 0..3000 {
        ax.step(Some(8.0), 1e-3);
        vmax = vmax.max(ax.velocity_m_per_s.abs());
        assert!((ax.velocity_m_per_s - prev_v).abs() <= 14.0 * 1e-3 + 1e-12);
        prev_v = ax.velocity_m_per_s;
    }
    assert!(vmax <= 5.0 + 1e-12 && vmax > 4.9);
    assert!((ax.length_m - 8.0).abs() < 1e-9, "{}", ax.length_m);
    ax.step(Some(0.0), 1e-3);
    for _ in 0..1000 {
        ax.step(None, 1e-3);
    }
    assert_eq!(ax.velocity_m_per_s, 0.0);
}

fn sdo(s: &mut DriveSlave, f: can_transport::CanFrame) -> SdoResponse {
    let mut o = FrameBuf::default();
    s.handle_frame(&f, 0, &mut o);
    match o
        .as_slice()
        .iter()
        .map(decode)
        .find(|m| matches!(m, Message::SdoResponse { .. }))
    {
        Some(Message::SdoResponse { data, .. }) => parse_sdo_response(&data),
        m => panic!("{m:?}"),
    }
}

#[test]
fn pdo_mapping_follows_the_od_and_the_cia301_procedure() {
    let mut s = operational(3);
    let ok = |r: SdoResponse| assert!(matches!(r, SdoResponse::DownloadOk { .. }), "{r:?}");
    let abort = |r: SdoResponse, want: u32| match r {
        SdoResponse::Abort { code, .. } => assert_eq!(code, want, "{code:#x}"),
        r => panic!("{r:?}"),
    };
    // Mapping a valid PDO is refused; so is changing a valid PDO's COB-ID.
    abort(
        sdo(&mut s, sdo_download(3, 0x1A00, 0, 0, 1)),
        SDO_ABORT_UNSUPPORTED_ACCESS,
    );
    abort(
        sdo(&mut s, sdo_download(3, 0x1800, 1, 0x190, 4)),
        SDO_ABORT_VALUE_RANGE,
    );
    // Remap TPDO1 to position actual only, on COB-ID 0x190.
    ok(sdo(&mut s, sdo_download(3, 0x1800, 1, 0x8000_0183, 4)));
    ok(sdo(&mut s, sdo_download(3, 0x1A00, 0, 0, 1)));
    // Entries only while sub 0 = 0; statusword is TPDO-mappable, controlword is not readable?
    ok(sdo(&mut s, sdo_download(3, 0x1A00, 1, 0x6064_0020, 4)));
    abort(
        sdo(&mut s, sdo_download(3, 0x1A00, 2, 0x6065_0020, 4)),
        SDO_ABORT_NOT_MAPPABLE,
    );
    abort(
        sdo(&mut s, sdo_download(3, 0x1A00, 2, 0x6064_0010, 4)),
        SDO_ABORT_NOT_MAPPABLE,
    );
    ok(sdo(&mut s, sdo_download(3, 0x1A00, 0, 1, 1)));
    abort(
        sdo(&mut s, sdo_download(3, 0x1A00, 1, 0x6041_0010, 4)),
        SDO_ABORT_UNSUPPORTED_ACCESS,
    );
    ok(sdo(&mut s, sdo_download(3, 0x1800, 1, 0x190, 4)));
    // Transmission types 241..=251 are reserved.
    abort(
        sdo(&mut s, sdo_download(3, 0x1801, 2, 245, 1)),
        SDO_ABORT_VALUE_RANGE,
    );
    let mut out = FrameBuf::default();
    s.set_actual(0x0102_0304, 0, 0);
    s.transmit_pdos(&mut out);
    let f: Vec<(u32, Vec<u8>)> = out
        .as_slice()
        .iter()
        .map(|f| (f.id(), f.data().to_vec()))
        .collect();
    assert_eq!(f[0], (0x190, vec![4, 3, 2, 1]));
    assert_eq!(f[1].0, 0x283, "TPDO2 unchanged");
    // Read-back of what was written; 0x6064 is read-only; a missing sub-index is named so.
    assert_eq!(
        sdo(&mut s, sdo_upload(3, 0x1A00, 1)),
        SdoResponse::UploadOk {
            index: 0x1A00,
            sub: 1,
            value: 0x6064_0020
        }
    );
    abort(sdo(&mut s, sdo_upload(3, 0x1A00, 9)), SDO_ABORT_NO_SUB);
    // EDS limits: 0x6007 only 0..=3.
    abort(
        sdo(&mut s, sdo_download(3, 0x6007, 0, 4, 2)),
        SDO_ABORT_VALUE_HIGH,
    );
    abort(
        sdo(&mut s, sdo_download(3, 0x6007, 0, 2, 1)),
        SDO_ABORT_LENGTH,
    );
    // Reset communication restores the EDS defaults of 0x1000-0x1FFF.
    s.handle_frame(&nmt(NMT_RESET_COMM, 3), 0, &mut out);
    assert_eq!(s.od_value(0x1800, 1), Some(0x183));
    assert_eq!(s.od_value(0x1A00, 1), Some(0x6041_0010));
}

#[test]
fn rpdo_as_mapped_and_short_rpdo_rejected_with_emcy() {
    let mut s = operational(2);
    // RPDO1 remapped to the controlword only.
    for (i, sub, v, len) in [
        (0x1400, 1, 0x8000_0202u32, 4u8),
        (0x1600, 0, 0, 1),
        (0x1600, 1, 0x6040_0010, 4),
        (0x1600, 0, 1, 1),
        (0x1400, 1, 0x202, 4),
    ] {
        assert!(matches!(
            sdo(&mut s, sdo_download(2, i, sub, v, len)),
            SdoResponse::DownloadOk { .. }
        ));
    }
    let mut out = FrameBuf::default();
    s.handle_frame(
        &can_transport::CanFrame::new(0x202, &[6, 0]).unwrap(),
        0,
        &mut out,
    );
    assert_eq!(s.ds402_state(), Ds402State::ReadyToSwitchOn);
    // A 6-byte mapping receiving 1 byte: not processed, EMCY 0x8210 once.
    let mut s = operational(2);
    s.handle_frame(
        &can_transport::CanFrame::new(0x202, &[6]).unwrap(),
        0,
        &mut out,
    );
    assert_eq!(s.ds402_state(), Ds402State::SwitchOnDisabled);
    assert!(frames(&out).contains(&Message::Emcy {
        node: 2,
        code: 0x8210,
        error_register: 0x11
    }));
}

#[test]
fn consumer_heartbeat_loss_acts_per_0x6007() {
    let ms = 1_000_000u64;
    let mut s = operational(4);
    assert!(matches!(
        sdo(&mut s, sdo_download(4, 0x1016, 1, (0x7F << 16) | 50, 4)),
        SdoResponse::DownloadOk { .. }
    ));
    assert!(matches!(
        sdo(&mut s, sdo_download(4, 0x6007, 0, 3, 2)),
        SdoResponse::DownloadOk { .. }
    ));
    let mut out = FrameBuf::default();
    for cw in [CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION] {
        s.handle_frame(&rpdo1(4, cw, 0), 0, &mut out);
    }
    // Not armed before the first heartbeat of the producer.
    s.poll(500 * ms, &mut out);
    assert_eq!(s.ds402_state(), Ds402State::OperationEnabled);
    s.handle_frame(&heartbeat(0x7F, NmtState::Operational), 500 * ms, &mut out);
    out.clear();
    s.poll(550 * ms, &mut out);
    assert_eq!(s.ds402_state(), Ds402State::OperationEnabled);
    s.poll(550 * ms + 1, &mut out);
    assert_eq!(s.ds402_state(), Ds402State::QuickStopActive);
    assert!(frames(&out).contains(&Message::Emcy {
        node: 4,
        code: 0x8130,
        error_register: 0x11
    }));
}

#[test]
fn quick_stop_option_and_following_error_per_od() {
    // EDS default 0x605A = 2: after the ramp (velocity 0) Switch On Disabled.
    let mut s = operational(5);
    let mut out = FrameBuf::default();
    for cw in [
        CW_SHUTDOWN,
        CW_SWITCH_ON,
        CW_ENABLE_OPERATION,
        CW_QUICK_STOP,
    ] {
        s.handle_frame(&rpdo1(5, cw, 0), 0, &mut out);
    }
    s.set_actual(0, 100, 0);
    assert_eq!(s.ds402_state(), Ds402State::QuickStopActive);
    s.set_actual(0, 0, 0);
    assert_eq!(s.ds402_state(), Ds402State::SwitchOnDisabled);
    // 6: stays in Quick Stop Active.
    let mut s = operational(5);
    sdo(&mut s, sdo_download(5, 0x605A, 0, 6, 2));
    for cw in [
        CW_SHUTDOWN,
        CW_SWITCH_ON,
        CW_ENABLE_OPERATION,
        CW_QUICK_STOP,
    ] {
        s.handle_frame(&rpdo1(5, cw, 0), 0, &mut out);
    }
    s.set_actual(0, 0, 0);
    assert_eq!(s.ds402_state(), Ds402State::QuickStopActive);
    // Following error: window 100 counts, 3 ms at the default 1 ms cycle => fault on the 4th.
    let mut s = operational(5);
    sdo(&mut s, sdo_download(5, 0x6065, 0, 100, 4));
    sdo(&mut s, sdo_download(5, 0x6066, 0, 3, 2));
    for cw in [CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION] {
        s.handle_frame(&rpdo1(5, cw, 0), 0, &mut out);
    }
    s.handle_frame(&rpdo1(5, CW_ENABLE_OPERATION, 1000), 0, &mut out);
    s.handle_frame(&sync(), 0, &mut out);
    out.clear();
    for k in 0..4 {
        assert_eq!(s.ds402_state(), Ds402State::OperationEnabled, "cycle {k}");
        s.set_actual(500, 0, 0);
        s.transmit_pdos(&mut out);
    }
    assert_eq!(s.ds402_state(), Ds402State::Fault);
    assert!(frames(&out).contains(&Message::Emcy {
        node: 5,
        code: 0x8611,
        error_register: 0x01
    }));
    // Software position limits clamp the latched target.
    let mut s = operational(5);
    sdo(&mut s, sdo_download(5, 0x607D, 2, 700, 4));
    for cw in [CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION] {
        s.handle_frame(&rpdo1(5, cw, 0), 0, &mut out);
    }
    s.handle_frame(&rpdo1(5, CW_ENABLE_OPERATION, 1000), 0, &mut out);
    s.handle_frame(&sync(), 0, &mut out);
    assert_eq!(s.demand(), MotionDemand::Follow { target_counts: 700 });
}
