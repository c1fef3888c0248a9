//! The calibration report's plots parsed with a real XML parser (roxmltree): every figure is
//! well-formed, the step chart has a bar for each step that validated and none for a failed
//! one, and the per-cable chart a group per cable.

#[path = "../../calibrate/tests/common/mod.rs"]
mod common;
use calibrate::split;
use calibrate_diagnosis::pipeline::{self, PipelineConfig};
use calibrate_diagnosis::report;
use common::*;

fn filled(doc: &roxmltree::Document<'_>, color: &str) -> usize {
    doc.descendants()
        .filter(|n| n.tag_name().name() == "rect" && n.attribute("fill") == Some(color))
        .count()
}

fn texts(doc: &roxmltree::Document<'_>) -> Vec<String> {
    doc.descendants()
        .filter(|n| n.tag_name().name() == "text")
        .filter_map(|n| n.text().map(|t| t.trim().to_string()))
        .collect()
}

#[test]
fn the_plots_are_well_formed_and_a_failed_step_gets_no_bar() {
    // Slack held-out commands fail every elastostatic step's FK (tests/failure_reporting.rs).
    let obs = campaign(crs_like_effects(), 16, 5, true);
    let (train, mut holdout) = split(&obs, 4);
    for o in &mut holdout {
        o.q_cmd.iter_mut().for_each(|q| *q += 4.0);
    }
    let nominal = nominal();
    let rep = pipeline::run(
        &nominal.model,
        &train,
        &holdout,
        &PipelineConfig::default(),
        &mut |_, _, _| {},
    )
    .expect("pipeline");
    let plots = report::plots(&rep, &holdout);
    let names: Vec<&str> = plots.iter().map(|(n, _)| n.as_str()).collect();
    for want in [
        "residuals_per_cable.svg",
        "error_over_workspace.svg",
        "steps.svg",
        "condition.svg",
    ] {
        assert!(names.contains(&want), "{want} missing: {names:?}");
    }
    for (name, svg) in &plots {
        let doc = roxmltree::Document::parse(svg)
            .unwrap_or_else(|e| panic!("{name} is not well-formed: {e}"));
        assert_eq!(doc.root_element().tag_name().name(), "svg", "{name}");
        match name.as_str() {
            "steps.svg" => {
                let validated = rep.stages.iter().filter(|s| !s.failed()).count();
                let failed = rep.stages.len() - validated;
                assert!(failed > 0 && validated > 0, "the scenario has both");
                // One bar per validated step and the legend's sample.
                assert_eq!(filled(&doc, "#1F77B4"), validated + 1, "{svg}");
                let t = texts(&doc);
                assert_eq!(
                    t.iter().filter(|x| x.starts_with("step ")).count(),
                    validated,
                    "{t:?}"
                );
            }
            "residuals_per_cable.svg" => {
                let m = rep.stages[0].model.m();
                let t = texts(&doc);
                for i in 1..=m {
                    assert!(t.contains(&format!("cable {i}")), "cable {i}: {t:?}");
                }
                assert!(t.contains(&"mm".to_string()));
            }
            "error_over_workspace.svg" => {
                // One dot per held-out sample the first step's model predicts (its FK
                // converges), plus the legend's sample.
                let first = &rep.stages[0];
                let predicted = holdout
                    .iter()
                    .filter(|o| calibrate::validate::predict(first.kind, &first.model, o).is_ok())
                    .count();
                assert!(predicted > 0);
                let red = doc
                    .descendants()
                    .filter(|n| {
                        n.tag_name().name() == "circle" && n.attribute("fill") == Some("#D62728")
                    })
                    .count();
                assert_eq!(red, predicted + 1);
            }
            _ => {}
        }
    }
}
