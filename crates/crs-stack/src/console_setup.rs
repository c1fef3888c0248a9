//! The operator console (`crs-console`) of a stack: what its page draws — the platform geometry
//! and the plan of the daemon TOML — and its configuration, for `crs console` and
//! `crs sim --console`.

use cdpr_model::config::{ConfigError, Platform};
use crs_console::{ConsoleConfig, PlanView, PlatformView};
use motion_core::daemon::config::DaemonConfig;
use motion_core::daemon::trajectory::{self, PlanningFailed, WaypointError};
use std::net::SocketAddr;
use std::path::Path;

/// Why the plan of a waypoint file could not be shown.
#[derive(Debug, thiserror::Error)]
pub enum PlanViewError {
    #[error(transparent)]
    Waypoints(#[from] WaypointError),
    #[error(transparent)]
    Planning(#[from] PlanningFailed),
}

/// Why a console could not be set up or run.
#[derive(Debug, thiserror::Error)]
pub enum ConsoleSetupError {
    /// The daemon TOML or its platform.
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Console(#[from] crs_console::ConsoleError),
}

/// What the page draws: frame anchors a_i, platform anchors b_i and the force limits.
pub fn platform_view(p: &Platform) -> PlatformView {
    let par = p.model.params();
    PlatformView {
        name: p.name.clone(),
        frame_anchors_m: par.a.iter().map(|a| [a.x, a.y, a.z]).collect(),
        platform_anchors_m: par.b.iter().map(|b| [b.x, b.y, b.z]).collect(),
        f_min_n: par.f_min,
        f_max_n: par.f_max,
    }
}

/// The plan motion-core runs from home through `waypoints`, as time at each waypoint
/// (the same planner and limits as the daemon: `trajectory::plan_samples`).
pub fn plan_view(
    daemon: &DaemonConfig,
    platform: &Platform,
    waypoints: &Path,
) -> Result<PlanView, PlanViewError> {
    let wps = trajectory::read_waypoints(waypoints)?;
    let period_s = daemon.realtime.period_ns as f64 * 1e-9;
    let lim = motion_core::daemon::lifecycle::planner_limits(&platform.limits, &daemon.trajectory);
    let mut steps = vec![0usize; wps.len()];
    trajectory::plan_samples(platform.home, &wps, lim, period_s, |seg, _| {
        steps[seg] += 1;
        Ok::<(), PlanningFailed>(())
    })?;
    let mut t = 0.0;
    let waypoint_end_s = steps
        .iter()
        .map(|n| {
            t += *n as f64 * period_s;
            t
        })
        .collect();
    Ok(PlanView {
        period_s,
        total_s: t,
        waypoint_end_s,
    })
}

/// The console of the stack on `prefix` running `daemon` on `platform`; the plan of `waypoints`
/// shows as progress. A plan that cannot be computed is left out with a line saying why (the
/// console still serves the live state).
pub fn console_config(
    addr: SocketAddr,
    token: Option<String>,
    prefix: &str,
    daemon: &DaemonConfig,
    platform: &Platform,
    waypoints: Option<&Path>,
) -> ConsoleConfig {
    let plan = waypoints.and_then(|w| match plan_view(daemon, platform, w) {
        Ok(p) => Some(p),
        Err(e) => {
            println!("  console: no trajectory progress ({}: {e})", w.display());
            None
        }
    });
    ConsoleConfig {
        addr,
        token,
        prefix: prefix.to_string(),
        platform: Some(platform_view(platform)),
        plan,
        avoid_cpu: daemon.realtime.cpu,
    }
}

/// `crs console`: the console of the stack of the daemon TOML `config` (its platform, and the
/// plan of `waypoints` or the daemon's own), on `prefix` (default: `CRS_IPC_PREFIX`, empty for
/// the systemd stack), served until Ctrl-C.
pub fn serve(
    addr: SocketAddr,
    token: Option<String>,
    prefix: Option<String>,
    config: &Path,
    waypoints: Option<&Path>,
) -> Result<(), ConsoleSetupError> {
    let daemon = motion_core::daemon::config::load(config)?;
    let platform = cdpr_model::config::load_platform(&daemon.platform)?;
    let prefix = prefix.unwrap_or_else(|| std::env::var(crs_ipc::PREFIX_ENV).unwrap_or_default());
    let wps = waypoints
        .map(Path::to_path_buf)
        .or(daemon.trajectory.waypoints.clone());
    let cfg = console_config(addr, token, &prefix, &daemon, &platform, wps.as_deref());
    crs_console::run_blocking(cfg)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plan_view_ends_each_waypoint_later_and_the_last_at_the_total() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
        let daemon = motion_core::daemon::config::load(&dir.join("motion-core.toml")).unwrap();
        let pf = cdpr_model::config::load_platform(&daemon.platform).unwrap();
        let v = plan_view(&daemon, &pf, &dir.join("demo-waypoints.csv")).unwrap();
        assert!(!v.waypoint_end_s.is_empty());
        assert!(v.waypoint_end_s.windows(2).all(|w| w[1] > w[0]));
        assert_eq!(*v.waypoint_end_s.last().unwrap(), v.total_s);
        assert!(matches!(
            plan_view(&daemon, &pf, &dir.join("nonesuch.csv")),
            Err(PlanViewError::Waypoints(_))
        ));
        let view = platform_view(&pf);
        assert_eq!(view.frame_anchors_m.len(), pf.model.m());
    }
}
