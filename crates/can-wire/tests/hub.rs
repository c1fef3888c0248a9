//! The hub binary with `wire:` clients on the host: order and stamps of a master and two
//! drives, an overloaded bus next to a light one, robustness against a bad client.
//!
//! Timing is asserted only through the model's own stamps (deterministic relations between
//! the end-of-frame stamps, the frames' exact bit lengths and the clients' send times), never
//! as wall-clock thresholds.

mod common;

use can_bus_model::arbitration_key;
use can_transport::wire::bits;
use can_transport::{CanBus, CanError, CanFrame, RxEvent, monotonic_ns, open};
use common::{HubProc, test_dir};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

const BIT_NS: u64 = 1000; // 1 Mbit/s

fn client(sock: &Path) -> Box<dyn CanBus> {
    open(&format!("wire:{}", sock.display()).parse().unwrap()).expect("connecting to the hub")
}

/// A frame this client sent: monotonic time just before and just after `send`.
#[derive(Clone, Copy, Debug)]
struct Sent {
    frame: CanFrame,
    t_pre: u64,
    t_post: u64,
}

/// A frame this client saw on the bus (others' and, with echo, its own).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Seen {
    frame: CanFrame,
    eof: u64,
    own: bool,
}

struct Log {
    sent: Vec<Sent>,
    seen: Vec<Seen>,
    /// Drives: (end of frame of the SYNC answered, time the answer was sent).
    answers: Vec<(u64, u64)>,
    tx_full: u64,
}

/// What the test's threads count, for the main thread's wait.
#[derive(Default)]
struct Progress {
    sent_total: AtomicUsize,
    syncs_sent: AtomicUsize,
    answers: [AtomicUsize; 3],
    seen: [AtomicUsize; 3],
    sending_done: AtomicBool,
    stop: AtomicBool,
}

fn send_logged(bus: &mut dyn CanBus, f: CanFrame, log: &mut Log, p: &Progress) -> bool {
    let t_pre = monotonic_ns();
    match bus.send(&f) {
        Ok(()) => {
            log.sent.push(Sent {
                frame: f,
                t_pre,
                t_post: monotonic_ns(),
            });
            p.sent_total.fetch_add(1, Ordering::SeqCst);
            true
        }
        Err(CanError::TxFull { .. }) => {
            log.tx_full += 1;
            false
        }
        Err(e) => panic!("send: {e}"),
    }
}

/// Receives until `until` (monotonic ns), logging every frame; drives (`node` 1, 2) answer
/// each SYNC with one TPDO (0x181, 0x182).
fn receive_until(bus: &mut dyn CanBus, until: u64, log: &mut Log, node: usize, p: &Progress) {
    loop {
        let now = monotonic_ns();
        if now >= until {
            return;
        }
        match bus
            .recv_event_timeout(Duration::from_nanos(until - now))
            .unwrap()
        {
            Some(RxEvent::Frame(rx)) => {
                log.seen.push(Seen {
                    frame: rx.frame,
                    eof: rx.rx_monotonic_ns,
                    own: rx.own,
                });
                p.seen[node].fetch_add(1, Ordering::SeqCst);
                if rx.frame.id() == 0x080 && !rx.own && node != 0 {
                    let t = monotonic_ns();
                    let f =
                        CanFrame::new(0x180 + node as u16, &[node as u8, 0x37, 0x12, 0]).unwrap();
                    if send_logged(bus, f, log, p) {
                        log.answers.push((rx.rx_monotonic_ns, t));
                    }
                    p.answers[node].fetch_add(1, Ordering::SeqCst);
                }
            }
            Some(RxEvent::BusError(_)) => {}
            None => return,
        }
    }
}

