//! Real sockets: the multicast bus is shared by 3 endpoints; SocketCAN fails clearly without CAN.

use can_transport::{CanBus, CanError, CanFrame, TransportSpec, open};
use std::time::Duration;

fn port(offset: u16) -> u16 {
    // Distinct per test process and test so parallel runs don't share a bus.
    30000 + (std::process::id() % 2000) as u16 * 8 + offset
}

#[test]
fn three_members_see_each_others_frames_but_not_their_own() {
    let spec: TransportSpec = format!("udpbus:239.255.70.1:{}", port(0)).parse().unwrap();
    let mut a = open(&spec).unwrap();
    let mut b = open(&spec).unwrap();
    let mut c = open(&spec).unwrap();
    let f = CanFrame::new(0x181, &[1, 2, 3]).unwrap();
    a.send(&f).unwrap();
    for bus in [&mut b, &mut c] {
        let rx = bus
            .recv_timeout(Duration::from_secs(1))
            .unwrap()
            .expect("frame on the shared bus");
        assert_eq!(rx.frame, f);
        assert!(rx.rx_monotonic_ns > 0);
    }
    assert!(
        a.recv_timeout(Duration::from_millis(50)).unwrap().is_none(),
        "own frame must not loop back"
    );
    let g = CanFrame::new(0x201, &[9]).unwrap();
    c.send(&g).unwrap();
    assert_eq!(
        a.recv_timeout(Duration::from_secs(1))
            .unwrap()
            .unwrap()
            .frame,
        g
    );
    assert_eq!(
        b.recv_timeout(Duration::from_secs(1))
            .unwrap()
            .unwrap()
            .frame,
        g
    );
}

#[test]
fn malformed_datagram_is_counted_not_delivered() {
    let p = port(1);
    let spec: TransportSpec = format!("udpbus:239.255.70.1:{p}").parse().unwrap();
    let mut a = open(&spec).unwrap();
    let raw = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    raw.set_multicast_ttl_v4(0).unwrap();
    raw.send_to(&[2, 0, 0, 0, 5, 1], ("239.255.70.1", p))
        .unwrap();
    assert!(
        a.recv_timeout(Duration::from_millis(200))
            .unwrap()
            .is_none()
    );
    assert_eq!(a.rx_errors(), 1);
}

#[test]
fn peer_link_round_trip() {
    let (pa, pb) = (port(2), port(3));
    let mut a = open(
        &format!("udp:127.0.0.1:{pa}->127.0.0.1:{pb}")
            .parse()
            .unwrap(),
    )
    .unwrap();
    let mut b = open(
        &format!("udp:127.0.0.1:{pb}->127.0.0.1:{pa}")
            .parse()
            .unwrap(),
    )
    .unwrap();
    let f = CanFrame::with_flags(0x1ABCDEF, true, false, &[0xFF; 8]).unwrap();
    a.send(&f).unwrap();
    assert_eq!(
        b.recv_timeout(Duration::from_secs(1))
            .unwrap()
            .unwrap()
            .frame,
        f
    );
}

#[test]
fn socketcan_open_reports_missing_can_support_or_works() {
    // On this project's CI host the kernel has no CAN: the error must say so and name the
    // alternative. Inside the vcan VM vcan0 exists and the open succeeds.
    match open(&"socketcan:vcan0".parse().unwrap()) {
        Ok(_) => {}
        Err(e @ CanError::NoCanSupport { .. }) => {
            let msg = e.to_string();
            assert!(msg.contains("udpbus:"), "{msg}");
        }
        Err(e) => panic!("unexpected error kind: {e}"),
    }
}
