//! `crs plant record`: a measurement campaign driven on the simulated plant and written as a
//! data set (docs/data-format.md), with what could not be reached.

use cdpr_model::config::{ConfigError, load_platform};
use sim_plant::campaign::{CampaignError, CampaignResult};
use sim_plant::{CampaignConfig, Plant, PlantConfig, PlantError, run_campaign};
use std::fmt;
use std::path::{Path, PathBuf};

/// Why a campaign could not be recorded.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Plant(#[from] PlantError),
    #[error(transparent)]
    Campaign(#[from] CampaignError),
    /// The data set could not be written.
    #[error("{}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// A recorded campaign and where it went.
pub struct Recorded {
    pub result: CampaignResult,
    pub out: PathBuf,
    /// Time of the campaign, s.
    pub seconds: f64,
}

/// Drives the plant `cfg` through `camp` with its control platform (the campaign's, else the
/// plant's nominal) and writes the data set to `out`.
pub fn record(
    cfg: PlantConfig,
    camp: &CampaignConfig,
    out: &Path,
) -> Result<Recorded, RecordError> {
    let control_path = camp
        .control_platform
        .clone()
        .unwrap_or_else(|| cfg.platform_path.clone());
    let control = load_platform(&control_path)?;
    let mut p = Plant::new(cfg)?;
    let t0 = std::time::Instant::now();
    let result = run_campaign(&mut p, &control, camp, &control_path.display().to_string())?;
    let seconds = t0.elapsed().as_secs_f64();
    crs_dataset::save_dataset(out, &result.dataset).map_err(|source| RecordError::Write {
        path: out.to_path_buf(),
        source,
    })?;
    Ok(Recorded {
        result,
        out: out.to_path_buf(),
        seconds,
    })
}

/// The log of a recording (`crs plant record` prints it on stderr): samples written and every
/// unreachable pose with its reason.
impl fmt::Display for Recorded {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let r = &self.result;
        writeln!(
            f,
            "wrote {} samples to {} ({} unreachable) in {:.1} ms",
            r.dataset.samples.len(),
            self.out.display(),
            r.unreachable.len(),
            self.seconds * 1e3
        )?;
        for u in &r.unreachable {
            let x = u.pose_ref.to_array();
            writeln!(
                f,
                "  unreachable pose {} phase {} at [{:.3}, {:.3}, {:.3}] m: {}",
                u.pose_index, u.phase as u8, x[0], x[1], x[2], u.reason
            )?;
        }
        Ok(())
    }
}
