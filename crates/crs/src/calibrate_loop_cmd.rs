//! `crs calibrate loop` and `crs calibrate campaign`: the command line of
//! [`calibration_campaigns::calibration_loop`] and [`sim_runs::campaign`]. The closed loop on the running stack — record a campaign on
//! the simulated stack with the nominal model, identify, deploy the identified model and a
//! refitted surrogate, re-run the same campaign and report the MEASURED pose error at the rest
//! points before and after. `crs calibrate campaign` makes the campaign file.

use calibration_campaigns::calibration_loop::{LoopOptions, StackTools};
use calibration_campaigns::progress::Spinner;
use sim_runs::campaign::{self, CampaignRequest};
use std::path::PathBuf;

type BoxErr = Box<dyn std::error::Error>;

#[derive(clap::Args, Debug)]
pub struct LoopArgs {
    /// Nominal platform TOML: the model the stack runs before calibration and the start of the
    /// identification.
    #[arg(long, default_value = "config/icosahedron.toml")]
    platform: PathBuf,
    /// Plant TOML with the effects the model does not declare.
    #[arg(long, default_value = "config/plant/icosahedron-assembly.toml")]
    plant: PathBuf,
    /// Campaign: waypoint CSV (motion-core's format; the times are recomputed for the dwell).
    #[arg(long, default_value = "config/calibration-campaign.csv")]
    campaign: PathBuf,
    /// Use only the first N poses of the campaign.
    #[arg(long)]
    max_poses: Option<usize>,
    /// Rest at every pose (s); must exceed --settle-s.
    #[arg(long, default_value_t = 1.0)]
    dwell_s: f64,
    /// Reference constant this long before a rest point's readings count (s).
    #[arg(long, default_value_t = 0.5)]
    settle_s: f64,
    /// Hold out poses with index % N == N − 1 for the identification's validation figures.
    #[arg(long, default_value_t = 4)]
    holdout_every: u64,
    /// Run both campaigns with the kinematic controller only (no surrogate fitted or deployed).
    #[arg(long)]
    no_surrogate: bool,
    /// Validation samples of each surrogate fit (Halton, in addition to the 3^6 grid).
    #[arg(long, default_value_t = 2000)]
    surrogate_validation_samples: usize,
    /// Daemon TOML template ([realtime], [trajectory] limits); platform, surrogate and
    /// waypoints are replaced.
    #[arg(long, default_value = "config/motion-core.toml")]
    daemon_config: PathBuf,
    /// Safety-monitor TOML template; [monitor] platform and [can] drives are replaced.
    #[arg(long, default_value = "config/safety-monitor.toml")]
    monitor_config: PathBuf,
    #[arg(long, default_value = "config/drives.toml")]
    drives: PathBuf,
    /// `auto` (vcan0 if present, else the UDP loopback bus) or a transport spec.
    #[arg(long, default_value = "auto")]
    transport: String,
    /// Directory with the stack's binaries (default: next to this `crs`).
    #[arg(long)]
    bin_dir: Option<PathBuf>,
    /// Run without the safety monitor.
    #[arg(long)]
    no_monitor: bool,
    /// Ridge λ on k_F towards the nominal in the identification (`crs calibrate run
    /// --ridge-kf`, k_F in 1e6 N): keeps the weakly determined stiffnesses of a short campaign
    /// in range. Without it, 12 poses gave k_F of 1.0–5.3 MN (true 1.9–2.2) and a refitted
    /// surrogate above the 100 mm bound that motion-core refused; with 1000, 1.8–2.2 MN and
    /// 5–7× lower error. 0 = off.
    #[arg(long, default_value_t = 1000.0)]
    ridge_kf: f64,
    /// SCHED_FIFO priority of drive-io (sim-plant 5 below), as `crs sim --rt-priority`; 0 = off.
    /// On a shared, loaded host the default keeps the setpoint stream and SYNCs without gaps.
    #[arg(long, default_value_t = 75, value_parser = clap::value_parser!(i32).range(0..=99))]
    rt_priority: i32,
    /// Runs again (up to this many times) when drive-io stopped the bus during a run (a gap in
    /// the setpoint stream on a loaded, non-real-time host); the report counts the retries.
    #[arg(long, default_value_t = 2)]
    retries: usize,
    /// Fail (exit 1) unless the measured mean position error drops by at least this factor.
    #[arg(long)]
    min_improvement: Option<f64>,
    /// Output directory (before/, identification/, after/, report.md, report.json).
    #[arg(long, default_value = "out/calibrate-loop")]
    out: PathBuf,
}

impl LoopArgs {
    fn options(&self) -> LoopOptions {
        LoopOptions {
            platform: self.platform.clone(),
            plant: self.plant.clone(),
            campaign: self.campaign.clone(),
            max_poses: self.max_poses,
            dwell_s: self.dwell_s,
            settle_s: self.settle_s,
            holdout_every: self.holdout_every,
            no_surrogate: self.no_surrogate,
            surrogate_validation_samples: self.surrogate_validation_samples,
            daemon_config: self.daemon_config.clone(),
            monitor_config: self.monitor_config.clone(),
            drives: self.drives.clone(),
            transport: self.transport.clone(),
            bin_dir: self.bin_dir.clone(),
            no_monitor: self.no_monitor,
            ridge_kf: self.ridge_kf,
            rt_priority: self.rt_priority,
            retries: self.retries,
            min_improvement: self.min_improvement,
            out: self.out.clone(),
        }
    }
}

pub fn run_loop(a: LoopArgs, command: &str) -> Result<(), BoxErr> {
    let mut progress = Spinner::default();
    let mut tools = StackTools {
        progress: &mut progress,
    };
    calibration_campaigns::calibration_loop::run_loop(a.options(), command, &mut tools)?;
    Ok(())
}

#[derive(clap::Args, Debug)]
pub struct CampaignArgs {
    /// Platform TOML whose workspace region, force limits and planner limits are used.
    #[arg(long, default_value = "config/icosahedron.toml")]
    platform: PathBuf,
    /// Daemon TOML (planner limits, loop period, feasibility check).
    #[arg(long, default_value = "config/motion-core.toml")]
    daemon_config: PathBuf,
    /// Number of poses.
    #[arg(long, default_value_t = 40)]
    poses: usize,
    /// Fraction of the workspace box (around its centre) the poses are drawn from.
    #[arg(long, default_value_t = 0.8)]
    fraction: f64,
    /// Reference forces (eq. 3.41) must keep this distance from f_min and f_max (N), so the
    /// assembled plant stays within the limits too.
    #[arg(long, default_value_t = 1200.0)]
    force_margin_n: f64,
    /// Output CSV.
    #[arg(long, default_value = "config/calibration-campaign.csv")]
    out: PathBuf,
}

pub fn run_campaign(a: CampaignArgs) -> Result<(), BoxErr> {
    let (n, dur) = campaign::make(&CampaignRequest {
        platform: &a.platform,
        daemon_config: &a.daemon_config,
        poses: a.poses,
        fraction: a.fraction,
        force_margin_n: a.force_margin_n,
        out: &a.out,
    })?;
    println!(
        "wrote {n} poses to {} (plan {dur:.1} s without rests)",
        a.out.display()
    );
    Ok(())
}
