//! `crs sim` supervises the stack as a user relies on: a child that dies stops all the others
//! and the launcher exits with an error naming it; Ctrl-C (SIGINT) stops every process. Runs
//! the real binaries on the CAN-over-UDP loopback bus, with the relaxed timing of the other
//! stack tests (debug builds on a shared host; see tests/common).
mod common;
use common::{relaxed_configs, sim_command, stack_bin_dir};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// A running `crs sim` and the pids of the children it announced.
struct Sim {
    child: Child,
    lines: mpsc::Receiver<String>,
    log: Vec<String>,
    out: PathBuf,
}

impl Sim {
    fn start(tag: &str) -> Self {
        let crs = PathBuf::from(env!("CARGO_BIN_EXE_crs"));
        stack_bin_dir(&crs);
        let out = std::env::temp_dir().join(format!("crs-sim-sup-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let cfg = relaxed_configs(&out.join("cfg"));
        let mut child = sim_command(&crs, "wire", &cfg, &out.join("run"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn crs sim");
        let (tx, lines) = mpsc::channel();
        for stream in [
            Box::new(child.stdout.take().unwrap()) as Box<dyn std::io::Read + Send>,
            Box::new(child.stderr.take().unwrap()),
        ] {
            let tx = tx.clone();
            std::thread::spawn(move || {
                for l in BufReader::new(stream).lines().map_while(Result::ok) {
                    let _ = tx.send(l);
                }
            });
        }
        Self {
            child,
            lines,
            log: Vec::new(),
            out,
        }
    }

    /// Waits (bounded) for a line containing `what`; returns it.
    fn wait_line(&mut self, what: &str, secs: u64) -> String {
        let deadline = Instant::now() + Duration::from_secs(secs);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(l) => {
                    self.log.push(l.clone());
                    if l.contains(what) {
                        return l;
                    }
                }
                Err(_) => panic!("no `{what}` within {secs} s:\n{}", self.log.join("\n")),
            }
        }
    }

    /// Pids of the children from the "started NAME pid N" lines, waiting for all four.
    fn children(&mut self) -> Vec<(String, u32)> {
        let mut v = Vec::new();
        for name in ["sim-plant", "safety-monitor", "drive-io", "motion-core"] {
            let l = self.wait_line(&format!("started {name}"), 60);
            let pid = l
                .split_whitespace()
                .skip_while(|w| *w != "pid")
                .nth(1)
                .and_then(|p| p.parse().ok())
                .unwrap_or_else(|| panic!("no pid in `{l}`"));
            v.push((name.to_string(), pid));
        }
        v
    }

    /// Waits (bounded) for `crs sim` to exit; returns its status and the rest of its output.
    fn finish(&mut self, secs: u64) -> (std::process::ExitStatus, String) {
        let deadline = Instant::now() + Duration::from_secs(secs);
        let status = loop {
            if let Some(st) = self.child.try_wait().unwrap() {
                break st;
            }
            if Instant::now() > deadline {
                let _ = self.child.kill();
                panic!(
                    "crs sim did not exit within {secs} s:\n{}",
                    self.log.join("\n")
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        // The reader threads end at EOF once crs sim and its children closed the pipes.
        while let Ok(l) = self.lines.recv_timeout(Duration::from_secs(5)) {
            self.log.push(l);
        }
        (status, self.log.join("\n"))
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = std::fs::remove_dir_all(&self.out);
    }
}

/// True while `pid` exists and is not a zombie.
fn alive(pid: u32) -> bool {
    match std::fs::read_to_string(Path::new("/proc").join(pid.to_string()).join("stat")) {
        Ok(stat) => !stat
            .rsplit_once(')')
            .is_some_and(|(_, rest)| rest.trim_start().starts_with('Z')),
        Err(_) => false,
    }
}

#[test]
fn a_crashed_child_stops_the_whole_stack() {
    let _one = common::one_stack();
    let mut sim = Sim::start("kill");
    let kids = sim.children();
    // All four run (motion-core was started after the drives were operational): killing
    // drive-io now is a crash in the middle of a run.
    let drive_io = kids.iter().find(|(n, _)| n == "drive-io").unwrap().1;
    assert!(alive(drive_io));
    // SAFETY: sending SIGKILL to a pid this test just read from crs sim's own output.
    assert_eq!(unsafe { libc::kill(drive_io as i32, libc::SIGKILL) }, 0);
    let (status, text) = sim.finish(60);
    assert!(
        !status.success(),
        "crs sim must fail when a child dies:\n{text}"
    );
    assert!(text.contains("drive-io exited"), "{text}");
    for (name, pid) in &kids {
        assert!(
            !alive(*pid),
            "{name} (pid {pid}) still runs after crs sim exited"
        );
    }
}

#[test]
fn ctrl_c_stops_every_process() {
    let _one = common::one_stack();
    let mut sim = Sim::start("int");
    let kids = sim.children();
    for (name, pid) in &kids {
        assert!(alive(*pid), "{name} not running");
    }
    // SAFETY: SIGINT to the crs sim child this test spawned.
    assert_eq!(
        unsafe { libc::kill(sim.child.id() as i32, libc::SIGINT) },
        0
    );
    let (status, text) = sim.finish(60);
    assert!(!status.success(), "{text}");
    assert!(text.contains("interrupted"), "{text}");
    for (name, pid) in &kids {
        assert!(!alive(*pid), "{name} (pid {pid}) still runs after Ctrl-C");
    }
}

#[test]
fn a_monitor_timed_for_another_loop_period_is_refused_before_anything_starts() {
    let crs = PathBuf::from(env!("CARGO_BIN_EXE_crs"));
    stack_bin_dir(&crs);
    let out = std::env::temp_dir().join(format!("crs-sim-period-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let cfg = relaxed_configs(&out.join("cfg"));
    // motion-core runs at 4 ms (relaxed); the monitor is told 1 ms.
    let text = std::fs::read_to_string(&cfg[2]).unwrap();
    assert!(text.contains("setpoint_period_ms = 4.0"));
    std::fs::write(
        &cfg[2],
        text.replace("setpoint_period_ms = 4.0", "setpoint_period_ms = 1.0"),
    )
    .unwrap();
    let o = sim_command(&crs, "wire", &cfg, &out.join("run"))
        .output()
        .expect("run crs sim");
    let (so, se) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(!o.status.success());
    assert!(
        se.contains("setpoint_period_ms = 1") && se.contains("every 4 ms"),
        "{se}"
    );
    assert!(!so.contains("started"), "nothing may start: {so}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn an_operator_stop_is_summarised_as_stopped_in_words_and_exits_non_zero() {
    let _one = common::one_stack();
    let mut sim = Sim::start("stop");
    let line = sim.wait_line("iceoryx2 prefix", 60);
    let prefix = line
        .split("iceoryx2 prefix ")
        .nth(1)
        .and_then(|r| r.split(',').next())
        .unwrap_or_else(|| panic!("no prefix in `{line}`"))
        .to_string();
    sim.children();
    // The console's STOP: an e-stop event from the operator on the run's process bus.
    let node = crs_ipc::IpcNode::with_prefix("test-operator", &prefix).unwrap();
    let events = node.publisher::<crs_ipc::StateEvent>().unwrap();
    for k in 1..=3 {
        let ev =
            crs_ipc::StateEvent::new(crs_ipc::ProcessId::Operator, crs_ipc::EventKind::EStop, k);
        events.publish(&ev).unwrap();
        std::thread::sleep(Duration::from_millis(100));
    }
    let (status, text) = sim.finish(120);
    assert!(!status.success(), "a stopped run exited 0:\n{text}");
    assert!(
        text.contains("E-STOP by operator: stop requested by an operator"),
        "{text}"
    );
    assert!(
        text.contains(
            "STOPPED: the trajectory did not complete (operator: stop requested by an operator)"
        ),
        "{text}"
    );
    assert!(!text.contains("at rest after the trajectory"), "{text}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sim.out.join("run/summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["completed"], serde_json::Value::Bool(false));
    assert_eq!(
        summary["stopped_by"],
        "operator: stop requested by an operator"
    );
}
