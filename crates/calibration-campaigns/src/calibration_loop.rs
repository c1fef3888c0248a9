//! The closed calibration loop on the running stack (`crs calibrate loop`) — record a
//! campaign on the simulated stack with the nominal model, identify, deploy the identified
//! model and a refitted surrogate, re-run the same campaign and report the MEASURED pose error
//! at the rest points before and after.
//!
//! Steps (each one a command an operator could run by hand; the report lists them):
//! 1. surrogate of the nominal platform (`crs surrogate fit`), unless `--no-surrogate`;
//! 2. daemon + safety-monitor TOMLs pointing to it (same platform in both: identity check);
//! 3. `crs sim --dwell-s … --record before/campaign.csv` on the plant with undeclared effects;
//! 4. identification from the nominal model on the recording, held-out split
//!    (`crs calibrate run`), writing calibrated.toml;
//! 5. surrogate refitted on calibrated.toml;
//! 6. daemon + monitor TOMLs pointing to calibrated.toml and the new surrogate;
//! 7. the same campaign again (`after/campaign.csv`);
//! 8. report.md / report.json: before/after at the rest points, forces, identification figures.
//!
//! The cable offsets of the identification are not deployed: the stack's commissioning homes
//! the drives at the set-up pose to the controller's command there (`sim_plant::bus`), which
//! fixes them on the real robot too (eq. 3.14 / 6.24).

//!
//! The identification with its report and the surrogate fit (`crs calibrate run`, `crs
//! surrogate fit`) come in through [`LoopTools`]; [`StackTools`] is this library's own
//! (identification by `calibration_output`, the fit by `surrogate_evaluation`), showing its
//! progress through the caller's [`Progress`](crate::progress::Progress).

