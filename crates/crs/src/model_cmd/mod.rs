//! `crs model …`: inverse/forward kinematics, force distribution, stiffness and workspace of a
//! platform TOML at a pose, as tables for people or JSON for scripts. Units on the command line
//! are named in the flags: positions in m, angles in degrees, lengths in m, forces in N. The
//! analyses and their tables, JSON, CSV and SVG are the library `model-analysis`.

mod design_checks;

use cdpr_model::Pose;
use cdpr_model::config::{Platform, load_platform};
use cdpr_model::workspace::FeasibilityTest;
use model_analysis::Report;
use nalgebra::Vector3;
use std::error::Error;
use std::path::PathBuf;

type Res = Result<(), Box<dyn Error>>;

#[derive(clap::Args, Debug, Clone)]
pub struct Common {
    /// Platform TOML.
    #[arg(long, default_value = "config/icosahedron.toml")]
    pub(crate) platform: PathBuf,
    /// Machine-readable JSON instead of tables.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(clap::Args, Debug, Clone)]
pub struct PoseArgs {
    /// Platform position x,y,z in m (default: the platform's home pose).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    position_m: Option<Vec<f64>>,
    /// Platform rotation φx,φy,φz in degrees, R = Rx Ry Rz (eq. 2.2).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    rotation_deg: Option<Vec<f64>>,
}

/// A vector flag (`--position-m`, `--rotation-deg`, `--min-m`, ...) that is not three finite
/// numbers.
#[derive(Debug, thiserror::Error)]
pub(crate) enum TripleError {
    #[error("{flag} takes 3 comma-separated values, got {got}")]
    Count { flag: &'static str, got: usize },
    #[error("{flag} values must be finite")]
    NotFinite { flag: &'static str },
}

/// The platform of `--platform` or the pose of the pose flags could not be used.
#[derive(Debug, thiserror::Error)]
pub(crate) enum AtPoseError {
    #[error(transparent)]
    Platform(#[from] cdpr_model::config::ConfigError),
    #[error(transparent)]
    Pose(#[from] TripleError),
}

/// Three comma-separated numbers from a flag, or a clear error naming the flag.
fn triple(flag: &'static str, v: &[f64]) -> Result<Vector3<f64>, TripleError> {
    if v.len() != 3 {
        return Err(TripleError::Count { flag, got: v.len() });
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(TripleError::NotFinite { flag });
    }
    Ok(Vector3::new(v[0], v[1], v[2]))
}

impl PoseArgs {
    pub(crate) fn pose(&self, pf: &Platform) -> Result<Pose, TripleError> {
        let r = match &self.position_m {
            Some(v) => triple("--position-m", v)?,
            None => pf.home.r,
        };
        let phi = match &self.rotation_deg {
            Some(v) => triple("--rotation-deg", v)?.map(f64::to_radians),
            None => pf.home.phi,
        };
        Ok(Pose::new(r, phi))
    }
}

/// `--test` of `crs model workspace`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TestArg {
    ClosedForm,
    Exact,
    Both,
}

/// A platform at a pose.
#[derive(clap::Args, Debug, Clone)]
pub struct AtPose {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    pose: PoseArgs,
}

impl AtPose {
    fn load(&self) -> Result<(Platform, Pose), AtPoseError> {
        let pf = load(&self.common)?;
        let x = self.pose.pose(&pf)?;
        Ok((pf, x))
    }
}

#[derive(clap::Subcommand, Debug)]
pub enum ModelCommand {
    /// Inverse kinematics: cable lengths, directions, pulley wrap angles (eq. 2.3-2.8, 2.16-2.29).
    Ik(AtPose),
    /// Forward kinematics from cable lengths: least squares (eq. 2.11) or elastostatic (eq. 2.42).
    Fk(FkArgs),
    /// Closed-form force distribution (eq. 3.41), feasibility, internal/external split and section wrenches.
    Forces(AtPose),
    /// Stiffness at the reference force distribution: K_C, K_G, K_wx (eq. 2.67-2.78).
    Stiffness(AtPose),
    /// The spec's planar 4-cable robot (eq. 3.40 / 4.24): condition numbers, initial tension,
    /// physical and reachable areas and pulley influence of ch. 3-4, next to the spec's values.
    Planar(design_checks::PlanarArgs),
    /// Icosahedron cabin space-frame truss check (eq. 5.2-5.7): rod forces for a pose or the
    /// worst case over the operating region, against the 151 kN rod rating.
    Truss(design_checks::TrussArgs),
    /// Pose error caused by parameter errors (eq. 3.25-3.28): per parameter at a pose, and an
    /// RMS error map over the operating region for given anchor and stiffness uncertainties.
    Sensitivity(design_checks::SensitivityArgs),
    /// Wrench-feasible constant-orientation workspace (eq. 3.29): grid fraction and hull volume.
    Workspace(WorkspaceArgs),
}

#[derive(clap::Args, Debug, Clone)]
pub struct FkArgs {
    #[command(flatten)]
    common: Common,
    /// Controlled cable lengths q_θ, m (one per cable, comma separated).
    #[arg(
        long,
        value_delimiter = ',',
        required = true,
        allow_hyphen_values = true
    )]
    lengths_m: Vec<f64>,
    /// Solve the elastostatic forward kinematics ν_el with the platform's stiffness and wrench.
    #[arg(long)]
    elastic: bool,
    /// Initial guess (default: the platform's home pose).
    #[command(flatten)]
    guess: PoseArgs,
}

#[derive(clap::Args, Debug, Clone)]
pub struct WorkspaceArgs {
    #[command(flatten)]
    common: Common,
    /// Box minimum x,y,z in m (default: the configured workspace region).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    min_m: Option<Vec<f64>>,
    /// Box maximum x,y,z in m.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    max_m: Option<Vec<f64>>,
    /// Constant orientation φx,φy,φz in degrees.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,0,0",
        allow_hyphen_values = true
    )]
    rotation_deg: Vec<f64>,
    /// Grid points per axis.
    #[arg(long, default_value_t = 21)]
    resolution: usize,
    /// Also compute the workspace hull (Pott 2008) around the home position.
    #[arg(long)]
    hull: bool,
    /// Feasibility test: the hard loop's closed form (eq. 3.41, sufficient), the exact LP
    /// (eq. 3.29, necessary and sufficient), or both side by side.
    #[arg(long, value_enum, default_value_t = TestArg::ClosedForm)]
    test: TestArg,
    /// Reachable workspace of the kinematic controller (eq. 3.33-3.35) instead, with the
    /// exact W_WF, a payload-sensitivity map and, with --plant, the plant's measurement.
    #[arg(long)]
    reachable: bool,
    /// Plant TOML (sim-plant) that measures the reachable workspace (with --reachable).
    #[arg(long, requires = "reachable")]
    plant: Option<PathBuf>,
    /// SVG map of the slice through the home position (with --reachable).
    #[arg(long, requires = "reachable")]
    svg: Option<PathBuf>,
    /// Write every grid point with its verdict to this CSV file.
    #[arg(long)]
    csv: Option<PathBuf>,
}

