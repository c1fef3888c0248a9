//! The spec's planar four-cable robot (eq. 3.40 / 4.24) with the numbers of chapters 3–4
//! recomputed from the model library — condition numbers of the sample sets (eq. 4.26 / 4.28),
//! the initial tension of fig. 3.18a, the physical (W_PHYS, eq. 3.29) and reachable (W_R,
//! eq. 3.33–3.35) areas of sec. 3.6 and the pulley influence of sec. 3.8 — side by side with the
//! values the spec prints. [`PlanarReport::write_svg`] draws the area map.

use crate::AnalysisError;
use cdpr_analysis::planar::{self, AreaTest, PlanarModel, PlanarPose, Reachable};
use crs_plot::{Chart, Figure, Markers, Panel, Rect, Rgb};
use nalgebra::{DVector, Vector2};
use serde_json::json;
use std::fmt;
use std::path::{Path, PathBuf};

/// The parameters varied from the spec's example.
#[derive(Clone, Copy, Debug)]
pub struct PlanarRequest {
    /// Force limits, N (fig. 3.20: 1000 N; fig. 3.18a: 8000 N).
    pub f_min_n: f64,
    pub f_max_n: f64,
    /// Specific cable stiffness k_F, N (eq. 3.36: 2000 kN/m).
    pub k_f_n: f64,
    /// Grid spacing of the area computations, m.
    pub grid_m: f64,
}

/// The figures of ch. 3–4 for the planar robot.
pub struct PlanarReport {
    pub request: PlanarRequest,
    pub model: PlanarModel,
    pub x_ini: PlanarPose,
    pub grid: Vec<Vector2<f64>>,
    /// cond(J_qa) on the sample sets W_T1 and W_T2 (eq. 4.26, 4.28).
    pub cond: [f64; 2],
    /// Initial tension at [0, 5.2] m without load (fig. 3.18a), N.
    pub f_ini_unloaded: DVector<f64>,
    /// W_PHYS by the exact test and by the closed form, m².
    pub w_exact: f64,
    pub w_closed: f64,
    pub reach: Reachable,
    /// (pulley radius m, W_PHYS m², points not evaluated) for the radii of sec. 3.8.
    pub pulleys: Vec<(f64, f64, usize)>,
    /// Grid points the two W_PHYS tests could not evaluate.
    pub unevaluated: usize,
    /// The SVG map, once written.
    pub svg: Option<PathBuf>,
}

/// Recomputes the planar example with the limits, stiffness and grid of `r`.
pub fn planar(r: &PlanarRequest) -> Result<PlanarReport, AnalysisError> {
    let model = planar::spec_example().with(|p| {
        p.f_min = r.f_min_n;
        p.f_max = r.f_max_n;
        p.k_f = vec![r.k_f_n; 4];
    })?;
    let x_ini = PlanarPose::point(0.0, 5.2);
    let h = r.grid_m;
    let grid = planar::frame_grid(&model, Vector2::new(-6.4, -0.5), Vector2::new(5.5, 8.5), h);

    let cond1 =
        planar::condition_number_qa(&model, &planar::sample_grid((-4.0, 0.5), (4.0, 6.0), 5, 5))?;
    let cond2 =
        planar::condition_number_qa(&model, &planar::sample_grid((-3.0, 0.4), (2.0, 1.0), 4, 4))?;
    let unloaded = model.with(|p| p.w_e = DVector::zeros(2))?;
    let c = planar::inverse(&unloaded, &x_ini)?;
    let (f_ini_unloaded, _) =
        planar::closed_form(&unloaded, &planar::structure_matrix(&unloaded, &x_ini, &c))?;
    let (w_exact, e1) = planar::feasible_area(&model, &grid, h, 0.0, AreaTest::Exact);
    let (w_closed, e2) = planar::feasible_area(&model, &grid, h, 0.0, AreaTest::ClosedForm);
    let reach = planar::reachable(&model, &model, &x_ini, &grid, h)?;
    let mut pulleys = Vec::new();
    for rho in [0.15, 0.4] {
        let m = model.with(|p| p.pulley_radius = rho)?;
        let (area, errs) = planar::feasible_area(&m, &grid, h, 0.0, AreaTest::Exact);
        pulleys.push((rho, area, errs));
    }
    Ok(PlanarReport {
        request: *r,
        model,
        x_ini,
        grid,
        cond: [cond1, cond2],
        f_ini_unloaded,
        w_exact,
        w_closed,
        reach,
        pulleys,
        unevaluated: e1 + e2,
        svg: None,
    })
}

impl PlanarReport {
    pub fn json(&self) -> serde_json::Value {
        let (a, reach, w_exact) = (&self.request, &self.reach, self.w_exact);
        json!({
            "f_min_n": a.f_min_n, "f_max_n": a.f_max_n, "k_f_n": a.k_f_n, "grid_m": a.grid_m,
            "cond_j_qa_w_t1": self.cond[0], "cond_j_qa_w_t2": self.cond[1],
            "f_ini_unloaded_n": self.f_ini_unloaded.as_slice(),
            "w_phys_exact_m2": w_exact, "w_phys_closed_form_m2": self.w_closed,
            "w_r_m2": reach.area_m2, "w_r_f_ini_n": reach.f_ini.as_slice(),
            "w_r_mean_error_m": (reach.area_m2 > 0.0).then_some(reach.mean_error_m),
            "w_r_max_error_m": reach.max_error_m, "fk_failures": reach.fk_failures,
            "grid_points_not_evaluated": self.unevaluated,
            "pulleys": self.pulleys.iter().map(|(r, ar, e)| json!({
                "radius_m": r, "w_phys_exact_m2": ar, "relative": ar / w_exact,
                "grid_points_not_evaluated": e,
            })).collect::<Vec<_>>(),
        })
    }

