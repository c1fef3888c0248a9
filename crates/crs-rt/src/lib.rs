//! Real-time set-up of the stack's loops (SCHED_FIFO, mlockall, CPU affinity, timer slack) and the
//! absolute-deadline periodic timer (clock_nanosleep TIMER_ABSTIME on CLOCK_MONOTONIC).
//! Every setting is applied and reported; one the process is not permitted to use degrades
//! with a clear warning instead of failing silently.
//!
//! One home (issue 14): motion-core's 1 ms loop, the safety monitor's 15 ms cycle, drive-io's
//! SYNC loop and sim-plant's loop all set themselves up here. The monitor may use it and stay
//! independent of the controller: this is operating-system plumbing, not controller code.

use std::fmt;

/// `[realtime]` settings of the daemon TOML.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RealtimeSettings {
    /// Cycle period, ns.
    pub period_ns: u64,
    /// SCHED_FIFO priority 1..=99; 0 keeps SCHED_OTHER.
    pub priority: i32,
    /// CPU to pin the loop thread to; `None` leaves the affinity alone.
    pub cpu: Option<usize>,
    /// mlockall(MCL_CURRENT | MCL_FUTURE) so page faults cannot stall the loop.
    pub lock_memory: bool,
    /// PR_SET_TIMERSLACK in ns (1 = tightest).
    pub timer_slack_ns: u64,
}

/// Outcome of one setting.
#[derive(Clone, Debug, PartialEq)]
pub enum Applied {
    Ok(String),
    Skipped(String),
    Degraded(String),
}

impl fmt::Display for Applied {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Applied::Ok(s) => write!(f, "ok: {s}"),
            Applied::Skipped(s) => write!(f, "off: {s}"),
            Applied::Degraded(s) => write!(f, "WARNING, degraded: {s}"),
        }
    }
}

/// What [`apply`] did, per setting, for the start-up report.
#[derive(Clone, Debug, PartialEq)]
pub struct RealtimeReport {
    pub scheduler: Applied,
    pub memory_lock: Applied,
    pub affinity: Applied,
    pub timer_slack: Applied,
}

