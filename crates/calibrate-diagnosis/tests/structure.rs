//! Unexplained structure: with only tracker and force-sensor noise nothing
//! is flagged; with a drum radius error and the drum left out of the candidates, the final
//! model's held-out length residuals are flagged (the catalogue that was allowed does not
//! explain them), and with the drum allowed the structure goes away.

#[path = "../../calibrate/tests/common/mod.rs"]
mod common;
use calibrate_diagnosis::effects::Effect;
use calibrate_diagnosis::pipeline::{self, PipelineConfig, PipelineReport};
use common::*;
use sim_plant::config::Effects;

fn run(effects: Effects, candidates: Option<Vec<Effect>>) -> PipelineReport {
    let train = campaign(effects.clone(), 30, 21, true);
    let held = campaign(effects, 30, 22, true);
    let mut cfg = PipelineConfig::default();
    if let Some(c) = candidates {
        cfg.select.candidates = c;
    }
    pipeline::run(&nominal().model, &train, &held, &cfg, &mut |_, _, _| {}).expect("pipeline")
}

fn drum_effects() -> Effects {
    let fx = crs_like_effects();
    // The CRS-like drum radius error ×20 (2 mm on the 152.5 mm drum, the top of the
    // diagnosis benchmark's range): the test counts poses, not rows, so it needs a clear one.
    let mut winch = fx.winch.clone().expect("crs-like winch errors");
    winch
        .length_scale
        .iter_mut()
        .for_each(|s| *s = 1.0 + (*s - 1.0) * 20.0);
    Effects {
        winch: Some(winch),
        tracker: fx.tracker,
        force_sensors: fx.force_sensors.map(|mut f| {
            f.offset.iter_mut().for_each(|o| *o = 0.0);
            f.gain.iter_mut().for_each(|g| *g = 1.0);
            f
        }),
        ..Effects::default()
    }
}

#[test]
fn noise_is_not_structure() {
    let fx = crs_like_effects();
    let rep = run(
        Effects {
            tracker: fx.tracker,
            ..Effects::default()
        },
        None,
    );
    let st = rep.structure.as_ref().expect("structure test ran");
    assert!(
        st.cables.iter().all(|c| c.f_stat.is_some()),
        "every cable tested: {st:?}"
    );
    assert!(!st.any(), "{st:?}");
}

#[test]
fn a_drum_error_outside_the_allowed_catalogue_is_flagged_and_goes_with_the_drum() {
    let without = run(drum_effects(), Some(vec![Effect::Sag, Effect::Hysteresis]));
    let st = without.structure.as_ref().expect("structure test ran");
    assert!(st.any(), "{st:?}");
    let md = calibrate_diagnosis::report::markdown(&without, "test", &[]);
    assert!(md.contains("**Unexplained structure** remains"), "{md}");
    let with = run(drum_effects(), None);
    assert!(
        with.selection
            .as_ref()
            .unwrap()
            .chosen
            .contains(&Effect::Drum),
        "{:?}",
        with.selection.as_ref().unwrap().chosen
    );
    let flagged = |r: &PipelineReport| {
        r.structure
            .as_ref()
            .unwrap()
            .cables
            .iter()
            .filter(|c| c.significant)
            .count()
    };
    assert!(
        flagged(&with) < flagged(&without),
        "{} cables flagged with the drum vs {} without",
        flagged(&with),
        flagged(&without)
    );
}

#[test]
fn the_flexible_correction_takes_up_what_the_allowed_catalogue_leaves_and_says_what_it_is() {
    // A tension-dependent stiffness (the CRS-like plant's, no tracker noise, as the stiffness
    // case of tests/effects.rs) with the stiffness candidate not allowed: the force-quadratic
    // term of the correction can take it up.
    let fx = crs_like_effects();
    let effects = Effects {
        stiffness: fx.stiffness,
        ..Effects::default()
    };
    let train = campaign(effects.clone(), 30, 21, true);
    let held = campaign(effects, 30, 22, true);
    let mut cfg = PipelineConfig::default();
    cfg.select.candidates = vec![Effect::Hysteresis];
    cfg.flexible = true;
    let rep =
        pipeline::run(&nominal().model, &train, &held, &cfg, &mut |_, _, _| {}).expect("pipeline");
    assert!(rep.flexible_failure.is_none(), "{:?}", rep.flexible_failure);
    let fin = rep.final_stage();
    assert!(
        fin.name
            .ends_with("flexible length correction (not a physical effect)"),
        "{}",
        fin.name
    );
    assert!(!fin.failed(), "{:?}", fin.holdout.failure_text());
    let before = &rep.stages[rep.stages.len() - 2];
    assert!(
        fin.holdout.len_mean_mm < 0.5 * before.holdout.len_mean_mm,
        "held-out cable-length error {:.3} → {:.3} mm",
        before.holdout.len_mean_mm,
        fin.holdout.len_mean_mm
    );
    // Never a diagnosis: the chosen effects do not name it.
    assert!(
        rep.selection
            .as_ref()
            .unwrap()
            .chosen
            .iter()
            .all(|e| Effect::ALL.contains(e))
    );
    let md = calibrate_diagnosis::report::markdown(&rep, "test", &[]);
    assert!(md.contains("not a physical diagnosis"), "{md}");
    let side = calibrate_diagnosis::report::side_file(&fin.model, &[]);
    assert!(side.contains("flexible_correction_m = [["), "{side}");
}
