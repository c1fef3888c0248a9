//! The report of a surrogate evaluation on the plant (`crs surrogate fit --plant`, `crs surrogate
//! evaluate`): report.md (the table of both controllers), report.json and tracking.svg.

use crs_plot::{Chart, Figure, Line, Panel, Rgb};
use plant_experiments::surrogate_evaluation::{Evaluation, stats};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Why the report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Creating the report directory or writing one of its files (`path`).
    #[error("{source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Formatting the Markdown table.
    #[error(transparent)]
    Format(#[from] std::fmt::Error),
    /// Serialising report.json.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// Drawing or writing tracking.svg.
    #[error(transparent)]
    Plot(#[from] crs_plot::PlotError),
}

fn write_err(path: &Path) -> impl FnOnce(std::io::Error) -> ReportError + '_ {
    move |source| ReportError::Write {
        path: path.to_path_buf(),
        source,
    }
}

/// What [`write`] wrote: the Markdown table (also in report.md) and the files.
pub struct Written {
    pub markdown: String,
    pub files: Vec<PathBuf>,
}

/// As `crs surrogate` prints it: the Markdown table, then the files written.
impl std::fmt::Display for Written {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names: Vec<String> = self.files.iter().map(|p| p.display().to_string()).collect();
        write!(f, "\n{}", self.markdown)?;
        writeln!(f, "wrote {}", names.join(", "))
    }
}

/// Write report.md, report.json and tracking.svg of `ev` (and the fit's figures) into `dir`.
pub fn write(
    ev: &Evaluation,
    dir: &Path,
    fit: Option<&surrogate::FitReport>,
) -> Result<Written, ReportError> {
    std::fs::create_dir_all(dir).map_err(write_err(dir))?;
    let mut md = String::new();
    writeln!(
        md,
        "Surrogate evaluation on plant `{}` (platform `{}`): {} poses, {} wrench feasible (eq. 3.29/3.41)\n",
        ev.plant, ev.platform, ev.poses, ev.wrench_feasible
    )?;
    if let Some(r) = fit {
        writeln!(
            md,
            "Fit: degree {}, {} coefficients/cable, condition {:.2}; error vs full model max {:.4} mm, mean {:.4} mm; max |φ_sg| {:.2} mm\n",
            r.degree,
            r.n_coeffs_per_cable,
            r.condition_number,
            r.max_fit_error_mm,
            r.mean_fit_error_mm,
            r.max_abs_offset_mm
        )?;
    }
    writeln!(
        md,
        "| controller | force error mean / p95 / max (N) | position error mean / max (mm) | orientation error mean / max (deg) | reachable (eq. 3.33) | no equilibrium |"
    )?;
    writeln!(md, "|---|---|---|---|---|---|")?;
    for (name, t) in [
        (
            "kinematics, set up with f_ini (eq. 3.14, 6.22)",
            &ev.kinematic,
        ),
        (
            "kinematics + surrogate (eq. 5.26), set up with f_ref(home)",
            &ev.surrogate,
        ),
    ] {
        let f = stats(&t.force_error_n);
        let p = stats(&t.position_error_mm);
        let o = stats(&t.orientation_error_deg);
        let pct = if ev.wrench_feasible > 0 {
            100.0 * t.reachable as f64 / ev.wrench_feasible as f64
        } else {
            f64::NAN
        };
        writeln!(
            md,
            "| {name} | {:.0} / {:.0} / {:.0} | {:.3} / {:.3} | {:.4} / {:.4} | {} of {} ({pct:.1} %) | {} |",
            f.0, f.1, f.2, p.0, p.2, o.0, o.2, t.reachable, ev.wrench_feasible, t.failed
        )?;
    }
    let md_file = dir.join("report.md");
    std::fs::write(&md_file, &md).map_err(write_err(&md_file))?;
    let json_file = dir.join("report.json");
    std::fs::write(&json_file, serde_json::to_string_pretty(ev)?).map_err(write_err(&json_file))?;
    let svg = dir.join("tracking.svg");
    figure(ev).write(&svg)?;
    Ok(Written {
        markdown: md,
        files: vec![dir.join("report.md"), dir.join("report.json"), svg],
    })
}

/// Two panels: sorted force error and sorted position error of both controllers.
fn figure(ev: &Evaluation) -> Figure {
    let series = |v: &[f64]| {
        let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
        s.sort_by(f64::total_cmp);
        s
    };
    let line = |s: &[f64]| {
        let len = s.len().max(2) as f64 - 1.0;
        s.iter()
            .enumerate()
            .map(move |(i, v)| (100.0 * i as f64 / len, *v))
            .collect::<Vec<_>>()
    };
    let panels = [
        (
            "max cable force error |f̂ − f_ref|",
            "N",
            series(&ev.kinematic.force_error_n),
            series(&ev.surrogate.force_error_n),
        ),
        (
            "position error |r̂ − r|",
            "mm",
            series(&ev.kinematic.position_error_mm),
            series(&ev.surrogate.position_error_mm),
        ),
    ]
    .into_iter()
    .map(|(title, unit, kin, sg)| {
        let y_max = kin
            .iter()
            .chain(sg.iter())
            .copied()
            .fold(0.0f64, f64::max)
            .max(1e-9)
            * 1.05;
        let mut c = Chart::new(title, "poses, sorted (%)", unit);
        c.x_range = Some((0.0, 100.0));
        c.y_range = Some((0.0, y_max));
        for (label, color, s) in [
            ("kinematics + set-up offsets", Rgb::RED, &kin),
            ("kinematics + surrogate", Rgb::BLUE, &sg),
        ] {
            let mut l = Line::new(label, color, line(s));
            l.width = 2;
            c.lines.push(l);
        }
        Panel::Chart(c)
    })
    .collect();
    Figure {
        title: String::new(),
        size: (1000, 420),
        columns: 2,
        panels,
        notes: Vec::new(),
        legend: Vec::new(),
    }
}
