//! A node's priority transmit path (`CanBus::open_priority_path` on `wire:`): a second,
//! send-only node of the bus whose frames compete by identifier, so a SYNC never waits behind
//! its own node's queued low-priority frames — but still behind the frame already on the wire
//! and behind a lower identifier pending at another node.
//!
//! The bus runs at 1 kbit/s, so a frame takes 55–135 ms on the wire and every submission of a
//! step lands while the first frame is still on the wire, whatever the host's scheduling; the
//! test checks that precondition on the model's stamps and says so when it does not hold.
//! Everything asserted is the model's order and stamps.

mod common;

use can_transport::wire::bits;
use can_transport::{CanBus, CanFrame, RxEvent, monotonic_ns, open};
use common::{HubProc, test_dir};
use std::path::Path;
use std::time::{Duration, Instant};

const BITRATE: u32 = 1000;
const BIT_NS: u64 = 1_000_000;

fn client(sock: &Path) -> Box<dyn CanBus> {
    open(&format!("wire:{}", sock.display()).parse().unwrap()).expect("connecting to the hub")
}

fn hub(name: &str) -> (HubProc, std::path::PathBuf) {
    let dir = test_dir(name);
    let sock = dir.join("can0.sock");
    let h = HubProc::start(
        &dir,
        &[
            "--bus".into(),
            format!("name=can0,bitrate={BITRATE},socket={}", sock.display()),
        ],
    );
    (h, sock)
}

/// Receives on `bus` until `n` frames were seen (or 30 s passed: then panics with what came).
fn frames_seen(bus: &mut dyn CanBus, n: usize) -> Vec<(CanFrame, u64)> {
    let mut seen = Vec::new();
    let t0 = Instant::now();
    while seen.len() < n {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "only {} of {n} frames on the wire: {seen:?}",
            seen.len()
        );
        if let Some(RxEvent::Frame(rx)) =
            bus.recv_event_timeout(Duration::from_millis(100)).unwrap()
        {
            seen.push((rx.frame, rx.rx_monotonic_ns));
        }
    }
    seen
}

/// SOF of a frame seen with end of frame `eof`.
fn sof(f: &CanFrame, eof: u64) -> u64 {
    eof - u64::from(bits::exact(f).to_eof()) * BIT_NS
}

/// When the bus is free after a frame with end of frame `eof` (its intermission over).
fn free_after(f: &CanFrame, eof: u64) -> u64 {
    let b = bits::exact(f);
    eof + u64::from(b.total() - b.to_eof()) * BIT_NS
}

fn rpdo(k: u16) -> CanFrame {
    CanFrame::new(0x200 + k, &[0x0F, 0, k as u8, 0, 0, 0]).unwrap()
}

fn sync() -> CanFrame {
    CanFrame::new(0x080, &[]).unwrap()
}

/// `N` RPDOs queued by the master, then the SYNC: through the priority path it is on the
/// wire right after the RPDO that was already on the wire; through the master's own queue
/// (the control) it waits behind all of them.
fn sync_after_queued_rpdos(priority: bool) -> (Vec<(CanFrame, u64)>, u64) {
    const N: u16 = 6;
    let (hub, sock) = hub(if priority { "prio-sync" } else { "fifo-sync" });
    let mut listener = client(&sock);
    let mut master = client(&sock);
    let mut prio = master
        .open_priority_path()
        .unwrap()
        .expect("wire: has a priority path");
    for k in 1..=N {
        master.send(&rpdo(k)).unwrap();
    }
    let t_sync = if priority {
        prio.send(&sync()).unwrap();
        monotonic_ns()
    } else {
        master.send(&sync()).unwrap();
        monotonic_ns()
    };
    let seen = frames_seen(listener.as_mut(), usize::from(N) + 1);
    // Precondition: the SYNC was handed over while the first RPDO was still on the wire.
    assert!(
        t_sync < seen[0].1,
        "host too slow for this test: the SYNC was sent {} ms after the first frame's end",
        (t_sync - seen[0].1) / 1_000_000
    );
    // The priority node receives nothing (a send-only path), though 7 frames went by.
    assert!(prio.try_recv().unwrap().is_none());
    // The master's own queue receives the SYNC as another node's frame (SocketCAN's local
    // loopback does the same for a second socket).
    if priority {
        let got = frames_seen(master.as_mut(), 1);
        assert_eq!(got[0].0.id(), 0x080);
    }
    let st = hub.stop();
    assert_eq!(st["buses"][0]["violations"], 0, "{st}");
    (seen, t_sync)
}

