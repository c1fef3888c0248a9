//! The one process supervisor of the stack: children started in order, each with its own log
//! file and the run's iceoryx2 service prefix; the first child that exits is reported with the
//! tail of its log; all are stopped in reverse start order (SIGTERM, then SIGKILL after a grace
//! period) on [`Supervisor::stop_all`] or on drop, so no daemon outlives a failed run.
//!
//! Used by `crs sim` (and through it the closed calibration loop) and by the safety HIL
//! (`crates/safety-hil`): per-child extra environment, a configurable grace period,
//! [`Supervisor::stop`] for one child, [`Supervisor::signal`] (freeze, thaw, kill: the fault
//! injections), [`Supervisor::kill`] / [`Supervisor::kill_all`] (no grace: a scenario that kills
//! a process, or ends with every process killed outright), [`Supervisor::stop_with_usage`] (the
//! child's whole-life CPU time from wait4) and [`Supervisor::quiet`] (no "started" lines among a
//! harness's own output).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A signal could not be delivered to a named child.
#[derive(Debug, thiserror::Error)]
pub enum SignalError {
    #[error("{name} is not running under this supervisor")]
    NotRunning { name: String },
    /// It exited (and was reaped): its pid may belong to another process by now.
    #[error("{name} has exited ({status})")]
    Exited { name: String, status: ExitStatus },
    #[error("kill({name}, {signal}): {source}")]
    Kill {
        name: String,
        signal: i32,
        #[source]
        source: std::io::Error,
    },
}

/// How a child stopped by [`Supervisor::stop_with_usage`] ended and what it used over its whole
/// life (wait4's rusage).
#[derive(Debug, Clone, Copy)]
pub struct Usage {
    pub status: ExitStatus,
    pub user: Duration,
    pub system: Duration,
    pub max_rss_kib: i64,
    pub voluntary_switches: i64,
    pub involuntary_switches: i64,
}

