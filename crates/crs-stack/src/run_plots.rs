//! Plots of every `crs sim` run: `<out>/pose.svg` (tracked vs reference pose over time),
//! `<out>/forces.svg` (cable forces with f_min / f_max), `<out>/loop.svg` (histogram of the
//! loop's setpoint period and motion-core's lateness quantiles), `<out>/events.svg` (monitor and
//! process events on the time axis) and `<out>/index.html` showing them with the summary.
//!
//! [`RunRecord`] is fed from the launcher's follow loop (a few lines in the `crs` binary's `sim_cmd.rs`); it keeps
//! the streams decimated to [`KEEP_EVERY`] (100 Hz of a 1 kHz stream) so a long run stays small.

use crs_ipc::{
    EventKind, JointSetpoint, LoopStatsSample, MAX_CABLES, PlantTruth, ProcessId, StateEvent,
};
use std::path::{Path, PathBuf};

/// Keep every n-th sample of the 1 kHz streams.
pub const KEEP_EVERY: u64 = 10;
/// Setpoint-period histogram: bin width and range (µs).
const BIN_US: f64 = 20.0;
const HIST_MAX_US: f64 = 3000.0;

/// What a run's plots are made of.
#[derive(Default)]
pub struct RunRecord {
    t0_ns: Option<u64>,
    f_min: f64,
    f_max: f64,
    n_sp: u64,
    n_truth: u64,
    /// (t s, pose) of the reference (setpoints).
    reference: Vec<(f64, [f64; 6])>,
    /// (t s, pose, forces) of the plant.
    actual: Vec<(f64, [f64; 6], Vec<f64>)>,
    last_sp_ns: Option<u64>,
    /// Setpoint periods in bins of BIN_US; the last bin holds everything above HIST_MAX_US.
    period_hist: Vec<u64>,
    period_max_us: f64,
    /// (t s, lateness p50, p99, max µs) from motion-core's loop statistics.
    lateness: Vec<(f64, f64, f64, f64)>,
    /// (t s, source, what).
    events: Vec<(f64, String, String)>,
}

impl RunRecord {
    pub fn new(f_min: f64, f_max: f64) -> Self {
        Self {
            f_min,
            f_max,
            period_hist: vec![0; (HIST_MAX_US / BIN_US) as usize + 1],
            ..Self::default()
        }
    }

    fn t(&mut self, ns: u64) -> f64 {
        let t0 = *self.t0_ns.get_or_insert(ns);
        (ns as f64 - t0 as f64) * 1e-9
    }

    pub fn setpoint(&mut self, sp: &JointSetpoint) {
        if let Some(prev) = self.last_sp_ns {
            let us = sp.timestamp_ns.saturating_sub(prev) as f64 * 1e-3;
            let k = ((us / BIN_US) as usize).min(self.period_hist.len() - 1);
            self.period_hist[k] += 1;
            self.period_max_us = self.period_max_us.max(us);
        }
        self.last_sp_ns = Some(sp.timestamp_ns);
        if self.n_sp.is_multiple_of(KEEP_EVERY) {
            let t = self.t(sp.timestamp_ns);
            self.reference.push((t, sp.pose));
        }
        self.n_sp += 1;
    }

    pub fn truth(&mut self, p: &PlantTruth) {
        if self.n_truth.is_multiple_of(KEEP_EVERY) {
            let t = self.t(p.timestamp_ns);
            let m = (p.cable_count as usize).min(MAX_CABLES);
            self.actual.push((t, p.pose, p.force_n[..m].to_vec()));
        }
        self.n_truth += 1;
    }

    pub fn loop_stats(&mut self, s: &LoopStatsSample) {
        let t = self.t(s.timestamp_ns);
        self.lateness.push((
            t,
            s.lateness_p50_ns as f64 * 1e-3,
            s.lateness_p99_ns as f64 * 1e-3,
            s.lateness_max_ns as f64 * 1e-3,
        ));
    }

    pub fn event(&mut self, e: &StateEvent) {
        let source = match e.source {
            x if x == ProcessId::MotionCore as u32 => "motion-core",
            x if x == ProcessId::DriveIo as u32 => "drive-io",
            x if x == ProcessId::SafetyMonitor as u32 => "safety-monitor",
            x if x == ProcessId::Operator as u32 => "operator",
            _ => "other",
        };
        let what = match e.kind {
            x if x == EventKind::EStop as u32 => {
                if e.source == ProcessId::SafetyMonitor as u32 {
                    let cause = safety_monitor::Cause::from_code(e.detail)
                        .map_or(format!("cause {}", e.detail), |c| c.to_string());
                    format!("E-STOP: {cause}")
                } else {
                    "E-STOP".to_string()
                }
            }
            x if x == EventKind::Fault as u32 => {
                format!("fault (state {}, detail {})", e.state, e.detail)
            }
            x if x == EventKind::Reset as u32 => "reset".to_string(),
            _ if e.source == ProcessId::MotionCore as u32
                && e.state == crs_ipc::motion_state::STOPPING =>
            {
                "end of setpoint stream".to_string()
            }
            _ => format!("state {}", e.state),
        };
        let t = self.t(e.timestamp_ns);
        self.events.push((t, source.to_string(), what));
    }

