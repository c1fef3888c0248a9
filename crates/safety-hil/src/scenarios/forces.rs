//! Measured forces: one cable's force leaves the band and stays out.

use crate::Res;
use crate::scenarios::{Outcome, ms, trip_ms};
use crate::stack::Stack;
use safety_monitor::Cause;

/// One cable's measured force leaves [f_min − 500 N, f_max + 1000 N] (test cabin: 1000 /
/// 9000 N) and stays there: the monitor's force check (8 of the last 16 readings) trips on that
/// cable. Timed from the instant the emulation loop first reported the injected force (the
/// fault exists for the load cell); how long the emulator took to read the control file is
/// the rig's latency and is printed separately.
pub fn force_fault(st: &mut Stack, cable: usize, force_n: f64, cause: Cause) -> Res<Outcome> {
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let written = st.inject();
    st.set_force(cable, Some(force_n))?;
    let ev = st.monitor_trip(cause, 10.0)?;
    if ev.detail_node as usize != cable {
        return Err(format!(
            "tripped on cable {}, expected {cable}",
            ev.detail_node
        ));
    }
    let stopped = st.require_braked()?;
    let t0 = st.emu()?.drives[cable - 1].force_override_applied_ns;
    if t0 < written {
        return Err(format!(
            "the emulator's status does not show when it applied the injected force on cable \
             {cable} (applied_ns {t0}, control file written at {written})"
        ));
    }
    Ok(Outcome {
        cause: format!("{cause} cable {cable}"),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!(
            "emulated load cell reports {force_n} N (t0 = the emulator's first pass with it, \
             {:.1} ms after the control file was written; 8 of 16 readings)",
            (t0 - written) as f64 * 1e-6
        ),
    })
}

pub fn overload_one_cable(st: &mut Stack) -> Res<Outcome> {
    // Above f_max + margin (10 kN), below drive-io's own hard limit (14 kN): the monitor's
    // filtered overload check is what stops it.
    force_fault(st, 4, 10_500.0, Cause::ForceOverload)
}

pub fn slack_one_cable(st: &mut Stack) -> Res<Outcome> {
    force_fault(st, 2, 200.0, Cause::ForceSlack)
}
