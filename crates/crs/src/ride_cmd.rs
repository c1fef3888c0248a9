//! `crs sim --source helicopter`: the helicopter hover physics (eq. 5.21–5.22) as the stack's
//! motion source (`sim_runs::ride_run`), flown by a pilot CSV, a script or a game controller.

use sim_runs::ride_run::{PilotSpec, RideSpec};
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct RideArgs {
    /// What moves the cabin: `waypoints` (the demo trajectory, motion-core's planner),
    /// `helicopter` (the hover physics with elastic walls, eq. 5.21-5.22, on motion-core's
    /// cueing input; platform helicopter unless --platform says otherwise) or `cueing` (a
    /// vehicle's motion through the classical washout with tilt coordination, --vehicle;
    /// docs/motion-cueing.md).
    #[arg(long, default_value = "waypoints", value_parser = ["waypoints", "helicopter", "cueing"])]
    pub(crate) source: String,
    /// The pilot of `--source helicopter`: a pilot CSV (columns t_s,collective,roll,pitch,yaw;
    /// docs/ride-physics.md), `script:walls` / `script:corners` (full stick into every wall /
    /// corner), or `gamepad` (a game controller on /dev/input/js*).
    #[arg(long)]
    pub(crate) pilot: Option<String>,
    /// How long a `--pilot gamepad` flight lasts, s.
    #[arg(long, default_value_t = 60.0)]
    pub(crate) flight_s: f64,
    /// The ride TOML of `--source helicopter` (damping, controls, walls).
    #[arg(long, default_value = "config/ride-helicopter.toml")]
    pub(crate) ride_config: PathBuf,
}

/// Ride flags that do not go together.
#[derive(Debug, thiserror::Error)]
pub(crate) enum RideFlagError {
    #[error("--flight-s must be > 0")]
    FlightS(f64),
    #[error("--source helicopter needs --pilot FILE.csv | script:walls | script:corners | gamepad")]
    NoPilot,
    #[error("--pilot needs --source helicopter")]
    PilotWithoutRide,
}

impl RideArgs {
    /// The platform `--source helicopter` flies when `--platform` is not given.
    pub(crate) fn default_platform(&self) -> Option<String> {
        (self.source == "helicopter").then(|| "helicopter".to_string())
    }

    /// The ride of the run, checked for consistent flags.
    pub(crate) fn spec(&self) -> Result<Option<RideSpec>, RideFlagError> {
        match (self.source.as_str(), &self.pilot) {
            ("helicopter", Some(p)) => {
                if !(self.flight_s.is_finite() && self.flight_s > 0.0) {
                    return Err(RideFlagError::FlightS(self.flight_s));
                }
                Ok(Some(RideSpec {
                    settings: self.ride_config.clone(),
                    pilot: PilotSpec::parse(p, self.flight_s),
                }))
            }
            ("helicopter", None) => Err(RideFlagError::NoPilot),
            (_, Some(_)) => Err(RideFlagError::PilotWithoutRide),
            _ => Ok(None),
        }
    }
}
