//! The figures parsed back with a real XML parser (roxmltree): well-formed, and holding the
//! elements their data asks for.

use super::*;

/// The SVG parsed; panics with the parser's message (a test failure) if it is not XML.
fn parse(svg: &str) -> roxmltree::Document<'_> {
    roxmltree::Document::parse(svg).unwrap_or_else(|e| panic!("not well-formed XML: {e}\n{svg}"))
}

fn count(doc: &roxmltree::Document<'_>, tag: &str) -> usize {
    doc.descendants()
        .filter(|n| n.tag_name().name() == tag)
        .count()
}

fn texts(doc: &roxmltree::Document<'_>) -> Vec<String> {
    doc.descendants()
        .filter(|n| n.tag_name().name() == "text")
        .filter_map(|n| n.text().map(|t| t.trim().to_string()))
        .collect()
}

fn line_figure(lines: Vec<Line>) -> Figure {
    let mut c = Chart::new("panel", "t (s)", "x (m)");
    c.lines = lines;
    Figure::single("title & <escaped>", (600, 400), Panel::Chart(c))
}

#[test]
fn a_line_chart_has_one_polyline_per_solid_line_through_every_finite_point_and_a_legend() {
    let a = Line::new("first", Rgb::BLUE, vec![(0.0, 0.0), (1.0, 1.0), (2.0, 4.0)]);
    let b = Line::new(
        "second",
        Rgb::RED,
        vec![(0.0, 1.0), (f64::NAN, 2.0), (2.0, 2.0)],
    );
    let svg = line_figure(vec![a, b]).svg().unwrap();
    let doc = parse(&svg);
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    let data: Vec<usize> = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "polyline")
        .filter(|n| matches!(n.attribute("stroke"), Some("#1F77B4") | Some("#D62728")))
        .map(|n| n.attribute("points").unwrap().split_whitespace().count())
        .collect();
    // Two data lines (3 and 2 finite points) and their two legend samples (2 points each).
    let mut sorted = data.clone();
    sorted.sort();
    assert_eq!(sorted, vec![2, 2, 2, 3], "{data:?}");
    let t = texts(&doc);
    for want in [
        "first",
        "second",
        "panel",
        "t (s)",
        "x (m)",
        "title & <escaped>",
    ] {
        assert!(t.iter().any(|s| s == want), "{want} missing in {t:?}");
    }
}

#[test]
fn markers_are_one_circle_per_finite_point_with_their_texts() {
    let mut c = Chart::new("scatter", "a", "b");
    let mut m = Markers::new(
        "pts",
        Rgb::GREEN,
        vec![(0.0, 0.0), (1.0, 2.0), (f64::INFINITY, 1.0)],
    );
    m.texts = vec!["p0".into(), "p1".into(), "never".into()];
    c.markers.push(m);
    let svg = Figure::single("", (500, 400), Panel::Chart(c))
        .svg()
        .unwrap();
    let doc = parse(&svg);
    // Two points and the legend's sample.
    assert_eq!(count(&doc, "circle"), 3);
    let t = texts(&doc);
    assert!(t.contains(&"p0".to_string()) && t.contains(&"p1".to_string()));
    assert!(!t.contains(&"never".to_string()));
}

#[test]
fn cells_are_rectangles_with_their_text_and_an_equal_scale_keeps_squares_square() {
    let mut c = Chart::new("map", "x (m)", "y (m)");
    c.equal_scale = true;
    for i in 0..3 {
        let mut r = Rect::filled((i as f64, 0.0), (i as f64 + 1.0, 1.0), Rgb::ORANGE, 0.5);
        r.text = Some(format!("cell {i}"));
        c.rects.push(r);
    }
    let svg = Figure::single("", (800, 300), Panel::Chart(c))
        .svg()
        .unwrap();
    let doc = parse(&svg);
    let cells: Vec<(f64, f64)> = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "rect" && n.attribute("fill") == Some("#FF7F0E"))
        .map(|n| {
            let v = |a| n.attribute(a).unwrap().parse::<f64>().unwrap();
            (v("width"), v("height"))
        })
        .collect();
    assert_eq!(cells.len(), 3, "{svg}");
    for (w, h) in cells {
        assert!((w - h).abs() <= 2.0, "a 1 m × 1 m cell drawn {w} × {h} px");
    }
    assert!(texts(&doc).contains(&"cell 2".to_string()));
}

