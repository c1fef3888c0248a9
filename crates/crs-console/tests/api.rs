//! The console's HTTP API against a fake stack on a private iceoryx2 prefix: status, the stop
//! request on the bus, the start-ride request behind the pre-ride checks (a fake control
//! socket), the token check, the live stream.

use crs_console::{ConsoleConfig, PlatformView};
use crs_ipc::{EventKind, Heartbeat, IpcNode, JointSetpoint, ProcessId, StateEvent};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

fn prefix(tag: &str) -> String {
    format!("crs-console-test-{}-{tag}/", std::process::id())
}

fn config(prefix: &str, token: Option<&str>) -> ConsoleConfig {
    ConsoleConfig {
        addr: "127.0.0.1:0".parse().unwrap(),
        token: token.map(str::to_string),
        prefix: prefix.to_string(),
        platform: Some(PlatformView {
            name: "test".into(),
            frame_anchors_m: vec![[1.0, 1.0, 1.0]; 8],
            platform_anchors_m: vec![[0.1, 0.1, 0.1]; 8],
            f_min_n: 1000.0,
            f_max_n: 9000.0,
        }),
        plan: None,
        avoid_cpu: Some(1),
        rides: None,
    }
}

/// One HTTP/1.1 request; returns (status code, body).
fn http(addr: SocketAddr, method: &str, path: &str, headers: &[&str]) -> (u16, String) {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut req = format!(
        "{method} {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\nContent-Length: 0\r\n"
    );
    for h in headers {
        req.push_str(h);
        req.push_str("\r\n");
    }
    req.push_str("\r\n");
    s.write_all(req.as_bytes()).unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).expect("read response");
    let code = out[9..12].parse().expect("status code");
    let body = out
        .split_once("\r\n\r\n")
        .map_or("", |(_, b)| b)
        .to_string();
    (code, body)
}

fn status(addr: SocketAddr) -> serde_json::Value {
    let (code, body) = http(addr, "GET", "/api/status", &[]);
    assert_eq!(code, 200, "{body}");
    serde_json::from_str(&body).expect("status JSON")
}

