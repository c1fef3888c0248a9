//! `crs console` and `crs sim --console ADDR`: the operator console (`crs-console`) with the
//! platform geometry and the plan of the daemon TOML (`crs_stack::console_setup`).

use crs_stack::sim_observer::ConsoleRequest;
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
    crs_stack::console_setup::serve(a.addr, a.token, a.prefix, &a.config, a.waypoints.as_deref())?;
    Ok(())
}