#[test]
fn bars_are_one_rectangle_per_finite_value_with_the_group_names() {
    let b = Bars {
        title: "bars".into(),
        y_label: "mm".into(),
        groups: vec!["g1".into(), "g2".into(), "g3".into()],
        series: vec![
            BarSeries {
                label: "s1".into(),
                color: Rgb::RED,
                values: vec![1.0, 2.0, 3.0],
            },
            BarSeries {
                label: "s2".into(),
                color: Rgb::BLUE,
                values: vec![0.5, f64::NAN, 1.5],
            },
        ],
    };
    let svg = Figure::single("", (700, 400), Panel::Bars(b))
        .svg()
        .unwrap();
    let doc = parse(&svg);
    let filled = |c: &str| {
        doc.descendants()
            .filter(|n| n.tag_name().name() == "rect" && n.attribute("fill") == Some(c))
            .count()
    };
    // Bars and one legend sample per series.
    assert_eq!(filled("#D62728"), 3 + 1);
    assert_eq!(filled("#1F77B4"), 2 + 1);
    let t = texts(&doc);
    for want in ["g1", "g2", "g3", "s1", "s2", "mm"] {
        assert!(t.iter().any(|s| s == want), "{want} missing in {t:?}");
    }
}

#[test]
fn empty_and_degenerate_input_draws_an_empty_state_not_a_panic() {
    let cases = vec![
        Figure::single(
            "none",
            (300, 200),
            Panel::Chart(Chart::new("empty", "x", "y")),
        ),
        line_figure(vec![Line::new("nan", Rgb::BLACK, vec![(f64::NAN, 1.0)])]),
        Figure::single(
            "bars",
            (300, 200),
            Panel::Bars(Bars {
                title: "no groups".into(),
                ..Bars::default()
            }),
        ),
        Figure {
            title: "no panels".into(),
            size: (0, 0),
            columns: 0,
            panels: vec![],
            notes: vec!["a note".into()],
            legend: Vec::new(),
        },
    ];
    for f in cases {
        let svg = f.svg().unwrap();
        let doc = parse(&svg);
        assert!(
            texts(&doc).iter().any(|t| t.ends_with("no data")),
            "{}: {svg}",
            f.title
        );
    }
    // One point, or all points equal: a visible range around it.
    let svg = line_figure(vec![Line::new(
        "one",
        Rgb::BLACK,
        vec![(3.0, 3.0), (3.0, 3.0)],
    )])
    .svg()
    .unwrap();
    parse(&svg);
    // Dashed lines of no, one and only non-finite points; a limit that is not a number.
    let dashed = |points: Vec<(f64, f64)>| {
        let mut l = Line::new("dashed", Rgb::GREY, points);
        l.dashed = true;
        l
    };
    let mut c = Chart::new("dashed", "x", "y");
    c.lines = vec![
        dashed(vec![]),
        dashed(vec![(1.0, 1.0)]),
        dashed(vec![(f64::NAN, f64::NAN), (2.0, 2.0)]),
    ];
    c.hlines.push(HLine {
        y: f64::NAN,
        color: Rgb::RED,
        dashed: true,
    });
    parse(
        &Figure::single("", (300, 200), Panel::Chart(c))
            .svg()
            .unwrap(),
    );
    // A height of zero is drawn at the smallest size.
    let tiny = Figure::single("", (500, 0), Panel::Chart(Chart::new("t", "x", "y")));
    let svg = tiny.svg().unwrap();
    assert_eq!(parse(&svg).root_element().attribute("height"), Some("64"));
    // A given range that is not one falls back to the data's.
    let mut c = Chart::new("bad range", "x", "y");
    c.x_range = Some((1.0, 1.0));
    c.y_range = Some((f64::NAN, 2.0));
    c.lines
        .push(Line::new("l", Rgb::BLACK, vec![(0.0, 0.0), (1.0, 1.0)]));
    parse(
        &Figure::single("", (300, 200), Panel::Chart(c))
            .svg()
            .unwrap(),
    );
}

#[test]
fn limits_and_notes_are_drawn() {
    let mut c = Chart::new("limits", "t (s)", "m");
    c.lines
        .push(Line::new("x", Rgb::BLUE, vec![(0.0, 0.0), (1.0, 0.5)]));
    c.hlines.push(HLine {
        y: 1.0,
        color: Rgb(255, 0, 0),
        dashed: false,
    });
    let mut f = Figure::single("", (400, 300), Panel::Chart(c));
    f.notes = vec!["red: the limit".into()];
    let svg = f.svg().unwrap();
    let doc = parse(&svg);
    assert_eq!(
        doc.descendants()
            .filter(
                |n| n.tag_name().name() == "polyline" && n.attribute("stroke") == Some("#FF0000")
            )
            .count(),
        1
    );
    assert!(texts(&doc).contains(&"red: the limit".to_string()));
}

