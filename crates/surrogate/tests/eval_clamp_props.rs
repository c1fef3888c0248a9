//! Evaluation outside the region (clamping) and robustness for arbitrary finite poses.

mod common;

use common::{crs_region, smooth_target};
use proptest::prelude::*;
use std::sync::OnceLock;
use surrogate::{EvalError, FitOptions, Surrogate, fit};

fn surrogate() -> &'static Surrogate {
    static S: OnceLock<Surrogate> = OnceLock::new();
    S.get_or_init(|| {
        let opts = FitOptions {
            validation_samples: 500,
            ..FitOptions::default()
        };
        fit(&crs_region(), &opts, 8, "p", |x: &[f64; 6]| {
            Ok::<_, String>(smooth_target::<8>(x))
        })
        .unwrap()
        .0
    })
}

fn eval(x: &[f64; 6]) -> [f64; 8] {
    let mut q = [0.0; 8];
    surrogate().eval(x, &mut q).unwrap();
    q
}

#[test]
fn outside_the_region_the_boundary_value_is_returned() {
    let r = crs_region();
    let inside = [0.7, -1.1, 2.2, 0.05, -0.12, 0.3];
    for i in 0..6 {
        for (far, edge) in [
            (r.upper[i] + 5.0, r.upper[i]),
            (r.lower[i] - 1e6, r.lower[i]),
            (f64::INFINITY, r.upper[i]),
            (f64::MAX, r.upper[i]),
            (-f64::MAX, r.lower[i]),
        ] {
            let mut x_far = inside;
            x_far[i] = far;
            let mut x_edge = inside;
            x_edge[i] = edge;
            let (a, b) = (eval(&x_far), eval(&x_edge));
            for j in 0..8 {
                assert!(
                    (a[j] - b[j]).abs() <= 1e-15,
                    "coord {i} cable {j}: {} vs boundary {}",
                    a[j],
                    b[j]
                );
            }
        }
    }
    // A corner outside in all coordinates equals the region corner.
    let far: [f64; 6] = std::array::from_fn(|i| r.upper[i] + 100.0);
    let (a, b) = (eval(&far), eval(&r.upper));
    assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-15));
    // And the boundary value is not just some constant: it differs from an inside value.
    assert_ne!(eval(&inside), eval(&r.upper));
}

#[test]
fn wrong_output_length_is_an_error_not_a_panic() {
    let mut q = [0.0; 7];
    assert_eq!(
        surrogate().eval(&[0.0; 6], &mut q),
        Err(EvalError::OutputLength {
            expected: 8,
            got: 7
        })
    );
}

#[test]
fn nan_pose_gives_nan_not_a_plausible_value() {
    let q = eval(&[f64::NAN, 0.0, 2.0, 0.0, 0.0, 0.0]);
    assert!(q.iter().all(|v| v.is_nan()));
}

fn finite() -> impl Strategy<Value = f64> {
    prop_oneof![
        -10.0..10.0f64,
        -1e6..1e6f64,
        proptest::num::f64::NORMAL | proptest::num::f64::SUBNORMAL | proptest::num::f64::ZERO,
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    #[test]
    fn eval_is_finite_and_within_certified_bound_for_any_finite_pose(
        x in proptest::array::uniform6(finite())
    ) {
        let q = eval(&x);
        let bound_m = surrogate().report().certified_bound_mm * 1e-3;
        for v in q {
            prop_assert!(v.is_finite());
            prop_assert!(v.abs() <= bound_m * (1.0 + 1e-12));
        }
    }
}
