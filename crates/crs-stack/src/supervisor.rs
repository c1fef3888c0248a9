//! The one process supervisor of the stack: children started in order, each with its own log
//! file and the run's iceoryx2 service prefix; the first child that exits is reported with the
//! tail of its log; all are stopped in reverse start order (SIGTERM, then SIGKILL after a grace
//! period) on [`Supervisor::stop_all`] or on drop, so no daemon outlives a failed run.
//!
//! Used by `crs sim` (and through it the closed calibration loop). Written so the safety HIL
//! (`safety-hil`, its own copy today) can move onto it: per-child extra environment, a
//! configurable grace period, [`Supervisor::stop`] for one child (a scenario that kills the
//! publisher) and [`Supervisor::pid`] to signal one.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

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
        }
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
        println!("  started {name:<15} pid {pid:>6}  log {}", log.display());
        self.procs.push(Proc { name, child, log });
        Ok(pid)
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
}
