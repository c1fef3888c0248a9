//! The pipeline's optional Cartesian stage (the residual through the forward kinematics, eq.
//! 4.3–4.4; its Jacobian and identification are tested in calibrate's tests/cartesian.rs).

#[path = "../../calibrate/tests/common/mod.rs"]
mod common;
use common::*;

#[test]
fn pipeline_reports_the_cartesian_stage_and_it_lowers_the_held_out_pose_error() {
    // CRS-like plant (geometry errors, pulleys, load, hysteresis, sag, sensor noise: the
    // kinematic model cannot be exact), 30 identification and 15 validation poses.
    let train = campaign(crs_like_effects(), 30, 11, false);
    let holdout = campaign(crs_like_effects(), 15, 1011, false);
    let cfg = calibrate_diagnosis::pipeline::PipelineConfig {
        no_extension: true,
        cartesian: true,
        ..Default::default()
    };
    let rep = calibrate_diagnosis::pipeline::run(
        &nominal().model,
        &train,
        &holdout,
        &cfg,
        &mut |_, _, _| {},
    )
    .expect("pipeline");
    let joint = &rep.stage("optimal kinematic").unwrap().holdout;
    let cart = &rep
        .stage("optimal kinematic (Cartesian residual)")
        .expect("Cartesian stage")
        .holdout;
    eprintln!(
        "held-out position error: joint-space fit {:.2} mm, Cartesian fit {:.2} mm",
        joint.pos_mean_mm, cart.pos_mean_mm
    );
    // It minimises the pose error itself, so it beats the joint-space fit on held-out poses.
    assert!(
        cart.pos_mean_mm < joint.pos_mean_mm,
        "{cart:?} vs {joint:?}"
    );
}