use calibrate::Observation;
use calibrate::{from_dataset, split};
use calibrate_diagnosis::pipeline::PipelineReport;
use cdpr_model::config::{Platform, load_platform};
use motion_core::daemon::config::DaemonConfig;
use motion_core::daemon::lifecycle;
use motion_core::daemon::trajectory;
use sim_runs::campaign::timed_waypoints;
use sim_runs::campaign::write_waypoints;
use sim_runs::sim_run::{self, SimOptions, Summary};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Why the closed loop stopped: refused inputs, a step that failed, or (with
/// `--min-improvement`) a calibration that did not help enough.
#[derive(Debug, thiserror::Error)]
pub enum LoopError {
    /// `--dwell-s` must exceed `--settle-s`, which must be positive.
    #[error("--dwell-s ({dwell_s}) must exceed --settle-s ({settle_s}) > 0")]
    Dwell { dwell_s: f64, settle_s: f64 },
    /// An input file given on the command line does not exist.
    #[error("{}: no such file", path.display())]
    NoSuchFile { path: PathBuf },
    /// A platform, plant or daemon TOML (names its file and key).
    #[error(transparent)]
    Config(#[from] cdpr_model::config::ConfigError),
    /// The plant is not built on the nominal platform.
    #[error(
        "{}: the plant's nominal platform ({}) is not {}",
        plant.display(),
        plant_platform.display(),
        platform.display()
    )]
    PlantPlatform {
        plant: PathBuf,
        plant_platform: PathBuf,
        platform: PathBuf,
    },
    /// The campaign's waypoint file.
    #[error(transparent)]
    Waypoints(#[from] trajectory::WaypointError),
    #[error("--max-poses must be ≥ 1")]
    MaxPoses,
    #[error("{poses} poses are too few for a held-out split every {holdout_every}")]
    TooFewPoses { poses: usize, holdout_every: u64 },
    /// Reading `path` (a template, a platform to pin) or resolving it to an absolute path.
    #[error("{}: {source}", path.display())]
    File {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A template is not TOML.
    #[error("{}: {source}", template.display())]
    TemplateToml {
        template: PathBuf,
        #[source]
        source: toml::de::Error,
    },
    /// A template lacks a table the loop fills in.
    #[error("{}: no [{table}] table", template.display())]
    NoTable { template: PathBuf, table: String },
    /// A written TOML could not be formatted.
    #[error(transparent)]
    TomlOut(#[from] toml::ser::Error),
    /// Creating an output directory or writing an output file (`path`).
    #[error("{source}")]
    Output {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Writing or timing the campaign.
    #[error(transparent)]
    Campaign(#[from] sim_runs::campaign::CampaignError),
    /// The controller cannot be configured for the nominal platform.
    #[error(transparent)]
    Configure(#[from] lifecycle::ConfigureError),
    /// The nominal controller refuses the campaign.
    #[error("{}: the plan is refused: {source}", campaign.display())]
    PlanRefused {
        campaign: PathBuf,
        #[source]
        source: lifecycle::PlanRefused,
    },
    /// The calibrated controller refuses the campaign.
    #[error("the calibrated model {} refuses the campaign: {source}", calibrated.display())]
    CalibratedRefuses {
        calibrated: PathBuf,
        #[source]
        source: lifecycle::PlanRefused,
    },
    /// The surrogate fit.
    #[error(transparent)]
    Fit(#[from] surrogate::FitError),
    /// Saving the surrogate to `path`.
    #[error("{}: {source}", path.display())]
    SaveSurrogate {
        path: PathBuf,
        #[source]
        source: surrogate::FileError,
    },
    /// A run of the stack.
    #[error(transparent)]
    Run(#[from] sim_run::SimError),
    /// A run completed with stops, faults or refused references (`fails`), logs in `dir`.
    #[error("the {name} run failed: {} (logs in {})", fails.join("; "), dir.display())]
    RunFailed {
        name: String,
        fails: Vec<String>,
        dir: PathBuf,
    },
    /// A run did not record a rest point at every pose.
    #[error(
        "the {label} run recorded {recorded} rest points for {poses} poses ({skipped} skipped): see {}",
        dir.display()
    )]
    RestPoints {
        label: String,
        recorded: usize,
        poses: usize,
        skipped: usize,
        dir: PathBuf,
    },
    /// The before-run's recording.
    #[error(transparent)]
    Dataset(#[from] crs_dataset::DatasetError),
    /// The before-run's recording does not give observations.
    #[error("{}: {source}", record.display())]
    Observations {
        record: PathBuf,
        #[source]
        source: calibrate::observation::ObservationError,
    },
    /// The identification and its report.
    #[error(transparent)]
    Identify(#[from] crate::calibration_output::OutputError),
    /// Serialising report.json.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// `--min-improvement` not reached.
    #[error(
        "the measured mean position error dropped by {improvement:.2}×, less than --min-improvement {min}"
    )]
    NotImproved { improvement: f64, min: f64 },
}

fn output(path: &Path) -> impl FnOnce(std::io::Error) -> LoopError + '_ {
    move |source| LoopError::Output {
        path: path.to_path_buf(),
        source,
    }
}

fn file(path: &Path) -> impl FnOnce(std::io::Error) -> LoopError + '_ {
    move |source| LoopError::File {
        path: path.to_path_buf(),
        source,
    }
}

/// The two steps of the loop an operator also runs by hand.
pub trait LoopTools {
    /// `crs surrogate fit` of `pf` with `opts` (progress shown as the caller likes).
    fn fit_surrogate(
        &mut self,
        pf: &Platform,
        opts: &surrogate::FitOptions,
    ) -> Result<(surrogate::Surrogate, surrogate::FitReport), surrogate::FitError>;
    /// `crs calibrate run --no-extension --holdout-every … --ridge-kf …` from `nominal` on
    /// the recorded observations, writing its report and calibrated.toml into `out`.
    #[allow(clippy::too_many_arguments)]
    fn identify(
        &mut self,
        nominal: &Platform,
        train: &[Observation],
        held: &[Observation],
        out: &Path,
        holdout_every: u64,
        ridge_kf: f64,
        command: &str,
    ) -> Result<PipelineReport, crate::calibration_output::OutputError>;
}

/// The loop's tools from this library: the surrogate fit of `crs surrogate fit`
/// ([`fit_platform`](plant_experiments::surrogate_evaluation::fit_platform)) and the identification of
/// `crs calibrate run --no-extension --ridge-kf λ`, every other option at its default
/// ([`identify_and_report`](crate::calibration_output::identify_and_report)); `progress` shows
/// them running.
pub struct StackTools<'a> {
    pub progress: &'a mut dyn crate::progress::Progress,
}

impl LoopTools for StackTools<'_> {
    fn fit_surrogate(
        &mut self,
        pf: &Platform,
        opts: &surrogate::FitOptions,
    ) -> Result<(surrogate::Surrogate, surrogate::FitReport), surrogate::FitError> {
        self.progress
            .start(&format!("fitting the surrogate of `{}`", pf.name));
        let r = plant_experiments::surrogate_evaluation::fit_platform(pf, opts);
        self.progress.finish();
        r
    }

    fn identify(
        &mut self,
        nominal: &Platform,
        train: &[Observation],
        held: &[Observation],
        out: &Path,
        _holdout_every: u64,
        ridge_kf: f64,
        command: &str,
    ) -> Result<PipelineReport, crate::calibration_output::OutputError> {
        let cfg = calibrate_diagnosis::pipeline::PipelineConfig {
            ridge_kf,
            no_extension: true,
            ..Default::default()
        };
        let id = crate::calibration_output::Identification {
            pipeline: &cfg,
            repeatability: None,
            out,
            command,
        };
        let rep = crate::calibration_output::identify_and_report(
            nominal,
            train,
            held,
            &id,
            false,
            self.progress,
        )?;
        Ok(rep)
    }
}

/// The options of `crs calibrate loop`.
#[derive(Clone, Debug)]
pub struct LoopOptions {
    /// Nominal platform TOML: the model the stack runs before calibration and the start of the
    /// identification.
    pub platform: PathBuf,
    /// Plant TOML with the effects the model does not declare.
    pub plant: PathBuf,
    /// Campaign: waypoint CSV (motion-core's format; the times are recomputed for the dwell).
    pub campaign: PathBuf,
    /// Use only the first N poses of the campaign.
    pub max_poses: Option<usize>,
    /// Rest at every pose (s); must exceed --settle-s.
    pub dwell_s: f64,
    /// Reference constant this long before a rest point's readings count (s).
    pub settle_s: f64,
    /// Hold out poses with index % N == N − 1 for the identification's validation figures.
    pub holdout_every: u64,
    /// Run both campaigns with the kinematic controller only (no surrogate fitted or deployed).
    pub no_surrogate: bool,
    /// Validation samples of each surrogate fit (Halton, in addition to the 3^6 grid).
    pub surrogate_validation_samples: usize,
    /// Daemon TOML template ([realtime], [trajectory] limits); platform, surrogate and
    /// waypoints are replaced.
    pub daemon_config: PathBuf,
    /// Safety-monitor TOML template; [monitor] platform and [can] drives are replaced.
    pub monitor_config: PathBuf,
    pub drives: PathBuf,
    /// `auto` (vcan0 if present, else the UDP loopback bus) or a transport spec.
    pub transport: String,
    /// Directory with the stack's binaries (default: next to this `crs`).
    pub bin_dir: Option<PathBuf>,
    /// Run without the safety monitor.
    pub no_monitor: bool,
    /// Ridge λ on k_F towards the nominal in the identification (`crs calibrate run
    /// --ridge-kf`, k_F in 1e6 N): keeps the weakly determined stiffnesses of a short campaign
    /// in range. Without it, 12 poses gave k_F of 1.0–5.3 MN (true 1.9–2.2) and a refitted
    /// surrogate above the 100 mm bound that motion-core refused; with 1000, 1.8–2.2 MN and
    /// 5–7× lower error. 0 = off.
    pub ridge_kf: f64,
    /// SCHED_FIFO priority of drive-io (sim-plant 5 below), as `crs sim --rt-priority`; 0 = off.
    /// On a shared, loaded host the default keeps the setpoint stream and SYNCs without gaps.
    pub rt_priority: i32,
    /// Runs again (up to this many times) when drive-io stopped the bus during a run (a gap in
    /// the setpoint stream on a loaded, non-real-time host); the report counts the retries.
    pub retries: usize,
    /// Fail (exit 1) unless the measured mean position error drops by at least this factor.
    pub min_improvement: Option<f64>,
    /// Output directory (before/, identification/, after/, report.md, report.json).
    pub out: PathBuf,
}

fn abs(p: &Path) -> Result<PathBuf, LoopError> {
    std::fs::canonicalize(p).map_err(file(p))
}

/// A TOML template as a table; errors name the file.
fn read_template(template: &Path) -> Result<toml::Table, LoopError> {
    let text = std::fs::read_to_string(template).map_err(file(template))?;
    text.parse().map_err(|source| LoopError::TemplateToml {
        template: template.to_path_buf(),
        source,
    })
}

/// The `[name]` table of a template (must exist).
fn section<'a>(
    t: &'a mut toml::Table,
    name: &str,
    template: &Path,
) -> Result<&'a mut toml::Table, LoopError> {
    t.get_mut(name)
        .and_then(|v| v.as_table_mut())
        .ok_or_else(|| LoopError::NoTable {
            template: template.to_path_buf(),
            table: name.to_string(),
        })
}

