//! Process-bus hardening and configuration integrity: a forged STOPPING, a foreign
//! setpoint publisher, drives with another SRDO configuration, tampered safety configs.

use crate::Res;
use crate::emulator::DEMAND_FOLLOW;
use crate::scenarios::{Outcome, ms, trip_ms};
use crate::stack::Stack;
use crs_ipc::{BusState, IpcNode, StateEvent, monotonic_ns};
use safety_monitor::Cause;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// A STOPPING announced by another process in motion-core's name while motion-core is in
/// the middle of its plan: it would disarm the silence and sequence checks. The monitor
/// trips `unplanned_stream_end`, everything brakes.
pub fn forged_stopping(st: &mut Stack) -> Res<Outcome> {
    st.start_motion_core()?;
    st.wait_following(true)?;
    let node = IpcNode::with_prefix("shil-forger", &st.prefix).map_err(|e| e.to_string())?;
    let publ = node.publisher::<StateEvent>().map_err(|e| e.to_string())?;
    let ev = StateEvent::motion(crs_ipc::MotionState::Stopping, 1);
    let t0 = monotonic_ns();
    publ.publish(&ev).map_err(|e| e.to_string())?;
    let trip = st.monitor_trip(Cause::UnplannedStreamEnd, 10.0)?;
    let stopped = st.require_braked()?;
    st.wait("motion-core latched (E-STOPPED)", 10.0, |s| {
        Ok(s.motion_state == Some(crs_ipc::MotionState::EStopped))
    })?;
    Ok(Outcome {
        cause: "unplanned_stream_end".into(),
        detect_ms: trip_ms(t0, trip.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: "STOPPING forged mid-plan by another process; motion-core e-stopped".into(),
    })
}

/// Another process (this harness, not motion-core) owns the setpoint stream and publishes
/// perfectly plausible setpoints at home with the right identity: only the owner check
/// (publisher's process executable, iceoryx2 service introspection) can tell. The monitor
/// trips `foreign_publisher`, the drives brake.
pub fn foreign_publisher(st: &mut Stack) -> Res<Outcome> {
    let t0 = st.inject();
    let c = st.fake()?.clone();
    let trip = st.monitor_trip(Cause::ForeignPublisher, 10.0)?;
    let stopped = st.require_braked()?;
    if c.published.load(Ordering::Relaxed) == 0 {
        return Err("the foreign publisher published nothing".into());
    }
    Ok(Outcome {
        cause: "foreign_publisher".into(),
        detect_ms: trip_ms(t0, trip.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: "setpoint stream opened by safety-hil (valid setpoints, right identity)".into(),
    })
}

/// The drives (winch emulator) are configured with another SRDO validation time than the
/// monitor announces: their configuration CRC differs, so their watch never permits; no
/// drive is ever enabled although the monitor runs and drive-io tries; nothing moves, also
/// not when motion-core starts.
pub fn heartbeat_config_crc_mismatch(st: &mut Stack) -> Res<Outcome> {
    st.wait("the monitor RUN (every drive operational)", 30.0, |s| {
        Ok(s.monitor_state == Some(crs_ipc::MonitorState::Armed))
    })?;
    st.start_motion_core()?;
    // Watch for 3 s of monitor cycles: no drive enabled, none following, drive-io never
    // Ready / Running, the emulator's watch inhibiting throughout.
    let h0 = st.monitor_heartbeats;
    let e0 = st.emu()?;
    st.wait("3 s of monitor cycles", 30.0, |s| {
        let e = s.emu()?;
        if !e.inhibit || e.drives.iter().any(|d| d.demand == DEMAND_FOLLOW) {
            return Err("a drive was released or follows despite the CRC mismatch".into());
        }
        if matches!(s.bus_state(), Some(BusState::Ready | BusState::Running)) {
            return Err("drive-io enabled the drives despite the CRC mismatch".into());
        }
        Ok(s.monitor_heartbeats >= h0 + 200)
    })?;
    st.require_braked()?;
    let e1 = st.emu()?;
    for (i, (a, b)) in e0.drives.iter().zip(&e1.drives).enumerate() {
        if (a.length_m - b.length_m).abs() > 1e-9 {
            return Err(format!("cable {} moved", i + 1));
        }
    }
    Ok(Outcome {
        cause: "drives: SRDO configuration CRC mismatch".into(),
        detect_ms: None,
        stop_ms: None,
        note: "emulator's validation time 10 ms longer than the monitor's: its watch never \
               permitted over 200 monitor cycles, drive-io never enabled"
            .into(),
    })
}

/// Runs `safety-monitor --config cfg` and requires it to refuse to start (exit != 0 within
/// 10 s) with `expect` in its error output.
pub fn refuses(st: &Stack, cfg: &Path, expect: &str) -> Res<()> {
    let mut child = Command::new(st.exe("safety-monitor"))
        .arg("--config")
        .arg(cfg)
        .args(st.buses.args("safety-monitor"))
        .env("CRS_IPC_PREFIX", format!("{}tampered/", st.prefix))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| e.to_string())?;
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().map_err(|e| e.to_string())? {
            break s;
        }
        if t0.elapsed() > Duration::from_secs(10) {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("{}: the monitor STARTED", cfg.display()));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let out = child.wait_with_output().map_err(|e| e.to_string())?;
    let err = String::from_utf8_lossy(&out.stderr);
    if status.success() || !err.contains(expect) {
        return Err(format!(
            "{}: exit {status}, expected a refusal naming {expect}: {err}",
            cfg.display()
        ));
    }
    Ok(())
}

/// The operator restarts the monitor on a tampered safety configuration: the platform file
/// changed after it was accepted (one parameter edited), or a check switched off in the
/// robot profile. The monitor refuses to start in both cases; without its heartbeat the
/// drives and drive-io brake, and nothing moves.
pub fn tampered_safety_config(st: &mut Stack) -> Res<Outcome> {
    st.start_motion_core()?;
    st.wait_following(true)?;
    let t0 = monotonic_ns();
    st.signal("safety-monitor", libc::SIGTERM)?;
    st.reap("safety-monitor");
    let mon =
        std::fs::read_to_string(st.cfg.join("safety-monitor.toml")).map_err(|e| e.to_string())?;
    let plat = std::fs::read_to_string(st.cfg.join("platform.toml")).map_err(|e| e.to_string())?;
    // 1. The platform edited after acceptance (f_max 9000 -> 9900 N).
    let tampered = plat.replace("f_max_n = 9000.0", "f_max_n = 9900.0");
    if tampered == plat {
        return Err("could not tamper with the platform".into());
    }
    std::fs::write(st.dir.join("platform.toml"), tampered).map_err(|e| e.to_string())?;
    std::fs::copy(st.cfg.join("drives.toml"), st.dir.join("drives.toml"))
        .map_err(|e| e.to_string())?;
    let cfg1 = st.dir.join("safety-monitor-tampered-platform.toml");
    std::fs::write(&cfg1, &mon).map_err(|e| e.to_string())?;
    refuses(st, &cfg1, "monitor.platform_sha256")?;
    // 2. A check switched off outside the bench profile.
    let off = mon.replace("check_rpdo = true", "check_rpdo = false");
    if off == mon {
        return Err("could not switch check_rpdo off".into());
    }
    std::fs::write(st.dir.join("platform.toml"), &plat).map_err(|e| e.to_string())?;
    let cfg2 = st.dir.join("safety-monitor-check-off.toml");
    std::fs::write(&cfg2, off).map_err(|e| e.to_string())?;
    refuses(st, &cfg2, "can.check_rpdo")?;
    let (_, stopped) = st.stopped_by_the_drives_watch()?;
    Ok(Outcome {
        cause: "monitor refused both tampered configs".into(),
        detect_ms: None,
        stop_ms: ms(t0, stopped),
        note: "platform edited after acceptance; check_rpdo off in the robot profile".into(),
    })
}
