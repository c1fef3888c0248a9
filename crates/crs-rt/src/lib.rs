//! Real-time set-up of the stack's loops (SCHED_FIFO, mlockall, CPU affinity, timer slack) and the
//! absolute-deadline periodic timer (clock_nanosleep TIMER_ABSTIME on CLOCK_MONOTONIC).
//! Every setting is applied and reported; one the process is not permitted to use degrades
//! with a clear warning instead of failing silently.
//!
//! One home (each loop had its own copy before): motion-core's 1 ms loop, the safety monitor's 15 ms cycle and its bus
//! reader, drive-io's SYNC loop and its latency bench, sim-plant's loop and the operator
//! console's background threads all set themselves up here; no other crate calls
//! sched_setscheduler, mlockall, sched_setaffinity, PR_SET_TIMERSLACK or clock_nanosleep.
//! The monitor may use it and stay independent of the controller: this is operating-system
//! plumbing, not controller code. Dependencies: libc and thiserror only, so that stays true.
//!
//! The single settings ([`set_fifo_priority`], [`lock_memory`], [`pin_to_cpu`],
//! [`set_affinity`], [`keep_off_cpu`], [`set_thread_nice`], [`set_timer_slack`]) return the
//! kernel's error; the preambles combine them: [`apply`] (reports, degrades), [`apply_strict`]
//! and [`make_realtime`] (refuse what was not granted).

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

/// SCHED_FIFO at `priority` for the calling thread: a FIFO thread runs until it blocks, so the
/// loop's wake-up is not delayed by SCHED_OTHER work on its CPU. Needs CAP_SYS_NICE (or root,
/// or an RLIMIT_RTPRIO at least `priority`); the kernel's refusal is returned as is.
pub fn set_fifo_priority(priority: i32) -> std::io::Result<()> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: plain syscall on the calling thread with a valid parameter struct.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// mlockall(MCL_CURRENT | MCL_FUTURE) for the whole process: no page of it, present or later
/// mapped, is paged out, so a loop never stalls on a page fault (a major fault costs
/// milliseconds, the loop's whole period). Needs CAP_IPC_LOCK or a large enough
/// RLIMIT_MEMLOCK (the systemd units set LimitMEMLOCK=infinity).
pub fn lock_memory() -> std::io::Result<()> {
    // SAFETY: mlockall has no memory-safety preconditions.
    let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Sets the calling thread's affinity to exactly `cpus`. Pinning keeps a loop on the CPU set
/// aside for it (no migrations, warm caches) and keeps helper threads off it. A CPU number
/// beyond the kernel's `cpu_set_t` (CPU_SETSIZE) is refused as invalid input rather than
/// written out of bounds (the numbers come from configuration files and flags).
pub fn set_affinity(cpus: impl IntoIterator<Item = usize>) -> std::io::Result<()> {
    // SAFETY: cpu_set_t is plain data; all-zero is the empty set.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    for cpu in cpus {
        if cpu >= libc::CPU_SETSIZE as usize {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("CPU {cpu} is beyond CPU_SETSIZE ({})", libc::CPU_SETSIZE),
            ));
        }
        // SAFETY: cpu < CPU_SETSIZE (checked above), so the bit lies inside the set.
        unsafe { libc::CPU_SET(cpu, &mut set) };
    }
    // SAFETY: affinity of the calling thread, with a valid cpu_set_t of the size passed.
    let rc = unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Pins the calling thread to `cpu` alone (see [`set_affinity`]).
pub fn pin_to_cpu(cpu: usize) -> std::io::Result<()> {
    set_affinity([cpu])
}

/// Sets the calling thread to every online CPU except `cpu`, for threads that must stay off a
/// loop's CPU (the operator console's web threads: a burst of requests must not compete with
/// the 1 ms loop). With one CPU online, or `cpu` not among them, the affinity is left alone:
/// there is nowhere else to go, and an empty set would be refused.
pub fn keep_off_cpu(cpu: usize) -> std::io::Result<()> {
    // SAFETY: sysconf has no preconditions.
    let online = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) }.max(1) as usize;
    if online <= 1 || cpu >= online {
        return Ok(());
    }
    set_affinity((0..online.min(libc::CPU_SETSIZE as usize)).filter(|c| *c != cpu))
}

/// Nice value of the calling thread (setpriority on its thread id: on Linux the nice value is
/// per thread). Background threads take a positive one so that, on a shared CPU, SCHED_OTHER
/// work of the stack gets ahead of them.
pub fn set_thread_nice(nice: i32) -> std::io::Result<()> {
    // SAFETY: gettid and setpriority on the calling thread have no memory-safety preconditions.
    let rc = unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, nice)
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// PR_SET_TIMERSLACK for the calling thread, ns. The kernel may defer a timer wake-up by up to
/// the slack (default 50 µs) to batch wake-ups; a 1 ms loop wants its deadline met as closely
/// as the scheduler allows, so loops set it to 1 ns. (0 would mean "back to the default".)
pub fn set_timer_slack(slack_ns: u64) -> std::io::Result<()> {
    // SAFETY: prctl(PR_SET_TIMERSLACK) takes an integer argument and affects only this thread.
    let rc = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, slack_ns as libc::c_ulong, 0, 0, 0) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Applies the settings to the calling thread (and the process, for the memory lock): every
