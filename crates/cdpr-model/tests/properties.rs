//! Property tests over random poses in the operating region (proptest).
mod common;

use cdpr_model::forward::{self, FkOptions};
use cdpr_model::{Data, Pose, kinematics, statics, workspace};
use common::*;
use nalgebra::Vector3;
use proptest::prelude::*;

fn region_pose() -> impl Strategy<Value = Pose> {
    let d = 4f64.to_radians();
    (-1.5..1.5f64, -1.5..1.5f64, 1.3..2.6f64, -d..d, -d..d, -d..d)
        .prop_map(|(x, y, z, a, b, c)| Pose::new(Vector3::new(x, y, z), Vector3::new(a, b, c)))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn ik_fk_round_trip_anywhere_in_the_region(pose in region_pose(), pulley in any::<bool>()) {
        let model = if pulley { pulley_model() } else { icosahedron() };
        let mut data = Data::new(&model);
        kinematics::inverse(&model, &mut data, &pose).unwrap();
        let q = data.q.clone();
        let guess = Pose::new(pose.r + Vector3::new(0.01, 0.01, -0.01), pose.phi + Vector3::repeat(0.0175));
        let sol = forward::least_squares(&model, &mut data, &q, &guess, &FkOptions::default()).unwrap();
        let (dr, dphi) = sol.pose.error_to(&pose);
        prop_assert!(dr < 1e-9 && dphi < 1e-9, "{dr:e} m, {dphi:e} rad");
    }

    #[test]
    fn closed_form_forces_always_close_the_wrench(pose in region_pose()) {
        let model = icosahedron();
        let p = model.params();
        let mut data = Data::new(&model);
        let mut f = vec![0.0; 8];
        let fd = workspace::check_pose(&model, &mut data, &pose, &mut f).unwrap();
        prop_assert!(statics::residual_wrench(&data, &f, &p.w_e).amax() < 1e-7);
        // The verdict is exactly the limit check on the returned forces.
        let inside = f.iter().all(|x| *x >= p.f_min && *x <= p.f_max);
        prop_assert_eq!(fd.feasible, inside);
    }

    #[test]
    fn elastostatic_round_trip_at_feasible_poses(pose in region_pose(), pulley in any::<bool>()) {
        let model = if pulley { pulley_model() } else { icosahedron() };
        let p = model.params().clone();
        let mut data = Data::new(&model);
        let mut f = vec![0.0; 8];
        let fd = workspace::check_pose(&model, &mut data, &pose, &mut f).unwrap();
        prop_assume!(fd.feasible);
        let mut qt = vec![0.0; 8];
        cdpr_model::elastostatics::inverse(&model, &mut data, &pose, &f, &mut qt).unwrap();
        let sol = forward::elastostatic(&model, &mut data, &qt, &pose.add_increment(&nalgebra::Vector6::repeat(0.005)), &FkOptions::default()).unwrap();
        let (dr, dphi) = sol.pose.error_to(&pose);
        prop_assert!(dr < 1e-9 && dphi < 1e-9, "{dr:e} m, {dphi:e} rad");
        prop_assert!(statics::residual_wrench(&data, &data.f, &p.w_e).amax() < 1e-4);
    }
}
