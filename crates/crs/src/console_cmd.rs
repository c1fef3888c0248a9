//! `crs console` and `crs sim --console ADDR`: the operator console (`crs-console`) with the
//! platform geometry and the plan of the daemon TOML.

use cdpr_model::config::{Platform, load_platform};
use crs_console::{ConsoleConfig, PlanView, PlatformView};
use motion_core::daemon::config::DaemonConfig;
use motion_core::daemon::trajectory;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct ConsoleArgs {
    /// Address to serve on. Anything but a loopback address needs --token.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,
    /// Access token (≥ 16 characters), checked on every request: `Authorization: Bearer T` or
    /// `?token=T` in the page's address. Also from the environment variable CRS_CONSOLE_TOKEN.
    #[arg(long, env = "CRS_CONSOLE_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// iceoryx2 service prefix of the stack (default: CRS_IPC_PREFIX, empty for the systemd stack).
    #[arg(long)]
    pub prefix: Option<String>,
    /// motion-core daemon TOML: the platform drawn and the plan shown as progress.
    #[arg(long, default_value = "config/motion-core.toml")]
    pub config: PathBuf,
    /// Waypoint CSV the stack runs (default: the daemon TOML's).
    #[arg(long)]
    pub waypoints: Option<PathBuf>,
}

/// `crs sim`'s console options (flattened into `SimArgs`).
#[derive(clap::Args, Debug, Default)]
pub struct SimConsoleArgs {
    /// Serve the operator console on this address while the run lasts (e.g. 127.0.0.1:8080).
    #[arg(long, value_name = "ADDR")]
    pub console: Option<SocketAddr>,
    /// Token for a console on a non-loopback address (also CRS_CONSOLE_TOKEN).
    #[arg(long, env = "CRS_CONSOLE_TOKEN", hide_env_values = true)]
    pub console_token: Option<String>,
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
) -> Result<PlanView, Box<dyn std::error::Error>> {
    let wps = trajectory::read_waypoints(waypoints)?;
    let period_s = daemon.realtime.period_ns as f64 * 1e-9;
    let lim = motion_core::daemon::lifecycle::planner_limits(&platform.limits, &daemon.trajectory);
    let mut steps = vec![0usize; wps.len()];
    trajectory::plan_samples(platform.home, &wps, lim, period_s, |seg, _| {
        steps[seg] += 1;
        Ok::<(), motion_core::daemon::trajectory::PlanningFailed>(())
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

fn console_config(
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

/// `crs sim --console`: starts the console on the run's prefix; None without --console.
pub(crate) fn start_for_sim(
    a: &SimConsoleArgs,
    prefix: &str,
    daemon: &DaemonConfig,
    platform: &Platform,
    waypoints: Option<&Path>,
) -> Result<Option<crs_console::ConsoleHandle>, Box<dyn std::error::Error>> {
    let Some(addr) = a.console else {
        return Ok(None);
    };
    let cfg = console_config(
        addr,
        a.console_token.clone(),
        prefix,
        daemon,
        platform,
        waypoints,
    );
    let h = crs_console::spawn(cfg)?;
    println!("  operator console: http://{}/", h.addr);
    Ok(Some(h))
}

/// `crs console`: serves until Ctrl-C.
pub fn run(a: ConsoleArgs) -> Result<(), Box<dyn std::error::Error>> {
    // The console's own log (stop requests, events): journal under systemd, else stdout.
    crs_log::init("crs-console");
    let daemon = motion_core::daemon::config::load(&a.config).map_err(|e| e.to_string())?;
    let platform = load_platform(&daemon.platform)?;
    let prefix = a
        .prefix
        .clone()
        .unwrap_or_else(|| std::env::var(crs_ipc::PREFIX_ENV).unwrap_or_default());
    let wps = a.waypoints.clone().or(daemon.trajectory.waypoints.clone());
    let cfg = console_config(a.addr, a.token, &prefix, &daemon, &platform, wps.as_deref());
    crs_console::run_blocking(cfg)?;
    Ok(())
}
