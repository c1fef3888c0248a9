//! The seed's walking-subject experiment (sec. 5.3, Fig. 5.12–5.13) on the simulated plant:
//! the cabin is held at its set-up pose with constant commanded lengths, a subject walks a
//! path on the cabin floor, and the load tracker (`load_tracking::point_load`, eq. 5.9–5.10)
//! estimates where the subject stands from the force sensors alone, with the CONTROLLER's
//! geometry and at the pose the controller holds (it does not know where the elastic cabin
//! really is). The plant is `config/plant/icosahedron.toml`: assembly errors, hysteresis and
//! 10 N sensor noise, so the tracking error is what these effects leave — compared with the
//! seed's ±9.7 cm.
//!
//! Why off the hard loop and off the safety monitor: the estimate is a comfort/interaction
//! signal (who stands where), not a safety function; a wrong estimate must not stop a ride.
//! It runs in the operator tools (`crs load track`, `crs commission`), reading the forces the
//! drives report.

use cdpr_model::Data;
use cdpr_model::config::{Platform, load_platform};
use crs_limits::quantile::quantile_sorted;
use crs_plot::{Chart, Figure, Line, Markers, Panel, Rgb};
use load_tracking::G;
use load_tracking::point_load::{self, PointLoad};
use nalgebra::{Vector3, Vector6};
use sim_plant::config::Load;
use sim_plant::{Plant, load_plant};
use std::path::{Path, PathBuf};

