//! The daemon TOML (`config/motion-core.toml`): which platform, which surrogate, the
//! `[realtime]` settings and the trajectory generator's limits. Unknown keys are rejected;
//! errors name the file, key and line.

use super::realtime::RealtimeSettings;
use cdpr_model::config::ConfigError;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use toml::Spanned;

#[derive(Clone, Debug, PartialEq)]
pub struct DaemonConfig {
    /// Platform TOML (resolved relative to the daemon TOML's directory).
    pub platform: PathBuf,
    /// Optional surrogate file; none = zero offset (pure standard kinematics).
    pub surrogate: Option<PathBuf>,
    /// Check wrench feasibility (eq. 3.29) of every reference.
    pub check_wrench_feasibility: bool,
    /// Check (and plan for) the dynamic wrench w = w_e + w_in (eq. 5.13–5.16) when the platform
    /// TOML has `[dynamics]`; false: the static wrench w_e only.
    pub dynamic_wrench: bool,
    /// Log a statistics summary every this many seconds (0 = only at exit).
    pub stats_interval_s: f64,
    /// Optional file the statistics summary is written to (JSON, rewritten each interval).
    pub stats_file: Option<PathBuf>,
    pub realtime: RealtimeSettings,
    /// How long before drive-io's SYNC the loop ticks when the drive bus announces its
    /// schedule (`[realtime] sync_lead_us`, ns; 0 = never align, keep the loop's own grid).
    pub sync_lead_ns: u64,
    pub trajectory: TrajectorySettings,
}

