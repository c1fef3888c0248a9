#![allow(dead_code)]
//! Shared by the tests that run the whole simulated stack (sim-plant, safety-monitor, drive-io,
//! motion-core as separate processes on the CAN-over-UDP loopback bus).
use std::path::{Path, PathBuf};
use std::process::Command;

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

/// `crs sim` from the repository root on the CAN-over-UDP bus `transport`, with the daemon,
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

/// Copies of the stack's daemon, drives and monitor TOML with the timing relaxed for this test
/// (as tools/stack-hil.sh does for the emulated guest): 4 ms loop and SYNC, drives' stale
/// setpoints 100 cycles, heartbeat timeout 300 ms, safety-heartbeat validation 150 ms, monitor
/// silence 10 / feedback silence 20 cycles. The test runs DEBUG builds of four processes on a
/// shared 2-core host, where the spec's 1 ms / 50 ms watchdogs trip on scheduling stalls (seen:
/// the drives' safety-heartbeat timeout, then sequence gaps). It asserts what calibration does
/// on the running stack, not timing: timing is the benches' job (benches/RESULTS.md). Returns
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
    std::fs::create_dir_all(dir).unwrap();
    let edit = |name: &str, rules: &[(&str, &str)]| -> PathBuf {
        let text = std::fs::read_to_string(root().join("config").join(name)).unwrap();
        let mut seen = vec![0usize; rules.len()];
        let lines: Vec<String> = text
            .lines()
            .map(|l| {
                for (k, (key, value)) in rules.iter().enumerate() {
                    if l.starts_with(&format!("{key} = ")) {
                        seen[k] += 1;
                        return format!("{key} = {value}");
                    }
                }
                // Paths of the copied files resolve against their own directory: point the
                // platform and the waypoints back at config/ (the drives copy stays beside).
                for key in ["platform", "waypoints"] {
                    if let Some(v) = l.strip_prefix(&format!("{key} = \"")) {
                        let v = v.trim_end_matches('"');
                        return format!("{key} = {:?}", root().join("config").join(v));
                    }
                }
                l.to_string()
            })
            .collect();
        assert!(
            seen.iter().all(|n| *n > 0),
            "config/{name}: a relaxed key is missing: {rules:?} {seen:?}"
        );
        let path = dir.join(name);
        std::fs::write(&path, lines.join("\n") + "\n").unwrap();
        path
    };
    [
        edit(daemon, &[("period_us", "4000")]),
        edit(
            drives,
            &[
                ("sync_period_us", "4000"),
                ("stale_setpoint_cycles", "100"),
                ("heartbeat_producer_ms", "20"),
                ("heartbeat_timeout_ms", "300"),
                ("validation_time_ms", "150"),
                ("pair_window_ms", "75"),
            ],
        ),
        // Both silence_cycles keys ([monitor] and [feedback]) become 10; identity grace 40;
        // the monitor's stream period follows motion-core's 4 ms.
        edit(
            monitor,
            &[
                ("silence_cycles", "10"),
                ("identity_grace_cycles", "40"),
                ("setpoint_period_ms", "4.0"),
                // The monitor's SRDO configuration follows the drives' (its CRC must match).
                ("safety_validation_time_ms", "150"),
                ("safety_pair_window_ms", "75"),
            ],
        ),
    ]
}