/// An absolute path as a TOML string (the written files live elsewhere than the template).
fn path_value(p: &Path) -> Result<toml::Value, LoopError> {
    Ok(toml::Value::String(abs(p)?.display().to_string()))
}

/// Writes `t` to `out` with a header naming the template it came from.
fn write_from_template(
    out: &Path,
    t: &toml::Table,
    what: &str,
    template: &Path,
) -> Result<(), LoopError> {
    let body = toml::to_string(t)?;
    std::fs::write(
        out,
        format!(
            "# {what} TOML written by `crs calibrate loop` from {}.\n{body}",
            template.display()
        ),
    )
    .map_err(output(out))
}

/// The daemon TOML of one run: the template with platform, surrogate and waypoints replaced.
fn write_daemon_toml(
    template: &Path,
    out: &Path,
    platform: &Path,
    surrogate: Option<&Path>,
    waypoints: &Path,
) -> Result<(), LoopError> {
    let mut t = read_template(template)?;
    let d = section(&mut t, "daemon", template)?;
    d.insert("platform".into(), path_value(platform)?);
    d.insert(
        "surrogate".into(),
        match surrogate {
            Some(p) => path_value(p)?,
            None => toml::Value::String(String::new()),
        },
    );
    d.remove("stats_file");
    section(&mut t, "trajectory", template)?.insert("waypoints".into(), path_value(waypoints)?);
    write_from_template(out, &t, "motion-core daemon", template)?;
    // The daemon's loader must accept it.
    motion_core::daemon::config::load(out)?;
    Ok(())
}

/// The safety-monitor TOML of one run: the template with [monitor] platform and [can] drives.
fn write_monitor_toml(
    template: &Path,
    out: &Path,
    platform: &Path,
    drives: &Path,
) -> Result<(), LoopError> {
    let mut t = read_template(template)?;
    let mon = section(&mut t, "monitor", template)?;
    mon.insert("platform".into(), path_value(platform)?);
    // The closed loop's simulated runs use the platform they were told to (the nominal or the
    // calibrated one): this run's monitor accepts exactly that file (the monitor runs only an accepted platform; on a robot the
    // operator accepts with `safety-monitor accept`, which shows the diff first).
    let bytes = std::fs::read(platform).map_err(file(platform))?;
    mon.insert(
        "platform_sha256".into(),
        toml::Value::String(safety_monitor::identity::hex(
            &safety_monitor::config::sha256_of(&bytes),
        )),
    );
    mon.insert("trip_log".into(), toml::Value::String(String::new()));
    section(&mut t, "can", template)?.insert("drives".into(), path_value(drives)?);
    write_from_template(out, &t, "safety-monitor", template)
}

