//! The wrench-feasible constant-orientation workspace (eq. 3.29) on a grid and as a hull
//! (Pott 2008), with the closed-form or the exact feasibility test, or both side by side (the
//! closed form is sufficient only, so its workspace is a subset of the exact one).

use crate::AnalysisError;
use cdpr_model::config::Platform;
use cdpr_model::workspace::{self, FeasibilityTest, GridResult, Hull, PositionBox};
use serde_json::json;
use std::fmt;
use std::path::{Path, PathBuf};

/// The grid (and hull) of one feasibility test.
pub struct Evaluated {
    pub test: FeasibilityTest,
    pub grid: GridResult,
    pub hull: Option<Hull>,
}

/// The workspace of a platform in a box at one orientation, for each requested test.
pub struct WorkspaceReport {
    pub platform: String,
    pub bounds: PositionBox,
    /// The constant orientation as given, degrees.
    pub rotation_deg: [f64; 3],
    /// Grid points per axis.
    pub resolution: usize,
    /// One entry per test, in the order asked for.
    pub runs: Vec<Evaluated>,
    /// The CSV of the grid, once written.
    pub csv: Option<PathBuf>,
}

/// Samples the `resolution`³ grid of `bounds` at the orientation `rotation_deg` with each of
/// `tests`; with `hull` also the workspace hull around the home position.
pub fn workspace(
    pf: &Platform,
    bounds: PositionBox,
    rotation_deg: [f64; 3],
    resolution: usize,
    hull: bool,
    tests: &[FeasibilityTest],
) -> Result<WorkspaceReport, AnalysisError> {
    let model = &pf.model;
    let phi = nalgebra::Vector3::from(rotation_deg).map(f64::to_radians);
    let mut runs = Vec::new();
    for &t in tests {
        let grid = workspace::sample_grid_with(model, &bounds, &phi, [resolution; 3], t);
        let hull = if hull {
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
    Ok(WorkspaceReport {
        platform: pf.name.clone(),
        bounds,
        rotation_deg,
        resolution,
        runs,
        csv: None,
    })
}

fn key(t: FeasibilityTest) -> &'static str {
    match t {
        FeasibilityTest::ClosedForm => "closed_form",
        FeasibilityTest::Exact => "exact",
    }
}

impl WorkspaceReport {
    /// Every grid point with each test's verdict and whether it lies on the boundary.
    pub fn write_csv(&mut self, path: &Path) -> Result<(), AnalysisError> {
        let mut w = csv::Writer::from_path(path)?;
        let mut header = vec!["x_m", "y_m", "z_m"];
        for r in &self.runs {
            header.extend(match r.test {
                FeasibilityTest::ClosedForm => ["feasible", "boundary"],
                FeasibilityTest::Exact => ["feasible_exact", "boundary_exact"],
            });
        }
        w.write_record(&header)?;
        self.csv = Some(path.to_path_buf());
        let Some(first) = self.runs.first() else {
            return Ok(w.flush()?);
        };
        for (k, (p, _)) in first.grid.points.iter().enumerate() {
            let mut rec = vec![p.x.to_string(), p.y.to_string(), p.z.to_string()];
            for r in &self.runs {
                rec.push(r.grid.points[k].1.to_string());
                rec.push(r.grid.boundary.iter().any(|b| b == p).to_string());
            }
            w.write_record(&rec)?;
        }
        Ok(w.flush()?)
    }

    pub fn json(&self) -> serde_json::Value {
        let mut v = json!({
            "platform": self.platform,
            "box_min_m": self.bounds.min.as_slice(), "box_max_m": self.bounds.max.as_slice(),
            "rotation_deg": self.rotation_deg, "resolution": self.resolution,
        });
        for (n, r) in self.runs.iter().enumerate() {
            let g = &r.grid;
            let entry = json!({
                "points": g.total, "feasible": g.feasible, "fraction": g.fraction,
                "feasible_volume_m3": g.volume, "boundary_points": g.boundary.len(),
                "hull_volume_m3": r.hull.as_ref().map(|h| h.volume),
            });
            // The first test's figures also stay at the top level (the pre-existing layout).
            if n == 0 {
                for (k, val) in entry.as_object().into_iter().flatten() {
                    v[k] = val.clone();
                }
            }
            v[key(r.test)] = entry;
        }
        v
    }
}

impl fmt::Display for WorkspaceReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (b, rot) = (&self.bounds, &self.rotation_deg);
        writeln!(
            f,
            "{}: wrench-feasible workspace (eq. 3.29) at φ = [{:.1}, {:.1}, {:.1}]°, box [{:.2}, {:.2}, {:.2}] .. [{:.2}, {:.2}, {:.2}] m, {}³ grid",
            self.platform,
            rot[0],
            rot[1],
            rot[2],
            b.min.x,
            b.min.y,
            b.min.z,
            b.max.x,
            b.max.y,
            b.max.z,
            self.resolution,
        )?;
        for r in &self.runs {
            let g = &r.grid;
            writeln!(
                f,
                "  {:<24} {} of {} feasible ({:.1} %), ≈ {:.2} m³, {} boundary points",
                r.test.name(),
                g.feasible,
                g.total,
                100.0 * g.fraction,
                g.volume,
                g.boundary.len()
            )?;
            if let Some(h) = &r.hull {
                writeln!(
                    f,
                    "  {:<24} hull (Pott 2008, {} rays around the home position): {:.2} m³",
                    "",
                    h.vertices.len(),
                    h.volume
                )?;
            }
        }
        if let [a, b] = &self.runs[..] {
            writeln!(
                f,
                "  the closed form keeps {:.1} % of the exact grid workspace{}",
                100.0 * a.grid.feasible as f64 / b.grid.feasible.max(1) as f64,
                match (&a.hull, &b.hull) {
                    (Some(ha), Some(hb)) =>
                        format!(" and {:.1} % of its hull", 100.0 * ha.volume / hb.volume),
                    _ => String::new(),
                }
            )?;
        }
        if let Some(p) = &self.csv {
            writeln!(f, "grid written to {}", p.display())?;
        }
        Ok(())
    }
}
