//! `crs model workspace --reachable`: the reachable workspace W_R (eq. 3.33–3.35) of the
//! kinematic controller (lengths of the standard model φ, tension set at the home pose) on the
//! elastic robot, predicted by the model library alone, next to the exact wrench-feasible
//! workspace (eq. 3.29) and — with `--plant` — what the simulated plant (sim-plant, its own
//! cable laws and effects) measures when commanded the same lengths. Also the sensitivity map:
//! the linear pose response to a 1 kN payload step (Δx = −K_wx⁻¹ Δw, eq. 2.76 / 3.23) against the
//! plant's measured response. `--svg` draws the horizontal slice through the home position.

use super::Res;
use cdpr_model::config::Platform;
use cdpr_model::workspace::{self, PositionBox, Reach, ReachableAnalysis};
use cdpr_model::{Data, Pose};
use crs_stack::reachable_on_plant::{Measured, measure_with_plant, payload_step};
use nalgebra::Vector3;
use serde_json::json;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub(super) struct ReachableRequest<'a> {
    pub pf: &'a Platform,
    pub platform_path: &'a Path,
    pub bounds: PositionBox,
    pub phi: Vector3<f64>,
    pub resolution: usize,
    pub plant: Option<PathBuf>,
    pub svg: Option<PathBuf>,
    pub json: bool,
}