/// The surrogate of one run (none with `--no-surrogate`), its figures printed and its command
/// recorded.
fn maybe_fit_surrogate(
    tools: &mut dyn LoopTools,
    with_sg: bool,
    platform: &Path,
    a: &LoopOptions,
    out: &Path,
    commands: &mut Vec<String>,
) -> Result<Option<surrogate::FitReport>, LoopError> {
    if !with_sg {
        return Ok(None);
    }
    let r = fit_surrogate(tools, platform, a.surrogate_validation_samples, out)?;
    println!(
        "  max |φ_sg| {:.1} mm, fit error max {:.3} mm → {}",
        r.max_abs_offset_mm,
        r.max_fit_error_mm,
        out.display()
    );
    commands.push(format!(
        "crs surrogate fit --platform {} --validation-samples {} --out {}",
        platform.display(),
        a.surrogate_validation_samples,
        out.display()
    ));
    Ok(Some(r))
}

/// The daemon and safety-monitor TOMLs of one run in `dir`, both on `platform`.
fn write_run_configs(
    a: &LoopOptions,
    dir: &Path,
    platform: &Path,
    surrogate: Option<&Path>,
    campaign: &Path,
) -> Result<(PathBuf, PathBuf), LoopError> {
    let (daemon, monitor) = (
        dir.join("motion-core.toml"),
        dir.join("safety-monitor.toml"),
    );
    write_daemon_toml(&a.daemon_config, &daemon, platform, surrogate, campaign)?;
    write_monitor_toml(&a.monitor_config, &monitor, platform, &a.drives)?;
    Ok((daemon, monitor))
}

/// A run must have recorded a rest point at every pose of the campaign.
fn all_rest_points(label: &str, sum: &Summary, poses: usize, dir: &Path) -> Result<(), LoopError> {
    if sum.rest.rest_points == poses {
        return Ok(());
    }
    Err(LoopError::RestPoints {
        label: label.to_string(),
        recorded: sum.rest.rest_points,
        poses,
        skipped: sum.rest_points_skipped,
        dir: dir.to_path_buf(),
    })
}

/// Fits the surrogate of `platform` (as `crs surrogate fit` with the default degree and margin).
fn fit_surrogate(
    tools: &mut dyn LoopTools,
    platform: &Path,
    validation_samples: usize,
    out: &Path,
) -> Result<surrogate::FitReport, LoopError> {
    let pf = load_platform(platform)?;
    let opts = surrogate::FitOptions {
        validation_samples,
        margin_m: 0.010,
        ..surrogate::FitOptions::default()
    };
    let (sg, report) = tools.fit_surrogate(&pf, &opts)?;
    sg.save(out).map_err(|source| LoopError::SaveSurrogate {
        path: out.to_path_buf(),
        source,
    })?;
    Ok(report)
}

/// One run of the campaign on the stack, as reported.
#[derive(Clone, Debug, serde::Serialize)]
struct RunReport {
    platform: PathBuf,
    surrogate: Option<PathBuf>,
    surrogate_max_offset_mm: Option<f64>,
    daemon_config: PathBuf,
    monitor_config: PathBuf,
    record: PathBuf,
    /// Runs needed (more than 1: drive-io stopped the bus in an earlier one, `--retries`).
    attempts: usize,
    summary: Summary,
}

#[derive(Clone, Debug, serde::Serialize)]
struct StageRow {
    name: String,
    holdout: calibrate::validate::Errors,
}

#[derive(Clone, Debug, serde::Serialize)]
struct LoopReport {
    command: String,
    plant: PathBuf,
    campaign: PathBuf,
    poses: usize,
    dwell_s: f64,
    settle_s: f64,
    control_model: String,
    before: RunReport,
    identification: Vec<StageRow>,
    identification_train: usize,
    identification_holdout: usize,
    deployed_stage: String,
    calibrated_platform: PathBuf,
    after: RunReport,
    /// Measured mean position error before / after at the rest points.
    improvement_position_mean: f64,
    improvement_position_max: f64,
    improvement_rotation_mean: f64,
    runtime_s: f64,
    commands: Vec<String>,
}

#[allow(clippy::too_many_arguments)]
fn stack_run(
    a: &LoopOptions,
    daemon_toml: &Path,
    monitor_toml: &Path,
    campaign: &Path,
    dir: &Path,
    record: &Path,
    timeout_s: f64,
    name: &str,
) -> Result<(Summary, usize), LoopError> {
    let args = SimOptions {
        operator_start: false,
        config: daemon_toml.to_path_buf(),
        drives: a.drives.clone(),
        plant: a.plant.clone(),
        transport: a.transport.clone(),
        waypoints: Some(campaign.to_path_buf()),
        hold_s: a.dwell_s,
        timeout_s,
        bin_dir: a.bin_dir.clone(),
        out: dir.to_path_buf(),
        no_monitor: a.no_monitor,
        check: false,
        max_static_error_mm: f64::INFINITY,
        monitor_config: monitor_toml.to_path_buf(),
        dwell_s: Some(a.dwell_s),
        record: Some(record.to_path_buf()),
        settle_s: a.settle_s,
        record_mean_forces: false,
        campaign: Some(name.to_string()),
        rt_priority: (a.rt_priority >= 6).then_some(a.rt_priority),
        ride: None,
        cueing: None,
    };
    let mut attempt = 0;
    let sum = loop {
        let sum = sim_run::execute(&args)?;
        match &sum.bus_stopped_during_run {
            Some(b) if attempt < a.retries => {
                attempt += 1;
                println!(
                    "  the {name} run was interrupted: drive-io stopped the bus ({b}), most likely a gap in the setpoint stream on a loaded host; running it again ({attempt}/{})",
                    a.retries
                );
            }
            _ => break sum,
        }
    };
    let mut fails = Vec::new();
    if let Some(b) = &sum.bus_stopped_during_run {
        fails.push(format!("drive-io stopped the bus during the run ({b})"));
    }
    if sum.estops > 0 {
        fails.push(format!("{} e-stop(s)", sum.estops));
    }
    if sum.drive_faults > 0 {
        fails.push(format!("{} drive fault reports", sum.drive_faults));
    }
    if sum.loop_rejected > 0 {
        fails.push(format!("{} references refused", sum.loop_rejected));
    }
    if sum.non_converged_plant_steps > 0 {
        fails.push(format!(
            "{} plant steps without equilibrium",
            sum.non_converged_plant_steps
        ));
    }
    if !fails.is_empty() {
        return Err(LoopError::RunFailed {
            name: name.to_string(),
            fails,
            dir: dir.to_path_buf(),
        });
    }
    Ok((sum, attempt + 1))
}

