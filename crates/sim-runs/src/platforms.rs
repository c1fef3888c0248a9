//! The platforms the simulated stack runs (`crs sim --platform`): for each cabin a consistent
//! set of configuration files — the daemon (motion-core), the plant (sim-plant), the safety
//! monitor and the drives — that all name the same platform TOML.
//!
//! | name | platform | daemon | plant | monitor | drives |
//! |---|---|---|---|---|---|
//! | `icosahedron` (default) | `icosahedron.toml` | `motion-core.toml` | `plant/icosahedron.toml` | `safety-monitor.toml` | `drives.toml` |
//! | `helicopter` | `helicopter.toml` | `motion-core-helicopter.toml` | `plant/helicopter.toml` | `safety-monitor-helicopter.toml` | `drives.toml` |
//!
//! (paths relative to the configuration directory, `config/` of the repository). Both cabins
//! hang in the same 8 winches, so they share the drives config. A platform can also be chosen
//! by its platform TOML path: the set whose platform file that is.
//!
//! [`check_monitor_platform`] refuses a run whose safety monitor would read another platform
//! than the daemon (it would trip on the identity check the moment motion-core announces its
//! platform); [`plant_platform_note`] says when the plant simulates another platform than the
//! controller's model (legitimate: a plant with undeclared errors, but worth a line).

use cdpr_model::config::Platform;
use std::path::{Path, PathBuf};

/// One platform's configuration files, relative to the configuration directory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KnownPlatform {
    /// What `--platform` takes.
    pub name: &'static str,
    pub platform: &'static str,
    pub daemon: &'static str,
    pub plant: &'static str,
    pub monitor: &'static str,
    pub drives: &'static str,
}

/// The platforms of the repository's `config/`; the first is the default.
pub const KNOWN: [KnownPlatform; 2] = [
    KnownPlatform {
        name: "icosahedron",
        platform: "icosahedron.toml",
        daemon: "motion-core.toml",
        plant: "plant/icosahedron.toml",
        monitor: "safety-monitor.toml",
        drives: "drives.toml",
    },
    KnownPlatform {
        name: "helicopter",
        platform: "helicopter.toml",
        daemon: "motion-core-helicopter.toml",
        plant: "plant/helicopter.toml",
        monitor: "safety-monitor-helicopter.toml",
        drives: "drives.toml",
    },
];

/// The configuration directory's name in the repository; `crs sim` reads the directory the
/// stack's lookup rule gives ([`crs_service::paths::config_dir`]: $CRS_CONFIG_DIR, ./config, else
/// /etc/crs/config).
pub const CONFIG_DIR: &str = crs_service::paths::CONFIG_PREFIX;

/// A resolved platform: the files of one run of the stack.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StackConfigs {
    pub name: &'static str,
    pub platform: PathBuf,
    pub daemon: PathBuf,
    pub plant: PathBuf,
    pub monitor: PathBuf,
    pub drives: PathBuf,
}

impl KnownPlatform {
    pub fn configs(&self, dir: &Path) -> StackConfigs {
        StackConfigs {
            name: self.name,
            platform: dir.join(self.platform),
            daemon: dir.join(self.daemon),
            plant: dir.join(self.plant),
            monitor: dir.join(self.monitor),
            drives: dir.join(self.drives),
        }
    }
}

fn names() -> String {
    KNOWN.iter().map(|k| k.name).collect::<Vec<_>>().join(", ")
}

/// The known platforms' TOML files under the configuration directory `dir`.
fn platform_files(dir: &Path) -> String {
    KNOWN
        .iter()
        .map(|k| dir.join(k.platform).display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Why `--platform` names no platform set ([`resolve`]); each message lists the known ones.
#[derive(Debug, thiserror::Error)]
pub enum ResolveError {
    /// Neither a known name nor a path.
    #[error(
        "--platform {choice}: unknown platform (known: {}; or the path of one of their platform TOML files)",
        names()
    )]
    Unknown { choice: String },
    /// A path that does not resolve (missing file, unreadable directory).
    #[error("--platform {choice}: {source}")]
    Path {
        choice: String,
        #[source]
        source: std::io::Error,
    },
    /// A platform TOML that is none of the known sets' (`dir`: the configuration directory).
    #[error(
        "--platform {choice}: no stack configuration is set up for this platform TOML (known: {}, \
         with {}); give its daemon, plant and monitor configs with --config, --plant and \
         --monitor-config instead",
        names(),
        platform_files(dir)
    )]
    NotSetUp { choice: String, dir: PathBuf },
}

