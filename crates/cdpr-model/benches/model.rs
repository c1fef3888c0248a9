//! Criterion benches of the model hot paths on the CRS icosahedron (8 cables).
//! Targets: standard IK ≤ 150 ns, closed-form forces ≤ 2 µs, LM FK from a
//! 1 cm / 1° guess ≤ 10 µs, elastostatic FK ≤ 30 µs. Figures go to benches/RESULTS.md.

use cdpr_model::config::load_platform;
use cdpr_model::forward::{self, FkOptions};
use cdpr_model::{Data, Pose, elastostatics, feasibility, kinematics, statics};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{DVector, Vector3};
use std::hint::black_box;

fn platform(name: &str) -> cdpr_model::Model {
    load_platform(format!(
        "{}/../../config/{name}",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap()
    .model
}

fn benches(c: &mut Criterion) {
    let pose = Pose::new(
        Vector3::new(0.4, -0.3, 1.8),
        Vector3::new(0.02, -0.015, 0.025),
    );
    let d = 1f64.to_radians();
    let guess = Pose::new(
        pose.r + Vector3::new(0.01, -0.01, 0.01),
        pose.phi + Vector3::new(d, -d, d),
    );
    for (name, model) in [
        ("standard", platform("icosahedron.toml")),
        ("pulley", platform("icosahedron-pulleys.toml")),
    ] {
        let p = model.params().clone();
        let mut data = Data::new(&model);
        c.bench_function(&format!("ik_{name}"), |b| {
            b.iter(|| kinematics::inverse(&model, &mut data, black_box(&pose)).unwrap())
        });
        let mut f = vec![0.0; model.m()];
        kinematics::inverse(&model, &mut data, &pose).unwrap();
        c.bench_function(&format!("forces_closed_form_{name}"), |b| {
            b.iter(|| {
                statics::force_distribution(&data, black_box(&p.w_e), p.f_min, p.f_max, &mut f)
                    .unwrap()
            })
        });
        c.bench_function(&format!("ik_plus_forces_{name}"), |b| {
            b.iter(|| {
                kinematics::inverse(&model, &mut data, black_box(&pose)).unwrap();
                statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f).unwrap()
            })
        });
        // Exact wrench feasibility (eq. 3.29): the dedicated vertex solver against
        // microlp's simplex on the same pose; the closed form above is the hard loop's test.
        let at = statics::structure_matrix(&data);
        let w = DVector::from_column_slice(p.w_e.as_slice());
        c.bench_function(&format!("feasibility_exact_vertex_{name}"), |b| {
            b.iter(|| feasibility::exact_vertex(black_box(&at), &w, p.f_min, p.f_max).unwrap())
        });
        c.bench_function(&format!("feasibility_exact_simplex_{name}"), |b| {
            b.iter(|| feasibility::exact_lp(black_box(&at), &w, p.f_min, p.f_max).unwrap())
        });
        kinematics::inverse(&model, &mut data, &pose).unwrap();
        let q = data.q.clone();
        let opts = FkOptions::default();
        c.bench_function(&format!("fk_least_squares_1cm_1deg_{name}"), |b| {
            b.iter(|| {
                forward::least_squares(&model, &mut data, black_box(&q), &guess, &opts).unwrap()
            })
        });
        statics::force_distribution(&data, &p.w_e, p.f_min, p.f_max, &mut f).unwrap();
        let mut q_theta = vec![0.0; model.m()];
        elastostatics::inverse(&model, &mut data, &pose, &f, &mut q_theta).unwrap();
        c.bench_function(&format!("fk_elastostatic_1cm_1deg_{name}"), |b| {
            b.iter(|| {
                forward::elastostatic(&model, &mut data, black_box(&q_theta), &guess, &opts)
                    .unwrap()
            })
        });
        let it_ls = forward::least_squares(&model, &mut data, &q, &guess, &opts)
            .unwrap()
            .iterations;
        let it_el = forward::elastostatic(&model, &mut data, &q_theta, &guess, &opts)
            .unwrap()
            .iterations;
        println!(
            "{name}: LM iterations from 1 cm / 1°: least squares {it_ls}, elastostatic {it_el}"
        );
    }
}

criterion_group! {
    name = model;
    config = Criterion::default().sample_size(50).measurement_time(std::time::Duration::from_secs(2)).warm_up_time(std::time::Duration::from_millis(500));
    targets = benches
}
criterion_main!(model);