    /// Area map: grey = W_PHYS by the exact test only, blue = also the closed form, outlined
    /// cells = reachable by the kinematic controller (W_R); frame anchors as red dots.
    pub fn write_svg(&mut self, path: &Path) -> Result<(), AnalysisError> {
        let (model, grid, h, x_ini) = (&self.model, &self.grid, self.request.grid_m, &self.x_ini);
        let mut c = Chart::new("", "x (m)", "y (m)");
        c.equal_scale = true;
        c.x_range = Some((-6.6, 5.7));
        c.y_range = Some((-0.7, 8.7));
        for r in grid {
            let reach = planar::reachable(model, model, x_ini, std::slice::from_ref(r), h)
                .is_ok_and(|re| re.area_m2 > 0.0);
            let pose = PlanarPose { r: *r, theta: 0.0 };
            let Ok(cables) = planar::inverse(model, &pose) else {
                continue;
            };
            let at = planar::structure_matrix(model, &pose, &cables);
            let exact = planar::exact(model, &at).is_ok_and(|e| e.feasible);
            let closed = planar::closed_form(model, &at).is_ok_and(|(_, m)| m >= 0.0);
            let fill = match (exact, closed) {
                (true, true) => CLOSED_FORM,
                (true, false) => EXACT_ONLY,
                _ => continue,
            };
            let half = 0.45 * h;
            let mut cell = Rect::filled(
                (r.x - half, r.y - half),
                (r.x + half, r.y + half),
                fill,
                1.0,
            );
            if reach {
                cell.stroke = Some((REACHABLE, 2, false));
            }
            c.rects.push(cell);
        }
        c.markers.push(Markers::new(
            "frame anchors",
            Rgb(255, 0, 0),
            model.params().a.iter().map(|a| (a.x, a.y)).collect(),
        ));
        let mut figure = Figure::single(
            "planar 4-cable robot (eq. 3.40 / 4.24): wrench-feasible and reachable areas",
            (820, 760),
            Panel::Chart(c),
        );
        figure.notes = vec![
            "blue: wrench feasible by eq. 3.41 (and 3.29); grey: by the exact test (eq. 3.29) only".into(),
            "magenta outline: reachable by the kinematic controller (W_R, eq. 3.33-3.35); red: frame anchors".into(),
        ];
        std::fs::write(path, figure.svg()?)?;
        self.svg = Some(path.to_path_buf());
        Ok(())
    }
}

const CLOSED_FORM: Rgb = Rgb(0x4a, 0x7f, 0xc1);
const EXACT_ONLY: Rgb = Rgb(0xb9, 0xb9, 0xb9);
const REACHABLE: Rgb = Rgb(0xe0, 0x21, 0x8a);

impl fmt::Display for PlanarReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (a, reach, w_exact) = (&self.request, &self.reach, self.w_exact);
        let h = a.grid_m;
        writeln!(
            f,
            "planar 4-cable robot of eq. 3.40 / 4.24: w_e = [0, -1962] N, f in [{:.0}, {:.0}] N, k_F = {:.0} kN/m, grid {h} m",
            a.f_min_n,
            a.f_max_n,
            a.k_f_n / 1e3
        )?;
        writeln!(f, "{:<58} {:>14} {:>10}", "figure", "here", "spec")?;
        let mut row =
            |name: &str, here: String, spec: &str| writeln!(f, "{name:<58} {here:>14} {spec:>10}");
        let (cond1, cond2, fi) = (self.cond[0], self.cond[1], &self.f_ini_unloaded);
        row(
            "cond(J_qa), W_T1 5x5 (eq. 4.25-4.26)",
            format!("{cond1:.2}"),
            "3.2",
        )?;
        row(
            "cond(J_qa), W_T2 4x4 (eq. 4.27-4.28)",
            format!("{cond2:.2}"),
            "19.3",
        )?;
        row(
            "f_ini at [0, 5.2] m, w_e = 0 (fig. 3.18a), N",
            format!("{:.0} {:.0} {:.0} {:.0}", fi[0], fi[1], fi[2], fi[3]),
            "5196 5247 3380 3394",
        )?;
        row(
            "W_PHYS, exact test (eq. 3.29), m²",
            format!("{w_exact:.2}"),
            "70",
        )?;
        row(
            "W_PHYS, closed form (eq. 3.41), m²",
            format!("{:.2}", self.w_closed),
            "-",
        )?;
        row(
            "W_R, kinematic controller, full elastostatic FK, m²",
            format!("{:.2}", reach.area_m2),
            "51",
        )?;
        row(
            "W_R / W_PHYS",
            format!("{:.1} %", 100.0 * reach.area_m2 / w_exact),
            "73 %",
        )?;
        if reach.area_m2 > 0.0 {
            row(
                "pose error in W_R, mean / max, mm",
                format!(
                    "{:.1} / {:.1}",
                    1e3 * reach.mean_error_m,
                    1e3 * reach.max_error_m
                ),
                "- / 20",
            )?;
        }
        for ((rho, area, _), spec) in self.pulleys.iter().zip(["98.95 %", "97.54 %"]) {
            row(
                &format!("W_PHYS(r_p = {:.0} mm) / W_PHYS(0) (sec. 3.8)", rho * 1e3),
                format!("{:.2} %", 100.0 * area / w_exact),
                spec,
            )?;
        }
        if reach.fk_failures > 0 || self.unevaluated > 0 {
            writeln!(
                f,
                "not evaluated (counted as outside): elastostatic FK failed on {} grid points, {} points could not be evaluated",
                reach.fk_failures, self.unevaluated
            )?;
        }
        if let Some(p) = &self.svg {
            writeln!(f, "map written to {}", p.display())?;
        }
        Ok(())
    }
}