/// The loop's seven steps, as printed.
const STEPS: usize = 7;

fn step(k: usize, what: &str) {
    println!("\n[{k}/{STEPS}] {what}");
}

/// The loop checked and set up before any fit or run: the campaign as run, its plan verified on
/// the nominal platform, the run directories.
struct LoopPlan {
    nominal: Platform,
    daemon_tpl: DaemonConfig,
    wps: Vec<trajectory::Waypoint>,
    dir_b: PathBuf,
    dir_i: PathBuf,
    dir_a: PathBuf,
    /// The campaign as run (first N poses).
    campaign: PathBuf,
    plan_s: f64,
    timeout_s: f64,
    name: String,
    with_sg: bool,
}

/// The options and the files checked, the campaign written and verified with motion-core's own
/// checks on the nominal platform; nothing runs yet.
fn prepare_loop(a: &LoopOptions) -> Result<LoopPlan, LoopError> {
    if !(a.dwell_s.is_finite() && a.settle_s > 0.0 && a.dwell_s > a.settle_s) {
        return Err(LoopError::Dwell {
            dwell_s: a.dwell_s,
            settle_s: a.settle_s,
        });
    }
    for f in [
        &a.platform,
        &a.plant,
        &a.campaign,
        &a.daemon_config,
        &a.monitor_config,
        &a.drives,
    ] {
        if !f.is_file() {
            return Err(LoopError::NoSuchFile { path: f.clone() });
        }
    }
    let nominal = load_platform(&a.platform)?;
    let pcfg = sim_plant::load_plant(&a.plant)?;
    if pcfg.platform.model.identity_hex() != nominal.model.identity_hex() {
        return Err(LoopError::PlantPlatform {
            plant: a.plant.clone(),
            plant_platform: pcfg.platform_path.clone(),
            platform: a.platform.clone(),
        });
    }
    let daemon_tpl = motion_core::daemon::config::load(&a.daemon_config)?;
    let mut wps = trajectory::read_waypoints(&a.campaign)?;
    if let Some(n) = a.max_poses {
        if n == 0 {
            return Err(LoopError::MaxPoses);
        }
        wps.truncate(n);
    }
    let holdout = a.holdout_every;
    if holdout != 0 && wps.len() < 2 * holdout as usize {
        return Err(LoopError::TooFewPoses {
            poses: wps.len(),
            holdout_every: holdout,
        });
    }
    std::fs::create_dir_all(&a.out).map_err(output(&a.out))?;
    let (dir_b, dir_i, dir_a) = (
        a.out.join("before"),
        a.out.join("identification"),
        a.out.join("after"),
    );
    for d in [&dir_b, &dir_i, &dir_a] {
        std::fs::create_dir_all(d).map_err(output(d))?;
    }
    let campaign = a.out.join("campaign.csv");
    write_waypoints(
        &campaign,
        &wps,
        &format!(
            "{} poses of {} (crs calibrate loop)",
            wps.len(),
            a.campaign.display()
        ),
    )?;
    let nominal_checks = lifecycle::configure_checks(&daemon_tpl, &nominal)?;
    nominal_checks
        .verify_plan(&wps)
        .map_err(|source| LoopError::PlanRefused {
            campaign: a.campaign.clone(),
            source,
        })?;
    let (_, plan_s) = timed_waypoints(
        nominal.home,
        &wps,
        nominal_checks.planner_limits(),
        nominal_checks.period_s(),
        a.dwell_s,
    )?;
    let name = a
        .campaign
        .file_stem()
        .map_or("campaign".into(), |n| n.to_string_lossy().into_owned());
    Ok(LoopPlan {
        nominal,
        daemon_tpl,
        wps,
        dir_b,
        dir_i,
        dir_a,
        campaign,
        plan_s,
        timeout_s: 1.5 * (plan_s + a.dwell_s) + 60.0,
        name,
        with_sg: !a.no_surrogate,
    })
}

