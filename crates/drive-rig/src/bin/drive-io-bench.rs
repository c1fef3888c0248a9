//! BENCH ONLY: `drive-io-bench` is drive-io (the same command line, [`drive_io::cli`]) that also
//! runs a drives config without `[safety_heartbeat]` — no safety monitor on the bus, nothing
//! stops the drives when a monitor is absent. A separate executable of the test rigs, so the
//! production `drive-io` has no switch for it; never named in config/ or systemd/ (checked by
//! crates/drive-io/tests/shipped_configs.rs); `crs sim --no-monitor` uses it only for a drives
//! config without the table. Logged as an error at start.

use clap::Parser;
use drive_io::cli::{Args, Bench, run};
use std::process::ExitCode;

fn main() -> ExitCode {
    crs_log::init("drive-io");
    match run(Args::parse(), Bench::WithoutSafetyHeartbeat) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("drive-io-bench: error: {e}");
            ExitCode::FAILURE
        }
    }
}
