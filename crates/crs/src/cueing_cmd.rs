//! `crs sim --source cueing --vehicle FILE.csv`: a vehicle's motion through the motion cueing
//! (classical washout with tilt coordination, crate `motion-cueing`) as the stack's motion
//! source (`sim_runs::cueing_run`), with what the rider perceives of it.

use sim_runs::cueing_run::CueingSpec;
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct CueingArgs {
    /// The vehicle of `--source cueing`: a CSV of specific force and angular velocity at the
    /// rider's head (columns t_s, f_x/y/z_m_per_s2, omega_x/y/z_rad_per_s; docs/motion-cueing.md),
    /// e.g. config/vehicle/braking.csv.
    #[arg(long)]
    pub(crate) vehicle: Option<PathBuf>,
    /// The cueing TOML of `--source cueing` (scaling, washout, tilt, workspace, perception).
    #[arg(long, default_value = "config/cueing.toml")]
    pub(crate) cueing_config: PathBuf,
}

/// Cueing flags that do not go together.
#[derive(Debug, thiserror::Error)]
pub(crate) enum CueingFlagError {
    #[error("--source cueing needs --vehicle FILE.csv (e.g. config/vehicle/braking.csv)")]
    NoVehicle,
    #[error("--vehicle needs --source cueing")]
    VehicleWithoutCueing,
}

impl CueingArgs {
    /// The cueing of the run for the chosen `--source`, checked for consistent flags.
    pub(crate) fn spec(&self, source: &str) -> Result<Option<CueingSpec>, CueingFlagError> {
        match (source, &self.vehicle) {
            ("cueing", Some(v)) => Ok(Some(CueingSpec {
                settings: self.cueing_config.clone(),
                vehicle: v.clone(),
            })),
            ("cueing", None) => Err(CueingFlagError::NoVehicle),
            (_, Some(_)) => Err(CueingFlagError::VehicleWithoutCueing),
            _ => Ok(None),
        }
    }
}