/// The `crs sim` command line of one of the loop's runs (for the report).
fn sim_command_line(a: &LoopOptions, campaign: &Path, dir: &Path) -> String {
    format!(
        "crs sim --config {} --monitor-config {} --plant {} --drives {} --waypoints {} --dwell-s {} --settle-s {} --hold-s {} --record {} --out {}{}",
        dir.join("motion-core.toml").display(),
        dir.join("safety-monitor.toml").display(),
        a.plant.display(),
        a.drives.display(),
        campaign.display(),
        a.dwell_s,
        a.settle_s,
        a.dwell_s,
        dir.join("campaign.csv").display(),
        dir.display(),
        if a.rt_priority >= 6 {
            format!(" --rt-priority {}", a.rt_priority)
        } else {
            String::new()
        }
    )
}

/// The campaign on the stack with the run's configs in `dir`, every rest point required.
#[allow(clippy::too_many_arguments)]
fn campaign_run(
    a: &LoopOptions,
    plan: &LoopPlan,
    platform: &Path,
    surrogate: Option<(PathBuf, Option<surrogate::FitReport>)>,
    (daemon_config, monitor_config): (PathBuf, PathBuf),
    dir: &Path,
    label: &str,
    commands: &mut Vec<String>,
) -> Result<RunReport, LoopError> {
    let record = dir.join("campaign.csv");
    let (summary, attempts) = stack_run(
        a,
        &daemon_config,
        &monitor_config,
        &plan.campaign,
        dir,
        &record,
        plan.timeout_s,
        &plan.name,
    )?;
    commands.push(sim_command_line(a, &plan.campaign, dir));
    all_rest_points(label, &summary, plan.wps.len(), dir)?;
    let (surrogate, fit) = surrogate.unzip();
    Ok(RunReport {
        platform: platform.to_path_buf(),
        surrogate,
        surrogate_max_offset_mm: fit.flatten().map(|r| r.max_abs_offset_mm),
        daemon_config,
        monitor_config,
        record,
        attempts,
        summary,
    })
}

/// Steps 1–2: the nominal platform's surrogate, then the campaign on the stack (before).
fn run_before(
    a: &LoopOptions,
    plan: &LoopPlan,
    tools: &mut dyn LoopTools,
    commands: &mut Vec<String>,
) -> Result<RunReport, LoopError> {
    let with_sg = plan.with_sg;
    step(
        1,
        if with_sg {
            "surrogate of the nominal platform"
        } else {
            "no surrogate (--no-surrogate)"
        },
    );
    let sg = plan.dir_b.join("surrogate.json");
    let fit = maybe_fit_surrogate(tools, with_sg, &a.platform, a, &sg, commands)?;
    let configs = write_run_configs(
        a,
        &plan.dir_b,
        &a.platform,
        with_sg.then_some(sg.as_path()),
        &plan.campaign,
    )?;
    step(2, "campaign on the stack with the nominal model (before)");
    campaign_run(
        a,
        plan,
        &a.platform,
        with_sg.then_some((sg, fit)),
        configs,
        &plan.dir_b,
        "before",
        commands,
    )
}

/// What step 3 identified: its report and the calibrated platform it wrote.
struct Identified {
    report: PipelineReport,
    calibrated: PathBuf,
    platform: Platform,
}

/// Step 3: identification from the nominal model on the recording of the run before.
fn identify(
    a: &LoopOptions,
    plan: &LoopPlan,
    tools: &mut dyn LoopTools,
    record: &Path,
    commands: &mut Vec<String>,
) -> Result<Identified, LoopError> {
    step(3, "identification from the nominal model on the recording");
    let holdout = a.holdout_every;
    let ds = crs_dataset::load_dataset(record)?;
    let obs =
        from_dataset(&ds, plan.nominal.model.m()).map_err(|source| LoopError::Observations {
            record: record.to_path_buf(),
            source,
        })?;
    let (train, held) = split(&obs, holdout);
    let cal_cmd = format!(
        "crs calibrate run --platform {} --data {} --holdout-every {holdout} --no-extension --ridge-kf {} --out {}",
        a.platform.display(),
        record.display(),
        a.ridge_kf,
        plan.dir_i.display()
    );
    let report: PipelineReport = tools.identify(
        &plan.nominal,
        &train,
        &held,
        &plan.dir_i,
        holdout,
        a.ridge_kf,
        &cal_cmd,
    )?;
    commands.push(cal_cmd);
    let calibrated = plan.dir_i.join("calibrated.toml");
    let platform = load_platform(&calibrated)?;
    Ok(Identified {
        report,
        calibrated,
        platform,
    })
}

/// Steps 4–6: the calibrated platform's surrogate, its daemon and monitor configs checked with
/// motion-core's own checks, then the same campaign on the stack (after).
fn run_after(
    a: &LoopOptions,
    plan: &LoopPlan,
    tools: &mut dyn LoopTools,
    id: &Identified,
    commands: &mut Vec<String>,
) -> Result<RunReport, LoopError> {
    let with_sg = plan.with_sg;
    step(
        4,
        if with_sg {
            "surrogate refitted on the calibrated platform"
        } else {
            "no surrogate (--no-surrogate)"
        },
    );
    let sg = plan.dir_a.join("surrogate.json");
    let fit = maybe_fit_surrogate(tools, with_sg, &id.calibrated, a, &sg, commands)?;
    step(
        5,
        "daemon and safety-monitor configuration for the calibrated model",
    );
    let (daemon, monitor) = write_run_configs(
        a,
        &plan.dir_a,
        &id.calibrated,
        with_sg.then_some(sg.as_path()),
        &plan.campaign,
    )?;
    lifecycle::configure_checks(&plan.daemon_tpl, &id.platform)?
        .verify_plan(&plan.wps)
        .map_err(|source| LoopError::CalibratedRefuses {
            calibrated: id.calibrated.clone(),
            source,
        })?;
    println!(
        "  {} (platform `{}`), {}",
        daemon.display(),
        id.platform.name,
        monitor.display()
    );
    step(6, "the same campaign with the calibrated model (after)");
    campaign_run(
        a,
        plan,
        &id.calibrated,
        with_sg.then_some((sg, fit)),
        (daemon, monitor),
        &plan.dir_a,
        "after",
        commands,
    )
}

