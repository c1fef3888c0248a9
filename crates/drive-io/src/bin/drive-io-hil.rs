//! HIL test binary for the vcan VM (built static, copied into the guest by tools/hil-run.sh):
//! runs every scenario of `drive_io::hil`, one CAN interface each, prints `HIL PASS|FAIL` lines
//! and `HIL_RESULT PASS|FAIL`; exit status 0 iff all passed.
//!
//! usage: drive-io-hil [--realtime] [TRANSPORT...]   (default socketcan:vcan0 .. socketcan:vcan3)
//! Without --realtime (the VM case) timing-dependent checks are reported, not asserted.

use std::process::ExitCode;

fn main() -> ExitCode {
    crs_log::init("drive-io-hil");
    let mut transports: Vec<String> = std::env::args().skip(1).collect();
    let timing = if transports.first().is_some_and(|a| a == "--realtime") {
        transports.remove(0);
        drive_io::hil::Timing::RealTime
    } else {
        drive_io::hil::Timing::Emulated
    };
    if transports.is_empty() {
        transports = (0..4).map(|i| format!("socketcan:vcan{i}")).collect();
    }
    let prefix = format!("hil-vm/{}/", std::process::id());
    let ok = drive_io::hil::run_all(&transports, &prefix, timing);
    println!("HIL_RESULT {}", if ok { "PASS" } else { "FAIL" });
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