/// Why the walk could not be run on the plant.
#[derive(Debug, thiserror::Error)]
pub enum WalkError {
    /// The plant TOML or the controller's platform TOML (names its file and key).
    #[error(transparent)]
    Config(#[from] cdpr_model::config::ConfigError),
    /// The plant refuses to start, to tension at home or to settle for the baseline.
    #[error(transparent)]
    Plant(#[from] sim_plant::PlantError),
    /// The load tracker's baseline (eq. 5.10) at the home pose.
    #[error(transparent)]
    Baseline(#[from] cdpr_model::kinematics::KinematicsError),
    /// Not one sample gave an estimate.
    #[error("no estimate in {samples} samples")]
    NoEstimate { samples: usize },
}

/// Why the walk's files could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WalkWriteError {
    /// Creating the output directory or writing `path`.
    #[error("{source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Serialising walk.json.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// Drawing or writing walk.svg.
    #[error(transparent)]
    Plot(#[from] crs_plot::PlotError),
}

/// What to run.
#[derive(Clone, Debug)]
pub struct WalkConfig {
    /// The plant (its nominal platform is the controller's model unless `control` is given).
    pub plant: PathBuf,
    /// The controller's platform TOML (default: the plant's nominal platform).
    pub control: Option<PathBuf>,
    /// Subject mass, kg (the seed: "around 80 kg").
    pub subject_kg: f64,
    /// Half-sizes of the rectangle walked on the floor (platform frame), m.
    pub half_x_m: f64,
    pub half_y_m: f64,
    /// Floor height in the platform frame, m (does not enter the estimate: eq. 5.9 sees xy).
    pub floor_z_m: f64,
    /// Walking speed, m/s, and the force sampling rate, Hz.
    pub speed_m_per_s: f64,
    pub rate_hz: f64,
    pub laps: usize,
    /// Force readings averaged for the unloaded baseline (eq. 5.10).
    pub baseline_readings: usize,
    pub seed: u64,
}

impl Default for WalkConfig {
    fn default() -> Self {
        WalkConfig {
            plant: PathBuf::from("config/plant/icosahedron.toml"),
            control: None,
            subject_kg: 80.0,
            half_x_m: 0.6,
            half_y_m: 0.5,
            floor_z_m: -0.75,
            speed_m_per_s: 0.5,
            rate_hz: 10.0,
            laps: 2,
            baseline_readings: 50,
            seed: 1,
        }
    }
}

/// One sample of the walk.
#[derive(Clone, Debug, serde::Serialize)]
pub struct WalkSample {
    pub t_s: f64,
    /// Where the subject is (platform frame xy), m.
    pub true_xy_m: [f64; 2],
    /// The estimate, or why there is none.
    pub estimate: Option<PointLoad>,
    pub failure: Option<String>,
}

/// The experiment's result.
#[derive(Clone, Debug, serde::Serialize)]
pub struct WalkResult {
    pub plant: String,
    pub subject_kg: f64,
    pub samples: Vec<WalkSample>,
    /// Tracking error |p̂ − p| over the samples with an estimate, m.
    pub error_mean_m: f64,
    pub error_p95_m: f64,
    pub error_max_m: f64,
    /// Share of estimates within the seed's ±9.7 cm (sec. 5.3).
    pub within_seed_share: f64,
    pub mass_mean_kg: f64,
    /// Mean 1σ the estimator states (from 10 N sensor noise through A^T).
    pub stated_std_mean_m: f64,
    pub failed: usize,
}

/// The seed's tracking accuracy (sec. 5.3), m.
pub const SEED_TRACKING_M: f64 = 0.097;

/// The summary `crs load track` prints: samples, tracking error against the seed's ±9.7 cm,
/// estimated mass and the estimator's stated 1σ.
impl std::fmt::Display for WalkResult {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "walking subject {:.0} kg on plant `{}`: {} samples, {} without an estimate",
            self.subject_kg,
            self.plant,
            self.samples.len(),
            self.failed
        )?;
        writeln!(
            f,
            "  tracking error: mean {:.1} cm, p95 {:.1} cm, max {:.1} cm; {:.0} % within the seed's ±{:.1} cm",
            self.error_mean_m * 100.0,
            self.error_p95_m * 100.0,
            self.error_max_m * 100.0,
            self.within_seed_share * 100.0,
            SEED_TRACKING_M * 100.0
        )?;
        writeln!(
            f,
            "  estimated mass mean {:.1} kg; stated 1σ (10 N sensor noise) {:.1} cm",
            self.mass_mean_kg,
            self.stated_std_mean_m * 100.0
        )
    }
}

/// Writes `walk.svg` ([`figure`]) and `walk.json` into `out`; returns their paths.
pub fn write(r: &WalkResult, out: &Path) -> Result<(PathBuf, PathBuf), WalkWriteError> {
    std::fs::create_dir_all(out).map_err(|source| WalkWriteError::Write {
        path: out.to_path_buf(),
        source,
    })?;
    let svg = out.join("walk.svg");
    figure(r).write(&svg)?;
    let json = out.join("walk.json");
    if let Err(source) = std::fs::write(&json, serde_json::to_string_pretty(r)?) {
        return Err(WalkWriteError::Write { path: json, source });
    }
    Ok((svg, json))
}

/// The walked rectangle: position at arc length s (platform frame xy).
fn path_at(c: &WalkConfig, s: f64) -> [f64; 2] {
    let (a, b) = (c.half_x_m, c.half_y_m);
    let per = 4.0 * (a + b);
    let mut s = s.rem_euclid(per);
    let legs = [
        ([-a, -b], [a, -b], 2.0 * a),
        ([a, -b], [a, b], 2.0 * b),
        ([a, b], [-a, b], 2.0 * a),
        ([-a, b], [-a, -b], 2.0 * b),
    ];
    for (p0, p1, len) in legs {
        if s <= len {
            let t = s / len;
            return [p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1])];
        }
        s -= len;
    }
    [-a, -b]
}