/// The safety monitor would supervise another platform than the daemon runs
/// ([`check_monitor_platform`]).
#[derive(Debug, thiserror::Error)]
pub enum MonitorPlatformError {
    /// The monitor configuration (or its platform file) does not load.
    #[error(transparent)]
    Load(#[from] safety_monitor::config::ConfigError),
    /// The monitor's platform is not the daemon's (compared by the monitor's identity).
    #[error(
        "{}: [monitor] platform = {} is not the platform motion-core runs ({}: [daemon] \
         platform = {}); the monitor would trip on the platform identity. Use the monitor \
         config of that platform (crs sim --platform {})",
        monitor_config.display(),
        monitor_platform.display(),
        daemon_config.display(),
        daemon_platform.display(),
        names().replace(", ", "|")
    )]
    Mismatch {
        monitor_config: PathBuf,
        monitor_platform: PathBuf,
        daemon_config: PathBuf,
        daemon_platform: PathBuf,
    },
}

/// The plant TOML `plant` does not load ([`plant_platform_note`]).
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", plant.display())]
pub struct PlantLoadError {
    pub plant: PathBuf,
    /// Boxed: the loader's error is large and this one travels inside [`SelectError`].
    #[source]
    pub source: Box<cdpr_model::config::ConfigError>,
}

/// `choice` is a platform name of [`KNOWN`] or the path of one of their platform TOML files
/// (any spelling of the path: compared after resolving it); `dir` is the configuration
/// directory. Anything else is an error that lists what is known.
pub fn resolve(choice: &str, dir: &Path) -> Result<StackConfigs, ResolveError> {
    if let Some(k) = KNOWN.iter().find(|k| k.name == choice) {
        return Ok(k.configs(dir));
    }
    let path = Path::new(choice);
    let looks_like_path = choice.ends_with(".toml") || choice.contains('/');
    if !looks_like_path {
        return Err(ResolveError::Unknown {
            choice: choice.to_string(),
        });
    }
    let wanted = path.canonicalize().map_err(|source| ResolveError::Path {
        choice: choice.to_string(),
        source,
    })?;
    for k in &KNOWN {
        let c = k.configs(dir);
        if c.platform.canonicalize().is_ok_and(|p| p == wanted) {
            return Ok(c);
        }
    }
    Err(ResolveError::NotSetUp {
        choice: choice.to_string(),
        dir: dir.to_path_buf(),
    })
}

/// The safety monitor must supervise the daemon's platform: its own parser's identity of the
/// monitor config's `[monitor] platform` against the identity of the daemon's platform
/// (`daemon_platform`, read from `[daemon] platform` of `daemon_config`).
pub fn check_monitor_platform(
    monitor_config: &Path,
    daemon_config: &Path,
    daemon_platform_file: &Path,
    daemon_platform: &Platform,
) -> Result<(), MonitorPlatformError> {
    let mon = safety_monitor::config::load(monitor_config)?;
    let monitor_id = safety_monitor::identity::platform_identity(&mon.platform);
    if monitor_id != daemon_platform.identity() {
        return Err(MonitorPlatformError::Mismatch {
            monitor_config: monitor_config.to_path_buf(),
            monitor_platform: mon.platform_file,
            daemon_config: daemon_config.to_path_buf(),
            daemon_platform: daemon_platform_file.to_path_buf(),
        });
    }
    Ok(())
}

/// A note when the plant simulates another platform than the controller's (None when the
/// parameters are the same).
pub fn plant_platform_note(
    plant: &Path,
    daemon_platform_file: &Path,
    daemon_platform: &Platform,
) -> Result<Option<String>, PlantLoadError> {
    let cfg = sim_plant::load_plant(plant).map_err(|source| PlantLoadError {
        plant: plant.to_path_buf(),
        source: Box::new(source),
    })?;
    if cfg.platform.model.identity() == daemon_platform.model.identity() {
        return Ok(None);
    }
    Ok(Some(format!(
        "note: the plant {} simulates {} ({}), the controller runs {} ({})",
        plant.display(),
        cfg.platform.name,
        cfg.platform_path.display(),
        daemon_platform.name,
        daemon_platform_file.display()
    )))
}

