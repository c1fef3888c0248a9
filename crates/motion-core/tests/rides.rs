//! Rides started on purpose: the loop comes up idle holding home; a ride runs only when handed
//! in and verified; a bad ride is refused naming file, line, axis and bound and moves nothing;
//! abort brakes at the planner's per-axis accelerations to rest; start away from home is
//! refused; home returns; a latched loop refuses rides until the monitor's reset. The control
//! socket's protocol round trip. The loop thread allocates and frees nothing throughout.
mod common;

use crs_ipc::JointSetpoint;
use crs_ipc::ride_control::{self as ride_control, Request};
use motion_core::daemon::ride::{RideCommandError, RideControl, RidePhase, RideSlot};
use motion_core::daemon::ride_socket;
use motion_core::daemon::stats::LoopStats;
use motion_core::daemon::trajectory::{self, PlanningFailed};
use motion_core::daemon::{
    Command, CommandSource, HardLoop, LoopState, ResetGate, SetpointSink, config, lifecycle,
};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);
thread_local!(static COUNT_HERE: Cell<bool> = const { Cell::new(false) });

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if COUNT_HERE.with(|c| c.get()) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        if COUNT_HERE.with(|c| c.get()) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.dealloc(p, l) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

struct Last(Option<JointSetpoint>, u64);
impl SetpointSink for Last {
    fn publish(&mut self, sp: &JointSetpoint) -> bool {
        self.0 = Some(*sp);
        self.1 += 1;
        true
    }
}

struct Commands(Option<Command>);
impl CommandSource for Commands {
    fn poll(&mut self) -> Option<Command> {
        self.0.take()
    }
}

struct Rig {
    hl: HardLoop,
    slot: Arc<RideSlot>,
    control: RideControl,
    sink: Last,
    cmds: Commands,
    stats: LoopStats,
    limits: trajectory::PlannerLimits,
    home: [f64; 6],
}

fn no_error(e: PlanningFailed) {
    panic!("{e}")
}

fn rig() -> Rig {
    let cfg = config::load(common::config_path("motion-core.toml").as_ref()).unwrap();
    let pf = common::platform("icosahedron.toml");
    let c = lifecycle::configure_checks(&cfg, &pf).unwrap();
    let limits = c.planner_limits();
    let period_s = c.period_s();
    let slot = Arc::new(RideSlot::new(pf.home, 0));
    let hl = c
        .activate(Vec::new(), no_error)
        .with_rides(slot.clone(), limits, period_s, pf.home);
    let control = RideControl::new(lifecycle::configure_checks(&cfg, &pf).unwrap());
    Rig {
        hl,
        slot,
        control,
        sink: Last(None, 0),
        cmds: Commands(None),
        stats: LoopStats::default(),
        limits,
        home: pf.home.to_array(),
    }
}

impl Rig {
    /// One loop cycle, counting the loop thread's allocations.
    fn step(&mut self) -> LoopState {
        COUNT_HERE.with(|c| c.set(true));
        let s = self.hl.step(0, &mut self.sink, &mut self.cmds, &self.stats);
        COUNT_HERE.with(|c| c.set(false));
        s
    }

    fn sp(&self) -> JointSetpoint {
        self.sink.0.expect("a setpoint was published")
    }

    /// Steps until `cond` holds (the planner thread fills the loop's queue meanwhile);
    /// panics after `max` cycles.
    fn until(&mut self, what: &str, max: usize, mut cond: impl FnMut(&Self) -> bool) -> usize {
        for n in 0..max {
            self.step();
            if cond(self) {
                return n + 1;
            }
            std::thread::yield_now();
        }
        panic!(
            "{what}: not after {max} cycles (phase {:?})",
            self.slot.phase()
        )
    }
}

const HEADER: &str = "t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg\n";

fn ride(name: &str, rows: &str) -> trajectory::RideFile {
    trajectory::parse_ride(&format!("{HEADER}{rows}"), name).unwrap()
}

