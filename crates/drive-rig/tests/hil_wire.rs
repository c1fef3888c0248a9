//! The HIL scenarios on the host over the wire model (same code as in the vcan VM): each test
//! runs the `can-wire` hub on a thread with the rig's two 1 Mbit/s buses, its own sockets.

use drive_rig::hil::{self, RigBuses};

fn check(name: &str, run: fn(&RigBuses, &str) -> Result<String, String>) {
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("hil-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (hub, transports) = can_wire::HubThread::start(
        &dir,
        &[("can0", 1_000_000), ("can1", 1_000_000)],
        50,
        50,
        100,
    )
    .expect("the wire hub");
    let prefix = format!("hil/{}/{name}/", std::process::id());
    let r = run(&RigBuses::shared(&transports), &prefix);
    let stats = hub.stop().expect("the hub's statistics");
    let _ = std::fs::remove_dir_all(&dir);
    match r {
        Ok(msg) => eprintln!("PASS: {msg}"),
        Err(msg) => panic!("{msg}\nwire statistics: {stats}"),
    }
}

#[test]
fn follow_setpoints() {
    check("follow", hil::scenario_follow);
}

#[test]
fn stale_setpoints_quick_stop() {
    check("stale", hil::scenario_stale);
}

#[test]
fn heartbeat_loss_faults_all() {
    check("hb", hil::scenario_heartbeat_loss);
}

#[test]
fn estop_event_quick_stop_and_reset() {
    check("estop", hil::scenario_estop);
}

#[test]
fn phase_locked_cycles_follow_the_setpoints() {
    check("phase", hil::scenario_phase_lock);
}