pub(super) fn reachable_cmd(r: &ReachableRequest) -> Res {
    let pf = r.pf;
    let model = &pf.model;
    let n = r.resolution;
    let lin = |a: f64, b: f64, k: usize| a + (b - a) * k as f64 / (n - 1) as f64;
    let mut refs = Vec::with_capacity(n * n * n);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let p = Vector3::new(
                    lin(r.bounds.min.x, r.bounds.max.x, i),
                    lin(r.bounds.min.y, r.bounds.max.y, j),
                    lin(r.bounds.min.z, r.bounds.max.z, k),
                );
                refs.push(Pose::new(p, r.phi));
            }
        }
    }
    let f_ini = workspace::setup_tension(model, &pf.home, pf.f_ini.as_deref())?;
    let t0 = std::time::Instant::now();
    let pred =
        workspace::reachable_kinematic(model, model, &pf.home, &f_ini, &refs, &payload_step())?;
    let t_pred = t0.elapsed().as_secs_f64();
    let mut data = Data::new(model);
    let exact: Vec<bool> = refs
        .iter()
        .map(|x| workspace::check_pose_exact(model, &mut data, x).is_ok_and(|e| e.feasible))
        .collect();
    let t1 = std::time::Instant::now();
    let measured = match &r.plant {
        Some(p) => {
            let (ms, note) = measure_with_plant(p, r.platform_path, pf, &refs, &f_ini)?;
            if let Some(n) = note {
                eprintln!("{n}");
            }
            Some(ms)
        }
        None => None,
    };
    let t_plant = t1.elapsed().as_secs_f64();
    // Volume of a point: the box volume over the grid points (as `crs model workspace`).
    let cell = r.bounds.volume() / refs.len() as f64;
    let n_exact = exact.iter().filter(|b| **b).count();
    let n_pred = pred.reachable();
    let pred_ok: Vec<bool> = pred
        .points
        .iter()
        .map(|(_, o)| {
            matches!(
                o,
                Reach::Settled {
                    within_limits: true,
                    ..
                }
            )
        })
        .collect();
    let plant_summary = measured.as_ref().map(|ms| {
        let ok: Vec<bool> = ms
            .iter()
            .map(|m| matches!(m, Measured::Reachable { .. }))
            .collect();
        let n_meas = ok.iter().filter(|b| **b).count();
        let agree = ok.iter().zip(&pred_ok).filter(|(a, b)| a == b).count();
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
        let errs: Vec<f64> = ms
            .iter()
            .filter_map(|m| match m {
                Measured::Reachable { error_m, .. } => Some(*error_m),
                _ => None,
            })
            .collect();
        (n_meas, agree, failed, rel, errs)
    });
    if let Some(path) = &r.svg {
        write_svg(path, r, &refs, &exact, &pred, measured.as_deref())?;
    }
    let (mean_e, max_e) = pred.position_error().unzip();
    let (mean_lin, max_lin) = pred.linearisation_error().unzip();
    if r.json {
        let mut v = json!({
            "platform": pf.name, "resolution": n, "points": refs.len(),
            "box_min_m": r.bounds.min.as_slice(), "box_max_m": r.bounds.max.as_slice(),
            "f_ini_n": pred.f_ini,
            "exact_feasible": n_exact, "exact_volume_m3": n_exact as f64 * cell,
            "reachable_predicted": n_pred, "reachable_predicted_volume_m3": n_pred as f64 * cell,
            "predicted_fk_failures": pred.fk_failures(),
            "predicted_mean_error_m": mean_e, "predicted_max_error_m": max_e,
            "linearisation_error_mean_m": mean_lin, "linearisation_error_max_m": max_lin,
            "linear_prediction_failures": pred.linear_failures(),
            "predict_seconds": t_pred,
        });
        if let Some((n_meas, agree, failed, rel, errs)) = &plant_summary {
            v["plant"] = json!({
                "config": r.plant.as_ref().map(|p| p.display().to_string()),
                "reachable": n_meas, "volume_m3": *n_meas as f64 * cell,
                "agreement": *agree as f64 / refs.len() as f64, "failed": failed,
                "mean_error_m": (!errs.is_empty()).then(|| errs.iter().sum::<f64>() / errs.len() as f64),
                "sensitivity_rel_error_median": rel.get(rel.len() / 2),
                "sensitivity_rel_error_max": rel.last(),
                "seconds": t_plant,
            });
        }
        println!("{v}");
        return Ok(());
    }
    println!(
        "{}: reachable workspace of the kinematic controller (eq. 3.33-3.35), tension set at home, {}³ grid of [{:.2}, {:.2}, {:.2}] .. [{:.2}, {:.2}, {:.2}] m",
        pf.name,
        n,
        r.bounds.min.x,
        r.bounds.min.y,
        r.bounds.min.z,
        r.bounds.max.x,
        r.bounds.max.y,
        r.bounds.max.z
    );
    println!(
        "  W_WF exact (eq. 3.29)            {:>6} points  ≈ {:.2} m³",
        n_exact,
        n_exact as f64 * cell
    );
    println!(
        "  W_R predicted (model, full FK)   {:>6} points  ≈ {:.2} m³ ({:.1} % of W_WF){}",
        n_pred,
        n_pred as f64 * cell,
        100.0 * n_pred as f64 / n_exact.max(1) as f64,
        match (mean_e, max_e) {
            (Some(a), Some(b)) =>
                format!(", pose error mean {:.1} / max {:.1} mm", a * 1e3, b * 1e3),
            _ => String::new(),
        }
    );
    if let (Some(a), Some(b)) = (mean_lin, max_lin) {
        println!(
            "  linear prediction of the pose error (eq. 3.24) vs the full FK: mean {:.2} / max {:.2} mm apart",
            a * 1e3,
            b * 1e3
        );
    }
    if pred.linear_failures() > 0 {
        println!(
            "  the linear prediction (eq. 3.24) failed (singular K_wx) on {} reachable poses: left out of the figure above",
            pred.linear_failures()
        );
    }
    if pred.fk_failures() > 0 {
        println!(
            "  the elastostatic FK failed on {} of {} reference poses (counted as not reachable)",
            pred.fk_failures(),
            refs.len()
        );
    }
    if let Some((n_meas, agree, failed, rel, errs)) = &plant_summary {
        println!(
            "  W_R measured by the plant        {:>6} points  ≈ {:.2} m³ ({}); prediction agrees on {:.1} % of the grid{}",
            n_meas,
            *n_meas as f64 * cell,
            r.plant
                .as_ref()
                .map(|p| p.display().to_string())
                .unwrap_or_default(),
            100.0 * *agree as f64 / refs.len() as f64,
            if *failed > 0 {
                format!(", plant failed on {failed} poses")
            } else {
                String::new()
            }
        );
        if !errs.is_empty() {
            println!(
                "  plant pose error in its W_R: mean {:.1} mm",
                1e3 * errs.iter().sum::<f64>() / errs.len() as f64
            );
        }
        if let (Some(med), Some(max)) = (rel.get(rel.len() / 2), rel.last()) {
            println!(
                "  sensitivity to +1 kN payload: predicted |Δr| = |K_wx⁻¹Δw| vs measured, relative error median {:.2} %, max {:.2} % ({} poses)",
                100.0 * med,
                100.0 * max,
                rel.len()
            );
        }
    }
    if let Some(p) = &r.svg {
        println!("  map of the slice through home written to {}", p.display());
    }
    Ok(())
}