/// Why the configs of a run could not be chosen.
#[derive(Debug, thiserror::Error)]
pub enum SelectError {
    /// `--platform` names no known platform (the message lists them).
    #[error(transparent)]
    Platform(#[from] ResolveError),
    /// The daemon TOML or a platform TOML.
    #[error(transparent)]
    Config(#[from] cdpr_model::config::ConfigError),
    /// `--platform` and the daemon TOML of `--config` name different platforms.
    #[error(
        "--platform {choice} is {platform}, but --config {config} runs {runs} ({runs_file}): leave one out"
    )]
    Conflict {
        choice: String,
        platform: String,
        config: String,
        runs: String,
        runs_file: String,
    },
    /// The plant TOML.
    #[error(transparent)]
    Plant(#[from] PlantLoadError),
    #[error(transparent)]
    Timing(#[from] crs_supervisor::timing::TimingError),
}

/// Single files that replace those of a platform's set (`crs sim --config/--drives/--plant/
/// --monitor-config`).
#[derive(Clone, Debug, Default)]
pub struct Overrides {
    pub daemon: Option<PathBuf>,
    pub drives: Option<PathBuf>,
    pub plant: Option<PathBuf>,
    pub monitor: Option<PathBuf>,
}

/// The config files a run uses.
#[derive(Clone, Debug, PartialEq)]
pub struct RunFiles {
    pub daemon: PathBuf,
    pub drives: PathBuf,
    pub plant: PathBuf,
    pub monitor: PathBuf,
}

/// The files of a run: the set of `platform` (or of the daemon override, see [`select`]) with
/// single files replaced by `overrides`; the daemon, drives and monitor configs as the timing
/// profile `timing` runs them (non-spec profiles: relaxed copies written under
/// `out/timing-<profile>/`, [`crs_supervisor::timing::write_profile`]).
pub fn run_files(
    platform: Option<&str>,
    overrides: &Overrides,
    timing: &str,
    out: &Path,
) -> Result<RunFiles, SelectError> {
    let set = select(
        platform,
        overrides.daemon.as_deref(),
        &crs_service::paths::config_dir(),
    )?;
    let pick =
        |flag: &Option<PathBuf>, default: &PathBuf| flag.clone().unwrap_or_else(|| default.clone());
    let profile: crs_supervisor::timing::TimingProfile = timing.parse()?;
    let timed = crs_supervisor::timing::write_profile(
        profile,
        &crs_supervisor::timing::TimedConfigs {
            daemon: pick(&overrides.daemon, &set.daemon),
            drives: pick(&overrides.drives, &set.drives),
            monitor: pick(&overrides.monitor, &set.monitor),
        },
        &out.join(format!("timing-{}", profile.name())),
    )?;
    Ok(RunFiles {
        daemon: timed.daemon,
        drives: timed.drives,
        plant: pick(&overrides.plant, &set.plant),
        monitor: timed.monitor,
    })
}

/// [`plant_platform_note`] for the platform the daemon TOML `daemon_config` runs.
pub fn plant_note_for_daemon(
    plant: &Path,
    daemon_config: &Path,
) -> Result<Option<String>, SelectError> {
    let daemon = motion_core::daemon::config::load(daemon_config)?;
    let platform = cdpr_model::config::load_platform(&daemon.platform)?;
    Ok(plant_platform_note(plant, &daemon.platform, &platform)?)
}

/// The set of configs of a run: `platform`'s; without it the set of the platform the daemon
/// TOML `config` runs (if it is a known one), else the default ([`KNOWN`]`[0]`, the
/// icosahedron). A daemon TOML given next to `platform` must run that platform.
pub fn select(
    platform: Option<&str>,
    config: Option<&Path>,
    dir: &Path,
) -> Result<StackConfigs, SelectError> {
    if let Some(p) = platform {
        let set = resolve(p, dir)?;
        if let Some(config) = config {
            let daemon = motion_core::daemon::config::load(config)?;
            let runs = cdpr_model::config::load_platform(&daemon.platform)?;
            let chosen = cdpr_model::config::load_platform(&set.platform)?;
            if runs.model.identity() != chosen.model.identity() {
                return Err(SelectError::Conflict {
                    choice: p.to_string(),
                    platform: set.platform.display().to_string(),
                    config: config.display().to_string(),
                    runs: runs.name,
                    runs_file: daemon.platform.display().to_string(),
                });
            }
        }
        return Ok(set);
    }
    if let Some(config) = config {
        let daemon = motion_core::daemon::config::load(config)?;
        if let Ok(set) = resolve(&daemon.platform.display().to_string(), dir) {
            return Ok(set);
        }
    }
    Ok(KNOWN[0].configs(dir))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config_dir() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config")
    }

    #[test]
    fn names_and_platform_paths_resolve_to_the_same_set() {
        let dir = config_dir();
        for k in &KNOWN {
            let by_name = resolve(k.name, &dir).unwrap();
            let path = dir.join(k.platform);
            let by_path = resolve(path.to_str().unwrap(), &dir).unwrap();
            assert_eq!(by_name, by_path);
            for f in [
                &by_name.platform,
                &by_name.daemon,
                &by_name.plant,
                &by_name.monitor,
                &by_name.drives,
            ] {
                assert!(f.is_file(), "{} missing", f.display());
            }
        }
    }

    #[test]
    fn unknown_platforms_are_refused_listing_the_known_ones() {
        let dir = config_dir();
        let e = resolve("zeppelin", &dir).unwrap_err();
        assert!(matches!(e, ResolveError::Unknown { .. }), "{e}");
        let e = e.to_string();
        assert!(e.contains("icosahedron, helicopter"), "{e}");
        let other = dir.join("crs-nominal.toml");
        let e = resolve(other.to_str().unwrap(), &dir).unwrap_err();
        assert!(matches!(e, ResolveError::NotSetUp { .. }), "{e}");
        let e = e.to_string();
        assert!(e.contains("no stack configuration"), "{e}");
        assert!(e.contains("helicopter.toml"), "{e}");
        let e = resolve("config/nope.toml", &dir).unwrap_err();
        assert!(matches!(e, ResolveError::Path { .. }), "{e}");
        let e = e.to_string();
        assert!(e.contains("nope.toml"), "{e}");
    }

    #[test]
    fn every_set_is_consistent_and_crossing_them_is_refused() {
        let dir = config_dir();
        let sets: Vec<StackConfigs> = KNOWN.iter().map(|k| k.configs(&dir)).collect();
        for s in &sets {
            let daemon = motion_core::daemon::config::load(&s.daemon).unwrap();
            let pf = cdpr_model::config::load_platform(&daemon.platform).unwrap();
            assert_eq!(
                daemon.platform.canonicalize().unwrap(),
                s.platform.canonicalize().unwrap(),
                "{}: the daemon runs another platform",
                s.name
            );
            check_monitor_platform(&s.monitor, &s.daemon, &daemon.platform, &pf).unwrap();
            assert_eq!(
                plant_platform_note(&s.plant, &daemon.platform, &pf).unwrap(),
                None
            );
            for o in sets.iter().filter(|o| o.name != s.name) {
                let e = check_monitor_platform(&o.monitor, &s.daemon, &daemon.platform, &pf)
                    .unwrap_err();
                assert!(matches!(e, MonitorPlatformError::Mismatch { .. }), "{e}");
                let e = e.to_string();
                assert!(e.contains("[monitor] platform"), "{e}");
                let note = plant_platform_note(&o.plant, &daemon.platform, &pf).unwrap();
                assert!(note.is_some_and(|n| n.contains(&pf.name)));
            }
        }
    }

    #[test]
    fn select_takes_the_flag_else_the_daemons_platform_else_the_icosahedron() {
        let dir = config_dir();
        let heli = dir.join("motion-core-helicopter.toml");
        let ico = dir.join("motion-core.toml");
        assert_eq!(select(None, None, &dir).unwrap(), KNOWN[0].configs(&dir));
        assert_eq!(
            select(None, Some(&heli), &dir).unwrap(),
            resolve("helicopter", &dir).unwrap()
        );
        assert_eq!(
            select(Some("helicopter"), Some(&heli), &dir).unwrap(),
            resolve("helicopter", &dir).unwrap()
        );
        // A daemon TOML of another platform next to --platform is refused, naming both.
        let e = select(Some("helicopter"), Some(&ico), &dir).unwrap_err();
        assert!(matches!(e, SelectError::Conflict { .. }), "{e}");
        let text = e.to_string();
        assert!(
            text.contains("--platform helicopter") && text.contains("leave one out"),
            "{text}"
        );
        assert!(matches!(
            select(Some("nonesuch"), None, &dir),
            Err(SelectError::Platform(_))
        ));
    }

    // The shipped platforms' configs under the timing profiles (crs_supervisor::timing).
    fn shipped(k: &KnownPlatform) -> crs_supervisor::timing::TimedConfigs {
        let s = k.configs(&config_dir());
        crs_supervisor::timing::TimedConfigs {
            daemon: s.daemon,
            drives: s.drives,
            monitor: s.monitor,
        }
    }

    /// Both platforms' shipped configs relax under both profiles, and the copies load with the
    /// daemons' own loaders with the relaxed values (a rule that silently matched nothing, or a
    /// broken path, would show here).
    #[test]
    fn every_platform_relaxes_and_the_copies_load() {
        for k in KNOWN {
            for profile in [
                crs_supervisor::timing::TimingProfile::Relaxed,
                crs_supervisor::timing::TimingProfile::Emulated,
            ] {
                let dir = std::env::temp_dir().join(format!(
                    "crs-timing-{}-{}-{}",
                    k.name,
                    profile.name(),
                    std::process::id()
                ));
                let out = crs_supervisor::timing::write_profile(profile, &shipped(&k), &dir)
                    .expect("relaxed copies");
                let d = motion_core::daemon::config::load(&out.daemon).expect("daemon loads");
                assert_eq!(d.realtime.period_ns, 4_000_000, "{}", k.name);
                let drives = drives_config::DrivesConfig::load(&out.drives).expect("drives load");
                assert_eq!(drives.bus.sync_period_us, 4000);
                assert_eq!(drives.bus.stale_setpoint_cycles, 100);
                let mon = safety_monitor::config::load(&out.monitor).expect("monitor loads");
                assert_eq!(mon.monitor.silence_cycles, 10);
                assert_eq!(mon.monitor.identity_grace_cycles, 40);
                assert_eq!(mon.can.reader_stall_cycles, 40);
                if profile == crs_supervisor::timing::TimingProfile::Emulated {
                    assert_eq!(d.realtime.priority, 0);
                    assert_eq!(drives.bus.boot_timeout_ms, 20000);
                }
                setpoint_buffer_outlasts_the_heartbeat_watch(&d, &drives, k.name);
                // The monitor reads the relaxed drives copy beside it.
                let text = std::fs::read_to_string(&out.monitor).unwrap();
                assert!(text.contains("drives = \"drives.toml\""), "{text}");
                let _ = std::fs::remove_dir_all(&dir);
            }
        }
    }

    /// The monitor's setpoint buffer (crs-ipc) spans more of the stream than the drives'
    /// safety-heartbeat watch tolerates of a silent monitor: a monitor its host stalls is
    /// stopped by that watch or catches up without a lost setpoint, never misreported as a
    /// lossy stream (`sequence_gaps`; the CI failure of the 32-sample buffer at the 4 ms loop).
    fn setpoint_buffer_outlasts_the_heartbeat_watch(
        d: &motion_core::daemon::config::DaemonConfig,
        drives: &drives_config::DrivesConfig,
        name: &str,
    ) {
        let watch = drives
            .safety_heartbeat
            .as_ref()
            .expect("the drives watch the monitor's heartbeat");
        let span_ns = <crs_ipc::JointSetpoint as crs_ipc::Topic>::SUBSCRIBER_BUFFER as u64
            * d.realtime.period_ns;
        assert!(
            span_ns > u64::from(watch.validation_time_ms) * 1_000_000,
            "{name}: setpoint buffer {span_ns} ns <= validation time {} ms",
            watch.validation_time_ms
        );
    }

    #[test]
    fn the_spec_setpoint_buffer_outlasts_the_heartbeat_watch() {
        for k in KNOWN {
            let s = shipped(&k);
            let d = motion_core::daemon::config::load(&s.daemon).expect("daemon loads");
            let drives = drives_config::DrivesConfig::load(&s.drives).expect("drives load");
            setpoint_buffer_outlasts_the_heartbeat_watch(&d, &drives, k.name);
        }
    }
}
