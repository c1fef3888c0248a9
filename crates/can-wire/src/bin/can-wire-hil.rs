//! `can-wire-hil`: the hub's vcan forwarding on a real kernel (run by tools/wire-hil.sh inside
//! the QEMU guest, after tests/hil/wire-guest.sh created vcan10..vcan12).
//!
//! Starts `can-wire` (from PATH) with one bus over ports vcan10+vcan11+vcan12 and checks
//! behaviour only (the guest's time is emulated): every frame reaches every other node once
//! and never its sender, all receivers see one order, a burst beyond the queue is dropped and
//! counted, error frames pass through, and SocketCAN's transmit echo (`CAN_RAW_RECV_OWN_MSGS`,
//! `MSG_CONFIRM`) marks own frames on vcan0. Prints `WIRE-HIL PASS|FAIL <check>` and
//! `WIRE_RESULT PASS|FAIL`; exit status 0 iff all passed.

use can_transport::{BusErrorFrame, CanBus, CanFrame, RxEvent, SocketCanBus};
use std::path::Path;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

const PORTS: [&str; 3] = ["vcan10", "vcan11", "vcan12"];
const QUEUE: usize = 8;
const BURST: usize = 40;
const STATS: &str = "/tmp/wire.json";
const READY: &str = "/tmp/wire.ready";

type Check = Result<(), String>;

fn ensure(cond: bool, what: impl FnOnce() -> String) -> Check {
    if cond { Ok(()) } else { Err(what()) }
}

/// Frames (not error frames) received until `n` arrived or `quiet` passed without one.
fn receive(bus: &mut SocketCanBus, n: usize, quiet: Duration) -> Vec<CanFrame> {
    let mut v = Vec::new();
    while v.len() < n {
        match bus.recv_timeout(quiet) {
            Ok(Some(rx)) => v.push(rx.frame),
            _ => break,
        }
    }
    v
}

