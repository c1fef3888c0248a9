//! Figures of a cueing run, drawn with the plot layer (`crs-plot`): panels of time series
//! ([`panels_svg`]), the perception figure (vehicle vs cabin vs perceived, per axis:
//! [`perception_svg`]), the cabin's motion in its cueing box ([`motion_svg`]) and a scatter of
//! tunings ([`scatter_svg`]).

use crate::perception::{PerceptionReport, PerceptionSeries};
use crs_plot::{Chart, Figure, HLine, Line, Markers, Rgb};

/// One line of a panel.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub label: String,
    pub color: Rgb,
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

const PANEL_W: u32 = 460;
const PANEL_H: u32 = 230;
/// Points drawn per line at most (every k-th point of a longer one): a figure of a 10 min
/// run stays a few hundred kB.
const MAX_POINTS: usize = 500;

const BLACK: Rgb = Rgb::BLACK;
const CABIN: Rgb = Rgb(31, 119, 180);
const PERCEIVED_VEHICLE: Rgb = Rgb(85, 85, 85);
const PERCEIVED_CABIN: Rgb = Rgb(255, 127, 14);
const DEMAND: Rgb = Rgb(153, 153, 153);
const TILT: Rgb = Rgb(44, 160, 44);
const LIMIT: Rgb = Rgb(255, 0, 0);

