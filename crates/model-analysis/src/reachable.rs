//! The reachable workspace W_R (eq. 3.33–3.35) of the kinematic controller (lengths of the
//! standard model φ, tension set at the home pose) on the elastic robot, predicted by the model
//! alone, next to the exact wrench-feasible workspace (eq. 3.29) and — when given — what a plant
//! measured when commanded the same lengths. Also the sensitivity map: the linear pose response
//! to a 1 kN payload step (Δx = −K_wx⁻¹ Δw, eq. 2.76 / 3.23) against the plant's measured
//! response. [`ReachableReport::write_svg`] draws the horizontal slice through the home position.

use crate::AnalysisError;
use cdpr_model::config::Platform;
use cdpr_model::workspace::{self, PositionBox, Reach, ReachableAnalysis};
use cdpr_model::{Data, Pose};
use crs_limits::quantile::quantile_sorted;
use crs_plot::{Chart, Figure, Markers, Panel, Rect, Rgb};
use nalgebra::{Vector3, Vector6};
use serde_json::json;
use std::fmt;
use std::path::{Path, PathBuf};

/// What a plant did at one reference pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Measured {
    /// Forces within the limits; position error |r_M − r| (m) and the measured |Δr| (m) under the
    /// payload step.
    Reachable {
        error_m: f64,
        dr_m: f64,
    },
    OutOfLimits,
    Failed,
}

/// The wrench step of the sensitivity map: 1 kN more payload.
pub fn payload_step() -> Vector6<f64> {
    Vector6::new(0.0, 0.0, -1000.0, 0.0, 0.0, 0.0)
}

/// The model's side: the reference grid, the set-up tension and the prediction at each point.
pub struct Prediction {
    /// The `resolution`³ reference poses (x slowest, z fastest).
    pub refs: Vec<Pose>,
    /// The set-up tension at home (eq. 3.14, 3.19), N.
    pub f_ini: Vec<f64>,
    pub analysis: ReachableAnalysis,
    /// Wrench feasible by the exact test (eq. 3.29), per reference pose.
    pub exact: Vec<bool>,
    /// Time of the full-FK prediction, s.
    pub seconds: f64,
}

/// Predicts W_R of `pf` on the `resolution`³ grid of `bounds` at orientation `phi` (rad).
pub fn predict(
    pf: &Platform,
    bounds: &PositionBox,
    phi: &Vector3<f64>,
    resolution: usize,
) -> Result<Prediction, AnalysisError> {
    let model = &pf.model;
    let n = resolution;
    let lin = |a: f64, b: f64, k: usize| a + (b - a) * k as f64 / (n - 1) as f64;
    let mut refs = Vec::with_capacity(n * n * n);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let p = Vector3::new(
                    lin(bounds.min.x, bounds.max.x, i),
                    lin(bounds.min.y, bounds.max.y, j),
                    lin(bounds.min.z, bounds.max.z, k),
                );
                refs.push(Pose::new(p, *phi));
            }
        }
    }
    let f_ini = workspace::setup_tension(model, &pf.home, pf.f_ini.as_deref())?;
    let t0 = std::time::Instant::now();
    let analysis =
        workspace::reachable_kinematic(model, model, &pf.home, &f_ini, &refs, &payload_step())?;
    let seconds = t0.elapsed().as_secs_f64();
    let mut data = Data::new(model);
    let exact = refs
        .iter()
        .map(|x| workspace::check_pose_exact(model, &mut data, x).is_ok_and(|e| e.feasible))
        .collect();
    Ok(Prediction {
        refs,
        f_ini,
        analysis,
        exact,
        seconds,
    })
}

/// A plant's measurement of the same grid.
pub struct PlantMeasurement {
    /// The plant's name as shown (its TOML path).
    pub config: String,
    /// One per reference pose.
    pub measured: Vec<Measured>,
    /// Time of the measurement, s.
    pub seconds: f64,
}

/// Prediction and plant side by side.
pub struct ReachableReport {
    pub platform: String,
    pub home: Pose,
    pub bounds: PositionBox,
    pub resolution: usize,
    pub prediction: Prediction,
    pub plant: Option<PlantMeasurement>,
    /// The SVG map, once written.
    pub svg: Option<PathBuf>,
}

