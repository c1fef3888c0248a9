//! The polynomial surrogate fitted to the CRS platform's nominal elastostatic force control
//! (sec. 5.6, eq. 5.23–5.27): default fit (degree 3) over the platform's region must reproduce
//! q_off(x) = φ_el(x, f_ref(x)) − φ(x) within 1 mm, checked here against fresh poses the fit
//! never saw, and the daemon's cycle adds exactly that offset to the standard kinematics.
mod common;

use cdpr_model::offset_target::{OffsetTarget, region_box};
use cdpr_model::{Data, Pose, kinematics};
use nalgebra::Vector3;
use surrogate::{FitOptions, Region, fit};

#[test]
fn default_fit_on_crs_nominal_is_within_1_mm() {
    let pf = common::platform("crs-nominal.toml");
    let m = pf.model.m();
    let (lower, upper) = region_box(&pf.region);
    let region = Region { lower, upper };
    let mut target = OffsetTarget::new(&pf.model);
    let opts = FitOptions {
        validation_samples: 2000,
        ..FitOptions::default()
    };
    let (sg, report) = fit(
        &region,
        &opts,
        m,
        &pf.model.identity_hex(),
        |x: &[f64; 6]| {
            let mut out = [0.0; 8];
            target
                .offset(&Pose::from_array(*x), &mut out[..m])
                .map(|_| out)
        },
    )
    .unwrap();
    assert_eq!(report.degree, 3);
    assert_eq!(report.n_coeffs_per_cable, 84);
    assert!(report.max_fit_error_mm <= 1.0, "{report:?}");
    // The offset is real (tens of mm), so 1 mm is a meaningful accuracy.
    assert!(
        report.max_abs_offset_mm > 10.0,
        "{}",
        report.max_abs_offset_mm
    );
    assert!(report.max_abs_offset_mm < 90.0);

    // Independent check on a grid the fit did not use (corners included).
    let mut worst: f64 = 0.0;
    let mut exact = [0.0; 8];
    let mut approx = [0.0; 8];
    for i in 0..5 {
        for j in 0..5 {
            for k in 0..5 {
                for r in 0..8 {
                    let t = |a: usize, n: usize, d: usize| {
                        lower[d] + (upper[d] - lower[d]) * a as f64 / (n - 1) as f64
                    };
                    let x = [
                        t(i, 5, 0),
                        t(j, 5, 1),
                        t(k, 5, 2),
                        if r & 1 == 0 { lower[3] } else { upper[3] },
                        if r & 2 == 0 { lower[4] } else { upper[4] },
                        if r & 4 == 0 { lower[5] } else { upper[5] },
                    ];
                    target
                        .offset(&Pose::from_array(x), &mut exact[..m])
                        .unwrap();
                    sg.eval(&x, &mut approx[..m]).unwrap();
                    for c in 0..m {
                        worst = worst.max((exact[c] - approx[c]).abs());
                    }
                }
            }
        }
    }
    assert!(worst <= 1e-3, "max error on the check grid {worst} m");
}

#[test]
fn offset_target_is_the_elastic_elongation_of_the_reference_forces() {
    // With the linear law q_θ = q − f q / k_F (eq. 2.33, 2.37): q_off_i = −f_i q_i / k_F.
    let pf = common::platform("crs-nominal.toml");
    let m = pf.model.m();
    let pose = Pose::new(
        Vector3::new(0.4, -0.3, 1.6),
        Vector3::new(0.02, -0.03, 0.01),
    );
    let mut t = OffsetTarget::new(&pf.model);
    let mut off = vec![0.0; m];
    let fd = t.offset(&pose, &mut off).unwrap();
    assert!(fd.feasible);
    let f: Vec<f64> = t.reference_forces(&pose).unwrap().0.to_vec();
    let mut d = Data::new(&pf.model);
    kinematics::inverse(&pf.model, &mut d, &pose).unwrap();
    let k_f = &pf.model.params().k_f;
    for i in 0..m {
        let expect = -f[i] * d.q[i] / k_f[i];
        assert!(
            (off[i] - expect).abs() < 1e-12,
            "cable {i}: {} vs {expect}",
            off[i]
        );
        assert!(f[i] >= pf.model.params().f_min - 1e-9);
    }
}
