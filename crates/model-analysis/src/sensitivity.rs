//! How far the platform lands from where the controller believes it is when the model's
//! parameters are wrong (eq. 3.25–3.28) — per parameter at one pose, and as a map of the expected
//! (RMS) position error over the operating region. It tells a designer how accurately the frame
//! and platform anchors and the cable stiffness must be known.

use crate::{AnalysisError, fmt_pose, pose_json};
use cdpr_analysis::sensitivity::{
    self, Parameter, ParameterErrors, ParameterSensitivity, PoseErrorEstimate,
};
use cdpr_model::config::Platform;
use cdpr_model::{Data, Model, Pose, workspace};
use crs_limits::quantile::quantile_sorted;
use crs_plot::{Chart, Figure, Panel, Rect, Rgb};
use nalgebra::Vector3;
use serde_json::json;
use std::fmt;
use std::path::{Path, PathBuf};

/// The parameter uncertainties in the units people give them, and what to show.
#[derive(Clone, Debug)]
pub struct SensitivityRequest {
    /// Standard deviation of every frame-anchor coordinate a_i, mm.
    pub frame_anchor_sigma_mm: f64,
    /// Standard deviation of every platform-anchor coordinate b_i, mm.
    pub platform_anchor_sigma_mm: f64,
    /// Standard deviation of every cable's k_F, percent of its value.
    pub stiffness_sigma_pct: f64,
    /// Parameters listed in the table.
    pub top: usize,
    /// Grid points per axis of the map over the operating region (level platform); none = no
    /// map. At least 2.
    pub map_resolution: Option<usize>,
}

impl SensitivityRequest {
    /// The uncertainties in SI units (m, relative).
    pub fn errors(&self) -> ParameterErrors {
        ParameterErrors {
            frame_anchor_m: self.frame_anchor_sigma_mm * 1e-3,
            platform_anchor_m: self.platform_anchor_sigma_mm * 1e-3,
            stiffness_rel: self.stiffness_sigma_pct * 1e-2,
        }
    }
}

/// One point of the map.
pub enum MapPoint {
    /// RMS position error, m.
    Estimated(f64),
    NotFeasible,
    Failed(String),
}

/// One parameter's row: name, ∂r/∂p and ∂φ/∂p, its gain in reader's units and its
/// contribution at the given σ (m).
pub struct ParameterRow {
    pub name: String,
    pub dr_dp: [f64; 3],
    pub dphi_dp: [f64; 3],
    pub gain: f64,
    pub gain_unit: &'static str,
    pub contribution_m: f64,
}

/// The per-parameter sensitivity at a pose and, when asked, the map.
pub struct SensitivityReport {
    /// The platform as named to the reader (its TOML path).
    pub platform: String,
    pub request: SensitivityRequest,
    pub errors: ParameterErrors,
    pub pose: Pose,
    /// The commanded forces at the pose, N.
    pub forces: Vec<f64>,
    pub estimate: PoseErrorEstimate,
    /// RMS position error of the frame anchors, platform anchors and stiffness alone, m.
    pub groups: [f64; 3],
    /// Every parameter, largest contribution first.
    pub parameters: Vec<ParameterRow>,
    /// The map's points (x slowest, z fastest) with the region it covers.
    pub map: Option<Vec<(Pose, MapPoint)>>,
    region: cdpr_model::workspace::PositionBox,
    home_z: f64,
    /// The SVG of the map's slice, once written.
    pub svg: Option<PathBuf>,
}

/// RMS position error of one parameter group alone, m.
fn group_rms(s: &ParameterSensitivity, model: &Model, e: &ParameterErrors, g: usize) -> f64 {
    let only = ParameterErrors {
        frame_anchor_m: if g == 0 { e.frame_anchor_m } else { 0.0 },
        platform_anchor_m: if g == 1 { e.platform_anchor_m } else { 0.0 },
        stiffness_rel: if g == 2 { e.stiffness_rel } else { 0.0 },
    };
    s.pose_error(model, &only).rms_position_m
}

/// Position gain of one parameter in the unit a reader thinks in: mm per mm of anchor error,
/// mm per percent of k_F.
fn gain(s: &ParameterSensitivity, model: &Model, j: usize) -> (f64, &'static str) {
    let c = s.j_xp.column(j);
    let g = Vector3::new(c[0], c[1], c[2]).norm();
    match s.params[j] {
        Parameter::Stiffness { cable } => (g * 1e3 * model.params().k_f[cable] * 1e-2, "mm/%"),
        _ => (g, "mm/mm"),
    }
}