#[test]
fn a_master_and_two_drives_order_and_stamps() {
    const CYCLES: u64 = 300;
    let dir = test_dir("master-drives");
    let sock = dir.join("can0.sock");
    // A queue of 1000: a sender learns that a frame left the wire when the hub delivers it,
    // which a SCHED_OTHER debug-build hub on a loaded test host does up to 100 ms late; this
    // test is about order and stamps, the overload test about full queues.
    let hub = HubProc::start(
        &dir,
        &[
            "--bus".into(),
            format!(
                "name=can0,bitrate=1000000,socket={},queue=1000",
                sock.display()
            ),
            "--lookahead-us".into(),
            "100".into(),
        ],
    );
    let p = Arc::new(Progress::default());
    let mut buses: Vec<Box<dyn CanBus>> = (0..3).map(|_| client(&sock)).collect();
    for b in &mut buses {
        b.enable_tx_echo().unwrap();
    }
    let threads: Vec<_> = buses
        .into_iter()
        .enumerate()
        .map(|(node, mut bus)| {
            let p = p.clone();
            std::thread::spawn(move || {
                let mut log = Log {
                    sent: Vec::new(),
                    seen: Vec::new(),
                    answers: Vec::new(),
                    tx_full: 0,
                };
                if node == 0 {
                    // The master: SYNC, then 8 RPDOs (controlword only), every 1 ms; a late
                    // cycle is skipped, not caught up.
                    let t0 = monotonic_ns() + 20_000_000;
                    for c in 0..CYCLES {
                        let deadline = t0 + c * 1_000_000;
                        receive_until(&mut *bus, deadline, &mut log, 0, &p);
                        if monotonic_ns() > deadline + 500_000 {
                            continue;
                        }
                        if send_logged(&mut *bus, CanFrame::new(0x080, &[]).unwrap(), &mut log, &p)
                        {
                            p.syncs_sent.fetch_add(1, Ordering::SeqCst);
                        }
                        for n in 1..=8u16 {
                            let f = CanFrame::new(0x200 + n, &[0x0F, c as u8]).unwrap();
                            send_logged(&mut *bus, f, &mut log, &p);
                        }
                    }
                    p.sending_done.store(true, Ordering::SeqCst);
                }
                while !p.stop.load(Ordering::SeqCst) {
                    receive_until(&mut *bus, monotonic_ns() + 5_000_000, &mut log, node, &p);
                }
                log
            })
        })
        .collect();
    // Wait until the master is done, both drives answered every SYNC and every client has
    // seen every frame sent (all three echo their own).
    let t = Instant::now();
    loop {
        let syncs = p.syncs_sent.load(Ordering::SeqCst);
        let total = p.sent_total.load(Ordering::SeqCst);
        if p.sending_done.load(Ordering::SeqCst)
            && (1..3).all(|d| p.answers[d].load(Ordering::SeqCst) == syncs)
            && p.seen.iter().all(|s| s.load(Ordering::SeqCst) == total)
        {
            break;
        }
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "clients did not settle"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    p.stop.store(true, Ordering::SeqCst);
    let logs: Vec<Log> = threads.into_iter().map(|t| t.join().unwrap()).collect();
    let stats = hub.stop();
    let bus = &stats["buses"][0];

    // Every client saw the same bus: the same frames with the same end-of-frame stamps.
    let timeline: Vec<(CanFrame, u64)> = logs[0].seen.iter().map(|s| (s.frame, s.eof)).collect();
    for l in &logs[1..] {
        let other: Vec<(CanFrame, u64)> = l.seen.iter().map(|s| (s.frame, s.eof)).collect();
        assert_eq!(other, timeline, "two nodes saw different buses");
    }
    let total_sent: usize = logs.iter().map(|l| l.sent.len()).sum();
    assert_eq!(
        timeline.len(),
        total_sent,
        "every frame sent left the wire once"
    );
    assert_eq!(bus["frames"].as_u64().unwrap() as usize, total_sent);
    assert!(
        logs.iter().all(|l| l.tx_full == 0),
        "a light bus refused a frame: {:?} {stats}",
        logs.iter().map(|l| l.tx_full).collect::<Vec<_>>()
    );
    assert_eq!(bus["dropped"], 0);
    let syncs = logs[0]
        .sent
        .iter()
        .filter(|s| s.frame.id() == 0x080)
        .count();
    assert!(
        syncs as u64 > CYCLES / 2,
        "only {syncs} of {CYCLES} cycles were sent"
    );
    for l in &logs[1..] {
        assert_eq!(l.answers.len(), syncs, "a drive missed a SYNC");
    }

    // Frames never overlap: consecutive end-of-frame stamps are at least the later frame's
    // exact length (SOF to SOF, intermission included) apart.
    for w in timeline.windows(2) {
        let ((_, e0), (f1, e1)) = (w[0], w[1]);
        assert!(
            e1 - e0 >= u64::from(bits::exact(&f1).total()) * BIT_NS,
            "{f1:?} ends {} ns after its predecessor, shorter than its {} bits",
            e1 - e0,
            bits::exact(&f1).total()
        );
    }

    // Per node: FIFO (own echoes in send order) and each sent frame's end of frame.
    let mut ends: Vec<Vec<(Sent, u64)>> = Vec::new();
    for (node, l) in logs.iter().enumerate() {
        let own: Vec<&Seen> = l.seen.iter().filter(|s| s.own).collect();
        assert_eq!(own.len(), l.sent.len(), "node {node}: echoes");
        let mut v = Vec::new();
        for (s, o) in l.sent.iter().zip(&own) {
            assert_eq!(s.frame, o.frame, "node {node}: echo out of FIFO order");
            v.push((*s, o.eof));
        }
        ends.push(v);
    }
    let index_of = |eof: u64| timeline.binary_search_by_key(&eof, |&(_, e)| e).unwrap();
    // No frame ends before it was sent plus its length; a frame queued before its
    // predecessor's free time follows it back to back (SOF right after the intermission).
    let mut back_to_back = 0;
    for (node, v) in ends.iter().enumerate() {
        for &(s, eof) in v {
            let len = u64::from(bits::exact(&s.frame).to_eof()) * BIT_NS;
            assert!(
                eof >= s.t_pre + len,
                "node {node}: {:?} ended before it was sent",
                s.frame
            );
            let k = index_of(eof);
            if k == 0 {
                continue;
            }
            let prev_eof = timeline[k - 1].1;
            if s.t_post <= prev_eof + 3 * BIT_NS {
                assert_eq!(
                    eof - prev_eof,
                    u64::from(bits::exact(&s.frame).total()) * BIT_NS,
                    "node {node}: {:?} was queued but did not follow back to back",
                    s.frame
                );
                back_to_back += 1;
            }
        }
    }
    assert!(
        back_to_back > syncs * 4,
        "only {back_to_back} back-to-back frames checked"
    );

    // A drive answers a SYNC only after the hub delivered it, which is not before its EOF.
    for l in &logs[1..] {
        for &(sync_eof, t) in &l.answers {
            assert!(
                t >= sync_eof,
                "SYNC delivered {} ns before its end of frame",
                sync_eof - t
            );
        }
    }

    // Arbitration: when a frame started, no frame that was certainly queued then as its
    // node's head had a lower arbitration field. Holds when every submission reached the hub
    // within the look-ahead (no model violation).
    let violations = bus["violations"].as_u64().unwrap();
    if violations == 0 {
        let mut checked = 0;
        for &(f, eof) in &timeline {
            let start = eof - u64::from(bits::exact(&f).to_eof()) * BIT_NS;
            for v in &ends {
                // This node's first frame not yet complete at `start` is its head then.
                if let Some(&(h, h_eof)) = v.iter().find(|(_, e)| *e > start)
                    && h_eof != eof
                    && h.t_post <= start
                {
                    assert!(h_eof > eof);
                    assert!(
                        arbitration_key(&h.frame) > arbitration_key(&f),
                        "{:?} (queued as its node's head) lost arbitration to {f:?}",
                        h.frame
                    );
                    checked += 1;
                }
            }
        }
        // The drives' answers compete with the master's RPDOs of the same cycle every time.
        assert!(checked > syncs, "only {checked} arbitrations checked");
    } else {
        eprintln!("arbitration check skipped: {violations} model violations on this run");
    }

    // The statistics: every node and identifier counted.
    let nodes = bus["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 3);
    for (n, l) in logs.iter().enumerate() {
        assert_eq!(nodes[n]["sent"].as_u64().unwrap() as usize, l.sent.len());
    }
    let sync = bus["ids"]
        .as_array()
        .unwrap()
        .iter()
        .find(|i| i["id"] == "0x080")
        .expect("SYNC in the statistics");
    assert_eq!(sync["count"].as_u64().unwrap() as usize, syncs);
    let lat = &sync["latency_ns"];
    assert!(lat["p99"].as_u64().unwrap() <= lat["max"].as_u64().unwrap() * 101 / 100 + 1);
}

/// `per_ms` frames of 8 bytes every 1 ms for `ms` ms (a late cycle is skipped); waits until
/// the last one is off the wire. Returns (sent, refused with TxFull).
fn frames_per_ms(sock: &Path, per_ms: u16, ms: u64) -> (u64, u64) {
    let mut bus = can_transport::wire::WireBus::connect(sock).unwrap();
    let mut sent = 0;
    let mut full = 0;
    let t0 = monotonic_ns() + 10_000_000;
    for c in 0..ms {
        let deadline = t0 + c * 1_000_000;
        crs_rt::sleep_until(deadline);
        if monotonic_ns() > deadline + 500_000 {
            continue;
        }
        for i in 0..per_ms {
            match bus.send(&CanFrame::new(0x100 + i, &[0x5A; 8]).unwrap()) {
                Ok(()) => sent += 1,
                Err(CanError::TxFull { .. }) => full += 1,
                Err(e) => panic!("{e}"),
            }
        }
    }
    let t = Instant::now();
    while bus.in_flight() > 0 {
        assert!(t.elapsed() < Duration::from_secs(20), "queue never drained");
        std::thread::sleep(Duration::from_millis(1));
    }
    (sent, full)
}

#[test]
fn an_overloaded_bus_fails_visibly_a_light_one_does_not() {
    // 20 frames of 8 bytes per ms at 1 Mbit/s is about 2.3 ms of wire per 1 ms; 2 per ms is
    // about 23 %. Two buses of one hub, 2.3 s each (a full 1 s load window while sending).
    // The light bus has a queue of 1000: a sender learns that a slot is free when the hub has
    // delivered the frame, and a SCHED_OTHER debug-build hub on a loaded 2-core test host was
    // seen to stall for 139 ms, which the sender sees as a full queue of 10. The light bus's
    // verdict here is its latency; both buses with the same queue of 10, in model time:
    // crates/can-bus-model/tests/wire_model.rs.
    let dir = test_dir("overload");
    let heavy = dir.join("heavy.sock");
    let light = dir.join("light.sock");
    let hub = HubProc::start(
        &dir,
        &[
            "--bus".into(),
            format!("name=heavy,bitrate=1000000,socket={}", heavy.display()),
            "--bus".into(),
            format!(
                "name=light,bitrate=1000000,socket={},queue=1000",
                light.display()
            ),
        ],
    );
    // A listener on each bus, draining (it must not overflow its receive buffer).
    // Until it has `expected` frames (known once the senders are done), or 30 s.
    let expected: Arc<[std::sync::atomic::AtomicU64; 2]> =
        Arc::new([u64::MAX.into(), u64::MAX.into()]);
    let listeners: Vec<_> = [&heavy, &light]
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut b = client(p);
            let expected = expected.clone();
            std::thread::spawn(move || {
                let mut n = 0u64;
                let t = Instant::now();
                while n < expected[i].load(Ordering::SeqCst) && t.elapsed().as_secs() < 30 {
                    if b.recv_timeout(Duration::from_millis(5)).unwrap().is_some() {
                        n += 1;
                    }
                }
                n
            })
        })
        .collect();
    let h = std::thread::spawn(move || frames_per_ms(&heavy, 20, 2300));
    let l = std::thread::spawn(move || frames_per_ms(&light, 2, 2300));
    let (h_sent, h_full) = h.join().unwrap();
    let (l_sent, l_full) = l.join().unwrap();
    expected[0].store(h_sent, Ordering::SeqCst);
    expected[1].store(l_sent, Ordering::SeqCst);
    let got: Vec<u64> = listeners.into_iter().map(|t| t.join().unwrap()).collect();
    let stats = hub.stop();
    let (hb, lb) = (&stats["buses"][0], &stats["buses"][1]);
    assert_eq!(hb["name"], "heavy");

    // Heavy: the sender's queue overflowed (TxFull at once, and counted by the hub), frames
    // waited longer than the period, the bus was full.
    assert!(h_full > 1000, "heavy: only {h_full} refusals");
    assert_eq!(
        hb["dropped"].as_u64().unwrap(),
        h_full,
        "heavy: drops counted by the hub"
    );
    assert!(hb["latency_max_ns"].as_u64().unwrap() > 1_000_000, "{hb}");
    // The heavy bus is busier than the light one (how near full depends on how soon the
    // sender learns of free slots: the hub's real-time delivery, not asserted here).
    assert!(
        hb["load_window_max"].as_f64().unwrap() > lb["load_window_max"].as_f64().unwrap(),
        "{hb}"
    );
    assert_eq!(hb["frames"].as_u64().unwrap(), h_sent);
    assert_eq!(
        got[0], h_sent,
        "heavy: the listener got every frame that left the wire"
    );

    // Light: nothing refused, every frame well within the period.
    assert_eq!((l_full, lb["dropped"].as_u64().unwrap()), (0, 0), "{lb}");
    assert!(lb["latency_max_ns"].as_u64().unwrap() < 1_000_000, "{lb}");
    assert!(lb["load_window_max"].as_f64().unwrap() < 0.5, "{lb}");
    assert_eq!(lb["frames"].as_u64().unwrap(), l_sent);
    assert_eq!(got[1], l_sent);
}

