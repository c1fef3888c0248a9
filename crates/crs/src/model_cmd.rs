//! `crs model …`: inverse/forward kinematics, force distribution, stiffness and workspace of a
//! platform TOML at a pose, as tables for people or JSON for scripts. Units on the command line
//! are named in the flags: positions in m, angles in degrees, lengths in m, forces in N.

use cdpr_model::config::{Platform, load_platform};
use cdpr_model::elastostatics::{self, Stiffness};
use cdpr_model::forward::{self, FkOptions};
use cdpr_model::workspace;
use cdpr_model::{Data, Pose, kinematics, statics};
use nalgebra::{Matrix6, Vector3};
use serde_json::json;
use std::error::Error;
use std::path::PathBuf;

type Res = Result<(), Box<dyn Error>>;

#[derive(clap::Args, Debug, Clone)]
pub struct Common {
    /// Platform TOML.
    #[arg(long, default_value = "config/icosahedron.toml")]
    platform: PathBuf,
    /// Machine-readable JSON instead of tables.
    #[arg(long)]
    json: bool,
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

/// Three comma-separated numbers from a flag, or a clear error naming the flag.
fn triple(flag: &str, v: &[f64]) -> Result<Vector3<f64>, Box<dyn Error>> {
    if v.len() != 3 {
        return Err(format!("{flag} takes 3 comma-separated values, got {}", v.len()).into());
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(format!("{flag} values must be finite").into());
    }
    Ok(Vector3::new(v[0], v[1], v[2]))
}

impl PoseArgs {
    fn pose(&self, pf: &Platform) -> Result<Pose, Box<dyn Error>> {
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

#[derive(clap::Subcommand, Debug)]
pub enum ModelCommand {
    /// Inverse kinematics: cable lengths, directions, pulley wrap angles (eq. 2.3-2.8, 2.16-2.29).
    Ik {
        #[command(flatten)]
        common: Common,
        #[command(flatten)]
        pose: PoseArgs,
    },
    /// Forward kinematics from cable lengths: least squares (eq. 2.11) or elastostatic (eq. 2.42).
    Fk {
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
    },
    /// Closed-form force distribution (eq. 3.41), feasibility, internal/external split and section wrenches.
    Forces {
        #[command(flatten)]
        common: Common,
        #[command(flatten)]
        pose: PoseArgs,
    },
    /// Stiffness at the reference force distribution: K_C, K_G, K_wx (eq. 2.67-2.78).
    Stiffness {
        #[command(flatten)]
        common: Common,
        #[command(flatten)]
        pose: PoseArgs,
    },
    /// Wrench-feasible constant-orientation workspace (eq. 3.29): grid fraction and hull volume.
    Workspace {
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
        /// Write every grid point with its verdict to this CSV file.
        #[arg(long)]
        csv: Option<PathBuf>,
    },
}

pub fn run(cmd: ModelCommand) -> Res {
    match cmd {
        ModelCommand::Ik { common, pose } => ik(&common, &pose),
        ModelCommand::Fk {
            common,
            lengths_m,
            elastic,
            guess,
        } => fk(&common, &lengths_m, elastic, &guess),
        ModelCommand::Forces { common, pose } => forces(&common, &pose),
        ModelCommand::Stiffness { common, pose } => stiffness(&common, &pose),
        ModelCommand::Workspace {
            common,
            min_m,
            max_m,
            rotation_deg,
            resolution,
            hull,
            csv,
        } => workspace_cmd(&common, min_m, max_m, &rotation_deg, resolution, hull, csv),
    }
}

fn load(c: &Common) -> Result<Platform, Box<dyn Error>> {
    Ok(load_platform(&c.platform)?)
}

fn pose_json(p: &Pose) -> serde_json::Value {
    json!({
        "position_m": [p.r.x, p.r.y, p.r.z],
        "rotation_deg": [p.phi.x.to_degrees(), p.phi.y.to_degrees(), p.phi.z.to_degrees()],
    })
}

fn fmt_pose(p: &Pose) -> String {
    format!(
        "r = [{:.4}, {:.4}, {:.4}] m, φ = [{:.4}, {:.4}, {:.4}]°",
        p.r.x,
        p.r.y,
        p.r.z,
        p.phi.x.to_degrees(),
        p.phi.y.to_degrees(),
        p.phi.z.to_degrees()
    )
}

fn ik(c: &Common, pa: &PoseArgs) -> Res {
    let pf = load(c)?;
    let model = &pf.model;
    let pose = pa.pose(&pf)?;
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, &pose)?;
    if c.json {
        let cables: Vec<_> = (0..model.m())
            .map(|i| {
                json!({
                    "cable": i + 1,
                    "length_m": data.q[i],
                    "free_length_m": data.q_free[i],
                    "wrap_angle_deg": data.beta[i].to_degrees(),
                    "unit_vector": [data.u[i].x, data.u[i].y, data.u[i].z],
                    "exit_point_m": [data.p_exit[i].x, data.p_exit[i].y, data.p_exit[i].z],
                })
            })
            .collect();
        println!(
            "{}",
            json!({"platform": pf.name, "pose": pose_json(&pose), "cables": cables})
        );
        return Ok(());
    }
    println!("{} at {}", pf.name, fmt_pose(&pose));
    println!(
        "{:>5} {:>10} {:>10} {:>8} {:>26}",
        "cable", "q [m]", "q_f [m]", "β [°]", "u"
    );
    for i in 0..model.m() {
        let u = data.u[i];
        println!(
            "{:>5} {:>10.5} {:>10.5} {:>8.2}   [{:+.4}, {:+.4}, {:+.4}]",
            i + 1,
            data.q[i],
            data.q_free[i],
            data.beta[i].to_degrees(),
            u.x,
            u.y,
            u.z
        );
    }
    Ok(())
}

fn fk(c: &Common, q: &[f64], elastic: bool, guess: &PoseArgs) -> Res {
    let pf = load(c)?;
    let model = &pf.model;
    if q.len() != model.m() {
        return Err(format!(
            "--lengths-m has {} values but {} has {} cables",
            q.len(),
            pf.name,
            model.m()
        )
        .into());
    }
    let g = guess.pose(&pf)?;
    let mut data = Data::new(model);
    let opts = FkOptions::default();
    let sol = if elastic {
        forward::elastostatic(model, &mut data, q, &g, &opts)?
    } else {
        forward::least_squares(model, &mut data, q, &g, &opts)?
    };
    if c.json {
        let mut v = json!({
            "platform": pf.name,
            "method": if elastic { "elastostatic" } else { "least_squares" },
            "pose": pose_json(&sol.pose),
            "iterations": sol.iterations,
            "residual": sol.residual_norm,
        });
        if elastic {
            v["forces_n"] = json!(data.f);
        }
        println!("{v}");
        return Ok(());
    }
    println!(
        "{} forward kinematics ({}): {}",
        pf.name,
        if elastic {
            "elastostatic ν_el, eq. 2.42"
        } else {
            "least squares ν, eq. 2.11"
        },
        fmt_pose(&sol.pose)
    );
    println!(
        "iterations {}, residual {:.3e} {}",
        sol.iterations,
        sol.residual_norm,
        if elastic { "N" } else { "m" }
    );
    if elastic {
        for (i, f) in data.f.iter().enumerate() {
            println!("  f_{} = {:>9.1} N", i + 1, f);
        }
    }
    Ok(())
}

fn forces(c: &Common, pa: &PoseArgs) -> Res {
    let pf = load(c)?;
    let model = &pf.model;
    let p = model.params();
    let pose = pa.pose(&pf)?;
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, &pose)?;
    let m = model.m();
    let mut f = vec![0.0; m];
    let fd = statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f)?;
    let (mut fe, mut fi) = (vec![0.0; m], vec![0.0; m]);
    statics::split_internal_external(&data, &p.w_e, &f, &mut fe, &mut fi)?;
    let sections: Vec<_> = pf
        .sections
        .iter()
        .map(|s| {
            (
                s.name.clone(),
                statics::section_wrench(&data, &f, &s.cables),
            )
        })
        .collect();
    if c.json {
        let secs: serde_json::Map<_, _> = sections
            .iter()
            .map(|(n, w)| (n.clone(), json!(w.as_slice())))
            .collect();
        println!(
            "{}",
            json!({
                "platform": pf.name, "pose": pose_json(&pose),
                "forces_n": f, "external_n": fe, "internal_n": fi,
                "f_min_n": p.f_min, "f_max_n": p.f_max, "feasible": fd.feasible, "margin_n": fd.margin,
                "section_wrenches": secs,
            })
        );
        return Ok(());
    }
    println!("{} at {}", pf.name, fmt_pose(&pose));
    println!(
        "closed-form force distribution (eq. 3.41), limits [{:.0}, {:.0}] N",
        p.f_min, p.f_max
    );
    println!(
        "{:>5} {:>10} {:>10} {:>10}",
        "cable", "f [N]", "f_ext [N]", "f_int [N]"
    );
    for i in 0..m {
        println!(
            "{:>5} {:>10.1} {:>10.1} {:>10.1}",
            i + 1,
            f[i],
            fe[i],
            fi[i]
        );
    }
    println!(
        "verdict: {} (min {:.1} N on cable {}, max {:.1} N on cable {}, margin {:.1} N)",
        if fd.feasible {
            "FEASIBLE"
        } else {
            "NOT FEASIBLE"
        },
        fd.f_lo,
        fd.cable_lo + 1,
        fd.f_hi,
        fd.cable_hi + 1,
        fd.margin
    );
    for (name, w) in &sections {
        println!(
            "section wrench {name} (eq. 5.11): f = [{:.0}, {:.0}, {:.0}] N, τ = [{:.0}, {:.0}, {:.0}] N·m",
            w[0], w[1], w[2], w[3], w[4], w[5]
        );
    }
    Ok(())
}

