//! Timing profiles of a run (`crs sim --timing spec|relaxed|emulated`): ONE place that knows
//! which watchdogs and periods a slow machine needs relaxed, instead of a sed list in the HIL
//! script and copies in the tests.
//!
//! * `spec` — the configs as shipped: the spec's 1 ms loop and SYNC (sec. 5.6), the drives'
//!   10-cycle stale-setpoint stop, 50 ms safety-heartbeat validation, the monitor's silence
//!   counts. What a real machine runs.
//! * `relaxed` — for DEBUG builds of four processes on a shared 2-core host (the crs tests):
//!   4 ms loop and SYNC, the drives' stale setpoints 100 cycles, heartbeat producer 20 ms /
//!   timeout 300 ms, safety-heartbeat validation 150 ms (pair window 75 ms), the monitor's
//!   silence counts 10 and its identity grace 40 cycles, 40 cycles before its bus reader counts
//!   as stalled (seen: a 150 ms reader stall at load average 14 tripped `bus_observation`), its
//!   stream period following the 4 ms loop. The 1 ms / 50 ms watchdogs trip there on scheduling stalls, not on faults; tests that
//!   run it assert behaviour, timing is the benches' job (benches/RESULTS.md).
//! * `emulated` — the QEMU guest (software emulation, tools/stack-hil.sh): `relaxed` plus no
//!   SCHED_FIFO / CPU pinning / mlockall, the demo at 0.1 of the table 5.1 speed and
//!   acceleration, longer boot (20 s) and SDO (500 ms) timeouts, feedback and force silence 20
//!   cycles. In the emulator a
//!   1 ms loop stalls for up to a second; when drive-io stalls ~100 ms the drives chase a
//!   target that ran ahead, and at full speed that catch-up (not the trajectory) leaves
//!   [f_min, f_max].
//!
//! Only the timing keys change; the platform, plant, limits and the 100 mm check stay each
//! platform's as `crs sim --platform` picks them. The relaxed copies are written beside each
//! other (the monitor's `drives = "drives.toml"` then names the relaxed drives copy); every
//! other file a copy names (platform, waypoints, surrogate, …) is pointed back at the original
//! by its absolute path. Edits are line based, so comments survive, and every key must be found
//! exactly where expected: a renamed key is an error naming file, section and key, never a
//! silently unrelaxed run.

use std::path::{Path, PathBuf};
use std::str::FromStr;

/// How much slack the run's watchdogs and periods get.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TimingProfile {
    /// The shipped configs, unchanged.
    #[default]
    Spec,
    /// A loaded host running debug builds (the crs tests).
    Relaxed,
    /// Software emulation (the QEMU vcan guest).
    Emulated,
}

impl TimingProfile {
    pub const NAMES: [&'static str; 3] = ["spec", "relaxed", "emulated"];

    pub fn name(self) -> &'static str {
        match self {
            TimingProfile::Spec => "spec",
            TimingProfile::Relaxed => "relaxed",
            TimingProfile::Emulated => "emulated",
        }
    }