/// The closed calibration loop (`crs calibrate loop`): the campaign on the stack with the
/// nominal model, identification on its recording, the same campaign with the calibrated model,
/// the report.
pub fn run_loop(a: LoopOptions, command: &str, tools: &mut dyn LoopTools) -> Result<(), LoopError> {
    let t_start = Instant::now();
    let plan = prepare_loop(&a)?;
    println!(
        "crs calibrate loop: {} poses of {}, rest {} s each (plan {:.0} s per run), plant {}, controller {}",
        plan.wps.len(),
        a.campaign.display(),
        a.dwell_s,
        plan.plan_s,
        a.plant.display(),
        if plan.with_sg {
            "kinematics + surrogate"
        } else {
            "kinematics only (--no-surrogate)"
        }
    );
    let mut commands = Vec::new();
    let before = run_before(&a, &plan, tools, &mut commands)?;
    let id = identify(&a, &plan, tools, &before.record, &mut commands)?;
    let after = run_after(&a, &plan, tools, &id, &mut commands)?;
    step(7, "report");
    let report = loop_report(&a, command, &plan, before, id, after, commands, t_start);
    write_report(&a, &report)
}

/// Step 7's report of the loop, the before/after ratios of the rest-point errors.
#[allow(clippy::too_many_arguments)]
fn loop_report(
    a: &LoopOptions,
    command: &str,
    plan: &LoopPlan,
    before: RunReport,
    id: Identified,
    after: RunReport,
    commands: Vec<String>,
    t_start: Instant,
) -> LoopReport {
    let ratio = |b: f64, a: f64| if a > 0.0 { b / a } else { f64::INFINITY };
    let (rb, ra) = (&before.summary.rest, &after.summary.rest);
    LoopReport {
        command: command.to_string(),
        plant: a.plant.clone(),
        campaign: a.campaign.clone(),
        poses: plan.wps.len(),
        dwell_s: a.dwell_s,
        settle_s: a.settle_s,
        control_model: if plan.with_sg {
            "kinematic+surrogate".into()
        } else {
            "kinematic".into()
        },
        improvement_position_mean: ratio(rb.position_mean_mm, ra.position_mean_mm),
        improvement_position_max: ratio(rb.position_max_mm, ra.position_max_mm),
        improvement_rotation_mean: ratio(rb.rotation_mean_deg, ra.rotation_mean_deg),
        before,
        identification: id
            .report
            .stages
            .iter()
            .map(|s| StageRow {
                name: s.name.clone(),
                holdout: s.holdout.clone(),
            })
            .collect(),
        identification_train: id.report.n_train,
        identification_holdout: id.report.n_holdout,
        deployed_stage: id.report.final_stage().name.clone(),
        calibrated_platform: id.calibrated,
        after,
        runtime_s: t_start.elapsed().as_secs_f64(),
        commands,
    }
}

/// report.md and report.json, the before/after table and the verdict against
/// `--min-improvement`.
fn write_report(a: &LoopOptions, report: &LoopReport) -> Result<(), LoopError> {
    let md = markdown(report);
    let md_file = a.out.join("report.md");
    std::fs::write(&md_file, &md).map_err(output(&md_file))?;
    let json_file = a.out.join("report.json");
    std::fs::write(&json_file, serde_json::to_string_pretty(report)?)
        .map_err(output(&json_file))?;
    println!("\n{}", before_after_table(report));
    println!(
        "measured mean position error {:.2} mm → {:.2} mm ({:.1}×) in {:.0} s; report {}",
        report.before.summary.rest.position_mean_mm,
        report.after.summary.rest.position_mean_mm,
        report.improvement_position_mean,
        report.runtime_s,
        a.out.join("report.md").display()
    );
    if let Some(f) = a.min_improvement
        && (report.improvement_position_mean.is_nan() || report.improvement_position_mean < f)
    {
        return Err(LoopError::NotImproved {
            improvement: report.improvement_position_mean,
            min: f,
        });
    }
    Ok(())
}

