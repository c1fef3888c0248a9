//! A process of the stack dies, freezes or is replaced: motion-core frozen or killed, drive-io
//! killed (and replaced by a faulty adapter), the monitor killed.

use crate::Res;
use crate::scenarios::{Outcome, ms, trip_ms};
use crate::stack::{Stack, open_bus};
use crs_ipc::{BusState, DriveFeedback, IpcNode, monotonic_ns};
use safety_monitor::Cause;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

pub fn motion_core_fault(st: &mut Stack, sig: i32) -> Res<Outcome> {
    st.start_motion_core()?;
    st.wait_following(true)?;
    // Let it run a little.
    std::thread::sleep(Duration::from_millis(300));
    st.poll()?;
    let t0 = monotonic_ns();
    st.signal("motion-core", sig)?;
    if sig == libc::SIGKILL {
        st.reap("motion-core");
    }
    let ev = st.monitor_trip(Cause::SetpointSilence, 10.0)?;
    let stopped = st.require_braked()?;
    if sig == libc::SIGSTOP {
        // Thawing the loop does not restart motion: the latch holds.
        st.signal("motion-core", libc::SIGCONT)?;
        std::thread::sleep(Duration::from_millis(300));
        st.require_braked()?;
    }
    Ok(Outcome {
        cause: "setpoint_silence".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: if sig == libc::SIGSTOP {
            "SIGSTOP; after SIGCONT still braked".into()
        } else {
            "SIGKILL".into()
        },
    })
}

pub fn frozen_motion_core(st: &mut Stack) -> Res<Outcome> {
    motion_core_fault(st, libc::SIGSTOP)
}

pub fn kill_motion_core(st: &mut Stack) -> Res<Outcome> {
    motion_core_fault(st, libc::SIGKILL)
}

pub fn kill_drive_io(st: &mut Stack) -> Res<Outcome> {
    st.start_motion_core()?;
    st.wait_following(true)?;
    let t0 = monotonic_ns();
    st.signal("drive-io", libc::SIGKILL)?;
    st.reap("drive-io");
    // Two independent detections race: drive-io's feedback topic goes silent, and without its
    // SYNC the drives stop sending TPDO2, so the force readings go silent too. Whichever of
    // the two silence limits is shorter trips first (on the host both are 4 cycles and the
    // feedback check runs first; the guest's feedback limit is 20).
    let ev = st.monitor_trip_any(&[Cause::FeedbackSilence, Cause::ForceSilence], 10.0)?;
    let stopped = st.require_braked()?;
    let e = st.emu()?;
    if e.drives.iter().any(|d| d.nmt != 4) {
        return Err("the drives should be NMT-stopped by the monitor".into());
    }
    Ok(Outcome {
        cause: Cause::from_code(ev.detail).map_or("?".into(), |c| c.to_string()),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: "drives NMT-stopped by the monitor's own socket".into(),
    })
}

pub fn kill_monitor(st: &mut Stack) -> Res<Outcome> {
    st.start_motion_core()?;
    st.wait_following(true)?;
    let t0 = monotonic_ns();
    st.signal("safety-monitor", libc::SIGKILL)?;
    st.reap("safety-monitor");
    let (e, stopped) = st.stopped_by_the_drives_watch()?;
    Ok(Outcome {
        cause: "drives: safety heartbeat timeout".into(),
        detect_ms: ms(t0, e.safety_tripped_ns),
        stop_ms: ms(t0, stopped),
        note: "no monitor: drives + drive-io brake by themselves".into(),
    })
}

