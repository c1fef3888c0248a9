//! Hot paths allocate nothing: a counting global allocator around many calls of the inverse
//! kinematics (standard, pulley), the force distribution, φ_el and both forward kinematics.
//! Only allocations of the thread running the hot paths count (a thread-local gate): the test
//! harness's own thread may still be printing or bookkeeping when counting starts on a loaded
//! machine, and its allocations are not the hot paths'.
mod common;

use cdpr_model::forward::{self, FkOptions};
use cdpr_model::{Data, Pose, elastostatics, kinematics, statics};
use common::*;
use nalgebra::Vector3;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);
thread_local! {
    // const-initialised, no destructor: reading it never allocates, also inside the allocator.
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

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
        COUNTING.with(|c| c.set(true));
        // Sanity: the counter sees allocations at all.
        let before = ALLOCS.load(Ordering::Relaxed);
        drop(std::hint::black_box(vec![1u8; 16]));
        assert!(ALLOCS.load(Ordering::Relaxed) > before);

        let start = ALLOCS.load(Ordering::Relaxed);
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
        let n = ALLOCS.load(Ordering::Relaxed) - start;
        COUNTING.with(|c| c.set(false));
        assert_eq!(n, 0, "{n} heap allocations in the hot paths");
    }
}