fn map(pf: &Platform, e: &ParameterErrors, n: usize) -> Vec<(Pose, MapPoint)> {
    let model = &pf.model;
    let b = pf.region.position;
    let mut data = Data::new(model);
    let mut f = vec![0.0; model.m()];
    let mut out = Vec::with_capacity(n * n * n);
    for ix in 0..n {
        for iy in 0..n {
            for iz in 0..n {
                let t = |i: usize, k: usize| {
                    b.min[k] + (b.max[k] - b.min[k]) * i as f64 / (n - 1) as f64
                };
                let x = Pose::new(Vector3::new(t(ix, 0), t(iy, 1), t(iz, 2)), Vector3::zeros());
                let pt = match workspace::check_pose(model, &mut data, &x, &mut f) {
                    Ok(fd) if fd.feasible => {
                        match sensitivity::parameter_sensitivity(model, &x, &f) {
                            Ok(s) => MapPoint::Estimated(s.pose_error(model, e).rms_position_m),
                            Err(err) => MapPoint::Failed(err.to_string()),
                        }
                    }
                    Ok(_) => MapPoint::NotFeasible,
                    Err(err) => MapPoint::Failed(err.to_string()),
                };
                out.push((x, pt));
            }
        }
    }
    out
}

/// The sensitivity of `pf` (named `label` to the reader) at `pose` for the uncertainties of
/// `request`. A pose the closed form cannot hold is an error: the controller has no forces to
/// command there.
pub fn sensitivity(
    pf: &Platform,
    label: &str,
    pose: &Pose,
    request: &SensitivityRequest,
) -> Result<SensitivityReport, AnalysisError> {
    let model = &pf.model;
    let e = request.errors();
    let mut data = Data::new(model);
    let mut f = vec![0.0; model.m()];
    let fd = workspace::check_pose(model, &mut data, pose, &mut f)?;
    if !fd.feasible {
        let low = fd.f_lo < model.params().f_min;
        return Err(AnalysisError::PoseNotFeasible {
            pose: fmt_pose(pose),
            cable: if low { fd.cable_lo } else { fd.cable_hi },
            force_n: if low { fd.f_lo } else { fd.f_hi },
        });
    }
    let s = sensitivity::parameter_sensitivity(model, pose, &f)?;
    let estimate = s.pose_error(model, &e);
    let groups = [0, 1, 2].map(|g| group_rms(&s, model, &e, g));
    let mut order: Vec<usize> = (0..s.params.len()).collect();
    // Rank by contribution to the expected error (gain × σ), the question a designer asks.
    let contrib = |j: usize| s.contribution(j, &e, model).0;
    order.sort_by(|&i, &j| contrib(j).total_cmp(&contrib(i)));
    let parameters = order
        .iter()
        .map(|&j| {
            let c = s.j_xp.column(j);
            let (gain, gain_unit) = gain(&s, model, j);
            ParameterRow {
                name: s.params[j].name(),
                dr_dp: [c[0], c[1], c[2]],
                dphi_dp: [c[3], c[4], c[5]],
                gain,
                gain_unit,
                contribution_m: contrib(j),
            }
        })
        .collect();
    Ok(SensitivityReport {
        platform: label.to_string(),
        request: request.clone(),
        pose: *pose,
        forces: s.forces.clone(),
        estimate,
        groups,
        parameters,
        map: request.map_resolution.map(|n| map(pf, &e, n)),
        errors: e,
        region: pf.region.position,
        home_z: pf.home.r.z,
        svg: None,
    })
}

/// The map's figures: estimated points sorted by error, not-feasible count, failures, total.
struct MapStats<'a> {
    vals: Vec<(f64, Pose)>,
    not_feasible: usize,
    failed: Vec<&'a str>,
    total: usize,
}

