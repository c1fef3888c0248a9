//! The maps of `crs model planar / workspace --reachable / sensitivity --svg` parsed with a real
//! XML parser (roxmltree): well-formed, one cell per grid point the analysis draws, and the
//! plant's disagreements and the cells' numbers where the report's data put them.

use cdpr_model::config::load_platform;
use cdpr_model::workspace::Reach;
use crs_test_support::fixtures::config;
use model_analysis::planar::{PlanarRequest, planar};
use model_analysis::reachable::{Measured, PlantMeasurement, ReachableReport, predict};
use model_analysis::sensitivity::{MapPoint, SensitivityRequest, sensitivity};
use nalgebra::Vector3;

fn temp(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("model-analysis-{name}-{}.svg", std::process::id()))
}

/// Rects filled with one of `fills` (`#RRGGBB`).
fn cells<'a>(doc: &'a roxmltree::Document<'a>, fills: &[&str]) -> Vec<roxmltree::Node<'a, 'a>> {
    doc.descendants()
        .filter(|n| n.tag_name().name() == "rect")
        .filter(|n| n.attribute("fill").is_some_and(|f| fills.contains(&f)))
        .collect()
}

fn texts(doc: &roxmltree::Document<'_>) -> Vec<String> {
    doc.descendants()
        .filter(|n| n.tag_name().name() == "text")
        .filter_map(|n| n.text().map(|t| t.trim().to_string()))
        .collect()
}

#[test]
fn the_planar_map_has_a_cell_per_wrench_feasible_grid_point() {
    let h = 0.5;
    let mut r = planar(&PlanarRequest {
        f_min_n: 1000.0,
        f_max_n: 8000.0,
        k_f_n: 2e6,
        grid_m: h,
    })
    .unwrap();
    let p = temp("planar");
    r.write_svg(&p).unwrap();
    let svg = std::fs::read_to_string(&p).unwrap();
    std::fs::remove_file(&p).ok();
    let doc = roxmltree::Document::parse(&svg).expect("well-formed SVG");
    // W_PHYS (exact test) is the count of its grid points times h².
    let feasible = (r.w_exact / (h * h)).round() as usize;
    assert!(feasible > 10, "{feasible}");
    let drawn = cells(&doc, &["#4A7FC1", "#B9B9B9"]);
    assert_eq!(drawn.len(), feasible, "one cell per W_PHYS point");
    let closed = cells(&doc, &["#4A7FC1"]).len();
    assert!(closed > 0 && closed <= (r.w_closed / (h * h)).round() as usize);
    // Outlines are closed polylines around their cells.
    let outlined = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "polyline" && n.attribute("stroke") == Some("#E0218A"))
        .count();
    assert!(outlined > 0 && outlined <= (r.reach.area_m2 / (h * h)).round() as usize);
    // The four frame anchors (and the legend's sample).
    let anchors = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "circle" && n.attribute("fill") == Some("#FF0000"))
        .count();
    assert_eq!(anchors, 4 + 1);
    assert!(
        texts(&doc)
            .iter()
            .any(|t| t.starts_with("magenta outline: reachable"))
    );
    assert!(r.to_string().contains("map written to"));
}

