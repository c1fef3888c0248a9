//! Fit accuracy, conditioning and refusal behaviour of `surrogate::fit`.

mod common;

use common::{crs_region, smooth_target};
use surrogate::{Basis, FitError, FitOptions, fit, n_basis};

/// An exact polynomial of total degree 3 in the *physical* coordinates (so the fit must undo the
/// normalisation), 4 cables, values within a few cm on the CRS region.
fn cubic_target(x: &[f64; 6]) -> [f64; 4] {
    let [px, py, pz, ax, ay, az] = *x;
    [
        0.01 + 0.002 * px - 0.003 * py * pz + 0.0004 * px * px * py,
        -0.02 + 0.01 * ax * ay * az + 0.001 * pz * pz * pz - 0.0005 * px * pz,
        0.003 * px * ax + 0.02 * ay - 0.004 * py * py * az + 0.0002 * px * py * pz,
        0.0,
    ]
}

#[test]
fn exact_polynomial_target_is_reproduced_to_round_off_in_both_bases() {
    for basis in [Basis::Legendre, Basis::Monomial] {
        let opts = FitOptions {
            degree: 3,
            basis,
            validation_samples: 3000,
            ..FitOptions::default()
        };
        let (s, rep) = fit(&crs_region(), &opts, 4, "p", |x: &[f64; 6]| {
            Ok::<_, String>(cubic_target(x))
        })
        .unwrap();
        assert_eq!(rep.n_coeffs_per_cable, 84);
        assert_eq!(rep.n_fit_samples, 6 * 84);
        assert!(
            rep.max_fit_error_mm < 1e-8,
            "{basis:?}: max fit error {} mm",
            rep.max_fit_error_mm
        );
        // Independent check at poses of neither design set.
        let mut q = [0.0; 4];
        for k in 0..200 {
            let t = k as f64 / 200.0;
            let x = [
                -3.0 + 6.0 * t,
                2.5 * (7.0 * t).sin(),
                0.5 + 3.5 * (t * t),
                0.3 * (11.0 * t).cos(),
                -0.3 + 0.6 * (1.0 - t),
                0.5 * (5.0 * t).sin(),
            ];
            s.eval(&x, &mut q).unwrap();
            let want = cubic_target(&x);
            for j in 0..4 {
                assert!(
                    (q[j] - want[j]).abs() < 1e-11,
                    "{basis:?} cable {j} at {x:?}"
                );
            }
        }
    }
}

#[test]
fn smooth_target_error_decreases_with_degree() {
    let mut errs = Vec::new();
    for degree in 1..=4 {
        let opts = FitOptions {
            degree,
            validation_samples: 2000,
            ..FitOptions::default()
        };
        let (_, rep) = fit(&crs_region(), &opts, 3, "p", |x: &[f64; 6]| {
            Ok::<_, String>(smooth_target::<3>(x))
        })
        .unwrap();
        eprintln!("{rep}");
        assert_eq!(rep.n_coeffs_per_cable, n_basis(degree));
        assert!(rep.mean_fit_error_mm <= rep.max_fit_error_mm);
        errs.push(rep.max_fit_error_mm);
    }
    for w in errs.windows(2) {
        assert!(w[1] < 0.7 * w[0], "no convergence: {errs:?}");
    }
    assert!(errs[3] < errs[0] / 20.0, "too slow: {errs:?}");
}

#[test]
fn legendre_basis_is_better_conditioned_than_monomials() {
    let cond = |basis| {
        let opts = FitOptions {
            degree: 3,
            basis,
            validation_samples: 0,
            ..FitOptions::default()
        };
        fit(&crs_region(), &opts, 1, "p", |x: &[f64; 6]| {
            Ok::<_, String>([smooth_target::<1>(x)[0]])
        })
        .unwrap()
        .1
        .condition_number
    };
    let (leg, mono) = (cond(Basis::Legendre), cond(Basis::Monomial));
    eprintln!("condition number degree 3: Legendre {leg:.3}, monomial {mono:.3}");
    assert!(leg.is_finite() && leg >= 1.0);
    assert!(leg * 3.0 < mono, "Legendre {leg} vs monomial {mono}");
}