impl SensitivityReport {
    fn map_stats(&self) -> Option<MapStats<'_>> {
        let pts = self.map.as_ref()?;
        let mut vals: Vec<(f64, Pose)> = pts
            .iter()
            .filter_map(|(x, p)| match p {
                MapPoint::Estimated(v) => Some((*v, *x)),
                _ => None,
            })
            .collect();
        vals.sort_by(|a, b| a.0.total_cmp(&b.0));
        let not_feasible = pts
            .iter()
            .filter(|(_, p)| matches!(p, MapPoint::NotFeasible))
            .count();
        let failed = pts
            .iter()
            .filter_map(|(_, p)| match p {
                MapPoint::Failed(m) => Some(m.as_str()),
                _ => None,
            })
            .collect();
        Some(MapStats {
            vals,
            not_feasible,
            failed,
            total: pts.len(),
        })
    }

    pub fn json(&self) -> serde_json::Value {
        let e = &self.errors;
        let params: Vec<_> = self
            .parameters
            .iter()
            .map(|p| {
                json!({
                    "name": p.name,
                    "dr_dp": p.dr_dp,
                    "dphi_dp": p.dphi_dp,
                    "contribution_m": p.contribution_m,
                })
            })
            .collect();
        let mut v = json!({
            "platform": self.platform,
            "pose": pose_json(&self.pose),
            "forces_n": self.forces,
            "errors": {
                "frame_anchor_sigma_m": e.frame_anchor_m,
                "platform_anchor_sigma_m": e.platform_anchor_m,
                "stiffness_sigma_rel": e.stiffness_rel,
            },
            "rms_position_m": self.estimate.rms_position_m,
            "rms_rotation_rad": self.estimate.rms_rotation_rad,
            "groups_rms_position_m": {
                "frame_anchors": self.groups[0],
                "platform_anchors": self.groups[1],
                "stiffness": self.groups[2],
            },
            "parameters": params,
        });
        if let Some(m) = self.map_stats() {
            let rms: Vec<f64> = m.vals.iter().map(|v| v.0).collect();
            v["map"] = json!({
                "points": m.total,
                "estimated": m.vals.len(),
                "not_wrench_feasible": m.not_feasible,
                "failed": m.failed.len(),
                "failures": m.failed,
                "median_rms_position_m": quantile_sorted(&rms, 0.5),
                "p95_rms_position_m": quantile_sorted(&rms, 0.95),
                "max_rms_position_m": m.vals.last().map(|v| v.0),
                "max_at": m.vals.last().map(|v| pose_json(&v.1)),
            });
        }
        v
    }

    /// The map's slice through the home height; nothing without a map.
    pub fn write_svg(&mut self, path: &Path) -> Result<(), AnalysisError> {
        let Some(pts) = &self.map else {
            return Ok(());
        };
        let (b, e) = (&self.region, &self.errors);
        let n = ((pts.len() as f64).cbrt().round() as usize).max(1);
        let steps = n.saturating_sub(1).max(1) as f64;
        let z = |k: usize| b.min.z + (b.max.z - b.min.z) * k as f64 / steps;
        // The z layer nearest the home height.
        let kz = (0..n)
            .min_by(|&i, &j| {
                (z(i) - self.home_z)
                    .abs()
                    .total_cmp(&(z(j) - self.home_z).abs())
            })
            .unwrap_or(0);
        let (cw, ch) = ((b.max.x - b.min.x) / steps, (b.max.y - b.min.y) / steps);
        let max = pts
            .iter()
            .filter_map(|(_, p)| match p {
                MapPoint::Estimated(v) => Some(*v),
                _ => None,
            })
            .fold(0.0, f64::max);
        let mut c = Chart::new("", "x (m)", "y (m)");
        c.equal_scale = true;
        c.x_range = Some((b.min.x - cw / 2.0, b.max.x + cw / 2.0));
        c.y_range = Some((b.min.y - ch / 2.0, b.max.y + ch / 2.0));
        // Numbers in the cells while they fit (up to 19 cells a row).
        let labelled = n <= 19;
        for (x, p) in pts
            .iter()
            .enumerate()
            .filter(|(idx, _)| idx % n == kz)
            .map(|(_, v)| v)
        {
            let (fill, opacity, label) = match p {
                MapPoint::Estimated(v) => (
                    ESTIMATED,
                    0.15 + 0.85 * v / max.max(1e-12),
                    labelled.then(|| format!("{:.1}", v * 1e3)),
                ),
                MapPoint::NotFeasible => (NOT_FEASIBLE, 1.0, None),
                MapPoint::Failed(_) => (Rgb::BLACK, 1.0, None),
            };
            let (hx, hy) = (0.47 * cw, 0.47 * ch);
            let mut cell = Rect::filled(
                (x.r.x - hx, x.r.y - hy),
                (x.r.x + hx, x.r.y + hy),
                fill,
                opacity,
            );
            cell.text = label;
            c.rects.push(cell);
        }
        let mut figure = Figure::single(
            format!(
                "{}: pose sensitivity to parameter errors (eq. 3.28)",
                self.platform
            ),
            (720, 800),
            Panel::Chart(c),
        );
        figure.notes = vec![
            format!(
                "slice z = {:.2} m, level platform: RMS position error (mm, eq. 3.28) for σ(a) = {:.1} mm, σ(b) = {:.1} mm, σ(k_F) = {:.0} %; max {:.2} mm",
                z(kz),
                e.frame_anchor_m * 1e3,
                e.platform_anchor_m * 1e3,
                e.stiffness_rel * 1e2,
                max * 1e3
            ),
            "grey: not wrench feasible with the closed form (eq. 3.41); black: computation failed"
                .into(),
        ];
        std::fs::write(path, figure.svg()?)?;
        self.svg = Some(path.to_path_buf());
        Ok(())
    }
}

