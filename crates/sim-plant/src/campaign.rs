//! Measurement campaigns (ch. 6.1, 6.4): drive the plant through reference poses with a
//! control model, record what the sensors read. The initial tension is set from f_ini at the
//! home pose via cable offsets (eq. 3.14, 6.24); poses whose forces leave [f_min, f_max] are
//! bookkept as unreachable and not sampled (eq. 3.33); optional tension tests shorten all
//! cables and return (Fig. 6.15).

use crate::config::{Locator, pose_deg};
use crate::plant::{Plant, PlantError};
use cdpr_model::config::{ConfigError, Platform};
use cdpr_model::{Data, Pose, elastostatics, kinematics, statics};
use crs_dataset::{Dataset, Phase, Sample};
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// How the controller turns a reference pose into commanded lengths.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControlKind {
    /// q_cmd = φ(x_ref) + q_off (standard/pulley kinematics of the control platform; offsets
    /// from eq. 3.14 computed on the plant at the home pose).
    Kinematic,
    /// q_cmd = φ_el(x_ref, f_ref) (eq. 2.37) with f_ref from the force distribution eq. 3.41.
    Elastostatic,
}

impl ControlKind {
    pub fn name(&self) -> &'static str {
        match self {
            ControlKind::Kinematic => "kinematic",
            ControlKind::Elastostatic => "elastostatic",
        }
    }
}

/// Where the reference poses come from.
#[derive(Clone, Debug, PartialEq)]
pub enum PoseSet {
    /// Grid with `points` per axis in the box, visited in serpentine order; the rotation list
    /// (rad) is cycled over the grid points.
    Grid {
        min: Vector3<f64>,
        max: Vector3<f64>,
        points: [usize; 3],
        rotations: Vec<Vector3<f64>>,
    },
    /// `count` uniform random poses in the box, rotations uniform in ±`rotation_max` (rad).
    Random {
        min: Vector3<f64>,
        max: Vector3<f64>,
        count: usize,
        rotation_max: Vector3<f64>,
        seed: u64,
    },
}

impl PoseSet {
    /// The reference poses in visiting order.
    pub fn poses(&self) -> Vec<Pose> {
        match self {
            PoseSet::Grid {
                min,
                max,
                points,
                rotations,
            } => {
                let lin = |k: usize, j: usize| {
                    if points[k] <= 1 {
                        0.5 * (min[k] + max[k])
                    } else {
                        min[k] + (max[k] - min[k]) * j as f64 / (points[k] - 1) as f64
                    }
                };
                let mut out = Vec::new();
                for iz in 0..points[2] {
                    for iy0 in 0..points[1] {
                        let iy = if iz % 2 == 0 {
                            iy0
                        } else {
                            points[1] - 1 - iy0
                        };
                        for ix0 in 0..points[0] {
                            let row = iz * points[1] + iy0;
                            let ix = if row % 2 == 0 {
                                ix0
                            } else {
                                points[0] - 1 - ix0
                            };
                            let rot = if rotations.is_empty() {
                                Vector3::zeros()
                            } else {
                                rotations[out.len() % rotations.len()]
                            };
                            out.push(Pose::new(
                                Vector3::new(lin(0, ix), lin(1, iy), lin(2, iz)),
                                rot,
                            ));
                        }
                    }
                }
                out
            }
            PoseSet::Random {
                min,
                max,
                count,
                rotation_max,
                seed,
            } => {
                let mut rng = StdRng::seed_from_u64(*seed);
                (0..*count)
                    .map(|_| {
                        let r = Vector3::from_fn(|k, _| {
                            min[k] + (max[k] - min[k]) * rng.random::<f64>()
                        });
                        let p = Vector3::from_fn(|k, _| {
                            rotation_max[k] * (2.0 * rng.random::<f64>() - 1.0)
                        });
                        Pose::new(r, p)
                    })
                    .collect()
            }
        }
    }
}

