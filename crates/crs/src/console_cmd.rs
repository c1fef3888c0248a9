//! `crs console` and `crs sim --console ADDR`: the operator console (`crs-console`) with the
//! platform geometry and the plan of the daemon TOML (`sim_runs::console_setup`).

use stack_reports::sim_observer::ConsoleRequest;
use std::net::SocketAddr;
use std::path::PathBuf;

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
    /// Waypoint CSV the stack runs, shown as progress (default: the --ride file, else the
    /// daemon TOML's).
    #[arg(long)]
    pub waypoints: Option<PathBuf>,
    /// motion-core's control socket (`motion-core --control PATH`, as `crs ride` uses): enables
    /// the START RIDE button, which starts --ride only while the pre-ride checks pass (stack
    /// running, motion-core idle and holding, monitor armed, no latched trip).
    #[arg(long, value_name = "PATH", env = "CRS_CONTROL_SOCKET")]
    pub control: Option<PathBuf>,
    /// The ride of the START RIDE button (waypoint CSV), verified with motion-core's own checks
    /// when the console starts (a refused ride names file, line, axis and bound, exit 1).
    #[arg(long, value_name = "FILE")]
    pub ride: Option<PathBuf>,
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
    /// The ride waits for an operator: motion-core comes up idle and holding with its control
    /// socket (<out>/control.sock) and the ride starts from the console's START RIDE button
    /// once the pre-ride checks pass (or `crs ride start FILE --socket <out>/control.sock`).
    #[arg(long, requires = "console")]
    pub start_from_console: bool,
}

impl SimConsoleArgs {
    /// The console to run next to the stack; None without --console.
    pub(crate) fn request(&self) -> Option<ConsoleRequest> {
        self.console.map(|addr| ConsoleRequest {
            addr,
            token: self.console_token.clone(),
        })
    }
}

/// `crs console`: serves until Ctrl-C.
pub fn run(a: ConsoleArgs) -> Result<(), Box<dyn std::error::Error>> {
    // The console's own log (stop requests, events): journal under systemd, else stdout.
    crs_log::init("crs-console");
    sim_runs::console_setup::serve(sim_runs::console_setup::ServeOptions {
        addr: a.addr,
        token: a.token,
        prefix: a.prefix,
        config: &a.config,
        waypoints: a.waypoints.as_deref(),
        control: a.control,
        ride: a.ride.as_deref(),
    })?;
    Ok(())
}
