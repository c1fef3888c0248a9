//! `crs plant …`: the simulated plant (crates/sim-plant) from the command line — check a plant
//! TOML, record a measurement campaign into a data set, evaluate a data set's pose errors.

use crs_dataset::load_dataset;
use sim_plant::campaign::{ControlKind, pose_errors};
use sim_plant::{CampaignConfig, load_campaign, load_plant};
use std::path::PathBuf;

#[derive(clap::Subcommand, Debug)]
pub enum PlantCommand {
    /// Validate a plant TOML, list its effects and settle it at the home pose.
    Check {
        /// Plant TOML (config/plant/*.toml).
        plant: PathBuf,
    },
    /// Drive the plant through a measurement campaign and write a data set (CSV).
    Record(RecordArgs),
    /// Pose errors (eq. 3.3) of a data set's measured poses against its reference poses.
    Evaluate {
        /// Data set CSV.
        data: PathBuf,
    },
}

#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    /// Plant TOML (the ground truth).
    #[arg(long)]
    plant: PathBuf,
    /// Campaign TOML (default: 5x5x4 grid in x_min = [-1.5,-1.5,1.25], x_max = [1.5,1.5,2.0]).
    #[arg(long)]
    campaign: Option<PathBuf>,
    /// Control platform TOML (default: the campaign's, else the plant's nominal platform).
    #[arg(long)]
    control: Option<PathBuf>,
    /// Control model: kinematic (q = φ(x) + q_off) or elastostatic (q = φ_el(x, f_ref)).
    #[arg(long, value_parser = ["kinematic", "elastostatic"])]
    control_model: Option<String>,
    /// Tension test at every pose: shorten all cables by this many metres and return.
    #[arg(long)]
    tension_test_m: Option<f64>,
    /// Do not write force columns (no force sensors).
    #[arg(long)]
    no_forces: bool,
    /// Sensor-noise seed (default: the campaign's, else the plant's).
    #[arg(long)]
    seed: Option<u64>,
    /// Output CSV.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(cmd: PlantCommand) -> Result<(), Box<dyn std::error::Error>> {
    match cmd {
        PlantCommand::Check { plant } => {
            let c = plant_experiments::plant_check::check(&plant)?;
            print!("{c}");
            match c.failure() {
                Some(f) => Err(f.into()),
                None => Ok(()),
            }
        }
        PlantCommand::Record(a) => {
            let cfg = load_plant(&a.plant)?;
            let mut camp = match &a.campaign {
                Some(c) => load_campaign(c)?,
                None => CampaignConfig::default(),
            };
            if let Some(c) = a.control {
                camp.control_platform = Some(c);
            }
            if let Some(k) = a.control_model.as_deref() {
                camp.control = if k == "elastostatic" {
                    ControlKind::Elastostatic
                } else {
                    ControlKind::Kinematic
                };
            }
            if let Some(t) = a.tension_test_m {
                if !(t.is_finite() && t > 0.0 && t <= 0.2) {
                    return Err(format!("--tension-test-m must be in (0, 0.2] m, got {t}").into());
                }
                camp.tension_test = Some(t);
            }
            if a.no_forces {
                camp.force_columns = false;
            }
            if a.seed.is_some() {
                camp.seed = a.seed;
            }
            let rec = plant_experiments::plant_record::record(cfg, &camp, &a.out)?;
            eprint!("{rec}");
            if let Some(e) = pose_errors(&rec.result.dataset) {
                println!("{e}");
            }
            Ok(())
        }
        PlantCommand::Evaluate { data } => {
            let ds = load_dataset(&data)?;
            match pose_errors(&ds) {
                Some(e) => {
                    println!("{e}");
                    Ok(())
                }
                None => {
                    Err(format!("{}: no pose rows with reference columns", data.display()).into())
                }
            }
        }
    }
}
