//! SVG figures of a cueing run (hand-written SVG, no plotting dependency in the model layer):
//! panels of time series ([`panels_svg`]), the perception figure (vehicle vs cabin vs
//! perceived, per axis: [`perception_svg`]), the cabin's motion in its cueing box
//! ([`motion_svg`]) and a scatter of tunings ([`scatter_svg`]).

use crate::perception::{PerceptionReport, PerceptionSeries};
use std::fmt::Write;

/// One line of a panel.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub label: String,
    pub color: &'static str,
    pub dashed: bool,
    pub points: Vec<(f64, f64)>,
}

/// One panel: a title, its y unit, lines and optional horizontal limits (drawn red, dashed).
#[derive(Clone, Debug, PartialEq)]
pub struct Panel {
    pub title: String,
    pub unit: String,
    pub series: Vec<Series>,
    pub limits: Vec<f64>,
}

const PANEL_W: f64 = 460.0;
const PANEL_H: f64 = 170.0;
const MAX_POINTS: usize = 500;

pub(crate) fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Panels in a grid of `columns`, with a title line on top.
pub fn panels_svg(title: &str, panels: &[Panel], columns: usize) -> String {
    let columns = columns.max(1);
    let rows = panels.len().div_ceil(columns);
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{:.0}" height="{:.0}" font-family="sans-serif" font-size="11">"#,
        columns as f64 * PANEL_W,
        rows as f64 * PANEL_H + 30.0
    );
    let _ = write!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = write!(
        s,
        r#"<text x="8" y="18" font-size="13">{}</text>"#,
        esc(title)
    );
    for (i, p) in panels.iter().enumerate() {
        let (x0, y0) = (
            (i % columns) as f64 * PANEL_W,
            30.0 + (i / columns) as f64 * PANEL_H,
        );
        panel(&mut s, p, x0, y0);
    }
    s.push_str("</svg>\n");
    s
}

fn panel(s: &mut String, p: &Panel, x0: f64, y0: f64) {
    let (l, r, t, b) = (52.0, 10.0, 18.0, 22.0);
    let (w, h) = (PANEL_W - l - r, PANEL_H - t - b);
    let pts = p.series.iter().flat_map(|s| s.points.iter());
    let (mut xmin, mut xmax, mut ymin, mut ymax) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, y) in pts.filter(|(x, y)| x.is_finite() && y.is_finite()) {
        xmin = xmin.min(x);
        xmax = xmax.max(x);
        ymin = ymin.min(y);
        ymax = ymax.max(y);
    }
    for &lim in &p.limits {
        ymin = ymin.min(lim);
        ymax = ymax.max(lim);
    }
    if !(xmin.is_finite() && ymin.is_finite()) {
        let _ = write!(
            s,
            r#"<text x="{:.0}" y="{:.0}">{}: no data</text>"#,
            x0 + l,
            y0 + t + 20.0,
            esc(&p.title)
        );
        return;
    }
    if xmax - xmin < 1e-12 {
        xmax = xmin + 1.0;
    }
    let span = (ymax - ymin).max(1e-9);
    ymin -= 0.05 * span;
    ymax += 0.05 * span;
    let px = |x: f64| x0 + l + (x - xmin) / (xmax - xmin) * w;
    let py = |y: f64| y0 + t + h - (y - ymin) / (ymax - ymin) * h;
    let _ = write!(
        s,
        r##"<rect x="{:.1}" y="{:.1}" width="{w:.1}" height="{h:.1}" fill="none" stroke="#888"/>"##,
        x0 + l,
        y0 + t
    );
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}">{} ({})</text>"#,
        x0 + l,
        y0 + t - 5.0,
        esc(&p.title),
        esc(&p.unit)
    );
    // Axis labels: y min/max, x min/max, zero line.
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
        x0 + l - 3.0,
        py(ymax) + 9.0,
        fmt(ymax)
    );
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
        x0 + l - 3.0,
        py(ymin),
        fmt(ymin)
    );
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}">{}</text>"#,
        x0 + l,
        y0 + t + h + 13.0,
        fmt(xmin)
    );
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{} s</text>"#,
        x0 + l + w,
        y0 + t + h + 13.0,
        fmt(xmax)
    );
    if ymin < 0.0 && ymax > 0.0 {
        let _ = write!(
            s,
            r##"<line x1="{:.1}" x2="{:.1}" y1="{:.1}" y2="{:.1}" stroke="#ccc"/>"##,
            x0 + l,
            x0 + l + w,
            py(0.0),
            py(0.0)
        );
    }
    for &lim in &p.limits {
        let _ = write!(
            s,
            r#"<line x1="{:.1}" x2="{:.1}" y1="{:.1}" y2="{:.1}" stroke="red" stroke-dasharray="4 3"/>"#,
            x0 + l,
            x0 + l + w,
            py(lim),
            py(lim)
        );
    }
    for (k, ser) in p.series.iter().enumerate() {
        let step = ser.points.len().div_ceil(MAX_POINTS).max(1);
        let mut d = String::new();
        for (x, y) in ser
            .points
            .iter()
            .step_by(step)
            .filter(|(x, y)| x.is_finite() && y.is_finite())
        {
            let _ = write!(d, "{:.1},{:.1} ", px(*x), py(*y));
        }
        let dash = if ser.dashed {
            r#" stroke-dasharray="5 3""#
        } else {
            ""
        };
        let _ = write!(
            s,
            r#"<polyline fill="none" stroke="{}" stroke-width="1.3"{dash} points="{}"/>"#,
            ser.color,
            d.trim_end()
        );
        let lx = x0 + l + 6.0 + k as f64 * 110.0;
        let _ = write!(
            s,
            r#"<line x1="{lx:.1}" x2="{:.1}" y1="{:.1}" y2="{:.1}" stroke="{}" stroke-width="2"{dash}/><text x="{:.1}" y="{:.1}">{}</text>"#,
            lx + 14.0,
            y0 + t + 10.0,
            y0 + t + 10.0,
            ser.color,
            lx + 17.0,
            y0 + t + 13.0,
            esc(&ser.label)
        );
    }
}