    /// (section, key, value) edits of the daemon, drives and monitor TOML.
    fn rules(self) -> [Vec<Rule>; 3] {
        type R = Rule;
        let mut daemon = vec![R::one("realtime", "period_us", "4000")];
        let mut drives = vec![
            R::one("bus", "sync_period_us", "4000"),
            R::one("bus", "stale_setpoint_cycles", "100"),
            R::one("bus", "heartbeat_producer_ms", "20"),
            R::one("bus", "heartbeat_timeout_ms", "300"),
            R::one("safety_heartbeat", "validation_time_ms", "150"),
            R::one("safety_heartbeat", "pair_window_ms", "75"),
        ];
        let mut monitor = vec![
            R::one("monitor", "silence_cycles", "10"),
            R::one("monitor", "identity_grace_cycles", "40"),
            R::one("motion", "setpoint_period_ms", "4.0"),
            R::one("can", "reader_stall_cycles", "40"),
            // The monitor's SRDO configuration follows the drives' relaxed watch: its CRC (the
            // configuration signature the drives compare) must match theirs.
            R::one("can", "safety_validation_time_ms", "150"),
            R::one("can", "safety_pair_window_ms", "75"),
        ];
        match self {
            TimingProfile::Spec => return [Vec::new(), Vec::new(), Vec::new()],
            TimingProfile::Relaxed => {
                monitor.push(R::one("feedback", "silence_cycles", "10"));
                // The load cells report every 5th SYNC (20 ms at the relaxed 4 ms SYNC): the
                // same 300 ms drive-io allows them (bus.heartbeat_timeout_ms above).
                monitor.push(R::one("forces", "silence_cycles", "20"));
            }
            TimingProfile::Emulated => {
                daemon.extend([
                    R::one("realtime", "priority", "0"),
                    R::one("realtime", "cpu", "-1"),
                    R::one("realtime", "lock_memory", "false"),
                    R::one("trajectory", "velocity_scale", "0.1"),
                    R::one("trajectory", "acceleration_scale", "0.1"),
                ]);
                drives.extend([
                    R::one("bus", "boot_timeout_ms", "20000"),
                    R::one("bus", "sdo_timeout_ms", "500"),
                    // The emulator's stalls bunch motion-core's setpoints: their steps judged
                    // at the bound, not the shipped 50 m/s² (the speed check stays).
                    R::one("bus", "max_cable_acceleration_m_per_s2", "200.0"),
                ]);
                monitor.extend([
                    R::one("feedback", "silence_cycles", "20"),
                    R::one("forces", "silence_cycles", "20"),
                    // The safety I/O node's 10 ms inputs through an emulated guest's stalls.
                    R::one("can", "safety_io_silence_cycles", "10"),
                ]);
            }
        }
        [daemon, drives, monitor]
    }
}

impl FromStr for TimingProfile {
    type Err = TimingError;
    fn from_str(s: &str) -> Result<Self, TimingError> {
        match s {
            "spec" => Ok(TimingProfile::Spec),
            "relaxed" => Ok(TimingProfile::Relaxed),
            "emulated" => Ok(TimingProfile::Emulated),
            other => Err(TimingError::UnknownProfile(other.to_string())),
        }
    }
}

/// Why relaxed copies could not be written.
#[derive(Debug, thiserror::Error)]
pub enum TimingError {
    #[error("unknown timing profile `{0}` (expected spec, relaxed or emulated)")]
    UnknownProfile(String),
    #[error("{path}: {err}")]
    Io {
        path: PathBuf,
        #[source]
        err: std::io::Error,
    },
    #[error("{path}: [{section}] {key} not found (config keys changed?)")]
    MissingKey {
        path: PathBuf,
        section: &'static str,
        key: &'static str,
    },
    #[error("{path}: the daemon, drives and monitor configs need distinct file names")]
    NameClash { path: PathBuf },
}

/// One key's new value in one section.
#[derive(Clone, Copy, Debug)]
struct Rule {
    section: &'static str,
    key: &'static str,
    value: &'static str,
}

impl Rule {
    const fn one(section: &'static str, key: &'static str, value: &'static str) -> Self {
        Rule {
            section,
            key,
            value,
        }
    }
}

/// The daemon, drives and monitor files of a run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TimedConfigs {
    pub daemon: PathBuf,
    pub drives: PathBuf,
    pub monitor: PathBuf,
}

/// Writes copies of `files` with `profile`'s timing into `dir` (kept under their own file
/// names) and returns their paths; `Spec` returns `files` unchanged and writes nothing.
pub fn write_profile(
    profile: TimingProfile,
    files: &TimedConfigs,
    dir: &Path,
) -> Result<TimedConfigs, TimingError> {
    if profile == TimingProfile::Spec {
        return Ok(files.clone());
    }
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |err| TimingError::Io { path, err }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let originals = [&files.daemon, &files.drives, &files.monitor];
    let names: Vec<_> = originals.iter().map(|p| p.file_name()).collect();
    if names[0] == names[1] || names[1] == names[2] || names[0] == names[2] {
        return Err(TimingError::NameClash {
            path: files.monitor.clone(),
        });
    }
    let sibling_names: Vec<String> = names
        .iter()
        .filter_map(|n| n.map(|n| n.to_string_lossy().into_owned()))
        .collect();
    let mut out: [PathBuf; 3] = Default::default();
    for ((orig, rules), slot) in originals.iter().zip(profile.rules()).zip(&mut out) {
        let text = std::fs::read_to_string(orig).map_err(io(orig))?;
        let base = orig.parent().unwrap_or(Path::new("."));
        let edited = edit(&text, &rules, base, &sibling_names).map_err(|(section, key)| {
            TimingError::MissingKey {
                path: orig.to_path_buf(),
                section,
                key,
            }
        })?;
        let path = dir.join(orig.file_name().unwrap_or_default());
        std::fs::write(&path, edited).map_err(io(&path))?;
        *slot = path;
    }
    let [daemon, drives, monitor] = out;
    Ok(TimedConfigs {
        daemon,
        drives,
        monitor,
    })
}