#[test]
fn the_reachable_slice_marks_where_the_plant_disagrees() {
    let pf = load_platform(config("icosahedron.toml")).unwrap();
    let n = 3;
    let prediction = predict(&pf, &pf.region.position, &Vector3::zeros(), n).unwrap();
    // A plant that failed everywhere disagrees exactly where the prediction reaches.
    let measured = vec![Measured::Failed; prediction.refs.len()];
    let refs = prediction.refs.clone();
    let points = prediction.analysis.points.clone();
    let exact = prediction.exact.clone();
    let mut r = ReachableReport::new(
        &pf,
        pf.region.position,
        n,
        prediction,
        Some(PlantMeasurement {
            config: "failing plant".into(),
            measured,
            seconds: 0.0,
        }),
    );
    let p = temp("reachable");
    r.write_svg(&p).unwrap();
    let svg = std::fs::read_to_string(&p).unwrap();
    std::fs::remove_file(&p).ok();
    let doc = roxmltree::Document::parse(&svg).expect("well-formed SVG");
    // The slice: the grid's z nearest home.
    let dz = |k: usize| (refs[k].r.z - pf.home.r.z).abs();
    let kz = (0..n).min_by(|a, b| dz(*a).total_cmp(&dz(*b))).unwrap();
    let in_slice: Vec<usize> = (0..refs.len()).filter(|i| i % n == kz).collect();
    assert_eq!(in_slice.len(), n * n);
    let reach = in_slice
        .iter()
        .filter(|&&i| {
            matches!(
                points[i].1,
                Reach::Settled {
                    within_limits: true,
                    ..
                }
            )
        })
        .count();
    let grey = in_slice
        .iter()
        .filter(|&&i| {
            exact[i]
                && !matches!(
                    points[i].1,
                    Reach::Settled {
                        within_limits: true,
                        ..
                    }
                )
        })
        .count();
    assert!(reach > 0, "home's slice has reachable points");
    assert_eq!(cells(&doc, &["#1F6FBF"]).len(), reach);
    assert_eq!(cells(&doc, &["#B0B0B0"]).len(), grey);
    let circles = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "circle" && n.attribute("stroke") == Some("#D62728"))
        .count();
    assert_eq!(
        circles,
        reach + 1,
        "a circle per disagreement and the legend's"
    );
    let t = texts(&doc);
    assert!(
        t.iter()
            .any(|x| x == "red circles: the plant (failing plant) disagrees with the prediction"),
        "{t:?}"
    );
}

#[test]
fn the_sensitivity_map_has_a_cell_per_point_of_the_slice_with_its_number() {
    let pf = load_platform(config("icosahedron.toml")).unwrap();
    let req = |map| SensitivityRequest {
        frame_anchor_sigma_mm: 1.0,
        platform_anchor_sigma_mm: 1.0,
        stiffness_sigma_pct: 5.0,
        top: 5,
        map_resolution: map,
    };
    // No map: nothing written, no error.
    let p = temp("sensitivity-none");
    sensitivity(&pf, "home", &pf.home, &req(None))
        .unwrap()
        .write_svg(&p)
        .unwrap();
    assert!(!p.exists());
    let n = 3;
    let mut r = sensitivity(&pf, "home", &pf.home, &req(Some(n))).unwrap();
    let p = temp("sensitivity");
    r.write_svg(&p).unwrap();
    let svg = std::fs::read_to_string(&p).unwrap();
    std::fs::remove_file(&p).ok();
    let doc = roxmltree::Document::parse(&svg).expect("well-formed SVG");
    let map = r.map.as_ref().unwrap();
    assert_eq!(map.len(), n * n * n);
    assert_eq!(cells(&doc, &["#D95F02", "#B0B0B0", "#000000"]).len(), n * n);
    // The numbers are the estimated RMS errors of the slice in mm.
    let b = &pf.region.position;
    let z = |k: usize| b.min.z + (b.max.z - b.min.z) * k as f64 / (n - 1) as f64;
    let kz = (0..n)
        .min_by(|i, j| {
            (z(*i) - pf.home.r.z)
                .abs()
                .total_cmp(&(z(*j) - pf.home.r.z).abs())
        })
        .unwrap();
    let t = texts(&doc);
    let mut estimated = 0;
    for (_, (_, p)) in map.iter().enumerate().filter(|(i, _)| i % n == kz) {
        if let MapPoint::Estimated(v) = p {
            estimated += 1;
            let want = format!("{:.1}", v * 1e3);
            assert!(t.contains(&want), "{want} missing: {t:?}");
        }
    }
    assert!(estimated > 0);
    assert_eq!(cells(&doc, &["#D95F02"]).len(), estimated);
}
