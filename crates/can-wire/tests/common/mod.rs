//! The hub binary as a child process of a test.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub struct HubProc {
    child: Option<Child>,
    pub dir: PathBuf,
}

/// A fresh directory under the target dir for one test's sockets and files.
pub fn test_dir(name: &str) -> PathBuf {
    let d =
        PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

impl HubProc {
    /// Starts `can-wire` with `args` (plus --stats, --ready-file, --rt-priority 0) and waits
    /// until it reports ready (its ready file exists) or exits.
    pub fn start(dir: &Path, args: &[String]) -> Self {
        let log = std::fs::File::create(dir.join("hub.log")).unwrap();
        let child = Command::new(env!("CARGO_BIN_EXE_can-wire"))
            .args(args)
            .arg("--stats")
            .arg(dir.join("wire.json"))
            .arg("--ready-file")
            .arg(dir.join("ready"))
            .args(["--rt-priority", "0"])
            .stdout(Stdio::from(log.try_clone().unwrap()))
            .stderr(Stdio::from(log))
            .spawn()
            .expect("starting can-wire");
        let mut h = Self {
            child: Some(child),
            dir: dir.to_path_buf(),
        };
        let t0 = Instant::now();
        while !dir.join("ready").exists() {
            if let Some(st) = h.child.as_mut().unwrap().try_wait().unwrap() {
                panic!("can-wire exited before ready ({st}): {}", h.log());
            }
            assert!(
                t0.elapsed() < Duration::from_secs(30),
                "can-wire not ready: {}",
                h.log()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        h
    }

    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("hub.log")).unwrap_or_default()
    }

    /// SIGTERM, wait for the exit, return the final statistics.
    pub fn stop(mut self) -> serde_json::Value {
        let mut child = self.child.take().unwrap();
        // SAFETY: signalling our own child by its pid.
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
        let st = child.wait().unwrap();
        assert!(st.success(), "can-wire exit {st}: {}", self.log());
        let text = std::fs::read_to_string(self.dir.join("wire.json")).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["final"], true, "{text}");
        v
    }
}

impl Drop for HubProc {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}