fn start_hub() -> Result<Child, String> {
    let _ = std::fs::remove_file(READY);
    let child = Command::new("can-wire")
        .args([
            "--bus",
            &format!(
                "name=can0,bitrate=125000,ports={},queue={QUEUE}",
                PORTS.join("+")
            ),
            "--stats",
            STATS,
            "--ready-file",
            READY,
            "--rt-priority",
            "0",
            // The emulated guest is slow: a long look-ahead keeps submissions in time.
            "--lookahead-us",
            "20000",
        ])
        .spawn()
        .map_err(|e| format!("starting can-wire: {e}"))?;
    let t = Instant::now();
    while !Path::new(READY).exists() {
        if t.elapsed() > Duration::from_secs(60) {
            return Err("can-wire did not report ready within 60 s".into());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(child)
}

/// A's frames reach B and C in A's order, B's reach A and C; nobody gets its own; C sees
/// one order containing both.
fn forwarding(a: &mut SocketCanBus, b: &mut SocketCanBus, c: &mut SocketCanBus) -> Check {
    let from_a: Vec<CanFrame> = (0..5u16)
        .map(|i| CanFrame::new(0x100 + i, &[i as u8, 0xA5]).unwrap())
        .collect();
    let from_b = [
        CanFrame::new(0x050, &[1]).unwrap(),
        CanFrame::new(0x300, &[2, 3, 4]).unwrap(),
    ];
    for f in &from_a {
        a.send(f).map_err(|e| format!("vcan10 send: {e}"))?;
    }
    for f in &from_b {
        b.send(f).map_err(|e| format!("vcan11 send: {e}"))?;
    }
    let quiet = Duration::from_secs(5);
    let got_a = receive(a, 3, quiet);
    let got_b = receive(b, 6, quiet);
    let got_c = receive(c, 8, quiet);
    ensure(got_a == from_b, || {
        format!("vcan10 got {got_a:?}, expected B's two")
    })?;
    ensure(got_b == from_a, || {
        format!("vcan11 got {got_b:?}, expected A's five in order")
    })?;
    ensure(got_c.len() == 7, || {
        format!("vcan12 got {} frames, expected 7", got_c.len())
    })?;
    let c_a: Vec<CanFrame> = got_c
        .iter()
        .copied()
        .filter(|f| from_a.contains(f))
        .collect();
    let c_b: Vec<CanFrame> = got_c
        .iter()
        .copied()
        .filter(|f| from_b.contains(f))
        .collect();
    ensure(c_a == from_a && c_b == from_b, || {
        format!("vcan12's order {got_c:?} breaks a sender's FIFO")
    })
}

/// A writes a burst the bus cannot carry at once: the model keeps QUEUE frames not yet off the
/// wire and drops the rest; B and C receive the same survivors.
fn burst(
    a: &mut SocketCanBus,
    b: &mut SocketCanBus,
    c: &mut SocketCanBus,
) -> Result<usize, String> {
    for i in 0..BURST {
        let f = CanFrame::new(0x200 + i as u16, &[i as u8; 8]).unwrap();
        a.send(&f).map_err(|e| format!("vcan10 send {i}: {e}"))?;
    }
    let quiet = Duration::from_secs(5);
    let got_b = receive(b, BURST, quiet);
    let got_c = receive(c, BURST, quiet);
    ensure(got_b == got_c, || {
        format!(
            "vcan11 and vcan12 differ: {} vs {} frames",
            got_b.len(),
            got_c.len()
        )
    })?;
    ensure(got_b.len() >= QUEUE && got_b.len() < BURST, || {
        format!(
            "{} of {BURST} frames arrived; expected some dropped, at least {QUEUE} kept",
            got_b.len()
        )
    })?;
    ensure(got_b.windows(2).all(|w| w[0].id() < w[1].id()), || {
        "the survivors are out of the sender's order".into()
    })?;
    Ok(got_b.len())
}

fn error_frames(a: &mut SocketCanBus, b: &mut SocketCanBus) -> Check {
    b.subscribe_bus_errors().map_err(|e| e.to_string())?;
    a.send_bus_error(&BusErrorFrame::bus_off())
        .map_err(|e| format!("vcan10 error frame: {e}"))?;
    match b.recv_event_timeout(Duration::from_secs(5)) {
        Ok(Some(RxEvent::BusError(e))) if e.error.is_bus_off() => Ok(()),
        other => Err(format!(
            "vcan11 expected the bus-off error frame, got {other:?}"
        )),
    }
}

/// SocketCAN's transmit echo on plain vcan0 (no hub): own frames come back marked own.
fn tx_echo() -> Check {
    let mut e1 = SocketCanBus::open("vcan0").map_err(|e| e.to_string())?;
    let mut e2 = SocketCanBus::open("vcan0").map_err(|e| e.to_string())?;
    e1.enable_tx_echo().map_err(|e| e.to_string())?;
    let f = CanFrame::new(0x123, &[7]).unwrap();
    e1.send(&f).map_err(|e| e.to_string())?;
    let own = e1
        .recv_timeout(Duration::from_secs(5))
        .map_err(|e| e.to_string())?;
    let other = e2
        .recv_timeout(Duration::from_secs(5))
        .map_err(|e| e.to_string())?;
    ensure(own.is_some_and(|r| r.own && r.frame == f), || {
        format!("the sender's echo: {own:?}")
    })?;
    ensure(other.is_some_and(|r| !r.own && r.frame == f), || {
        format!("the other socket: {other:?}")
    })
}

fn stop_hub(mut hub: Child) -> Result<serde_json::Value, String> {
    // SAFETY: signalling our own child by its pid.
    unsafe { libc::kill(hub.id() as libc::pid_t, libc::SIGTERM) };
    let st = hub.wait().map_err(|e| e.to_string())?;
    ensure(st.success(), || format!("can-wire exited {st}"))?;
    let text = std::fs::read_to_string(STATS).map_err(|e| format!("{STATS}: {e}"))?;
    serde_json::from_str(&text).map_err(|e| format!("{STATS}: {e}"))
}

fn stats(v: &serde_json::Value, kept: usize) -> Check {
    let bus = &v["buses"][0];
    ensure(v["final"] == true, || "statistics not final".into())?;
    let frames = bus["frames"].as_u64().unwrap_or(0) as usize;
    ensure(frames == 5 + 2 + kept, || {
        format!("{frames} frames counted, expected {}", 7 + kept)
    })?;
    let dropped = bus["nodes"][0]["dropped"].as_u64().unwrap_or(0) as usize;
    ensure(dropped == BURST - kept, || {
        format!(
            "vcan10: {dropped} dropped counted, {} not delivered",
            BURST - kept
        )
    })?;
    ensure(bus["error_frames"] == 1, || {
        format!("error frames: {}", bus["error_frames"])
    })?;
    for (i, p) in PORTS.iter().enumerate() {
        ensure(bus["nodes"][i]["name"] == *p, || {
            format!("node {i}: {}", bus["nodes"][i])
        })?;
    }
    Ok(())
}

fn main() {
    let mut ok = true;
    let mut report = |name: &str, r: Check| match r {
        Ok(()) => println!("WIRE-HIL PASS {name}"),
        Err(e) => {
            ok = false;
            println!("WIRE-HIL FAIL {name}: {e}");
        }
    };
    report("socketcan_tx_echo", tx_echo());
    let hub = match start_hub() {
        Ok(h) => h,
        Err(e) => {
            report("hub_start", Err(e));
            println!("WIRE_RESULT FAIL");
            std::process::exit(1);
        }
    };
    let open = |p: &str| SocketCanBus::open(p).map_err(|e| format!("{p}: {e}"));
    let ports = (open(PORTS[0]), open(PORTS[1]), open(PORTS[2]));
    let (mut a, mut b, mut c) = match ports {
        (Ok(a), Ok(b), Ok(c)) => (a, b, c),
        (a, b, c) => {
            let e = [a.err(), b.err(), c.err()]
                .into_iter()
                .flatten()
                .collect::<Vec<_>>();
            report("open_ports", Err(e.join("; ")));
            println!("WIRE_RESULT FAIL");
            std::process::exit(1);
        }
    };
    report("forwarding", forwarding(&mut a, &mut b, &mut c));
    let kept = burst(&mut a, &mut b, &mut c);
    let kept_n = *kept.as_ref().unwrap_or(&0);
    report("burst_beyond_the_queue", kept.map(|_| ()));
    report("error_frames", error_frames(&mut a, &mut b));
    match stop_hub(hub) {
        Ok(v) => report("statistics", stats(&v, kept_n)),
        Err(e) => report("hub_exit", Err(e)),
    }
    println!("WIRE_RESULT {}", if ok { "PASS" } else { "FAIL" });
    std::process::exit(if ok { 0 } else { 1 });
}
