//! HIL test binary for the vcan VM (built static, copied into the guest by tools/hil-run.sh):
//! runs every scenario of `drive_rig::hil` on the wire model, one set of buses each, prints
//! `HIL PASS|FAIL` lines and `HIL_RESULT PASS|FAIL`; exit status 0 iff all passed.
//!
//! usage: drive-io-hil [--realtime] BUSES...
//!   BUSES: `dio=socketcan:A,socketcan:B;emu=socketcan:C,socketcan:D` (drive-io's and the
//!   emulator's vcan port of each of the rig's two interfaces; the `can-wire` hub forwards
//!   between them, tests/hil/drive-hil-guest.sh), or `T0,T1` for both nodes.
//! Without --realtime (the VM case) timing-dependent checks are reported, not asserted.

use std::process::ExitCode;

fn main() -> ExitCode {
    crs_log::init("drive-io-hil");
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let timing = if args.first().is_some_and(|a| a == "--realtime") {
        args.remove(0);
        drive_rig::hil::Timing::RealTime
    } else {
        drive_rig::hil::Timing::Emulated
    };
    let buses: Result<Vec<_>, _> = args
        .iter()
        .map(|a| drive_rig::hil::RigBuses::parse(a))
        .collect();
    let buses = match buses {
        Ok(b) if !b.is_empty() => b,
        Ok(_) => {
            eprintln!("drive-io-hil: give the rig's buses (see --help in the source)");
            return ExitCode::from(2);
        }
        Err(e) => {
            eprintln!("drive-io-hil: {e}");
            return ExitCode::from(2);
        }
    };
    let prefix = format!("hil-vm/{}/", std::process::id());
    let ok = drive_rig::hil::run_all(&buses, &prefix, timing);
    println!("HIL_RESULT {}", if ok { "PASS" } else { "FAIL" });
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
