//! The surrogate of a platform fitted (`crs surrogate fit`) and evaluated on the simulated
//! plant: the kinematic controller against kinematics + surrogate (eq. 5.26), both compared to
//! the reference forces f_ref (eq. 3.41).

use cdpr_model::config::Platform;
use cdpr_model::offset_target::{OffsetTarget, region_box};
use cdpr_model::{Data, Pose, kinematics};
use crs_limits::quantile::quantile_sorted;
use sim_plant::{Plant, load_plant};
use std::path::Path;
use surrogate::{FitOptions, Region, Surrogate, fit};

/// Why a surrogate evaluation on the plant could not be made.
#[derive(Debug, thiserror::Error)]
pub enum EvaluationError {
    /// `--grid` outside 2..=25.
    #[error("--grid must lie in 2..=25, got {grid}")]
    Grid { grid: usize },
    /// The plant TOML (names its file and key).
    #[error(transparent)]
    PlantConfig(#[from] cdpr_model::config::ConfigError),
    /// The plant and the platform have different cable counts.
    #[error(
        "plant {} has {plant_cables} cables, platform {platform} has {platform_cables}",
        plant.display()
    )]
    CableCount {
        plant: std::path::PathBuf,
        plant_cables: usize,
        platform: String,
        platform_cables: usize,
    },
    /// The platform has no `[home] f_ini_n`.
    #[error(
        "platform `{platform}` has no [home] f_ini_n: the kinematic controller needs the initial tension (eq. 6.22)"
    )]
    NoInitialTension { platform: String },
    /// The plant refuses to start, to tension at home or to settle at the set-up command.
    #[error(transparent)]
    Plant(#[from] sim_plant::PlantError),
    /// The reference forces f_ref (eq. 3.41) at a pose.
    #[error(transparent)]
    ReferenceForces(#[from] cdpr_model::offset_target::OffsetTargetError),
    /// The controller's inverse kinematics.
    #[error(transparent)]
    Kinematics(#[from] cdpr_model::kinematics::KinematicsError),
    /// The surrogate refuses a pose.
    #[error("surrogate: {0}")]
    Surrogate(#[source] surrogate::EvalError),
}

/// The fit of `crs surrogate fit`: target q_off from [`OffsetTarget`] over the platform region.
pub fn fit_platform(
    pf: &Platform,
    opts: &FitOptions,
) -> Result<(Surrogate, surrogate::FitReport), surrogate::FitError> {
    let m = pf.model.m();
    let (lower, upper) = region_box(&pf.region);
    let region = Region { lower, upper };
    let mut target = OffsetTarget::new(&pf.model);
    fit(
        &region,
        opts,
        m,
        &pf.model.identity_hex(),
        |x: &[f64; 6]| {
            let mut out = vec![0.0; m];
            target.offset(&Pose::from_array(*x), &mut out).map(|_| out)
        },
    )
}

/// Why a surrogate file could not be written or read for a platform.
#[derive(Debug, thiserror::Error)]
pub enum SurrogateFileError {
    #[error(transparent)]
    Platform(#[from] cdpr_model::config::ConfigError),
    #[error(transparent)]
    Fit(#[from] surrogate::FitError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The surrogate file (named) could not be saved or loaded.
    #[error("{}: {source}", file.display())]
    File {
        file: std::path::PathBuf,
        source: surrogate::FileError,
    },
}

/// A fitted surrogate, saved; it prints as `crs surrogate fit` shows it: size, conditioning,
/// fit error and the bound of eq. 5.27 with its margin.
pub struct Fitted {
    pub surrogate: Surrogate,
    pub report: surrogate::FitReport,
    /// Time of the fit, s.
    pub seconds: f64,
    /// The file written.
    pub out: std::path::PathBuf,
    /// The platform's name and cable count.
    pub platform: String,
    pub cables: usize,
}

impl std::fmt::Display for Fitted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let report = &self.report;
        writeln!(
            f,
            "fitted `{}` ({} cables) over its operating region in {:.2} s",
            self.platform, self.cables, self.seconds
        )?;
        writeln!(
            f,
            "  degree {}, {} coefficients/cable, {} fit / {} validation samples, condition {:.2}",
            report.degree,
            report.n_coeffs_per_cable,
            report.n_fit_samples,
            report.n_validation_samples,
            report.condition_number
        )?;
        writeln!(
            f,
            "  fit error vs the full model: max {:.4} mm, mean {:.4} mm",
            report.max_fit_error_mm, report.mean_fit_error_mm
        )?;
        writeln!(
            f,
            "  max |φ_sg| {:.2} mm (sampled), certified Σ|c| {:.2} mm < bound {:.0} mm − margin {:.0} mm (eq. 5.27)",
            report.max_abs_offset_mm, report.certified_bound_mm, report.bound_mm, report.margin_mm
        )?;
        writeln!(f, "wrote {}", self.out.display())
    }
}

/// [`fit_platform`] timed and saved to `out` (its directory created).
pub fn fit_and_save(
    pf: &Platform,
    opts: &FitOptions,
    out: &Path,
) -> Result<Fitted, SurrogateFileError> {
    let t0 = std::time::Instant::now();
    let (sg, report) = fit_platform(pf, opts)?;
    let dt = t0.elapsed().as_secs_f64();
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    sg.save(out).map_err(|source| SurrogateFileError::File {
        file: out.to_path_buf(),
        source,
    })?;
    Ok(Fitted {
        surrogate: sg,
        report,
        seconds: dt,
        out: out.to_path_buf(),
        platform: pf.name.clone(),
        cables: pf.model.m(),
    })
}

/// The platform TOML `platform` and the surrogate file `file` checked against it as the daemon
/// loads it (format, checksum, platform identity, bound).
pub fn load_for_platform(
    file: &Path,
    platform: &Path,
) -> Result<(Platform, Surrogate), SurrogateFileError> {
    let pf = cdpr_model::config::load_platform(platform)?;
    let sg = Surrogate::load(file, &pf.model.identity_hex()).map_err(|source| {
        SurrogateFileError::File {
            file: file.to_path_buf(),
            source,
        }
    })?;
    Ok((pf, sg))
}

/// One controller's tracking on the plant over the evaluation grid.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Tracking {
    /// Per evaluated pose (same order for both controllers): max_i |f̂_i − f_ref,i| (N),
    /// position error (mm), orientation error (deg); NaN where the plant did not settle.
    pub force_error_n: Vec<f64>,
    pub position_error_mm: Vec<f64>,
    pub orientation_error_deg: Vec<f64>,
    /// Wrench-feasible poses where the plant's forces stayed in [f_min, f_max] (eq. 3.33).
    pub reachable: usize,
    /// Poses where the plant found no equilibrium.
    pub failed: usize,
}

#[derive(Debug, serde::Serialize)]
pub struct Evaluation {
    pub platform: String,
    pub plant: String,
    pub poses: usize,
    pub wrench_feasible: usize,
    pub kinematic: Tracking,
    pub surrogate: Tracking,
}

/// Commands the plant over a grid in the platform region with (a) kinematics + set-up offsets
/// (eq. 3.14/6.24) and (b) kinematics + surrogate (eq. 5.26) + set-up offsets; compares to
/// f_ref (eq. 3.41). The kinematic controller's force error is mostly the level of its set-up
/// tension f_ini (eq. 6.22) propagated through the workspace (ch. 3.4): it has no force goal.
pub fn evaluate(
    pf: &Platform,
    sg: &Surrogate,
    plant_path: &Path,
    grid: usize,
) -> Result<Evaluation, EvaluationError> {
    if !(2..=25).contains(&grid) {
        return Err(EvaluationError::Grid { grid });
    }
    let cfg = load_plant(plant_path)?;
    let plant_name = cfg.name.clone();
    let m = pf.model.m();
    if cfg.platform.model.m() != m {
        return Err(EvaluationError::CableCount {
            plant: plant_path.to_path_buf(),
            plant_cables: cfg.platform.model.m(),
            platform: pf.name.clone(),
            platform_cables: m,
        });
    }
    let f_ini = pf
        .f_ini
        .clone()
        .ok_or_else(|| EvaluationError::NoInitialTension {
            platform: pf.name.clone(),
        })?;
    let mut plant = Plant::new(cfg)?;
    let poses = grid_poses(pf, grid);
    let mut target = OffsetTarget::new(&pf.model);
    let mut f_ref = Vec::with_capacity(poses.len());
    let mut feasible = Vec::with_capacity(poses.len());
    for x in &poses {
        let (f, fd) = target.reference_forces(x)?;
        f_ref.push(f.to_vec());
        feasible.push(fd.feasible);
    }
    let campaign = Campaign {
        pf,
        sg,
        f_ini: &f_ini,
        poses: &poses,
        f_ref: &f_ref,
        feasible: &feasible,
    };
    let mut data = Data::new(&pf.model);
    let kinematic = track(&campaign, &mut plant, &mut target, &mut data, false)?;
    let surrogate = track(&campaign, &mut plant, &mut target, &mut data, true)?;
    Ok(Evaluation {
        platform: pf.name.clone(),
        plant: plant_name,
        poses: poses.len(),
        wrench_feasible: feasible.iter().filter(|f| **f).count(),
        kinematic,
        surrogate,
    })
}

/// The evaluation grid: `grid`³ positions spanning the region's box, each with the 27
/// combinations of the lowest, zero (clamped into the region) and highest angle per axis.
fn grid_poses(pf: &Platform, grid: usize) -> Vec<Pose> {
    let (lo, hi) = region_box(&pf.region);
    let mut poses = Vec::new();
    let at = |d: usize, k: usize, n: usize| lo[d] + (hi[d] - lo[d]) * k as f64 / (n - 1) as f64;
    let rot = |d: usize, k: usize| match k {
        0 => lo[d],
        1 => 0.0f64.clamp(lo[d], hi[d]),
        _ => hi[d],
    };
    for iz in 0..grid {
        for iy in 0..grid {
            for ix in 0..grid {
                for r in 0..27 {
                    poses.push(Pose::from_array([
                        at(0, ix, grid),
                        at(1, iy, grid),
                        at(2, iz, grid),
                        rot(3, r % 3),
                        rot(4, (r / 3) % 3),
                        rot(5, r / 9),
                    ]));
                }
            }
        }
    }
    poses
}

/// What both controllers are evaluated on: the poses with their reference forces f_ref
/// (eq. 3.41) and wrench feasibility, the kinematic controller's set-up tension f_ini.
struct Campaign<'a> {
    pf: &'a Platform,
    sg: &'a Surrogate,
    f_ini: &'a [f64],
    poses: &'a [Pose],
    f_ref: &'a [Vec<f64>],
    feasible: &'a [bool],
}

/// One controller (kinematic, or with the surrogate) set up at home, then commanded to every
/// pose of the campaign in turn.
fn track(
    c: &Campaign<'_>,
    plant: &mut Plant,
    target: &mut OffsetTarget,
    data: &mut Data,
    use_surrogate: bool,
) -> Result<Tracking, EvaluationError> {
    let (pf, sg, m) = (c.pf, c.sg, c.pf.model.m());
    let p = pf.model.params();
    // Set-up at home (sec. 6.1, eq. 3.14/6.24): the operator tensions the cables at the home
    // pose and zeroes the cable offsets there. The kinematic controller is set up with the
    // spec's initial tension f_ini (eq. 6.22); the surrogate controller with its own
    // reference f_ref(home) (eq. 3.41), so the offsets c only absorb what the control model
    // does not know (encoder offsets, drive-train length): c = q_setup − (φ + φ_sg)(home).
    let f_setup: Vec<f64> = if use_surrogate {
        target.reference_forces(&pf.home)?.0.to_vec()
    } else {
        c.f_ini.to_vec()
    };
    let setup = plant.setup_tension(&pf.home, &f_setup)?;
    kinematics::inverse(&pf.model, data, &pf.home)?;
    let mut sg_home = vec![0.0; m];
    if use_surrogate {
        sg.eval(&pf.home.to_array(), &mut sg_home)
            .map_err(EvaluationError::Surrogate)?;
    }
    let q_setup: Vec<f64> = (0..m)
        .map(|i| setup.q_cmd[i] - data.q[i] - sg_home[i])
        .collect();
    plant.step(&setup.q_cmd)?;
    let mut last_pose = pf.home;
    let mut t = Tracking::default();
    let mut q = vec![0.0; m];
    let mut qs = vec![0.0; m];
    let mut off = vec![0.0; m];
    let mut command = |x: &Pose, q: &mut [f64]| -> Result<(), EvaluationError> {
        kinematics::inverse(&pf.model, data, x)?;
        if use_surrogate {
            sg.eval(&x.to_array(), &mut off)
                .map_err(EvaluationError::Surrogate)?;
        } else {
            off.fill(0.0);
        }
        for i in 0..m {
            q[i] = data.q[i] + off[i] + q_setup[i];
        }
        Ok(())
    };
    for (k, x) in c.poses.iter().enumerate() {
        command(x, &mut q)?;
        let before = plant.state();
        // Move there as the robot would: along the straight pose path from the last
        // settled pose in sub-steps of ≤ 50 mm and ≤ 1°, each commanded by the same
        // controller, so the plant's equilibrium search starts close (continuation).
        let a = last_pose.to_array();
        let b = x.to_array();
        let dp = (0..3).map(|d| (b[d] - a[d]).abs()).fold(0.0, f64::max);
        let dr = (3..6).map(|d| (b[d] - a[d]).abs()).fold(0.0, f64::max);
        let n_sub = ((dp / 0.05).max(dr / 1f64.to_radians()).ceil() as usize).max(1);
        let mut result = Err(sim_plant::PlantError::WrongLength {
            expected: m,
            got: 0,
        });
        for s in 1..=n_sub {
            let w = s as f64 / n_sub as f64;
            let mut xs = [0.0; 6];
            for d in 0..6 {
                xs[d] = a[d] + w * (b[d] - a[d]);
            }
            command(&Pose::from_array(xs), &mut qs)?;
            result = plant.step(&qs);
            if result.is_err() {
                break;
            }
        }
        match result {
            Ok(eq) => {
                last_pose = *x;
                let (dp, dr) = eq.pose.error_to(x);
                let fe = eq
                    .forces
                    .iter()
                    .zip(&c.f_ref[k])
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                t.force_error_n.push(fe);
                t.position_error_mm.push(dp * 1e3);
                t.orientation_error_deg.push(dr.to_degrees());
                let ok = eq.forces.iter().all(|f| *f >= p.f_min && *f <= p.f_max);
                if c.feasible[k] && ok {
                    t.reachable += 1;
                }
            }
            Err(e) => {
                if std::env::var_os("CRS_DEBUG_PLANT").is_some() {
                    eprintln!("pose {k} {:?}: {e}", x.to_array());
                }
                plant.restore(&before);
                t.failed += 1;
                t.force_error_n.push(f64::NAN);
                t.position_error_mm.push(f64::NAN);
                t.orientation_error_deg.push(f64::NAN);
            }
        }
    }
    Ok(t)
}

pub fn stats(v: &[f64]) -> (f64, f64, f64) {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    s.sort_by(f64::total_cmp);
    let mean = s.iter().sum::<f64>() / s.len() as f64;
    let p95 = quantile_sorted(&s, 0.95).unwrap_or(f64::NAN);
    (mean, p95, *s.last().unwrap_or(&f64::NAN))
}