/// A parsed campaign.
#[derive(Clone, Debug, PartialEq)]
pub struct CampaignConfig {
    pub name: String,
    pub control: ControlKind,
    /// Control platform TOML (`None`: the plant's own nominal platform).
    pub control_platform: Option<PathBuf>,
    pub poses: PoseSet,
    /// Tension test shortening, m (`None`: no tension tests).
    pub tension_test: Option<f64>,
    /// Write force columns.
    pub force_columns: bool,
    /// Seed of the sensor noise (`None`: the plant's seed).
    pub seed: Option<u64>,
}

impl Default for CampaignConfig {
    /// The experiments' campaign (sec. 6.1): box x_min = [−1.5, −1.5, 1.25],
    /// x_max = [1.5, 1.5, 2.0], 5 × 5 × 4 grid with ±5° rotations cycled, kinematic control.
    fn default() -> Self {
        Self {
            name: "default".into(),
            control: ControlKind::Kinematic,
            control_platform: None,
            poses: PoseSet::Grid {
                min: Vector3::new(-1.5, -1.5, 1.25),
                max: Vector3::new(1.5, 1.5, 2.0),
                points: [5, 5, 4],
                rotations: default_rotations(),
            },
            tension_test: None,
            force_columns: true,
            seed: None,
        }
    }
}