#[test]
fn a_bad_client_is_counted_not_obeyed_and_a_second_hub_is_refused() {
    use can_transport::wire::proto;
    use std::os::fd::AsRawFd;
    let dir = test_dir("bad-client");
    let sock = dir.join("can0.sock");
    let hub = HubProc::start(
        &dir,
        &[
            "--bus".into(),
            format!("name=can0,bitrate=125000,socket={}", sock.display()),
        ],
    );
    // A second hub on the same socket refuses to start, naming the reason.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_can-wire"))
        .args(["--rt-priority", "0", "--bus"])
        .arg(format!("name=x,bitrate=125000,socket={}", sock.display()))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("another process is listening"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let mut good = client(&sock);
    // A raw client speaking the protocol badly: garbage, a record of unknown kind, and a frame
    // stamped 50 ms in the past (after the bus decided on a later frame: a model violation).
    let fd = {
        // SAFETY: socket(2); checked.
        let fd =
            unsafe { libc::socket(libc::AF_UNIX, libc::SOCK_SEQPACKET | libc::SOCK_CLOEXEC, 0) };
        assert!(fd >= 0);
        // SAFETY: the descriptor socket(2) returned.
        unsafe { <std::os::fd::OwnedFd as std::os::fd::FromRawFd>::from_raw_fd(fd) }
    };
    {
        // SAFETY: sockaddr_un is plain data; connect our socket to the hub's path.
        let mut a: libc::sockaddr_un = unsafe { std::mem::zeroed() };
        a.sun_family = libc::AF_UNIX as libc::sa_family_t;
        for (d, s) in a
            .sun_path
            .iter_mut()
            .zip(sock.as_os_str().as_encoded_bytes())
        {
            *d = *s as libc::c_char;
        }
        // SAFETY: as above.
        let rc = unsafe {
            libc::connect(
                fd.as_raw_fd(),
                (&a as *const libc::sockaddr_un).cast(),
                std::mem::size_of::<libc::sockaddr_un>() as libc::socklen_t,
            )
        };
        assert_eq!(rc, 0, "{}", std::io::Error::last_os_error());
    }
    let send = |b: &[u8]| {
        // SAFETY: send our buffer on our socket.
        let n = unsafe {
            libc::send(
                fd.as_raw_fd(),
                b.as_ptr().cast(),
                b.len(),
                libc::MSG_NOSIGNAL,
            )
        };
        assert_eq!(n, b.len() as isize, "{}", std::io::Error::last_os_error());
    };
    send(&proto::Hello { name: "raw".into() }.encode());
    let mut m = [0u8; proto::HANDSHAKE_LEN];
    let (n, cfd) = proto::recv_with_fd(fd.as_raw_fd(), &mut m).unwrap();
    assert_eq!(n, proto::HANDSHAKE_LEN);
    let w = proto::Welcome::decode(&m).unwrap();
    assert_eq!(
        (w.bitrate_bps, w.queue_len, w.bus.as_str()),
        (125_000, 10, "can0")
    );
    // SAFETY: the counter table descriptor we received.
    drop(unsafe { <std::os::fd::OwnedFd as std::os::fd::FromRawFd>::from_raw_fd(cfd.unwrap()) });
    send(&[1, 2, 3]); // not a whole record
    let mut r = [0u8; proto::RECORD_LEN];
    r[0] = 77;
    send(&r); // unknown kind
    // The good client puts a frame on the wire; then the raw one claims it had one queued
    // 50 ms earlier.
    good.enable_tx_echo().unwrap();
    good.send(&CanFrame::new(0x300, &[1]).unwrap()).unwrap();
    let echo = good
        .recv_timeout(Duration::from_secs(10))
        .unwrap()
        .expect("echo");
    assert!(echo.own);
    let f = CanFrame::new(0x001, &[2]).unwrap();
    proto::encode_frame(
        proto::Kind::Frame,
        &f,
        echo.rx_monotonic_ns - 50_000_000,
        0,
        &mut r,
    );
    send(&r);
    let rx = good
        .recv_timeout(Duration::from_secs(10))
        .unwrap()
        .expect("the raw node's frame");
    assert_eq!(rx.frame, f);
    assert!(!rx.own);
    drop(fd); // the raw node leaves
    // Error frames pass straight through to the others.
    let mut other = client(&sock);
    other.subscribe_bus_errors().unwrap();
    good.send_bus_error(&can_transport::BusErrorFrame::bus_off())
        .unwrap();
    match other.recv_event_timeout(Duration::from_secs(10)).unwrap() {
        Some(RxEvent::BusError(e)) => assert!(e.error.is_bus_off()),
        ev => panic!("expected the bus-off error frame, got {ev:?}"),
    }
    // The others see the raw node leave; the hub notices at its next read of that socket.
    good.send(&CanFrame::new(0x301, &[1]).unwrap()).unwrap();
    assert!(
        good.recv_timeout(Duration::from_secs(10))
            .unwrap()
            .unwrap()
            .own
    );
    let stats = hub.stop();
    let bus = &stats["buses"][0];
    assert_eq!(bus["protocol_errors"].as_u64().unwrap(), 2, "{bus}");
    assert_eq!(bus["violations"].as_u64().unwrap(), 1, "{bus}");
    assert!(
        bus["violation_max_ns"].as_u64().unwrap() > 40_000_000,
        "{bus}"
    );
    assert_eq!(bus["error_frames"].as_u64().unwrap(), 1);
    let raw_node = &bus["nodes"][1];
    assert_eq!(raw_node["name"], "raw");
    assert_eq!(raw_node["connected"], false);
    assert_eq!(raw_node["sent"], 1);
}
