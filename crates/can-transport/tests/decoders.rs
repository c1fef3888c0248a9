//! Property tests: decoders never panic on arbitrary input, and encode/decode round-trip.

use can_transport::candump::{parse_line, write_line};
use can_transport::cannelloni::{self, DecodeError};
use can_transport::{CanFrame, TransportSpec};
use proptest::prelude::*;
use std::time::{Duration, UNIX_EPOCH};

fn arb_frame() -> impl Strategy<Value = CanFrame> {
    (
        any::<bool>(),
        any::<bool>(),
        any::<u32>(),
        proptest::collection::vec(any::<u8>(), 0..=8),
    )
        .prop_map(|(ext, rtr, id, data)| {
            let id = if ext { id & 0x1FFF_FFFF } else { id & 0x7FF };
            if rtr {
                CanFrame::remote(id, ext, data.len() as u8).unwrap()
            } else {
                CanFrame::with_flags(id, ext, false, &data).unwrap()
            }
        })
}

proptest! {
    #[test]
    fn cannelloni_decode_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let mut n = 0;
        let r = cannelloni::decode(&bytes, |_| n += 1);
        if r.is_err() { prop_assert_eq!(n, 0usize, "a malformed packet must deliver no frame {}", bytes.len()); }
    }

    #[test]
    fn cannelloni_round_trip(seq in any::<u8>(), frames in proptest::collection::vec(arb_frame(), 0..20)) {
        let mut buf = [0u8; 1024];
        let n = cannelloni::encode(seq, &frames, &mut buf).unwrap();
        let mut out = Vec::new();
        let (s, c) = cannelloni::decode(&buf[..n], |f| out.push(f)).unwrap();
        prop_assert_eq!(s, seq);
        prop_assert_eq!(c as usize, frames.len());
        prop_assert_eq!(out, frames);
    }

    #[test]
    fn cannelloni_truncation_is_an_error(frames in proptest::collection::vec(arb_frame(), 1..5), cut in 1usize..20) {
        let mut buf = [0u8; 256];
        let n = cannelloni::encode(0, &frames, &mut buf).unwrap();
        let cut = cut.min(n);
        let r = cannelloni::decode(&buf[..n - cut], |_| ());
        prop_assert!(r.is_err());
    }

    #[test]
    fn candump_parse_never_panics(s in "\\PC{0,60}") {
        let _ = parse_line(&s);
    }

    #[test]
    fn candump_parse_never_panics_near_valid(s in "\\([0-9]{0,11}\\.[0-9]{0,7}\\) [a-z0-9]{0,6} [0-9A-Fa-f]{0,9}#[0-9A-FRr.#]{0,18}") {
        let _ = parse_line(&s);
    }

    #[test]
    fn candump_round_trip(f in arb_frame(), secs in 0u64..4_000_000_000, us in 0u32..1_000_000) {
        let mut line = Vec::new();
        let t = UNIX_EPOCH + Duration::new(secs, us * 1000);
        write_line(&mut line, t, "vcan3", &f).unwrap();
        let parsed = parse_line(std::str::from_utf8(&line).unwrap()).unwrap();
        prop_assert_eq!(parsed.frame, f);
        prop_assert_eq!(parsed.seconds, secs);
        prop_assert_eq!(parsed.micros, us);
        prop_assert_eq!(parsed.iface, "vcan3");
    }

    #[test]
    fn transport_spec_never_panics_and_round_trips(s in "\\PC{0,40}") {
        if let Ok(spec) = s.parse::<TransportSpec>() {
            prop_assert_eq!(spec.to_string().parse::<TransportSpec>().unwrap(), spec);
        }
    }
}

#[test]
fn cannelloni_known_bytes() {
    // One standard frame 0x123 [0xAA, 0xBB], seq 7, as cannelloni puts it on the wire.
    let f = CanFrame::new(0x123, &[0xAA, 0xBB]).unwrap();
    let mut buf = [0u8; 32];
    let n = cannelloni::encode(7, &[f], &mut buf).unwrap();
    assert_eq!(&buf[..n], &[2, 0, 7, 0, 1, 0, 0, 0x01, 0x23, 2, 0xAA, 0xBB]);
    // Extended + RTR flags in the id word, no data bytes for RTR.
    let r = CanFrame::remote(0x1234567, true, 4).unwrap();
    let n = cannelloni::encode(0, &[r], &mut buf).unwrap();
    assert_eq!(&buf[..n], &[2, 0, 0, 0, 1, 0xC1, 0x23, 0x45, 0x67, 4]);
    assert_eq!(
        cannelloni::decode(&[3, 0, 0, 0, 0], |_| {}),
        Err(DecodeError::Version(3))
    );
    assert_eq!(
        cannelloni::decode(&[2, 0, 0, 0, 1, 0, 0, 1, 0, 9], |_| {}),
        Err(DecodeError::Length { index: 0, len: 9 })
    );
}

