//! Commissioning and the pre-ride check (`crs commission`, spec sec. 6.5, eq. 6.21–6.24 and
//! eq. 3.42): the running stack visits the set-up pose (the platform's home, eq. 6.21) and a
//! few poses around it (level offsets, then small tilts so the COG height becomes observable),
//! rests at each and records the force sensors (`crs sim --record`). From those rest points:
//!
//! 1. the external wrench at the set-up pose, w_e = −A^T f (eq. 6.22–6.23), and mass and COG
//!    over all rest poses with their standard deviations (`load_tracking::payload`);
//! 2. the cable offsets of the set-up, q_off = −K^{-1} f (eq. 6.24);
//! 3. the initial tension f_ini that keeps the forces closest to f_ref (eq. 3.41) along the
//!    daemon's planned tour (eq. 3.42, `load_tracking::setup`), for the load as measured;
//! 4. the verdict: the payload against the operator's configured load (`[load] wrench_n_nm` of
//!    the platform TOML) within tolerances — out of tolerance, the stack must not be armed for
//!    rides, and the command says so and exits non-zero.
//!
//! What it found goes to `<out>/commission.toml` for review (with the plant's truth next to it
//! when the run is simulated), never over the operator's config.

use cdpr_model::config::{Platform, load_platform};
use cdpr_model::{Data, Pose};
use crs_dataset::load_dataset;
use load_tracking::payload::{self, Payload, RestSample};
use load_tracking::setup::{self, InitialTension};
use load_tracking::wrench_from_forces;
use motion_core::daemon::trajectory::{Waypoint, read_waypoints};
use nalgebra::{Vector3, Vector6};
use sim_runs::campaign::write_waypoints;
use sim_runs::sim_run::{self, SimOptions};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Why commissioning could not measure or write its result.
#[derive(Debug, thiserror::Error)]
pub enum CommissionError {
    /// The daemon TOML, its platform TOML or the plant TOML (names its file and key).
    #[error(transparent)]
    Config(#[from] cdpr_model::config::ConfigError),
    /// Creating the output directory or writing a result file (`path`).
    #[error("{source}")]
    Output {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Writing the commissioning tour.
    #[error(transparent)]
    Tour(#[from] sim_runs::campaign::CampaignError),
    /// The run of the stack.
    #[error(transparent)]
    Run(#[from] sim_run::SimError),
    /// The run stopped (e-stops, a stopped drive bus): its rest points are not a measurement.
    #[error(
        "the commissioning run did not complete cleanly ({estops} e-stop(s){}): nothing was measured",
        if *bus_stopped { ", the drive bus stopped" } else { "" }
    )]
    NotClean { estops: u64, bus_stopped: bool },
    /// The recorded data set (names its file and line).
    #[error(transparent)]
    Dataset(#[from] crs_dataset::DatasetError),
    /// The daemon's waypoint file (its planned tour, eq. 3.42).
    #[error(transparent)]
    Waypoints(#[from] motion_core::daemon::trajectory::WaypointError),
    #[error("the recording has no rest point with force readings")]
    NoRestPoints,
    #[error("no rest point at the set-up pose (eq. 6.21) was recorded")]
    NoSetupRestPoint,
    /// The wrench or the cable offsets at the set-up pose (eq. 6.23/6.24).
    #[error(transparent)]
    Kinematics(#[from] cdpr_model::kinematics::KinematicsError),
    /// Mass and COG from the rest points.
    #[error(transparent)]
    Payload(#[from] load_tracking::payload::PayloadError),
    /// The simulated plant (its true payload).
    #[error(transparent)]
    Plant(#[from] sim_plant::PlantError),
    /// Serialising commission.json.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
}

fn output(path: &Path) -> impl FnOnce(std::io::Error) -> CommissionError + '_ {
    move |source| CommissionError::Output {
        path: path.to_path_buf(),
        source,
    }
}

/// What to run and how strict the check is.
#[derive(Clone, Debug)]
pub struct CommissionConfig {
    /// The stack to run (daemon, drives, plant, monitor, transport, out); its waypoints,
    /// recording and dwell are set by the commissioning.
    pub sim: SimOptions,
    /// Level offsets from the set-up pose, m, and the tilt of the tilted poses, rad.
    pub offset_m: f64,
    pub tilt_rad: f64,
    /// Rest at every pose, s.
    pub dwell_s: f64,
    /// The configured payload must agree within these.
    pub mass_tolerance_kg: f64,
    pub cog_tolerance_m: f64,
}

/// The verdict of the pre-ride check.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub enum Verdict {
    /// The measured payload matches the configured one: the stack may be armed.
    Ready,
    /// Do not arm: why.
    Refused(Vec<String>),
}

/// Everything commissioning found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Commission {
    pub platform: String,
    pub setup_pose: [f64; 6],
    pub rest_points: usize,
    /// w_e at the set-up pose from the measured forces (eq. 6.23), N and N·m.
    pub w_e_setup: [f64; 6],
    /// The measured forces at the set-up pose (eq. 6.22), N.
    pub f_setup: Vec<f64>,
    /// q_off from those forces (eq. 6.24), m.
    pub q_off_m: Vec<f64>,
    pub payload: Payload,
    /// The operator's configured payload (mass kg, COG x, y m).
    pub configured: (f64, [f64; 2]),
    /// The simulated plant's true payload, when the run is simulated (mass kg, COG m).
    pub truth: Option<(f64, [f64; 3])>,
    /// eq. 3.42 along the daemon's tour, or why it could not be chosen (in the JSON as
    /// `{"Err": "<message>"}`).
    #[serde(serialize_with = "serialize_f_ini")]
    pub f_ini: Result<InitialTension, InitialTensionError>,
    pub verdict: Verdict,
}

/// Why eq. 3.42 gave no initial tension for the measured load.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InitialTensionError {
    /// The model with the measured wrench w_e (eq. 6.23) is not valid.
    #[error(transparent)]
    MeasuredModel(#[from] cdpr_model::ModelError),
    /// eq. 3.42 along the tour.
    #[error(transparent)]
    Setup(#[from] setup::SetupError),
}

/// `f_ini` as serde writes a `Result`, the error as its message.
fn serialize_f_ini<S: serde::Serializer>(
    r: &Result<InitialTension, InitialTensionError>,
    s: S,
) -> Result<S::Ok, S::Error> {
    match r {
        Ok(t) => s.serialize_newtype_variant("Result", 0, "Ok", t),
        Err(e) => s.serialize_newtype_variant("Result", 1, "Err", &e.to_string()),
    }
}

/// The commissioning tour around the set-up pose x0: x0, four level offsets, two tilts (roll,
/// pitch), back to x0.
pub fn tour(x0: &Pose, offset_m: f64, tilt_rad: f64) -> Vec<Pose> {
    let d = offset_m;
    let mut out = vec![*x0];
    for (dx, dy) in [(d, 0.0), (0.0, d), (-d, 0.0), (0.0, -d)] {
        out.push(Pose::new(x0.r + Vector3::new(dx, dy, 0.0), x0.phi));
    }
    for t in [
        Vector3::new(tilt_rad, 0.0, 0.0),
        Vector3::new(0.0, tilt_rad, 0.0),
    ] {
        out.push(Pose::new(x0.r, x0.phi + t));
    }
    out.push(*x0);
    out
}

/// Runs the commissioning on the stack `c.sim` describes.
pub fn run(c: &CommissionConfig) -> Result<Commission, CommissionError> {
    let daemon = motion_core::daemon::config::load(&c.sim.config)?;
    let platform = load_platform(&daemon.platform)?;
    let x0 = platform.home;
    std::fs::create_dir_all(&c.sim.out).map_err(output(&c.sim.out))?;
    let poses = tour(&x0, c.offset_m, c.tilt_rad);
    let wps: Vec<Waypoint> = poses
        .iter()
        .map(|p| Waypoint {
            pose: *p,
            not_before_s: 0.0,
        })
        .collect();
    let tour_csv = c.sim.out.join("commission-tour.csv");
    write_waypoints(
        &tour_csv,
        &wps,
        "Commissioning tour (crs commission): the set-up pose (eq. 6.21), level offsets, tilts.",
    )?;
    let record = c.sim.out.join("commission-rest.csv");
    let mut sim = c.sim.clone();
    sim.waypoints = Some(tour_csv);
    sim.dwell_s = Some(c.dwell_s);
    sim.hold_s = sim.hold_s.max(c.dwell_s);
    sim.record = Some(record.clone());
    sim.record_mean_forces = true;
    sim.campaign = Some("commission".into());
    sim.check = false;
    let sum = sim_run::execute(&sim)?;
    if sum.estops > 0 || sum.bus_stopped_during_run.is_some() {
        return Err(CommissionError::NotClean {
            estops: sum.estops,
            bus_stopped: sum.bus_stopped_during_run.is_some(),
        });
    }
    let ds = load_dataset(&record)?;
    analyse(&platform, &daemon_tour(&daemon)?, &ds, c, Some(&sim.plant))
}

fn daemon_tour(
    d: &motion_core::daemon::config::DaemonConfig,
) -> Result<Vec<Pose>, CommissionError> {
    match &d.trajectory.waypoints {
        Some(p) => Ok(read_waypoints(p)?.into_iter().map(|w| w.pose).collect()),
        None => Ok(Vec::new()),
    }
}

/// The path eq. 3.42 integrates over: the tour's waypoints with 8 poses on each segment.
fn sampled_path(x0: &Pose, tour: &[Pose]) -> Vec<Pose> {
    let mut out = Vec::new();
    let mut prev = *x0;
    for p in tour {
        for k in 1..=8 {
            let t = k as f64 / 8.0;
            out.push(Pose::new(
                prev.r + (p.r - prev.r) * t,
                prev.phi + (p.phi - prev.phi) * t,
            ));
        }
        prev = *p;
    }
    out
}

/// The analysis of a recorded commissioning data set (separate from [`run`] so a recording of
/// a real robot can be analysed the same way).
pub fn analyse(
    platform: &Platform,
    planned_tour: &[Pose],
    ds: &crs_dataset::Dataset,
    c: &CommissionConfig,
    plant: Option<&Path>,
) -> Result<Commission, CommissionError> {
    let model = &platform.model;
    let x0 = platform.home;
    let mut data = Data::new(model);
    let rest: Vec<RestSample> = ds
        .samples
        .iter()
        .filter_map(|s| {
            Some(RestSample {
                // The tracker's pose, not the reference: the COG height rests on the torque a
                // 2° tilt adds, and the tilt the cabin really has differs from the reference by
                // its elastic deformation under an off-centre load (≈ 0.03° on the helicopter):
                // with the reference, c_z came out 3 cm high, ≈ 3 stated σ (measured 2026-11-25).
                pose: s.pose,
                forces: s.forces.clone()?,
            })
        })
        .collect();
    if rest.is_empty() {
        return Err(CommissionError::NoRestPoints);
    }
    // The set-up pose is found by the reference (the tracker sees it within its noise).
    let Some(setup_forces) = ds.samples.iter().find_map(|s| {
        let p = s.pose_ref.unwrap_or(s.pose);
        let (dp, dr) = p.error_to(&x0);
        (dp < 1e-3 && dr < 1e-4)
            .then_some(s.forces.as_ref())
            .flatten()
    }) else {
        return Err(CommissionError::NoSetupRestPoint);
    };
    let w = wrench_from_forces(model, &mut data, &x0, setup_forces)?;
    let q_off = setup::cable_offsets(model, &mut data, &x0, setup_forces)?;
    let fit = payload::identify(model, &mut data, &rest)?;
    let (m_cfg, c_cfg) = payload::configured(&model.params().w_e);
    let truth = match plant {
        Some(p) => {
            let cfg = sim_plant::load_plant(p)?;
            let pl = sim_plant::Plant::new(cfg)?;
            let wt: Vector6<f64> = pl.wrench_at(&x0);
            let (m, cxy) = payload::configured(&wt);
            let cz = pl
                .config()
                .effects
                .load
                .as_ref()
                .map_or(0.0, |l| l.center_of_gravity.z);
            Some((m, [cxy.x, cxy.y, cz]))
        }
        None => None,
    };
    // eq. 3.42 with the load as measured (eq. 6.23), not as configured: the tension is set
    // for the cabin that is really there.
    let mut measured = model.params().clone();
    measured.w_e = w;
    let f_ini = cdpr_model::Model::new(measured)
        .map_err(InitialTensionError::from)
        .and_then(|mm| {
            Ok(setup::initial_tension(
                &mm,
                &x0,
                &sampled_path(&x0, planned_tour),
            )?)
        });
    let mut why = Vec::new();
    let dm = fit.mass_kg - m_cfg;
    if dm.abs() > c.mass_tolerance_kg {
        why.push(format!(
            "payload mass {:.1} ± {:.1} kg differs from the configured {:.1} kg by {:+.1} kg (tolerance ±{:.1} kg)",
            fit.mass_kg, fit.mass_std_kg, m_cfg, dm, c.mass_tolerance_kg
        ));
    }
    for (a, name) in ["x", "y"].iter().enumerate() {
        match fit.cog_m[a] {
            Some(v) if (v - c_cfg[a]).abs() > c.cog_tolerance_m => why.push(format!(
                "centre of gravity {name} = {v:.3} m differs from the configured {:.3} m by {:+.3} m (tolerance ±{:.3} m)",
                c_cfg[a],
                v - c_cfg[a],
                c.cog_tolerance_m
            )),
            Some(_) => {}
            None => why.push(format!(
                "centre of gravity {name} is not observable from the recorded poses"
            )),
        }
    }
    let verdict = if why.is_empty() {
        Verdict::Ready
    } else {
        Verdict::Refused(why)
    };
    Ok(Commission {
        platform: platform.name.clone(),
        setup_pose: x0.to_array(),
        rest_points: rest.len(),
        w_e_setup: [w[0], w[1], w[2], w[3], w[4], w[5]],
        f_setup: setup_forces.clone(),
        q_off_m: q_off,
        payload: fit,
        configured: (m_cfg, [c_cfg.x, c_cfg.y]),
        truth,
        f_ini,
        verdict,
    })
}

fn list(v: &[f64], prec: usize) -> String {
    v.iter()
        .map(|x| format!("{x:.prec$}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn opt(v: Option<f64>, prec: usize) -> String {
    v.map_or("\"not observable\"".into(), |x| format!("{x:.prec$}"))
}

/// The reviewed result as TOML text (`commission.toml`).
pub fn to_toml(c: &Commission) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Commissioning of `{}` (crs commission; spec eq. 6.21-6.24, 3.42).\n# REVIEW before use: nothing here was written into the operator's config.\n",
        c.platform
    );
    let _ = writeln!(
        s,
        "[verdict]\nready = {}\nreasons = [{}]\n",
        c.verdict == Verdict::Ready,
        match &c.verdict {
            Verdict::Ready => String::new(),
            Verdict::Refused(w) => w
                .iter()
                .map(|x| format!("{x:?}"))
                .collect::<Vec<_>>()
                .join(", "),
        }
    );
    let p = &c.payload;
    let _ = writeln!(
        s,
        "[payload]\nmass_kg = {:.2}\nmass_std_kg = {:.2}\ncog_m = [{}, {}, {}]\ncog_std_m = [{}, {}, {}]\nresidual_rms = {:.2}\nlateral_force_n = [{:.1}, {:.1}]\nrest_points = {}\nconfigured_mass_kg = {:.2}\nconfigured_cog_xy_m = [{:.4}, {:.4}]",
        p.mass_kg,
        p.mass_std_kg,
        opt(p.cog_m[0], 4),
        opt(p.cog_m[1], 4),
        opt(p.cog_m[2], 4),
        opt(p.cog_std_m[0], 4),
        opt(p.cog_std_m[1], 4),
        opt(p.cog_std_m[2], 4),
        p.residual_rms,
        p.lateral_force_n[0],
        p.lateral_force_n[1],
        c.rest_points,
        c.configured.0,
        c.configured.1[0],
        c.configured.1[1],
    );
    if let Some((m, cog)) = c.truth {
        let _ = writeln!(
            s,
            "plant_truth_mass_kg = {m:.2}\nplant_truth_cog_m = [{:.4}, {:.4}, {:.4}]",
            cog[0], cog[1], cog[2]
        );
    }
    let _ = writeln!(
        s,
        "\n[setup]\npose = [{}]\nw_e_n_nm = [{}]  # eq. 6.23\nf_measured_n = [{}]  # eq. 6.22\nq_off_m = [{}]  # eq. 6.24",
        list(&c.setup_pose, 4),
        list(&c.w_e_setup, 1),
        list(&c.f_setup, 1),
        list(&c.q_off_m, 5)
    );
    match &c.f_ini {
        Ok(t) => {
            let _ = writeln!(
                s,
                "\n[initial_tension]  # eq. 3.42 along the daemon's tour\nf_ini_n = [{}]\nq_off_m = [{}]\nrms_to_f_ref_n = {:.1}\nrms_to_f_ref_start_n = {:.1}\npath_force_range_n = [{:.0}, {:.0}]",
                list(&t.f_ini, 1),
                list(&t.q_off, 5),
                t.rms_chosen_n,
                t.rms_start_n,
                t.f_min_n,
                t.f_max_n
            );
        }
        Err(e) => {
            let _ = writeln!(s, "\n[initial_tension]\nfailed = {:?}", e.to_string());
        }
    }
    s
}

/// Writes `commission.toml` and `commission.json` into `out`; returns the TOML path.
pub fn write(c: &Commission, out: &Path) -> Result<PathBuf, CommissionError> {
    std::fs::create_dir_all(out).map_err(output(out))?;
    let path = out.join("commission.toml");
    std::fs::write(&path, to_toml(c)).map_err(output(&path))?;
    let json = out.join("commission.json");
    std::fs::write(&json, serde_json::to_string_pretty(c)?).map_err(output(&json))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tour_starts_and_ends_at_the_setup_pose_and_tilts_twice() {
        let x0 = Pose::new(Vector3::new(0.0, 0.0, 1.5), Vector3::zeros());
        let t = tour(&x0, 0.3, 0.035);
        assert_eq!(t.first(), Some(&x0));
        assert_eq!(t.last(), Some(&x0));
        assert_eq!(t.iter().filter(|p| p.phi != Vector3::zeros()).count(), 2);
        assert_eq!(sampled_path(&x0, &t[1..2]).len(), 8);
    }

    /// The TOML a reviewer reads parses, says not ready when refused, and marks the
    /// unobservable COG height instead of printing a number.
    #[test]
    fn the_reviewed_file_parses_and_says_what_is_unknown() {
        let c = Commission {
            platform: "p".into(),
            setup_pose: [0.0, 0.0, 1.5, 0.0, 0.0, 0.0],
            rest_points: 3,
            w_e_setup: [0.0, 0.0, -7000.0, 0.0, -600.0, 0.0],
            f_setup: vec![4000.0; 8],
            q_off_m: vec![-0.02; 8],
            payload: Payload {
                mass_kg: 713.0,
                mass_std_kg: 1.0,
                cog_m: [Some(0.08), Some(0.0), None],
                cog_std_m: [Some(0.01), Some(0.01), None],
                residual_rms: 3.0,
                lateral_force_n: [1.0, -2.0],
                samples: 3,
            },
            configured: (764.5, [0.08, 0.0]),
            truth: None,
            f_ini: Err(setup::SetupError::EmptyPath.into()),
            verdict: Verdict::Refused(vec!["payload mass differs".into()]),
        };
        let t: toml::Table = to_toml(&c).parse().expect("valid TOML");
        assert_eq!(t["verdict"]["ready"].as_bool(), Some(false));
        assert_eq!(t["payload"]["cog_m"][2].as_str(), Some("not observable"));
        assert_eq!(
            t["initial_tension"]["failed"].as_str(),
            Some("the path is empty")
        );
        let json = serde_json::to_value(&c).expect("serialisable");
        assert_eq!(json["f_ini"]["Err"].as_str(), Some("the path is empty"));
    }
}
