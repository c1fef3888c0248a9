//! The operator console (`crs-console`) of a stack: what its page draws — the platform geometry
//! and the plan of the daemon TOML — and its configuration, for `crs console` and
//! `crs sim --console`.

use cdpr_model::config::{ConfigError, Platform};
use crs_console::{ConsoleConfig, LoadedRide, PlanView, PlatformView, RideSetup};
use motion_core::daemon::config::DaemonConfig;
use motion_core::daemon::trajectory::{self, PlanningFailed, WaypointError};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

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
    /// The controller cannot be configured for the daemon's platform (verifying a ride).
    #[error(transparent)]
    Configure(#[from] motion_core::daemon::lifecycle::ConfigureError),
    /// The ride for the start button, refused by the loop's own checks (file, line, axis, bound).
    #[error("--ride refused: {0}")]
    Ride(#[from] motion_core::daemon::lifecycle::RideRefused),
    #[error("--ride needs --control (motion-core's control socket)")]
    RideWithoutControl,
}

/// The start button's ride: `file` read and verified with motion-core's own ride checks
/// (region, limits, wrench feasibility along the planned path) for `daemon` on `platform`.
pub fn load_ride(
    daemon: &DaemonConfig,
    platform: &Platform,
    file: &Path,
) -> Result<LoadedRide, ConsoleSetupError> {
    use motion_core::daemon::lifecycle::{self, RideRefused};
    let name = file.display().to_string();
    let text = std::fs::read_to_string(file).map_err(|e| {
        RideRefused::File(WaypointError::Read {
            file: name.clone(),
            reason: e.to_string(),
        })
    })?;
    let ride = trajectory::parse_ride(&text, &name).map_err(RideRefused::File)?;
    let plan = lifecycle::configure(daemon, platform)?.verify_ride(&ride)?;
    Ok(LoadedRide::verified(
        name,
        text,
        ride.waypoints.len(),
        plan.duration_s,
    ))
}

/// The start button of a console: motion-core's control socket and, when given, the ride
/// (verified now: a refused ride ends the console's set-up with the refusal).
pub fn ride_setup(
    daemon: &DaemonConfig,
    platform: &Platform,
    control: Option<PathBuf>,
    ride: Option<&Path>,
) -> Result<Option<RideSetup>, ConsoleSetupError> {
    match (control, ride) {
        (None, None) => Ok(None),
        (None, Some(_)) => Err(ConsoleSetupError::RideWithoutControl),
        (Some(socket), ride) => Ok(Some(RideSetup {
            socket,
            ride: ride.map(|f| load_ride(daemon, platform, f)).transpose()?,
        })),
    }
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
        rides: None,
    }
}

/// `crs console`'s options.
pub struct ServeOptions<'a> {
    pub addr: SocketAddr,
    pub token: Option<String>,
    /// iceoryx2 prefix (default: `CRS_IPC_PREFIX`, empty for the systemd stack).
    pub prefix: Option<String>,
    /// The daemon TOML.
    pub config: &'a Path,
    /// The plan shown as progress (default: the daemon TOML's).
    pub waypoints: Option<&'a Path>,
    /// motion-core's control socket for the start button.
    pub control: Option<PathBuf>,
    /// The ride the start button starts.
    pub ride: Option<&'a Path>,
}

/// `crs console`: the console of the stack of the daemon TOML `config` (its platform, and the
/// plan of `waypoints`, of the ride, or the daemon's own), on `prefix`, with the start button
/// when a control socket is given, served until Ctrl-C.
pub fn serve(o: ServeOptions<'_>) -> Result<(), ConsoleSetupError> {
    let daemon = motion_core::daemon::config::load(o.config)?;
    let platform = cdpr_model::config::load_platform(&daemon.platform)?;
    let rides = ride_setup(&daemon, &platform, o.control, o.ride)?;
    let prefix = o
        .prefix
        .unwrap_or_else(|| std::env::var(crs_ipc::PREFIX_ENV).unwrap_or_default());
    let wps = o
        .waypoints
        .or(o.ride)
        .map(Path::to_path_buf)
        .or(daemon.trajectory.waypoints.clone());
    let mut cfg = console_config(o.addr, o.token, &prefix, &daemon, &platform, wps.as_deref());
    cfg.rides = rides;
    if let Some(r) = cfg.rides.as_ref().and_then(|r| r.ride.as_ref()) {
        println!("  start button: ride {}", r.describe());
    }
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

    #[test]
    fn the_start_buttons_ride_is_verified_with_the_loops_checks() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
        let daemon = motion_core::daemon::config::load(&dir.join("motion-core.toml")).unwrap();
        let pf = cdpr_model::config::load_platform(&daemon.platform).unwrap();
        let demo = dir.join("demo-waypoints.csv");
        let ride = load_ride(&daemon, &pf, &demo).unwrap();
        assert!(
            ride.describe().contains("waypoints, plan"),
            "{}",
            ride.describe()
        );
        // A waypoint outside the region: refused naming the file, the line and the bound.
        let bad = std::env::temp_dir().join(format!("crs-console-ride-{}.csv", std::process::id()));
        std::fs::write(
            &bad,
            "t_s,x_m,y_m,z_m,phi_x_deg,phi_y_deg,phi_z_deg\n2,0,0,2,0,0,0\n4,0,4.0,2,0,0,0\n",
        )
        .unwrap();
        let e = load_ride(&daemon, &pf, &bad).unwrap_err().to_string();
        std::fs::remove_file(&bad).unwrap();
        assert!(e.contains(":3:") && e.contains("y_m"), "{e}");
        assert!(matches!(
            ride_setup(&daemon, &pf, None, Some(&demo)),
            Err(ConsoleSetupError::RideWithoutControl)
        ));
        let setup = ride_setup(&daemon, &pf, Some("/tmp/x.sock".into()), None)
            .unwrap()
            .unwrap();
        assert!(setup.ride.is_none());
    }
}
