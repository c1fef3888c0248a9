#![allow(dead_code)]
//! Shared by the tests that run the whole simulated stack (sim-plant, safety-monitor, drive-io,
//! motion-core as separate processes on the CAN-over-UDP loopback bus).
use std::path::{Path, PathBuf};
use std::process::Command;

/// One whole stack at a time within a test binary: each runs five real-time processes, and two
/// at once on the host's two cores starve each other (a motion-core stalled 170 ms and the
/// monitor tripped `setpoint_silence`). Hold the guard for the whole run.
pub fn one_stack() -> std::sync::MutexGuard<'static, ()> {
    static STACK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    STACK.lock().unwrap_or_else(|p| p.into_inner())
}

pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The directory of the stack's binaries (next to this package's `crs`), checked complete:
/// `cargo test --workspace` (tools/test.sh) builds them; `cargo test -p crs` alone may not,
/// and then the test fails saying so.
pub fn stack_bin_dir(crs: &Path) -> PathBuf {
    let bin_dir = crs.parent().unwrap().to_path_buf();
    let missing: Vec<&str> = ["motion-core", "drive-io", "sim-plant", "safety-monitor"]
        .into_iter()
        .filter(|n| !bin_dir.join(n).is_file())
        .collect();
    assert!(
        missing.is_empty(),
        "{missing:?} not built in {}: run `cargo test --workspace` or `cargo build --workspace --bins` first",
        bin_dir.display()
    );
    bin_dir
}

/// `crs sim` from the repository root on the buses `transport` (`wire`: the wire model), with the daemon,
/// drives and monitor configs `cfg` (from [`relaxed_configs`]) and its output in `out`; the
/// caller adds its own arguments and runs it.
pub fn sim_command(crs: &Path, transport: &str, cfg: &[PathBuf; 3], out: &Path) -> Command {
    let mut c = Command::new(crs);
    c.current_dir(root())
        .args(["sim", "--transport", transport])
        .arg("--config")
        .arg(&cfg[0])
        .arg("--drives")
        .arg(&cfg[1])
        .arg("--monitor-config")
        .arg(&cfg[2])
        .arg("--out")
        .arg(out);
    c
}

/// Copies of the stack's daemon, drives and monitor TOML with the `relaxed` timing profile
/// (crs_supervisor::timing: 4 ms loop and SYNC, longer watchdogs). The tests run DEBUG builds of four
/// processes on a shared 2-core host, where the spec's 1 ms / 50 ms watchdogs trip on
/// scheduling stalls (seen: the drives' safety-heartbeat timeout, then sequence gaps). They
/// assert behaviour, not timing: timing is the benches' job (benches/RESULTS.md). Returns
/// [daemon, drives, monitor] (of the default platform, the icosahedron).
pub fn relaxed_configs(dir: &Path) -> [PathBuf; 3] {
    relaxed_configs_of(
        dir,
        "motion-core.toml",
        "drives.toml",
        "safety-monitor.toml",
    )
}

/// [`relaxed_configs`] of another platform's daemon, drives and monitor TOML in config/ (e.g.
/// the helicopter's `motion-core-helicopter.toml`, `safety-monitor-helicopter.toml`).
pub fn relaxed_configs_of(dir: &Path, daemon: &str, drives: &str, monitor: &str) -> [PathBuf; 3] {
    use crs_supervisor::timing::{TimedConfigs, TimingProfile, write_profile};
    let c = root().join("config");
    let files = TimedConfigs {
        daemon: c.join(daemon),
        drives: c.join(drives),
        monitor: c.join(monitor),
    };
    let t = write_profile(TimingProfile::Relaxed, &files, dir).expect("relaxed configs");
    [t.daemon, t.drives, t.monitor]
}