#[test]
fn a_sync_on_the_priority_path_leaves_before_its_nodes_queued_frames() {
    let (seen, t_sync) = sync_after_queued_rpdos(true);
    let ids: Vec<u32> = seen.iter().map(|(f, _)| f.id()).collect();
    // RPDO 1 was on the wire when the SYNC came; the SYNC wins the next arbitration against
    // RPDO 2 (0x080 < 0x202), the rest follow in FIFO order.
    assert_eq!(
        ids,
        vec![0x201, 0x080, 0x202, 0x203, 0x204, 0x205, 0x206],
        "{seen:?}"
    );
    // Every frame before the SYNC had started before the SYNC was sent.
    let k = ids.iter().position(|&i| i == 0x080).unwrap();
    for (f, eof) in &seen[..k] {
        assert!(
            sof(f, *eof) <= t_sync,
            "{f:?} started after the SYNC was sent"
        );
    }
    // Back to back: the SYNC starts at the end of RPDO 1's intermission.
    assert_eq!(
        sof(&seen[1].0, seen[1].1),
        free_after(&seen[0].0, seen[0].1)
    );
}

#[test]
fn a_sync_in_the_nodes_own_fifo_waits_behind_its_queued_frames() {
    // The control: the same frames with the SYNC in the master's FIFO queue.
    let (seen, _) = sync_after_queued_rpdos(false);
    let ids: Vec<u32> = seen.iter().map(|(f, _)| f.id()).collect();
    assert_eq!(
        ids,
        vec![0x201, 0x202, 0x203, 0x204, 0x205, 0x206, 0x080],
        "{seen:?}"
    );
}

#[test]
fn the_priority_path_still_loses_to_the_wire_and_to_lower_identifiers() {
    let (hub, sock) = hub("prio-arbitration");
    let mut listener = client(&sock);
    let mut master = client(&sock);
    let mut prio = master.open_priority_path().unwrap().unwrap();
    let mut nmt_node = client(&sock);
    let mut drive = client(&sock);
    // On the wire first: the master's RPDO 1 (115 ms at 1 kbit/s); queued behind it RPDO 2.
    master.send(&rpdo(1)).unwrap();
    master.send(&rpdo(2)).unwrap();
    // While it is on the wire: a lower identifier at another node (NMT 0x000), a higher one
    // (TPDO1 0x181), then the SYNC on the priority path.
    nmt_node
        .send(&CanFrame::new(0x000, &[0x80, 0]).unwrap())
        .unwrap();
    drive
        .send(&CanFrame::new(0x181, &[0x37, 0x12, 0, 0]).unwrap())
        .unwrap();
    prio.send(&sync()).unwrap();
    let t_last = monotonic_ns();
    let seen = frames_seen(listener.as_mut(), 5);
    assert!(
        t_last < seen[0].1,
        "host too slow for this test: the last frame was sent {} ms after the first one's end",
        (t_last - seen[0].1) / 1_000_000
    );
    let ids: Vec<u32> = seen.iter().map(|(f, _)| f.id()).collect();
    // The frame on the wire completes; then 0x000 < 0x080 < 0x181 < 0x202.
    assert_eq!(ids, vec![0x201, 0x000, 0x080, 0x181, 0x202], "{seen:?}");
    // Back to back, each at the previous frame's end of intermission.
    for w in seen.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        assert_eq!(sof(&b.0, b.1), free_after(&a.0, a.1), "{a:?} then {b:?}");
    }
    let st = hub.stop();
    assert_eq!(st["buses"][0]["violations"], 0, "{st}");
}