#[test]
fn over_range_fit_is_refused_naming_pose_cable_and_value() {
    let region = crs_region();
    // Cable 5 reaches +100 mm at x = upper: over the 100 - 10 mm limit there, fine elsewhere.
    let target = |x: &[f64; 6]| {
        let u0 = x[0] / 3.0;
        let mut q = [0.01; 8];
        q[5] = 0.06 + 0.04 * u0;
        Ok::<_, String>(q)
    };
    let err = fit(&region, &FitOptions::default(), 8, "p", target).unwrap_err();
    match &err {
        FitError::BoundViolated {
            at,
            cable,
            offset_mm,
            limit_mm,
            ..
        } => {
            assert_eq!(*cable, 5);
            assert_eq!(at.cable, 5);
            assert_eq!(at.pose[0], region.upper[0]);
            assert!((offset_mm - 100.0).abs() < 1e-6, "{offset_mm}");
            assert!((limit_mm - 90.0).abs() < 1e-9);
        }
        other => panic!("expected BoundViolated, got {other}"),
    }
    let msg = err.to_string();
    assert!(
        msg.contains("cable 5") && msg.contains("x_m=3.000000"),
        "{msg}"
    );

    // Same target with a smaller margin passes (the check is not a blanket refusal).
    let opts = FitOptions {
        bound_m: 0.1005,
        margin_m: 0.0,
        ..FitOptions::default()
    };
    let (_, rep) = fit(&region, &opts, 8, "p", target).unwrap();
    assert!((rep.max_abs_offset_mm - 100.0).abs() < 1e-6);
    assert_eq!(rep.max_abs_offset_at.cable, 5);
}

#[test]
fn certified_bound_and_fit_error_limits_refuse_when_requested() {
    let region = crs_region();
    let t = |x: &[f64; 6]| Ok::<_, String>(smooth_target::<2>(x));
    let (_, rep) = fit(&region, &FitOptions::default(), 2, "p", t).unwrap();
    assert!(rep.certified_bound_mm >= rep.max_abs_offset_mm);
    // Demand a certified bound below what the coefficients give.
    let opts = FitOptions {
        bound_m: rep.certified_bound_mm * 1e-3 * 0.99,
        margin_m: 0.0,
        require_certified_bound: true,
        ..FitOptions::default()
    };
    assert!(
        rep.max_abs_offset_mm < rep.certified_bound_mm * 0.99,
        "test premise"
    );
    let e = fit(&region, &opts, 2, "p", t).unwrap_err();
    assert!(matches!(e, FitError::CertifiedBoundViolated { .. }), "{e}");
    let opts = FitOptions {
        max_fit_error_m: Some(rep.max_fit_error_mm * 1e-3 * 0.5),
        ..FitOptions::default()
    };
    let e = fit(&region, &opts, 2, "p", t).unwrap_err();
    assert!(matches!(e, FitError::FitErrorTooLarge { .. }), "{e}");
}

#[test]
fn bad_targets_and_options_are_refused_clearly() {
    let region = crs_region();
    let o = FitOptions::default();
    let e = fit(&region, &o, 3, "p", |_: &[f64; 6]| {
        Ok::<_, String>(vec![0.0; 2])
    })
    .unwrap_err();
    assert!(e.to_string().contains("returned 2 offsets"), "{e}");
    let e = fit(&region, &o, 2, "p", |x: &[f64; 6]| {
        Ok::<_, String>([0.0, if x[0] > 2.0 { f64::NAN } else { 0.0 }])
    })
    .unwrap_err();
    assert!(e.to_string().contains("cable 1 is not finite"), "{e}");
    let e = fit(&region, &o, 1, "p", |_: &[f64; 6]| {
        Err::<[f64; 1], _>("IK did not converge")
    })
    .unwrap_err();
    assert!(e.to_string().contains("IK did not converge"), "{e}");
    let bad = FitOptions {
        fit_samples: Some(50),
        ..FitOptions::default()
    };
    let e = fit(&region, &bad, 1, "p", |_: &[f64; 6]| Ok::<_, String>([0.0])).unwrap_err();
    assert!(e.to_string().contains("fit_samples"), "{e}");
    let mut r = region;
    r.lower[4] = r.upper[4];
    let e = fit(&r, &o, 1, "p", |_: &[f64; 6]| Ok::<_, String>([0.0])).unwrap_err();
    assert!(e.to_string().contains("phi_y_rad"), "{e}");
    let e = fit(&region, &o, 17, "p", |_: &[f64; 6]| {
        Ok::<_, String>([0.0; 17])
    })
    .unwrap_err();
    assert!(e.to_string().contains("n_cables"), "{e}");
}

#[test]
fn ridge_shrinks_coefficients() {
    let region = crs_region();
    let t = |x: &[f64; 6]| Ok::<_, String>(smooth_target::<1>(x));
    let (s0, _) = fit(&region, &FitOptions::default(), 1, "p", t).unwrap();
    let opts = FitOptions {
        ridge: 1.0,
        ..FitOptions::default()
    };
    let (s1, r1) = fit(&region, &opts, 1, "p", t).unwrap();
    let n = |s: &surrogate::Surrogate| {
        s.coefficients(0)
            .unwrap()
            .iter()
            .map(|c| c * c)
            .sum::<f64>()
    };
    assert!(n(&s1) < n(&s0));
    assert_eq!(r1.ridge, 1.0);
}
