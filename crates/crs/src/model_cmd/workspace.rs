//! `crs model workspace`: the wrench-feasible constant-orientation workspace (eq. 3.29) on a grid
//! and as a hull (Pott 2008), with the closed-form or the exact feasibility test, or both side by
//! side (the closed form is sufficient only, so its workspace is a subset of the exact one).

use super::{Common, Res, TestArg, load, triple};
use cdpr_model::workspace::{self, FeasibilityTest, GridResult, Hull, PositionBox};
use serde_json::json;
use std::path::PathBuf;

struct Evaluated {
    test: FeasibilityTest,
    grid: GridResult,
    hull: Option<Hull>,
}

/// The box of `--min-m/--max-m` (default: the configured region), validated with the grid size.
pub(super) fn box_from_flags(
    pf: &cdpr_model::config::Platform,
    min_m: Option<Vec<f64>>,
    max_m: Option<Vec<f64>>,
    resolution: usize,
) -> Result<PositionBox, Box<dyn std::error::Error>> {
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
    Ok(bounds)
}

#[allow(clippy::too_many_arguments)]
pub(super) fn workspace_cmd(
    c: &Common,
    min_m: Option<Vec<f64>>,
    max_m: Option<Vec<f64>>,
    rotation_deg: &[f64],
    resolution: usize,
    with_hull: bool,
    test: TestArg,
    csv_path: Option<PathBuf>,
) -> Res {
    let pf = load(c)?;
    let model = &pf.model;
    let bounds = box_from_flags(&pf, min_m, max_m, resolution)?;
    let phi = triple("--rotation-deg", rotation_deg)?.map(f64::to_radians);
    let tests: &[FeasibilityTest] = match test {
        TestArg::ClosedForm => &[FeasibilityTest::ClosedForm],
        TestArg::Exact => &[FeasibilityTest::Exact],
        TestArg::Both => &[FeasibilityTest::ClosedForm, FeasibilityTest::Exact],
    };
    let mut runs = Vec::new();
    for &t in tests {
        let grid = workspace::sample_grid_with(model, &bounds, &phi, [resolution; 3], t);
        let hull = if with_hull {
            Some(workspace::hull_with(
                model, &pf.home.r, &phi, 2, 10.0, 1e-3, t,
            )?)
        } else {
            None
        };
        runs.push(Evaluated {
            test: t,
            grid,
            hull,
        });
    }
    if let Some(path) = &csv_path {
        let mut w = csv::Writer::from_path(path)?;
        let mut header = vec!["x_m", "y_m", "z_m"];
        for r in &runs {
            header.extend(match r.test {
                FeasibilityTest::ClosedForm => ["feasible", "boundary"],
                FeasibilityTest::Exact => ["feasible_exact", "boundary_exact"],
            });
        }
        w.write_record(&header)?;
        for (k, (p, _)) in runs[0].grid.points.iter().enumerate() {
            let mut rec = vec![p.x.to_string(), p.y.to_string(), p.z.to_string()];
            for r in &runs {
                rec.push(r.grid.points[k].1.to_string());
                rec.push(r.grid.boundary.iter().any(|b| b == p).to_string());
            }
            w.write_record(&rec)?;
        }
        w.flush()?;
    }
    let key = |t: FeasibilityTest| match t {
        FeasibilityTest::ClosedForm => "closed_form",
        FeasibilityTest::Exact => "exact",
    };
    if c.json {
        let mut v = json!({
            "platform": pf.name,
            "box_min_m": bounds.min.as_slice(), "box_max_m": bounds.max.as_slice(),
            "rotation_deg": rotation_deg, "resolution": resolution,
        });
        for r in &runs {
            let g = &r.grid;
            let entry = json!({
                "points": g.total, "feasible": g.feasible, "fraction": g.fraction,
                "feasible_volume_m3": g.volume, "boundary_points": g.boundary.len(),
                "hull_volume_m3": r.hull.as_ref().map(|h| h.volume),
            });
            // The first test's figures also stay at the top level (the pre-existing layout).
            if r.test == runs[0].test {
                for (k, val) in entry.as_object().into_iter().flatten() {
                    v[k] = val.clone();
                }
            }
            v[key(r.test)] = entry;
        }
        println!("{v}");
        return Ok(());
    }
    println!(
        "{}: wrench-feasible workspace (eq. 3.29) at φ = [{:.1}, {:.1}, {:.1}]°, box [{:.2}, {:.2}, {:.2}] .. [{:.2}, {:.2}, {:.2}] m, {}³ grid",
        pf.name,
        rotation_deg[0],
        rotation_deg[1],
        rotation_deg[2],
        bounds.min.x,
        bounds.min.y,
        bounds.min.z,
        bounds.max.x,
        bounds.max.y,
        bounds.max.z,
        resolution,
    );
    for r in &runs {
        let g = &r.grid;
        println!(
            "  {:<24} {} of {} feasible ({:.1} %), ≈ {:.2} m³, {} boundary points",
            r.test.name(),
            g.feasible,
            g.total,
            100.0 * g.fraction,
            g.volume,
            g.boundary.len()
        );
        if let Some(h) = &r.hull {
            println!(
                "  {:<24} hull (Pott 2008, {} rays around the home position): {:.2} m³",
                "",
                h.vertices.len(),
                h.volume
            );
        }
    }
    if let [a, b] = &runs[..] {
        println!(
            "  the closed form keeps {:.1} % of the exact grid workspace{}",
            100.0 * a.grid.feasible as f64 / b.grid.feasible.max(1) as f64,
            match (&a.hull, &b.hull) {
                (Some(ha), Some(hb)) =>
                    format!(" and {:.1} % of its hull", 100.0 * ha.volume / hb.volume),
                _ => String::new(),
            }
        );
    }
    if let Some(p) = csv_path {
        println!("grid written to {}", p.display());
    }
    Ok(())
}