/// The plant's figures against the prediction.
struct PlantSummary {
    reachable: usize,
    agree: usize,
    failed: usize,
    /// Relative error of the predicted |Δr| where both reach, sorted.
    rel: Vec<f64>,
    /// Pose errors in the measured W_R, m.
    errs: Vec<f64>,
}

fn settled_within(o: &Reach) -> bool {
    matches!(
        o,
        Reach::Settled {
            within_limits: true,
            ..
        }
    )
}

impl ReachableReport {
    pub fn new(
        pf: &Platform,
        bounds: PositionBox,
        resolution: usize,
        prediction: Prediction,
        plant: Option<PlantMeasurement>,
    ) -> Self {
        Self {
            platform: pf.name.clone(),
            home: pf.home,
            bounds,
            resolution,
            prediction,
            plant,
            svg: None,
        }
    }

    /// Volume of a point: the box volume over the grid points (as the workspace grid).
    fn cell(&self) -> f64 {
        self.bounds.volume() / self.prediction.refs.len() as f64
    }

    fn n_exact(&self) -> usize {
        self.prediction.exact.iter().filter(|b| **b).count()
    }

    fn plant_summary(&self) -> Option<PlantSummary> {
        let pred = &self.prediction.analysis;
        let ms = &self.plant.as_ref()?.measured;
        let ok: Vec<bool> = ms
            .iter()
            .map(|m| matches!(m, Measured::Reachable { .. }))
            .collect();
        let reachable = ok.iter().filter(|b| **b).count();
        let agree = ok
            .iter()
            .zip(pred.points.iter().map(|(_, o)| settled_within(o)))
            .filter(|(a, b)| **a == *b)
            .count();
        let failed = ms.iter().filter(|m| matches!(m, Measured::Failed)).count();
        // Sensitivity: predicted vs measured |Δr| where both reach.
        let mut rel = Vec::new();
        for ((_, o), m) in pred.points.iter().zip(ms) {
            if let (
                Reach::Settled {
                    within_limits: true,
                    compliance_dr_m: Some(compliance_dr_m),
                    ..
                },
                Measured::Reachable { dr_m, .. },
            ) = (o, m)
                && *dr_m > 1e-9
            {
                rel.push((compliance_dr_m - dr_m).abs() / dr_m);
            }
        }
        rel.sort_by(f64::total_cmp);
        let errs = ms
            .iter()
            .filter_map(|m| match m {
                Measured::Reachable { error_m, .. } => Some(*error_m),
                _ => None,
            })
            .collect();
        Some(PlantSummary {
            reachable,
            agree,
            failed,
            rel,
            errs,
        })
    }

    pub fn json(&self) -> serde_json::Value {
        let pr = &self.prediction;
        let pred = &pr.analysis;
        let cell = self.cell();
        let n_exact = self.n_exact();
        let n_pred = pred.reachable();
        let (mean_e, max_e) = pred.position_error().unzip();
        let (mean_lin, max_lin) = pred.linearisation_error().unzip();
        let mut v = json!({
            "platform": self.platform, "resolution": self.resolution, "points": pr.refs.len(),
            "box_min_m": self.bounds.min.as_slice(), "box_max_m": self.bounds.max.as_slice(),
            "f_ini_n": pred.f_ini,
            "exact_feasible": n_exact, "exact_volume_m3": n_exact as f64 * cell,
            "reachable_predicted": n_pred, "reachable_predicted_volume_m3": n_pred as f64 * cell,
            "predicted_fk_failures": pred.fk_failures(),
            "predicted_mean_error_m": mean_e, "predicted_max_error_m": max_e,
            "linearisation_error_mean_m": mean_lin, "linearisation_error_max_m": max_lin,
            "linear_prediction_failures": pred.linear_failures(),
            "predict_seconds": pr.seconds,
        });
        if let (Some(s), Some(plant)) = (self.plant_summary(), &self.plant) {
            let (rel, errs) = (&s.rel, &s.errs);
            v["plant"] = json!({
                "config": plant.config,
                "reachable": s.reachable, "volume_m3": s.reachable as f64 * cell,
                "agreement": s.agree as f64 / pr.refs.len() as f64, "failed": s.failed,
                "mean_error_m": (!errs.is_empty()).then(|| errs.iter().sum::<f64>() / errs.len() as f64),
                "sensitivity_rel_error_median": quantile_sorted(rel, 0.5),
                "sensitivity_rel_error_max": rel.last(),
                "seconds": plant.seconds,
            });
        }
        v
    }