/// Runs the walk on the plant.
pub fn run(c: &WalkConfig) -> Result<WalkResult, WalkError> {
    let base_cfg = load_plant(&c.plant)?;
    let control: Platform = match &c.control {
        Some(p) => load_platform(p)?,
        None => base_cfg.platform.clone(),
    };
    // The set-up tension as the simulated stack sets it (sim-plant's bus face): the platform's
    // `[home] f_ini_n`, else f_m = (f_min + f_max)/2 in every cable, projected onto the
    // plant's equilibrium by `setup_tension` (eq. 3.19).
    let f_ini = control.f_ini.clone().unwrap_or_else(|| {
        let p = control.model.params();
        vec![0.5 * (p.f_min + p.f_max); control.model.m()]
    });
    let home = control.home;
    let mut plant = Plant::new(base_cfg.clone())?;
    plant.reseed(c.seed);
    let setup = plant.setup_tension(&home, &f_ini)?;
    let q_cmd = setup.q_cmd.clone();
    // The platform's own load as the plant has it (no load effect: the nominal wrench).
    let w_platform = plant.wrench_at(&home);
    let mut data = Data::new(&control.model);
    // Baseline (eq. 5.10): mean of readings before the subject steps on.
    let mut f_mean = vec![0.0; control.model.m()];
    for _ in 0..c.baseline_readings.max(1) {
        let eq = plant.step(&q_cmd)?;
        let r = plant.measure(&eq);
        for (m, f) in f_mean.iter_mut().zip(&r.forces) {
            *m += f / c.baseline_readings.max(1) as f64;
        }
    }
    let base = point_load::baseline(&control.model, &mut data, &home, &f_mean)?;
    let sigma_f = base_cfg
        .effects
        .force_sensors
        .as_ref()
        .map_or(0.0, |s| s.noise);
    let mut state = plant.state();
    let per = 4.0 * (c.half_x_m + c.half_y_m);
    let duration = per * c.laps as f64 / c.speed_m_per_s;
    let n = (duration * c.rate_hz).round() as usize;
    let mut samples = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64 / c.rate_hz;
        let xy = path_at(c, c.speed_m_per_s * t);
        // The subject's weight at (x, y, floor) of the (level) platform, in world axes.
        let at = home.rotation() * Vector3::new(xy[0], xy[1], c.floor_z_m);
        let fs = Vector3::new(0.0, 0.0, -c.subject_kg * G);
        let tau = at.cross(&fs);
        let mut cfg = base_cfg.clone();
        cfg.effects.load = Some(Load {
            mass: 0.0,
            center_of_gravity: Vector3::zeros(),
            extra_wrench: w_platform + Vector6::new(fs.x, fs.y, fs.z, tau.x, tau.y, tau.z),
            gravity: G,
        });
        cfg.seed = c.seed.wrapping_add(k as u64 + 1);
        let mut p = Plant::new(cfg)?;
        p.restore(&state);
        let sample = match p.step(&q_cmd) {
            Ok(eq) => {
                let r = p.measure(&eq);
                state = p.state();
                match point_load::estimate(
                    &control.model,
                    &mut data,
                    &base,
                    &r.forces,
                    sigma_f,
                    100.0,
                ) {
                    Ok(e) => WalkSample {
                        t_s: t,
                        true_xy_m: xy,
                        estimate: Some(e),
                        failure: None,
                    },
                    Err(e) => WalkSample {
                        t_s: t,
                        true_xy_m: xy,
                        estimate: None,
                        failure: Some(e.to_string()),
                    },
                }
            }
            Err(e) => WalkSample {
                t_s: t,
                true_xy_m: xy,
                estimate: None,
                failure: Some(format!("plant: {e}")),
            },
        };
        samples.push(sample);
    }
    walk_result(&base_cfg.name, c.subject_kg, samples)
}

/// The walk's statistics over its samples: the estimate's position error (mean, p95, max), the
/// share within the seed's tracking figure, the mean estimated mass and stated deviation.
fn walk_result(
    plant: &str,
    subject_kg: f64,
    samples: Vec<WalkSample>,
) -> Result<WalkResult, WalkError> {
    let mut errs: Vec<f64> = samples
        .iter()
        .filter_map(|s| {
            s.estimate.map(|e| {
                ((e.x_m - s.true_xy_m[0]).powi(2) + (e.y_m - s.true_xy_m[1]).powi(2)).sqrt()
            })
        })
        .collect();
    let failed = samples.len() - errs.len();
    if errs.is_empty() {
        return Err(WalkError::NoEstimate {
            samples: samples.len(),
        });
    }
    errs.sort_by(f64::total_cmp);
    let ne = errs.len() as f64;
    let est: Vec<&PointLoad> = samples.iter().filter_map(|s| s.estimate.as_ref()).collect();
    Ok(WalkResult {
        plant: plant.to_string(),
        subject_kg,
        error_mean_m: errs.iter().sum::<f64>() / ne,
        error_p95_m: quantile_sorted(&errs, 0.95).unwrap_or(f64::NAN),
        error_max_m: *errs.last().unwrap_or(&f64::NAN),
        within_seed_share: errs.iter().filter(|e| **e <= SEED_TRACKING_M).count() as f64 / ne,
        mass_mean_kg: est.iter().map(|e| e.mass_kg).sum::<f64>() / ne,
        stated_std_mean_m: est.iter().map(|e| e.x_std_m.hypot(e.y_std_m)).sum::<f64>() / ne,
        failed,
        samples,
    })
}