    fn t_end(&self) -> f64 {
        let a = self.reference.last().map_or(0.0, |r| r.0);
        let b = self.actual.last().map_or(0.0, |r| r.0);
        a.max(b).max(1e-3)
    }
}

/// What one plot's drawing returns: plotters' error of the SVG backend (file I/O).
type Plot = Result<(), plotters::drawing::DrawingAreaErrorKind<std::io::Error>>;

/// Why the run's plots could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RunPlotError {
    /// Drawing the SVG `file`.
    #[error("{source}")]
    Draw {
        file: PathBuf,
        #[source]
        source: plotters::drawing::DrawingAreaErrorKind<std::io::Error>,
    },
    /// Writing `index.html` (`file`).
    #[error("{source}")]
    Write {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

fn draw_events<DB: plotters::prelude::DrawingBackend>(
    chart: &mut plotters::prelude::ChartContext<
        '_,
        DB,
        plotters::prelude::Cartesian2d<
            plotters::coord::types::RangedCoordf64,
            plotters::coord::types::RangedCoordf64,
        >,
    >,
    events: &[(f64, String, String)],
    y: (f64, f64),
) -> Result<(), plotters::drawing::DrawingAreaErrorKind<DB::ErrorType>>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    for (t, _, what) in events {
        let colour = if what.starts_with("E-STOP") || what.starts_with("fault") {
            RED
        } else {
            RGBColor(120, 120, 120)
        };
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(*t, y.0), (*t, y.1)],
            colour.stroke_width(1),
        )))?;
    }
    Ok(())
}

fn pose_plot(r: &RunRecord, path: &Path) -> Plot {
    use plotters::prelude::*;
    let root = SVGBackend::new(path, (1100, 640)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((2, 3));
    let names = ["x (m)", "y (m)", "z (m)", "φx (°)", "φy (°)", "φz (°)"];
    let t_end = r.t_end();
    for (k, area) in panels.iter().enumerate() {
        let scale = if k < 3 {
            1.0
        } else {
            180.0 / std::f64::consts::PI
        };
        let vals = r
            .reference
            .iter()
            .map(|(_, p)| p[k] * scale)
            .chain(r.actual.iter().map(|(_, p, _)| p[k] * scale));
        let (lo, hi) = vals.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
        let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
        let pad = ((hi - lo) * 0.08).max(if k < 3 { 0.01 } else { 0.1 });
        let mut chart = ChartBuilder::on(area)
            .caption(names[k], ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(55)
            .build_cartesian_2d(0f64..t_end, (lo - pad)..(hi + pad))?;
        chart.configure_mesh().x_desc("t (s)").draw()?;
        draw_events(&mut chart, &r.events, (lo - pad, hi + pad))?;
        chart
            .draw_series(LineSeries::new(
                r.reference.iter().map(|(t, p)| (*t, p[k] * scale)),
                RGBColor(239, 143, 0).stroke_width(2),
            ))?
            .label("reference")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], RGBColor(239, 143, 0)));
        chart
            .draw_series(LineSeries::new(
                r.actual.iter().map(|(t, p, _)| (*t, p[k] * scale)),
                BLUE.stroke_width(1),
            ))?
            .label("plant (true)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLUE));
        if k == 0 {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperLeft)
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
        }
    }
    root.present()?;
    Ok(())
}

