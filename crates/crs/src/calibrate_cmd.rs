//! `crs calibrate …`: identification, residual diagnosis and model extension from measured
//! data sets (docs/data-format.md), with a Markdown/JSON/SVG report and the identified model
//! written back as a platform TOML (crates/calibrate, docs/calibration.md).

use crate::calibrate_report::{Opts, Spinner, calibrate_and_report};
use calibrate::{Observation, from_dataset, split};
use cdpr_model::config::load_platform;
use std::path::{Path, PathBuf};

#[derive(clap::Subcommand, Debug)]
pub enum CalibrateCommand {
    /// Calibrate a platform from a recorded data set (and optionally a validation data set).
    Run {
        /// Nominal platform TOML (the start model p_N).
        #[arg(long)]
        platform: PathBuf,
        /// Identification data set (CSV, docs/data-format.md).
        #[arg(long)]
        data: PathBuf,
        /// Validation data set; without it, every `--holdout-every`-th pose is held out.
        #[arg(long)]
        validate: Option<PathBuf>,
        #[command(flatten)]
        opts: Opts,
    },
    /// Record identification and validation campaigns on the simulated plant, then calibrate
    /// (the CRS-like scenario of docs/calibration.md).
    Demo {
        /// Plant TOML (config/plant/*.toml).
        #[arg(long, default_value = "config/plant/crs-like.toml")]
        plant: PathBuf,
        /// Campaign TOML for the identification data.
        #[arg(long, default_value = "config/plant/campaign-91.toml")]
        campaign: PathBuf,
        /// Seed offset of the validation campaign's random poses.
        #[arg(long, default_value_t = 1000)]
        validation_seed_offset: u64,
        #[command(flatten)]
        opts: Opts,
    },
    /// The closed loop on the running stack: record a campaign with the nominal model, identify,
    /// deploy the identified model and a refitted surrogate, re-run the campaign, report the
    /// measured pose error before and after.
    Loop(crate::calibrate_loop_cmd::LoopArgs),
    /// Make a calibration campaign: feasible waypoint poses spread over the workspace with
    /// varied orientations, the whole plan verified with motion-core's checks.
    Campaign(crate::calibrate_loop_cmd::CampaignArgs),
    /// Diagnosis benchmark: single-effect scenarios on the simulated plant (every catalogue
    /// effect plus a baseline, several seeds, randomised magnitudes); prints the confusion
    /// matrix, FK failures and held-out error against the true-effect model.
    BenchDiagnosis(crate::calibrate_bench::BenchArgs),
}

fn load(path: &Path, m: usize) -> Result<Vec<Observation>, Box<dyn std::error::Error>> {
    let ds = crs_dataset::load_dataset(path)?;
    Ok(from_dataset(&ds, m).map_err(|e| format!("{}: {e}", path.display()))?)
}

pub fn run(cmd: CalibrateCommand) -> Result<(), Box<dyn std::error::Error>> {
    let command: String = std::env::args().collect::<Vec<_>>().join(" ");
    match cmd {
        CalibrateCommand::Run {
            platform,
            data,
            validate,
            opts,
        } => {
            let base = load_platform(&platform)?;
            let m = base.model.m();
            let obs = load(&data, m)?;
            let (train, holdout) = match &validate {
                Some(v) => (obs, load(v, m)?),
                None => split(&obs, opts.holdout_every),
            };
            calibrate_and_report(&base, &train, &holdout, &opts, &command).map(|_| ())
        }
        CalibrateCommand::Demo {
            plant,
            campaign,
            validation_seed_offset,
            opts,
        } => {
            let demo = crs_stack::calibration_demo::record(
                &plant,
                &campaign,
                validation_seed_offset,
                &opts.out,
                &mut Spinner::default(),
            )?;
            let (base, m) = (&demo.base, demo.base.model.m());
            let train = from_dataset(&demo.identification, m)?;
            let holdout = from_dataset(&demo.validation, m)?;
            calibrate_and_report(base, &train, &holdout, &opts, &command).map(|_| ())
        }
        CalibrateCommand::Loop(a) => crate::calibrate_loop_cmd::run_loop(a, &command),
        CalibrateCommand::Campaign(a) => crate::calibrate_loop_cmd::run_campaign(a),
        CalibrateCommand::BenchDiagnosis(a) => crate::calibrate_bench::run(a),
    }
}