fn before_after_table(r: &LoopReport) -> String {
    let mut s = String::new();
    s.push_str("| at the rest points | before (nominal) | after (calibrated) |\n|---|---|---|\n");
    let (b, a) = (&r.before.summary, &r.after.summary);
    let row = |s: &mut String, name: &str, vb: String, va: String| {
        let _ = writeln!(s, "| {name} | {vb} | {va} |");
    };
    row(
        &mut s,
        "rest points",
        b.rest.rest_points.to_string(),
        a.rest.rest_points.to_string(),
    );
    row(
        &mut s,
        "measured position error mean / max (mm)",
        format!(
            "{:.2} / {:.2}",
            b.rest.position_mean_mm, b.rest.position_max_mm
        ),
        format!(
            "{:.2} / {:.2}",
            a.rest.position_mean_mm, a.rest.position_max_mm
        ),
    );
    row(
        &mut s,
        "measured rotation error mean / max (deg)",
        format!(
            "{:.3} / {:.3}",
            b.rest.rotation_mean_deg, b.rest.rotation_max_deg
        ),
        format!(
            "{:.3} / {:.3}",
            a.rest.rotation_mean_deg, a.rest.rotation_max_deg
        ),
    );
    row(
        &mut s,
        "true position error mean / max (mm, plant truth)",
        format!(
            "{:.2} / {:.2}",
            b.rest.true_position_mean_mm, b.rest.true_position_max_mm
        ),
        format!(
            "{:.2} / {:.2}",
            a.rest.true_position_mean_mm, a.rest.true_position_max_mm
        ),
    );
    let forces = |x: &Summary| {
        format!(
            "{:.0} … {:.0} ({})",
            x.force_min_n,
            x.force_max_n,
            if x.force_min_n >= x.f_min_n && x.force_max_n <= x.f_max_n {
                "within"
            } else {
                "OUTSIDE"
            }
        )
    };
    row(
        &mut s,
        &format!(
            "cable forces over the run (N; limits {:.0} … {:.0})",
            b.f_min_n, b.f_max_n
        ),
        forces(b),
        forces(a),
    );
    row(
        &mut s,
        "tracking error mean / max while moving (mm)",
        format!(
            "{:.2} / {:.2}",
            b.tracking_position_mean_mm, b.tracking_position_max_mm
        ),
        format!(
            "{:.2} / {:.2}",
            a.tracking_position_mean_mm, a.tracking_position_max_mm
        ),
    );
    row(
        &mut s,
        "e-stops / drive faults / refused references",
        format!("{} / {} / {}", b.estops, b.drive_faults, b.loop_rejected),
        format!("{} / {} / {}", a.estops, a.drive_faults, a.loop_rejected),
    );
    row(
        &mut s,
        "stack runs needed (bus stopped by host load otherwise)",
        r.before.attempts.to_string(),
        r.after.attempts.to_string(),
    );
    row(
        &mut s,
        "run time (s)",
        format!("{:.1}", b.duration_s),
        format!("{:.1}", a.duration_s),
    );
    s
}

fn markdown(r: &LoopReport) -> String {
    let mut s = String::new();
    s.push_str("# Closed calibration loop on the running stack\n\n");
    let _ = writeln!(s, "Command: `{}`\n", r.command);
    let _ = writeln!(
        s,
        "Plant `{}` (effects the model does not declare), campaign `{}` ({} poses, rest {} s each, readings taken after {} s settled: the last tracker pose and force-sensor readings before the reference moves). Controller: {}. The pose errors are MEASURED: the tracker's pose against the reference at every rest point; the plant's true pose is shown for comparison.\n",
        r.plant.display(),
        r.campaign.display(),
        r.poses,
        r.dwell_s,
        r.settle_s,
        r.control_model
    );
    s.push_str("## Before / after\n\n");
    s.push_str(&before_after_table(r));
    let _ = writeln!(
        s,
        "\nMeasured mean position error: {:.1}× smaller (max {:.1}×, mean rotation {:.1}×). Total run time {:.0} s.\n",
        r.improvement_position_mean,
        r.improvement_position_max,
        r.improvement_rotation_mean,
        r.runtime_s
    );
    s.push_str("## Identification (held-out figures, through the model's forward kinematics)\n\n");
    let _ = writeln!(
        s,
        "{} training and {} held-out rest points from the before run; deployed: **{}** → `{}`.\n",
        r.identification_train,
        r.identification_holdout,
        r.deployed_stage,
        r.calibrated_platform.display()
    );
    s.push_str("| step | mean / max position (mm) | mean / max rotation (deg) | mean cable length (mm) | mean / max force (N) |\n|---|---|---|---|---|\n");
    for st in &r.identification {
        let h = &st.holdout;
        let f = |v: Option<f64>| v.map_or("–".into(), |x| format!("{x:.1}"));
        let _ = writeln!(
            s,
            "| {} | {:.2} / {:.2} | {:.3} / {:.3} | {:.2} | {} / {} |",
            st.name,
            h.pos_mean_mm,
            h.pos_max_mm,
            h.rot_mean_deg,
            h.rot_max_deg,
            h.len_mean_mm,
            f(h.force_mean_n),
            f(h.force_max_n)
        );
    }
    s.push_str("\nThe identification's own report (condition numbers, parameters, plots) is in `identification/report.md`.\n\n## Deployed configuration\n\n");
    for (name, run) in [("before", &r.before), ("after", &r.after)] {
        let _ = writeln!(
            s,
            "* {name}: platform `{}`, surrogate {}, daemon `{}`, monitor `{}`, recording `{}`",
            run.platform.display(),
            match (&run.surrogate, run.surrogate_max_offset_mm) {
                (Some(p), Some(mx)) => format!("`{}` (max |φ_sg| {mx:.1} mm)", p.display()),
                (Some(p), None) => format!("`{}`", p.display()),
                _ => "none".into(),
            },
            run.daemon_config.display(),
            run.monitor_config.display(),
            run.record.display()
        );
    }
    s.push_str("\n## The same by hand\n\n```sh\n");
    for c in &r.commands {
        let _ = writeln!(s, "{c}");
    }
    s.push_str("```\n");
    s
}