fn default_rotations() -> Vec<Vector3<f64>> {
    let d = 5f64.to_radians();
    vec![
        Vector3::zeros(),
        Vector3::new(d, 0.0, 0.0),
        Vector3::new(0.0, d, 0.0),
        Vector3::new(0.0, 0.0, d),
        Vector3::new(-d, 0.0, 0.0),
        Vector3::new(0.0, -d, 0.0),
        Vector3::new(0.0, 0.0, -d),
    ]
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCampaign {
    campaign: RawMeta,
    poses: Option<RawPoses>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMeta {
    name: String,
    control_model: Option<Spanned<String>>,
    control_platform: Option<String>,
    tension_test_shortening_m: Option<Spanned<f64>>,
    force_columns: Option<bool>,
    seed: Option<u64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPoses {
    kind: Spanned<String>,
    position_min_m: Option<Spanned<[f64; 3]>>,
    position_max_m: Option<Spanned<[f64; 3]>>,
    points: Option<Spanned<[i64; 3]>>,
    rotations_deg: Option<Spanned<Vec<[f64; 3]>>>,
    count: Option<Spanned<i64>>,
    rotation_max_deg: Option<Spanned<[f64; 3]>>,
    seed: Option<u64>,
}

/// Reads a campaign TOML; `campaign.control_platform` is relative to the file.
pub fn load_campaign(path: impl AsRef<Path>) -> Result<CampaignConfig, ConfigError> {
    let path = path.as_ref();
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
        file: file.clone(),
        line: None,
        column: None,
        key: String::new(),
        message: format!("cannot read: {e}"),
    })?;
    parse_campaign(&text, &file, path.parent().unwrap_or(Path::new(".")))
}

/// Parses campaign TOML text.
pub fn parse_campaign(
    text: &str,
    file: &str,
    base_dir: &Path,
) -> Result<CampaignConfig, ConfigError> {
    let loc = Locator { text, file };
    let raw: RawCampaign = toml::from_str(text).map_err(|e| loc.toml_err(e))?;
    let mut c = CampaignConfig {
        name: raw.campaign.name.clone(),
        ..CampaignConfig::default()
    };
    if let Some(k) = &raw.campaign.control_model {
        c.control = match k.get_ref().as_str() {
            "kinematic" => ControlKind::Kinematic,
            "elastostatic" => ControlKind::Elastostatic,
            other => {
                return Err(loc.err(
                    k.span(),
                    "campaign.control_model",
                    format!("must be \"kinematic\" or \"elastostatic\", got \"{other}\""),
                ));
            }
        };
    }
    c.control_platform = raw
        .campaign
        .control_platform
        .as_ref()
        .map(|p| base_dir.join(p));
    if let Some(s) = &raw.campaign.tension_test_shortening_m {
        c.tension_test =
            Some(loc.scalar(s, "campaign.tension_test_shortening_m", 0.0, 0.2, true)?);
    }
    if let Some(f) = raw.campaign.force_columns {
        c.force_columns = f;
    }
    c.seed = raw.campaign.seed;
    if let Some(p) = &raw.poses {
        c.poses = poses(&loc, p)?;
    }
    Ok(c)
}

/// An optional 3-vector of the `[poses]` table (degrees converted when `deg`).
fn vec3_or(
    loc: &Locator,
    v: &Option<Spanned<[f64; 3]>>,
    key: &str,
    dflt: Vector3<f64>,
    deg: bool,
) -> Result<Vector3<f64>, ConfigError> {
    match v {
        None => Ok(dflt),
        Some(s) => {
            let a = s.get_ref();
            if !a.iter().all(|x| x.is_finite()) {
                return Err(loc.err(s.span(), key, "must be finite"));
            }
            let k = if deg {
                std::f64::consts::PI / 180.0
            } else {
                1.0
            };
            Ok(Vector3::new(a[0] * k, a[1] * k, a[2] * k))
        }
    }
}

/// The `[poses]` table: a grid or random poses in the position box.
fn poses(loc: &Locator, p: &RawPoses) -> Result<PoseSet, ConfigError> {
    let min = vec3_or(
        loc,
        &p.position_min_m,
        "poses.position_min_m",
        Vector3::new(-1.5, -1.5, 1.25),
        false,
    )?;
    let max = vec3_or(
        loc,
        &p.position_max_m,
        "poses.position_max_m",
        Vector3::new(1.5, 1.5, 2.0),
        false,
    )?;
    if (0..3).any(|k| min[k] > max[k]) {
        let span = p
            .position_max_m
            .as_ref()
            .or(p.position_min_m.as_ref())
            .map(|s| s.span())
            .unwrap_or(0..0);
        return Err(loc.err(
            span,
            "poses.position_max_m",
            "must be >= position_min_m per axis",
        ));
    }
    match p.kind.get_ref().as_str() {
        "grid" => grid(loc, p, min, max),
        "random" => random(loc, p, min, max),
        other => Err(loc.err(
            p.kind.span(),
            "poses.kind",
            format!("must be \"grid\" or \"random\", got \"{other}\""),
        )),
    }
}

fn grid(
    loc: &Locator,
    p: &RawPoses,
    min: Vector3<f64>,
    max: Vector3<f64>,
) -> Result<PoseSet, ConfigError> {
    let points = match &p.points {
        None => [5, 5, 4],
        Some(s) => {
            let a = s.get_ref();
            if a.iter().any(|n| *n < 1 || *n > 1000) {
                return Err(loc.err(s.span(), "poses.points", "each entry must be in 1..=1000"));
            }
            [a[0] as usize, a[1] as usize, a[2] as usize]
        }
    };
    let rotations = match &p.rotations_deg {
        None => default_rotations(),
        Some(s) => {
            if s.get_ref()
                .iter()
                .flatten()
                .any(|x| !x.is_finite() || x.abs() > 90.0)
            {
                return Err(loc.err(
                    s.span(),
                    "poses.rotations_deg",
                    "angles must be finite and within ±90°",
                ));
            }
            s.get_ref()
                .iter()
                .map(|r| pose_deg([0.0; 3], *r).phi)
                .collect()
        }
    };
    Ok(PoseSet::Grid {
        min,
        max,
        points,
        rotations,
    })
}

fn random(
    loc: &Locator,
    p: &RawPoses,
    min: Vector3<f64>,
    max: Vector3<f64>,
) -> Result<PoseSet, ConfigError> {
    let count = match &p.count {
        None => 91,
        Some(s) => {
            if *s.get_ref() < 1 || *s.get_ref() > 1_000_000 {
                return Err(loc.err(s.span(), "poses.count", "must be in 1..=1000000"));
            }
            *s.get_ref() as usize
        }
    };
    let rotation_max = vec3_or(
        loc,
        &p.rotation_max_deg,
        "poses.rotation_max_deg",
        Vector3::new(5.0, 5.0, 5.0),
        true,
    )?;
    Ok(PoseSet::Random {
        min,
        max,
        count,
        rotation_max,
        seed: p.seed.unwrap_or(0),
    })
}

/// A reference pose (or tension-test step) that was not sampled, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Unreachable {
    pub pose_index: usize,
    pub phase: Phase,
    pub pose_ref: Pose,
    pub reason: SkipReason,
}

