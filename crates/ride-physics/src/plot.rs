//! The flown path against the walls (cf. fig. 5.19a), drawn with the plot layer (`crs-plot`):
//! a top view (x–y) and a side view (x–z) with the operating region the hard loop enforces
//! (grey), the elastic walls (red, dashed), the path (blue) and where a wall pushed (orange).

use crate::walls::Walls;
use cdpr_model::config::Region;
use crs_plot::{Chart, Figure, Line, Markers, Panel, Rect, Rgb};

/// One recorded point of a flight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathPoint {
    pub t_s: f64,
    /// Pose [x, y, z, φx, φy, φz] (m, rad).
    pub pose: [f64; 6],
    /// A wall pushed at this point.
    pub contact: bool,
}

const HOVER: Rgb = Rgb(17, 85, 204);
const REFERENCE: Rgb = Rgb(34, 170, 34);
const CONTACT: Rgb = Rgb(255, 136, 0);
const WALL: Rgb = Rgb(204, 0, 0);

/// The SVG of `hover` (the model's path) and, when given, `reference` (what the hard loop
/// followed, e.g. motion-core's setpoints) in the `region` with the `walls`.
pub fn path_svg(
    title: &str,
    region: &Region,
    walls: &Walls,
    hover: &[PathPoint],
    reference: &[[f64; 3]],
) -> String {
    let (lo, hi) = (region.position.min, region.position.max);
    let panels = [
        (1usize, "top view x–y (m)", "y (m)"),
        (2, "side view x–z (m)", "z (m)"),
    ]
    .into_iter()
    .map(|(ay, name, y_label)| {
        let mut c = Chart::new(name, "x (m)", y_label);
        c.equal_scale = true;
        c.x_range = Some((lo[0] - 0.3, hi[0] + 0.3));
        c.y_range = Some((lo[ay] - 0.3, hi[ay] + 0.3));
        let mut grey = Rect::filled((lo[0], lo[ay]), (hi[0], hi[ay]), Rgb(238, 238, 238), 1.0);
        grey.stroke = Some((Rgb(136, 136, 136), 1, false));
        c.rects.push(grey);
        c.rects.push(Rect::outlined(
            (walls.min[0], walls.min[ay]),
            (walls.max[0], walls.max[ay]),
            WALL,
            true,
        ));
        if !reference.is_empty() {
            let mut l = Line::new(
                "motion-core's reference",
                REFERENCE,
                reference.iter().map(|p| (p[0], p[ay])).collect(),
            );
            l.width = 3;
            l.opacity = 0.5;
            c.lines.push(l);
        }
        c.lines.push(Line::new(
            "hover model",
            HOVER,
            hover.iter().map(|p| (p.pose[0], p.pose[ay])).collect(),
        ));
        let mut pushed = Markers::new(
            "wall pushing",
            CONTACT,
            hover
                .iter()
                .filter(|p| p.contact)
                .step_by(5)
                .map(|p| (p.pose[0], p.pose[ay]))
                .collect(),
        );
        pushed.radius = 2;
        c.markers.push(pushed);
        // The note under the views names the colours; a legend box would cover the path.
        c.lines.iter_mut().for_each(|l| l.label = None);
        c.markers.iter_mut().for_each(|m| m.label = None);
        Panel::Chart(c)
    })
    .collect();
    Figure {
        title: title.to_string(),
        size: (920, 520),
        columns: 2,
        panels,
        notes: vec![format!(
            "grey: operating region (hard loop) · red dashed: elastic walls (eq. 5.22) · blue: hover model · orange: wall pushing{}",
            if reference.is_empty() {
                ""
            } else {
                " · green: motion-core's reference"
            }
        )],
        legend: Vec::new(),
    }
    .render()
}

#[cfg(test)]
mod tests {
    use super::*;
    use cdpr_model::workspace::PositionBox;
    use nalgebra::Vector3;

    fn region() -> Region {
        Region {
            position: PositionBox {
                min: Vector3::new(-2.0, -1.5, 1.0),
                max: Vector3::new(2.0, 1.5, 3.0),
            },
            rotation_min: Vector3::repeat(-0.2),
            rotation_max: Vector3::repeat(0.2),
        }
    }

    fn walls() -> Walls {
        Walls {
            min: Vector3::new(-1.8, -1.3, 1.2),
            max: Vector3::new(1.8, 1.3, 2.8),
            stiffness: 1e4,
            damping: 1e3,
        }
    }

    fn polylines<'a>(doc: &'a roxmltree::Document<'a>, stroke: &str) -> Vec<usize> {
        doc.descendants()
            .filter(|n| n.tag_name().name() == "polyline" && n.attribute("stroke") == Some(stroke))
            .map(|n| n.attribute("points").unwrap().split_whitespace().count())
            .collect()
    }

    #[test]
    fn both_views_draw_the_path_its_reference_and_the_wall_contacts() {
        // 12 points, 11 of them pushing a wall: every 5th contact drawn, 3 per view.
        let hover: Vec<PathPoint> = (0..12)
            .map(|k| PathPoint {
                t_s: k as f64 * 0.1,
                pose: [0.1 * k as f64, 0.05 * k as f64, 2.0, 0.0, 0.0, 0.0],
                contact: k > 0,
            })
            .collect();
        let reference = [[0.0, 0.0, 2.0], [0.5, 0.2, 2.1], [1.0, 0.4, 2.2]];
        let svg = path_svg("flight <1>", &region(), &walls(), &hover, &reference);
        let doc = roxmltree::Document::parse(&svg).expect("well-formed SVG");
        // Per view: the path (12 points) and the reference (3).
        assert_eq!(polylines(&doc, "#1155CC"), vec![12, 12], "{svg}");
        assert_eq!(polylines(&doc, "#22AA22"), vec![3, 3]);
        let contacts = doc
            .descendants()
            .filter(|n| n.tag_name().name() == "circle" && n.attribute("fill") == Some("#FF8800"))
            .count();
        assert_eq!(contacts, 2 * 3, "3 contacts per view");
        let text: String = doc
            .descendants()
            .filter_map(|n| n.text())
            .collect::<Vec<_>>()
            .join("|");
        for want in [
            "flight <1>",
            "top view x–y (m)",
            "side view x–z (m)",
            "elastic walls",
            "motion-core's reference",
        ] {
            assert!(text.contains(want), "{want} missing: {text}");
        }
    }

    #[test]
    fn an_empty_flight_draws_the_region_and_no_path() {
        let svg = path_svg("empty", &region(), &walls(), &[], &[]);
        let doc = roxmltree::Document::parse(&svg).expect("well-formed SVG");
        assert!(polylines(&doc, "#1155CC").is_empty(), "no path drawn");
        // The region's and the walls' outlines are drawn all the same (one each per view).
        assert_eq!(polylines(&doc, "#888888"), vec![5, 5]);
        assert!(!svg.contains("motion-core's reference"));
    }
}
