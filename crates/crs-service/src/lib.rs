//! # crs-service: a daemon of the stack as systemd, man and the administrator see it
//!
//! * [`notify_ready`]: `READY=1` (with a `STATUS=` line) once the daemon's ports and sockets
//!   are open, so a `Type=notify` unit is "started" when the daemon can do its job, and units
//!   ordered `After=` it wait for that, not for the exec.
//! * [`Watchdog`]: `WATCHDOG=1` from a helper thread, sent only while the daemon's cycle
//!   counter advances, so a frozen cycle stops the pings and systemd kills the process after
//!   `WatchdogSec=`. The cycle itself only bumps an atomic counter (no system call, no lock, no
//!   allocation in the hard loop).
//! * [`gen_man_if_asked`]: `DAEMON --gen-man DIR` writes `DIR/DAEMON.1` from the daemon's clap
//!   command line (clap_mangen), so the installed page never drifts from the flags.
//!
//! * [`paths`]: where every binary finds its configuration (the one lookup rule: installed
//!   `/etc/crs/config`, from the repository `config/`).
//!
//! Outside systemd (no `NOTIFY_SOCKET` / `WATCHDOG_USEC`) every call here is a no-op.

pub mod paths;

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

/// Tells systemd the daemon is ready (`READY=1`) and why (`STATUS=`). A failed send is logged
/// to stderr once and otherwise ignored: the daemon's job does not depend on systemd.
pub fn notify_ready(status: &str) {
    if let Err(e) = sd_notify::notify(
        false,
        &[
            sd_notify::NotifyState::Ready,
            sd_notify::NotifyState::Status(status),
        ],
    ) {
        eprintln!("sd_notify READY=1 failed: {e}");
    }
}

/// The daemon's cycle counter as the watchdog thread sees it: the cycle bumps it, the thread
/// pings systemd only when it moved since the last look.
#[derive(Clone, Debug, Default)]
pub struct CycleCounter(Arc<AtomicU64>);

impl CycleCounter {
    pub fn new() -> Self {
        Self::default()
    }
    /// One more cycle done (Relaxed store: the thread needs progress, not ordering).
    #[inline]
    pub fn tick(&self) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }
    pub fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// The watchdog helper thread (only when the unit has `WatchdogSec=`).
pub struct Watchdog {
    thread: std::thread::JoinHandle<()>,
    stop: Arc<AtomicBool>,
}

impl Watchdog {
    /// Starts the thread when systemd asked for a watchdog (`WATCHDOG_USEC` for this process),
    /// looking at the daemon's cycle count (`cycles()`, e.g. a [`CycleCounter`]'s `get`) four
    /// times per watchdog period. `None` without a watchdog.
    pub fn spawn(cycles: impl Fn() -> u64 + Send + 'static) -> std::io::Result<Option<Watchdog>> {
        let mut usec = 0u64;
        if !sd_notify::watchdog_enabled(false, &mut usec) || usec == 0 {
            return Ok(None);
        }
        let look = Duration::from_micros((usec / 4).max(1000));
        let stop = Arc::new(AtomicBool::new(false));
        let stop_t = stop.clone();
        let thread = std::thread::Builder::new()
            .name("sd-watchdog".into())
            .spawn(move || {
                let mut last = cycles();
                while !stop_t.load(Ordering::Relaxed) {
                    std::thread::sleep(look);
                    let now = cycles();
                    // A frozen cycle sends nothing: systemd's WatchdogSec= then ends us.
                    if now != last {
                        let _ = sd_notify::notify(false, &[sd_notify::NotifyState::Watchdog]);
                    }
                    last = now;
                }
            })?;
        Ok(Some(Watchdog { thread, stop }))
    }

    /// Ends the thread (the daemon is stopping).
    pub fn stop(self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.thread.join();
    }
}

/// Tells systemd the daemon is stopping (`STOPPING=1`).
pub fn notify_stopping() {
    let _ = sd_notify::notify(false, &[sd_notify::NotifyState::Stopping]);
}

/// `NAME --gen-man DIR` (checked before the command line is parsed, so a daemon's required
/// arguments do not get in the way): writes `DIR/NAME.1` (and `DIR/NAME-SUB.1` per subcommand)
/// from `cmd`, prints the files and returns the exit code; `None` when the daemon was started
/// any other way.
pub fn gen_man_if_asked(name: &str, cmd: impl FnOnce() -> clap::Command) -> Option<ExitCode> {
    let mut args = std::env::args_os().skip(1);
    if args.next().as_deref() != Some(std::ffi::OsStr::new("--gen-man")) {
        return None;
    }
    let Some(dir) = args.next().map(PathBuf::from) else {
        eprintln!("{name}: --gen-man needs a directory");
        return Some(ExitCode::from(2));
    };
    Some(match write_man(name, cmd(), &dir) {
        Ok(paths) => {
            for p in paths {
                println!("{}", p.display());
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{name}: --gen-man {}: {e}", dir.display());
            ExitCode::FAILURE
        }
    })
}

/// Writes `dir/NAME.1` for `cmd` and `dir/NAME-SUB.1` for each subcommand, recursively (all in
/// man1 beside `crs`'s pages, where `man NAME` finds them); returns the files.
pub fn write_man(name: &str, cmd: clap::Command, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    fn walk(
        cmd: &clap::Command,
        name: &str,
        dir: &Path,
        out: &mut Vec<PathBuf>,
    ) -> std::io::Result<()> {
        let cmd = cmd.clone().name(name.to_string());
        let path = dir.join(format!("{name}.1"));
        let mut buf = Vec::new();
        clap_mangen::Man::new(cmd.clone()).render(&mut buf)?;
        std::fs::write(&path, buf)?;
        out.push(path);
        for sub in cmd.get_subcommands().filter(|s| s.get_name() != "help") {
            walk(sub, &format!("{name}-{}", sub.get_name()), dir, out)?;
        }
        Ok(())
    }
    std::fs::create_dir_all(dir)?;
    let mut cmd = cmd.name(name.to_string());
    cmd.build();
    let mut out = Vec::new();
    walk(&cmd, name, dir, &mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_page_names_the_daemon_and_its_flags() {
        let cmd = clap::Command::new("x")
            .about("a daemon")
            .arg(clap::Arg::new("config").long("config").help("its config"))
            .subcommand(clap::Command::new("reset").about("ask for a reset"));
        let dir = std::env::temp_dir().join(format!("crs-service-man-{}", std::process::id()));
        let paths = write_man("safety-monitor", cmd, &dir).unwrap();
        let page = std::fs::read_to_string(&paths[0]).unwrap();
        let sub = std::fs::read_to_string(dir.join("safety-monitor-reset.1")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(paths.len(), 2, "{paths:?}");
        assert!(page.contains(".TH safety-monitor 1"), "{page}");
        assert!(page.contains("\\-\\-config"), "{page}");
        assert!(sub.contains("ask for a reset"), "{sub}");
    }

    #[test]
    fn the_counter_counts() {
        let c = CycleCounter::new();
        let seen = c.clone();
        c.tick();
        c.tick();
        assert_eq!(seen.get(), 2);
    }

    #[test]
    fn no_watchdog_outside_systemd() {
        // The test runner is not a unit with WatchdogSec=.
        if std::env::var_os("WATCHDOG_USEC").is_none() {
            let c = CycleCounter::new();
            assert!(Watchdog::spawn(move || c.get()).unwrap().is_none());
        }
    }
}
