//! The dynamic wrench in the hard loop's check (eq. 5.13–5.16): with the
//! platform's `[dynamics]` the cycle distributes forces for w = w_e + w_in of the reference's
//! acceleration, so a reference the static check (w_e alone) accepts can be refused: the
//! helicopter cabin at its home pose accelerating upwards at 8 m/s² (within table 5.1's
//! 14 m/s²) needs more than f_max in an upper cable. The planner's accelerations come from what stays
//! feasible (`lifecycle::configure`).
mod common;
use cdpr_model::Pose;
use cdpr_model::dynamics::{Motion, inertial_wrench};
use cdpr_model::statics;
use motion_core::daemon::config;
use motion_core::daemon::cycle::{Cycle, Reference, Rejection};
use motion_core::daemon::lifecycle;
use nalgebra::{Vector3, Vector6};

fn cycles() -> (Cycle, Cycle, cdpr_model::config::Platform) {
    let pf = common::platform("helicopter.toml");
    let stat = Cycle::new(pf.model.clone(), pf.limits, pf.region, true);
    let mut dynamic = Cycle::new(pf.model.clone(), pf.limits, pf.region, true);
    dynamic.set_dynamics(pf.dynamics);
    (stat, dynamic, pf)
}

fn vertical(pose: Pose, a_z: f64) -> Reference {
    Reference {
        pose,
        velocity: [0.0; 6],
        acceleration: [0.0, 0.0, a_z, 0.0, 0.0, 0.0],
    }
}

#[test]
fn a_reference_the_static_check_accepts_is_refused_with_its_inertial_wrench() {
    let (mut stat, mut dynamic, pf) = cycles();
    let mut sp = crs_ipc::JointSetpoint::default();
    let r = vertical(pf.home, 8.0);
    assert_eq!(stat.compute(&r, &mut sp), Ok(()));
    match dynamic.compute(&r, &mut sp) {
        Err(Rejection::NotWrenchFeasible { force_n, .. }) => {
            assert!(force_n > pf.model.params().f_max, "{force_n}")
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    // At rest both agree (the dynamic wrench adds nothing).
    assert_eq!(dynamic.compute(&vertical(pf.home, 0.0), &mut sp), Ok(()));
    // Forces side by side (docs/ride-physics.md): static vs dynamic at +8 m/s².
    let mut data = cdpr_model::Data::new(&pf.model);
    cdpr_model::kinematics::inverse(&pf.model, &mut data, &pf.home).unwrap();
    let p = pf.model.params();
    let mut fs = vec![0.0; 8];
    let mut fd = vec![0.0; 8];
    let m = Motion {
        acceleration: Vector3::new(0.0, 0.0, 8.0),
        ..Motion::default()
    };
    let w_in = inertial_wrench(pf.dynamics.as_ref().unwrap(), &pf.home, &m);
    let s = statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut fs).unwrap();
    let d = statics::force_distribution(&data, &(p.w_e + w_in), p.f_min, p.f_max, &mut fd).unwrap();
    println!("static  f = {fs:.0?} N (feasible {})", s.feasible);
    println!(
        "dynamic f = {fd:.0?} N (feasible {}), w_in = {:.0?}",
        d.feasible,
        w_in.as_slice()
    );
    assert!(s.feasible && !d.feasible);
    // The dynamic forces close the dynamic wrench: A^T f + w_e + w_in = 0.
    let res: Vector6<f64> = statics::residual_wrench(&data, &fd, &(p.w_e + w_in));
    assert!(res.norm() < 1e-6, "{res}");
}

#[test]
fn the_planner_accelerations_come_from_what_stays_feasible() {
    let pf = common::platform("helicopter.toml");
    let mut daemon = config::load(std::path::Path::new(&common::config_path(
        "motion-core-helicopter.toml",
    )))
    .unwrap();
    let dynamic = lifecycle::configure(&daemon, &pf).unwrap();
    daemon.dynamic_wrench = false;
    let stat = lifecycle::configure(&daemon, &pf).unwrap();
    assert!(stat.dynamic_limits().is_none());
    let d = dynamic.dynamic_limits().unwrap();
    let (ls, ld) = (stat.planner_limits(), dynamic.planner_limits());
    assert!(
        d.acceleration_factor > 0.1 && d.acceleration_factor < 1.0,
        "{d:?}"
    );
    assert!(
        (ld.linear_acceleration - ls.linear_acceleration * d.acceleration_factor).abs() < 1e-12
    );
    assert_eq!(ld.linear_velocity, ls.linear_velocity);
    println!(
        "helicopter planner accelerations: static {:.2} m/s², {:.1}°/s²; dynamic {:.2} m/s², {:.1}°/s² (factor {:.3})",
        ls.linear_acceleration,
        ls.angular_acceleration.to_degrees(),
        ld.linear_acceleration,
        ld.angular_acceleration.to_degrees(),
        d.acceleration_factor
    );
    // The demo tour stays feasible under the dynamic check with the scaled limits.
    let wps = motion_core::daemon::trajectory::read_waypoints(std::path::Path::new(
        &common::config_path("demo-waypoints-helicopter.csv"),
    ))
    .unwrap();
    dynamic.verify_plan(&wps).unwrap();
    // Without [dynamics] in the platform the check stays static.
    let mut bare = pf.clone();
    bare.dynamics = None;
    daemon.dynamic_wrench = true;
    assert!(
        lifecycle::configure(&daemon, &bare)
            .unwrap()
            .dynamic_limits()
            .is_none()
    );
}
