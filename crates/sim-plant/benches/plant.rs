//! Plant benchmarks: one equilibrium with every effect on (target ≤ 200 µs) and a 91-pose
//! campaign with tension tests (target: well under a second).

use criterion::{Criterion, criterion_group, criterion_main};
use sim_plant::{Plant, load_campaign, load_plant, run_campaign};
use std::hint::black_box;
use std::path::PathBuf;

fn config(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config")
        .join(rel)
}

fn bench(c: &mut Criterion) {
    let cfg = load_plant(config("plant/crs-like.toml")).expect("crs-like.toml");
    assert_eq!(cfg.effects.enabled_names().len(), 10, "all effects on");
    let home = cfg.platform.home;
    let f_ini = cfg.platform.f_ini.clone().expect("f_ini");
    let mut plant = Plant::new(cfg.clone()).expect("plant");
    let q0 = plant.setup_tension(&home, &f_ini).expect("setup").q_cmd;
    // two commands 5 mm apart per cable (mixed signs): each step is one fresh equilibrium
    let q1: Vec<f64> = q0
        .iter()
        .enumerate()
        .map(|(i, q)| q + if i % 2 == 0 { 0.005 } else { -0.005 })
        .collect();
    plant.step(&q0).expect("step");
    let mut toggle = false;
    c.bench_function("plant_step_all_effects", |b| {
        b.iter(|| {
            toggle = !toggle;
            let q = if toggle { &q1 } else { &q0 };
            black_box(plant.step(black_box(q)).expect("equilibrium"))
        })
    });

    let camp = load_campaign(config("plant/campaign-91.toml")).expect("campaign-91.toml");
    let control = cfg.platform.clone();
    let mut g = c.benchmark_group("campaign");
    g.sample_size(10);
    g.bench_function("campaign_91_poses_tension_tests", |b| {
        b.iter(|| {
            let mut p = Plant::new(cfg.clone()).expect("plant");
            black_box(run_campaign(&mut p, &control, &camp, "nominal").expect("campaign"))
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
