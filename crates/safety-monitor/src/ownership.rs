//! One owner per stream: the single-owner streams of the process bus
//! (setpoints, drive feedback, platform identity) must have at most one publisher, and that
//! publisher must run one of the executables the monitor's configuration names (`[ipc]`).
//!
//! iceoryx2 0.10 lists a service's publishers in its dynamic configuration (shared memory);
//! each entry carries the `UniqueNodeId` of the node that created it, which encodes the
//! creating process's id (`UniqueNodeId::pid`). The monitor resolves that pid to the
//! executable through the kernel (`/proc/<pid>/exe`, not settable by the process; the
//! self-chosen `/proc/<pid>/comm` only if `exe` cannot be read). A publisher whose process no
//! longer exists (killed, its port not yet cleaned up) cannot publish and is not counted.
//!
//! What this does NOT give: the node id lives in memory every process of the stack's user can
//! write, so a process of that user that forges its port entry can pose as another pid. It
//! detects a mis-started, stray or foreign process that opens a stream, not a deliberate local
//! attacker of the same user (docs/safety-monitor.md, threat model).

use crs_ipc::PublisherInfo;

/// How a publisher's process is resolved (the kernel in the daemon, a table in tests).
pub trait ProcessLookup {
    /// The executable's file name, or None if the process does not exist (any more).
    fn executable(&mut self, pid: i32) -> Option<String>;
}

/// Resolves through /proc.
#[derive(Debug, Default)]
pub struct ProcFs;

impl ProcessLookup for ProcFs {
    fn executable(&mut self, pid: i32) -> Option<String> {
        if pid <= 0 {
            return None;
        }
        let exe = std::fs::read_link(format!("/proc/{pid}/exe"))
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .map(|n| n.trim_end_matches(" (deleted)").to_string());
        exe.or_else(|| {
            std::fs::read_to_string(format!("/proc/{pid}/comm"))
                .ok()
                .map(|c| c.trim_end().to_string())
        })
    }
}

/// Verdict on one stream's publishers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Ownership {
    /// No live publisher, or one of an allowed executable.
    Ok,
    /// More than one live publisher.
    Several(usize),
    /// A live publisher of another executable (pid, executable).
    Foreign(i32, String),
}

/// Watches one stream. Resolving a pid touches /proc (allocates): done only when the set of
/// publisher pids changed since the last check, so a steady stream costs a shared-memory scan.
#[derive(Debug)]
pub struct OwnerWatch {
    stream: &'static str,
    allowed: Vec<String>,
    last_pids: [Option<i32>; 4],
    last_count: usize,
    verdict: Ownership,
}

impl OwnerWatch {
    /// `allowed` empty: the check is off (bench profile only, enforced by the config loader).
    pub fn new(stream: &'static str, allowed: Vec<String>) -> Self {
        Self {
            stream,
            allowed,
            last_pids: [None; 4],
            last_count: usize::MAX,
            verdict: Ownership::Ok,
        }
    }

    pub fn stream(&self) -> &'static str {
        self.stream
    }

    /// Checks this cycle's publisher list (`count` publishers, the first of them in `pubs`).
    /// Returns the verdict and whether it was re-evaluated (the set changed: log then).
    pub fn check(
        &mut self,
        count: usize,
        pubs: &[PublisherInfo],
        procs: &mut impl ProcessLookup,
    ) -> (&Ownership, bool) {
        if self.allowed.is_empty() {
            return (&self.verdict, false);
        }
        let mut pids = [None; 4];
        for (o, p) in pids.iter_mut().zip(pubs) {
            *o = Some(p.pid.unwrap_or(-1));
        }
        if count == self.last_count && pids == self.last_pids {
            return (&self.verdict, false);
        }
        self.last_count = count;
        self.last_pids = pids;
        let mut live = 0usize;
        let mut foreign = None;
        for p in pubs.iter().take(count) {
            let pid = p.pid.unwrap_or(-1);
            match procs.executable(pid) {
                None if pid > 0 => {}
                None => {
                    live += 1;
                    foreign.get_or_insert((pid, "<unknown process>".to_string()));
                }
                Some(exe) => {
                    live += 1;
                    if !self.allowed.contains(&exe) {
                        foreign.get_or_insert((pid, exe));
                    }
                }
            }
        }
        // Publishers beyond the inspected slots count as live (fail closed).
        live += count.saturating_sub(pubs.len());
        self.verdict = match (live, foreign) {
            (n, _) if n > 1 => Ownership::Several(n),
            (_, Some((pid, exe))) => Ownership::Foreign(pid, exe),
            _ => Ownership::Ok,
        };
        (&self.verdict, true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    struct Table(HashMap<i32, &'static str>);
    impl ProcessLookup for Table {
        fn executable(&mut self, pid: i32) -> Option<String> {
            self.0.get(&pid).map(|s| s.to_string())
        }
    }

    fn info(pid: i32) -> PublisherInfo {
        PublisherInfo { pid: Some(pid) }
    }

    #[test]
    fn one_allowed_owner_passes_others_trip() {
        let mut t = Table(HashMap::from([
            (10, "motion-core"),
            (11, "python3"),
            (12, "motion-core"),
        ]));
        let mut w = OwnerWatch::new("setpoints", vec!["motion-core".into()]);
        assert_eq!(w.check(0, &[], &mut t).0, &Ownership::Ok);
        assert_eq!(w.check(1, &[info(10)], &mut t).0, &Ownership::Ok);
        // Unchanged set: not re-evaluated.
        assert!(!w.check(1, &[info(10)], &mut t).1);
        assert_eq!(
            w.check(1, &[info(11)], &mut t).0,
            &Ownership::Foreign(11, "python3".into())
        );
        assert_eq!(
            w.check(2, &[info(10), info(12)], &mut t).0,
            &Ownership::Several(2)
        );
        // A dead publisher (process gone) does not count.
        assert_eq!(w.check(2, &[info(10), info(99)], &mut t).0, &Ownership::Ok);
        // An unreadable pid counts as a foreign live publisher (fail closed).
        assert!(matches!(
            w.check(1, &[PublisherInfo { pid: None }], &mut t).0,
            Ownership::Foreign(-1, _)
        ));
        // More publishers than inspected slots: several.
        assert!(matches!(
            w.check(6, &[info(10); 4], &mut t).0,
            Ownership::Several(_)
        ));
    }

    #[test]
    fn this_process_resolves_to_its_own_executable() {
        let me = std::process::id() as i32;
        let exe = ProcFs.executable(me).unwrap();
        let expect = std::env::current_exe().unwrap();
        assert_eq!(exe, expect.file_name().unwrap().to_string_lossy());
        assert_eq!(ProcFs.executable(i32::MAX), None);
    }
}
