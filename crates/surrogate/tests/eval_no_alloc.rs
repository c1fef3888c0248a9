//! `Surrogate::eval` must not allocate (1 ms hard loop): crs_test_support's counting allocator
//! counts the allocations this test's thread makes.

use crs_test_support::alloc::{CountingAlloc, count_allocations};
use surrogate::{FitOptions, Region, fit};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

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

    // count_allocations first checks that the counter sees allocations on this thread.
    let (sum, n) = count_allocations(|| {
        let mut sum = 0.0;
        for k in 0..1000 {
            let t = k as f64 * 0.01;
            let x = [10.0 * t.sin(), t - 5.0, 2.0, 0.1 * t, -0.4, 1e9 * t];
            let r = s.eval(std::hint::black_box(&x), &mut out);
            sum += out[3] + if r.is_ok() { 0.0 } else { 1.0 };
            // The error path must not allocate either.
            let _ = std::hint::black_box(s.eval(&x, &mut out[..3]));
        }
        sum
    });
    std::hint::black_box(sum);
    assert_eq!(n, 0, "eval allocated {n} times");
}