/// A report as JSON or as its table.
pub(crate) fn show(json: bool, r: &impl Report) {
    if json {
        println!("{}", r.json());
    } else {
        print!("{r}");
    }
}

pub fn run(cmd: ModelCommand) -> Res {
    use model_analysis::{kinematics, statics};
    match cmd {
        ModelCommand::Ik(a) => {
            let (pf, x) = a.load()?;
            show(a.common.json, &kinematics::ik(&pf, &x)?);
        }
        ModelCommand::Fk(a) => {
            let pf = load(&a.common)?;
            if a.lengths_m.len() != pf.model.m() {
                return Err(format!(
                    "--lengths-m has {} values but {} has {} cables",
                    a.lengths_m.len(),
                    pf.name,
                    pf.model.m()
                )
                .into());
            }
            let g = a.guess.pose(&pf)?;
            show(
                a.common.json,
                &kinematics::fk(&pf, &a.lengths_m, a.elastic, &g)?,
            );
        }
        ModelCommand::Forces(a) => {
            let (pf, x) = a.load()?;
            show(a.common.json, &statics::forces(&pf, &x)?);
        }
        ModelCommand::Stiffness(a) => {
            let (pf, x) = a.load()?;
            show(a.common.json, &statics::stiffness(&pf, &x)?);
        }
        ModelCommand::Planar(a) => design_checks::planar(&a)?,
        ModelCommand::Truss(a) => design_checks::truss(&a)?,
        ModelCommand::Sensitivity(a) => design_checks::sensitivity(&a)?,
        ModelCommand::Workspace(a) => a.run()?,
    }
    Ok(())
}

impl WorkspaceArgs {
    fn run(self) -> Res {
        let pf = load(&self.common)?;
        // The box of `--min-m/--max-m` (default: the configured region) and the grid size.
        let mut bounds = pf.region.position;
        if let Some(v) = &self.min_m {
            bounds.min = triple("--min-m", v)?;
        }
        if let Some(v) = &self.max_m {
            bounds.max = triple("--max-m", v)?;
        }
        if (0..3).any(|k| bounds.min[k] >= bounds.max[k]) {
            return Err("--min-m must be below --max-m on every axis".into());
        }
        if self.resolution < 2 {
            return Err("--resolution must be at least 2".into());
        }
        let rot = triple("--rotation-deg", &self.rotation_deg)?;
        let (json, n) = (self.common.json, self.resolution);
        if self.reachable {
            let (mut r, note) = plant_experiments::reachable_on_plant::analyse(
                &pf,
                &self.common.platform,
                bounds,
                &rot.map(f64::to_radians),
                n,
                self.plant.as_deref(),
            )?;
            if let Some(n) = note {
                eprintln!("{n}");
            }
            if let Some(path) = &self.svg {
                r.write_svg(path)?;
            }
            show(json, &r);
            return Ok(());
        }
        let tests: &[FeasibilityTest] = match self.test {
            TestArg::ClosedForm => &[FeasibilityTest::ClosedForm],
            TestArg::Exact => &[FeasibilityTest::Exact],
            TestArg::Both => &[FeasibilityTest::ClosedForm, FeasibilityTest::Exact],
        };
        let mut r =
            model_analysis::workspace::workspace(&pf, bounds, rot.into(), n, self.hull, tests)?;
        if let Some(path) = &self.csv {
            r.write_csv(path)?;
        }
        show(json, &r);
        Ok(())
    }
}

pub(crate) fn load(c: &Common) -> Result<Platform, cdpr_model::config::ConfigError> {
    load_platform(&c.platform)
}