fn dist(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn the_loop_comes_up_idle_holding_home_and_moves_only_for_a_verified_ride() {
    let mut r = rig();
    // Idle: 500 cycles of the home setpoint, at rest.
    r.until("the idle plan delivered", 10_000, |r| {
        r.slot.phase() == RidePhase::Idle
    });
    let q0 = r.sp().cable_length_m;
    for _ in 0..500 {
        assert_eq!(r.step(), LoopState::Running);
        assert_eq!(r.slot.phase(), RidePhase::Idle);
        let sp = r.sp();
        assert_eq!(sp.cable_length_m, q0, "the idle loop moved");
        assert_eq!(dist(&sp.pose, &r.home), 0.0);
        assert_eq!(sp.pose_velocity, [0.0; 6]);
    }

    // A ride that leaves the region is refused naming the file, line, axis and bound, and
    // nothing is handed to the loop.
    let bad = ride("bad.csv", "0,0.3,0,2,0,0,0\n2,0,4.0,2,0,0,0\n");
    let e = r.control.start(&r.slot, &bad, no_error).unwrap_err();
    let text = e.to_string();
    assert!(matches!(e, RideCommandError::Refused(_)), "{text}");
    assert!(text.contains("bad.csv:3:"), "{text}");
    assert!(text.contains("y_m = 4.000 m"), "{text}");
    assert!(text.contains("[-1.500, 1.500] m"), "{text}");
    for _ in 0..200 {
        r.step();
        assert_eq!(
            r.sp().cable_length_m,
            q0,
            "a refused ride moved the platform"
        );
    }
    assert_eq!(r.slot.rides_started(), 0);

    // A good ride runs; a second start while riding is refused.
    let good = ride("good.csv", "0,0.5,0.0,2.0,0,0,0\n0,0.5,0.4,2.0,0,0,2\n");
    let plan = r.control.start(&r.slot, &good, no_error).unwrap();
    assert!(plan.samples > 100, "{plan:?}");
    r.until("the ride under way", 10_000, |r| {
        r.slot.phase() == RidePhase::Riding && dist(&r.sp().pose, &r.home) > 0.01
    });
    assert_eq!(r.slot.rides_started(), 1);
    let again = r.control.start(&r.slot, &good, no_error).unwrap_err();
    assert!(
        matches!(again, RideCommandError::NotIdle(RidePhase::Riding)),
        "{again}"
    );

    // Abort at speed: the ride brakes at the planner's per-axis accelerations to rest.
    r.until("the ride at speed", 100_000, |r| {
        let v = r.sp().pose_velocity;
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() > 0.05
    });
    r.control.abort(&r.slot).unwrap();
    // The brake takes the fastest axis' |v| / (a/√3) cycles (within one), never a jump.
    let v0 = r.sp().pose_velocity;
    let a_lin = r.limits.linear_acceleration / 3f64.sqrt();
    let longest = v0[..3].iter().map(|v| v.abs()).fold(0.0, f64::max) / a_lin / 1e-3;
    let braking = r.until("braked to rest", 100_000, |r| {
        r.slot.phase() == RidePhase::Idle
    });
    assert!(
        (braking as f64 - longest).abs() <= 2.0,
        "braked in {braking} cycles, expected {longest:.1}"
    );
    r.step();
    let rest = r.sp();
    assert_eq!(rest.pose_velocity, [0.0; 6]);
    assert!(dist(&rest.pose, &r.home) > 0.01, "braked where it was");
    assert!(
        r.slot.plan_end() <= r.sink.1,
        "the stream's end ({}) is not yet reached after braking ({} setpoints)",
        r.slot.plan_end(),
        r.sink.1
    );
    assert!(matches!(
        r.control.abort(&r.slot),
        Err(RideCommandError::NothingToAbort(RidePhase::Idle))
    ));

    // Away from home: start refused; home returns; then a ride starts again.
    let away = r.control.start(&r.slot, &good, no_error).unwrap_err();
    assert!(matches!(away, RideCommandError::NotAtHome(_)), "{away}");
    r.control.home(&r.slot, no_error).unwrap();
    r.until("back home", 100_000, |r| {
        r.slot.phase() == RidePhase::Idle && r.slot.rides_started() == 2
    });
    assert!(dist(&r.slot.pose().to_array(), &r.home) < 1e-6);
    r.control.start(&r.slot, &good, no_error).unwrap();
    r.until("the second ride under way", 10_000, |r| {
        r.slot.phase() == RidePhase::Riding
    });

    // E-stop: latched, rides refused; after the monitor's reset the loop holds, and home works.
    r.cmds.0 = Some(Command::EStop);
    assert_eq!(r.step(), LoopState::EStopped);
    assert_eq!(r.slot.phase(), RidePhase::Latched);
    assert!(matches!(
        r.control.home(&r.slot, no_error),
        Err(RideCommandError::Latched)
    ));
    // The monitor's reset as the gate accepts it: its epoch announced, then the Reset event of
    // that epoch, both fresh on the loop's clock.
    let now = crs_ipc::monotonic_ns();
    let mut gate = ResetGate::new();
    let mut announce = crs_ipc::StateEvent::new(
        crs_ipc::ProcessId::SafetyMonitor,
        crs_ipc::EventKind::StateChanged,
        1,
    );
    announce.detail = crs_ipc::MonitorCode::EpochAnnounce.into();
    announce.detail_node = 1;
    announce.timestamp_ns = now;
    assert!(
        gate.check(&announce, now).is_err(),
        "an announcement is not a reset"
    );
    let mut ev = crs_ipc::StateEvent::new(
        crs_ipc::ProcessId::SafetyMonitor,
        crs_ipc::EventKind::Reset,
        2,
    );
    ev.detail = 1;
    ev.timestamp_ns = now;
    r.cmds.0 = Some(Command::Reset(gate.check(&ev, now).unwrap()));
    assert_eq!(r.step(), LoopState::Holding);
    assert_eq!(r.slot.phase(), RidePhase::Idle);
    r.control.home(&r.slot, no_error).unwrap();
    r.until("home after the reset", 100_000, |r| {
        r.slot.rides_started() == 4 && r.slot.phase() == RidePhase::Idle
    });
    assert!(dist(&r.slot.pose().to_array(), &r.home) < 1e-6);
    assert_eq!(
        ALLOCS.load(Ordering::Relaxed),
        0,
        "the loop thread allocated"
    );
}

/// The state code heartbeats and state events carry (`HardLoop::state_code`), in words: an
/// idle loop must say HOLDING, never RUNNING (the console, the run report and safety-hil read
/// it as "what motion-core does").
#[test]
fn heartbeats_say_holding_while_idle_and_running_only_while_a_ride_moves() {
    use crs_ipc::MotionState::{EStopped as ESTOPPED, Holding as HOLDING, Running as RUNNING};
    let mut r = rig();
    // From the very first cycle (no waypoints: nothing to wait for), for as long as it idles.
    for n in 0..300 {
        r.step();
        assert_eq!(
            r.hl.state_code(),
            HOLDING,
            "idle cycle {n} reports {:?}",
            r.hl.state_code()
        );
        assert!(r.hl.is_idle());
    }
    let good = ride("good.csv", "0,0.5,0.0,2.0,0,0,0\n");
    r.control.start(&r.slot, &good, no_error).unwrap();
    r.until("the ride under way", 10_000, |r| {
        r.slot.phase() == RidePhase::Riding
    });
    assert_eq!(r.hl.state_code(), RUNNING, "a ride under way");
    // Every cycle until the ride's end says RUNNING; from then on HOLDING again.
    let mut riding = 0usize;
    while r.slot.phase() == RidePhase::Riding {
        assert_eq!(r.hl.state_code(), RUNNING);
        r.step();
        riding += 1;
        assert!(riding < 200_000, "the ride never ended");
    }
    assert!(riding > 100, "{riding} cycles");
    assert_eq!(r.slot.phase(), RidePhase::Idle);
    for _ in 0..100 {
        r.step();
        assert_eq!(r.hl.state_code(), HOLDING, "idle after the ride");
    }
    // An abort braked to rest is idle too.
    r.control.home(&r.slot, no_error).unwrap();
    r.until("homing under way", 10_000, |r| {
        r.slot.phase() == RidePhase::Riding
    });
    r.control.abort(&r.slot).unwrap();
    r.until("braked to rest", 100_000, |r| {
        r.slot.phase() == RidePhase::Idle
    });
    r.step();
    assert_eq!(r.hl.state_code(), HOLDING, "braked to rest");
    // A latch says what it is, not HOLDING.
    r.cmds.0 = Some(Command::EStop);
    r.step();
    assert_eq!(r.hl.state_code(), ESTOPPED);
    assert!(!r.hl.is_idle());
}

#[test]
fn braking_reduces_each_axis_speed_at_the_planner_limit_and_stops() {
    let limits = rig().limits;
    let dt = 1e-3;
    let mut r = motion_core::daemon::cycle::Reference {
        velocity: [0.3, -0.2, 0.1, 0.02, 0.0, -0.01],
        ..Default::default()
    };
    let s3 = 3f64.sqrt();
    let mut n = 0usize;
    loop {
        let before = r.velocity;
        let rest = motion_core::daemon::ride::brake_step(&mut r, &limits, dt);
        n += 1;
        for (k, (v, v0)) in r.velocity.iter().zip(before).enumerate() {
            let a = if k < 3 {
                limits.linear_acceleration
            } else {
                limits.angular_acceleration
            } / s3;
            let dv = (v - v0).abs();
            assert!(dv <= a * dt * (1.0 + 1e-12), "axis {k}: {dv}");
            assert!(v.abs() <= v0.abs(), "axis {k} sped up");
            assert!(v * v0 >= 0.0, "axis {k} reversed");
        }
        if rest {
            break;
        }
        assert!(n < 100_000);
    }
    assert_eq!(r.velocity, [0.0; 6]);
    // The slowest axis took |v|/a cycles: 0.3 m/s at the linear limit.
    let expect = (0.3 / (limits.linear_acceleration / s3) / dt).ceil() as usize;
    assert!(n.abs_diff(expect) <= 1, "{n} cycles, expected {expect}");
}

#[test]
fn the_control_socket_answers_ok_and_refused_lines() {
    let r = rig();
    let dir = std::env::temp_dir().join(format!("crs-ride-sock-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("control.sock");
    let listener = ride_socket::bind(&path).unwrap();
    let (slot, control) = (r.slot.clone(), r.control);
    let server = std::thread::spawn(move || {
        for conn in listener.incoming().take(3) {
            ride_socket::serve_one(conn.unwrap(), &control, &slot, |_| {}).unwrap();
        }
    });
    let status = ride_control::request(&path, &Request::Status).unwrap();
    assert!(status.starts_with("idle, holding"), "{status}");
    let refused = ride_control::request(
        &path,
        &Request::Start {
            name: "/home/op/rides/wild.csv".into(),
            text: format!("# wild\n{HEADER}0,0,0,2,0,9,0\n"),
        },
    )
    .unwrap_err()
    .to_string();
    assert!(refused.contains("/home/op/rides/wild.csv:3:"), "{refused}");
    assert!(refused.contains("phi_y_deg = 9.000 °"), "{refused}");
    let abort = ride_control::request(&path, &Request::Abort)
        .unwrap_err()
        .to_string();
    assert!(abort.contains("no ride to abort"), "{abort}");
    server.join().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}
