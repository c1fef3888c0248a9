//! The reachable workspace of the kinematic controller measured on the simulated plant
//! (`crs model workspace --reachable --plant`): at each reference pose the kinematic controller
//! commands the home lengths plus the model's length change (eq. 3.24) and the plant — its own
//! cable laws and effects — says whether the forces stay within [f_min, f_max] (eq. 3.33), how
//! far from the reference it settles, and how far a 1 kN payload step moves it (the measured
//! side of the sensitivity map, eq. 2.76 / 3.23).

use cdpr_model::config::Platform;
use cdpr_model::{Data, Pose, kinematics};
use std::path::Path;

use cdpr_model::workspace::PositionBox;
use model_analysis::reachable::{self, PlantMeasurement, Prediction, ReachableReport};
/// What the plant did at one reference pose, and the payload step of the sensitivity map: the
/// analysis side (`model_analysis::reachable`) defines both, the plant fills them in here.
pub use model_analysis::reachable::{Measured, payload_step};
use nalgebra::Vector3;

/// Why the reachable workspace could not be predicted or measured.
#[derive(Debug, thiserror::Error)]
pub enum ReachableError {
    /// The plant TOML (names its file and key).
    #[error(transparent)]
    PlantConfig(#[from] cdpr_model::config::ConfigError),
    /// The plant's model with the payload step added.
    #[error(transparent)]
    PayloadModel(#[from] cdpr_model::ModelError),
    /// The plant refuses to start or to tension its cables at home.
    #[error(transparent)]
    Plant(#[from] sim_plant::PlantError),
    /// The controller's inverse kinematics at home.
    #[error(transparent)]
    Home(#[from] cdpr_model::kinematics::KinematicsError),
    /// The model's prediction.
    #[error(transparent)]
    Prediction(#[from] model_analysis::AnalysisError),
}

/// Measures `refs` on the plant `plant_path`; returns the measurements and, when the plant is
/// built on another platform file than the controller's `platform_path`, a note saying so.
pub fn measure_with_plant(
    plant_path: &Path,
    platform_path: &Path,
    pf: &Platform,
    refs: &[Pose],
    f_ini: &[f64],
) -> Result<(Vec<Measured>, Option<String>), ReachableError> {
    let cfg = sim_plant::load_plant(plant_path)?;
    let note = if let (Ok(a), Ok(b)) = (
        cfg.platform_path.canonicalize(),
        platform_path.canonicalize(),
    ) && a != b
    {
        Some(format!(
            "note: the plant {} is built on {}, the controller uses {}",
            plant_path.display(),
            cfg.platform_path.display(),
            platform_path.display()
        ))
    } else {
        None
    };
    let mut loaded_cfg = cfg.clone();
    loaded_cfg.platform.model = cfg
        .platform
        .model
        .with_params(|p| p.w_e += payload_step())?;
    let mut plant = sim_plant::Plant::new(cfg)?;
    let mut loaded = sim_plant::Plant::new(loaded_cfg)?;
    let home = pf.home;
    let setup = plant.setup_tension(&home, f_ini)?;
    loaded.setup_tension(&home, f_ini)?;
    let (s0, s1) = (plant.state(), loaded.state());
    let model = &pf.model;
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, &home)?;
    let q_home = data.q.clone();
    let lim = model.params();
    let mut out = Vec::with_capacity(refs.len());
    let mut cmd = vec![0.0; model.m()];
    for x in refs {
        // The kinematic controller: home command plus the model's length change (eq. 3.24).
        if kinematics::inverse(model, &mut data, x).is_err() {
            out.push(Measured::Failed);
            continue;
        }
        for i in 0..cmd.len() {
            cmd[i] = setup.q_cmd[i] + data.q[i] - q_home[i];
        }
        plant.restore(&s0);
        loaded.restore(&s1);
        let m = match (plant.step(&cmd), loaded.step(&cmd)) {
            (Ok(eq), Ok(eq1)) => {
                if eq.forces.iter().all(|f| *f >= lim.f_min && *f <= lim.f_max) {
                    Measured::Reachable {
                        error_m: (eq.pose.r - x.r).norm(),
                        dr_m: (eq1.pose.r - eq.pose.r).norm(),
                    }
                } else {
                    Measured::OutOfLimits
                }
            }
            _ => Measured::Failed,
        };
        out.push(m);
    }
    Ok((out, note))
}

/// [`measure_with_plant`] on the grid of `pred`, timed, as the analysis' plant side.
pub fn measure_prediction(
    plant_path: &Path,
    platform_path: &Path,
    pf: &Platform,
    pred: &Prediction,
) -> Result<(PlantMeasurement, Option<String>), ReachableError> {
    let t0 = std::time::Instant::now();
    let (measured, note) =
        measure_with_plant(plant_path, platform_path, pf, &pred.refs, &pred.f_ini)?;
    let m = PlantMeasurement {
        config: plant_path.display().to_string(),
        measured,
        seconds: t0.elapsed().as_secs_f64(),
    };
    Ok((m, note))
}

/// `crs model workspace --reachable`: the model's prediction of W_R on the `resolution`³ grid
/// of `bounds` at orientation `phi` (rad) and, with `plant`, the plant's measurement of it;
/// `platform_path` is the controller's platform file (a plant built on another one gets a note,
/// returned next to the report).
pub fn analyse(
    pf: &Platform,
    platform_path: &Path,
    bounds: PositionBox,
    phi: &Vector3<f64>,
    resolution: usize,
    plant: Option<&Path>,
) -> Result<(ReachableReport, Option<String>), ReachableError> {
    let pred = reachable::predict(pf, &bounds, phi, resolution)?;
    let (measured, note) = match plant {
        Some(p) => {
            let (m, note) = measure_prediction(p, platform_path, pf, &pred)?;
            (Some(m), note)
        }
        None => (None, None),
    };
    let r = ReachableReport::new(pf, bounds, resolution, pred, measured);
    Ok((r, note))
}