fn fmt(v: f64) -> String {
    if v.abs() >= 100.0 {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.3}")
    }
}

/// Vehicle vs cabin vs perceived, per axis: left column specific force x, y, z (m/s²), right
/// column angular velocity x, y, z (°/s). Black: vehicle, blue: cabin (motion-core's
/// reference); dashed: what the vestibular models perceive of each. The panel titles carry
/// the perceived RMS error and correlation.
pub fn perception_svg(title: &str, s: &PerceptionSeries, r: &PerceptionReport) -> String {
    let deg = 180.0 / std::f64::consts::PI;
    let corr = |c: Option<f64>| c.map_or("–".to_string(), |c| format!("{c:.2}"));
    let mut panels = Vec::new();
    for k in 0..3 {
        for (is_w, name) in [
            (false, ["f_x", "f_y", "f_z"][k]),
            (true, ["ω_x (roll)", "ω_y (pitch)", "ω_z (yaw)"][k]),
        ] {
            let (scale, unit, rep) = if is_w {
                (deg, "°/s", &r.angular_velocity[k])
            } else {
                (1.0, "m/s²", &r.specific_force[k])
            };
            let pick = |v: &[nalgebra::Vector3<f64>]| -> Vec<(f64, f64)> {
                s.t_s
                    .iter()
                    .zip(v)
                    .map(|(t, x)| (*t, x[k] * scale))
                    .collect()
            };
            let (veh, cab, pveh, pcab) = if is_w {
                (
                    &s.vehicle_w,
                    &s.cabin_w,
                    &s.perceived_vehicle_w,
                    &s.perceived_cabin_w,
                )
            } else {
                (
                    &s.vehicle_f,
                    &s.cabin_f,
                    &s.perceived_vehicle_f,
                    &s.perceived_cabin_f,
                )
            };
            panels.push(Panel {
                title: format!(
                    "{name}: perceived RMS error {:.3}, corr. {}",
                    rep.perceived.rms_error * scale,
                    corr(rep.perceived.correlation)
                ),
                unit: unit.into(),
                series: vec![
                    Series {
                        label: "vehicle".into(),
                        color: "black",
                        dashed: false,
                        points: pick(veh),
                    },
                    Series {
                        label: "cabin".into(),
                        color: "#1f77b4",
                        dashed: false,
                        points: pick(cab),
                    },
                    Series {
                        label: "perceived vehicle".into(),
                        color: "#555555",
                        dashed: true,
                        points: pick(pveh),
                    },
                    Series {
                        label: "perceived cabin".into(),
                        color: "#ff7f0e",
                        dashed: true,
                        points: pick(pcab),
                    },
                ],
                limits: Vec::new(),
            });
        }
    }
    panels_svg(title, &panels, 2)
}