#[test]
fn candump_known_lines() {
    let l = parse_line("(1700000000.123456) vcan0 181#0700E8030000").unwrap();
    assert_eq!(
        l.frame,
        CanFrame::new(0x181, &[7, 0, 0xE8, 3, 0, 0]).unwrap()
    );
    assert_eq!(l.micros, 123456);
    assert!(parse_line("(1.5) can0 12345678#R").unwrap().frame.is_rtr());
    assert_eq!(
        parse_line("(1.5) can0 1234#00").unwrap_err().to_string(),
        "bad CAN id \"1234\" (3 hex digits standard, 8 hex digits extended)"
    );
    assert!(parse_line("(1.5) can0 123#0").is_err());
    assert!(parse_line("(1.5) can0 123##100").is_err());
}

#[test]
fn spec_errors_are_clear() {
    assert_eq!(
        "socketcan:vcan0".parse::<TransportSpec>().unwrap(),
        TransportSpec::SocketCan {
            iface: "vcan0".into()
        }
    );
    assert!(
        "udp:127.0.0.1:20000->127.0.0.1:20001"
            .parse::<TransportSpec>()
            .is_ok()
    );
    let e = "udpbus:127.0.0.1:20000"
        .parse::<TransportSpec>()
        .unwrap_err();
    assert!(e.to_string().contains("multicast"), "{e}");
    assert!("can:vcan0".parse::<TransportSpec>().is_err());
}

#[test]
fn cannelloni_error_frames() {
    use can_transport::BusErrorFrame;
    use can_transport::cannelloni::Item;
    // Bus-off as cannelloni forwards a subscribed SocketCAN's error frame: id word with
    // CAN_ERR_FLAG (0x20000000) | CAN_ERR_BUSOFF (0x40), len 8, 8 data bytes.
    let e = BusErrorFrame::bus_off();
    let mut buf = [0u8; 32];
    let n = cannelloni::encode_bus_error(9, &e, &mut buf).unwrap();
    assert_eq!(
        &buf[..n],
        &[2, 0, 9, 0, 1, 0x20, 0, 0, 0x40, 8, 0, 0, 0, 0, 0, 0, 0, 0]
    );
    // The data-frame decoder refuses it (as before); the item decoder delivers it typed.
    assert_eq!(
        cannelloni::decode(&buf[..n], |_| {}),
        Err(DecodeError::ErrorFrame { index: 0 })
    );
    let mut items = Vec::new();
    cannelloni::decode_items(&buf[..n], |i| items.push(i)).unwrap();
    assert_eq!(items, vec![Item::BusError(e)]);
    // Mixed with data frames in one packet, in order; a truncated packet delivers nothing.
    let f = CanFrame::new(0x181, &[1, 2]).unwrap();
    let mut pkt = vec![2, 0, 0, 0, 2];
    pkt.extend_from_slice(&[0, 0, 0x01, 0x81, 2, 1, 2]);
    let p = BusErrorFrame::error_passive(130, 7);
    pkt.extend_from_slice(&[0x20, 0, 0x02, 0x04, 8]);
    pkt.extend_from_slice(p.data());
    let mut items = Vec::new();
    cannelloni::decode_items(&pkt, |i| items.push(i)).unwrap();
    assert_eq!(items, vec![Item::Frame(f), Item::BusError(p)]);
    assert!(p.is_error_passive() && p.counters() == Some((130, 7)));
    let mut n = 0;
    assert!(cannelloni::decode_items(&pkt[..pkt.len() - 1], |_| n += 1).is_err());
    assert_eq!(n, 0);
}

#[test]
fn wire_spec_names_the_hub_socket() {
    let s: TransportSpec = "wire:out/sim/can0.sock".parse().unwrap();
    assert_eq!(
        s,
        TransportSpec::Wire {
            path: "out/sim/can0.sock".into()
        }
    );
    assert_eq!(s.to_string(), "wire:out/sim/can0.sock");
    let e = "wire:".parse::<TransportSpec>().unwrap_err().to_string();
    assert!(e.contains("socket path must be 1..=107 bytes"), "{e}");
    let long = format!("wire:/{}", "x".repeat(107));
    assert!(long.parse::<TransportSpec>().is_err());
    assert!(
        "nope:x"
            .parse::<TransportSpec>()
            .unwrap_err()
            .to_string()
            .contains("wire:<socket path>")
    );
}