#[derive(Clone, Debug, PartialEq)]
pub struct TrajectorySettings {
    /// Fraction of the table 5.1 velocity limits the planner uses (0, 1].
    pub velocity_scale: f64,
    /// Fraction of the table 5.1 acceleration limits the planner uses (0, 1].
    pub acceleration_scale: f64,
    /// Jerk limits (not in table 5.1): m/s³ and rad/s³.
    pub linear_jerk_max: f64,
    pub angular_jerk_max: f64,
    /// Optional waypoint CSV run at start (see `trajectory::read_waypoints`).
    pub waypoints: Option<PathBuf>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    daemon: RawDaemon,
    realtime: RawRealtime,
    trajectory: RawTrajectory,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDaemon {
    platform: String,
    surrogate: Option<String>,
    #[serde(default = "yes")]
    check_wrench_feasibility: bool,
    #[serde(default = "yes")]
    dynamic_wrench: bool,
    #[serde(default = "one")]
    stats_interval_s: Spanned<f64>,
    stats_file: Option<String>,
}

fn yes() -> bool {
    true
}
fn one() -> Spanned<f64> {
    Spanned::new(0..0, 1.0)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRealtime {
    period_us: Spanned<u64>,
    #[serde(default = "zero")]
    priority: Spanned<i32>,
    /// -1 = no pinning.
    #[serde(default = "no_cpu")]
    cpu: Spanned<i64>,
    #[serde(default)]
    lock_memory: bool,
    #[serde(default = "slack")]
    timer_slack_ns: u64,
    #[serde(default = "lead")]
    sync_lead_us: Spanned<u64>,
}

fn lead() -> Spanned<u64> {
    // The publish stage's phase (200 µs) + drive-io's wake-up + the cycle's RPDOs on the wire
    // (2 drives: 230 µs at 1 Mbit/s) + margin: docs/can-protocol.md "Cycle timing".
    Spanned::new(0..0, 700)
}

fn zero() -> Spanned<i32> {
    Spanned::new(0..0, 0)
}
fn no_cpu() -> Spanned<i64> {
    Spanned::new(0..0, -1)
}
fn slack() -> u64 {
    1
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTrajectory {
    velocity_scale: Spanned<f64>,
    acceleration_scale: Spanned<f64>,
    linear_jerk_max_m_per_s3: Spanned<f64>,
    angular_jerk_max_deg_per_s3: Spanned<f64>,
    waypoints: Option<String>,
}

fn err(
    text: &str,
    file: &str,
    span: std::ops::Range<usize>,
    key: &str,
    msg: String,
) -> ConfigError {
    config_diagnostics::Locator::new(text, file).err(span, key, msg)
}

pub fn load(path: &Path) -> Result<DaemonConfig, ConfigError> {
    let file = path.display().to_string();
    let text = config_diagnostics::read(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    parse(&text, &file, base)
}

pub fn parse(text: &str, file: &str, base: &Path) -> Result<DaemonConfig, ConfigError> {
    let raw: Raw =
        toml::from_str(text).map_err(|e| config_diagnostics::Locator::new(text, file).toml(&e))?;
    let rt = &raw.realtime;
    let period_us = *rt.period_us.get_ref();
    if !(100..=100_000).contains(&period_us) {
        return Err(err(
            text,
            file,
            rt.period_us.span(),
            "realtime.period_us",
            format!("must lie in 100..=100000 µs, got {period_us}"),
        ));
    }
    let priority = *rt.priority.get_ref();
    if !(0..=99).contains(&priority) {
        return Err(err(
            text,
            file,
            rt.priority.span(),
            "realtime.priority",
            format!("must lie in 0..=99 (0 = SCHED_OTHER), got {priority}"),
        ));
    }
    let cpu = *rt.cpu.get_ref();
    if !(-1..=1023).contains(&cpu) {
        return Err(err(
            text,
            file,
            rt.cpu.span(),
            "realtime.cpu",
            format!("must be -1 (no pinning) or a CPU number, got {cpu}"),
        ));
    }
    let lead_us = *rt.sync_lead_us.get_ref();
    if lead_us >= period_us {
        return Err(err(
            text,
            file,
            rt.sync_lead_us.span(),
            "realtime.sync_lead_us",
            format!(
                "must be below realtime.period_us ({period_us} µs; 0 = no alignment), got {lead_us}"
            ),
        ));
    }
    let tr = &raw.trajectory;
    let frac = |v: &Spanned<f64>, key: &str| -> Result<f64, ConfigError> {
        let x = *v.get_ref();
        if !(x > 0.0 && x <= 1.0) {
            return Err(err(
                text,
                file,
                v.span(),
                key,
                format!("must lie in (0, 1], got {x}"),
            ));
        }
        Ok(x)
    };
    let pos = |v: &Spanned<f64>, key: &str| -> Result<f64, ConfigError> {
        let x = *v.get_ref();
        if !(x.is_finite() && x > 0.0) {
            return Err(err(
                text,
                file,
                v.span(),
                key,
                format!("must be a finite number > 0, got {x}"),
            ));
        }
        Ok(x)
    };
    let si = *raw.daemon.stats_interval_s.get_ref();
    if !(si.is_finite() && si >= 0.0) {
        return Err(err(
            text,
            file,
            raw.daemon.stats_interval_s.span(),
            "daemon.stats_interval_s",
            format!("must be >= 0, got {si}"),
        ));
    }
    Ok(DaemonConfig {
        platform: base.join(&raw.daemon.platform),
        surrogate: raw
            .daemon
            .surrogate
            .as_ref()
            .filter(|s| !s.is_empty())
            .map(|s| base.join(s)),
        check_wrench_feasibility: raw.daemon.check_wrench_feasibility,
        dynamic_wrench: raw.daemon.dynamic_wrench,
        stats_interval_s: si,
        stats_file: raw.daemon.stats_file.as_ref().map(|s| base.join(s)),
        realtime: RealtimeSettings {
            period_ns: period_us * 1000,
            priority,
            cpu: (cpu >= 0).then_some(cpu as usize),
            lock_memory: rt.lock_memory,
            timer_slack_ns: rt.timer_slack_ns.max(1),
        },
        sync_lead_ns: lead_us * 1000,
        trajectory: TrajectorySettings {
            velocity_scale: frac(&tr.velocity_scale, "trajectory.velocity_scale")?,
            acceleration_scale: frac(&tr.acceleration_scale, "trajectory.acceleration_scale")?,
            linear_jerk_max: pos(
                &tr.linear_jerk_max_m_per_s3,
                "trajectory.linear_jerk_max_m_per_s3",
            )?,
            angular_jerk_max: pos(
                &tr.angular_jerk_max_deg_per_s3,
                "trajectory.angular_jerk_max_deg_per_s3",
            )?
            .to_radians(),
            waypoints: tr.waypoints.as_ref().map(|s| base.join(s)),
        },
    })
}
