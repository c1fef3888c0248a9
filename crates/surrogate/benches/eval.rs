//! Real-time evaluation cost of the surrogate: degree 3 (84 coefficients per cable), 8 cables.
//! Target from the issue: <= 300 ns per evaluation. Results: benches/RESULTS.md.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use surrogate::{FitOptions, Region, fit};

fn crs_like() -> surrogate::Surrogate {
    // CRS-sized region (m, rad) and a smooth made-up offset of a few cm per cable.
    let region = Region {
        lower: [-3.0, -2.5, 0.5, -0.3, -0.3, -0.5],
        upper: [3.0, 2.5, 4.0, 0.3, 0.3, 0.5],
    };
    let opts = FitOptions {
        degree: 3,
        validation_samples: 2_000,
        ..FitOptions::default()
    };
    let (s, _) = fit(&region, &opts, 8, "bench", |x: &[f64; 6]| {
        let q: [f64; 8] = std::array::from_fn(|j| {
            let w = 0.3 + 0.1 * j as f64;
            0.02 * (w * x[0] + 0.2 * x[1]).sin() + 0.005 * x[2] * x[3] + 0.003 * (x[5] * w).cos()
        });
        Ok::<_, String>(q)
    })
    .expect("bench fit");
    s
}

fn bench_eval(c: &mut Criterion) {
    let s = crs_like();
    // A few poses (inside and outside the region) cycled so the measurement is not one cached
    // input; eval's cost is data independent anyway.
    let poses: Vec<[f64; 6]> = (0..16)
        .map(|k| {
            let t = k as f64 / 16.0;
            [
                6.0 * t - 3.5,
                2.0 * (6.0 * t).sin(),
                0.4 + 3.8 * t,
                0.3 * (3.0 * t).cos(),
                -0.2 + 0.4 * t,
                0.6 * (t - 0.5),
            ]
        })
        .collect();
    let mut out = [0.0; 8];
    let mut i = 0usize;
    c.bench_function("surrogate eval degree 3, 8 cables", |b| {
        b.iter(|| {
            i = (i + 1) & 15;
            s.eval(black_box(&poses[i]), black_box(&mut out)).unwrap();
            black_box(out[7])
        })
    });
}

/// Reference floor on this machine: the bare 8 x 84 matrix-vector product (nalgebra, fixed
/// size) with a precomputed basis vector, i.e. eval without normalisation and basis values.
fn bench_matvec_floor(c: &mut Criterion) {
    let m = nalgebra::SMatrix::<f64, 8, 84>::from_fn(|i, j| ((i * 84 + j) as f64).sin());
    let v = nalgebra::SVector::<f64, 84>::from_fn(|j, _| (j as f64).cos());
    c.bench_function("reference: SMatrix<8,84> * SVector<84> only", |b| {
        b.iter(|| black_box(black_box(&m) * black_box(&v)))
    });
}

criterion_group!(benches, bench_eval, bench_matvec_floor);
criterion_main!(benches);