#[test]
fn status_reports_no_stack_then_live_values_and_stop_reaches_the_bus() {
    let p = prefix("live");
    let console = crs_console::spawn(config(&p, None)).expect("console starts");
    let addr = console.addr;
    let (code, page) = http(addr, "GET", "/", &[]);
    assert_eq!(code, 200);
    assert!(page.contains("CRS operator console"));
    let s = status(addr);
    assert_eq!(s["stack_running"], false, "{s}");

    // A fake motion-core: heartbeats and setpoints.
    let node = IpcNode::with_prefix("fake-stack", &p).unwrap();
    let hb = node.publisher::<Heartbeat>().unwrap();
    let sp = node.publisher::<JointSetpoint>().unwrap();
    let events = node.subscriber::<StateEvent>().unwrap();
    let t0 = Instant::now();
    let mut seen = None;
    for seq in 1.. {
        hb.publish(&Heartbeat::motion(crs_ipc::MotionState::Running, seq))
            .unwrap();
        let mut s = JointSetpoint {
            sequence: seq,
            cable_count: 8,
            ..Default::default()
        };
        s.pose[2] = 2.0 + seq as f64 * 1e-3;
        sp.publish(&s).unwrap();
        std::thread::sleep(Duration::from_millis(5));
        let st = status(addr);
        if st["stack_running"] == true && st["setpoint_sequence"].as_u64().unwrap() > 0 {
            match seen {
                None => seen = Some(st["setpoint_sequence"].as_u64().unwrap()),
                // Live: a later status shows a newer setpoint.
                Some(first) if st["setpoint_sequence"].as_u64().unwrap() > first => {
                    assert_eq!(st["motion_state"], "running");
                    assert!(st["reference"]["position_m"][2].as_f64().unwrap() > 2.0);
                    assert_eq!(
                        st["reference"]["anchors_world_m"].as_array().unwrap().len(),
                        8
                    );
                    break;
                }
                _ => {}
            }
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the console never showed live values"
        );
    }

    // Stop: an e-stop from the operator on the bus.
    let (code, body) = http(addr, "POST", "/api/stop", &[]);
    assert_eq!(code, 200, "{body}");
    let t0 = Instant::now();
    loop {
        if let Some(e) = events.receive().unwrap()
            && e.kind == EventKind::EStop as u32
        {
            assert_eq!(e.source, ProcessId::Operator as u32);
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no e-stop on the bus"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    // The trip log names it.
    let t0 = Instant::now();
    loop {
        let (code, body) = http(addr, "GET", "/api/trips", &[]);
        assert_eq!(code, 200);
        let trips: serde_json::Value = serde_json::from_str(&body).unwrap();
        if trips
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["kind"] == "E-STOP" && t["source"] == "operator")
        {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "trip log without the stop: {body}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // No reset from the browser: there is no such route.
    let (code, _) = http(addr, "POST", "/api/reset", &[]);
    assert_eq!(code, 404);
    console
        .stop()
        .expect("console stops while no stream is open");
}

#[test]
fn token_is_checked_on_every_request() {
    let p = prefix("token");
    let tok = "0123456789abcdef-token";
    let console = crs_console::spawn(config(&p, Some(tok))).unwrap();
    let addr = console.addr;
    for path in ["/", "/api/status", "/api/trips", "/api/events"] {
        assert_eq!(http(addr, "GET", path, &[]).0, 401, "{path} without token");
        assert_eq!(
            http(
                addr,
                "GET",
                path,
                &["Authorization: Bearer wrong-token-0000000"]
            )
            .0,
            401,
            "{path} wrong token"
        );
    }
    assert_eq!(http(addr, "POST", "/api/stop", &[]).0, 401);
    assert_eq!(http(addr, "POST", "/api/ride/start", &[]).0, 401);
    assert_eq!(
        http(
            addr,
            "GET",
            "/api/status",
            &[&format!("Authorization: Bearer {tok}")]
        )
        .0,
        200
    );
    assert_eq!(
        http(addr, "GET", &format!("/api/status?token={tok}"), &[]).0,
        200
    );
}

#[test]
fn other_addresses_need_a_token() {
    let mut c = config("x/", None);
    c.addr = "0.0.0.0:8080".parse().unwrap();
    assert!(matches!(
        c.validate(),
        Err(crs_console::ConsoleError::TokenRequired(_))
    ));
    c.token = Some("short".into());
    assert!(matches!(
        c.validate(),
        Err(crs_console::ConsoleError::TokenTooShort)
    ));
    c.token = Some("long-enough-token-1234".into());
    assert!(c.validate().is_ok());
}

#[test]
fn live_stream_sends_status_events_and_ends_on_shutdown() {
    let p = prefix("sse");
    let console = crs_console::spawn(config(&p, None)).unwrap();
    let mut s = TcpStream::connect(console.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(b"GET /api/events HTTP/1.1\r\nHost: localhost\r\n\r\n")
        .unwrap();
    let mut buf = Vec::new();
    let mut chunk = [0u8; 4096];
    while String::from_utf8_lossy(&buf)
        .matches("event: status")
        .count()
        < 3
    {
        let n = s.read(&mut chunk).expect("stream data");
        assert!(n > 0, "stream ended early");
        buf.extend_from_slice(&chunk[..n]);
    }
    // Stopping the console ends the open stream instead of waiting for the client: stop()
    // returns while this client still holds the stream open, and the stream then reads EOF
    // (the deadline below only stops a hang; the stream itself would never end).
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || tx.send(console.stop()).unwrap());
    rx.recv_timeout(Duration::from_secs(60))
        .expect("stop() waited for the open stream")
        .unwrap();
    loop {
        match s.read(&mut chunk) {
            Ok(0) => break,
            Ok(_) => continue,
            Err(e) => panic!("the stream did not end with the console: {e}"),
        }
    }
}

/// A fake motion-core control socket: answers `status` with the phase it is given and `start`
/// with a started ride; keeps every request.
struct FakeControl {
    path: std::path::PathBuf,
    phase: std::sync::Arc<std::sync::Mutex<String>>,
    requests: std::sync::Arc<std::sync::Mutex<Vec<String>>>,
}

impl FakeControl {
    fn start(tag: &str) -> Self {
        use std::os::unix::net::UnixListener;
        let path = std::env::temp_dir().join(format!(
            "crs-console-test-{}-{tag}.sock",
            std::process::id()
        ));
        let _ = std::fs::remove_file(&path);
        let l = UnixListener::bind(&path).unwrap();
        let phase = std::sync::Arc::new(std::sync::Mutex::new("riding".to_string()));
        let requests = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let (ph, rq) = (phase.clone(), requests.clone());
        std::thread::spawn(move || {
            for conn in l.incoming() {
                let Ok(mut c) = conn else { break };
                let mut req = String::new();
                if c.read_to_string(&mut req).is_err() {
                    continue;
                }
                let reply = if req.starts_with("status") {
                    format!(
                        "ok {}; pose [0.000, 0.000, 2.000] m [0.00, 0.00, 0.00]°; rides started: 0",
                        ph.lock().unwrap()
                    )
                } else {
                    rq.lock().unwrap().push(req.clone());
                    "ok ride rides/tour.csv started (2 waypoints): plan 3.0 s".to_string()
                };
                let _ = c.write_all(format!("{reply}\n").as_bytes());
            }
        });
        Self {
            path,
            phase,
            requests,
        }
    }
}

/// Waits until the console's status satisfies `want` (the poller and the control watch run
/// on their own clocks: this waits on the answer, not on a time).
fn wait_status(addr: SocketAddr, what: &str, want: impl Fn(&serde_json::Value) -> bool) {
    let t0 = Instant::now();
    loop {
        let s = status(addr);
        if want(&s) {
            return;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "never {what}: {}",
            s["ride"]
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn check_ok(s: &serde_json::Value, name: &str) -> bool {
    s["ride"]["checks"]
        .as_array()
        .unwrap()
        .iter()
        .any(|c| c["name"] == name && c["ok"] == true)
}

#[test]
fn start_ride_goes_to_the_control_socket_only_while_the_pre_ride_checks_pass() {
    use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
    let p = prefix("ride");
    let fake = FakeControl::start("ride");
    let ride_text =
        "t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg\n2,0.1,0,2,0,0,0\n4,0,0,2,0,0,0\n";
    let mut cfg = config(&p, None);
    cfg.rides = Some(crs_console::RideSetup {
        socket: fake.path.clone(),
        ride: Some(crs_console::LoadedRide::verified(
            "rides/tour.csv".into(),
            ride_text.into(),
            2,
            3.0,
        )),
    });
    let console = crs_console::spawn(cfg).unwrap();
    let addr = console.addr;
    // No stack: refused, naming the checks that fail.
    let s = status(addr);
    assert_eq!(s["ride"]["start_allowed"], false, "{}", s["ride"]);
    assert_eq!(
        s["ride"]["loaded"],
        "rides/tour.csv (2 waypoints, plan 3.0 s)"
    );
    let (code, body) = http(addr, "POST", "/api/ride/start", &[]);
    assert_eq!(code, 409, "{body}");
    assert!(
        body.contains("stack running") && body.contains("safety monitor armed"),
        "{body}"
    );

    // A fake stack: motion-core and an armed monitor beating.
    let monitor = std::sync::Arc::new(AtomicU32::new(crs_ipc::MonitorState::Armed.into()));
    let done = std::sync::Arc::new(AtomicBool::new(false));
    let (m2, d2, p2) = (monitor.clone(), done.clone(), p.clone());
    let beats = std::thread::spawn(move || {
        let node = IpcNode::with_prefix("fake-stack-ride", &p2).unwrap();
        let hb = node.publisher::<Heartbeat>().unwrap();
        for seq in 1.. {
            if d2.load(Ordering::Relaxed) {
                break;
            }
            hb.publish(&Heartbeat::motion(crs_ipc::MotionState::Running, seq))
                .unwrap();
            let state = crs_ipc::MonitorState::try_from(m2.load(Ordering::Relaxed)).unwrap();
            hb.publish(&Heartbeat::monitor(state, seq)).unwrap();
            std::thread::sleep(Duration::from_millis(20));
        }
    });
    wait_status(addr, "the monitor armed and motion-core riding", |s| {
        check_ok(s, "safety monitor armed")
            && s["ride"]["control"]
                .as_str()
                .is_some_and(|c| c.starts_with("riding"))
    });
    // Riding: not idle, refused.
    let (code, body) = http(addr, "POST", "/api/ride/start", &[]);
    assert_eq!(code, 409, "{body}");
    assert!(
        body.contains("motion-core idle and holding: riding"),
        "{body}"
    );
    assert!(fake.requests.lock().unwrap().is_empty());

    // Idle and holding: every check passes, the ride goes to the socket as `crs ride start`.
    *fake.phase.lock().unwrap() = "idle, holding".into();
    wait_status(addr, "the start allowed", |s| {
        s["ride"]["start_allowed"] == true
    });
    let (code, body) = http(addr, "POST", "/api/ride/start", &[]);
    assert_eq!(code, 200, "{body}");
    assert!(body.contains("\"ride\":\"started\""), "{body}");
    assert_eq!(
        *fake.requests.lock().unwrap(),
        vec![format!("start rides/tour.csv\n{ride_text}")]
    );

    // A tripped monitor: the start is refused again and nothing reaches the socket.
    monitor.store(crs_ipc::MonitorState::Tripped.into(), Ordering::Relaxed);
    wait_status(addr, "the trip latched", |s| {
        s["ride"]["start_allowed"] == false && !check_ok(s, "no latched trip")
    });
    let (code, body) = http(addr, "POST", "/api/ride/start", &[]);
    assert_eq!(code, 409, "{body}");
    assert!(
        body.contains("no latched trip: the safety monitor is TRIPPED"),
        "{body}"
    );
    assert_eq!(fake.requests.lock().unwrap().len(), 1);
    done.store(true, Ordering::Relaxed);
    beats.join().unwrap();
    let _ = std::fs::remove_file(&fake.path);
}

#[test]
fn without_a_control_socket_the_start_is_refused_and_says_why() {
    let p = prefix("noride");
    let console = crs_console::spawn(config(&p, None)).unwrap();
    let s = status(console.addr);
    assert_eq!(s["ride"]["start_allowed"], false);
    assert_eq!(s["ride"]["control"], "no control socket");
    let (code, body) = http(console.addr, "POST", "/api/ride/start", &[]);
    assert_eq!(code, 409, "{body}");
    assert!(
        body.contains("no control socket given to the console"),
        "{body}"
    );
    assert!(body.contains("a validated ride loaded: none"), "{body}");
}
