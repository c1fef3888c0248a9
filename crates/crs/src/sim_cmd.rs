//! `crs sim`: the whole simulated stack as separate processes, as a user runs it — the
//! command line of [`crs_stack::sim_run`] (which starts, follows and stops the processes and
//! writes the summary) plus the `--check` verdict.

use crate::console_cmd::SimConsoleArgs;
use cdpr_model::config::load_platform;
use crs_ipc::{JointSetpoint, LoopStatsSample, PlantTruth, StateEvent};
use crs_stack::platforms;
use crs_stack::run_plots::{self, RunRecord};
use crs_stack::sim_run::{RunObserver, RunStart, SimOptions, Summary, execute_observed};
use crs_stack::timing::{self, TimedConfigs, TimingProfile};
use std::path::Path;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct SimArgs {
    /// The cabin: `icosahedron` or `helicopter`, or the path of one of their platform TOML
    /// files. Picks that platform's daemon, plant, safety-monitor and drives configs (config/;
    /// crs_stack::platforms); --config, --plant, --monitor-config and --drives replace single
    /// files of the set. Default: the platform of --config if it is one of these, else the
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
    /// Static (at rest) position error bound for --check, mm.
    #[arg(long, default_value_t = 20.0)]
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
    /// drives and monitor configs written to <out>/timing-<profile>/ (crs_stack::timing).
    #[arg(long, default_value = "spec", value_parser = TimingProfile::NAMES)]
    pub(crate) timing: String,
    #[command(flatten)]
    pub(crate) console: SimConsoleArgs,
    #[command(flatten)]
    pub(crate) ride: crate::ride_cmd::RideArgs,
}

/// What `crs sim` runs next to the stack: the operator console (`--console`) and the run's
/// plots (out/sim/*.svg + index.html).
struct SimObserver<'a> {
    console_args: &'a SimConsoleArgs,
    console: Option<crs_console::ConsoleHandle>,
    plots: Option<RunRecord>,
}

impl RunObserver for SimObserver<'_> {
    fn started(&mut self, run: &RunStart<'_>) -> Result<(), Box<dyn std::error::Error>> {
        self.console = crate::console_cmd::start_for_sim(
            self.console_args,
            run.prefix,
            run.daemon,
            run.platform,
            run.waypoints,
        )?;
        let p = run.platform.model.params();
        self.plots = Some(RunRecord::new(p.f_min, p.f_max));
        Ok(())
    }
    fn setpoint(&mut self, sp: &JointSetpoint) {
        if let Some(p) = self.plots.as_mut() {
            p.setpoint(sp);
        }
    }
    fn truth(&mut self, t: &PlantTruth) {
        if let Some(p) = self.plots.as_mut() {
            p.truth(t);
        }
    }
    fn loop_stats(&mut self, s: &LoopStatsSample) {
        if let Some(p) = self.plots.as_mut() {
            p.loop_stats(s);
        }
    }
    fn event(&mut self, e: &StateEvent) {
        if let Some(p) = self.plots.as_mut() {
            p.event(e);
        }
    }
    fn finished(&mut self, out: &Path, summary: &Summary) {
        let Some(plots) = self.plots.as_ref() else {
            return;
        };
        let written = serde_json::to_value(summary)
            .map_err(|e| e.to_string())
            .and_then(|v| run_plots::write(out, plots, &v).map_err(|e| e.to_string()));
        match written {
            Ok(index) => println!("plots written to {}", index.display()),
            Err(e) => println!("plots NOT written: {e}"),
        }
    }
}

impl SimArgs {
    /// The platform's set of configs: `--platform`'s; without it the set of the platform the
    /// `--config` daemon runs (if it is a known one), else the default (icosahedron).
    fn platform_set(&self) -> Result<platforms::StackConfigs, Box<dyn std::error::Error>> {
        let dir = Path::new(platforms::CONFIG_DIR);
        if let Some(p) = self
            .platform
            .clone()
            .or(self.ride.default_platform())
            .as_ref()
        {
            let set = platforms::resolve(p, dir)?;
            if let Some(config) = &self.config {
                // A daemon TOML given next to --platform must run that platform.
                let daemon =
                    motion_core::daemon::config::load(config).map_err(|e| e.to_string())?;
                let runs = load_platform(&daemon.platform)?;
                if runs.model.identity() != load_platform(&set.platform)?.model.identity() {
                    return Err(format!(
                        "--platform {p} is {}, but --config {} runs {} ({}): leave one out",
                        set.platform.display(),
                        config.display(),
                        runs.name,
                        daemon.platform.display()
                    )
                    .into());
                }
            }
            return Ok(set);
        }
        if let Some(config) = &self.config {
            let daemon = motion_core::daemon::config::load(config).map_err(|e| e.to_string())?;
            if let Ok(set) = platforms::resolve(&daemon.platform.display().to_string(), dir) {
                return Ok(set);
            }
        }
        Ok(platforms::KNOWN[0].configs(dir))
    }

    /// The run's options: the files of the platform's set, single files replaced by the flags.
    pub(crate) fn options(&self) -> Result<SimOptions, Box<dyn std::error::Error>> {
        let set = self.platform_set()?;
        let pick = |flag: &Option<PathBuf>, default: &PathBuf| {
            flag.clone().unwrap_or_else(|| default.clone())
        };
        let profile: TimingProfile = self.timing.parse()?;
        let timed = timing::write_profile(
            profile,
            &TimedConfigs {
                daemon: pick(&self.config, &set.daemon),
                drives: pick(&self.drives, &set.drives),
                monitor: pick(&self.monitor_config, &set.monitor),
            },
            &self.out.join(format!("timing-{}", profile.name())),
        )?;
        Ok(SimOptions {
            config: timed.daemon,
            drives: timed.drives,
            plant: pick(&self.plant, &set.plant),
            transport: self.transport.clone(),
            waypoints: self.waypoints.clone(),
            hold_s: self.hold_s,
            timeout_s: self.timeout_s,
            bin_dir: self.bin_dir.clone(),
            out: self.out.clone(),
            no_monitor: self.no_monitor,
            check: self.check,
            max_static_error_mm: self.max_static_error_mm,
            monitor_config: timed.monitor,
            dwell_s: self.dwell_s,
            record: self.record.clone(),
            settle_s: self.settle_s,
            record_mean_forces: false,
            campaign: self.campaign.clone(),
            rt_priority: self.rt_priority,
            ride: self.ride.spec()?,
        })
    }
}

/// A plant of another platform than the daemon's runs, with a note (a plant with undeclared
/// errors is built on the nominal platform, so this only notes a real mix-up or a deliberate
/// experiment).
fn note_plant_platform(o: &SimOptions) -> Result<(), Box<dyn std::error::Error>> {
    let daemon = motion_core::daemon::config::load(&o.config).map_err(|e| e.to_string())?;
    let platform = load_platform(&daemon.platform)?;
    if let Some(note) = platforms::plant_platform_note(&o.plant, &daemon.platform, &platform)? {
        println!("  {note}");
    }
    Ok(())
}

pub fn run(a: SimArgs) -> Result<(), Box<dyn std::error::Error>> {
    let mut observer = SimObserver {
        console_args: &a.console,
        console: None,
        plots: None,
    };
    let options = a.options()?;
    note_plant_platform(&options)?;
    let sum = execute_observed(&options, &mut observer)?;
    drop(observer.console.take());
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