impl RealtimeReport {
    pub fn lines(&self) -> [(&'static str, &Applied); 4] {
        [
            ("scheduler", &self.scheduler),
            ("memory lock", &self.memory_lock),
            ("cpu affinity", &self.affinity),
            ("timer slack", &self.timer_slack),
        ]
    }

    pub fn degraded(&self) -> bool {
        self.lines()
            .iter()
            .any(|(_, a)| matches!(a, Applied::Degraded(_)))
    }
}

fn errno_text() -> String {
    std::io::Error::last_os_error().to_string()
}

/// Applies the settings to the calling thread (and the process, for the memory lock).
pub fn apply(s: &RealtimeSettings) -> RealtimeReport {
    let scheduler = if s.priority <= 0 {
        Applied::Skipped("SCHED_OTHER (priority 0 configured)".into())
    } else {
        let param = libc::sched_param {
            sched_priority: s.priority.min(99),
        };
        // SAFETY: plain syscall on the calling thread with a valid parameter struct.
        let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
        if rc == 0 {
            Applied::Ok(format!("SCHED_FIFO priority {}", s.priority.min(99)))
        } else {
            Applied::Degraded(format!(
                "SCHED_FIFO priority {} not permitted ({}); running SCHED_OTHER — grant CAP_SYS_NICE or run as root for real-time timing",
                s.priority,
                errno_text()
            ))
        }
    };
    let memory_lock = if !s.lock_memory {
        Applied::Skipped("memory not locked (lock_memory = false)".into())
    } else {
        // SAFETY: mlockall has no memory-safety preconditions.
        let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
        if rc == 0 {
            Applied::Ok("mlockall(MCL_CURRENT | MCL_FUTURE)".into())
        } else {
            Applied::Degraded(format!(
                "mlockall failed ({}); page faults may stall the loop — raise LimitMEMLOCK",
                errno_text()
            ))
        }
    };
    let affinity = match s.cpu {
        None => Applied::Skipped("no CPU pinning configured".into()),
        Some(cpu) => {
            // SAFETY: cpu_set_t is plain data; CPU_SET writes inside it.
            let rc = unsafe {
                let mut set: libc::cpu_set_t = std::mem::zeroed();
                libc::CPU_SET(cpu, &mut set);
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
            };
            if rc == 0 {
                Applied::Ok(format!("pinned to CPU {cpu}"))
            } else {
                Applied::Degraded(format!("pinning to CPU {cpu} failed ({})", errno_text()))
            }
        }
    };
    // SAFETY: prctl(PR_SET_TIMERSLACK) takes an integer argument.
    let rc = unsafe {
        libc::prctl(
            libc::PR_SET_TIMERSLACK,
            s.timer_slack_ns as libc::c_ulong,
            0,
            0,
            0,
        )
    };
    let timer_slack = if rc == 0 {
        Applied::Ok(format!("{} ns", s.timer_slack_ns))
    } else {
        Applied::Degraded(format!("PR_SET_TIMERSLACK failed ({})", errno_text()))
    };
    RealtimeReport {
        scheduler,
        memory_lock,
        affinity,
        timer_slack,
    }
}

/// Monotonic time in ns (CLOCK_MONOTONIC), the time base of the loop and of the IPC payloads.
#[inline]
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until the absolute CLOCK_MONOTONIC time `deadline_ns` (TIMER_ABSTIME: no drift,
/// EINTR restarts with the same deadline).
#[inline]
pub fn sleep_until(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: valid timespec, null remainder (not used with TIMER_ABSTIME).
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if rc != libc::EINTR {
            return;
        }
    }
}

/// Why a strict real-time set-up failed: every setting that was asked for and not granted.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("real-time set-up not granted: {}", .0.join("; "))]
pub struct RtError(pub Vec<String>);

/// [`apply`], but a setting asked for and not granted is an error (for daemons whose operator
/// asked for real time on the command line and must not silently run without it).
pub fn apply_strict(s: &RealtimeSettings) -> Result<RealtimeReport, RtError> {
    let report = apply(s);
    let failed: Vec<String> = report
        .lines()
        .iter()
        .filter_map(|(what, a)| match a {
            Applied::Degraded(text) => Some(format!("{what}: {text}")),
            _ => None,
        })
        .collect();
    if failed.is_empty() {
        Ok(report)
    } else {
        Err(RtError(failed))
    }
}

/// The set-up of a loop whose operator asked for real time on the command line (drive-io's SYNC
/// loop, sim-plant's loop, the monitor's cycle): SCHED_FIFO at `priority` (1..=99), optionally
/// pinned to `cpu`, all memory locked; the kernel's default 50 µs timer slack. Anything not
/// granted is an error naming the setting (needs root or CAP_SYS_NICE + CAP_IPC_LOCK).
pub fn make_realtime(priority: i32, cpu: Option<usize>) -> Result<RealtimeReport, RtError> {
    apply_strict(&RealtimeSettings {
        period_ns: 0,
        priority: priority.max(1),
        cpu,
        lock_memory: true,
        timer_slack_ns: 50_000,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sleep_until_waits_for_the_absolute_deadline() {
        let t0 = now_ns();
        let deadline = t0 + 2_000_000;
        sleep_until(deadline);
        assert!(now_ns() >= deadline, "woke before the deadline");
        // A deadline in the past returns at once (a late cycle does not sleep again).
        sleep_until(t0);
    }

    #[test]
    fn nothing_asked_for_is_nothing_degraded() {
        let s = RealtimeSettings {
            period_ns: 1_000_000,
            priority: 0,
            cpu: None,
            lock_memory: false,
            timer_slack_ns: 50_000,
        };
        let r = apply_strict(&s).expect("no real-time setting asked for");
        assert!(matches!(r.scheduler, Applied::Skipped(_)));
        assert!(matches!(r.memory_lock, Applied::Skipped(_)));
        assert!(matches!(r.affinity, Applied::Skipped(_)));
    }

    #[test]
    fn a_setting_not_granted_is_an_error_in_strict_mode() {
        // CPU 1023 does not exist on any machine this runs on: pinning must fail, and the
        // strict set-up must say so instead of running unpinned.
        let s = RealtimeSettings {
            period_ns: 1_000_000,
            priority: 0,
            cpu: Some(1023),
            lock_memory: false,
            timer_slack_ns: 50_000,
        };
        let e = apply_strict(&s).unwrap_err();
        assert!(e.to_string().contains("cpu affinity"), "{e}");
    }
}
