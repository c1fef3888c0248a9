//! `crs sim`: the whole simulated stack as separate processes, as a user runs it — the
//! command line of [`sim_runs::sim_run`] (which starts, follows and stops the processes and
//! writes the summary) plus the `--check` verdict.

use crate::console_cmd::SimConsoleArgs;
use crs_supervisor::timing::TimingProfile;
use sim_runs::platforms;
use sim_runs::sim_run::{SimOptions, execute_observed};
use stack_reports::sim_observer::SimObserver;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct SimArgs {
    /// The cabin: `icosahedron` or `helicopter`, or the path of one of their platform TOML
    /// files. Picks that platform's daemon, plant, safety-monitor and drives configs
    /// (config/); --config, --plant, --monitor-config and --drives replace single files of the
    /// set. Default: the platform of --config if it is one of these, else the
    /// icosahedron.
    #[arg(long)]
    pub(crate) platform: Option<String>,
    /// motion-core daemon TOML (platform, surrogate, realtime, trajectory) [default: the
    /// platform's, config/motion-core.toml for the icosahedron].
    #[arg(long)]
    pub(crate) config: Option<PathBuf>,
    /// Drive bus TOML [default: the platform's, config/drives.toml].
    #[arg(long)]
    pub(crate) drives: Option<PathBuf>,
    /// Plant TOML [default: the platform's, config/plant/icosahedron.toml for the icosahedron].
    /// A plant of another platform than the daemon's is run with a note.
    #[arg(long)]
    pub(crate) plant: Option<PathBuf>,
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
    /// Static (at rest) position error bound for --check, mm. The default is twice the largest
    /// at-rest error seen on the shipped plants (4.9 mm at the end of the demo hover flight,
    /// 0.15–0.44 mm after the tours).
    #[arg(long, default_value_t = sim_runs::sim_run::DEFAULT_MAX_STATIC_ERROR_MM)]
    pub(crate) max_static_error_mm: f64,
    /// Safety-monitor TOML (its [monitor] platform must be the daemon's platform) [default:
    /// the platform's, config/safety-monitor.toml for the icosahedron].
    #[arg(long)]
    pub(crate) monitor_config: Option<PathBuf>,
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
    /// Timing profile: `spec` (the configs as shipped), `relaxed` (debug builds on a loaded
    /// host: 4 ms loop and SYNC, longer watchdogs) or `emulated` (the QEMU guest: relaxed, no
    /// SCHED_FIFO, 0.1 of the demo speed). Non-spec profiles run relaxed copies of the daemon,
    /// drives and monitor configs written to <out>/timing-<profile>/.
    #[arg(long, default_value = "spec", value_parser = TimingProfile::NAMES)]
    pub(crate) timing: String,
    #[command(flatten)]
    pub(crate) console: SimConsoleArgs,
    #[command(flatten)]
    pub(crate) ride: crate::ride_cmd::RideArgs,
    #[command(flatten)]
    pub(crate) cueing: crate::cueing_cmd::CueingArgs,
}

/// The flags of `crs sim` do not give a run: the config set, or the ride flags.
#[derive(Debug, thiserror::Error)]
pub(crate) enum SimArgsError {
    #[error(transparent)]
    Configs(#[from] platforms::SelectError),
    #[error(transparent)]
    Ride(#[from] crate::ride_cmd::RideFlagError),
    #[error(transparent)]
    Cueing(#[from] crate::cueing_cmd::CueingFlagError),
}

impl SimArgs {
    /// The run's options.
    pub(crate) fn options(&self) -> Result<SimOptions, SimArgsError> {
        // The platform's set of configs (`--platform`'s, else that of the `--config` daemon),
        // single files replaced by the flags, as the timing profile runs them.
        let platform = self.platform.clone().or(self.ride.default_platform());
        let overrides = platforms::Overrides {
            daemon: self.config.clone(),
            drives: self.drives.clone(),
            plant: self.plant.clone(),
            monitor: self.monitor_config.clone(),
        };
        let files = platforms::run_files(platform.as_deref(), &overrides, &self.timing, &self.out)?;
        Ok(SimOptions {
            config: files.daemon,
            drives: files.drives,
            plant: files.plant,
            transport: self.transport.clone(),
            waypoints: self.waypoints.clone(),
            hold_s: self.hold_s,
            timeout_s: self.timeout_s,
            bin_dir: self.bin_dir.clone(),
            out: self.out.clone(),
            no_monitor: self.no_monitor,
            check: self.check,
            max_static_error_mm: self.max_static_error_mm,
            monitor_config: files.monitor,
            dwell_s: self.dwell_s,
            record: self.record.clone(),
            settle_s: self.settle_s,
            record_mean_forces: false,
            campaign: self.campaign.clone(),
            rt_priority: self.rt_priority,
            ride: self.ride.spec()?,
            cueing: self.cueing.spec(&self.ride.source)?,
            operator_start: self.console.start_from_console,
        })
    }
}

pub fn run(a: SimArgs) -> Result<(), Box<dyn std::error::Error>> {
    let mut observer = SimObserver::new(a.console.request());
    let options = a.options()?;
    // A plant of another platform than the daemon's runs, with a note (a plant with undeclared
    // errors is built on the nominal platform, so this only notes a real mix-up or a deliberate
    // experiment).
    if let Some(note) = platforms::plant_note_for_daemon(&options.plant, &options.config)? {
        println!("  {note}");
    }
    let sum = execute_observed(&options, &mut observer)?;
    observer.stop_console();
    // A stopped run is never a success, with or without --check.
    if !sum.completed {
        let who = sum.stopped_by.as_deref().unwrap_or("the run ended early");
        if a.check {
            // The stop first, then whatever else the check finds (a run stopped early has no
            // at-rest error to judge).
            let mut fails = vec![format!("stopped: {who}")];
            fails.extend(
                sum.check_failures(a.max_static_error_mm)
                    .into_iter()
                    .filter(|f| {
                        !(sum.static_position_mm.is_nan() && f.starts_with("static position error"))
                    }),
            );
            println!("SIM-CHECK: FAIL ({})", fails.join("; "));
        }
        return Err(format!("the run was stopped: {who}; the trajectory did not complete").into());
    }
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
