//! `crs model planar`, `crs model truss` and `crs model sensitivity`: the design checks of
//! chapters 3–5 (the spec's planar robot, the cabin's space frame, the pose error caused by
//! parameter errors); their flags here, the analyses in `model_analysis::{planar, truss,
//! sensitivity}`.

use super::{Common, PoseArgs, Res, load, show};
use cdpr_analysis::truss::ROD_EA_DEFAULT_N;
use model_analysis::planar::PlanarRequest;
use model_analysis::sensitivity::SensitivityRequest;
use model_analysis::truss::TrussRequest;
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct PlanarArgs {
    /// Lower force limit f_min, N (fig. 3.20: 1000 N).
    #[arg(long, default_value_t = 1000.0)]
    f_min_n: f64,
    /// Upper force limit f_max, N (fig. 3.18a: 8000 N).
    #[arg(long, default_value_t = 8000.0)]
    f_max_n: f64,
    /// Specific cable stiffness k_F, N (eq. 3.36: 2000 kN/m).
    #[arg(long, default_value_t = 2.0e6)]
    k_f_n: f64,
    /// Grid spacing of the area computations, m.
    #[arg(long, default_value_t = 0.2)]
    grid_m: f64,
    /// Write an SVG map of W_PHYS (exact and closed form) and W_R to this file.
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Machine-readable JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(clap::Args, Debug, Clone)]
pub struct TrussArgs {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    pose: PoseArgs,
    /// Evaluate a grid over the operating region (5 positions per axis × 7 orientations: level
    /// and each axis at its limits) and report the worst member.
    #[arg(long)]
    worst_case: bool,
    /// Extra downward load at every joint (equipment), N; fig. 5.10b uses 10000.
    #[arg(long, default_value_t = 0.0)]
    joint_load_n: f64,
    /// Axial stiffness EA of a rod, N (the spec gives none; forces of the determinate
    /// icosahedron do not depend on it, displacements do).
    #[arg(long, default_value_t = ROD_EA_DEFAULT_N)]
    rod_ea_n: f64,
}

#[derive(clap::Args, Debug, Clone)]
pub struct SensitivityArgs {
    #[command(flatten)]
    common: Common,
    #[command(flatten)]
    pose: PoseArgs,
    /// Standard deviation of every frame-anchor coordinate a_i, mm.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    frame_anchor_sigma_mm: f64,
    /// Standard deviation of every platform-anchor coordinate b_i, mm.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    platform_anchor_sigma_mm: f64,
    /// Standard deviation of every cable's k_F, percent of its value.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    stiffness_sigma_pct: f64,
    /// Parameters listed in the per-parameter table.
    #[arg(long, default_value_t = 10)]
    top: usize,
    /// Also map the expected position error over the operating region (level platform), with
    /// this many grid points per axis.
    #[arg(long)]
    map_resolution: Option<usize>,
    /// SVG of the map's slice through the home height (with --map-resolution).
    #[arg(long, requires = "map_resolution")]
    svg: Option<PathBuf>,
}

pub(super) fn planar(a: &PlanarArgs) -> Res {
    if !(a.grid_m.is_finite() && a.grid_m >= 0.02) {
        return Err("--grid-m must be at least 0.02 m".into());
    }
    let mut r = model_analysis::planar::planar(&PlanarRequest {
        f_min_n: a.f_min_n,
        f_max_n: a.f_max_n,
        k_f_n: a.k_f_n,
        grid_m: a.grid_m,
    })?;
    if let Some(path) = &a.svg {
        r.write_svg(path)?;
    }
    show(a.json, &r);
    Ok(())
}

pub(super) fn truss(a: &TrussArgs) -> Res {
    if !(a.joint_load_n.is_finite() && a.joint_load_n >= 0.0) {
        return Err("--joint-load-n must be a finite force >= 0 N".into());
    }
    let pf = load(&a.common)?;
    let pose = if a.worst_case {
        pf.home
    } else {
        a.pose.pose(&pf)?
    };
    let r = model_analysis::truss::truss(
        &pf,
        &TrussRequest {
            pose,
            worst_case: a.worst_case,
            joint_load_n: a.joint_load_n,
            rod_ea_n: a.rod_ea_n,
        },
    )?;
    show(a.common.json, &r);
    Ok(())
}

pub(super) fn sensitivity(a: &SensitivityArgs) -> Res {
    let pf = load(&a.common)?;
    for (flag, v) in [
        ("--frame-anchor-sigma-mm", a.frame_anchor_sigma_mm),
        ("--platform-anchor-sigma-mm", a.platform_anchor_sigma_mm),
        ("--stiffness-sigma-pct", a.stiffness_sigma_pct),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(format!("{flag} must be a finite number >= 0, got {v}").into());
        }
    }
    if a.map_resolution.is_some_and(|n| n < 2) {
        return Err("--map-resolution must be at least 2".into());
    }
    let x = a.pose.pose(&pf)?;
    let label = a.common.platform.display().to_string();
    let mut r = model_analysis::sensitivity::sensitivity(
        &pf,
        &label,
        &x,
        &SensitivityRequest {
            frame_anchor_sigma_mm: a.frame_anchor_sigma_mm,
            platform_anchor_sigma_mm: a.platform_anchor_sigma_mm,
            stiffness_sigma_pct: a.stiffness_sigma_pct,
            top: a.top,
            map_resolution: a.map_resolution,
        },
    )?;
    if let Some(path) = &a.svg {
        r.write_svg(path)?;
    }
    if a.common.json {
        println!("{}", serde_json::to_string_pretty(&r.json())?);
        return Ok(());
    }
    print!("{r}");
    Ok(())
}
