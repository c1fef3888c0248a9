//! `crs sim`: the whole simulated stack as separate processes, as a user runs it — the
//! command line of [`crs_stack::sim_run`] (which starts, follows and stops the processes and
//! writes the summary) plus the `--check` verdict.

use crs_stack::sim_run::{SimOptions, execute};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct SimArgs {
    /// motion-core daemon TOML (platform, surrogate, realtime, trajectory).
    #[arg(long, default_value = "config/motion-core.toml")]
    pub(crate) config: PathBuf,
    /// Drive bus TOML.
    #[arg(long, default_value = "config/drives.toml")]
    pub(crate) drives: PathBuf,
    /// Plant TOML (must be the platform of the daemon TOML).
    #[arg(long, default_value = "config/plant/icosahedron.toml")]
    pub(crate) plant: PathBuf,
    /// `auto` (vcan0 if present, else the UDP loopback bus), or a transport such as
    /// `socketcan:vcan0` / `udpbus:239.255.70.9:20900`.
    #[arg(long, default_value = "auto")]
    pub(crate) transport: String,
    /// Waypoint CSV for the demo trajectory (default: the daemon TOML's).
    #[arg(long)]
    pub(crate) waypoints: Option<PathBuf>,
    /// Seconds to hold after the trajectory before stopping (static error is taken here).
    #[arg(long, default_value_t = 1.0)]
    pub(crate) hold_s: f64,
    /// Give up after this many seconds.
    #[arg(long, default_value_t = 120.0)]
    pub(crate) timeout_s: f64,
    /// Directory with the stack's binaries (default: next to this `crs`).
    #[arg(long)]
    pub(crate) bin_dir: Option<PathBuf>,
    /// Directory for the children's logs and the JSON summary.
    #[arg(long, default_value = "out/sim")]
    pub(crate) out: PathBuf,
    /// Run without the safety monitor even if it is built.
    #[arg(long)]
    pub(crate) no_monitor: bool,
    /// Fail (exit 1) unless the run meets the expectations: trajectory completed, no e-stop,
    /// every plant step converged, forces within [f_min, f_max], static error below
    /// --max-static-error-mm. For tests and CI.
    #[arg(long)]
    pub(crate) check: bool,
    /// Static (at rest) position error bound for --check, mm.
    #[arg(long, default_value_t = 20.0)]
    pub(crate) max_static_error_mm: f64,
    /// Safety-monitor TOML (its [monitor] platform must be the daemon's platform).
    #[arg(long, default_value = "config/safety-monitor.toml")]
    pub(crate) monitor_config: PathBuf,
    /// Rest this long at every waypoint (s): the waypoint times are recomputed with the
    /// daemon's planner limits (written to <out>/waypoints-timed.csv). Default: the CSV's times.
    #[arg(long)]
    pub(crate) dwell_s: Option<f64>,
    /// Write the rest points of the run as a crs-dataset 1 CSV (docs/data-format.md):
    /// commanded lengths, tracker pose, force sensors, reference pose.
    #[arg(long)]
    pub(crate) record: Option<PathBuf>,
    /// A rest point needs the reference constant for at least this long (s); its sample is the
    /// last tracker / force reading before the reference moves again.
    #[arg(long, default_value_t = 0.5)]
    pub(crate) settle_s: f64,
    /// Campaign name for the recording's metadata (default: the waypoint file's name).
    #[arg(long)]
    pub(crate) campaign: Option<String>,
    /// Run drive-io's SYNC loop (this priority) and sim-plant's loop (5 below) as SCHED_FIFO
    /// with mlockall, as motion-core and the monitor run theirs: keeps the setpoint stream and
    /// the SYNCs going on a loaded host (needs root; ignored with a note otherwise).
    #[arg(long, value_parser = clap::value_parser!(i32).range(6..=99))]
    pub(crate) rt_priority: Option<i32>,
}

impl SimArgs {
    pub(crate) fn options(&self) -> SimOptions {
        SimOptions {
            config: self.config.clone(),
            drives: self.drives.clone(),
            plant: self.plant.clone(),
            transport: self.transport.clone(),
            waypoints: self.waypoints.clone(),
            hold_s: self.hold_s,
            timeout_s: self.timeout_s,
            bin_dir: self.bin_dir.clone(),
            out: self.out.clone(),
            no_monitor: self.no_monitor,
            check: self.check,
            max_static_error_mm: self.max_static_error_mm,
            monitor_config: self.monitor_config.clone(),
            dwell_s: self.dwell_s,
            record: self.record.clone(),
            settle_s: self.settle_s,
            campaign: self.campaign.clone(),
            rt_priority: self.rt_priority,
        }
    }
}

pub fn run(a: SimArgs) -> Result<(), Box<dyn std::error::Error>> {
    let sum = execute(&a.options())?;
    if a.check {
        let fails = sum.check_failures(a.max_static_error_mm);
        if !fails.is_empty() {
            println!("SIM-CHECK: FAIL ({})", fails.join("; "));
            return Err(format!("check failed: {}", fails.join("; ")).into());
        }
        println!("SIM-CHECK: PASS");
    }
    Ok(())
}