fn write_svg(
    path: &Path,
    r: &ReachableRequest,
    refs: &[Pose],
    exact: &[bool],
    pred: &ReachableAnalysis,
    measured: Option<&[Measured]>,
) -> Res {
    let n = r.resolution;
    // The z layer nearest the home position.
    let kz = (0..n)
        .min_by(|&a, &b| {
            (refs[a].r.z - r.pf.home.r.z)
                .abs()
                .total_cmp(&(refs[b].r.z - r.pf.home.r.z).abs())
        })
        .unwrap_or(0);
    let (w, h) = (
        r.bounds.max.x - r.bounds.min.x,
        r.bounds.max.y - r.bounds.min.y,
    );
    let s = 520.0 / w.max(h);
    let cw = w / (n - 1) as f64 * s;
    let ch = h / (n - 1) as f64 * s;
    let px = |x: f64| 20.0 + cw / 2.0 + (x - r.bounds.min.x) * s;
    let py = |y: f64| 20.0 + ch / 2.0 + (r.bounds.max.y - y) * s;
    let mut svg = String::new();
    writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{:.0}" height="{:.0}" font-family="sans-serif" font-size="12">"#,
        (w * s + 40.0 + cw).max(640.0),
        h * s + 110.0 + ch
    )?;
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
    for (idx, x) in refs.iter().enumerate() {
        if idx % n != kz {
            continue;
        }
        let (fill, opacity) = match &pred.points[idx].1 {
            Reach::Settled {
                within_limits: true,
                compliance_dr_m,
                ..
            } => (
                "#1f6fbf",
                // No compliance (singular K_wx): the lightest shade, not a number.
                0.25 + 0.75 * compliance_dr_m.unwrap_or(0.0) / max_dr.max(1e-12),
            ),
            _ if exact[idx] => ("#b0b0b0", 1.0),
            _ => continue,
        };
        writeln!(
            svg,
            r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="{fill}" fill-opacity="{opacity:.2}"/>"#,
            px(x.r.x) - cw / 2.0,
            py(x.r.y) - ch / 2.0,
            cw * 0.92,
            ch * 0.92
        )?;
        if let Some(ms) = measured {
            let pred_ok = matches!(
                pred.points[idx].1,
                Reach::Settled {
                    within_limits: true,
                    ..
                }
            );
            let meas_ok = matches!(ms[idx], Measured::Reachable { .. });
            if pred_ok != meas_ok {
                writeln!(
                    svg,
                    r##"<circle cx="{:.1}" cy="{:.1}" r="{:.1}" fill="none" stroke="#d62728" stroke-width="2"/>"##,
                    px(x.r.x),
                    py(x.r.y),
                    cw.min(ch) * 0.3
                )?;
            }
        }
    }
    let y0 = h * s + 45.0 + ch;
    writeln!(
        svg,
        r#"<text x="20" y="{y0:.0}">slice z = {:.2} m. Blue: W_R predicted (darker = larger |Δr| for +1 kN payload, max {:.2} mm)</text>"#,
        refs[kz].r.z,
        max_dr * 1e3
    )?;
    writeln!(
        svg,
        r#"<text x="20" y="{:.0}">grey: wrench feasible (exact, eq. 3.29) but not reachable by the kinematic controller</text>"#,
        y0 + 18.0
    )?;
    writeln!(
        svg,
        r#"<text x="20" y="{:.0}">red circles: the plant ({}) disagrees with the prediction</text></svg>"#,
        y0 + 36.0,
        r.plant
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "not run".into())
    )?;
    std::fs::write(path, svg)?;
    Ok(())
}