/// A child could not be started.
#[derive(Debug, thiserror::Error)]
pub enum SpawnError {
    #[error("{}: {source}", path.display())]
    Log {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("starting {}: {source}", exe.display())]
    Start {
        exe: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

struct Proc {
    name: &'static str,
    child: Child,
    log: PathBuf,
}

/// The children of one run.
pub struct Supervisor {
    procs: Vec<Proc>,
    prefix: String,
    log_dir: PathBuf,
    grace: Duration,
    announce: bool,
}

/// A child that exited on its own.
#[derive(Debug)]
pub struct Exited {
    pub name: &'static str,
    pub status: ExitStatus,
    pub log: PathBuf,
}

impl Supervisor {
    /// Children get `CRS_IPC_PREFIX=prefix` (the run's own iceoryx2 services) and log to
    /// `<log_dir>/<name>.log`; stopping waits `3 s` before SIGKILL.
    pub fn new(prefix: &str, log_dir: &Path) -> Self {
        Self {
            procs: Vec::new(),
            prefix: prefix.to_string(),
            log_dir: log_dir.to_path_buf(),
            grace: Duration::from_secs(3),
            announce: true,
        }
    }

    /// No "started <name> pid … log …" line on stdout per child (a harness whose stdout is
    /// parsed by scripts).
    pub fn quiet(mut self) -> Self {
        self.announce = false;
        self
    }

    /// SIGTERM → SIGKILL grace period of [`Supervisor::stop_all`].
    pub fn with_grace(mut self, grace: Duration) -> Self {
        self.grace = grace;
        self
    }

    /// Starts `exe args` as `name` (stdout and stderr to its log; RUST_LOG passed on, default
    /// `info`), with `env` added.
    pub fn spawn(
        &mut self,
        name: &'static str,
        exe: &Path,
        args: &[String],
        env: &[(&str, &str)],
    ) -> Result<u32, SpawnError> {
        let log = self.log_dir.join(format!("{name}.log"));
        let log_err = |source| SpawnError::Log {
            path: log.clone(),
            source,
        };
        let f = std::fs::File::create(&log).map_err(log_err)?;
        let f2 = f.try_clone().map_err(log_err)?;
        let mut cmd = Command::new(exe);
        cmd.args(args)
            .env("CRS_IPC_PREFIX", &self.prefix)
            .env(
                "RUST_LOG",
                std::env::var("RUST_LOG").unwrap_or_else(|_| "info".into()),
            )
            .stdin(Stdio::null())
            .stdout(f)
            .stderr(f2);
        for (k, v) in env {
            cmd.env(k, v);
        }
        let child = cmd.spawn().map_err(|source| SpawnError::Start {
            exe: exe.to_path_buf(),
            source,
        })?;
        let pid = child.id();
        if let Some(line) = self.started_line(name, pid, &log) {
            println!("{line}");
        }
        self.procs.push(Proc { name, child, log });
        Ok(pid)
    }

    fn started_line(&self, name: &str, pid: u32, log: &Path) -> Option<String> {
        self.announce
            .then(|| format!("  started {name:<15} pid {pid:>6}  log {}", log.display()))
    }

    /// The pid of the running child `name`.
    pub fn pid(&self, name: &str) -> Option<u32> {
        self.procs
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.child.id())
    }

    /// The first child that has exited, with its status.
    pub fn exited(&mut self) -> Option<Exited> {
        for p in &mut self.procs {
            if let Ok(Some(status)) = p.child.try_wait() {
                return Some(Exited {
                    name: p.name,
                    status,
                    log: p.log.clone(),
                });
            }
        }
        None
    }

    /// Stops one child (SIGTERM, SIGKILL after the grace period) and forgets it.
    pub fn stop(&mut self, name: &str) -> Option<ExitStatus> {
        let k = self.procs.iter().position(|p| p.name == name)?;
        let mut p = self.procs.remove(k);
        terminate(&mut p.child);
        wait_or_kill(&mut p.child, Instant::now(), self.grace)
    }

    /// Sends `signal` (SIGSTOP, SIGCONT, SIGKILL, …) to the running child `name`; it stays
    /// supervised (a killed child then shows in [`Supervisor::exited`]). Refused for a child
    /// that has already exited and been reaped: its pid may have been reused.
    pub fn signal(&mut self, name: &str, signal: i32) -> Result<(), SignalError> {
        let p = self
            .procs
            .iter_mut()
            .find(|p| p.name == name)
            .ok_or_else(|| SignalError::NotRunning { name: name.into() })?;
        if let Ok(Some(status)) = p.child.try_wait() {
            return Err(SignalError::Exited {
                name: name.into(),
                status,
            });
        }
        // SAFETY: kill(2) on our own child, not reaped (try_wait above), so the pid is its own.
        if unsafe { libc::kill(p.child.id() as libc::pid_t, signal) } != 0 {
            return Err(SignalError::Kill {
                name: name.into(),
                signal,
                source: std::io::Error::last_os_error(),
            });
        }
        Ok(())
    }

    /// Kills one child at once (SIGKILL, no grace period), reaps and forgets it.
    pub fn kill(&mut self, name: &str) -> Option<ExitStatus> {
        let k = self.procs.iter().position(|p| p.name == name)?;
        let mut p = self.procs.remove(k);
        let _ = p.child.kill();
        p.child.wait().ok()
    }

    /// Kills every child at once (SIGKILL, no grace period), then reaps them all.
    pub fn kill_all(&mut self) {
        for p in &mut self.procs {
            let _ = p.child.kill();
        }
        for p in &mut self.procs {
            let _ = p.child.wait();
        }
        self.procs.clear();
    }

    /// Stops one child like [`Supervisor::stop`] (SIGTERM, SIGKILL after the grace period),
    /// forgets it and returns its whole-life resource usage from wait4(2). None if there is no
    /// such child or it was already reaped (by [`Supervisor::exited`]).
    pub fn stop_with_usage(&mut self, name: &str) -> Option<Usage> {
        let k = self.procs.iter().position(|p| p.name == name)?;
        let p = self.procs.remove(k);
        let pid = p.child.id() as libc::pid_t;
        let mut status = 0;
        // SAFETY: a zeroed rusage is a valid out-parameter.
        let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
        // SAFETY: wait4 on our own child with valid out-pointers. WNOHANG: 0 while it runs;
        // -1 (ECHILD) if std has reaped it already, and then it must not be signalled.
        let mut wait = |flags| unsafe { libc::wait4(pid, &mut status, flags, &mut ru) };
        let mut r = wait(libc::WNOHANG);
        if r == 0 {
            // SAFETY: our child, not reaped (wait4 returned 0).
            unsafe { libc::kill(pid, libc::SIGTERM) };
            let t0 = Instant::now();
            loop {
                r = wait(libc::WNOHANG);
                if r != 0 {
                    break;
                }
                if t0.elapsed() > self.grace {
                    // SAFETY: still our unreaped child.
                    unsafe { libc::kill(pid, libc::SIGKILL) };
                    r = wait(0);
                    break;
                }
                std::thread::sleep(Duration::from_millis(10));
            }
        }
        if r != pid {
            return None;
        }
        let tv = |t: libc::timeval| {
            Duration::from_secs(t.tv_sec.max(0) as u64)
                + Duration::from_micros(t.tv_usec.max(0) as u64)
        };
        Some(Usage {
            status: std::os::unix::process::ExitStatusExt::from_raw(status),
            user: tv(ru.ru_utime),
            system: tv(ru.ru_stime),
            max_rss_kib: ru.ru_maxrss,
            voluntary_switches: ru.ru_nvcsw,
            involuntary_switches: ru.ru_nivcsw,
        })
    }

    /// Stops every child but `last` like [`Supervisor::stop_all`], then `last` (the bus hub:
    /// the others' final frames and goodbyes still travel, its statistics cover everything).
    pub fn stop_all_then(&mut self, last: &str) {
        let keep: Option<Proc> = self
            .procs
            .iter()
            .position(|p| p.name == last)
            .map(|i| self.procs.remove(i));
        self.stop_all();
        if let Some(p) = keep {
            self.procs.push(p);
            self.stop_all();
        }
    }

    /// Stops every child, in reverse start order: SIGTERM to all, then waits for each, SIGKILL
    /// after the grace period.
    pub fn stop_all(&mut self) {
        for p in self.procs.iter_mut().rev() {
            terminate(&mut p.child);
        }
        let t0 = Instant::now();
        for p in self.procs.iter_mut().rev() {
            wait_or_kill(&mut p.child, t0, self.grace);
        }
        self.procs.clear();
    }
}

fn terminate(child: &mut Child) {
    if let Ok(None) = child.try_wait() {
        // SAFETY: kill(2) on our own, not yet reaped child's pid.
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
    }
}

fn wait_or_kill(child: &mut Child, t0: Instant, grace: Duration) -> Option<ExitStatus> {
    loop {
        match child.try_wait() {
            Ok(Some(st)) => return Some(st),
            Err(_) => return None,
            Ok(None) if t0.elapsed() > grace => {
                let _ = child.kill();
                return child.wait().ok();
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(10)),
        }
    }
}

impl Drop for Supervisor {
    fn drop(&mut self) {
        self.stop_all();
    }
}

/// The last `n` lines of a log (empty if unreadable).
pub fn log_tail(path: &Path, n: usize) -> String {
    let s = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = s.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

/// The first `n` lines of a child's log that contain `needle`, from the level on (without the
/// timestamp): the monitor's trip records, drive-io's stop reasons, so a summary with a stop
/// says which check fired and with what value.
pub fn log_lines(log: &Path, needle: &str, n: usize) -> Vec<String> {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    text.lines()
        .filter(|l| l.contains(needle))
        .take(n)
        .map(|l| {
            l.split_once(' ')
                .map_or(l, |(_, rest)| rest)
                .trim()
                .to_string()
        })
        .collect()
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::Relaxed);
}

/// Routes SIGINT/SIGTERM to [`interrupted`] (the supervisor then stops its children cleanly).
pub fn install_interrupt_handler() {
    // SAFETY: an async-signal-safe handler that only stores to an atomic.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
}

/// True once SIGINT or SIGTERM arrived after [`install_interrupt_handler`].
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::Relaxed)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("crs-stack-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn reports_the_child_that_dies_with_its_log_and_stops_the_rest() {
        let d = dir("dies");
        let mut s = Supervisor::new("t", &d).with_grace(Duration::from_millis(500));
        let sh = Path::new("/bin/sh");
        s.spawn("sleeper", sh, &["-c".into(), "exec sleep 30".into()], &[])
            .unwrap();
        s.spawn(
            "failer",
            sh,
            &[
                "-c".into(),
                "echo \"prefix=$CRS_IPC_PREFIX x=$X\"; exit 3".into(),
            ],
            &[("X", "7")],
        )
        .unwrap();
        let t0 = Instant::now();
        let e = loop {
            if let Some(e) = s.exited() {
                break e;
            }
            assert!(t0.elapsed() < Duration::from_secs(10), "no child exited");
            std::thread::sleep(Duration::from_millis(10));
        };
        assert_eq!(e.name, "failer");
        assert_eq!(e.status.code(), Some(3));
        assert_eq!(log_tail(&e.log, 5), "prefix=t x=7");
        let pid = s.pid("sleeper").unwrap();
        s.stop_all();
        // The sleeper is gone (reaped: kill(pid, 0) fails).
        assert_eq!(unsafe { libc::kill(pid as libc::pid_t, 0) }, -1);
    }

    #[test]
    fn stop_one_child_returns_its_status() {
        let d = dir("stop");
        let mut s = Supervisor::new("t", &d);
        s.spawn("a", Path::new("/bin/sleep"), &["30".into()], &[])
            .unwrap();
        let st = s.stop("a").expect("stopped");
        assert!(!st.success());
        assert!(s.stop("a").is_none());
    }

    /// Waits (bounded) until `cond` holds.
    fn until(what: &str, mut cond: impl FnMut() -> bool) {
        let t0 = Instant::now();
        while !cond() {
            assert!(t0.elapsed() < Duration::from_secs(10), "timed out: {what}");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// The state letter of /proc/<pid>/stat (R, S, T, Z, …).
    fn proc_state(pid: u32) -> char {
        let t = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
        t[t.rfind(')').unwrap() + 2..].chars().next().unwrap()
    }

    #[test]
    fn signal_freezes_thaws_and_kills_a_named_child() {
        use std::os::unix::process::ExitStatusExt;
        let d = dir("signal");
        let mut s = Supervisor::new("t", &d).quiet();
        s.spawn("a", Path::new("/bin/sleep"), &["30".into()], &[])
            .unwrap();
        let pid = s.pid("a").unwrap();
        s.signal("a", libc::SIGSTOP).unwrap();
        until("stopped", || proc_state(pid) == 'T');
        s.signal("a", libc::SIGCONT).unwrap();
        until("running again", || proc_state(pid) != 'T');
        assert!(s.exited().is_none());
        s.signal("a", libc::SIGKILL).unwrap();
        let mut e = None;
        until("killed child reported", || {
            e = s.exited();
            e.is_some()
        });
        let e = e.unwrap();
        assert_eq!((e.name, e.status.signal()), ("a", Some(libc::SIGKILL)));
        // Reaped: no signal to a pid that may have been reused.
        assert!(matches!(
            s.signal("a", libc::SIGCONT),
            Err(SignalError::Exited { .. })
        ));
        assert!(matches!(
            s.signal("b", libc::SIGCONT),
            Err(SignalError::NotRunning { .. })
        ));
    }

    /// A shell that ignores SIGTERM (inherited by `sleep` across exec): only SIGKILL ends it.
    fn stubborn(s: &mut Supervisor, name: &'static str) -> u32 {
        s.spawn(
            name,
            Path::new("/bin/sh"),
            &["-c".into(), "trap '' TERM; exec sleep 30".into()],
            &[],
        )
        .unwrap()
    }

    #[test]
    fn kill_does_not_wait_for_the_grace_period() {
        use std::os::unix::process::ExitStatusExt;
        let d = dir("kill");
        let mut s = Supervisor::new("t", &d)
            .quiet()
            .with_grace(Duration::from_secs(60));
        stubborn(&mut s, "a");
        let t0 = Instant::now();
        let st = s.kill("a").expect("killed");
        assert!(t0.elapsed() < Duration::from_secs(10));
        assert_eq!(st.signal(), Some(libc::SIGKILL));
        assert!(s.pid("a").is_none() && s.kill("a").is_none());
    }

    #[test]
    fn kill_all_reaps_every_child_without_grace() {
        let d = dir("killall");
        let mut s = Supervisor::new("t", &d)
            .quiet()
            .with_grace(Duration::from_secs(60));
        let pids = [stubborn(&mut s, "a"), stubborn(&mut s, "b")];
        let t0 = Instant::now();
        s.kill_all();
        assert!(t0.elapsed() < Duration::from_secs(10));
        assert!(s.pid("a").is_none() && s.pid("b").is_none());
        for pid in pids {
            // Reaped: kill(pid, 0) fails.
            assert_eq!(unsafe { libc::kill(pid as libc::pid_t, 0) }, -1);
        }
    }

    #[test]
    fn stop_with_usage_terminates_and_reports_the_childs_cpu_time() {
        use std::os::unix::process::ExitStatusExt;
        let d = dir("usage");
        let mut s = Supervisor::new("t", &d).quiet();
        // Burns CPU in the shell, says so, then sleeps under the same pid until SIGTERM.
        s.spawn(
            "burner",
            Path::new("/bin/sh"),
            &[
                "-c".into(),
                "i=0; while [ $i -lt 100000 ]; do i=$((i+1)); done; echo burnt; exec sleep 30"
                    .into(),
            ],
            &[],
        )
        .unwrap();
        let log = d.join("burner.log");
        until("the burn done", || log_tail(&log, 1) == "burnt");
        let u = s.stop_with_usage("burner").expect("usage");
        // Ended by the SIGTERM (not the grace period's SIGKILL), its own CPU time counted.
        assert_eq!(u.status.signal(), Some(libc::SIGTERM));
        assert!(u.user + u.system > Duration::from_millis(5), "{u:?}");
        assert!(u.max_rss_kib > 0);
        assert!(s.pid("burner").is_none() && s.stop_with_usage("burner").is_none());
    }

    #[test]
    fn stop_with_usage_leaves_a_reaped_child_alone() {
        let d = dir("usage-reaped");
        let mut s = Supervisor::new("t", &d).quiet();
        s.spawn("q", Path::new("/bin/true"), &[], &[]).unwrap();
        until("exited", || s.exited().is_some());
        assert!(s.stop_with_usage("q").is_none());
    }

    #[test]
    fn quiet_supervisor_announces_no_child() {
        let d = dir("quiet");
        let log = d.join("a.log");
        let loud = Supervisor::new("t", &d);
        let line = loud.started_line("a", 42, &log).expect("announced");
        assert!(
            line.contains("started a") && line.contains("pid     42"),
            "{line}"
        );
        assert!(
            Supervisor::new("t", &d)
                .quiet()
                .started_line("a", 42, &log)
                .is_none()
        );
    }
}