    /// The map of the slice through the home position: W_R predicted (shade = |Δr| under the
    /// payload step), wrench feasible only, and where the plant disagrees.
    pub fn write_svg(&mut self, path: &Path) -> Result<(), AnalysisError> {
        let (refs, exact) = (&self.prediction.refs, &self.prediction.exact);
        let pred = &self.prediction.analysis;
        let measured = self.plant.as_ref().map(|p| &p.measured);
        let (n, b) = (self.resolution, &self.bounds);
        // The z layer nearest the home position.
        let home_z = self.home.r.z;
        let kz = (0..n.min(refs.len()))
            .min_by(|&a, &c| {
                (refs[a].r.z - home_z)
                    .abs()
                    .total_cmp(&(refs[c].r.z - home_z).abs())
            })
            .unwrap_or(0);
        let steps = n.saturating_sub(1).max(1) as f64;
        let (cw, ch) = ((b.max.x - b.min.x) / steps, (b.max.y - b.min.y) / steps);
        let max_dr = pred
            .points
            .iter()
            .filter_map(|(_, o)| match o {
                Reach::Settled {
                    compliance_dr_m: Some(dr),
                    within_limits: true,
                    ..
                } => Some(*dr),
                _ => None,
            })
            .fold(0.0, f64::max);
        let mut c = Chart::new("", "x (m)", "y (m)");
        c.equal_scale = true;
        c.x_range = Some((b.min.x - cw / 2.0, b.max.x + cw / 2.0));
        c.y_range = Some((b.min.y - ch / 2.0, b.max.y + ch / 2.0));
        let mut disagree = Markers::new("the plant disagrees", DISAGREE, Vec::new());
        disagree.filled = false;
        disagree.radius = 5;
        for (idx, x) in refs
            .iter()
            .enumerate()
            .filter(|(idx, _)| idx % n.max(1) == kz)
        {
            let (fill, opacity) = match pred.points.get(idx).map(|p| &p.1) {
                Some(Reach::Settled {
                    within_limits: true,
                    compliance_dr_m,
                    ..
                }) => (
                    REACHABLE,
                    // No compliance (singular K_wx): the lightest shade, not a number.
                    0.25 + 0.75 * compliance_dr_m.unwrap_or(0.0) / max_dr.max(1e-12),
                ),
                _ if exact.get(idx).copied().unwrap_or(false) => (FEASIBLE_ONLY, 1.0),
                _ => continue,
            };
            let (hx, hy) = (0.46 * cw, 0.46 * ch);
            c.rects.push(Rect::filled(
                (x.r.x - hx, x.r.y - hy),
                (x.r.x + hx, x.r.y + hy),
                fill,
                opacity,
            ));
            if let (Some(ms), Some((_, o))) = (measured, pred.points.get(idx)) {
                let meas_ok = matches!(ms.get(idx), Some(Measured::Reachable { .. }));
                if settled_within(o) != meas_ok {
                    disagree.points.push((x.r.x, x.r.y));
                }
            }
        }
        if disagree.points.is_empty() {
            disagree.label = None;
        }
        c.markers.push(disagree);
        let mut figure = Figure::single(
            format!(
                "{}: reachable workspace W_R of the kinematic controller (eq. 3.33-3.35)",
                self.platform
            ),
            (720, 800),
            Panel::Chart(c),
        );
        figure.notes = vec![
            format!(
                "slice z = {:.2} m. Blue: W_R predicted (darker = larger |Δr| for +1 kN payload, max {:.2} mm)",
                refs.get(kz).map_or(f64::NAN, |p| p.r.z),
                max_dr * 1e3
            ),
            "grey: wrench feasible (exact, eq. 3.29) but not reachable by the kinematic controller"
                .into(),
            format!(
                "red circles: the plant ({}) disagrees with the prediction",
                self.plant.as_ref().map_or("not run", |p| p.config.as_str())
            ),
        ];
        std::fs::write(path, figure.svg()?)?;
        self.svg = Some(path.to_path_buf());
        Ok(())
    }
}