const ESTIMATED: Rgb = Rgb(0xd9, 0x5f, 0x02);
const NOT_FEASIBLE: Rgb = Rgb(0xb0, 0xb0, 0xb0);

impl fmt::Display for SensitivityReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (r, est, groups) = (&self.request, &self.estimate, &self.groups);
        writeln!(
            f,
            "Pose sensitivity to parameter errors (eq. 3.28) — {}",
            self.platform
        )?;
        writeln!(
            f,
            "  pose {} with the closed-form forces of eq. 3.41",
            fmt_pose(&self.pose)
        )?;
        writeln!(
            f,
            "  independent errors: σ(a_i) = {} mm, σ(b_i) = {} mm, σ(k_F) = {} %",
            r.frame_anchor_sigma_mm, r.platform_anchor_sigma_mm, r.stiffness_sigma_pct
        )?;
        writeln!(
            f,
            "  expected pose error: {:.2} mm RMS position, {:.3}° RMS rotation",
            est.rms_position_m * 1e3,
            est.rms_rotation_rad.to_degrees()
        )?;
        writeln!(
            f,
            "  by group: frame anchors {:.2} mm, platform anchors {:.2} mm, cable stiffness {:.2} mm",
            groups[0] * 1e3,
            groups[1] * 1e3,
            groups[2] * 1e3
        )?;
        writeln!(
            f,
            "  largest contributions (|∂r/∂p| per unit, contribution at the σ above):"
        )?;
        for p in self.parameters.iter().take(r.top) {
            writeln!(
                f,
                "    {:<8} {:>8.3} {:<6} {:>7.3} mm",
                p.name,
                p.gain,
                p.gain_unit,
                p.contribution_m * 1e3
            )?;
        }
        if let Some(m) = self.map_stats() {
            let (nf, failed, total) = (m.not_feasible, &m.failed, m.total);
            writeln!(
                f,
                "  map over the operating region (level platform, {total} grid points):"
            )?;
            match m.vals.last() {
                None => writeln!(
                    f,
                    "    no point could be estimated ({nf} not wrench feasible, {} failed)",
                    failed.len()
                )?,
                Some(worst) => {
                    let v: Vec<f64> = m.vals.iter().map(|v| v.0).collect();
                    writeln!(
                        f,
                        "    RMS position error: median {:.2} mm, 95 % {:.2} mm, max {:.2} mm at [{:.2}, {:.2}, {:.2}] m",
                        quantile_sorted(&v, 0.5).unwrap_or(f64::NAN) * 1e3,
                        quantile_sorted(&v, 0.95).unwrap_or(f64::NAN) * 1e3,
                        worst.0 * 1e3,
                        worst.1.r.x,
                        worst.1.r.y,
                        worst.1.r.z
                    )?;
                    writeln!(
                        f,
                        "    {} estimated, {nf} not wrench feasible (closed form){}",
                        m.vals.len(),
                        if failed.is_empty() {
                            String::new()
                        } else {
                            format!(", {} FAILED (first: {})", failed.len(), failed[0])
                        }
                    )?;
                }
            }
        }
        if let Some(p) = &self.svg {
            writeln!(f, "  map slice written to {}", p.display())?;
        }
        Ok(())
    }
}