/// Why a campaign step was skipped (recorded in the data set's `# unreachable:` lines).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SkipReason {
    /// The control model has no inverse kinematics / elastostatics at the reference pose.
    #[error("control model: {0}")]
    ControlModel(#[source] cdpr_model::kinematics::KinematicsError),
    /// The control model's force distribution (eq. 3.41) failed.
    #[error("control model force distribution: {0}")]
    ForceDistribution(#[source] cdpr_model::statics::StaticsError),
    /// The control model's force distribution (eq. 3.41) is infeasible (cables 1-based).
    #[error(
        "control model force distribution (eq. 3.41) infeasible: cable {cable_lo} at {f_lo:.1} N, cable {cable_hi} at {f_hi:.1} N"
    )]
    Infeasible {
        cable_lo: usize,
        f_lo: f64,
        cable_hi: usize,
        f_hi: f64,
    },
    /// The plant found no equilibrium for the command.
    #[error("plant: {0}")]
    Plant(#[source] crate::plant::PlantError),
    /// A true cable force below the limit (eq. 3.29, 3.33); cable 1-based.
    #[error("force limits: cable {cable} carries {force_n:.1} N < {limit_n} N")]
    BelowLimit {
        cable: usize,
        force_n: f64,
        limit_n: f64,
    },
    /// A true cable force above the limit; cable 1-based.
    #[error("force limits: cable {cable} carries {force_n:.1} N > {limit_n} N")]
    AboveLimit {
        cable: usize,
        force_n: f64,
        limit_n: f64,
    },
}

/// Result of a campaign.
#[derive(Clone, Debug, PartialEq)]
pub struct CampaignResult {
    pub dataset: Dataset,
    pub unreachable: Vec<Unreachable>,
    /// Cable offsets q_off = φ̂_el(x_ini) − φ(x_ini) (eq. 3.14, 6.24), m (kinematic control).
    pub q_off: Vec<f64>,
}

/// Why a campaign could not run at all.
#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    #[error("control platform has {control} cables but the plant has {plant}")]
    CableCount { control: usize, plant: usize },
    #[error(
        "control platform has no f_ini (home.f_ini_n) to set the initial tension from (eq. 6.22)"
    )]
    NoInitialTension,
    #[error("setting the initial tension at the home pose failed: {0}")]
    Setup(PlantError),
    #[error("control model cannot compute the home pose: {0}")]
    ControlHome(String),
}

