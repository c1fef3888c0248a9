//! Every drives configuration shipped in config/ carries the safety
//! monitor's heartbeat (`[safety_heartbeat]`), and the bench-only override that lets drive-io
//! start without it appears nowhere in config/ or systemd/.

use drives_config::BENCH_EXECUTABLE;
use drives_config::DrivesConfig;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let p = e.unwrap().path();
        if p.is_dir() {
            files(&p, out);
        } else {
            out.push(p);
        }
    }
}

#[test]
fn every_shipped_drives_config_has_the_safety_heartbeat() {
    let mut all = Vec::new();
    files(&repo().join("config"), &mut all);
    let mut drives = 0;
    for p in all
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
    {
        let text = std::fs::read_to_string(p).unwrap();
        let is_drives = text.lines().any(|l| l.trim() == "[bus]")
            && text.lines().any(|l| l.trim() == "[[winch]]");
        if !is_drives {
            continue;
        }
        drives += 1;
        let cfg = DrivesConfig::load(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert!(
            cfg.safety_heartbeat.is_some(),
            "{}: no [safety_heartbeat]",
            p.display()
        );
        assert_eq!(cfg.require_safety_heartbeat(false).ok(), Some(false));
    }
    assert!(drives >= 1, "no drives config found under config/");
}

#[test]
fn the_bench_override_is_never_shipped() {
    let mut all = Vec::new();
    files(&repo().join("config"), &mut all);
    files(&repo().join("systemd"), &mut all);
    assert!(all.len() > 5);
    for p in &all {
        let Ok(text) = std::fs::read_to_string(p) else {
            continue;
        };
        for bench in [BENCH_EXECUTABLE, "--bench-without-safety-heartbeat"] {
            assert!(
                !text.contains(bench),
                "{}: names the bench-only {bench}",
                p.display()
            );
        }
    }
}

#[test]
fn without_the_heartbeat_drive_io_refuses_unless_overridden() {
    let text = std::fs::read_to_string(repo().join("config/drives.toml")).unwrap();
    let mut cfg = DrivesConfig::parse(&text).unwrap();
    cfg.safety_heartbeat = None;
    let e = cfg.require_safety_heartbeat(false).unwrap_err().to_string();
    assert!(
        e.contains("safety_heartbeat") && e.contains(BENCH_EXECUTABLE),
        "{e}"
    );
    assert_eq!(cfg.require_safety_heartbeat(true).ok(), Some(true));
}

/// The daemon itself: a config without `[safety_heartbeat]` is refused at start, naming the
/// table and the bench executable; the production binary has no switch to allow it (the old
/// `--bench-without-safety-heartbeat` is an unknown argument now).
#[test]
fn the_daemon_refuses_to_start_without_the_heartbeat() {
    let text = std::fs::read_to_string(repo().join("config/drives.toml")).unwrap();
    let start = text.find("[safety_heartbeat]").unwrap();
    let end = start + text[start..].find("[[winch]]").unwrap();
    let stripped = format!("{}{}", &text[..start], &text[end..]);
    let dir = std::env::temp_dir().join(format!("dio-no-hb-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("drives.toml");
    std::fs::write(&path, stripped).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_drive-io"))
        .arg("--config")
        .arg(&path)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("safety_heartbeat") && err.contains(BENCH_EXECUTABLE),
        "{err}"
    );
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_drive-io"))
        .arg("--config")
        .arg(&path)
        .arg("--bench-without-safety-heartbeat")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("unexpected argument"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `drive-io --print-plan | head -0`: the reader has closed the pipe before drive-io writes;
/// drive-io ends quietly with success, it does not panic on the broken pipe.
#[test]
fn print_plan_into_a_closed_pipe_ends_quietly() {
    use std::process::{Command, Stdio};
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = Command::new(env!("CARGO_BIN_EXE_drive-io"))
        .arg("--config")
        .arg(repo().join("config/drives.toml"))
        .arg("--print-plan")
        .stdout(Stdio::from(writer))
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(out.status.success(), "{:?}: {err}", out.status);
}
