//! TEST DOUBLE: answers as the m CiA 402 winch drives of config/drives.toml and moves each cable
//! kinematically (5 m/s, 14 m/s^2). Not the plant: see crates/sim-plant for the physics.

use clap::Parser;
use drive_rig::emulator::{self, EmulatorConfig, EmulatorControl};
use drives_config::DrivesConfig;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Duration;

#[derive(Parser)]
#[command(about = "Test double: emulates the winch drives (CiA 402 CSP) on the CAN bus")]
struct Args {
    #[arg(long, default_value = "config/drives.toml")]
    config: PathBuf,
    /// Override an interface's transport: `NAME=SPEC` per interface, or a bare SPEC with one.
    #[arg(long)]
    transport: Vec<String>,
    /// Initial cable length of every winch (m).
    #[arg(long, default_value_t = 5.0)]
    initial_length_m: f64,
    /// Stop the heartbeat of this winch index (0-based) after --mute-after-ms (fault injection).
    #[arg(long)]
    mute_heartbeat_index: Option<usize>,
    #[arg(long, default_value_t = 0)]
    mute_after_ms: u64,
    /// Write the emulated drives' true state to this file every 10 ms (atomic rename), for
    /// multi-process tests: lengths, velocities, NMT/CiA 402 state, motion demand, safety watch.
    #[arg(long)]
    status_file: Option<PathBuf>,
    /// FAULT INJECTION and the operator's hand (the safety HIL matrix): re-read this file
    /// every 5 ms; lines `force <cable 1-based> <newtons>|off` make that winch report the given
    /// measured force (TPDO2) instead of the pretension stand-in; `reset_key on|off` and
    /// `estop pressed|released` set the safety I/O node's inputs. A bad line is logged (naming
    /// the line) and ignored; a missing file means no override, key at rest, e-stop released.
    #[arg(long)]
    control_file: Option<PathBuf>,
    /// Run the emulation loop SCHED_FIFO at this priority (1..=99) with mlockall. The drives it
    /// stands in for are hardware with their own CPUs, never starved by the stack: on an
    /// emulated or loaded host (the QEMU guest of tools/safety-hil.sh) this keeps the test
    /// double from stalling hundreds of ms behind motion-core's start-up, which drive-io then
    /// (rightly) sees as lost drive heartbeats. Refused with an error if not granted.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    rt_priority: Option<i32>,
}

fn main() -> ExitCode {
    crs_log::init("winch-emulator");
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("winch-emulator: error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> Result<(), Box<dyn std::error::Error>> {
    let mut cfg = DrivesConfig::load(&args.config)?;
    cfg.override_transports(&args.transport)?;
    if !(args.initial_length_m.is_finite() && args.initial_length_m >= 0.0) {
        return Err("--initial-length-m must be finite and >= 0".into());
    }
    if let Some(i) = args.mute_heartbeat_index
        && i >= cfg.winches.len()
    {
        return Err(format!(
            "--mute-heartbeat-index {i}: only {} winches",
            cfg.winches.len()
        )
        .into());
    }
    let ecfg = EmulatorConfig::from_drives(&cfg, args.initial_length_m)?;
    let buses = cfg
        .transports()?
        .iter()
        .map(can_transport::open)
        .collect::<Result<Vec<_>, _>>()?;
    let control = EmulatorControl::new();
    if let Some(i) = args.mute_heartbeat_index {
        let c = control.clone();
        std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(args.mute_after_ms));
            tracing::warn!(index = i, "muting heartbeat (fault injection)");
            c.mute_heartbeat(i);
        });
    }
    if let Some(path) = args.status_file.clone() {
        let c = control.clone();
        let m = cfg.winches.len();
        std::thread::spawn(move || write_status_loop(&path, &c, m));
    }
    if let Some(path) = args.control_file.clone() {
        let c = control.clone();
        let m = cfg.winches.len();
        std::thread::spawn(move || read_control_loop(&path, &c, m));
    }
    tracing::info!(
        drives = cfg.winches.len(),
        safety_watch = ?ecfg.safety_watch,
        "winch emulator (test double) running"
    );
    if let Some(p) = args.rt_priority {
        // After the helper threads were spawned: only this (the emulation) thread is FIFO.
        let report = crs_rt::make_realtime(p, None)?;
        tracing::info!(
            priority = p,
            ?report,
            "emulation loop SCHED_FIFO + mlockall"
        );
    }
    emulator::run(buses, &ecfg, &control)?;
    control.stop.store(true, Ordering::Release);
    Ok(())
}

