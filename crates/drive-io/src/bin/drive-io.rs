//! drive-io daemon: CiA 402 master for the winch drives (see docs/can-protocol.md). The
//! command line and the process live in [`drive_io::cli`]; this binary refuses a drives config
//! without the safety monitor's heartbeat (`[safety_heartbeat]`), with no switch to allow it.

use clap::{CommandFactory, Parser};
use drive_io::cli::{Args, Bench, run};
use std::process::ExitCode;

fn main() -> ExitCode {
    if let Some(code) = crs_service::gen_man_if_asked("drive-io", Args::command) {
        return code;
    }
    crs_log::init("drive-io");
    match run(Args::parse(), Bench::Refused) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("drive-io: error: {e}");
            ExitCode::FAILURE
        }
    }
}