fn force_plot(r: &RunRecord, path: &Path) -> Plot {
    use plotters::prelude::*;
    let root = SVGBackend::new(path, (1100, 460)).into_drawing_area();
    root.fill(&WHITE)?;
    let t_end = r.t_end();
    let f_top = r
        .actual
        .iter()
        .flat_map(|(_, _, f)| f.iter().copied())
        .fold(r.f_max, f64::max)
        * 1.05;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "cable forces (plant truth) and the limits f_min, f_max",
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(34)
        .y_label_area_size(64)
        .build_cartesian_2d(0f64..t_end, 0f64..f_top)?;
    chart.configure_mesh().x_desc("t (s)").y_desc("N").draw()?;
    draw_events(&mut chart, &r.events, (0.0, f_top))?;
    for lim in [r.f_min, r.f_max] {
        chart.draw_series(DashedLineSeries::new(
            vec![(0.0, lim), (t_end, lim)],
            8,
            5,
            RED.stroke_width(2),
        ))?;
    }
    let m = r.actual.first().map_or(0, |a| a.2.len());
    for i in 0..m {
        let c = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(
                r.actual.iter().map(|(t, _, f)| (*t, f[i])),
                c.stroke_width(1),
            ))?
            .label(format!("cable {}", i + 1))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

fn loop_plot(r: &RunRecord, path: &Path) -> Plot {
    use plotters::prelude::*;
    let root = SVGBackend::new(path, (1100, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(600);
    let total: u64 = r.period_hist.iter().sum::<u64>().max(1);
    // Log-scaled counts: the tail bins (a few stalls) must stay visible next to the 1 ms peak.
    let y_top = (r.period_hist.iter().copied().max().unwrap_or(1).max(1) as f64 * 2.0).log10();
    let mut chart = ChartBuilder::on(&left)
        .caption(
            format!(
                "setpoint period histogram ({total} periods, max {:.0} µs)",
                r.period_max_us
            ),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(34)
        .y_label_area_size(50)
        .build_cartesian_2d(0f64..HIST_MAX_US + BIN_US, 0f64..y_top.max(1.0))?;
    chart
        .configure_mesh()
        .x_desc("time between consecutive setpoints (µs; last bin: ≥ 3 ms)")
        .y_desc("log10(count + 1)")
        .draw()?;
    chart.draw_series(r.period_hist.iter().enumerate().map(|(k, n)| {
        let x0 = k as f64 * BIN_US;
        Rectangle::new(
            [(x0, 0.0), (x0 + BIN_US, ((*n + 1) as f64).log10())],
            if k + 1 == r.period_hist.len() {
                RED
            } else {
                BLUE
            }
            .filled(),
        )
    }))?;
    let t_end = r.t_end();
    let y_max = r
        .lateness
        .iter()
        .map(|l| l.3)
        .fold(1.0f64, f64::max)
        .max(1.0);
    let mut chart = ChartBuilder::on(&right)
        .caption(
            "motion-core lateness (cumulative quantiles)",
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(34)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..t_end, (1f64..y_max * 2.0).log_scale())?;
    chart.configure_mesh().x_desc("t (s)").y_desc("µs").draw()?;
    for (k, (name, colour)) in [("p50", GREEN), ("p99", BLUE), ("max", RED)]
        .into_iter()
        .enumerate()
    {
        chart
            .draw_series(LineSeries::new(
                r.lateness.iter().map(move |l| {
                    let v = [l.1, l.2, l.3][k];
                    (l.0, v.max(1.0))
                }),
                colour.stroke_width(2),
            ))?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

fn events_plot(r: &RunRecord, path: &Path) -> Plot {
    use plotters::prelude::*;
    let sources = [
        "motion-core",
        "drive-io",
        "safety-monitor",
        "operator",
        "other",
    ];
    let root = SVGBackend::new(path, (1100, 260)).into_drawing_area();
    root.fill(&WHITE)?;
    let t_end = r.t_end();
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("events on the process bus ({})", r.events.len()),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(110)
        .build_cartesian_2d(0f64..t_end, -0.5f64..(sources.len() as f64 - 0.5))?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .y_labels(sources.len())
        .y_label_formatter(&|y| {
            let k = y.round();
            if (y - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < sources.len() {
                sources[k as usize].to_string()
            } else {
                String::new()
            }
        })
        .draw()?;
    for (t, src, what) in &r.events {
        let row = sources.iter().position(|s| s == src).unwrap_or(4) as f64;
        let bad = what.starts_with("E-STOP") || what.starts_with("fault");
        let colour = if bad { RED } else { BLUE };
        chart.draw_series(std::iter::once(Circle::new((*t, row), 5, colour.filled())))?;
        chart.draw_series(std::iter::once(Text::new(
            what.clone(),
            (*t, row + 0.25),
            ("sans-serif", 12),
        )))?;
    }
    root.present()?;
    Ok(())
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Writes the four SVGs and index.html into `out`; returns the index path.
pub fn write(
    out: &Path,
    r: &RunRecord,
    summary: &serde_json::Value,
) -> Result<PathBuf, RunPlotError> {
    type Draw = fn(&RunRecord, &Path) -> Plot;
    let plots: [(&str, Draw); 4] = [
        ("pose.svg", pose_plot),
        ("forces.svg", force_plot),
        ("loop.svg", loop_plot),
        ("events.svg", events_plot),
    ];
    for (name, plot) in plots {
        let file = out.join(name);
        if let Err(source) = plot(r, &file) {
            return Err(RunPlotError::Draw { file, source });
        }
    }
    let mut rows = String::new();
    if let Some(obj) = summary.as_object() {
        for (k, v) in obj {
            let v = match v {
                serde_json::Value::Number(n) => n.as_f64().map_or(n.to_string(), |x| {
                    if x.fract() == 0.0 {
                        format!("{x}")
                    } else {
                        format!("{x:.3}")
                    }
                }),
                serde_json::Value::Null => "–".into(),
                other => other.to_string(),
            };
            rows.push_str(&format!(
                "<tr><th>{}</th><td>{}</td></tr>\n",
                html_escape(k),
                html_escape(&v)
            ));
        }
    }
    let mut ev = String::new();
    for (t, src, what) in &r.events {
        ev.push_str(&format!(
            "<tr><td>{t:.3}</td><td>{}</td><td>{}</td></tr>\n",
            html_escape(src),
            html_escape(what)
        ));
    }
    let html = format!(
        r#"<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>crs sim run</title>
<style>body{{font-family:sans-serif;margin:16px;color:#1d232b}} table{{border-collapse:collapse}} th,td{{padding:2px 8px;border-bottom:1px solid #ddd;text-align:left}} img{{max-width:100%;border:1px solid #ddd;margin:6px 0}}</style>
</head><body>
<h1>crs sim run</h1>
<p>Time axis: seconds from the first setpoint or plant state the launcher received. Vertical lines in the plots mark events (red: e-stop / fault).</p>
<h2>Summary</h2>
<table>
{rows}</table>
<h2>Tracked vs reference pose</h2><img src="pose.svg" alt="pose">
<h2>Cable forces</h2><img src="forces.svg" alt="forces">
<h2>Loop timing</h2><img src="loop.svg" alt="loop">
<h2>Events</h2><img src="events.svg" alt="events">
<table><tr><th>t (s)</th><th>source</th><th>event</th></tr>
{ev}</table>
<p>Logs: <a href="sim-plant.log">sim-plant</a>, <a href="safety-monitor.log">safety-monitor</a>, <a href="drive-io.log">drive-io</a>, <a href="motion-core.log">motion-core</a>; <a href="summary.json">summary.json</a>.</p>
</body></html>
"#
    );
    let index = out.join("index.html");
    if let Err(source) = std::fs::write(&index, html) {
        return Err(RunPlotError::Write {
            file: index,
            source,
        });
    }
    Ok(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_four_plots_and_an_index_with_the_summary() {
        let dir = std::env::temp_dir().join(format!("crs-sim-plots-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut r = RunRecord::new(1000.0, 9000.0);
        for k in 0..2000u64 {
            let mut sp = JointSetpoint {
                sequence: k + 1,
                timestamp_ns: 1_000_000_000 + k * 1_000_000 + if k >= 1500 { 4_000_000 } else { 0 },
                ..Default::default()
            };
            sp.pose[0] = k as f64 * 1e-4;
            r.setpoint(&sp);
            let mut t = PlantTruth {
                cable_count: 8,
                timestamp_ns: sp.timestamp_ns + 500_000,
                ..Default::default()
            };
            t.pose = sp.pose;
            t.force_n[..8].fill(3000.0 + k as f64);
            r.truth(&t);
        }
        let mut e = StateEvent::new(ProcessId::SafetyMonitor, EventKind::EStop, 1);
        e.timestamp_ns = 2_500_000_000;
        e.detail = 1;
        r.event(&e);
        // 1999 periods: 1998 of 1 ms, one of 5 ms (the stall) in the overflow bin.
        assert_eq!(r.period_hist.iter().sum::<u64>(), 1999);
        assert_eq!(*r.period_hist.last().unwrap(), 1);
        assert_eq!(r.period_hist[(1000.0 / BIN_US) as usize], 1998);
        let summary = serde_json::json!({"setpoints": 2000, "tracking_position_mean_mm": 1.25});
        let index = write(&dir, &r, &summary).unwrap();
        let html = std::fs::read_to_string(index).unwrap();
        assert!(html.contains("tracking_position_mean_mm") && html.contains("1.250"));
        assert!(html.contains("E-STOP"));
        for f in ["pose.svg", "forces.svg", "loop.svg", "events.svg"] {
            let svg = std::fs::read_to_string(dir.join(f)).unwrap();
            assert!(svg.starts_with("<svg") && svg.len() > 2000, "{f}");
        }
        // The force plot draws the limits and 8 cables.
        let svg = std::fs::read_to_string(dir.join("forces.svg")).unwrap();
        assert!(svg.contains("cable 8") && svg.contains("f_min"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