#[test]
fn a_legend_strip_sits_above_every_panel_and_the_charts_draw_no_legend_of_their_own() {
    let mut panels = Vec::new();
    for k in 0..2 {
        let mut c = Chart::new(format!("panel {k}"), "t (s)", "m");
        let mut l = Line::new("unused", Rgb::BLUE, vec![(0.0, 1.0), (1.0, 2.0)]);
        l.label = None;
        c.lines.push(l);
        panels.push(Panel::Chart(c));
    }
    let f = Figure {
        title: String::new(),
        size: (800, 300),
        columns: 2,
        panels,
        notes: Vec::new(),
        legend: vec![
            ("reference".into(), Rgb::ORANGE),
            ("plant".into(), Rgb::BLUE),
        ],
    };
    let svg = f.svg().unwrap();
    let doc = parse(&svg);
    let t = texts(&doc);
    assert!(t.contains(&"reference".to_string()) && t.contains(&"plant".to_string()));
    assert!(!t.contains(&"unused".to_string()), "{t:?}");
    // The strip's samples lie above the top of every plot area (the strip is 30 px high).
    let samples: Vec<f64> = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "polyline" && n.attribute("stroke-width") == Some("3"))
        .map(|n| {
            let pts = n.attribute("points").unwrap();
            pts.split([' ', ','])
                .filter(|s| !s.is_empty())
                .nth(1)
                .unwrap()
                .parse()
                .unwrap()
        })
        .collect();
    assert_eq!(samples.len(), 2, "{svg}");
    assert!(samples.iter().all(|y| *y < 30.0), "{samples:?}");
    // Both data lines drawn below the strip.
    let data_y: Vec<f64> = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "polyline" && n.attribute("stroke-width") == Some("1"))
        .filter(|n| n.attribute("stroke") == Some("#1F77B4"))
        .flat_map(|n| {
            n.attribute("points")
                .unwrap()
                .split_whitespace()
                .map(|p| p.split(',').nth(1).unwrap().parse::<f64>().unwrap())
                .collect::<Vec<_>>()
        })
        .collect();
    assert_eq!(data_y.len(), 4);
    assert!(data_y.iter().all(|y| *y > 30.0), "{data_y:?}");
}

#[test]
fn marks_labels_named_rows_and_a_log_axis_are_drawn() {
    let mut c = Chart::new("events", "t (s)", "");
    c.y_categories = vec!["motion-core".into(), "drive-io".into()];
    c.x_range = Some((0.0, 10.0));
    c.y_range = Some((-0.5, 1.5));
    c.vlines = vec![
        VLine {
            x: 2.0,
            color: Rgb(200, 30, 30),
            dashed: false,
        },
        VLine {
            x: f64::NAN,
            color: Rgb(200, 30, 30),
            dashed: false,
        },
    ];
    c.labels = vec![
        Label {
            at: (2.0, 1.0),
            text: "fault".into(),
            color: Rgb::BLACK,
        },
        Label {
            at: (f64::NAN, 1.0),
            text: "never".into(),
            color: Rgb::BLACK,
        },
    ];
    let svg = Figure::single("", (600, 300), Panel::Chart(c))
        .svg()
        .unwrap();
    let doc = parse(&svg);
    let t = texts(&doc);
    for want in ["motion-core", "drive-io", "fault"] {
        assert!(t.iter().any(|s| s == want), "{want} missing in {t:?}");
    }
    assert!(!t.contains(&"never".to_string()));
    let marks = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "polyline" && n.attribute("stroke") == Some("#C81E1E"))
        .count();
    assert_eq!(marks, 1);

    // Log axis: 1 … 1000 spans three decades; values ≤ 0 are left out.
    let mut c = Chart::new("lateness", "t (s)", "µs");
    c.y_log = true;
    c.lines.push(Line::new(
        "p99",
        Rgb::GREEN,
        vec![(0.0, 1.0), (1.0, 0.0), (2.0, 10.0), (3.0, 1000.0)],
    ));
    let svg = Figure::single("", (600, 300), Panel::Chart(c))
        .svg()
        .unwrap();
    let doc = parse(&svg);
    let ys: Vec<f64> = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "polyline" && n.attribute("stroke") == Some("#2CA02C"))
        .filter(|n| n.attribute("points").unwrap().split_whitespace().count() == 3)
        .flat_map(|n| {
            n.attribute("points")
                .unwrap()
                .split_whitespace()
                .map(|p| p.split(',').nth(1).unwrap().parse::<f64>().unwrap())
                .collect::<Vec<_>>()
        })
        .collect();
    assert_eq!(ys.len(), 3, "{svg}");
    // Equal ratios are equal distances: 1 → 10 as far as 10 → 1000 is half of.
    let (d1, d2) = (ys[0] - ys[1], ys[1] - ys[2]);
    assert!((d2 - 2.0 * d1).abs() <= 2.0, "{ys:?}");
    assert_ne!(Rgb::palette(0), Rgb::palette(1));
}