/// setting is attempted even when another was refused, so the report says what the loop
/// really runs with.
pub fn apply(s: &RealtimeSettings) -> RealtimeReport {
    let scheduler = if s.priority <= 0 {
        Applied::Skipped("SCHED_OTHER (priority 0 configured)".into())
    } else {
        match set_fifo_priority(s.priority.min(99)) {
            Ok(()) => Applied::Ok(format!("SCHED_FIFO priority {}", s.priority.min(99))),
            Err(e) => Applied::Degraded(format!(
                "SCHED_FIFO priority {} not permitted ({e}); running SCHED_OTHER — grant CAP_SYS_NICE or run as root for real-time timing",
                s.priority
            )),
        }
    };
    let memory_lock = if !s.lock_memory {
        Applied::Skipped("memory not locked (lock_memory = false)".into())
    } else {
        match lock_memory() {
            Ok(()) => Applied::Ok("mlockall(MCL_CURRENT | MCL_FUTURE)".into()),
            Err(e) => Applied::Degraded(format!(
                "mlockall failed ({e}); page faults may stall the loop — raise LimitMEMLOCK"
            )),
        }
    };
    let affinity = match s.cpu {
        None => Applied::Skipped("no CPU pinning configured".into()),
        Some(cpu) => match pin_to_cpu(cpu) {
            Ok(()) => Applied::Ok(format!("pinned to CPU {cpu}")),
            Err(e) => Applied::Degraded(format!("pinning to CPU {cpu} failed ({e})")),
        },
    };
    let timer_slack = match set_timer_slack(s.timer_slack_ns) {
        Ok(()) => Applied::Ok(format!("{} ns", s.timer_slack_ns)),
        Err(e) => Applied::Degraded(format!("PR_SET_TIMERSLACK failed ({e})")),
    };
    RealtimeReport {
        scheduler,
        memory_lock,
        affinity,
        timer_slack,
    }
}

/// Monotonic time in ns (CLOCK_MONOTONIC): the time base of every loop, of every `*_ns`
/// payload field of the process bus and of the CAN receive stamps. The stack's one clock:
/// crs-ipc and can-transport re-export it (both depend on this crate), so all processes on one
/// host stamp with the same function.
#[inline]
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec we own; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    (ts.tv_sec as u64)
        .saturating_mul(1_000_000_000)
        .saturating_add(ts.tv_nsec as u64)
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
/// loop, sim-plant's loop) or in its configuration (the monitor's `[monitor] rt_priority`):
/// SCHED_FIFO at `priority` (1..=99), optionally pinned to `cpu`, all memory locked; the
/// kernel's default 50 µs timer slack (drive-io tightens its own afterwards). Anything not
/// granted is an error naming the setting (needs root or CAP_SYS_NICE + CAP_IPC_LOCK); every
/// setting is attempted regardless, so a caller that goes on after the error (the monitor, the
/// bus bench) runs with what was granted. The caller decides: the daemons started with
/// `--rt-priority` stop, the monitor warns and keeps supervising.
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
        let t0 = monotonic_ns();
        let deadline = t0 + 2_000_000;
        sleep_until(deadline);
        assert!(monotonic_ns() >= deadline, "woke before the deadline");
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

    /// The calling thread's affinity, as the set of allowed CPU numbers.
    fn allowed_cpus() -> Vec<usize> {
        // SAFETY: reads the calling thread's affinity into a set we own.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            let rc = libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set);
            assert_eq!(
                rc,
                0,
                "sched_getaffinity: {}",
                std::io::Error::last_os_error()
            );
            (0..libc::CPU_SETSIZE as usize)
                .filter(|c| libc::CPU_ISSET(*c, &set))
                .collect()
        }
    }

    #[test]
    fn pinning_leaves_the_thread_on_that_cpu_alone() {
        // In a thread of its own: the affinity must not leak into other tests.
        std::thread::spawn(|| {
            let cpu = *allowed_cpus().last().expect("some CPU is allowed");
            pin_to_cpu(cpu).expect("pinning to an allowed CPU");
            assert_eq!(allowed_cpus(), vec![cpu]);
        })
        .join()
        .unwrap();
    }

    #[test]
    fn a_cpu_beyond_the_cpu_set_is_refused_not_a_panic() {
        let e = pin_to_cpu(1 << 20).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput, "{e}");
        let r = apply(&RealtimeSettings {
            period_ns: 1_000_000,
            priority: 0,
            cpu: Some(1 << 20),
            lock_memory: false,
            timer_slack_ns: 50_000,
        });
        assert!(matches!(r.affinity, Applied::Degraded(_)), "{}", r.affinity);
    }

    #[test]
    fn the_timer_slack_is_set_on_the_calling_thread() {
        std::thread::spawn(|| {
            set_timer_slack(1).expect("PR_SET_TIMERSLACK");
            // SAFETY: PR_GET_TIMERSLACK takes no pointer argument.
            let slack = unsafe { libc::prctl(libc::PR_GET_TIMERSLACK, 0, 0, 0, 0) };
            assert_eq!(slack, 1);
        })
        .join()
        .unwrap();
    }

    #[test]
    fn a_background_thread_keeps_off_the_cpu_at_its_nice_value() {
        // SAFETY: sysconf has no preconditions.
        let online = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) } as usize;
        std::thread::spawn(move || {
            let before = allowed_cpus();
            keep_off_cpu(0).expect("keeping off CPU 0");
            // 19, the weakest: raising the nice value is always permitted (the tests may
            // already run at nice 19, and lowering it needs CAP_SYS_NICE).
            set_thread_nice(19).expect("raising the nice value");
            if online > 1 {
                assert!(!allowed_cpus().contains(&0), "still allowed on CPU 0");
            } else {
                assert_eq!(allowed_cpus(), before, "one CPU: affinity left alone");
            }
            // SAFETY: getpriority on the calling thread's id.
            let nice = unsafe {
                let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
                libc::getpriority(libc::PRIO_PROCESS, tid)
            };
            assert_eq!(nice, 19);
        })
        .join()
        .unwrap();
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
