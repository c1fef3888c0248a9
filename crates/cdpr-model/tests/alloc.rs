//! Hot paths allocate nothing: a counting global allocator around many calls of the inverse
//! kinematics (standard, pulley), the force distribution, φ_el and both forward kinematics.
//! Only allocations of the thread running the hot paths count (crs_test_support::alloc).
mod common;

use cdpr_model::forward::{self, FkOptions};
use cdpr_model::{Data, Pose, elastostatics, kinematics, statics};
use common::*;
use crs_test_support::alloc::{CountingAlloc, count_allocations};
use nalgebra::Vector3;

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn hot_paths_do_not_allocate() {
    for model in [icosahedron(), pulley_model()] {
        let p = model.params().clone();
        let m = model.m();
        let mut data = Data::new(&model);
        let mut f = vec![0.0; m];
        let mut q_theta = vec![0.0; m];
        let opts = FkOptions::default();
        let poses = test_poses();
        // count_allocations first checks that the counter sees allocations at all.
        let ((), n) = count_allocations(|| {
            for k in 0..300 {
                let pose = poses[k % poses.len()];
                kinematics::inverse(&model, &mut data, &pose).unwrap();
                statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f).unwrap();
                elastostatics::inverse(&model, &mut data, &pose, &f, &mut q_theta).unwrap();
                let guess = Pose::new(
                    pose.r + Vector3::new(0.01, -0.01, 0.01),
                    pose.phi + Vector3::repeat(0.017),
                );
                let el = forward::elastostatic(&model, &mut data, &q_theta, &guess, &opts).unwrap();
                kinematics::inverse(&model, &mut data, &pose).unwrap();
                f.copy_from_slice(&data.q);
                let ls = forward::least_squares(&model, &mut data, &f, &guess, &opts).unwrap();
                std::hint::black_box((el, ls));
            }
        });
        assert_eq!(n, 0, "{n} heap allocations in the hot paths");
    }
}
