//! Residual diagnosis: for each effect the plant can switch on, data with that effect (not
//! declared in the data set) must lead the pipeline, started from the nominal model, to choose
//! that effect and cut the held-out error; with no effect nothing may be added.

#[path = "../../calibrate/tests/common/mod.rs"]
mod common;
use calibrate::split;
use calibrate_diagnosis::effects::Effect;
use calibrate_diagnosis::pipeline::{self, PipelineConfig, PipelineReport};
use common::*;
use sim_plant::config::Effects;

fn run(effects: Effects) -> PipelineReport {
    let obs = campaign(effects, 20, 11, true);
    let (train, holdout) = split(&obs, 4);
    let nominal = nominal();
    let cfg = PipelineConfig::default();
    let rep =
        pipeline::run(&nominal.model, &train, &holdout, &cfg, &mut |_, _, _| {}).expect("pipeline");
    for s in &rep.stages {
        eprintln!(
            "{:<45} pos {:8.3} mm  rot {:7.4} deg  len {:8.3} mm  f {:?}",
            s.name,
            s.holdout.pos_mean_mm,
            s.holdout.rot_mean_deg,
            s.holdout.len_mean_mm,
            s.holdout.force_mean_n
        );
    }
    if let Some(sel) = &rep.selection {
        for (k, round) in sel.rounds.iter().enumerate() {
            for c in round {
                eprintln!(
                    "round {k} {:<11} score {:10.3e} (crit {:6.1}) rms {:.4e} -> {:.4e} bic {:.1} -> {:.1}: {}",
                    c.effect.name(),
                    c.score,
                    c.score_critical,
                    c.holdout_rms_before,
                    c.holdout_rms_after,
                    c.bic_before,
                    c.bic_after,
                    c.verdict
                );
            }
        }
    }
    rep
}

/// Held-out error measure a test asserts on.
#[derive(Clone, Copy, Debug)]
enum Metric {
    Position,
    Length,
    Force,
}

/// Asserts `effect` is chosen first and the held-out error `metric` of the final model is at
/// least `factor` times smaller than that of the optimal base elastostatic model.
fn check(effects: Effects, effect: Effect, metric: Metric, factor: f64) -> PipelineReport {
    let rep = run(effects);
    let sel = rep.selection.as_ref().expect("selection ran");
    assert_eq!(sel.chosen.first(), Some(&effect), "chosen {:?}", sel.chosen);
    // The chosen model's final estimate uses every sample and sizes the same effects.
    let all = rep
        .all_samples
        .as_ref()
        .expect("final estimate on all samples");
    assert_eq!(all.samples, rep.n_train + rep.n_holdout);
    let effects_of = |s: &[calibrate_diagnosis::effects::EffectSize]| {
        s.iter().map(|z| (z.effect, z.form)).collect::<Vec<_>>()
    };
    assert_eq!(effects_of(&all.sizes), effects_of(&sel.sizes));
    let base = rep.stage("optimal elastostatic").unwrap().holdout.clone();
    let fin = rep.final_stage().holdout.clone();
    let get = |e: &calibrate::validate::Errors| match metric {
        Metric::Position => e.pos_mean_mm,
        Metric::Length => e.len_mean_mm,
        Metric::Force => e.force_mean_n.unwrap_or(f64::NAN),
    };
    assert!(
        get(&fin) * factor <= get(&base),
        "held-out {metric:?} error {:.4} -> {:.4}, expected a factor {factor}",
        get(&base),
        get(&fin)
    );
    rep
}

fn crs() -> Effects {
    crs_like_effects()
}

#[test]
fn no_effect_nothing_added() {
    // Tracker and force-sensor noise only: noise is not an effect.
    let fx = crs();
    let effects = Effects {
        tracker: fx.tracker,
        ..Effects::default()
    };
    let rep = run(effects);
    assert!(rep.selection.unwrap().chosen.is_empty());
    assert!(rep.all_samples.is_none() && rep.all_samples_failure.is_none());
}

#[test]
fn pulleys_are_found() {
    check(
        Effects {
            pulleys: crs().pulleys,
            ..Effects::default()
        },
        Effect::Pulleys,
        Metric::Position,
        10.0,
    );
}

#[test]
fn powertrain_is_found() {
    check(
        Effects {
            powertrain: crs().powertrain,
            ..Effects::default()
        },
        Effect::Powertrain,
        Metric::Position,
        10.0,
    );
}

#[test]
fn tension_dependent_stiffness_is_found() {
    check(
        Effects {
            stiffness: crs().stiffness,
            ..Effects::default()
        },
        Effect::Stiffness,
        Metric::Length,
        2.0,
    );
}

#[test]
fn hysteresis_is_found() {
    check(
        Effects {
            hysteresis: crs().hysteresis,
            ..Effects::default()
        },
        Effect::Hysteresis,
        Metric::Force,
        2.0,
    );
}

#[test]
fn sag_is_found() {
    check(
        Effects {
            sag: crs().sag,
            ..Effects::default()
        },
        Effect::Sag,
        Metric::Length,
        2.0,
    );
}

#[test]
fn drum_radius_errors_are_found() {
    let rep = check(
        Effects {
            winch: crs().winch,
            ..Effects::default()
        },
        Effect::Drum,
        Metric::Position,
        10.0,
    );
    // More samples, a tighter size: the final estimate's 1σ is below the training fit's.
    let sigma = |s: &[calibrate_diagnosis::effects::EffectSize]| {
        s.iter()
            .find_map(|z| z.rms)
            .expect("a drum size with its 1σ")
            .sigma
    };
    let train = sigma(&rep.selection.as_ref().unwrap().sizes);
    let all = sigma(&rep.all_samples.as_ref().unwrap().sizes);
    assert!(
        all < train,
        "1σ on all samples {all:e} vs training {train:e}"
    );
}

#[test]
fn load_centre_of_gravity_is_found() {
    check(
        Effects {
            load: crs().load,
            ..Effects::default()
        },
        Effect::LoadCog,
        Metric::Position,
        2.0,
    );
}

#[test]
fn force_sensor_errors_are_found() {
    // Gains and offsets of the CRS-like plant without the 20 N noise: with the noise the
    // signature is significant and the BIC drops, but the held-out gain stays ≈ 1 % (< 5 %).
    let mut fs = crs().force_sensors.unwrap();
    fs.noise = 0.0;
    check(
        Effects {
            force_sensors: Some(fs),
            ..Effects::default()
        },
        Effect::ForceSensors,
        Metric::Force,
        2.0,
    );
}
