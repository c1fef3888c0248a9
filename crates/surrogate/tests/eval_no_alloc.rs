//! `Surrogate::eval` must not allocate (1 ms hard loop). A counting global allocator records
//! allocations made by this test's thread while the flag is set.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use surrogate::{FitOptions, Region, fit};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);
thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

// SAFETY: forwards to the system allocator; only adds a counter.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn eval_allocates_nothing() {
    let region = Region {
        lower: [-3.0, -2.5, 0.5, -0.3, -0.3, -0.5],
        upper: [3.0, 2.5, 4.0, 0.3, 0.3, 0.5],
    };
    let opts = FitOptions {
        validation_samples: 200,
        ..FitOptions::default()
    };
    let (s, _) = fit(&region, &opts, 8, "p", |x: &[f64; 6]| {
        Ok::<_, String>(std::array::from_fn::<f64, 8, _>(|j| {
            0.01 * (x[0] + j as f64).sin()
        }))
    })
    .unwrap();
    let mut out = [0.0; 8];

    // Sanity: the counter does see allocations on this thread.
    COUNTING.with(|c| c.set(true));
    let v = std::hint::black_box(vec![1u8; 64]);
    COUNTING.with(|c| c.set(false));
    drop(v);
    assert_eq!(
        ALLOCS.swap(0, Ordering::SeqCst),
        1,
        "counter is not working"
    );

    COUNTING.with(|c| c.set(true));
    let mut sum = 0.0;
    for k in 0..1000 {
        let t = k as f64 * 0.01;
        let x = [10.0 * t.sin(), t - 5.0, 2.0, 0.1 * t, -0.4, 1e9 * t];
        let r = s.eval(std::hint::black_box(&x), &mut out);
        sum += out[3] + if r.is_ok() { 0.0 } else { 1.0 };
        // The error path must not allocate either.
        let _ = std::hint::black_box(s.eval(&x, &mut out[..3]));
    }
    COUNTING.with(|c| c.set(false));
    std::hint::black_box(sum);
    assert_eq!(ALLOCS.load(Ordering::SeqCst), 0, "eval allocated");
}
