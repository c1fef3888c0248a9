//! The flown path against the walls as SVG (cf. fig. 5.19a): a top view (x–y) and a side view
//! (x–z) with the operating region the hard loop enforces (grey), the elastic walls (red,
//! dashed), the path (blue) and where a wall pushed (orange).

use crate::walls::Walls;
use cdpr_model::config::Region;
use std::fmt::Write;

/// One recorded point of a flight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathPoint {
    pub t_s: f64,
    /// Pose [x, y, z, φx, φy, φz] (m, rad).
    pub pose: [f64; 6],
    /// A wall pushed at this point.
    pub contact: bool,
}

/// The SVG of `hover` (the model's path) and, when given, `reference` (what the hard loop
/// followed, e.g. motion-core's setpoints) in the `region` with the `walls`.
pub fn path_svg(
    title: &str,
    region: &Region,
    walls: &Walls,
    hover: &[PathPoint],
    reference: &[[f64; 3]],
) -> String {
    let (w, h, pad) = (460.0, 420.0, 40.0);
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" font-family="sans-serif" font-size="12">"#,
        2.0 * w,
        h + 60.0
    );
    let _ = write!(
        s,
        r#"<text x="10" y="18" font-size="14">{}</text>"#,
        esc(title)
    );
    for (panel, (ax, ay, name)) in [
        (0usize, 1usize, "top view x–y (m)"),
        (0, 2, "side view x–z (m)"),
    ]
    .iter()
    .enumerate()
    .map(|(k, v)| (k, *v))
    {
        let x0 = panel as f64 * w;
        let lo = [region.position.min[ax] - 0.3, region.position.min[ay] - 0.3];
        let hi = [region.position.max[ax] + 0.3, region.position.max[ay] + 0.3];
        let scale = ((w - 2.0 * pad) / (hi[0] - lo[0])).min((h - 2.0 * pad) / (hi[1] - lo[1]));
        let px = |v: f64| x0 + pad + (v - lo[0]) * scale;
        let py = |v: f64| 30.0 + h - pad - (v - lo[1]) * scale;
        let rect = |s: &mut String, a: [f64; 2], b: [f64; 2], style: &str| {
            let _ = write!(
                s,
                r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" {style}/>"#,
                px(a[0]),
                py(b[1]),
                (b[0] - a[0]) * scale,
                (b[1] - a[1]) * scale
            );
        };
        rect(
            &mut s,
            [region.position.min[ax], region.position.min[ay]],
            [region.position.max[ax], region.position.max[ay]],
            r##"fill="#eee" stroke="#888""##,
        );
        rect(
            &mut s,
            [walls.min[ax], walls.min[ay]],
            [walls.max[ax], walls.max[ay]],
            r##"fill="none" stroke="#c00" stroke-dasharray="6 4""##,
        );
        let _ = write!(
            s,
            r#"<text x="{:.1}" y="{:.1}">{name}</text>"#,
            x0 + pad,
            30.0 + h - 8.0
        );
        for (v, label) in [(lo[0], lo[0]), (hi[0], hi[0])] {
            let _ = write!(
                s,
                r#"<text x="{:.1}" y="{:.1}" font-size="10">{label:.1}</text>"#,
                px(v),
                30.0 + h - pad + 14.0
            );
        }
        for (v, label) in [(lo[1], lo[1]), (hi[1], hi[1])] {
            let _ = write!(
                s,
                r#"<text x="{:.1}" y="{:.1}" font-size="10">{label:.2}</text>"#,
                x0 + 4.0,
                py(v)
            );
        }
        if !reference.is_empty() {
            let pts: Vec<String> = reference
                .iter()
                .map(|p| format!("{:.1},{:.1}", px(p[ax]), py(p[ay])))
                .collect();
            let _ = write!(
                s,
                r##"<polyline fill="none" stroke="#2a2" stroke-width="3" stroke-opacity="0.5" points="{}"/>"##,
                pts.join(" ")
            );
        }
        let pts: Vec<String> = hover
            .iter()
            .map(|p| format!("{:.1},{:.1}", px(p.pose[ax]), py(p.pose[ay])))
            .collect();
        let _ = write!(
            s,
            r##"<polyline fill="none" stroke="#15c" stroke-width="1" points="{}"/>"##,
            pts.join(" ")
        );
        for p in hover.iter().filter(|p| p.contact).step_by(5) {
            let _ = write!(
                s,
                r##"<circle cx="{:.1}" cy="{:.1}" r="1.5" fill="#f80"/>"##,
                px(p.pose[ax]),
                py(p.pose[ay])
            );
        }
    }
    let _ = write!(
        s,
        r##"<text x="10" y="{:.0}">grey: operating region (hard loop) · red dashed: elastic walls (eq. 5.22) · blue: hover model · orange: wall pushing{}</text></svg>"##,
        h + 52.0,
        if reference.is_empty() {
            ""
        } else {
            " · green: motion-core's reference"
        }
    );
    s
}

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