/// Runs a campaign on `plant` with the control model of `control`. `platform_label` and
/// `plant_label` are written into the metadata (never the plant's effect settings).
pub fn run_campaign(
    plant: &mut Plant,
    control: &Platform,
    campaign: &CampaignConfig,
    platform_label: &str,
) -> Result<CampaignResult, CampaignError> {
    let m = plant.m();
    if control.model.m() != m {
        return Err(CampaignError::CableCount {
            control: control.model.m(),
            plant: m,
        });
    }
    let seed = campaign.seed.unwrap_or(plant.config().seed);
    plant.reseed(seed);
    let model = &control.model;
    let mut data = Data::new(model);
    let p = model.params();
    let q_off = match campaign.control {
        ControlKind::Kinematic => kinematic_offsets(plant, control, &mut data)?,
        ControlKind::Elastostatic => vec![0.0; m],
    };
    let mut ds = Dataset::new(m, campaign.force_columns, true);
    ds.metadata = header_metadata(control, campaign, platform_label, seed, &q_off);
    let mut unreachable = Vec::new();
    let mut q_cmd = vec![0.0; m];
    let mut f_ref = vec![0.0; m];
    let mut sample = 0u64;
    for (k, x_ref) in campaign.poses.poses().iter().enumerate() {
        let mut skip = |phase, reason: SkipReason| {
            unreachable.push(Unreachable {
                pose_index: k,
                phase,
                pose_ref: *x_ref,
                reason,
            })
        };
        // Command from the control model.
        let cmd = match campaign.control {
            ControlKind::Kinematic => kinematics::inverse(model, &mut data, x_ref)
                .map(|_| {
                    for i in 0..m {
                        q_cmd[i] = data.q[i] + q_off[i];
                    }
                })
                .map_err(SkipReason::ControlModel),
            ControlKind::Elastostatic => {
                command_elastostatic(control, &mut data, x_ref, &mut f_ref, &mut q_cmd)
            }
        };
        if let Err(reason) = cmd {
            skip(Phase::Pose, reason);
            continue;
        }
        let before = plant.state();
        let eq = match visit(plant, &q_cmd, p.f_min, p.f_max) {
            Ok(eq) => eq,
            Err(reason) => {
                plant.restore(&before);
                skip(Phase::Pose, reason);
                continue;
            }
        };
        let mut record = |plant: &mut Plant, eq: &crate::plant::Equilibrium, phase, q: &[f64]| {
            let r = plant.measure(eq);
            ds.samples.push(Sample {
                sample,
                pose_index: k as u64,
                phase,
                q_cmd: q.to_vec(),
                pose: r.pose,
                forces: campaign.force_columns.then_some(r.forces),
                pose_ref: Some(*x_ref),
            });
            sample += 1;
        };
        record(plant, &eq, Phase::Pose, &q_cmd);
        if let Some(short) = campaign.tension_test {
            let q_t: Vec<f64> = q_cmd.iter().map(|q| q - short).collect();
            let at_pose = plant.state();
            // A tension test may exceed the operating limit but never the absolute limit.
            match visit(plant, &q_t, p.f_min, control.f_abs_max) {
                Ok(eq_t) => {
                    record(plant, &eq_t, Phase::Tensioned, &q_t);
                    match visit(plant, &q_cmd, p.f_min, p.f_max) {
                        Ok(eq_r) => record(plant, &eq_r, Phase::Returned, &q_cmd),
                        Err(reason) => {
                            plant.restore(&at_pose);
                            skip(Phase::Returned, reason);
                        }
                    }
                }
                Err(reason) => {
                    plant.restore(&at_pose);
                    skip(Phase::Tensioned, reason);
                }
            }
        }
    }
    ds.metadata.extend(unreachable.iter().map(unreachable_line));
    Ok(CampaignResult {
        dataset: ds,
        unreachable,
        q_off,
    })
}

/// eq. (3.14) / (6.24): q_off = φ̂_el(x_ini, f_ini) − φ(x_ini), the left term on the plant;
/// the plant is left settled at home with that command, so the run starts from the set-up state.
fn kinematic_offsets(
    plant: &mut Plant,
    control: &Platform,
    data: &mut Data,
) -> Result<Vec<f64>, CampaignError> {
    let f_ini = control
        .f_ini
        .as_ref()
        .ok_or(CampaignError::NoInitialTension)?;
    let setup = plant
        .setup_tension(&control.home, f_ini)
        .map_err(CampaignError::Setup)?;
    kinematics::inverse(&control.model, data, &control.home)
        .map_err(|e| CampaignError::ControlHome(e.to_string()))?;
    let q_off = setup
        .q_cmd
        .iter()
        .zip(&data.q)
        .map(|(c, q)| c - q)
        .collect();
    plant.step(&setup.q_cmd).map_err(CampaignError::Setup)?;
    Ok(q_off)
}

/// The data set's metadata lines before the samples (docs/data-format.md).
fn header_metadata(
    control: &Platform,
    campaign: &CampaignConfig,
    platform_label: &str,
    seed: u64,
    q_off: &[f64],
) -> Vec<(String, String)> {
    let p = control.model.params();
    let mut md = vec![
        (
            "platform".into(),
            format!("{} ({platform_label})", control.name),
        ),
        ("control_model".into(), campaign.control.name().into()),
        ("campaign".into(), campaign.name.clone()),
        ("seed".into(), seed.to_string()),
        ("force_limits_n".into(), format!("{} {}", p.f_min, p.f_max)),
    ];
    if let Some(s) = campaign.tension_test {
        md.push(("tension_test_shortening_m".into(), s.to_string()));
    }
    if campaign.control == ControlKind::Kinematic {
        let off: Vec<String> = q_off.iter().map(|v| v.to_string()).collect();
        md.push(("q_off_m".into(), off.join(" ")));
    }
    md
}