/// The cabin's pose coordinates over time (x, y, z in m; φx, φy, φz in °) against the cueing
/// box (red): the washout's demand (grey, dashed), the limited pose (blue) and the tilt part
/// of φx, φy (green, dashed). `t_s`, `desired`, `pose`, `tilt` share one time base.
pub fn motion_svg(
    title: &str,
    t_s: &[f64],
    desired: &[[f64; 6]],
    pose: &[[f64; 6]],
    tilt: &[[f64; 2]],
    box_min: &[f64; 6],
    box_max: &[f64; 6],
) -> String {
    let deg = 180.0 / std::f64::consts::PI;
    let names = ["x", "y", "z", "φx (roll)", "φy (pitch)", "φz (yaw)"];
    let panels = (0..6)
        .map(|k| {
            let sc = if k < 3 { 1.0 } else { deg };
            let col = |v: &[[f64; 6]]| -> Vec<(f64, f64)> {
                t_s.iter().zip(v).map(|(t, x)| (*t, x[k] * sc)).collect()
            };
            let mut series = vec![
                Series {
                    label: "washout demand".into(),
                    color: "#999999",
                    dashed: true,
                    points: col(desired),
                },
                Series {
                    label: "cabin".into(),
                    color: "#1f77b4",
                    dashed: false,
                    points: col(pose),
                },
            ];
            if (3..5).contains(&k) {
                series.push(Series {
                    label: "tilt part".into(),
                    color: "#2ca02c",
                    dashed: true,
                    points: t_s
                        .iter()
                        .zip(tilt)
                        .map(|(t, x)| (*t, x[k - 3] * deg))
                        .collect(),
                });
            }
            Panel {
                title: names[k].into(),
                unit: if k < 3 { "m".into() } else { "°".into() },
                series,
                limits: vec![box_min[k] * sc, box_max[k] * sc],
            }
        })
        .collect::<Vec<_>>();
    panels_svg(title, &panels, 2)
}

/// A labelled scatter (x, y, label) with axis titles, e.g. perception error against workspace
/// use of several tunings; `highlight` points are drawn red.
pub fn scatter_svg(
    title: &str,
    x_title: &str,
    y_title: &str,
    points: &[(f64, f64, String, bool)],
) -> String {
    let (w, h, l, b, t, r) = (820.0, 440.0, 60.0, 40.0, 30.0, 120.0);
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="11"><rect width="100%" height="100%" fill="white"/>"#
    );
    let _ = write!(
        s,
        r#"<text x="8" y="18" font-size="13">{}</text>"#,
        esc(title)
    );
    let fin: Vec<&(f64, f64, String, bool)> = points
        .iter()
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    if fin.is_empty() {
        s.push_str("<text x=\"60\" y=\"60\">no data</text></svg>\n");
        return s;
    }
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in &fin {
        x0 = x0.min(p.0);
        x1 = x1.max(p.0);
        y0 = y0.min(p.1);
        y1 = y1.max(p.1);
    }
    let (dx, dy) = ((x1 - x0).max(1e-9) * 0.08, (y1 - y0).max(1e-9) * 0.08);
    let (x0, x1, y0, y1) = (x0 - dx, x1 + dx, y0 - dy, y1 + dy);
    let px = |x: f64| l + (x - x0) / (x1 - x0) * (w - l - r);
    let py = |y: f64| h - b - (y - y0) / (y1 - y0) * (h - b - t);
    let _ = write!(
        s,
        r##"<rect x="{l}" y="{t}" width="{:.1}" height="{:.1}" fill="none" stroke="#888"/>"##,
        w - l - r,
        h - b - t
    );
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
        (l + w - r) / 2.0,
        h - 8.0,
        esc(x_title)
    );
    let _ = write!(
        s,
        r#"<text x="14" y="{:.1}" transform="rotate(-90 14 {:.1})" text-anchor="middle">{}</text>"#,
        (t + h - b) / 2.0,
        (t + h - b) / 2.0,
        esc(y_title)
    );
    let _ = write!(
        s,
        r#"<text x="{l}" y="{:.1}">{}</text>"#,
        h - b + 13.0,
        fmt(x0)
    );
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
        w - r,
        h - b + 13.0,
        fmt(x1)
    );
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
        l - 3.0,
        py(y0),
        fmt(y0)
    );
    let _ = write!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
        l - 3.0,
        py(y1) + 9.0,
        fmt(y1)
    );
    for p in fin {
        let c = if p.3 { "red" } else { "#1f77b4" };
        let _ = write!(
            s,
            r#"<circle cx="{:.1}" cy="{:.1}" r="3.5" fill="{c}"/>"#,
            px(p.0),
            py(p.1)
        );
        if !p.2.is_empty() {
            let _ = write!(
                s,
                r#"<text x="{:.1}" y="{:.1}" fill="{c}">{}</text>"#,
                px(p.0) + 5.0,
                py(p.1) - 4.0,
                esc(&p.2)
            );
        }
    }
    s.push_str("</svg>\n");
    s
}