const REACHABLE: Rgb = Rgb(0x1f, 0x6f, 0xbf);
const FEASIBLE_ONLY: Rgb = Rgb(0xb0, 0xb0, 0xb0);
const DISAGREE: Rgb = Rgb(0xd6, 0x27, 0x28);

impl fmt::Display for ReachableReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let pr = &self.prediction;
        let pred = &pr.analysis;
        let (b, n) = (&self.bounds, self.resolution);
        let cell = self.cell();
        let n_exact = self.n_exact();
        let n_pred = pred.reachable();
        let (mean_e, max_e) = pred.position_error().unzip();
        let (mean_lin, max_lin) = pred.linearisation_error().unzip();
        writeln!(
            f,
            "{}: reachable workspace of the kinematic controller (eq. 3.33-3.35), tension set at home, {}³ grid of [{:.2}, {:.2}, {:.2}] .. [{:.2}, {:.2}, {:.2}] m",
            self.platform, n, b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z
        )?;
        writeln!(
            f,
            "  W_WF exact (eq. 3.29)            {:>6} points  ≈ {:.2} m³",
            n_exact,
            n_exact as f64 * cell
        )?;
        writeln!(
            f,
            "  W_R predicted (model, full FK)   {:>6} points  ≈ {:.2} m³ ({:.1} % of W_WF){}",
            n_pred,
            n_pred as f64 * cell,
            100.0 * n_pred as f64 / n_exact.max(1) as f64,
            match (mean_e, max_e) {
                (Some(a), Some(b)) =>
                    format!(", pose error mean {:.1} / max {:.1} mm", a * 1e3, b * 1e3),
                _ => String::new(),
            }
        )?;
        if let (Some(a), Some(b)) = (mean_lin, max_lin) {
            writeln!(
                f,
                "  linear prediction of the pose error (eq. 3.24) vs the full FK: mean {:.2} / max {:.2} mm apart",
                a * 1e3,
                b * 1e3
            )?;
        }
        if pred.linear_failures() > 0 {
            writeln!(
                f,
                "  the linear prediction (eq. 3.24) failed (singular K_wx) on {} reachable poses: left out of the figure above",
                pred.linear_failures()
            )?;
        }
        if pred.fk_failures() > 0 {
            writeln!(
                f,
                "  the elastostatic FK failed on {} of {} reference poses (counted as not reachable)",
                pred.fk_failures(),
                pr.refs.len()
            )?;
        }
        if let (Some(s), Some(plant)) = (self.plant_summary(), &self.plant) {
            writeln!(
                f,
                "  W_R measured by the plant        {:>6} points  ≈ {:.2} m³ ({}); prediction agrees on {:.1} % of the grid{}",
                s.reachable,
                s.reachable as f64 * cell,
                plant.config,
                100.0 * s.agree as f64 / pr.refs.len() as f64,
                if s.failed > 0 {
                    format!(", plant failed on {} poses", s.failed)
                } else {
                    String::new()
                }
            )?;
            if !s.errs.is_empty() {
                writeln!(
                    f,
                    "  plant pose error in its W_R: mean {:.1} mm",
                    1e3 * s.errs.iter().sum::<f64>() / s.errs.len() as f64
                )?;
            }
            if let (Some(med), Some(max)) = (quantile_sorted(&s.rel, 0.5), s.rel.last()) {
                writeln!(
                    f,
                    "  sensitivity to +1 kN payload: predicted |Δr| = |K_wx⁻¹Δw| vs measured, relative error median {:.2} %, max {:.2} % ({} poses)",
                    100.0 * med,
                    100.0 * max,
                    s.rel.len()
                )?;
            }
        }
        if let Some(p) = &self.svg {
            writeln!(
                f,
                "  map of the slice through home written to {}",
                p.display()
            )?;
        }
        Ok(())
    }
}