/// An `unreachable` metadata line.
fn unreachable_line(u: &Unreachable) -> (String, String) {
    let x = u.pose_ref.to_array();
    (
        "unreachable".into(),
        format!(
            "pose_index {} phase {} x_ref [{:.4}, {:.4}, {:.4}, {:.5}, {:.5}, {:.5}]: {}",
            u.pose_index, u.phase as u8, x[0], x[1], x[2], x[3], x[4], x[5], u.reason
        ),
    )
}

/// Steps the plant and checks the true forces against [f_lo, f_hi] (eq. 3.29, 3.33).
fn visit(
    plant: &mut Plant,
    q: &[f64],
    f_lo: f64,
    f_hi: f64,
) -> Result<crate::plant::Equilibrium, SkipReason> {
    let eq = plant.step(q).map_err(SkipReason::Plant)?;
    for (i, f) in eq.forces.iter().enumerate() {
        if *f < f_lo {
            return Err(SkipReason::BelowLimit {
                cable: i + 1,
                force_n: *f,
                limit_n: f_lo,
            });
        }
        if *f > f_hi {
            return Err(SkipReason::AboveLimit {
                cable: i + 1,
                force_n: *f,
                limit_n: f_hi,
            });
        }
    }
    Ok(eq)
}

/// q_cmd = φ_el(x, f_ref) with f_ref from eq. (3.41) on the control model.
fn command_elastostatic(
    control: &Platform,
    data: &mut Data,
    x: &Pose,
    f_ref: &mut [f64],
    q_cmd: &mut [f64],
) -> Result<(), SkipReason> {
    let model = &control.model;
    let p = model.params();
    kinematics::inverse(model, data, x).map_err(SkipReason::ControlModel)?;
    let fd = statics::force_distribution(data, &p.w_e, p.f_min, p.f_max, f_ref)
        .map_err(SkipReason::ForceDistribution)?;
    if !fd.feasible {
        return Err(SkipReason::Infeasible {
            cable_lo: fd.cable_lo + 1,
            f_lo: fd.f_lo,
            cable_hi: fd.cable_hi + 1,
            f_hi: fd.f_hi,
        });
    }
    elastostatics::inverse(model, data, x, f_ref, q_cmd).map_err(SkipReason::ControlModel)
}

/// Pose error statistics (eq. 3.3) of measured against reference poses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseErrors {
    /// Mean and largest position error ‖r̂ − r_ref‖, m.
    pub mean_position: f64,
    pub max_position: f64,
    /// Mean and largest rotation error angle, rad.
    pub mean_rotation: f64,
    pub max_rotation: f64,
    /// Number of samples evaluated.
    pub samples: usize,
}

/// One line: position and rotation error, mean and max (mm, degrees).
impl std::fmt::Display for PoseErrors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "pose errors over {} samples (eq. 3.3): position mean {:.2} mm, max {:.2} mm; rotation mean {:.3} deg, max {:.3} deg",
            self.samples,
            self.mean_position * 1e3,
            self.max_position * 1e3,
            self.mean_rotation.to_degrees(),
            self.max_rotation.to_degrees()
        )
    }
}

/// Pose errors of the `Phase::Pose` rows against their reference poses (eq. 3.3); `None` when
/// there is no such row with reference columns.
pub fn pose_errors(ds: &Dataset) -> Option<PoseErrors> {
    let mut e = PoseErrors {
        mean_position: 0.0,
        max_position: 0.0,
        mean_rotation: 0.0,
        max_rotation: 0.0,
        samples: 0,
    };
    for s in ds.samples.iter().filter(|s| s.phase == Phase::Pose) {
        let Some(r) = s.pose_ref else { continue };
        let (ep, er) = s.pose.error_to(&r);
        e.mean_position += ep;
        e.mean_rotation += er;
        e.max_position = e.max_position.max(ep);
        e.max_rotation = e.max_rotation.max(er);
        e.samples += 1;
    }
    (e.samples > 0).then(|| PoseErrors {
        mean_position: e.mean_position / e.samples as f64,
        mean_rotation: e.mean_rotation / e.samples as f64,
        ..e
    })
}
