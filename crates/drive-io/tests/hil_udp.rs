//! The HIL scenarios on the host over the CAN-over-UDP multicast bus (same code as in the vcan VM).

use drive_io::hil;

fn transport(k: u16) -> String {
    // A distinct multicast port per scenario and test process, so parallel runs don't share a bus.
    format!(
        "udpbus:239.255.70.2:{}",
        40000 + (std::process::id() % 1000) as u16 * 8 + k
    )
}

fn prefix(name: &str) -> String {
    format!("hil/{}/{name}/", std::process::id())
}

fn check(r: Result<String, String>) {
    match r {
        Ok(msg) => eprintln!("PASS: {msg}"),
        Err(msg) => panic!("{msg}"),
    }
}

#[test]
fn follow_setpoints() {
    check(hil::scenario_follow(&transport(0), &prefix("follow")));
}

#[test]
fn stale_setpoints_quick_stop() {
    check(hil::scenario_stale(&transport(1), &prefix("stale")));
}

#[test]
fn heartbeat_loss_faults_all() {
    check(hil::scenario_heartbeat_loss(&transport(2), &prefix("hb")));
}

#[test]
fn estop_event_quick_stop_and_reset() {
    check(hil::scenario_estop(&transport(3), &prefix("estop")));
}

#[test]
fn phase_locked_cycles_follow_the_setpoints() {
    check(hil::scenario_phase_lock(&transport(4), &prefix("phase")));
}