/// Panels in a grid of `columns`, with a title line on top; time in s on every x axis. A
/// series' legend entry is drawn in the first panel that has it only.
pub fn panels_svg(title: &str, panels: &[Panel], columns: usize) -> String {
    let columns = columns.max(1);
    let mut named = std::collections::BTreeSet::new();
    let rows = panels.len().div_ceil(columns).max(1) as u32;
    let charts = panels
        .iter()
        .map(|p| {
            let mut c = Chart::new(
                format!("{} ({})", p.title, p.unit),
                "t (s)",
                p.unit.as_str(),
            );
            c.hlines = p
                .limits
                .iter()
                .map(|&y| HLine {
                    y,
                    color: LIMIT,
                    dashed: true,
                })
                .collect();
            c.lines = p
                .series
                .iter()
                .map(|s| {
                    let step = s.points.len().div_ceil(MAX_POINTS).max(1);
                    let mut l = Line::new(
                        s.label.as_str(),
                        s.color,
                        s.points.iter().step_by(step).copied().collect(),
                    );
                    l.dashed = s.dashed;
                    if !named.insert(s.label.clone()) {
                        l.label = None;
                    }
                    l
                })
                .collect();
            crs_plot::Panel::Chart(c)
        })
        .collect();
    Figure {
        title: title.to_string(),
        size: (columns as u32 * PANEL_W, rows * PANEL_H + 30),
        columns,
        panels: charts,
        notes: Vec::new(),
        legend: Vec::new(),
    }
    .render()
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
                        color: BLACK,
                        dashed: false,
                        points: pick(veh),
                    },
                    Series {
                        label: "cabin".into(),
                        color: CABIN,
                        dashed: false,
                        points: pick(cab),
                    },
                    Series {
                        label: "perceived vehicle".into(),
                        color: PERCEIVED_VEHICLE,
                        dashed: true,
                        points: pick(pveh),
                    },
                    Series {
                        label: "perceived cabin".into(),
                        color: PERCEIVED_CABIN,
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
                    color: DEMAND,
                    dashed: true,
                    points: col(desired),
                },
                Series {
                    label: "cabin".into(),
                    color: CABIN,
                    dashed: false,
                    points: col(pose),
                },
            ];
            if (3..5).contains(&k) {
                series.push(Series {
                    label: "tilt part".into(),
                    color: TILT,
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
    let mut c = Chart::new("", x_title, y_title);
    for (highlight, color) in [(false, CABIN), (true, Rgb::RED)] {
        let pick: Vec<&(f64, f64, String, bool)> =
            points.iter().filter(|p| p.3 == highlight).collect();
        let mut m = Markers::new("", color, pick.iter().map(|p| (p.0, p.1)).collect());
        m.label = None;
        m.radius = 4;
        m.texts = pick.iter().map(|p| p.2.clone()).collect();
        c.markers.push(m);
    }
    Figure::single(title, (900, 520), crs_plot::Panel::Chart(c)).render()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn doc(svg: &str) -> roxmltree::Document<'_> {
        roxmltree::Document::parse(svg).unwrap_or_else(|e| panic!("not XML: {e}\n{svg}"))
    }

    /// Point counts of the polylines drawn in `color` (`#RRGGBB`).
    fn lines(d: &roxmltree::Document<'_>, color: &str) -> Vec<usize> {
        let mut v: Vec<usize> = d
            .descendants()
            .filter(|n| n.tag_name().name() == "polyline" && n.attribute("stroke") == Some(color))
            .map(|n| n.attribute("points").unwrap().split_whitespace().count())
            .collect();
        v.sort();
        v
    }

    fn texts(d: &roxmltree::Document<'_>) -> Vec<String> {
        d.descendants()
            .filter(|n| n.tag_name().name() == "text")
            .filter_map(|n| n.text().map(|t| t.trim().to_string()))
            .collect()
    }

    #[test]
    fn the_perception_figure_has_six_panels_of_vehicle_and_cabin_with_their_errors() {
        let n = 40;
        let mut s = PerceptionSeries::default();
        for k in 0..n {
            let t = k as f64 * 0.05;
            let v = Vector3::new(t.sin(), 0.1 * t, 9.81);
            s.t_s.push(t);
            for x in [
                &mut s.vehicle_f,
                &mut s.vehicle_w,
                &mut s.cabin_f,
                &mut s.cabin_w,
                &mut s.perceived_vehicle_f,
                &mut s.perceived_vehicle_w,
                &mut s.perceived_cabin_f,
                &mut s.perceived_cabin_w,
            ] {
                x.push(v);
            }
        }
        let mut r = PerceptionReport::default();
        r.specific_force[0].perceived.rms_error = 0.123;
        let svg = perception_svg("braking", &s, &r);
        let d = doc(&svg);
        // Solid vehicle (black) and cabin lines: one per panel with all points, plus the
        // legend's sample (2 points) in the first panel only.
        assert_eq!(lines(&d, "#000000").iter().filter(|c| **c == n).count(), 6);
        assert_eq!(lines(&d, "#1F77B4"), [vec![2], vec![n; 6]].concat());
        let t = texts(&d);
        assert!(
            t.iter()
                .any(|x| x.starts_with("f_x: perceived RMS error 0.123, corr. –")),
            "{t:?}"
        );
        for want in [
            "braking",
            "vehicle",
            "cabin",
            "perceived vehicle",
            "perceived cabin",
        ] {
            assert!(t.iter().any(|x| x == want), "{want} missing: {t:?}");
        }
    }

    #[test]
    fn the_motion_figure_draws_the_cueing_box_and_the_tilt_of_roll_and_pitch() {
        let t: Vec<f64> = (0..10).map(|k| k as f64 * 0.1).collect();
        let pose: Vec<[f64; 6]> = t.iter().map(|t| [*t, 0.0, 0.0, 0.01, 0.02, 0.0]).collect();
        let tilt: Vec<[f64; 2]> = t.iter().map(|_| [0.01, 0.02]).collect();
        let svg = motion_svg(
            "motion",
            &t,
            &pose,
            &pose,
            &tilt,
            &[-1.0, -1.0, -1.0, -0.1, -0.1, -0.1],
            &[1.0, 1.0, 1.0, 0.1, 0.1, 0.1],
        );
        let d = doc(&svg);
        assert_eq!(lines(&d, "#1F77B4"), [vec![2], vec![10; 6]].concat());
        let t = texts(&d);
        assert_eq!(t.iter().filter(|x| *x == "tilt part").count(), 1, "{t:?}");
        // The box's limits are dashed red lines: present in every panel.
        assert!(
            d.descendants()
                .filter(|n| n.attribute("stroke") == Some("#FF0000"))
                .count()
                >= 12
        );
    }

    #[test]
    fn the_scatter_has_a_circle_and_a_label_per_tuning_and_red_highlights() {
        let pts = vec![
            (10.0, 0.2, "a".to_string(), false),
            (20.0, 0.1, "b".to_string(), false),
            (15.0, 0.15, "shipped: c".to_string(), true),
            (f64::NAN, 0.1, "lost".to_string(), false),
        ];
        let svg = scatter_svg("trade-off", "use (%)", "error", &pts);
        let d = doc(&svg);
        let fill = |c: &str| {
            d.descendants()
                .filter(|n| n.tag_name().name() == "circle" && n.attribute("fill") == Some(c))
                .count()
        };
        assert_eq!((fill("#1F77B4"), fill("#D62728")), (2, 1));
        let t = texts(&d);
        for want in ["a", "b", "shipped: c", "use (%)", "error", "trade-off"] {
            assert!(t.iter().any(|x| x == want), "{want} missing: {t:?}");
        }
        assert!(!t.iter().any(|x| x == "lost"));
    }

    #[test]
    fn no_data_is_said_not_drawn() {
        let d = scatter_svg("none", "x", "y", &[]);
        assert!(texts(&doc(&d)).iter().any(|t| t.ends_with("no data")));
        let p = panels_svg("empty", &[], 2);
        assert!(texts(&doc(&p)).iter().any(|t| t.ends_with("no data")));
    }
}