/// The walk as a figure: the walked path and the estimates (top view of the cabin floor).
pub fn figure(r: &WalkResult) -> Figure {
    let lim = r
        .samples
        .iter()
        .flat_map(|s| {
            let e = s.estimate.map_or([0.0, 0.0], |e| [e.x_m, e.y_m]);
            [
                s.true_xy_m[0].abs(),
                s.true_xy_m[1].abs(),
                e[0].abs(),
                e[1].abs(),
            ]
        })
        .fold(0.2f64, f64::max)
        * 1.15;
    let mut c = Chart::new(
        format!(
            "walking subject {:.0} kg on `{}`: mean {:.1} cm, p95 {:.1} cm (seed ±9.7 cm)",
            r.subject_kg,
            r.plant,
            r.error_mean_m * 100.0,
            r.error_p95_m * 100.0
        ),
        "x on the cabin floor (m)",
        "y (m)",
    );
    c.x_range = Some((-lim, lim));
    c.y_range = Some((-lim, lim));
    let mut walked = Line::new(
        "walked path (plant truth)",
        Rgb::GREEN,
        r.samples
            .iter()
            .map(|s| (s.true_xy_m[0], s.true_xy_m[1]))
            .collect(),
    );
    walked.width = 3;
    c.lines.push(walked);
    let mut est = Markers::new(
        "estimate from the cable forces (eq. 5.9)",
        Rgb::RED,
        r.samples
            .iter()
            .filter_map(|s| s.estimate)
            .map(|e| (e.x_m, e.y_m))
            .collect(),
    );
    est.radius = 2;
    c.markers.push(est);
    Figure::single("", (720, 600), Panel::Chart(c))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> WalkConfig {
        WalkConfig {
            plant: PathBuf::from(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../../config/plant/icosahedron.toml"
            )),
            laps: 1,
            rate_hz: 4.0,
            ..WalkConfig::default()
        }
    }

    /// On the mild plant the tracker follows the subject within the seed's accuracy on most
    /// samples and states an uncertainty of the right order; the path is the rectangle.
    #[test]
    fn the_walk_is_tracked_about_as_well_as_the_seed_reports() {
        let c = cfg();
        assert_eq!(path_at(&c, 0.0), [-0.6, -0.5]);
        assert_eq!(path_at(&c, 1.2), [0.6, -0.5]);
        let r = run(&c).expect("walk");
        assert_eq!(
            r.failed,
            0,
            "{:?}",
            r.samples.iter().find(|s| s.failure.is_some())
        );
        assert!(
            (r.mass_mean_kg - 80.0).abs() < 5.0,
            "mass {}",
            r.mass_mean_kg
        );
        assert!(
            r.error_mean_m < SEED_TRACKING_M,
            "mean {} m",
            r.error_mean_m
        );
        assert!(r.stated_std_mean_m > 0.001 && r.stated_std_mean_m < 0.2);
    }

    /// A heavier subject is tracked better (the torque grows with the weight, the noise does
    /// not): the estimator is reading the subject, not returning the path.
    #[test]
    fn more_weight_tracks_better() {
        let light = run(&WalkConfig {
            subject_kg: 20.0,
            ..cfg()
        })
        .unwrap();
        let heavy = run(&WalkConfig {
            subject_kg: 200.0,
            ..cfg()
        })
        .unwrap();
        assert!(
            heavy.error_mean_m < light.error_mean_m,
            "{} vs {}",
            heavy.error_mean_m,
            light.error_mean_m
        );
    }
}