/// drive-io dies and a faulty adapter takes its place at once: it keeps the drives
/// synchronised (SYNC, so they keep sending forces) and publishes Running feedback whose
/// applied setpoint the monitor never saw. The following-error check cannot be evaluated:
/// after `unchecked_cycles` (10) it trips instead of skipping. The monitor's feedback silence
/// is `configs::replacement_feedback_silence_cycles`: taking over the publisher must fit into it.
pub fn unknown_applied_sequence(st: &mut Stack) -> Res<Outcome> {
    let c = st.fake()?.clone();
    st.wait_following(false)?;
    let fb0 = st.last_feedback.ok_or("no drive-io feedback")?;
    // drive-io's death is preparation: the fault is the replacement's first sample. A host
    // stall that makes the replacement slower than the feedback silence is no verdict.
    st.injected = false;
    // Everything that takes time is prepared before drive-io dies: the node (its creation
    // sweeps dead nodes) and the SYNC thread that keeps the drives sending forces.
    let node =
        IpcNode::with_prefix("shil-faulty-drive-io", &st.prefix).map_err(|e| e.to_string())?;
    // SYNC on every drive interface, as drive-io sent it.
    let mut buses = crate::configs::INTERFACES[..4]
        .iter()
        .map(|i| open_bus(st, i))
        .collect::<Res<Vec<_>>>()?;
    let period = u64::from(st.period_us) * 1000;
    let sync_stop = Arc::new(AtomicBool::new(false));
    let sync = {
        let stop = sync_stop.clone();
        std::thread::spawn(move || {
            let f = can_transport::CanFrame::new_std_lossy(0x080, &[]);
            let mut next = monotonic_ns();
            while !stop.load(Ordering::Relaxed) {
                next += period;
                crs_rt::sleep_until(next);
                for bus in &mut buses {
                    let _ = bus.send(&f);
                }
            }
        })
    };
    // The feedback topic has one publisher: the replacement takes it once drive-io's is gone.
    st.signal("drive-io", libc::SIGKILL)?;
    st.reap("drive-io");
    let t0 = monotonic_ns();
    let fb_pub = loop {
        match node.publisher::<DriveFeedback>() {
            Ok(p) => break p,
            Err(e) if monotonic_ns() - t0 > 5_000_000_000 => {
                sync_stop.store(true, Ordering::Relaxed);
                return Err(format!("replacing drive-io's feedback publisher: {e}"));
            }
            Err(_) => {
                crs_ipc::cleanup_dead_nodes(&crs_ipc::iceoryx_config());
            }
        }
    };
    let t_replaced = monotonic_ns();
    st.poll()?;
    if !st.monitor_estops.is_empty() {
        sync_stop.store(true, Ordering::Relaxed);
        return Err(format!(
            "stalled: replacing drive-io's publisher took {:.0} ms, the monitor tripped first \
             ({:?})",
            (t_replaced - t0) as f64 * 1e-6,
            Cause::from_code(st.monitor_estops[0].detail)
        ));
    }
    st.injected = true;
    let mut next = t_replaced;
    // Past every cycle drive-io may have published after the harness's last sample: the
    // replacement's samples are fresh from the first (a sample whose cycle does not advance is
    // stale, and the monitor's `feedback_stale` would end the scenario before its fault).
    let mut cycle = fb0.cycle + 1_000;
    let mut first_sample_ns = None;
    let r = loop {
        next += period;
        crs_rt::sleep_until(next);
        cycle += 1;
        let mut fb = fb0;
        fb.cycle = cycle;
        fb.timestamp_ns = monotonic_ns();
        fb.bus_state = BusState::Running as u32;
        fb.applied_setpoint_sequence = c.published.load(Ordering::Relaxed) + 1_000_000;
        let _ = fb_pub.publish(&fb);
        let first = *first_sample_ns.get_or_insert(fb.timestamp_ns);
        st.poll()?;
        if let Some(e) = st.monitor_estops.first().copied() {
            // A feedback silence the monitor detected before the replacement's first sample
            // was out (its event reached the harness only now) is the stall above, not the
            // verdict: the fault is that sample.
            if e.trip_cause() == Ok(Cause::FeedbackSilence) && e.timestamp_ns < first {
                st.injected = false;
                sync_stop.store(true, Ordering::Relaxed);
                let _ = sync.join();
                return Err(format!(
                    "stalled: the monitor detected drive-io's silence {:.0} ms after the kill, \
                     before the replacement's first sample ({:.0} ms)",
                    (e.timestamp_ns.saturating_sub(t0)) as f64 * 1e-6,
                    (first - t0) as f64 * 1e-6
                ));
            }
            break st.monitor_trip(Cause::FollowingUnchecked, 1.0);
        }
        if monotonic_ns() - t0 > 10_000_000_000 {
            break Err("no trip within 10 s".into());
        }
    };
    sync_stop.store(true, Ordering::Relaxed);
    let _ = sync.join();
    let ev = r?;
    let stopped = st.require_braked()?;
    Ok(Outcome {
        cause: "following_unchecked".into(),
        detect_ms: trip_ms(t0, ev.timestamp_ns),
        stop_ms: ms(t0, stopped),
        note: format!(
            "drive-io replaced ({:.0} ms gap): Running feedback, applied sequence never published",
            (t_replaced - t0) as f64 * 1e-6
        ),
    })
}
