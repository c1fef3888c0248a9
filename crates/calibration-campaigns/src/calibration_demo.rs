//! The CRS-like calibration scenario of docs/calibration.md (`crs calibrate demo`): an
//! identification and a validation campaign recorded on the simulated plant with the nominal
//! model, saved as data sets next to the report.

use calibrate::Observation;
use cdpr_model::config::{ConfigError, Platform};
use sim_plant::campaign::CampaignError;
use sim_plant::{Plant, PlantError, PoseSet};
use std::path::Path;

/// Why the demo data could not be recorded.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Plant(#[from] PlantError),
    #[error(transparent)]
    Campaign(#[from] CampaignError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    Observations(#[from] calibrate::observation::ObservationError),
}

/// The two campaigns' observations and the platform they were recorded with (the plant's
/// nominal).
pub struct DemoData {
    pub base: Platform,
    pub identification: Vec<Observation>,
    pub validation: Vec<Observation>,
}

/// Records the campaign `campaign` on the plant `plant` (identification), and again with its
/// random poses and noise seeded `validation_seed_offset` further on (validation); writes
/// identification.csv and validation.csv into `out` and returns their observations. `progress` shows which campaign runs.
pub fn record(
    plant: &Path,
    campaign: &Path,
    validation_seed_offset: u64,
    out: &Path,
    progress: &mut dyn crate::progress::Progress,
) -> Result<DemoData, DemoError> {
    let pcfg = sim_plant::load_plant(plant)?;
    let camp = sim_plant::load_campaign(campaign)?;
    let base = pcfg.platform.clone();
    progress.start("recording identification campaign");
    let mut p = Plant::new(pcfg.clone())?;
    let identification = sim_plant::run_campaign(&mut p, &base, &camp, "nominal")?.dataset;
    let mut vcamp = camp.clone();
    if let PoseSet::Random { seed, .. } = &mut vcamp.poses {
        *seed += validation_seed_offset;
    }
    vcamp.seed = Some(camp.seed.unwrap_or(pcfg.seed) + validation_seed_offset);
    progress.update("recording validation campaign".into());
    let mut p = Plant::new(pcfg)?;
    let validation = sim_plant::run_campaign(&mut p, &base, &vcamp, "nominal")?.dataset;
    progress.finish();
    std::fs::create_dir_all(out)?;
    crs_dataset::save_dataset(out.join("identification.csv"), &identification)?;
    crs_dataset::save_dataset(out.join("validation.csv"), &validation)?;
    let m = base.model.m();
    Ok(DemoData {
        identification: calibrate::from_dataset(&identification, m)?,
        validation: calibrate::from_dataset(&validation, m)?,
        base,
    })
}