fn stiffness(c: &Common, pa: &PoseArgs) -> Res {
    let pf = load(c)?;
    let model = &pf.model;
    let p = model.params();
    let pose = pa.pose(&pf)?;
    let m = model.m();
    let mut data = Data::new(model);
    kinematics::inverse(model, &mut data, &pose)?;
    let mut f = vec![0.0; m];
    statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f)?;
    let mut qt = vec![0.0; m];
    elastostatics::inverse(model, &mut data, &pose, &f, &mut qt)?;
    elastostatics::cable_forces(&mut data, &model.linear_law(), &qt);
    let s = Stiffness::at(model, &data);
    let k_sys = -s.k_wx; // positive-definite stiffness, δw = −K_wx δx (eq. 2.76)
    let eig = k_sys.symmetric_eigen().eigenvalues;
    let translational = [k_sys[(0, 0)], k_sys[(1, 1)], k_sys[(2, 2)]];
    if c.json {
        let mat = |m: &Matrix6<f64>| {
            (0..6)
                .map(|r| (0..6).map(|k| m[(r, k)]).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        };
        println!(
            "{}",
            json!({
                "platform": pf.name, "pose": pose_json(&pose), "forces_n": f,
                "k_c": mat(&s.k_c), "k_g": mat(&s.k_g), "k_wx": mat(&s.k_wx),
                "stiffness_eigenvalues": eig.as_slice(),
                "translational_stiffness_n_per_m": translational,
            })
        );
        return Ok(());
    }
    println!(
        "{} at {} with the reference forces of eq. 3.41",
        pf.name,
        fmt_pose(&pose)
    );
    for (name, mat) in [
        ("K_C = A^T K A (eq. 2.75)", s.k_c),
        ("K_G (eq. 2.67)", s.k_g),
        ("K_wx = K_G − K_C (eq. 2.76)", s.k_wx),
    ] {
        println!("{name}  [N/m | N | N·m/rad]");
        for r in 0..6 {
            println!(
                "  {}",
                (0..6)
                    .map(|k| format!("{:>12.4e}", mat[(r, k)]))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
        }
    }
    println!(
        "translational stiffness diag(−K_wx): x {:.3e}, y {:.3e}, z {:.3e} N/m; eigenvalues of −K_wx: {}",
        translational[0],
        translational[1],
        translational[2],
        eig.iter()
            .map(|e| format!("{e:.3e}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}

fn workspace_cmd(
    c: &Common,
    min_m: Option<Vec<f64>>,
    max_m: Option<Vec<f64>>,
    rotation_deg: &[f64],
    resolution: usize,
    with_hull: bool,
    csv_path: Option<PathBuf>,
) -> Res {
    let pf = load(c)?;
    let model = &pf.model;
    let mut bounds = pf.region.position;
    if let Some(v) = min_m {
        bounds.min = triple("--min-m", &v)?;
    }
    if let Some(v) = max_m {
        bounds.max = triple("--max-m", &v)?;
    }
    if (0..3).any(|k| bounds.min[k] >= bounds.max[k]) {
        return Err("--min-m must be below --max-m on every axis".into());
    }
    if resolution < 2 {
        return Err("--resolution must be at least 2".into());
    }
    let phi = triple("--rotation-deg", rotation_deg)?.map(f64::to_radians);
    let g = workspace::sample_grid(model, &bounds, &phi, [resolution; 3]);
    let hull = if with_hull {
        Some(workspace::hull(model, &pf.home.r, &phi, 2, 10.0, 1e-3)?)
    } else {
        None
    };
    if let Some(path) = &csv_path {
        let mut w = csv::Writer::from_path(path)?;
        w.write_record(["x_m", "y_m", "z_m", "feasible", "boundary"])?;
        for (r, ok) in &g.points {
            let b = g.boundary.iter().any(|p| p == r);
            w.write_record([
                r.x.to_string(),
                r.y.to_string(),
                r.z.to_string(),
                ok.to_string(),
                b.to_string(),
            ])?;
        }
        w.flush()?;
    }
    if c.json {
        println!(
            "{}",
            json!({
                "platform": pf.name,
                "box_min_m": bounds.min.as_slice(), "box_max_m": bounds.max.as_slice(),
                "rotation_deg": rotation_deg, "resolution": resolution,
                "points": g.total, "feasible": g.feasible, "fraction": g.fraction,
                "feasible_volume_m3": g.volume, "boundary_points": g.boundary.len(),
                "hull_volume_m3": hull.as_ref().map(|h| h.volume),
            })
        );
        return Ok(());
    }
    println!(
        "{}: wrench-feasible workspace (eq. 3.29, closed-form forces eq. 3.41) at φ = [{:.1}, {:.1}, {:.1}]°",
        pf.name, rotation_deg[0], rotation_deg[1], rotation_deg[2]
    );
    println!(
        "box [{:.2}, {:.2}, {:.2}] .. [{:.2}, {:.2}, {:.2}] m, {}³ grid: {} of {} feasible ({:.1} %), ≈ {:.2} m³, {} boundary points",
        bounds.min.x,
        bounds.min.y,
        bounds.min.z,
        bounds.max.x,
        bounds.max.y,
        bounds.max.z,
        resolution,
        g.feasible,
        g.total,
        100.0 * g.fraction,
        g.volume,
        g.boundary.len()
    );
    if let Some(h) = hull {
        println!(
            "hull (Pott 2008, {} rays around the home position): volume {:.2} m³",
            h.vertices.len(),
            h.volume
        );
    }
    if let Some(p) = csv_path {
        println!("grid written to {}", p.display());
    }
    Ok(())
}