/// Status file format (one record per line, space separated):
/// `emulator <monotonic_ns> <syncs> <safety_inhibit 0|1> <safety_trips> <safety_tripped_ns>` then
/// per drive `drive <i> <length_m> <velocity_m_per_s> <nmt code> <statusword> <demand 0 hold|1
/// quick stop|2 follow> <left_follow_ns> <force_override_applied_ns>`.
fn write_status_loop(path: &std::path::Path, c: &EmulatorControl, m: usize) {
    use std::fmt::Write as _;
    let tmp = path.with_extension("tmp");
    let mut text = String::new();
    while !c.stop.load(Ordering::Acquire) {
        text.clear();
        let _ = writeln!(
            text,
            "emulator {} {} {} {} {}",
            crs_ipc::monotonic_ns(),
            c.syncs.load(Ordering::Acquire),
            u8::from(c.safety_inhibit.load(Ordering::Acquire)),
            c.safety_trips.load(Ordering::Acquire),
            c.safety_tripped_ns.load(Ordering::Acquire)
        );
        // Every drive's line from one pass of the emulation loop: a demand with the length
        // of the same pass (a braked drive never shows the length before its last step).
        let header = text.len();
        c.read_consistent(|c| {
            text.truncate(header);
            for i in 0..m {
                let _ = writeln!(
                    text,
                    "drive {i} {:.9} {:.9} {} {} {} {} {}",
                    c.length_m(i),
                    c.velocity_m_per_s(i),
                    c.nmt_state(i).map_or(255, |s| s.code()),
                    c.ds402_state(i).statusword(),
                    c.demand_code(i),
                    c.left_follow_ns(i),
                    c.force_override_applied_ns(i)
                );
            }
        });
        if std::fs::write(&tmp, &text).is_ok() {
            let _ = std::fs::rename(&tmp, path);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// One line of the control file.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Control {
    /// `force <cable 1-based> <newtons>|off`: the measured force cable `i` reports.
    Force(usize, Option<f64>),
    /// `reset_key on|off`: the safety I/O node's reset key turned (the operator's hand).
    ResetKey(bool),
    /// `estop pressed|released`: the safety I/O node's e-stop button (circuit open).
    EStop(bool),
}

fn parse_control_line(line: &str, m: usize) -> Result<Option<Control>, String> {
    let f: Vec<&str> = line.split_whitespace().collect();
    match f.as_slice() {
        [] => Ok(None),
        [c, ..] if c.starts_with('#') => Ok(None),
        ["force", cable, value] => {
            let i: usize = cable
                .parse()
                .ok()
                .filter(|&i| (1..=m).contains(&i))
                .ok_or_else(|| format!("cable {cable:?} is not in 1..={m}"))?;
            let v = match *value {
                "off" => None,
                v => Some(
                    v.parse::<f64>()
                        .ok()
                        .filter(|x| x.is_finite())
                        .ok_or_else(|| format!("force {v:?} is not a finite number (N)"))?,
                ),
            };
            Ok(Some(Control::Force(i - 1, v)))
        }
        ["reset_key", "on"] => Ok(Some(Control::ResetKey(true))),
        ["reset_key", "off"] => Ok(Some(Control::ResetKey(false))),
        ["estop", "pressed"] => Ok(Some(Control::EStop(true))),
        ["estop", "released"] => Ok(Some(Control::EStop(false))),
        _ => Err(
            "expected `force <cable> <newtons>|off`, `reset_key on|off` or \
             `estop pressed|released`"
                .into(),
        ),
    }
}

/// Re-reads the control file every 5 ms; its whole text is the injected state (a line that is
/// absent means: no force override, key at rest, e-stop released).
fn read_control_loop(path: &std::path::Path, c: &EmulatorControl, m: usize) {
    let mut last = String::new();
    while !c.stop.load(Ordering::Acquire) {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        if text != last {
            let mut set = vec![None; m];
            let (mut key, mut estop) = (false, false);
            for (n, line) in text.lines().enumerate() {
                match parse_control_line(line, m) {
                    Ok(Some(Control::Force(i, v))) => set[i] = v,
                    Ok(Some(Control::ResetKey(on))) => key = on,
                    Ok(Some(Control::EStop(pressed))) => estop = pressed,
                    Ok(None) => {}
                    Err(e) => tracing::error!("{}:{}: {e}", path.display(), n + 1),
                }
            }
            for (i, v) in set.into_iter().enumerate() {
                if v.is_some() {
                    tracing::warn!(
                        cable = i + 1,
                        force_n = v,
                        "measured force overridden (fault injection)"
                    );
                }
                c.set_force_override(i, v);
            }
            // Bit 0: e-stop circuit OPEN (pressed), bit 1: reset key turned.
            let inputs = u8::from(estop) | (u8::from(key) << 1);
            if c.io_inputs.swap(inputs, Ordering::AcqRel) != inputs {
                tracing::info!(
                    reset_key = key,
                    estop_pressed = estop,
                    "safety I/O node inputs"
                );
            }
            last = text;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[cfg(test)]
mod tests {
    use super::{Control, parse_control_line};

    #[test]
    fn control_lines() {
        assert_eq!(
            parse_control_line("force 3 10500", 8),
            Ok(Some(Control::Force(2, Some(10500.0))))
        );
        assert_eq!(
            parse_control_line("force 8 off", 8),
            Ok(Some(Control::Force(7, None)))
        );
        assert_eq!(parse_control_line("  # x", 8), Ok(None));
        assert_eq!(
            parse_control_line("reset_key on", 8),
            Ok(Some(Control::ResetKey(true)))
        );
        assert_eq!(
            parse_control_line("estop pressed", 8),
            Ok(Some(Control::EStop(true)))
        );
        assert!(parse_control_line("reset_key maybe", 8).is_err());
        assert!(
            parse_control_line("force 9 1", 8)
                .unwrap_err()
                .contains("cable")
        );
        assert!(
            parse_control_line("force 1 NaN", 8)
                .unwrap_err()
                .contains("finite")
        );
        assert!(parse_control_line("forc 1 1", 8).is_err());
    }
}