/// Applies `rules` (each must match at least once in its section) and points string values
/// that name an existing file relative to `base` at its absolute path, unless it is one of the
/// copies written beside this one (`siblings`).
fn edit(
    text: &str,
    rules: &[Rule],
    base: &Path,
    siblings: &[String],
) -> Result<String, (&'static str, &'static str)> {
    let mut section = String::new();
    let mut seen = vec![false; rules.len()];
    let mut out = String::with_capacity(text.len() + 64);
    for line in text.lines() {
        let trimmed = line.trim_start();
        if trimmed.starts_with('[') {
            section = trimmed
                .trim_start_matches('[')
                .split(']')
                .next()
                .unwrap_or("")
                .trim()
                .to_string();
        }
        let key = trimmed.split('=').next().unwrap_or("").trim();
        let has_value = !trimmed.starts_with('#') && trimmed.contains('=');
        let mut replaced = None;
        if has_value {
            for (k, r) in rules.iter().enumerate() {
                if r.section == section && r.key == key {
                    seen[k] = true;
                    replaced = Some(format!("{key} = {}", r.value));
                }
            }
            if replaced.is_none() {
                replaced = repoint(key, trimmed, base, siblings);
            }
        }
        out.push_str(replaced.as_deref().unwrap_or(line));
        out.push('\n');
    }
    match rules.iter().zip(&seen).find(|(_, s)| !**s) {
        Some((r, _)) => Err((r.section, r.key)),
        None => Ok(out),
    }
}

/// `key = "relative/file"` → `key = "/abs/relative/file"` when the file exists (a copy lives
/// in another directory, so its relative names would resolve elsewhere).
fn repoint(key: &str, line: &str, base: &Path, siblings: &[String]) -> Option<String> {
    let value = line.split_once('=')?.1.trim();
    let value = value.split(" #").next()?.trim();
    let inner = value.strip_prefix('"')?.strip_suffix('"')?;
    if inner.is_empty() || Path::new(inner).is_absolute() || siblings.iter().any(|s| s == inner) {
        return None;
    }
    let target = base.join(inner);
    if !target.is_file() {
        return None;
    }
    let abs = std::path::absolute(&target).ok()?;
    Some(format!("{key} = {:?}", abs.display().to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config_dir() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config")
    }

    #[test]
    fn spec_is_the_shipped_files_and_a_missing_key_is_named() {
        let dir = config_dir();
        let files = TimedConfigs {
            daemon: dir.join("motion-core.toml"),
            drives: dir.join("drives.toml"),
            monitor: dir.join("safety-monitor.toml"),
        };
        assert_eq!(
            write_profile(TimingProfile::Spec, &files, Path::new("/nonexistent")).unwrap(),
            files
        );
        let err = edit(
            "[realtime]\nperiod_ms = 1\n",
            &TimingProfile::Relaxed.rules()[0],
            Path::new("."),
            &[],
        )
        .unwrap_err();
        assert_eq!(err, ("realtime", "period_us"));
        // A key of the same name in another section is not the one meant.
        let err = edit(
            "[other]\nperiod_us = 1\n",
            &TimingProfile::Relaxed.rules()[0],
            Path::new("."),
            &[],
        )
        .unwrap_err();
        assert_eq!(err, ("realtime", "period_us"));
        assert!("fast".parse::<TimingProfile>().is_err());
    }
}
