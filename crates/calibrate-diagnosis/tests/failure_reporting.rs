//! A step whose forward kinematics fails on held-out samples is reported as failed, with the
//! count, never as a number: held-out commands with every cable 4 m slack cannot
//! hold the platform (no elastostatic equilibrium exists), so every elastostatic step must fail
//! there while the kinematic least-squares FK still converges.

#[path = "../../calibrate/tests/common/mod.rs"]
mod common;
use calibrate::split;
use calibrate_diagnosis::pipeline::{self, PipelineConfig};
use calibrate_diagnosis::report;
use common::*;
use sim_plant::config::Effects;

#[test]
fn failed_fk_is_reported_as_failed_never_as_zero() {
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
    let n = holdout.len();
    let el = rep
        .stage("optimal elastostatic")
        .expect("elastostatic step");
    assert!(
        el.failed(),
        "slack held-out commands must fail the elastostatic FK"
    );
    assert_eq!(el.holdout.total(), n);
    assert!(rep.final_stage().failed());
    let validated = rep
        .last_validated_stage()
        .expect("a kinematic step validates");
    assert!(validated.name.contains("kinematic"), "{}", validated.name);
    let table = report::stage_table(&rep);
    let md = report::markdown(&rep, "test", &[]);
    for line in table.lines().filter(|l| l.contains("elastostatic")) {
        assert!(line.contains("failed"), "{line}");
        assert!(
            line.contains(&format!("FK failed on {}/{n}", el.holdout.fk_failures)),
            "{line}"
        );
        assert!(
            !line.contains("0.00 /"),
            "a failure printed as a number: {line}"
        );
    }
    assert!(md.contains("## Failures"), "{md}");
    assert!(!md.contains("NaN"), "{md}");
}

#[test]
fn bounded_identification_keeps_stiffness_physical() {
    // Readings 40× the true forces (a wrong load-cell unit, ±40 % per cable): the elongation
    // f/k_F then asks for k_F ≈ 80 MN/m, which the unbounded fit returns.
    let mut obs = campaign(Effects::default(), 16, 9, true);
    for o in &mut obs {
        if let Some(f) = &mut o.forces {
            for (i, v) in f.iter_mut().enumerate() {
                *v *= 40.0 * (1.0 + 0.4 * (i as f64 - 3.5) / 3.5);
            }
        }
    }
    let (train, holdout) = split(&obs, 4);
    let nominal = nominal();
    let rep = pipeline::run(
        &nominal.model,
        &train,
        &holdout,
        &PipelineConfig::default(),
        &mut |_, _, _| {},
    )
    .expect("pipeline");
    for st in &rep.stages {
        for (i, k) in st.model.k_f.iter().enumerate() {
            assert!(
                (calibrate::params::KF_MIN_N..=calibrate::params::KF_MAX_N).contains(k),
                "{}: k_F{} = {k:e}",
                st.name,
                i + 1
            );
        }
        for l in &st.model.extra_length {
            assert!((0.0..=calibrate::params::STORED_ROPE_MAX_M).contains(l));
        }
    }
    let md = report::markdown(&rep, "test", &[]);
    assert!(!md.contains("NaN"), "{md}");
    assert!(!md.contains("± 0.0e0"), "{md}");
}
